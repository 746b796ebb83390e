"""Torque monitoring (docs/monitoring.md): the push on the simulated arm, the predictor of an
exported model, the thresholds, the residual filter, and ``jointid monitor`` on the simulated
buses (calibration, a push detected and logged, the stop, bad inputs)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from mcap.reader import make_reader
from robot_campaigns import ARM3, arm3_raw, to_toml, write_arm_csv

from daq.app.cli import main
from daq.runtime.monitor import SVFilter, TorqueMonitor, read_monitor
from ident import DataError
from ident.monitor import ExportedModel, Thresholds, load_model, thresholds_from_residual
from ident.robot.export_model import exported_torque, friction_record, urdf_text
from sim_drivers.arm import (
    ArmGains,
    ArmParams,
    ArmPlant,
    Payload,
    Push,
    model_reference,
    push_torque,
    simulate_arm,
    staged_push,
)
from sim_drivers.arm_push import DEFAULT_OFFSET_M
from trajectories.robot import load_robot

JOINT_CAMPAIGN = Path(__file__).resolve().parents[1] / "examples" / "campaign.toml"


@pytest.fixture(scope="module")
def arm3():
    robot = load_robot(ARM3)
    return robot, ArmParams.from_robot(robot)


def truth_model(robot, params) -> ExportedModel:
    """The simulator's own parameters as an exported paper model (the best a fit can do)."""
    tr = params.truth()
    k = len(robot.moving)
    text = urdf_text(robot.reduced(), tr, robot.numbers, "arm3")
    fr = friction_record("paper", tuple(robot.moving), robot.numbers, tr, tr,
                         [tr[f"qs{n}"] for n in robot.numbers], robot.gravity)
    assert len(fr["joints"]) == k
    return ExportedModel(text, fr, "truth")


# --------------------------------------------------------------------------- the push
def test_push_torque_is_the_virtual_work_of_the_force(arm3):
    """J^T F of a push equals F . dp/dq by finite differences of the point's position."""
    _, params = arm3
    model = params.dynamics_model(None)
    data = model.createData()
    rng = np.random.default_rng(1)
    for j in range(3):
        q = rng.uniform(-1, 1, 3)
        p = Push(j, tuple(rng.normal(size=3) * 10), tuple(rng.normal(size=3) * 0.2), 0, 1)
        tau = push_torque(model, data, q, p)

        def pos(qq, j=j, p=p):
            pin.forwardKinematics(model, data, qq)
            return data.oMi[j + 1].act(np.asarray(p.point))

        num = [np.asarray(p.force) @ (pos(q + h) - pos(q - h)) / 2e-6
               for h in np.eye(3) * 1e-6]
        np.testing.assert_allclose(tau, num, rtol=1e-6, atol=1e-8)
        assert np.all(tau[j + 1:] == 0.0)  # joints beyond the link feel nothing


def test_push_accelerates_the_arm_by_minv_jt_f_during_its_window(arm3):
    """Two plants, same noise: with a push the acceleration differs by M^-1 J^T F (sliding
    joints) over its window, and not before it."""
    _, params = arm3
    plants = [ArmPlant(params, 0.001, seed=3) for _ in range(2)]
    for pl in plants:
        pl.reset([0.2, -1.2, 1.2])
        pl.dq = np.array([0.3, -0.4, 0.5])
    push = staged_push(plants[1].model, plants[1].q, 1, 50.0, 0.0015, 0.003)
    assert np.linalg.norm(push.force) == pytest.approx(50.0)
    cmd = [5.0, 60.0, 20.0]
    diffs = []
    plants[1].pushes.append(push)
    n_active = 0
    for _ in range(6):
        t_start = plants[1].t
        for pl in plants:
            pl.step(cmd)
        diffs.append((t_start, plants[1].ddq_start - plants[0].ddq_start,
                      plants[1].tau_ext.copy()))
        n_active += push.active(t_start)
        for pl in plants[1:]:  # same state: the difference is this cycle's push alone
            pl.q, pl.dq = plants[0].q.copy(), plants[0].dq.copy()
    assert n_active == 3  # cycles starting at 2, 3, 4 ms
    for t0, d, ext in diffs:
        if push.active(t0):
            minv = pin.computeMinverse(plants[0].model, plants[0].model.createData(),
                                       plants[0].q_start)
            minv = np.triu(minv) + np.triu(minv, 1).T
            assert np.linalg.norm(ext) > 1.0
            np.testing.assert_allclose(d, minv @ ext, rtol=0.05, atol=1e-3)
        else:
            assert np.all(ext == 0.0) and np.allclose(d, 0.0)
    assert plants[1].pushes == []  # dropped once over


