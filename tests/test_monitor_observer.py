"""The generalized-momentum observer residual of ``jointid monitor`` (docs/monitoring.md,
issue 25): its per-cycle update on a synthetic trajectory of the exported model, the friction's
inverse, and on the simulated arm's buses (calibration, a push detected, a thresholds file of
the other residual refused)."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
from robot_campaigns import ARM3
from test_monitor import _campaign, _model_dir, truth_model

from daq import ConfigError
from daq.app.cli import main
from daq.runtime.monitor import MomentumObserver, ObserverResidual, TorqueMonitor, read_monitor
from ident import DataError
from ident.monitor import Thresholds, thresholds_from_residual
from ident.robot.export_model import exported_torque
from sim_drivers.arm import ArmParams
from trajectories.robot import load_robot

CYCLE_S = 0.001
GAIN = 50.0  # [1/s]


@pytest.fixture(scope="module")
def arm3():
    robot = load_robot(ARM3)
    return robot, ArmParams.from_robot(robot)


def _trajectory(seconds: float) -> tuple[np.ndarray, ...]:
    """q, dq, ddq (n, 3) of a motion whose velocities keep their sign (no reversal):
    q = q0 + v0 t + a sin(w t + phi), v0 > a w."""
    t = np.arange(int(round(seconds / CYCLE_S)))[:, None] * CYCLE_S
    q0, v0 = np.array([0.1, -1.5, 0.8]), np.array([0.6, -0.5, 0.7])
    a, w, ph = np.array([0.2, 0.15, 0.25]), np.array([2.0, 2.5, 1.8]), np.array([0, 1, 2])
    q = q0 + v0 * t + a * np.sin(w * t + ph)
    dq = v0 + a * w * np.cos(w * t + ph)
    ddq = -a * w * w * np.sin(w * t + ph)
    assert np.all(np.abs(dq) > 0.1)
    return q, dq, ddq


def _measured(em, q, dq, ddq, tau_ext) -> np.ndarray:
    """Drive torques (n, 3) [N m] of the exported model's friction when the links also get
    ``tau_ext`` [N m]: the drives deliver tau_out = M ddq + C dq + g - tau_ext."""
    model = pin.buildModelFromXML(em.urdf)
    model.gravity = pin.Motion(np.r_[em.friction["gravity"], 0, 0, 0])
    data = model.createData()
    tr = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    return exported_torque(em.friction, tr - tau_ext, dq, ddq)


@pytest.mark.parametrize("ext", [[0.0, 0.0, 0.0], [4.0, -6.0, 2.5]])
def test_observer_converges_to_the_external_torque(arm3, ext):
    """Exact friction, a constant external torque: after 5 / K_O the observer's r is the
    external torque within 1 % (and ~0 without one), the residual its negative; it would not
    be with a wrong sign of C^T dq or g or without the rotor inertia in M (the exported
    model's J = Ia + ZZ), whose share here is far above 1 %."""
    em = truth_model(*arm3)
    pr = em.predictor(None)
    q, dq, ddq = _trajectory(0.6)
    tau = _measured(em, q, dq, ddq, np.array(ext))
    res = ObserverResidual(lambda a, b, c: pr.observer_terms(a, b, c, 0.01), 3, CYCLE_S, GAIN)
    r = []
    for a, b, c in zip(q, dq, tau, strict=True):
        out = res.step(a, b, c)
        r.append(res.observer.r)
        assert out[0] == [-x for x in res.observer.r]  # moving: no static-friction interval
    after = np.array(r)[int(5 / GAIN / CYCLE_S):]
    assert np.abs(after - ext).max() <= 0.01 * max(np.abs(ext).max(), 1.0)
    # what the checks above rely on: rotor inertia, C^T dq and g are not small here
    ia = np.array([j["rotor_inertia"] for j in em.friction["joints"]])
    m, ctdq, g = pr.momentum_terms(q[300], dq[300])
    assert np.all(np.abs(ia * ddq[300]) > 0.05) and np.abs(g).max() > 5.0
    assert np.abs(ctdq).max() > 0.05 and np.allclose(m, m.T)


def test_load_interval_inverts_the_friction_and_holds_the_rest_band(arm3):
    """Moving: the friction's inverse gives back the load of the exported torque (either
    quadrant). Below the rest velocity: an interval holding the load whatever the sign of
    dq, at least the dry friction wide."""
    em = truth_model(*arm3)
    pr = em.predictor(None)
    rng = np.random.default_rng(3)
    for _ in range(20):
        q, dq, ddq = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3), rng.uniform(-3, 3, 3)
        tau = pr(q, dq, ddq)
        lo, hi = pr.load_interval(dq, tau, 0.0)
        want = np.array(pr._rigid(q, dq, ddq))  # tau_out = RNEA + Ia ddq
        np.testing.assert_allclose(lo, want, atol=1e-9)
        np.testing.assert_allclose(hi, want, atol=1e-9)
        for s in (1e-6, -1e-6):  # just either side of rest: inside the interval
            tau = pr(q, np.full(3, s), ddq)
            lo, hi = pr.load_interval(np.zeros(3), tau, 0.05)
            t_out = np.array(pr._rigid(q, np.full(3, s), ddq))
            assert np.all(np.array(lo) - 1e-6 <= t_out) and np.all(t_out <= np.array(hi) + 1e-6)
            assert np.all(np.array(hi) - np.array(lo) > 0.1)


