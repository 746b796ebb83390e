"""Shipped example files (installed as ``daq.examples``)."""

from importlib import resources
from pathlib import Path


def path(name: str) -> Path:
    """Return the installed path of the example file ``name`` (e.g. ``"campaign.toml"``)."""
    return Path(str(resources.files(__name__) / name))