@pytest.mark.parametrize("axis", ["x", "y", "z", "unaligned"])
def test_default_push_point_is_off_the_joint_axis_whatever_its_axis(axis):
    """One link whose centre of mass is on its joint's axis: the default push point is
    DEFAULT_OFFSET_M off that axis and the tangential push makes F * DEFAULT_OFFSET_M about
    it, for a joint turning about its frame's x, y, z or another axis (an offset along x
    alone would put the point on an x axis: no torque)."""
    jm = {"x": pin.JointModelRX(), "y": pin.JointModelRY(), "z": pin.JointModelRZ(),
          "unaligned": pin.JointModelRevoluteUnaligned(np.array([1.0, 1.0, 0.0])
                                                       / np.sqrt(2.0))}[axis]
    a = {"x": [1, 0, 0], "y": [0, 1, 0], "z": [0, 0, 1],
         "unaligned": [2 ** -0.5, 2 ** -0.5, 0]}[axis]
    model = pin.Model()
    jid = model.addJoint(0, jm, pin.SE3.Identity(), "j1")
    com = 0.3 * np.asarray(a, float)  # on the axis
    model.appendBodyToJoint(jid, pin.Inertia(2.0, com, np.eye(3) * 0.01), pin.SE3.Identity())
    push = staged_push(model, [0.4], 0, 20.0, 0.0, 0.2)
    r = np.asarray(push.point) - com
    assert np.linalg.norm(r) == pytest.approx(DEFAULT_OFFSET_M)
    assert abs(r @ a) < 1e-12  # perpendicular to the axis
    tau = push_torque(model, model.createData(), [0.4], push)
    assert abs(tau[0]) == pytest.approx(20.0 * DEFAULT_OFFSET_M, rel=1e-9)
    if axis in ("y", "z"):  # the frame's x axis is perpendicular: the documented point
        np.testing.assert_allclose(push.point, com + [DEFAULT_OFFSET_M, 0, 0])


