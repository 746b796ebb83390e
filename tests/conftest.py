"""Shared test fixtures: where the team's shared materials are, and how to skip without them."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("JOINTID_SHARED", ROOT.parent / "shared"))


def shared_path(*parts: str) -> Path:
    """Path under ../shared, or skip the test with a clear reason when it is absent."""
    p = SHARED.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"shared material not found: {p} (set JOINTID_SHARED to its folder)")
    return p


@pytest.fixture
def shared():
    return shared_path


VENDOR_EDS = (
    "maxon_epos4-module-50-5.eds",
    "elmo_gold.dcf",
    "nanotec_c5-e-2-09.eds",
    "ingenia_everest-net-c.eds",
    "zeroerr_erob-edriver.eds",
)


@pytest.fixture(autouse=True)
def _hermetic_python_can_config(monkeypatch):
    """python-can's own configuration (environment, ~/.canrc ...) fills what a campaign's
    ``[daq]`` leaves out (``daq.config.can_config_fallback``): tests start without any, and
    set what they exercise."""
    import can.util

    for var in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(can.util, "CONFIG_FILES", [])
    monkeypatch.setattr(can, "rc", {})
