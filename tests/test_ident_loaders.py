"""Loading experiments: CSV, MAT (with a column mapping and a drive gain), MCAP logs of
``jointid run`` (written with the daq writer, read back with the mcap library), and the
errors users see for bad files."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.io

from ident import DataError
from ident.loaders import (
    Experiment,
    ResamplingWarning,
    concat,
    load_experiment,
    load_experiments,
    parse_mapping,
    read_file,
)
from ident.robot import RobotIdentError
from ident.robot.loaders import load_robot_runs


def _arrays(n=500, dt=1e-3):
    t = np.arange(n) * dt
    q = 0.5 * np.sin(2.0 * t)
    tau = 10 * np.cos(2.0 * t) + 3
    return t, q, tau


def _write_csv(path, header, cols):
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(header), comments="")


def test_csv_canonical_columns_with_payload(tmp_path):
    t, q, tau = _arrays()
    p = tmp_path / "run.csv"
    _write_csv(p, ["t", "q", "tau", "payload_kg", "payload_arm_m"],
               [t, q, tau, np.full_like(t, 3.4584), np.full_like(t, 1.277)])  # fmt: skip
    e = load_experiment(p)
    np.testing.assert_allclose(e.q, q)
    np.testing.assert_allclose(e.tau, tau)
    assert e.payload_mass == 3.4584 and e.payload_arm == 1.277 and e.revolute
    assert e.dt == pytest.approx(1e-3)


def test_csv_mapping_and_numeric_gain(tmp_path):
    t, q, tau = _arrays()
    p = tmp_path / "foreign.csv"
    _write_csv(p, ["time", "pos", "cur"], [t + 5.0, q, tau / 2.0])
    e = load_experiment(p, mapping=parse_mapping("t=time,q=pos,tau=cur,payload_kg=2.5"),
                        gain=2.0, joint="prismatic")  # fmt: skip
    np.testing.assert_allclose(e.tau, tau)
    np.testing.assert_allclose(e.t, t, atol=1e-12)  # time restarts at 0
    assert e.payload_mass == 2.5 and not e.revolute


def test_mat_with_variable_gain(tmp_path):
    t, q, tau = _arrays()
    p = tmp_path / "data.mat"
    scipy.io.savemat(p, {"t": t[:, None], "qm": q[:, None], "vir": (tau / 35.15)[:, None],
                         "gtau": np.array([[35.15]])})  # fmt: skip
    e = load_experiment(p, mapping={"q": "qm", "tau": "vir"}, gain="gtau")
    np.testing.assert_allclose(e.tau, tau)
    with pytest.raises(DataError, match="gain variable 'nope'"):
        load_experiment(p, mapping={"q": "qm", "tau": "vir"}, gain="nope")


def test_missing_column_names_file_and_alternatives(tmp_path):
    t, q, tau = _arrays()
    p = tmp_path / "x.csv"
    _write_csv(p, ["t", "q", "torque"], [t, q, tau])
    with pytest.raises(DataError, match=r"x\.csv: missing column/variable 'tau'.*torque"):
        load_experiment(p)


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda t, q, tau: (t[::-1].copy(), q, tau), "not strictly increasing"),
        (lambda t, q, tau: (t, np.where(np.arange(q.size) == 7, np.nan, q), tau), "NaN"),
        (lambda t, q, tau: (t[:10], q[:10], tau[:10]), "at least"),
    ],
)
def test_bad_data_errors(tmp_path, mutate, match):
    t, q, tau = mutate(*_arrays())
    p = tmp_path / "bad.csv"
    _write_csv(p, ["t", "q", "tau"], [t, q, tau])
    with pytest.raises(DataError, match=match):
        load_experiment(p)


def test_irregular_sampling_is_resampled_with_warning(tmp_path):
    t, q, tau = _arrays(n=1000)
    rng = np.random.default_rng(0)
    tj = t + rng.uniform(-2e-4, 2e-4, t.size)
    tj[0] = 0.0
    p = tmp_path / "jitter.csv"
    _write_csv(p, ["t", "q", "tau"], [tj, np.interp(tj, t, q), np.interp(tj, t, tau)])
    with pytest.warns(ResamplingWarning, match="resampled"):
        e = load_experiment(p)
    assert np.allclose(np.diff(e.t), e.dt)
    np.testing.assert_allclose(e.q, 0.5 * np.sin(2.0 * e.t), atol=1e-5)


def test_an_experiment_is_a_view_of_its_one_joint_run(tmp_path):
    """An Experiment holds the run of one joint (RawRobotRun, k = 1) and reads its first axis
    without copying; built from 1-D arrays it builds that run; a run of several axes is no
    Experiment."""
    t, q, tau = _arrays()
    p = tmp_path / "run.csv"
    _write_csv(p, ["t", "q", "tau", "q_ref", "payload_kg"], [t, q, tau, 1.1 * q, 2 + 0 * t])
    e = load_experiment(p, joint="prismatic")
    raw = read_file(p, None)
    assert e.run.q.shape == e.run.tau.shape == e.run.q_ref.shape == (t.size, 1)
    assert e.run.revolute is False and raw.revolute is None  # the kind resolved on the view
    for name in ("q", "tau", "q_ref"):
        view, col = getattr(e, name), getattr(e.run, name)
        assert view.shape == (t.size,) and np.shares_memory(view, col)
        np.testing.assert_array_equal(view, getattr(raw, name)[:, 0])
    assert e.t is e.run.t and e.dt == e.run.dt and len(e) == t.size
    assert (e.payload_mass, e.payload_arm) == (2.0, 0.0) and e.run.payload.arm_m is None
    f = Experiment("arrays", t, q, tau, 3.0, 0.5, False)
    assert f.run.q.shape == (t.size, 1) and np.shares_memory(f.q, q) and f.q_ref is None
    assert (f.payload_mass, f.payload_arm, f.revolute, f.source) == (3.0, 0.5, False, "arrays")
    assert Experiment.of_run(f.run).revolute is False
    with pytest.raises(DataError, match=r"^arrays: payload_kg -1\.0: expected a mass >= 0"):
        Experiment("arrays", t, q, tau, -1.0)
    (arm,) = load_robot_runs(_write_two_axes(tmp_path, t, q, tau), ("a", "b"))
    with pytest.raises(DataError, match=r"two\.csv: 2 axes, an Experiment has one"):
        Experiment.of_run(arm)


def _write_two_axes(d, t, q, tau):
    p = d / "two.csv"
    _write_csv(p, ["t", "q1", "q2", "tau1", "tau2"], [t, q, q, tau, tau])
    return p


def test_unknown_extension_and_missing_file(tmp_path):
    with pytest.raises(DataError, match="no such file"):
        load_experiment(tmp_path / "none.csv")
    p = tmp_path / "a.parquet"
    p.write_text("x")
    with pytest.raises(DataError, match="unknown file type"):
        load_experiment(p)
    with pytest.raises(DataError, match="KEY=PATH"):
        parse_mapping("q")


def test_one_map_parser_for_one_joint_and_a_robot(tmp_path):
    """One ``--map`` parser: a single joint's keys are a robot's without the derivatives and
    the per-axis keys; numbers become floats on both paths, a name stays a name; each path
    keeps its error class, one line naming the entry or key and what was expected."""
    line = ["t=rec.t,q=rec.q[:, 1]", "tau=vir,payload_kg=2,payload_arm_m=nan"]
    one = parse_mapping(line)
    assert one == {"t": "rec.t", "q": "rec.q[:, 1]", "tau": "vir", "payload_kg": 2.0,
                   "payload_arm_m": "nan"}
    assert parse_mapping(line, robot=True) == one
    assert parse_mapping("dq=x,ddq=y,q_ref2=z", robot=True) == {"dq": "x", "ddq": "y",
                                                                 "q_ref2": "z"}
    for bad in ("dq=x", "q2=y"):
        with pytest.raises(DataError, match=rf"^--map key '{bad[:-2]}': expected one of t, q, "
                                            r"tau, q_ref, payload_kg, payload_arm_m$"):
            parse_mapping(bad)
    with pytest.raises(RobotIdentError, match=r"^--map key 'x': expected one of t, q, tau, "
                                              r"q_ref, dq, ddq, payload_kg, payload_arm_m or a "
                                              r"per-axis key such as q1, tau2, q_ref3$"):
        parse_mapping("x=y", robot=True)
    with pytest.raises(RobotIdentError, match=r"^--map entry 'q': expected KEY=PATH"):
        parse_mapping("q=a, q", robot=True)
    # a number where a signal's path is expected is refused when the file is read, per-axis too
    t, q, tau = _arrays()
    p = tmp_path / "x.csv"
    _write_csv(p, ["t", "q", "tau"], [t, q, tau])
    with pytest.raises(RobotIdentError, match=r"x\.csv: q1 must be a column/variable, not a "
                                              r"constant"):
        load_robot_runs(p, ("elbow",), mapping=parse_mapping("q1=3,tau1=tau", robot=True))


def test_concat_marks_experiments(tmp_path):
    t, q, tau = _arrays()
    paths = []
    for i, m in enumerate((0.0, 6.97)):
        p = tmp_path / f"r{i}.csv"
        _write_csv(p, ["t", "q", "tau", "payload_kg"], [t, q, tau, np.full_like(t, m)])
        paths.append(p)
    s = concat(load_experiments(paths))
    assert len(s) == 2 * t.size
    np.testing.assert_array_equal(np.unique(s.experiment), [0, 1])
    assert s.payload_mass[0] == 0.0 and s.payload_mass[-1] == 6.97


def test_mcap_log_written_by_daq_is_read_back(tmp_path):
    mcaplog = pytest.importorskip("daq.runtime.mcaplog")
    t, q, tau = _arrays(n=300)
    p = tmp_path / "run_payload1.mcap"
    meta = {"payload": {"mass_kg": "3.4584", "arm_m": "1.277"},
            "campaign": {"joint_kind": "revolute"}}  # fmt: skip
    with mcaplog.RunLog(p, n_axes=1, cycle_s=1e-3, metadata=meta) as log:
        for k in range(t.size):
            log.state(0, k, 10.0 + t[k], q[k], 0.0, tau[k], tau[k], int(q[k] * 65190), 0, 0,
                      0, 0x27)  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error", ResamplingWarning)
        e = load_experiment(p)
    np.testing.assert_allclose(e.q, q)
    np.testing.assert_allclose(e.tau, tau)
    np.testing.assert_allclose(e.t, t, atol=1e-9)
    assert e.payload_mass == 3.4584 and e.payload_arm == 1.277 and e.revolute


def test_longest_enabled_stretch_is_kept():
    """MCAP runs are cut to the cycles with the drive enabled (enable/stop phases dropped)."""
    from ident.loaders import _longest_true_run

    mask = np.array([0, 0, 1, 1, 1, 0, 1, 1, 1, 1, 0], dtype=bool)
    assert _longest_true_run(mask) == slice(6, 10)
    assert _longest_true_run(np.ones(5, bool)) == slice(0, 5)
    assert _longest_true_run(np.zeros(4, bool)) == slice(0, 0)


# -- one reader for one joint and n (a joint is a 1-dof robot) ---------------------------------


def test_a_joint_is_a_one_joint_robot_in_both_spellings(tmp_path):
    """The single-joint spelling (``q``, ``tau``, ``payload_arm_m``) and the robot's numbered
    one (``q1``, ``tau1``, ``q_ref1``) read the same arrays through both loaders, and the
    single-joint Experiment is the k = 1 view of the robot reader's run."""
    t, q, tau = _arrays()
    single = tmp_path / "single.csv"
    _write_csv(single, ["t", "q", "tau", "q_ref", "payload_kg", "payload_arm_m"],
               [t, q, tau, 1.1 * q, np.full_like(t, 2.0), np.full_like(t, 0.75)])
    numbered = tmp_path / "numbered.csv"
    _write_csv(numbered, ["t", "tau1", "q1", "q_ref1", "payload_mass_kg"],
               [t, tau, q, 1.1 * q, np.full_like(t, 2.0)])
    a, b = load_experiment(single), load_experiment(numbered, gain=2.0)
    (r,) = load_robot_runs(single, ("elbow",), gains=[2.0])
    for x in (a, b):
        np.testing.assert_array_equal(x.q, q)
        np.testing.assert_array_equal(x.q_ref, 1.1 * q)
        assert x.payload_mass == 2.0
    np.testing.assert_array_equal(a.tau, tau)
    np.testing.assert_array_equal(b.tau, 2.0 * tau)
    assert (a.payload_arm, b.payload_arm) == (0.75, 0.0)
    np.testing.assert_array_equal(r.q[:, 0], a.q)
    np.testing.assert_array_equal(r.tau[:, 0], 2.0 * a.tau)
    assert r.payload.mass == 2.0 and r.payload.arm_m == 0.75
    raw = read_file(single, None)
    assert raw.q.shape == (t.size, 1) and raw.revolute is None
    np.testing.assert_array_equal(raw.t, a.t)
    np.testing.assert_array_equal(raw.q[:, 0], a.q)
    # a lever arm without a mass places nothing: the robot drops it, the Experiment keeps it
    _write_csv(single, ["t", "q", "tau", "payload_arm_m"], [t, q, tau, np.full_like(t, 0.75)])
    assert load_robot_runs(single, ("elbow",))[0].payload.arm_m is None
    assert load_experiment(single).payload_arm == 0.75