# --------------------------------------------------------------------------- predictor
def test_predictor_is_exported_torque_and_band_holds_the_static_friction(arm3):
    robot, params = arm3
    em = truth_model(robot, params)
    pr = em.predictor(None)
    assert pr.q_s == [j["q_s"] for j in em.friction["joints"]] and min(pr.q_s) > 0
    rng = np.random.default_rng(2)
    q, dq, ddq = (rng.uniform(-1, 1, (50, 3)) for _ in range(3))
    model = pin.buildModelFromXML(em.urdf)
    model.gravity = pin.Motion(np.r_[em.friction["gravity"], 0, 0, 0])
    data = model.createData()
    tr = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    want = exported_torque(em.friction, tr, dq, ddq)
    got = np.array([pr(a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)
    lo, hi = pr.band(q[0], dq[0], ddq[0], v_rest=0.01)  # all moving: the prediction
    np.testing.assert_allclose(lo, got[0]) and np.testing.assert_allclose(hi, got[0])
    v = np.array([0.001, -0.002, 0.0])
    lo, hi = pr.band(q[0], v, ddq[0], v_rest=0.01)
    for s in (1e-9, -1e-9):  # the model just either side of rest is in the band
        x = pr(q[0], np.full(3, s), ddq[0])
        assert np.all(np.array(lo) - 0.05 <= x) and np.all(x <= np.array(hi) + 0.05)
    d_static = np.array([params.friction.c_m + params.friction.d_m]).ravel()
    assert np.all(np.array(hi) - np.array(lo) > d_static)  # at least the dry friction
    # the payload enters the rigid-body torque
    pay = type("P", (), {"mass_kg": 5.0, "com": [0.1, 0, 0], "inertia": [0.01] * 3 + [0] * 3})
    assert not np.allclose(em.predictor(pay)(q[0], dq[0], ddq[0]), got[0])


def test_rest_band_holds_the_models_own_friction_below_the_rest_velocity(arm3):
    """Below v_rest the band holds the model's prediction at every speed below v_rest, also
    for an identified model whose Stribeck terms are negative (static friction below the
    Coulomb level, as a fit may give); for physical terms it is the stiction band (E = 1)."""
    robot, params = arm3
    em = truth_model(robot, params)
    fr = json.loads(json.dumps(em.friction))
    for key in ("d_m", "d_g"):  # c + d < 0 on joint 1: breakaway below Coulomb
        fr["joints"][0][key] = -2.0 * fr["joints"][0]["c_m"]
    fr["joints"][0]["b_m"] = -0.2
    odd = ExportedModel(em.urdf, fr, "negative Stribeck terms")
    rng = np.random.default_rng(5)
    for model in (em, odd):
        pr = model.predictor(None)
        v_rest = [3.0 * x for x in pr.q_s]
        for _ in range(40):
            q, ddq = rng.uniform(-1, 1, 3), rng.uniform(-2, 2, 3)
            dq = rng.uniform(0.3, 1.0, 3) * np.array(v_rest) * rng.choice([-1, 1], 3)
            lo, hi = pr.band(q, dq, ddq, v_rest)
            x = pr(q, dq, ddq)
            assert np.all(np.array(lo) - 1e-9 <= x) and np.all(x <= np.array(hi) + 1e-9)
            if model is em:  # physical terms: the E = 1 range of either sign
                t_out = pr._rigid(q, dq, ddq)
                for j in range(3):
                    e1 = [pr._friction(j, t_out[j], dq[j], s, 1.0) for s in (1.0, -1.0)]
                    assert (lo[j], hi[j]) == pytest.approx((min(e1), max(e1)), abs=1e-9)


# --------------------------------------------------------------------------- thresholds
def test_thresholds_statistics_file_and_bad_files(tmp_path):
    rng = np.random.default_rng(0)
    r = rng.normal([0.5, -1.0], [0.1, 2.0], (5000, 2))
    r[:1000, 0] = 0.0  # inside the static band: left out of the statistics
    th = thresholds_from_residual(r, ["a", "b"], 5.0, "x", peak_margin=0.0)
    assert th.mean[0] == pytest.approx(0.5, abs=0.01)
    assert th.sigma[1] == pytest.approx(2.0, rel=0.05)
    assert th.upper[1] - th.lower[1] == pytest.approx(10 * th.sigma[1])  # 2 x 5 sigma
    wide = th.with_k(peak_margin=2.0)
    assert wide.half_width[0] == pytest.approx(2.0 * th.peak[0] * th.sigma[0])
    p = tmp_path / "th.json"
    p.write_text(json.dumps(wide.to_json()))
    assert Thresholds.read(p) == wide
    bad = tmp_path / "bad.json"
    for text, what in (("{", "not JSON"), ('{"format": "x"}', "format"),
                       (json.dumps({**wide.to_json(), "sigma": [1.0]}), "sigma")):
        bad.write_text(text)
        with pytest.raises(DataError, match=what) as e:
            Thresholds.read(bad)
        assert len(str(e.value).splitlines()) == 1 and str(bad) in str(e.value)
    with pytest.raises(DataError, match="at least 100"):
        thresholds_from_residual(r[:50], ["a", "b"], 5.0)


def test_svfilter_follows_a_ramp_and_its_slope():
    """Unit DC gain, and the derivative state of a ramp input is its slope."""
    f = SVFilter(20.0, 0.001, 2)
    f.reset([0.0, 1.0])
    for i in range(1, 2000):
        f.update([0.003 * i, 1.0])
    assert f.dy[0] == pytest.approx(3.0, rel=1e-2)  # (input held over each cycle)
    assert f.y[1] == pytest.approx(1.0)
    with pytest.raises(Exception, match="cutoff"):
        SVFilter(600.0, 0.001, 1)


# --------------------------------------------------------------------------- on the bus
def _campaign(tmp_path: Path, tag: str) -> Path:
    raw = arm3_raw(cycle_s=0.002, buses=tuple(f"mon-{tag}-{i}-{tmp_path.name}"
                                              for i in range(3)),
                   payloads=[{"mass_kg": 0.0}],
                   segments=[{"kind": "multisine", "period_s": 4.0, "periods": 1,
                              "harmonics": 4, "fill": 0.6, "seed": 1}])
    p = tmp_path / f"c_{tag}.toml"
    p.write_text(to_toml(raw))
    return p


def _model_dir(tmp_path: Path, arm3) -> Path:
    em = truth_model(*arm3)
    d = tmp_path / "model"
    d.mkdir(exist_ok=True)
    (d / "arm3.urdf").write_text(em.urdf)
    (d / "friction.json").write_text(json.dumps(em.friction))
    return d


def test_monitor_calibrate_then_detect_a_push_on_the_bus(tmp_path, arm3, capfd):
    """A validation run gives thresholds; the same motion with a 40 N push on the upper arm
    is detected within 50 ms, as a collision event of the run log (reference MCAP reader)
    after the push event; the residual channels are in the log; no crossing before the push;
    with --stop the run stops and the drives are disabled."""
    model = _model_dir(tmp_path, arm3)
    camp = _campaign(tmp_path, "a")
    cal = tmp_path / "cal"
    assert main(["monitor", str(model), str(camp), "--simulate", "--calibrate",
                 "-o", str(cal)]) == 0
    th = json.loads((cal / "thresholds.json").read_text())
    assert th["joints"] == ["j1", "j2", "j3"] and all(s > 0 for s in th["sigma"])
    capfd.readouterr()
    out = tmp_path / "push"
    assert main(["monitor", str(model), str(camp), "--simulate", "--thresholds",
                 str(cal / "thresholds.json"), "--push", "j2:40:2.0:0.2",
                 "-o", str(out)]) == 0
    text = capfd.readouterr().out
    assert "push 40 N on j2" in text and "detected after" in text, text
    s = json.loads((out / "monitor.json").read_text())
    (run,) = s["runs"]
    (p,) = run["pushes"]
    assert p["detected"] and p["delay_s"] <= 0.05
    assert all(f["cycle"] > p["cycle"] for f in run["false_alarms"])  # none before the push
    log = out / s["logs"][0]
    with open(log, "rb") as f:
        reader = make_reader(f)
        topics = {c.topic for c in reader.get_summary().channels.values()}
        events = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=["/events"])]
    assert {"/monitor/0/residual", "/monitor/2/residual"} <= topics
    kinds = [e["kind"] for e in events]
    assert kinds.index("push") < kinds.index("collision")
    ml = read_monitor(log)
    assert ml.residual.shape[1] == 3 and ml.armed.any()
    # the band of each cycle is the thresholds' at the logged moving time (regime bins)
    reg = th["regime"]
    assert reg["edges_s"] and np.all(np.diff(ml.moving_s[:, 0])[ml.moving_s[1:, 0] > 0]
                                      == pytest.approx(0.002))
    b = np.searchsorted(reg["edges_s"], ml.moving_s, side="right")
    want = np.array(reg["upper"])[np.arange(3)[None, :], b]
    assert np.allclose(ml.upper, want)
    assert (out / "report.html").is_file() and (out / "residual_0_j2.png").is_file()
    j2 = s["per_joint"][1]
    assert j2["joint"] == "j2" and (j2["pushes"], j2["detected"]) == (1, 1)
    assert all(0 < d["worst_fraction_of_band"] for d in s["per_joint"])
    assert "Per joint" in (out / "report.html").read_text()
    # --stop: the crossing stops the run through the stop sequence
    stop = tmp_path / "stop"
    main(["monitor", str(model), str(camp), "--simulate", "--thresholds",
          str(cal / "thresholds.json"), "--push", "j2:40:2.0:0.2", "--stop", "-o", str(stop)])
    s = json.loads((stop / "monitor.json").read_text())
    assert s["status"] == "stopped" and "residual" in s["reason"], s["reason"]
    with open(stop / s["logs"][0], "rb") as f:
        reader = make_reader(f)
        result = next(m for m in reader.iter_metadata() if m.name == "result").metadata
    assert int(result["stop_cycle"]) >= int(result["fault_cycle"]) >= 0


