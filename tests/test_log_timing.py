"""A log's torque timing (``campaign.torque_delay_cycles``, docs/log-format.md) is applied when
it is read: torque k is paired with q taken ``d - 0.5`` cycles later, the chain's half cycle
completing it (``ident.timing.align_to_torque``); logs without the key read as before."""

from __future__ import annotations

import numpy as np
import pytest

from ident import DataError
from ident.loaders import log_torque_delay
from ident.timing import CHAIN_DELAY, align_to_torque


def _poly(t):
    return 0.3 + 2.0 * t - 4.0 * t**2 + 9.0 * t**3


@pytest.mark.parametrize("delay", [0.0, 0.5, 0.8, 1.5, 2.25])
def test_torque_k_is_paired_with_q_at_the_log_delay_minus_the_chain_half_cycle(delay):
    dt = 1e-3
    t = np.arange(200) * dt
    tau = np.sin(t)
    q = np.column_stack([_poly(t), 2 * _poly(t)])
    t2, q2, tau2, ref2 = align_to_torque(t, q, tau, q[:, 0].copy(), delay, "x.mcap")
    e = delay - CHAIN_DELAY
    assert len(t2) == len(q2) == len(tau2) == len(ref2) == 200 - abs(int(np.floor(e)))
    inner = slice(2, -3)  # the ends are extrapolated linearly (trimmed by the chain)
    np.testing.assert_allclose(q2[inner, 0], _poly(t2 + e * dt)[inner], rtol=1e-12)
    np.testing.assert_allclose(q2[inner, 1], 2 * _poly(t2 + e * dt)[inner], rtol=1e-12)
    np.testing.assert_allclose(ref2[inner], _poly(t2 + e * dt)[inner], rtol=1e-12)
    np.testing.assert_array_equal(tau2, np.sin(t2))  # the torque and its stamps untouched
    if e == 0:
        assert q2 is q and t2 is t


def test_the_metadata_value_and_its_errors():
    assert log_torque_delay({}, "old.mcap") == 0.5  # logs before the key: as before
    assert log_torque_delay({"campaign": {"torque_delay_cycles": "1.5"}}, "a.mcap") == 1.5
    for bad in ("-1", "soon", "nan"):
        with pytest.raises(DataError, match=r"^a.mcap: metadata campaign.torque_delay_cycles "
                                            r".*: expected a number >= 0 \[cycles\]$"):
            log_torque_delay({"campaign": {"torque_delay_cycles": bad}}, "a.mcap")
    with pytest.raises(DataError, match="too few to align"):
        align_to_torque(np.arange(4.0), np.arange(4.0), np.arange(4.0), None, 2.5, "s.mcap")


def test_the_states_chain_completes_the_logs_timing_like_the_columns_chain():
    """Both robot chains pair a jointid log's torque with q half a cycle later (the chain's
    part of the log's timing); files of unknown timing get none. The states chain had none,
    which left a re-paired arm log's q half a cycle early (read as a torque lag)."""
    from ident.chain import TORQUE_DELAY
    from ident.robot.loaders import RawRobotRun, RobotPreprocessing, _settings

    t = np.arange(4000) * 1e-3
    q = np.column_stack([np.sin(2 * t), np.cos(3 * t)])
    tau = np.column_stack([np.cos(2 * t), np.sin(3 * t)])
    for name, want in (("run.mcap", TORQUE_DELAY), ("run.csv", 0.0)):
        runs = [RawRobotRun(name, t, q, tau)]
        assert _settings(runs, RobotPreprocessing()).torque_delay == want, name