def test_single_joint_errors_keep_their_spelling(tmp_path):
    """Read by the one reader, a single joint's missing signal is still named with its
    canonical key and the --map hint; a robot's with its numbered columns."""
    t, q, tau = _arrays()
    p = tmp_path / "x.csv"
    _write_csv(p, ["t", "q1", "q2", "tau1", "tau2"], [t, q, q, tau, tau])
    with pytest.raises(DataError, match=r"x\.csv: missing column/variable 'q' for 'q' "
                                        r"\(found: q1, q2, t, tau1, tau2; map one with --map"):
        load_experiment(p)
    e = load_experiment(p, mapping={"q": "q2", "tau": "tau2"})  # mapped: the other axes ignored
    np.testing.assert_array_equal(e.q, q)
    with pytest.raises(RobotIdentError, match=r"x\.csv: 2 axes in the file \(q1\.\.q2\), the "
                                              r"robot moves 1 joints \(elbow\)"):
        load_robot_runs(p, ("elbow",))


def test_a_foreign_mat_file_reads_the_same_as_one_joint_and_as_a_one_joint_robot(tmp_path):
    """The EMPS layout (``qm``, ``vir``, a gain variable ``gtau``): ``--map``/``--gain`` of the
    single joint and ``--map`` with the drive gain of a one-joint robot give the same arrays,
    the payload (mass and lever arm) included."""
    t, q, tau = _arrays()
    p = tmp_path / "emps_like.mat"
    scipy.io.savemat(p, {"t": t[:, None], "qm": q[:, None], "vir": (tau / 35.15)[:, None],
                         "gtau": np.array([[35.15]])})
    e = load_experiment(p, mapping=parse_mapping("q=qm,tau=vir,payload_kg=2,payload_arm_m=0.5"),
                        gain="gtau")
    (r,) = load_robot_runs(p, ("slide",), gains=[35.15], mapping=parse_mapping(
        "q=qm,tau=vir,payload_kg=2,payload_arm_m=0.5", robot=True))
    np.testing.assert_array_equal(r.q[:, 0], e.q)
    np.testing.assert_array_equal(r.tau[:, 0], e.tau)
    assert (r.payload.mass, r.payload.arm_m) == (e.payload_mass, e.payload_arm) == (2.0, 0.5)
