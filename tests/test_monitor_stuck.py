"""The stuck bin of the torque monitor's regime thresholds (docs/monitoring.md, issue 25): a
joint whose measured velocity is zero is held by its static friction; its residual is then 0
unless the torque leaves the model's static band, and its band comes from the validation's
stuck samples instead of the first bin's (which the start transients widen)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from test_monitor_regime import _Log as _RegimeLog
from test_monitor_regime import _run as _regime_run
from test_monitor_regime import _run_velocity

from daq import ConfigError
from daq.app.monitor import stuck_edges
from daq.runtime.monitor import TorqueMonitor, moving_seconds
from ident import DataError
from ident.monitor import DEFAULT_EDGES_S, Thresholds, thresholds_from_residual

CYCLE_S = 0.002
V_REST = 0.05  # [rad/s]
F_STATIC = 5.0  # [N m] the model's static band: +-F_STATIC below V_REST
#: the app's edges with the stuck bins (--stuck-velocity): held > 45 ms, held < 45 ms, moving
STUCK_EDGES = stuck_edges(DEFAULT_EDGES_S, "filtered", 20.0, 0.0)


class _Log(_RegimeLog):
    """What TorqueMonitor writes into a run log (``test_monitor_regime``'s, at 2 ms)."""

    start_ns, cycle_ns = 0, 2_000_000


def _static(payload):
    """The model: 0 while moving, the static band +-F_STATIC below the rest velocity."""
    def band(q, dq, ddq):
        return (([-F_STATIC], [F_STATIC]) if abs(dq[0]) < V_REST else ([0.0], [0.0]))
    return band


def _motion(seconds: float, seed: int, held_nm: float = 0.0, pushes=()
            ) -> tuple[np.ndarray, ...]:
    """One joint: 1 s at rest (measured dq exactly 0), 1 s moving (0.5 sin, one half wave),
    in turn. Measured torque: noise 0.1 N m; at rest a load the static friction holds,
    +-``held_nm`` (< F_STATIC, either side); at each start a 15 N m bump for 40 ms (what the
    model misses while the joint breaks away: it widens the first bin); plus ``pushes``
    (t0 [s], N m, duration [s])."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds / CYCLE_S)) * CYCLE_S
    phase = t % 2.0
    moving = phase >= 1.0
    dq = np.where(moving, 0.5 * np.sin(np.pi * (phase - 1.0)), 0.0)
    tau = rng.normal(0.0, 0.1, t.size)
    k = np.floor(t / 2.0).astype(int)
    tau += np.where(moving, 0.0, held_nm * np.where(k % 2, 1.0, -1.0))
    starts = np.flatnonzero(moving[1:] & ~moving[:-1]) + 1
    for i in starts:
        tau[i:i + 20] += 15.0
    for t0, nm, dt in pushes:
        tau[(t >= t0) & (t < t0 + dt)] += nm
    return t, dq, tau


def _run(mon: TorqueMonitor, t, dq, tau) -> _Log:
    return _regime_run(mon, t, dq, tau, _Log())


def _validation(stuck: bool, seed: int = 1) -> Thresholds:
    """Thresholds of a 100 s validation run (50 rests, 50 starts), with or without the
    stuck bin."""
    mon = TorqueMonitor(_static, ["a"], CYCLE_S, rest_velocity=[V_REST],
                        stuck_velocity=[0.0] if stuck else None)
    s = _run(mon, *_motion(100.0, seed, held_nm=4.0)).samples(0)
    armed = s["armed"].astype(bool)
    return thresholds_from_residual(
        s["residual"][armed, None], ["a"], 6.0, "synthetic", 1.5, s["moving_s"][armed, None],
        STUCK_EDGES if stuck else DEFAULT_EDGES_S, stuck_velocity=[0.0] if stuck else None)


def test_stuck_time_online_is_the_offline_rule():
    """The regime the monitor logs is minus the time the measured velocity has been 0
    while it is, else the moving time: :func:`moving_seconds` with the measured velocity."""
    t, dq, tau = _motion(8.0, 2)
    mon = TorqueMonitor(_static, ["a"], CYCLE_S, rest_velocity=[V_REST], stuck_velocity=[0.0])
    log, dqf = _run_velocity(mon, t, dq, tau, _Log())
    logged = log.samples(0)["moving_s"]
    np.testing.assert_allclose(
        logged, moving_seconds(dqf[:, None], [V_REST], CYCLE_S, dq[:, None],
                               [0.0])[:, 0], atol=1e-12)
    assert np.all((logged < 0) == (dq == 0.0))
    assert logged.min() == pytest.approx(-1.0, abs=2 * CYCLE_S)  # a whole rest
    # without a stuck velocity the regime is the moving time (>= 0), as before
    mon0 = TorqueMonitor(_static, ["a"], CYCLE_S, rest_velocity=[V_REST])
    assert _run(mon0, t, dq, tau).samples(0)["moving_s"].min() == 0.0


def test_held_push_at_rest_flagged_by_the_stuck_bin_not_by_the_first_bin():
    """A 3 N m push on a joint at rest holding 4 N m (static band 5 N m): its torque leaves
    the static band by 2 N m while the joint stays stuck. The stuck bin's band (no
    excursion at rest in the validation: the narrowest moving band, noise) flags it within
    the filter's delay; the first bin of the rule without it, widened by the 15 N m start
    bumps, does not. Neither alarms on another run without pushes (5 seeds)."""
    with_stuck, without = _validation(True), _validation(False)
    lo, hi = (np.array(x)[0] for x in with_stuck.bands())
    lo0, hi0 = (np.array(x)[0] for x in without.bands())
    assert with_stuck.bin_used[0][0] and with_stuck.bin_samples[0][0] > 20000
    assert hi[0] - lo[0] < 0.5 * (hi0[0] - lo0[0])  # the stuck band: narrower than bin 0's
    assert hi0[0] > 2.0  # the first bin holds the start bumps
    for seed in range(3, 8):
        t0 = 10.3 + 4.0 * (seed % 2)  # at rest (k = 5 or 7: held load +4 N m)
        pushes = [(t0, 3.0, 0.2)]
        for th, expect in ((with_stuck, True), (without, False)):
            vs = list(th.stuck_velocity) or None
            mon = TorqueMonitor(_static, ["a"], CYCLE_S, rest_velocity=[V_REST],
                                lower=th.bands()[0], upper=th.bands()[1], edges_s=th.edges_s,
                                stuck_velocity=vs)
            log = _run(mon, *_motion(16.0, seed, held_nm=4.0, pushes=pushes))
            hits = [c * CYCLE_S for c, kind, _ in log.events if kind == "collision"]
            inside = [h for h in hits if t0 <= h <= t0 + 0.2]
            assert bool(inside) is expect, (seed, hits)
            if expect:
                assert inside[0] - t0 < 0.03  # the filter's delay, a few cycles
            quiet = _run(TorqueMonitor(_static, ["a"], CYCLE_S, rest_velocity=[V_REST],
                                       lower=th.bands()[0], upper=th.bands()[1],
                                       edges_s=th.edges_s, stuck_velocity=vs),
                         *_motion(16.0, seed, held_nm=4.0))
            assert quiet.events == [], (seed, quiet.events)


def test_stuck_bin_file_round_trip_and_bad_inputs(tmp_path):
    """The thresholds file records the stuck velocity with the edges' leading 0 and reads
    it back (same bands); a stuck bin without its velocity, or a velocity without the bin,
    is refused in one line naming the key; so are stuck edges without a stuck velocity, and
    negative edges without 0 among them."""
    th = _validation(True)
    p = tmp_path / "t.json"
    p.write_text(json.dumps(th.to_json()))
    back = Thresholds.read(p)
    assert back.stuck_velocity == (0.0,) and back.edges_s == STUCK_EDGES == (
        -0.045, 0.0, *DEFAULT_EDGES_S)
    assert back.bands() == th.bands()
    assert back.constant().stuck_velocity == ()
    d = th.to_json()
    d["regime"]["stuck_velocity"] = None
    p.write_text(json.dumps(d))
    with pytest.raises(DataError, match="regime.stuck_velocity"):
        Thresholds.read(p)
    d = _validation(False).to_json()
    d["regime"]["stuck_velocity"] = [0.0]
    p.write_text(json.dumps(d))
    with pytest.raises(DataError, match="regime.stuck_velocity"):
        Thresholds.read(p)
    r = np.random.default_rng(0).normal(size=(500, 1))
    with pytest.raises(DataError, match="stuck_velocity"):
        thresholds_from_residual(r, ["a"], 6.0, "x", 1.5, np.zeros((500, 1)), STUCK_EDGES)
    with pytest.raises(DataError, match="regime edges"):
        thresholds_from_residual(r, ["a"], 6.0, "x", 1.5, np.zeros((500, 1)), (-0.1, 0.03),
                                 stuck_velocity=[0.0])
    with pytest.raises(ConfigError, match="stuck_velocity"):
        TorqueMonitor(_static, ["a", "b"], CYCLE_S, stuck_velocity=[0.0])
    # an old file (edges without 0) keeps its bands: stuck samples fall in its first bin
    old = _validation(False)
    assert dataclasses.replace(old).bands() == old.bands() and old.stuck_velocity == ()


def test_calibrate_with_stuck_velocity_on_the_bus(tmp_path, capfd):
    """``jointid monitor --calibrate --stuck-velocity 0`` on the simulated 3-dof arm (the
    simulator's own parameters as the model): the thresholds file has the stuck bins and
    velocity, the log's regime is negative exactly where a joint's measured velocity is 0,
    and a monitored run with that file checks them (no crossing without a push)."""
    from robot_campaigns import ARM3, arm3_raw, to_toml
    from test_monitor import truth_model

    from daq.app.cli import main
    from daq.protocol.reader import read_run
    from daq.runtime.monitor import read_monitor
    from sim_drivers.arm import ArmParams
    from trajectories.robot import load_robot

    robot = load_robot(ARM3)
    em = truth_model(robot, ArmParams.from_robot(robot))
    model = tmp_path / "model"
    model.mkdir()
    (model / "arm3.urdf").write_text(em.urdf)
    (model / "friction.json").write_text(json.dumps(em.friction))
    raw = arm3_raw(cycle_s=0.002, buses=tuple(f"stuck-{i}-{tmp_path.name}" for i in range(3)),
                   payloads=[{"mass_kg": 0.0}],
                   segments=[{"kind": "multisine", "period_s": 4.0, "periods": 1,
                              "harmonics": 4, "fill": 0.6, "seed": 1}])
    camp = tmp_path / "c.toml"
    camp.write_text(to_toml(raw))
    cal = tmp_path / "cal"
    assert main(["monitor", str(model), str(camp), "--simulate", "--calibrate",
                 "--stuck-velocity", "0", "-o", str(cal)]) == 0
    th = json.loads((cal / "thresholds.json").read_text())
    assert th["regime"]["edges_s"] == list(STUCK_EDGES)
    assert th["regime"]["stuck_velocity"] == [0.0, 0.0, 0.0]
    (log,) = sorted((cal / "logs").glob("*.mcap"))
    ml = read_monitor(log)
    for j in range(3):
        a = read_run(log, axis=j)
        dq = a.dq[np.searchsorted(a.cycle, ml.cycle)]
        assert np.array_equal(ml.moving_s[:, j] < 0, dq == 0.0), j
    assert (ml.moving_s < 0).any()
    capfd.readouterr()
    out = tmp_path / "run"
    assert main(["monitor", str(model), str(camp), "--simulate", "--thresholds",
                 str(cal / "thresholds.json"), "-o", str(out)]) == 0
    s = json.loads((out / "monitor.json").read_text())
    assert s["stuck_velocity"] == [0.0, 0.0, 0.0]
    assert all(not r["false_alarms"] for r in s["runs"]), s["runs"]
