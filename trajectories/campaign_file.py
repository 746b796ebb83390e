"""Read a campaign TOML file of either format into the one campaign type,
:class:`~trajectories.robot_campaign.RobotCampaign` (validation:
:func:`trajectories.robot_campaign.campaign_from_dict`)."""

from __future__ import annotations

import tomllib
from pathlib import Path

from trajectories.robot_campaign import RobotCampaign, campaign_from_dict

from . import CampaignFileError, SchemaError
from .schema import mixup_hint

__all__ = ["load_any_campaign", "load_campaign"]


def load_campaign(path: str | Path) -> RobotCampaign:
    """Load and validate a campaign file: a ``[robot]`` file, or a ``[joint]`` file read as a
    robot with one moving joint (no robot file; its drives are those of ``[daq]``).

    Parameters
    ----------
    path : str or Path
        A TOML file in the format documented in :mod:`trajectories.robot_campaign` or
        :mod:`trajectories.campaign`.

    Returns
    -------
    RobotCampaign
        Frozen; ``campaign.source`` is ``str(path)``.

    Raises
    ------
    trajectories.CampaignFileError
        The file is not valid TOML (the one-line message names the file, line and column)
        or is not UTF-8.
    trajectories.SchemaError
        The content does not match the schema (the message names the file and the key;
        a robot or plant file's adds what it looks like and where it goes:
        :func:`trajectories.schema.mixup_hint`).
    OSError
        The file cannot be read.
    """
    raw = _read(path)
    try:
        return campaign_from_dict(raw, source=str(path))
    except SchemaError as exc:  # a robot or plant file given as the campaign: say so
        hint = mixup_hint(raw, "campaign")
        if not hint:
            raise
        raise SchemaError(f"{exc}; {hint}") from None


#: the former name of :func:`load_campaign` (which reads both formats)
load_any_campaign = load_campaign


def _read(path: str | Path) -> dict:
    path = Path(path)
    data = path.read_bytes()
    try:
        raw = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        what = ("an MCAP log, not a campaign file: give it to jointid fit or jointid export"
                if data.startswith(b"\x89MCAP") else "expected a campaign file (TOML text)")
        raise CampaignFileError(
            f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start}); {what}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise CampaignFileError(f"{path}: invalid TOML: {exc}") from exc
    return raw
