"""Fingerprint of what the loaders read: every array (t, q, tau, q_ref, payload) of a set of
inputs, single-joint (``ident.loaders.load_experiment``) and robot (``load_robot_runs``),
pickled so that two versions of the loaders can be compared bit for bit.

    python benchmarks/loader_fingerprint.py make DIR          # write the inputs once
    python benchmarks/loader_fingerprint.py dump DIR OUT.pkl  # read them with this tree
    python benchmarks/loader_fingerprint.py cmp A.pkl B.pkl   # bit-identical or the diffs

Inputs: the EMPS and KUKA recordings of ../shared (when present), single-joint MCAP logs of
the simulated campaign (one damaged: lost chunk), a 3-axis MCAP log of the arm simulator
(torque delay 1.5 cycles), CSV files with jittered stamps / values at jittered instants, the
robot CSV (numbered, named) and MAT (rows, columns) files, and warnings / error messages.
"""

from __future__ import annotations

import pickle
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

SHARED = ROOT.parent.parent / "shared" / "data"
if not SHARED.is_dir():
    SHARED = ROOT.parent / "shared" / "data"
if not SHARED.is_dir():
    SHARED = Path("/work/shared/data")
SHARED = SHARED.resolve()  # the same file names from any checkout
EMPS = SHARED / "emps"
KUKA = SHARED / "kuka_kr300_weigand2021"
KUKA_MAP = {"t": "rec.time_cont", "q": "rec.act_pos_mot_deg", "tau": "rec.act_torque_abs_nm",
            "q_ref": "rec.ref_pos_deg"}


