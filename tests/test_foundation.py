"""The package installs, the CLI answers, and the CiA 402 tables follow the standard."""

from __future__ import annotations

import subprocess
import sys

import pytest

from daq.protocol import cia402
from daq.protocol.cia402 import Mode, State


def test_version_flag():
    out = subprocess.run(
        [sys.executable, "-c", "from daq.app.cli import main; main(['--version'])"],
        capture_output=True, text=True,
    )
    assert out.returncode == 0
    assert out.stdout.startswith("jointid ")


@pytest.mark.parametrize("state", list(State))
def test_statusword_roundtrip(state):
    for flags in ({}, {"bit12": True, "warning": True}, {"voltage_enabled": False}):
        assert cia402.state_from_statusword(cia402.statusword(state, **flags)) is state


def test_transition_table_matches_standard_numbers():
    numbers = {n for (_, n) in cia402.TRANSITIONS.values()}
    assert numbers == {2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12}
    assert cia402.next_state(State.SWITCH_ON_DISABLED, 0x06, 0)[1] == 2
    assert cia402.next_state(State.OPERATION_ENABLED, 0x02, 0x0F) == (State.QUICK_STOP_ACTIVE, 11)
    # fault reset acts on the rising edge of bit 7 only
    assert cia402.next_state(State.FAULT, 0x80, 0x00) == (State.SWITCH_ON_DISABLED, 15)
    assert cia402.next_state(State.FAULT, 0x80, 0x80) == (State.FAULT, None)
    assert cia402.next_state(State.QUICK_STOP_ACTIVE, 0x0F, 0x02, quick_stop_option=6)[1] == 16
    assert cia402.next_state(State.QUICK_STOP_ACTIVE, 0x0F, 0x02, quick_stop_option=2)[1] is None


def test_path_reaches_operation_enabled_from_fault():
    steps = cia402.path(State.FAULT, State.OPERATION_ENABLED)
    assert [n for n, _ in steps] == [15, 2, 3, 4]
    state, prev = State.FAULT, 0
    for _, cw in steps:
        state, _ = cia402.next_state(state, cw, prev)
        prev = cw
    assert state is State.OPERATION_ENABLED


def test_supported_modes_decodes_vendor_values():
    # Ingenia EVE-NET-C advertises no CST; ZeroErr does (see shared/eds/PROVENANCE.md)
    assert Mode.CYCLIC_SYNC_TORQUE not in cia402.supported_modes(0x301A5)
    assert Mode.CYCLIC_SYNC_TORQUE in cia402.supported_modes(0x38D)
    assert cia402.supported_modes(cia402.supported_modes_mask({Mode.CYCLIC_SYNC_POSITION})) == {
        Mode.CYCLIC_SYNC_POSITION
    }
