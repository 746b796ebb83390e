"""Plan time of the example campaign, and vectorised sampling against ruckig's at_time loop.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_plan.py [--repeat N]``. Prints medians
(and min-max) over the repetitions; quote ratios, the host is shared and noisy.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import ruckig
from daq.examples import path as example_path

from trajectories.campaign_file import load_campaign
from trajectories.plan import plan_campaign


def _times(fn, repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def _row(name: str, ts: list[float], per: int | None = None) -> str:
    med = statistics.median(ts)
    extra = f"{1e9 * med / per:10.1f}" if per else f"{'':>10}"
    return f"{name:<44} {1e3 * med:9.2f} {1e3 * min(ts):8.2f}-{1e3 * max(ts):<8.2f} {extra}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15)
    args = ap.parse_args()
    campaign = load_campaign(example_path("campaign.toml"))
    quick = campaign.quick()
    plan = plan_campaign(campaign)
    n = len(plan.reference)

    # ruckig at_time loop over the same number of samples on one 10 s rest-to-rest move
    inp = ruckig.InputParameter(1)
    inp.current_position, inp.target_position = [-1.1], [1.3]
    inp.current_velocity = inp.current_acceleration = [0.0]
    inp.target_velocity = inp.target_acceleration = [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [0.24], [4.0], [40.0]
    traj = ruckig.Trajectory(1)
    ruckig.Ruckig(1).calculate(inp, traj)
    t = np.linspace(0.0, traj.duration, n)

    def at_time_loop():
        q = np.empty(n)
        dq = np.empty(n)
        ddq = np.empty(n)
        for k in range(n):
            p, v, a = traj.at_time(t[k])
            q[k], dq[k], ddq[k] = p[0], v[0], a[0]

    rows = [
        ("plan_campaign(example)", _times(lambda: plan_campaign(campaign), args.repeat), n),
        ("plan_campaign(example.quick())",
         _times(lambda: plan_campaign(quick), args.repeat), None),
        ("summary() of the example plan", _times(plan.summary, args.repeat), n),
        (f"ruckig at_time loop, same {n} samples", _times(at_time_loop, max(3, args.repeat // 3)),
         n),
    ]
    print(f"example: {n} samples ({plan.reference.duration_s:.1f} s at "
          f"{1e3 * campaign.cycle_s:g} ms), {len(plan.reference.pieces)} pieces; "
          f"repeat={args.repeat}")
    print(f"{'case':<44} {'median ms':>9} {'min-max ms':>17} {'ns/sample':>10}")
    for name, ts, per in rows:
        print(_row(name, ts, per))
    plan_med = statistics.median(rows[0][1])
    loop_med = statistics.median(rows[3][1])
    print(f"ratio at_time loop / whole vectorised plan: {loop_med / plan_med:.1f}x")


if __name__ == "__main__":
    main()