def test_monitor_bad_inputs_one_line(tmp_path, arm3, capfd):
    model = _model_dir(tmp_path, arm3)
    camp = _campaign(tmp_path, "b")
    th = tmp_path / "th.json"
    th.write_text(json.dumps(Thresholds(("a", "b"), 5.0, (0, 0), (1, 1), (3, 3), 200
                                        ).to_json()))
    cases = [
        (["monitor", str(tmp_path / "nothing"), str(camp), "--simulate", "--calibrate"],
         "nothing"),
        (["monitor", str(model), str(camp), "--simulate", "--calibrate", "--push", "j2:x:1"],
         "--push"),
        (["monitor", str(model), str(camp), "--simulate", "--calibrate", "--push", "j9:20:1"],
         "j9"),
        (["monitor", str(model), str(camp), "--thresholds", str(th), "--push", "j2:20:1"],
         "--simulate"),
        (["monitor", str(model), str(camp), "--simulate", "--thresholds", str(th)],
         "joints"),
        (["monitor", str(model), str(ARM3), "--simulate", "--calibrate"], "arm3.toml"),
        (["monitor", str(model), str(JOINT_CAMPAIGN), "--simulate", "--calibrate"],
         "single-joint [joint] campaign"),
        (["monitor", str(model), str(camp), "--simulate", "--calibrate", "--regime-edges",
          "0.1,0.05"], "--regime-edges"),
        (["monitor", str(model), str(camp), "--simulate", "--thresholds", str(th),
          "--regime-edges", "0.1"], "--calibrate"),
        (["monitor", str(model), str(camp), "--simulate", "--thresholds", str(th),
          "--stuck-velocity", "0"], "--stuck-velocity"),
        (["monitor", str(model), str(camp), "--simulate", "--calibrate",
          "--stuck-velocity", "-1"], "--stuck-velocity"),
    ]
    for argv, what in cases:
        out = tmp_path / "never"
        code = main([*argv, "-o", str(out)])
        err = capfd.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and what in err, (argv, err)
        assert not out.exists()