def make(d: Path) -> None:
    import scipy.io
    from damaged_logs import damage_chunk
    from test_cutoff_jitter import JITTER_S
    from test_daq_run import small_campaign
    from test_robot_cli import ARM3, write_mcap

    from daq.protocol.control import ControllerGains
    from daq.runtime.runner import run_campaign
    from sim_drivers.arm import ArmGains, ArmParams, model_reference, simulate_arm
    from sim_drivers.offline import simulate
    from sim_drivers.plant_config import default_plant, load_plant
    from trajectories.plan import plan_campaign
    from trajectories.robot import load_robot
    from trajectories.robot_campaign import RobotCampaign

    d.mkdir(parents=True, exist_ok=True)
    # single-joint MCAP logs of the simulated campaign, one of them damaged
    c = small_campaign(n_payloads=2, periods=2, freq=1.0, amplitude=0.1)
    r = run_campaign(c, out_dir=d / "sj", simulate=default_plant(), yes=True)
    assert r.ok, r.reason
    for i, run in enumerate(r.runs):
        (d / f"sj{i}.mcap").write_bytes(Path(run.path).read_bytes())
    damage_chunk(d / "sj0.mcap", d / "sj_bad.mcap", at=1 / 3, min_chunks=4)
    # jittered CSV files (single joint, both spellings)
    import tomllib
    with open(ROOT / "examples" / "campaign.toml", "rb") as f:
        campaign = RobotCampaign.from_dict(tomllib.load(f), "campaign.toml").quick()
    plan = plan_campaign(campaign)
    plant = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml")
    gains = ControllerGains(**campaign.gains_kwargs())
    p = plan.payloads[1]
    run = simulate(plant, plan.reference, gains, payload_mass=p.mass_kg, payload_arm=p.arm_m,
                   seed=70)
    e = np.random.default_rng(5).uniform(-JITTER_S, JITTER_S, run.t.size)
    e[0] = 0.0
    cpr = plant.drive.counts_per_joint_rad
    for name, (t, q, tau) in {
        "clean": (run.t, run.q, run.tau_ref),
        "stamps": (run.t + e, run.q, run.tau_ref),
        "instants": (run.t + e, np.round(np.interp(run.t + e, run.t, run.q_true) * cpr) / cpr,
                     np.interp(run.t + e, run.t, run.tau_ref)),
    }.items():
        np.savetxt(d / f"{name}.csv", np.column_stack(
            [t, q, tau, run.q_true, np.full(t.size, p.mass_kg), np.full(t.size, p.arm_m)]),
            delimiter=",", fmt="%.10g", header="t,q,tau,q_ref,payload_kg,payload_arm_m",
            comments="")
        np.savetxt(d / f"{name}_1.csv", np.column_stack([t, q, tau]), delimiter=",",
                   fmt="%.10g", header="t,q1,tau1", comments="")
    scipy.io.savemat(d / "sj.mat", {"rec": {"pos_deg": np.degrees(np.vstack([run.q, -run.q])),
                                            "tq": np.vstack([run.tau_ref, run.tau_ref]) / 4.0,
                                            "time": run.t},
                                    "para": {"u": np.array([4.0, 2.0])}, "m": p.mass_kg})
    # the 3-axis arm: MCAP (torque delay of the simulated arm is written by the runner only;
    # write_mcap logs without it), CSV numbered / named, MAT rows / columns
    robot = load_robot(ARM3)
    params = ArmParams.from_robot(robot)
    ag = ArmGains.for_params(params)
    arm = simulate_arm(params, model_reference(params.model, duration_s=4.0, seed=1), ag, seed=1)
    joints = robot.moving
    write_mcap(d / "arm.mcap", arm, joints,
               payload={"index": "1", "mass_kg": "2.0", "com_m": "[0, 0, 0.1]"})
    arm.to_csv(d / "arm_numbered.csv")
    cols = {"t": arm.t}
    for i, j in enumerate(joints):
        cols[f"tau_{j}"] = arm.tau_ref[:, i]
        cols[f"q_{j}"] = arm.q[:, i]
    np.savetxt(d / "arm_named.csv", np.column_stack(list(cols.values())), delimiter=",",
               header=",".join(cols), comments="", fmt="%.17g")
    g = np.array([2.0, 4.0, 8.0])
    scipy.io.savemat(d / "arm_rows.mat", {"rec": {"t": arm.t, "pos_deg": np.degrees(arm.q).T,
                                                  "tau_motor": (arm.tau_ref / g).T}})
    scipy.io.savemat(d / "arm_cols.mat", {"t": arm.t, "q": np.degrees(arm.q),
                                          "tau": arm.tau_ref / g})
    # a 3-axis log of the runner (torque_delay_cycles 1.5) through the whole stack
    from robot_campaigns import arm3_campaign
    res = run_campaign(arm3_campaign(), out_dir=d / "arm_run", simulate=True, yes=True)
    assert res.ok, res.reason
    (d / "arm_run.mcap").write_bytes(Path(res.runs[0].path).read_bytes())


