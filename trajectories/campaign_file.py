"""Read a campaign TOML file; validation is in `trajectories.campaign.Campaign.from_dict`."""

from __future__ import annotations

import tomllib
from pathlib import Path

from trajectories.campaign import Campaign
from trajectories.robot_campaign import RobotCampaign, campaign_from_dict

from . import CampaignFileError

__all__ = ["load_any_campaign", "load_campaign"]


def load_campaign(path: str | Path) -> Campaign:
    """Load and validate a campaign file.

    Parameters
    ----------
    path : str or Path
        A TOML file in the format documented in :mod:`trajectories.campaign`.

    Returns
    -------
    Campaign
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
    return Campaign.from_dict(_read(path), source=str(path))


def load_any_campaign(path: str | Path) -> Campaign | RobotCampaign:
    """Load either campaign format: a ``[joint]`` file (:class:`Campaign`) or a ``[robot]``
    file (:class:`~trajectories.robot_campaign.RobotCampaign`). Errors as
    :func:`load_campaign`."""
    return campaign_from_dict(_read(path), source=str(path))


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
