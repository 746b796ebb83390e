"""Read a campaign TOML file of either format into the one campaign type,
:class:`~trajectories.robot_campaign.RobotCampaign` (validation:
:func:`trajectories.robot_campaign.campaign_from_dict`)."""

from __future__ import annotations

import tomllib
from pathlib import Path

from trajectories.robot_campaign import RobotCampaign, campaign_from_dict

from . import CampaignFileError

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
        The content does not match the schema (the message names the file and the key).
    OSError
        The file cannot be read.
    """
    return campaign_from_dict(_read(path), source=str(path))


#: the former name of :func:`load_campaign` (which reads both formats)
load_any_campaign = load_campaign


def _read(path: str | Path) -> dict:
    path = Path(path)
    data = path.read_bytes()
    try:
        raw = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise CampaignFileError(
            f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from exc
    except tomllib.TOMLDecodeError as exc:
        raise CampaignFileError(f"{path}: invalid TOML: {exc}") from exc
    return raw
