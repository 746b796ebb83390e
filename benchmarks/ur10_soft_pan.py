"""Does the soft quadrant weight fix the simulated UR10's shoulder pan (issue 25)?

docs/monitoring.md, "Simulated UR10 (6 dof)": the pan's monitoring band is +-3.9 N m with
the identified paper model against +-1.46 N m with the simulator's own parameters; the hard
fit gives the pan (vertical axis, load near zero) biased low-speed friction. This script
fits the paper model on the monitor bench's UR10 logs with hard quadrants (the default) and
with ``quadrants="soft"`` (``jointid fit --robot --quadrants soft``), both ``--no-prune``
(and with ``--prune`` the hard fit with the default pruning too; a soft fit prunes
nothing), cross-validated on the bench's
calibrate logs, and compares them with the simulator's truth
(``ArmParams.from_robot(...).truth()``, the bench's oracle):

- per joint, the paper parameters' z = (value - truth) / stated std (hard, soft) and the
  soft fit's load jitter sigma_j;
- the pan's breakaway per quadrant, c_m + d_m and c_g + d_g (the static friction the
  monitor's rest interval is built from), value +- stated std (the correlation of c and d
  from ``cov_``);
- the monitor's own residual (``bench_monitor.replay``: the logged q, dq, torque of the
  calibrate logs through the monitor's residual, 20 Hz filter, rest interval below 3 q_s)
  with the exported hard model of WORK/model (the bench's: ``--consistent``, ``--no-prune``)
  and with the simulator's parameters: each joint's constant band (``lower``, ``upper``
  of ``thresholds_from_residual``, k = 6, margin 1.5) and the pan's residual RMS and peak
  at rest (|dq_pan| < 3 q_s) and moving; a soft fit cannot be exported today, so as a
  proxy the exported hard model with the pan's ten friction parameters replaced by the
  truth's, by the hard fit's and by the soft fit's (the fits' values held to the bounds the
  export's consistent estimate enforces on them, c + d >= 0 and a_g - b_g >= 0, by moving d
  and b_g alone; the rest of the model, theta and the other joints, the exported hard one's);
- per joint, the prediction error on the validation logs (the fit chain's rows, every row,
  ``_validation_all``) of each fit and of the same estimator with the true parameters
  (``coef_`` = ``truth_vector``: the oracle through the same chain): RMS over the rows where
  the joint moves (|dq_j| >= 3 q_s, outside the monitor's rest band), the monitor's band
  rule on that residual (max(6 std, 1.5 |peak - mean|) [N m], the rule of
  ``ident.monitor.thresholds_from_residual`` with the bench's k and margin), and for the pan
  the RMS at low speed (3 q_s <= |dq_pan| < 0.1 rad/s, and |dq_pan| < 3 q_s).

Usage (after the bench's ``model`` and ``calibrate`` stages in WORK)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/ur10_soft_pan.py WORK [--prune] [--json OUT]

WORK/model_logs/*.mcap are the identification logs, WORK/calibrate/logs/*.mcap the
validation logs (``--validation DIR`` for others). The replay reads the robot, payloads and
cycle of examples/campaign_ur10_demo.toml (the same in the bench's campaigns derived from it
and in a copy with another multi-sine seed).

Measured (docs/monitoring.md, "Soft quadrant weight on the pan"): the soft weight takes the
pan's c_g bias away but not the band's gap to the oracle, which is the pan's breakaway
c + d, unidentified by the demo campaign.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from daq.app.monitor import DEFAULT_K_SIGMA, DEFAULT_PEAK_MARGIN, REST_QS  # noqa: E402
from daq.protocol.reader import read_run  # noqa: E402
from ident.cli_robot import fit_files  # noqa: E402
from ident.monitor import load_exported, thresholds_from_residual  # noqa: E402
from ident.robot.paper import PAPER_BLOCK  # noqa: E402
from sim_drivers.arm import ArmParams  # noqa: E402
from trajectories.robot import load_robot  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_monitor as bm  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ROBOT = ROOT / "examples" / "robots" / "ur10.toml"
CAMPAIGN = ROOT / "examples" / "campaign_ur10_demo.toml"
LOW_PAN = 0.1  # [rad/s]: the pan's low-speed slice


def fit(robot, logs: list[Path], val: list[Path], quadrants: str, prune: bool) -> dict:
    """``jointid fit --robot ROBOT LOGS --model paper --validate VAL --quadrants Q`` (the
    bench's options otherwise: ``--no-consistency``, ``--no-prune`` unless ``prune``)."""
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = fit_files(robot, logs, val, model="paper", feasibility=False,
                        quadrants=quadrants, prune=prune)
    out["_wall_s"] = time.perf_counter() - t0
    return out


def z_scores(out: dict, truth: dict[str, float]) -> dict[str, float]:
    """z = (value - truth) / stated std per paper-model parameter (NaN: pruned or no
    truth)."""
    est = out["_estimators"]["paper"]
    rec = out["models"]["paper"]["parameters"]
    tv = est.truth_vector(truth)
    return {n: (np.nan if rec[n]["pruned"] or not rec[n]["std"] > 0
                else (rec[n]["value"] - t) / rec[n]["std"])
            for n, t in zip(est.names_, tv, strict=True)}


def breakaway(out: dict, n: int) -> dict[str, tuple[float, float]]:
    """c_m + d_m and c_g + d_g of joint number ``n``: value and std (the record's stds, the
    correlation of c and d from the estimator's ``cov_``)."""
    est = out["_estimators"]["paper"]
    rec = out["models"]["paper"]["parameters"]
    names = list(est.names_)
    res = {}
    for q in ("m", "g"):
        c, d = f"c_{q}{n}", f"d_{q}{n}"
        sc, sd = rec[c]["std"], rec[d]["std"]
        i, k = names.index(c), names.index(d)
        cv = np.asarray(est.cov_)
        rho = cv[i, k] / np.sqrt(cv[i, i] * cv[k, k]) if cv[i, i] > 0 and cv[k, k] > 0 else 0.0
        res[f"c_{q}+d_{q}"] = (rec[c]["value"] + rec[d]["value"],
                               float(np.sqrt(sc ** 2 + sd ** 2 + 2 * rho * sc * sd)))
    return res


def pan_friction(values: dict[str, float], n: int) -> dict[str, float]:
    """The pan's paper friction of a fit (joint number ``n``) held to the export's bounds:
    d := max(d, -c) per quadrant, b_g := min(b_g, a_g)."""
    f = {p: float(values[f"{p}{n}"]) for p in PAPER_BLOCK}
    for q in ("m", "g"):
        f[f"d_{q}"] = max(f[f"d_{q}"], -f[f"c_{q}"])
    f["b_g"] = min(f["b_g"], f["a_g"])
    return f


def with_pan(work: Path, friction: dict[str, float], tmp: Path):
    """The exported model of ``work/model`` with the pan's friction replaced."""
    d = tmp / f"model_{len(list(tmp.glob('model_*')))}"
    shutil.copytree(work / "model", d)
    rec = json.loads((d / "friction.json").read_text())
    rec["joints"][0].update(friction)
    (d / "friction.json").write_text(json.dumps(rec))
    return load_exported(d)


def monitor_replay(work: Path, val: list[Path], pans: dict[str, dict[str, float]]
                   ) -> dict:
    """The monitor's residual on the validation logs (``bench_monitor.replay``) with the
    exported hard model of ``work/model`` and with the simulator's parameters: constant
    band per joint, the pan's RMS and peak at rest and moving [N m]."""
    bm.SOURCE["campaign"] = CAMPAIGN
    _, c = bm._source()
    out = {}
    models = {"oracle": bm.truth_model(c)}
    tmp = Path(tempfile.mkdtemp(prefix="ur10_soft_pan_"))
    if (work / "model").is_dir():
        models = {"hard (exported)": load_exported(work / "model"), **models}
        for name, f in pans.items():
            models[f"exported, pan friction of {name}"] = with_pan(work, f, tmp)
    for name, model in models.items():
        rs, ms, dq = [], [], []
        for p in val:
            ml, r, m = bm.replay(p, c, model)
            a = read_run(p, axis=0)
            rs.append(r[ml.armed])
            ms.append(m[ml.armed])
            dq.append(a.dq[np.searchsorted(a.cycle, ml.cycle)][ml.armed])
        r, m, v = np.concatenate(rs), np.concatenate(ms), np.abs(np.concatenate(dq))
        th = thresholds_from_residual(r, list(c.moving), DEFAULT_K_SIGMA, name,
                                      DEFAULT_PEAK_MARGIN, m)
        rest = v < REST_QS * model.predictor(None).q_s[0]
        out[name] = {"lower": list(th.lower), "upper": list(th.upper),
                     "pan_rest": {"rms": float(np.sqrt(np.mean(r[rest, 0] ** 2))),
                                  "peak": float(np.abs(r[rest, 0]).max())},
                     "pan_moving": {"rms": float(np.sqrt(np.mean(r[~rest, 0] ** 2))),
                                    "peak": float(np.abs(r[~rest, 0]).max())}}
    shutil.rmtree(tmp)
    return out


def oracle(est, truth: dict[str, float]):
    """The fitted estimator with the true parameters (same rows, filters, quadrant rule)."""
    o = copy.copy(est)
    o.coef_ = est.truth_vector(truth)
    if getattr(est, "quadrant_theta_", None) is not None:
        o.quadrant_theta_ = o.coef_[:est.n_theta_]
    if not np.isfinite(o.coef_).all():
        bad = [n for n, v in zip(est.names_, o.coef_, strict=True) if not np.isfinite(v)]
        raise SystemExit(f"oracle: the truth vector has NaN entries {bad}")
    return o


def errors(est, sig, q_s: np.ndarray) -> dict:
    """Per joint: RMS and monitor-rule band [N m] of tau - predict on the rows where the
    joint moves (|dq_j| >= 3 q_s_j); pan's RMS at low speed."""
    r = sig.tau - est.predict(sig)
    out: dict = {"rms": [], "band": [], "rows": []}
    for j in range(r.shape[1]):
        ok = np.isfinite(r[:, j]) & (np.abs(sig.dq[:, j]) >= REST_QS * q_s[j])
        x = r[ok, j]
        out["rms"].append(float(np.sqrt(np.mean(x ** 2))))
        out["band"].append(float(max(DEFAULT_K_SIGMA * x.std(),
                                     DEFAULT_PEAK_MARGIN * np.abs(x - x.mean()).max())))
        out["rows"].append(int(ok.sum()))
    v = np.abs(sig.dq[:, 0])
    fin = np.isfinite(r[:, 0])
    for key, m in (("pan_low", (v >= REST_QS * q_s[0]) & (v < LOW_PAN)),
                   ("pan_rest", v < REST_QS * q_s[0]),
                   ("pan_fast", v >= LOW_PAN)):
        x = r[m & fin, 0]
        out[key] = {"rms": float(np.sqrt(np.mean(x ** 2))) if x.size else None,
                    "mean": float(x.mean()) if x.size else None, "rows": int(x.size)}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("work", type=Path)
    ap.add_argument("--validation", type=Path, default=None,
                    help="directory of the validation logs (default WORK/calibrate/logs)")
    ap.add_argument("--prune", action="store_true",
                    help="also the hard fit with the default pruning (a soft fit prunes "
                    "nothing)")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    logs = sorted((a.work / "model_logs").glob("*.mcap"))
    vdir = a.validation or a.work / "calibrate" / "logs"
    val = sorted(vdir.glob("*.mcap"))
    if not logs or not val:
        raise SystemExit(f"{a.work}: no model_logs/*.mcap or {vdir}/*.mcap (run the monitor "
                         "bench's model and calibrate stages first)")
    robot = load_robot(ROBOT)
    truth = ArmParams.from_robot(robot).truth()
    joints = list(robot.moving)
    nums = list(robot.numbers)
    res: dict = {}
    # a soft fit prunes nothing (ident.robot.soft_fit): --prune adds the hard fit alone
    for q, prune in (("hard", False), ("soft", False), *((("hard", True),) if a.prune else ())):
        key = f"{q}{'-prune' if prune else ''}"
        out = fit(robot, logs, val, q, prune)
        est = out["_estimators"]["paper"]
        q_s = np.asarray(est.q_s_, dtype=float)
        sig = out["_validation_all"]
        rec = out["models"]["paper"]
        res[key] = {"wall_s": out["_wall_s"], "z": z_scores(out, truth),
                    "rel_error": rec.get("rel_error"),
                    "validation_rel_error": rec.get("validation_rel_error"),
                    "pruned": [n for n, p in rec["parameters"].items() if p["pruned"]],
                    "values": {n: p["value"] for n, p in rec["parameters"].items()},
                    "std": {n: p["std"] for n, p in rec["parameters"].items()},
                    "breakaway_pan": breakaway(out, nums[0]),
                    "errors": errors(est, sig, q_s)}
        if q == "soft":
            res[key]["sigma_j"] = [float(s) for s in est.quadrant_sigma_]
            res[key]["sigma_j_std"] = [float(s) for s in est.quadrant_sigma_std_]
            res[key]["sigma_j_at_bound"] = [bool(b) for b in est.quadrant_sigma_at_bound_]
        if key == "hard":
            res["oracle"] = {"errors": errors(oracle(est, truth), sig, q_s)}
        print(f"{key}: fitted in {out['_wall_s']:.0f} s", flush=True)
    res["truth"] = {f"{p}{n}": truth[f"{p}{n}"] for n in nums for p in PAPER_BLOCK}
    pans = {"truth": {p: res["truth"][f"{p}{nums[0]}"] for p in PAPER_BLOCK},
            **{k: pan_friction(res[k]["values"], nums[0]) for k in res
               if k not in ("oracle", "truth")}}
    res["monitor"] = monitor_replay(a.work, val, pans)
    report(res, joints, nums)
    if a.json:
        a.json.write_text(json.dumps(res, indent=1, default=float))


def report(res: dict, joints: list[str], nums: list) -> None:
    fits = [k for k in res if k not in ("oracle", "truth", "monitor")]
    print("\npaper parameters, z = (value - truth) / std (" + " / ".join(fits) + ")")
    for j, n in zip(joints, nums, strict=True):
        zs = "  ".join(f"{p} " + "/".join(f"{res[k]['z'].get(f'{p}{n}', np.nan):+.1f}"
                                          for k in fits) for p in PAPER_BLOCK)
        s2 = "  ".join(f"sum z^2 {k} " + "{:.0f}".format(np.nansum(
            [res[k]["z"].get(f"{p}{n}", np.nan) ** 2 for p in PAPER_BLOCK])) for k in fits)
        print(f"  {j}: {zs}\n      {s2}")
    print("\npan (joint 1): truth vs fitted value +- std")
    for p in ("c_m", "d_m", "c_g", "d_g", "b_m", "b_g", "a_m", "a_g", "FV", "OFF"):
        nm = f"{p}{nums[0]}"
        print(f"  {nm}: truth {res['truth'][nm]:+.4g}  " + "  ".join(
            f"{k} {res[k]['values'][nm]:+.4g} +- {res[k]['std'][nm]:.2g}" for k in fits))
    t = res["truth"]
    for q in ("m", "g"):
        tv = t[f"c_{q}{nums[0]}"] + t[f"d_{q}{nums[0]}"]
        print(f"  breakaway c_{q}+d_{q}: truth {tv:+.3f}  " + "  ".join(
            "{} {:+.3f} +- {:.2g}".format(k, *res[k]["breakaway_pan"][f"c_{q}+d_{q}"])
            for k in fits))
    for k in fits:
        if "sigma_j" in res[k]:
            print(f"{k} sigma_j [N m]: " + ", ".join(
                f"{j} {s:.3g} +- {sd:.2g}{' (bound)' if b else ''}" for j, s, sd, b in zip(
                    joints, res[k]["sigma_j"], res[k]["sigma_j_std"],
                    res[k]["sigma_j_at_bound"], strict=True)))
    cols = [*fits, "oracle"]
    print("\nvalidation residual per joint, moving rows (|dq| >= 3 q_s): RMS [N m] | band rule "
          "max(6 std, 1.5 peak) [N m]   (" + " / ".join(cols) + ")")
    for j, name in enumerate(joints):
        print(f"  {name}: " + " / ".join(f"{res[k]['errors']['rms'][j]:.3f}" for k in cols)
              + " | " + " / ".join(f"{res[k]['errors']['band'][j]:.2f}" for k in cols))
    for sl in ("pan_rest", "pan_low", "pan_fast"):
        print(f"  pan {sl}: RMS " + " / ".join(
            f"{res[k]['errors'][sl]['rms']:.3f}" for k in cols) + "  mean " + " / ".join(
            f"{res[k]['errors'][sl]['mean']:+.3f}" for k in cols)
            + f"  ({res['oracle']['errors'][sl]['rows']} rows)")
    print("\nmonitor residual on the validation logs (bench_monitor.replay): constant band "
          "[lower, upper] per joint [N m]; pan at rest / moving: RMS, peak [N m]")
    for name, m in res["monitor"].items():
        print(f"  {name}: " + ", ".join(f"[{lo:+.2f}, {hi:+.2f}]" for lo, hi in
                                        zip(m["lower"], m["upper"], strict=True)))
        print(f"      pan rest RMS {m['pan_rest']['rms']:.3f} peak {m['pan_rest']['peak']:.2f}; "
              f"moving RMS {m['pan_moving']['rms']:.3f} peak {m['pan_moving']['peak']:.2f}")
    for k in fits:
        print(f"{k}: rel. error fit {res[k]['rel_error']}, validation "
              f"{res[k]['validation_rel_error']}, pruned {res[k]['pruned']}, "
              f"{res[k]['wall_s']:.0f} s")


if __name__ == "__main__":
    main()