def _bad_cases(d: Path, arm_j: tuple[str, ...]) -> dict:
    """Bad inputs: the one-line messages of both loaders (compared as text)."""
    import scipy.io

    from ident.loaders import load_experiment, make_experiment
    from ident.robot.loaders import load_robot_runs

    b = d / "bad"
    b.mkdir(exist_ok=True)
    n = 200
    t = np.arange(n) * 1e-3
    q = 0.1 * np.sin(t)

    def csv(name: str, header: str, *cols: np.ndarray) -> Path:
        np.savetxt(b / name, np.column_stack(cols), delimiter=",", header=header, comments="")
        return b / name

    nanq = q.copy()
    nanq[7] = np.nan
    gap = t.copy()
    gap[100:] += 0.05
    one = np.ones(n)
    k3 = np.column_stack([q, q, q])
    scipy.io.savemat(b / "m.mat", {"t": t, "q": k3, "tau": k3, "rec": {"pos": k3.T, "x": 1.0},
                                   "q2d": k3})
    out = {
        "nan": lambda: load_experiment(csv("nan.csv", "t,q,tau", t, nanq, q)),
        "huge": lambda: load_experiment(csv("huge.csv", "t,q,current", t, q, 1e12 * one),
                                        mapping={"tau": "current"}),
        "reversed": lambda: load_experiment(csv("rev.csv", "t,q,tau", t[::-1], q, q)),
        "few": lambda: load_experiment(csv("few.csv", "t,q,tau", t[:10], q[:10], q[:10])),
        "gap": lambda: load_experiment(csv("gap.csv", "t,q,tau", gap, q, q)),
        "missing_tau": lambda: load_experiment(csv("mt.csv", "t,q,torque", t, q, q)),
        "neg_mass": lambda: load_experiment(csv("neg.csv", "t,q,tau,payload_kg", t, q, q,
                                                -2 * one)),
        "varying_mass": lambda: load_experiment(csv("vm.csv", "t,q,tau,payload_kg", t, q, q,
                                                    t)),
        "mat_2d": lambda: load_experiment(b / "m.mat", mapping={"q": "q2d", "tau": "tau"}),
        "mat_bad_field": lambda: load_experiment(b / "m.mat", mapping={"q": "rec.nope"}),
        "mat_row": lambda: load_experiment(b / "m.mat", mapping={"q": "rec.pos[7]"}),
        "mat_const": lambda: load_experiment(b / "m.mat", mapping={"q": 1.0}),
        "mcap_deg": lambda: load_experiment(d / "sj0.mcap", q_unit="deg"),
        "mcap_axis": lambda: load_experiment(d / "sj0.mcap", axis=3),
        "unit_kind": lambda: load_experiment(csv("u.csv", "t,q,tau", t, q, q), q_unit="mm",
                                             joint="revolute"),
        "mk_len": lambda: make_experiment("arrays", t, q[:-1], q),
        "mk_nan": lambda: make_experiment("arrays", t, nanq, q),
        "mk_mass": lambda: make_experiment("arrays", t, q, q, payload_mass=-1.0),
        "mk_arm": lambda: make_experiment("arrays", t, q, q, payload_arm=np.inf),
        "r_nan": lambda: load_robot_runs(csv("rn.csv", "t,q1,q2,q3,tau1,tau2,tau3", t, q,
                                             nanq, q, q, q, q), arm_j),
        "r_huge": lambda: load_robot_runs(csv("rh.csv", "t,q1,q2,q3,tau1,tau2,tau3", t, q, q,
                                              q, q, q, 1e12 * one), arm_j),
        "r_no_tau": lambda: load_robot_runs(csv("rt.csv", "t,q1,q2,q3", t, q, q, q), arm_j),
        "r_2axes": lambda: load_robot_runs(csv("r2.csv", "t,q1,q2,tau1,tau2", t, q, q, q, q),
                                           arm_j),
        "r_named": lambda: load_robot_runs(csv("rj.csv", "t,q_j9,tau_j9", t, q, q), arm_j),
        "r_no_q": lambda: load_robot_runs(csv("rq.csv", "t,x,tau", t, q, q), arm_j),
        "r_no_t": lambda: load_robot_runs(csv("rnt.csv", "time,q1,tau1", t, q, q), ("j",)),
        "r_pay_varies": lambda: load_robot_runs(csv("rp.csv", "t,q1,tau1,payload_mass_kg", t, q,
                                                    q, t), ("j",)),
        "r_mat_no_t": lambda: load_robot_runs(b / "m.mat", arm_j, mapping={"t": "rec.t"}),
        "r_mat_no_q": lambda: load_robot_runs(b / "m.mat", arm_j, mapping={"q": "rec.x"}),
        "r_mat_peraxis": lambda: load_robot_runs(b / "m.mat", arm_j, mapping={"q1": "q[:, 0]"}),
        "r_mat_extra": lambda: load_robot_runs(b / "m.mat", arm_j, mapping={
            "q1": "q[:, 0]", "q2": "q[:, 1]", "q3": "q[:, 2]", "q4": "q[:, 2]"}),
        "r_mat_2axes": lambda: load_robot_runs(b / "m.mat", arm_j[:2]),
        "r_mat_pay": lambda: load_robot_runs(b / "m.mat", arm_j, mapping={"payload_kg": "t"}),
        "r_mat_neg": lambda: load_robot_runs(b / "m.mat", arm_j, mapping={"payload_kg": "-3"}),
        "r_mcap_axes": lambda: load_robot_runs(d / "sj0.mcap", arm_j),
        "r_mcap_names": lambda: load_robot_runs(d / "arm.mcap", ("a", "b", "c")),
        "r_mcap_deg": lambda: load_robot_runs(d / "arm.mcap", arm_j, q_unit="deg"),
        "r_unit": lambda: load_robot_runs(d / "arm.mcap", arm_j, q_unit="furlong"),
        "r_nofile": lambda: load_robot_runs(b / "none.csv", arm_j),
        "r_ext": lambda: load_robot_runs(csv("x.parquet", "t", t), arm_j),
    }
    return out


