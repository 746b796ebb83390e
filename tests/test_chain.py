"""The one preprocessing chain (ident.chain) from one joint to n: k axes processed together
give, axis by axis, the floats of k one-axis runs; the settings are resolved by one rule; the
states chain (preprocess_runs) is the chain without columns."""

from __future__ import annotations

import numpy as np
import pytest

from ident import DataError
from ident.chain import (
    RawExperiment,
    decimate,
    diffcent,
    lowpass,
    resolve_settings,
    run_chain,
)
from ident.robot import RobotIdentError
from ident.robot.loaders import RawRobotRun, preprocess_runs, resolved_settings

FS = 1000.0


def _axes(k: int, n: int = 6000, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smooth positions with quantisation, torques with noise, references, (n, k) each."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    f = 0.3 + 0.2 * np.arange(k)
    ref = np.sin(2 * np.pi * np.outer(t, f)) + 0.2 * np.sin(2 * np.pi * np.outer(t, 3 * f))
    q = np.round((ref + 1e-6 * rng.standard_normal((n, k))) / 1e-6) * 1e-6
    tau = 2.0 * q + 0.3 * np.sign(np.gradient(ref, axis=0)) + 0.05 * rng.standard_normal((n, k))
    return q, tau, ref


def _columns(_: int, f) -> tuple[list[np.ndarray], np.ndarray]:  # noqa: ANN001 - FullRate
    """A nonlinear column per axis (sign(dq) ddq) and a rejection (|tau_f| < 0.1)."""
    return [(np.sign(f.dq) * f.ddq).T, f.ref_ddq.T], np.abs(f.tau_f) < 0.1


def test_k_axes_give_the_floats_of_k_single_axis_runs():
    q, tau, ref = _axes(3)
    dt = 1.0 / FS
    s = resolve_settings(q, dt, instruments=True, torque_delay=0.0)
    both, dq_min = run_chain([RawExperiment("a", q, tau, ref)], dt, s, _columns,
                             instruments=True, dq_min_rel=0.05)
    (b,) = both
    assert b.keep.shape == (b.index.size, 3) and dq_min is not None
    for j in range(3):
        # the one-axis run with the threshold of the k-axis run (a fraction of its max |dq|)
        one, _ = run_chain([RawExperiment("a", q[:, [j]], tau[:, [j]], ref[:, [j]])], dt,
                           resolve_settings(q, dt, instruments=True, torque_delay=0.0,
                                            dq_min=dq_min), _columns, instruments=True)
        (c,) = one
        for x, y in zip(b.states(), c.states(), strict=True):
            assert np.array_equal(x[:, j], y[:, 0])
        for x, y in zip(b.columns(), c.columns(), strict=True):
            assert np.array_equal(x[j], y[0])
        assert np.array_equal(b.keep[:, j], c.keep[:, 0])
    # the steps are the named functions: q low-passed, differenced, decimated in parallel
    r, trim = s.decimation, s.trim
    nf = q.shape[0] - 2 * trim
    assert b.index.size == decimate(np.zeros(nf), r)[0].size
    dq = diffcent(lowpass(q[:, 0], s.cutoff_hz, FS), dt)[trim:-trim]
    assert np.array_equal(b.states()[2][:, 0], decimate(dq, r)[0])


def test_settings_rule_and_errors():
    q, _, _ = _axes(2)
    dt = 1.0 / FS
    s = resolve_settings(q, dt, cutoff_hz=40.0)
    assert (s.decimation, s.trim, s.guard) == (25, 75, 75)  # round(f_s/fc), 3 f_s/fc, 3 r
    assert resolve_settings(q, dt, cutoff_hz=40.0, instruments=True).cutoff_hz == 40.0
    assert resolve_settings(q, dt, instruments=True).cutoff_hz >= 0.125 * FS
    assert resolve_settings(q, dt, sources=["a.mcap"]).torque_delay == 0.5
    assert resolve_settings(q, dt, sources=["a.csv", "b.mcap"]).torque_delay == 0.0
    for bad, what in (({"cutoff_hz": 600.0}, "Nyquist"), ({"decimation": 0}, "decimation"),
                      ({"trim": -1}, "trim"), ({"guard": -1}, "guard"),
                      ({"torque_delay": 1.0}, "torque_delay"), ({"dq_min": -1.0}, "dq_min")):
        with pytest.raises(DataError, match=what):
            resolve_settings(q, dt, **bad)
        with pytest.raises(RobotIdentError, match=what):
            resolve_settings(q, dt, error=RobotIdentError, **bad)
    short = RawExperiment("short.csv", q[:50], q[:50])
    with pytest.raises(DataError, match=r"short\.csv: 50 samples, too few"):
        run_chain([short], dt, s, lambda i, f: ([], None))


def test_states_chain_is_the_chain_without_columns():
    """preprocess_runs: the chain's decimated states with the states rule of decimation
    (the floor of the exact ratio 0.4 f_s / cut-off), time stamps of the kept samples, and the
    file's derivatives taken as given."""
    q, tau, ref = _axes(2)
    t = np.arange(q.shape[0]) / FS
    run = RawRobotRun("a.csv", t, q, tau, q_ref=ref)
    settings = resolved_settings([run])
    cut = settings["cutoff_hz"]
    assert settings["decimation"] == max(1, int(np.floor(0.4 * FS / cut + 1e-9)))
    assert resolved_settings([run], None) == settings
    dt = float(np.median(np.diff(t)))  # the chain's period
    s = resolve_settings(q, dt, cutoff_hz=cut, decimation=settings["decimation"],
                         trim=settings["trim"], torque_delay=0.0)
    (b,), _ = run_chain([RawExperiment("a.csv", q, tau, ref)], dt, s,
                        lambda i, f: ([f.ref.T], None))
    sig = preprocess_runs([run], ["j1", "j2"])
    for x, y in zip((sig.tau, sig.q, sig.dq, sig.ddq), b.states(), strict=True):
        assert np.array_equal(x, y)
    assert np.array_equal(sig.q_ref, b.columns()[0].T)
    assert np.array_equal(sig.t, t[b.full.keep][b.index])
    given = RawRobotRun("g.csv", t, q, tau, dq=2 * q, ddq=3 * q)
    sg = preprocess_runs([given], ["j1", "j2"])
    # decimate keeps linear relations: dq = 2 q, ddq = 3 q as the file gave them
    np.testing.assert_allclose(sg.dq, 2 * sg.q, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sg.ddq, 3 * sg.q, rtol=1e-12, atol=1e-12)