def test_model_from_a_fit_record_is_its_export(tmp_path, arm3, capfd):
    """MODEL given as a fit record (with its consistent block) predicts what its
    export-model folder predicts: same URDF text and friction file."""
    robot, params = arm3
    ref = model_reference(params.model, center=[0.0, -1.2, 1.2], fraction=0.9,
                          duration_s=4.0, seed=1)
    files = []
    for i, pay in enumerate((None, Payload(5.0, [0.0, 0.0, 0.05]))):
        run = simulate_arm(params, ref, ArmGains.for_params(params, payload=pay),
                           payload=pay, seed=10 + i)
        files.append(write_arm_csv(run, tmp_path / f"p{i}.csv"))
    fit = tmp_path / "fit.json"
    assert main(["fit", "--robot", str(ARM3), *map(str, files), "--model", "paper",
                 "--json", str(fit), "--no-consistency", "--consistent"]) == 0
    assert main(["export-model", str(fit), "-o", str(tmp_path / "model")]) == 0
    capfd.readouterr()
    a = load_model(fit, robot)
    b = load_model(tmp_path / "model", None)
    assert a.urdf == b.urdf and a.friction == b.friction
    with pytest.raises(DataError, match="robot"):
        load_model(fit, None)


@pytest.mark.slow
def test_no_false_alarm_without_push_under_another_payload(tmp_path, arm3, capfd):
    """Thresholds from a validation run without payload; the same motion with the 5 kg
    payload (the model gets it) and no push: no crossing (the long figure, 11 min:
    benchmarks/bench_monitor.py)."""
    model = _model_dir(tmp_path, arm3)
    raw = arm3_raw(cycle_s=0.002, buses=tuple(f"mon-fa-{i}-{tmp_path.name}" for i in range(3)),
                   segments=[{"kind": "multisine", "period_s": 4.0, "periods": 3,
                              "harmonics": 4, "fill": 0.6, "seed": 2}])
    camp = tmp_path / "c.toml"
    camp.write_text(to_toml(raw))
    cal = tmp_path / "cal"
    assert main(["monitor", str(model), str(camp), "--simulate", "--calibrate", "--payload",
                 "0", "-o", str(cal)]) == 0
    out = tmp_path / "run"
    assert main(["monitor", str(model), str(camp), "--simulate", "--thresholds",
                 str(cal / "thresholds.json"), "--payload", "1", "-o", str(out)]) == 0
    capfd.readouterr()
    (run,) = json.loads((out / "monitor.json").read_text())["runs"]
    assert run["payload"] == 1 and run["armed_s"] > 11.0
    assert run["false_alarms"] == []


class _Log:
    start_ns, cycle_ns = 0, 1_000_000

    def __init__(self) -> None:
        self.events = []

    def event(self, cycle, t, kind, message, axis=-1) -> None:
        self.events.append((cycle, kind, axis))


def test_monitor_counts_crossings_once_armed_and_not_on_stale_data():
    """A torque step of 5 N m against a model predicting 0 (band +-1): one collision event
    per excursion, after the warm-up; a cycle with a missing TPDO disarms the check for
    another warm-up; with stop, the first crossing is the returned reason."""
    zero = lambda q, dq, ddq: ([0.0, 0.0], [0.0, 0.0])  # noqa: E731
    mon = TorqueMonitor(lambda p: zero, ["a", "b"], 0.001, lower=[-1, -1], upper=[1, 1],
                        warmup_s=0.05, stop=True)
    log = _Log()
    mon.begin(0, None, log)
    tau = lambda c: [5.0 if 20 <= c < 300 or c >= 400 else 0.0, 0.0]  # noqa: E731
    reasons = []
    for c in range(600):
        why, axis = mon.step(c, c * 0.001, [0, 0], [0, 0], tau(c), log, valid=c != 380)
        if why:
            reasons.append((c, axis))
    cyc = [c for c, kind, axis in log.events if kind == "collision"]
    assert all(axis == 0 for _, _, axis in log.events)
    assert len(cyc) == 2 and 50 <= cyc[0] < 60  # armed at 50: the filter is there by then
    assert 380 + 50 <= cyc[1] < 440  # step at 400 while disarmed until 430
    assert reasons == [(cyc[0], 0), (cyc[1], 0)]