def _arrays(obj) -> dict:
    out = {}
    for name in ("source", "t", "q", "tau", "q_ref", "dq", "ddq", "payload_mass",
                 "payload_arm", "revolute"):
        if hasattr(obj, name):
            v = getattr(obj, name)
            out[name] = None if v is None else (np.array(v) if isinstance(v, np.ndarray) else v)
    pay = getattr(obj, "payload", None)
    if pay is not None:
        out["payload"] = {k: (np.array(v) if isinstance(v, np.ndarray) else v)
                          for k, v in vars(pay).items()}
    return out


def dump(d: Path, out: Path) -> None:
    from ident.cli_robot import robot_gains
    from ident.loaders import load_experiment
    from ident.robot.loaders import load_robot_runs
    from trajectories.robot import load_robot

    arm_j = load_robot(ROOT / "examples" / "robots" / "arm3.toml").moving
    cases = {
        "sj0": lambda: load_experiment(d / "sj0.mcap"),
        "sj1": lambda: load_experiment(d / "sj1.mcap"),
        "sj1_prism": lambda: load_experiment(d / "sj1.mcap", joint="prismatic"),
        "sj_bad": lambda: load_experiment(d / "sj_bad.mcap"),
        "sj0_robot": lambda: load_robot_runs(d / "sj0.mcap", ("j",)),
        "sj_bad_robot": lambda: load_robot_runs(d / "sj_bad.mcap", ("j",)),
        "sj_mat": lambda: load_experiment(d / "sj.mat", mapping={
            "t": "rec.time", "q": "rec.pos_deg[1]", "tau": "rec.tq[1]", "payload_kg": "m",
            "payload_arm_m": 0.5}, gain="para.u[0]*0.25*4", q_unit="deg"),
        "arm_axis": lambda: [load_experiment(d / "arm.mcap", axis=i) for i in range(3)],
        "arm_run_axis": lambda: [load_experiment(d / "arm_run.mcap", axis=i) for i in range(3)],
        "arm_mcap": lambda: load_robot_runs(d / "arm.mcap", arm_j),
        "arm_run": lambda: load_robot_runs(d / "arm_run.mcap", arm_j),
        "arm_numbered": lambda: load_robot_runs(d / "arm_numbered.csv", arm_j, gains=[1, 2, 3]),
        "arm_named": lambda: load_robot_runs(d / "arm_named.csv", arm_j, q_unit="deg"),
        "arm_rows": lambda: load_robot_runs(d / "arm_rows.mat", arm_j, gains=[2.0, 4.0, 8.0],
                                            q_unit="deg", mapping={
                                                "t": "rec.t", "q": "rec.pos_deg",
                                                "tau": "rec.tau_motor"}),
        "arm_cols": lambda: load_robot_runs(d / "arm_cols.mat", arm_j, gains=[2.0, 4.0, 8.0],
                                            q_unit="deg"),
        "arm_peraxis": lambda: load_robot_runs(d / "arm_cols.mat", arm_j, mapping={
            "q1": "q[:, 0]", "q2": "q[:, 1]", "q3": "q[:, 2]", "tau": "tau",
            "payload_kg": "1.5"}),
    }
    for name in ("clean", "stamps", "instants"):
        f = d / f"{name}.csv"
        f1 = d / f"{name}_1.csv"
        cases[name] = lambda f=f: load_experiment(f)
        cases[name + "_gain"] = lambda f=f: load_experiment(f, gain=2.5, q_unit="mm")
        cases[name + "_1"] = lambda f=f1: load_experiment(f, mapping={"q": "q1", "tau": "tau1"})
        cases[name + "_robot"] = lambda f=f1: load_robot_runs(f, ("j1",))
    if EMPS.is_dir():
        for n in ("DATA_EMPS", "DATA_EMPS_PULSES"):
            cases[n] = lambda n=n: load_experiment(EMPS / f"{n}.mat", mapping={
                "q": "qm", "tau": "vir"}, gain="gtau", joint="prismatic")
    if KUKA.is_dir():
        kuka_j = load_robot(ROOT / "examples" / "robots" / "kuka_kr300_r2500.toml")
        gains = robot_gains(kuka_j)
        for x in "ABC":
            f = KUKA / f"recorded_2020-10-21_FF_{x}_08ms.mat"
            cases[f"kuka_{x}"] = lambda f=f: load_robot_runs(
                f, kuka_j.moving, gains=gains, mapping=KUKA_MAP, q_unit="deg")
            cases[f"kuka_{x}_axes"] = lambda f=f: [load_experiment(f, mapping={
                "t": "rec.time_cont", "q": f"rec.act_pos_mot_deg[{a}]",
                "q_ref": f"rec.ref_pos_deg[{a}]", "tau": f"rec.act_torque_abs_nm[{a}]"},
                gain=f"para.u[{a}]", q_unit="deg") for a in range(6)]
    cases.update(_bad_cases(d, arm_j))
    res = {}
    for name, fn in cases.items():
        with warnings.catch_warnings(record=True) as rec:
            warnings.simplefilter("always")
            try:
                got = fn()
                objs = got if isinstance(got, list) else [got]
                res[name] = [_arrays(o) for o in objs]
            except Exception as exc:  # noqa: BLE001
                res[name] = f"{type(exc).__name__}: {exc}"
        res[name + ":warnings"] = [f"{w.category.__name__}: {w.message}" for w in rec]
        print(name, "ok" if not isinstance(res[name], str) else res[name], flush=True)
    out.write_bytes(pickle.dumps(res))


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.dtype == b.dtype
                and a.shape == b.shape and a.tobytes() == b.tobytes())
    if isinstance(a, dict) and isinstance(b, dict):  # a field added on one side: not compared
        return all(_same(a[k], b[k]) for k in a.keys() & b.keys())
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


def cmp(a: Path, b: Path) -> int:
    x, y = pickle.loads(a.read_bytes()), pickle.loads(b.read_bytes())
    bad = 0
    for k in sorted(set(x) | set(y)):
        if not _same(x.get(k), y.get(k)):
            bad += 1
            print(f"DIFF {k}:\n  {str(x.get(k))[:600]}\n  {str(y.get(k))[:600]}")
    print(f"{len(set(x) | set(y)) - bad} identical, {bad} different")
    return 1 if bad else 0


if __name__ == "__main__":
    cmd = sys.argv[1]
    if cmd == "make":
        make(Path(sys.argv[2]))
    elif cmd == "dump":
        dump(Path(sys.argv[2]), Path(sys.argv[3]))
    else:
        sys.exit(cmp(Path(sys.argv[2]), Path(sys.argv[3])))
