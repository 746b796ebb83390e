"""Read a campaign TOML file; validation is in `trajectories.campaign.Campaign.from_dict`."""

from __future__ import annotations

import tomllib
from pathlib import Path

from trajectories.campaign import Campaign

from . import CampaignFileError

__all__ = ["load_campaign"]


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
    path = Path(path)
    data = path.read_bytes()
    try:
        raw = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise CampaignFileError(
            f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from exc
    except tomllib.TOMLDecodeError as exc:
        raise CampaignFileError(f"{path}: invalid TOML: {exc}") from exc
    return Campaign.from_dict(raw, source=str(path))
