"""Multi-dof planning, excitation quality and multi-sine optimisation on UR10 (3- and 6-dof).

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_multi_plan.py [--repeat N]``. Prints
medians (and min-max) over the repetitions, the condition numbers before and after the
optimisation, and the velocity-band and quadrant shares of the optimised plans. The UR10
model and its regressor come from tests/ur_model.py (pinocchio, example-robot-data).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from ur_model import ur10  # noqa: E402

from trajectories.excitation import optimise_multisine, quality  # noqa: E402
from trajectories.multi import plan_robot, plan_robot_campaign  # noqa: E402
from trajectories.robot_campaign import (  # noqa: E402
    MultisineSegment,
    TrapezoidSweep,
    campaign_from_dict,
)


def _times(fn, repeat: int) -> tuple[list[float], object]:
    out, res = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = fn()
        out.append(time.perf_counter() - t0)
    return out, res


def _row(name: str, ts: list[float], extra: str = "") -> str:
    med = statistics.median(ts)
    return f"{name:<46} {1e3 * med:10.1f} {1e3 * min(ts):9.1f}-{1e3 * max(ts):<9.1f} {extra}"


def _segments(robot) -> list:
    """Per-joint trapezoids (the two gravity joints sweeping each other) + a multi-sine."""
    n = robot.names
    segs = []
    for j, lim in enumerate(robot.limits):
        lo, hi = lim.position
        pad = 0.05 * (hi - lo)
        sweep = {}
        if j in (1, 2):  # shoulder and elbow sweep each other's gravity range
            o = 3 - j
            olo, ohi = robot.limits[o].position
            sweep = {n[o]: (olo + pad, ohi - pad)}
        segs.append(TrapezoidSweep(n[j], (0.05, 0.3, 1.0), (lo + pad, hi - pad), sweep, 0.3,
                                   0.2))
    segs.append(MultisineSegment(period_s=10.0, periods=2, harmonics=5, seed=1))
    return segs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--evaluations", type=int, default=200,
                    help="optimiser budget per degree of freedom")
    args = ap.parse_args()
    with (ROOT / "examples" / "campaign_robot3.toml").open("rb") as f:
        example = campaign_from_dict(tomllib.load(f), "campaign_robot3.toml")
    ts, plan = _times(lambda: plan_robot_campaign(example), args.repeat)
    print(f"{'case':<46} {'median ms':>10} {'min-max ms':>19}")
    print(_row("plan_robot_campaign(campaign_robot3.toml)", ts,
               f"{len(plan)} samples, {plan.duration_s:.0f} s, "
               f"{1e9 * statistics.median(ts) / plan.q.size:.0f} ns/joint-sample"))
    tables = []
    for dof in (3, 6):
        robot = ur10(dof)
        segs = _segments(robot)
        ts, plan = _times(lambda r=robot, s=segs: plan_robot(s, r.names, r.limits, r.start,
                                                             0.001), args.repeat)
        print(_row(f"plan_robot, UR10 {dof}-dof", ts,
                   f"{len(plan)} samples, {plan.duration_s:.0f} s, "
                   f"{1e9 * statistics.median(ts) / plan.q.size:.0f} ns/joint-sample"))
        tq, qual = _times(lambda r=robot, p=plan: quality(
            p, r.regressor, inverse_dynamics=r.inverse_dynamics), max(1, args.repeat // 2))
        print(_row(f"quality (regressor + rnea on {qual.n_samples} samples)", tq,
                   f"cond {qual.cond:.4g}, {qual.rank} base columns"))
        budget = args.evaluations * dof
        to, res = _times(lambda r=robot, b=budget: optimise_multisine(
            r.regressor, r.limits, r.start, 10.0, 5, fill=0.8, seed=1, max_evaluations=b), 1)
        print(_row(f"optimise_multisine, L=5, {budget} evaluations", to,
                   f"cond {res.cond_start:.4g} -> {res.cond_end:.4g} ({res.stopped})"))
        seg_opt = MultisineSegment(10.0, 2, tuple(res.q0), tuple(map(tuple, res.a)),
                                   tuple(map(tuple, res.b)))
        segs_opt = [*segs[:-1], seg_opt]
        p_opt = plan_robot(segs_opt, robot.names, robot.limits, robot.start, 0.001)
        q_opt = quality(p_opt, robot.regressor, inverse_dynamics=robot.inverse_dynamics)
        p_ms = plan_robot([seg_opt], robot.names, robot.limits, robot.start, 0.001)
        q_ms = quality(p_ms, robot.regressor, base=res.base_columns)
        p_ms0 = plan_robot([segs[-1]], robot.names, robot.limits, robot.start, 0.001)
        q_ms0 = quality(p_ms0, robot.regressor, base=res.base_columns)
        tables.append((dof, qual, q_opt, q_ms0, q_ms))
    for dof, q0, q1, m0, m1 in tables:
        print(f"\nUR10 {dof}-dof: cond of the multi-sine alone {m0.cond:.4g} -> {m1.cond:.4g} "
              f"(optimised); whole plan (trapezoids + multi-sine) {q0.cond:.4g} -> "
              f"{q1.cond:.4g}")
        print(q1.format_table())
    np.set_printoptions(precision=3)


if __name__ == "__main__":
    main()
