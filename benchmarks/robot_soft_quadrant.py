"""The soft quadrant weight inside the robot path's paper model (``RobotModel(quadrants=
"soft")``, ``jointid fit --robot --quadrants soft``) against the hard default, on the
simulated arm3 at 1 kHz and on the real KUKA recordings (docs/robot-identification.md, "The
soft quadrant weight in the estimator").

Usage: ``python benchmarks/robot_soft_quadrant.py [--seeds 1 2] [--no-kuka]``

- arm3: tests/test_robot_cutoff_band.py's ``simulated`` (paper friction, three payload runs
  of 20 s, the drives' log at 1 kHz) through ``fit_files`` with ``jointid fit --robot``'s
  defaults (WLS, columns chain, sign check, honest sigma, pruning; no feasibility search),
  paper model only; z = (value - truth) / stated std, the pruned parameters left out: per
  joint the sum of z^2 over its paper parameters (how many), c_g's z, and soft's sigma_j.
- KUKA: recording A fitted, B and C cross-validated (tests/test_robot_cli.py's command),
  paper model: relative error on the fit rows and on B, C; the sigma_j and which sit on a
  bound.

Times: the whole ``fit_files`` call (preprocessing, fit, uncertainty, validation), hard and
soft on the same run.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from math import nan
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_robot_cutoff_band import logged, simulated, z_scores  # noqa: E402

from ident.cli_robot import fit_files  # noqa: E402
from ident.loaders import parse_mapping  # noqa: E402
from ident.robot.estimate import RobotModel  # noqa: E402
from ident.robot.paper import PAPER_BLOCK  # noqa: E402
from trajectories.robot import load_robot  # noqa: E402

KUKA = ROOT / "examples" / "robots" / "kuka_kr300_r2500.toml"
KUKA_DATA = ROOT.parent / "shared" / "data" / "kuka_kr300_weigand2021"
KUKA_MAP = "t=rec.time_cont,q=rec.act_pos_mot_deg,tau=rec.act_torque_abs_nm,q_ref=rec.ref_pos_deg"


def _fit(q: str, *args, **kw) -> tuple[dict, float]:
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = fit_files(*args, model="paper", feasibility=False, quadrants=q, **kw)
    return out, time.perf_counter() - t0


def _fit_only(out: dict) -> float:
    """Seconds of ``RobotModel.fit`` alone (the paper model's hyper-parameters) on the
    signals ``fit_files`` fitted."""
    est = out["_estimators"]["paper"]
    t0 = time.perf_counter()
    RobotModel(**est.get_params()).fit(out["_identification"])
    return time.perf_counter() - t0


def _sigmas(est, joints) -> str:
    return ", ".join(
        f"{j} {s:.3g}" + (f" (reported on its bound {lo:.3g} .. {hi:.3g})" if b
                          else f" +- {sd:.2g}")
        for j, s, sd, b, (lo, hi) in zip(joints, est.quadrant_sigma_, est.quadrant_sigma_std_,
                                         est.quadrant_sigma_at_bound_,
                                         est.quadrant_sigma_bounds_, strict=True))


def arm3(seed: int) -> None:
    params, reg, runs, truth = simulated("paper", seed)
    res = {q: _fit(q, reg.robot, logged(params, runs, 1)) for q in ("hard", "soft")}
    z = {q: z_scores(o, "paper", truth)[0] for q, (o, _) in res.items()}
    print(f"arm3, paper friction, 1 kHz, seed {seed}: sum of z^2 hard -> soft "
          f"(parameters; chi^2 0.999: 29.6 for 10)")
    for n in reg.numbers:
        names = {f"{p}{n}" for p in PAPER_BLOCK}
        line = []
        for q in ("hard", "soft"):
            zz = [v for k, v in z[q].items() if k in names]
            line.append(f"{sum(v * v for v in zz):7.1f} ({len(zz)})")
        cg = [f"{z[q].get(f'c_g{n}', float('nan')):+.1f}" for q in ("hard", "soft")]
        print(f"  joint {n}: {line[0]} -> {line[1]}   c_g{n} z {cg[0]} -> {cg[1]}")
    for q in ("hard", "soft"):
        zz = list(z[q].values())
        print(f"  whole arm {q}: sum z^2 {sum(v * v for v in zz):.1f} over {len(zz)}, "
              f"fit_files {res[q][1]:.1f} s"
              f"{' (with the jackknife)' if q == 'hard' else ''}, RobotModel.fit "
              f"{_fit_only(res[q][0]):.1f} s")
    est = res["soft"][0]["_estimators"]["paper"]
    print(f"  soft sigma_j [N m]: {_sigmas(est, reg.joints)}; bounds "
          + ", ".join(f"{hi:.3g}" for hi in est.quadrant_sigma_bounds_[:, 1]), flush=True)


def kuka() -> None:
    files = [KUKA_DATA / f"recorded_2020-10-21_FF_{x}_08ms.mat" for x in "ABC"]
    robot = load_robot(KUKA)
    mp = parse_mapping(KUKA_MAP, robot=True)
    print("KUKA KR300, paper model, fit on A, cross-validation on B and C: relative error "
          "[%] on the fit rows and on B and C")
    for q in ("hard", "soft"):
        out, dt = _fit(q, robot, files[:1], files[1:], mapping=mp, q_unit="deg")
        rec = out["models"]["paper"]
        if "error" in rec:
            print(f"  {q}: {rec['error']}")
            continue
        val = rec.get("validation_rel_error", {})
        per = rec["rel_error"]
        print(f"  {q}: fit {100 * per['all']:.2f}, B and C {100 * val.get('all', nan):.2f}"
              f"   (fit_files {dt:.1f} s, RobotModel.fit {_fit_only(out):.1f} s)")
        print("    per axis fit: " + ", ".join(f"{a} {100 * v:.2f}" for a, v in per.items()
                                               if a != "all"))
        print("    per axis B and C: " + ", ".join(f"{a} {100 * v:.2f}" for a, v in val.items()
                                                   if a != "all"))
        if q == "soft":
            est = out["_estimators"]["paper"]
            print(f"    sigma_j [N m]: {_sigmas(est, robot.moving)}")
            print("    bounds [N m]: " + ", ".join(
                f"{lo:.3g}..{hi:.3g}" for lo, hi in est.quadrant_sigma_bounds_))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="*", default=[1, 2])
    ap.add_argument("--no-kuka", action="store_true")
    a = ap.parse_args()
    for s in a.seeds:
        arm3(s)
    if not a.no_kuka and KUKA_DATA.is_dir():
        kuka()


if __name__ == "__main__":
    main()