def test_observer_residual_is_zero_while_the_static_friction_explains_it():
    """A beta known only within +-w: r's error bound w follows the low-pass of w, and the
    residual is 0 while |r| <= w; a bad gain is one ConfigError."""
    obs = MomentumObserver(GAIN, CYCLE_S, 1)
    res = ObserverResidual(lambda q, dq, tau: ([0.0], [tau[0]], [2.0]), 1, CYCLE_S, GAIN)
    res.observer = obs
    out = [res.step([0.0], [0.0], [1.5])[0][0] for _ in range(400)]
    assert obs.r[0] == pytest.approx(-1.5, rel=1e-3) and obs.w[0] == pytest.approx(2.0)
    assert out[-1] == 0.0  # |r| < w: the static friction could explain it
    for gain in (0.0, -1.0, 1000.0):
        with pytest.raises(ConfigError, match="observer gain"):
            TorqueMonitor(lambda p: None, ["a"], CYCLE_S, residual="observer",
                          observer_gain=gain)
    with pytest.raises(ConfigError, match="residual"):
        TorqueMonitor(lambda p: None, ["a"], CYCLE_S, residual="momentum")


# --------------------------------------------------------------------------- on the bus
def test_observer_calibrate_detect_and_the_other_kind_refused(tmp_path, arm3, capfd):
    """``--residual observer`` on the simulated arm's buses: the validation run's thresholds
    record the residual and its gain; a 40 N push on the upper arm is detected within 50 ms
    and logged; a thresholds file of the other residual is refused in one line naming it,
    and so is a bad gain, before anything is written."""
    model = _model_dir(tmp_path, arm3)
    camp = _campaign(tmp_path, "obs")
    cal = tmp_path / "cal"
    assert main(["monitor", str(model), str(camp), "--simulate", "--calibrate",
                 "--residual", "observer", "-o", str(cal)]) == 0
    th_path = cal / "thresholds.json"
    th = json.loads(th_path.read_text())
    assert th["residual"] == "observer" and th["observer_gain_per_s"] == 50.0
    assert Thresholds.read(th_path).residual == "observer"
    capfd.readouterr()
    out = tmp_path / "push"
    assert main(["monitor", str(model), str(camp), "--simulate", "--thresholds", str(th_path),
                 "--residual", "observer", "--push", "j2:40:2.0:0.2", "-o", str(out)]) == 0
    capfd.readouterr()
    s = json.loads((out / "monitor.json").read_text())
    (run,) = s["runs"]
    (p,) = run["pushes"]
    assert s["residual"] == "observer" and p["detected"] and p["delay_s"] <= 0.05, p
    assert all(f["cycle"] > p["cycle"] for f in run["false_alarms"])  # none before the push
    ml = read_monitor(out / s["logs"][0])
    assert ml.metadata["residual"] == "observer"
    filtered = tmp_path / "filtered.json"
    filtered.write_text(json.dumps(Thresholds(("j1", "j2", "j3"), 6.0, (0,) * 3, (1,) * 3,
                                              (3,) * 3, 200).to_json()))
    cases = [(["--thresholds", str(th_path)], f"{th_path}: calibrated with the observer"),
             (["--thresholds", str(filtered), "--residual", "observer"],
              f"{filtered}: calibrated with the filtered"),
             (["--calibrate", "--residual", "observer", "--observer-gain", "0"],
              "--observer-gain"),
             (["--calibrate", "--residual", "observer", "--observer-gain", "600"],
              "--observer-gain"),
             (["--calibrate", "--observer-gain", "20"], "--residual observer"),
             (["--thresholds", str(th_path), "--residual", "observer", "--observer-gain",
               "20"], "observer gain 50")]
    for argv, what in cases:
        never = tmp_path / "never"
        code = main(["monitor", str(model), str(camp), "--simulate", *argv, "-o", str(never)])
        err = capfd.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and what in err, (argv, err)
        assert not never.exists()


def test_thresholds_file_records_its_residual(tmp_path):
    """The residual and the observer's gain round-trip through the file; a /2 file without
    the key is filtered; an unknown residual or an observer file without its gain is one
    DataError naming the file."""
    rng = np.random.default_rng(4)
    th = thresholds_from_residual(rng.normal(size=(500, 2)), ["a", "b"], 6.0, kind="observer",
                                  observer_gain=40.0)
    p = tmp_path / "th.json"
    p.write_text(json.dumps(th.to_json()))
    back = Thresholds.read(p)
    assert (back.residual, back.observer_gain) == ("observer", 40.0)
    d = th.to_json()
    for key, value, what in (("residual", None, "filtered"), ("residual", "momentum", None),
                             ("observer_gain_per_s", None, None)):
        bad = {k: v for k, v in d.items() if k != key}
        if value is not None:
            bad[key] = value
        p.write_text(json.dumps(bad))
        if what:
            assert Thresholds.read(p).residual == what
        else:
            with pytest.raises(DataError, match=f"{p.name}.*{key}"):
                Thresholds.read(p)
    with pytest.raises(DataError, match="residual"):
        thresholds_from_residual(rng.normal(size=(500, 2)), ["a", "b"], 6.0, kind="observer")
