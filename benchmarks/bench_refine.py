"""Refinement time for 1e5 and 1e6 raw samples (budget: 1e6 samples < 10 s).

Data: the simulated joint of ``examples/campaign.toml`` (one payload run, ~105 s at 1 kHz)
with the usual friction and undeclared effects (position ripple, spring, and a dry friction
varying along the position, F_C(q) sign(q̇), period 1.57 rad, ±38 % — an interaction the
library search finds); the 1e6 case stacks ten such runs with independent measurement noise
as ten experiments. The design is built once (``build_design``, timed apart); ``refine``
starts from the usual model, without and with the interaction diagnosis + library search
(``library=False/True``), in the same run.

Usage: ``python benchmarks/bench_refine.py [--repeat 3]``. Prints a table of medians.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import tomllib
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from daq.protocol.control import ControllerGains  # noqa: E402
from ident.models import IdentModel, usual_model  # noqa: E402
from ident.preprocess import build_design  # noqa: E402
from ident.refine import refine  # noqa: E402
from ident.refine_library import library_step  # noqa: E402
from ident.signals import Signals  # noqa: E402
from sim_drivers.offline import simulate  # noqa: E402
from sim_drivers.plant_config import default_plant  # noqa: E402
from trajectories.plan import plan_campaign  # noqa: E402
from trajectories.robot_campaign import RobotCampaign  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def one_run():
    raw = tomllib.loads((ROOT / "examples" / "campaign.toml").read_text())
    camp = RobotCampaign.from_dict(raw, "examples/campaign.toml")
    plan = plan_campaign(camp)
    p = default_plant()
    f = replace(p.friction, a_m=1, a_g=1, b_m=0, b_g=0, c_m=18, c_g=18, d_m=0, d_g=0)
    p = replace(p, friction=f)
    p = p.with_effect("position_ripple", amplitude_Nm=5.0, period_rad=0.0628, phase_rad=0.4)
    p = p.with_effect("spring", stiffness_Nm_per_rad=30.0, rest_position_rad=0.2)
    gains = ControllerGains(**camp.gains_kwargs())
    run = simulate(p, plan.reference, gains, seed=0)
    # position-dependent dry friction (test-side injection in the logged torque)
    extra = 0.38 * 18.0 * np.sin(2 * np.pi * run.q_true / 1.57 + 0.3) * np.sign(run.dq_true)
    return replace(run, tau_ref=run.tau_ref + extra)


def signals(run, copies: int, n_target: int) -> Signals:
    rng = np.random.default_rng(1)
    parts = []
    for i in range(copies):
        n = min(len(run), n_target // copies)
        tau = run.tau_ref[:n] + (rng.normal(0, 1.0, n) if i else 0.0)
        parts.append((run.t[:n], run.q[:n], tau, np.full(n, i)))
    t, q, tau, e = (np.concatenate(x) for x in zip(*parts, strict=True))
    z = np.zeros_like(q)
    return Signals(t, q, z, z, tau, z, z, e, revolute=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    t0 = time.perf_counter()
    run = one_run()
    print(f"simulated one run of {len(run)} samples in {time.perf_counter() - t0:.1f} s\n")
    lib = usual_model(True, payload=False)
    rows = []
    for n_target, copies in ((100_000, 1), (1_000_000, 10)):
        s = signals(run, copies, n_target)
        t0 = time.perf_counter()
        d = build_design(lib, s, cutoff_hz=25.0, decimation=20, dq_min=0.02)
        t_design = time.perf_counter() - t0
        for library in (False, True):
            times, R = [], None
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                R = refine(d, IdentModel(lib), max_steps=5, library=library)
                times.append(time.perf_counter() - t0)
            steps = ", ".join(st.effect for st in R.steps)
            rows.append((len(s), len(d), library, t_design, statistics.median(times),
                         min(times), max(times), steps, R.rel_error_initial, R.rel_error_final))
    print(f"{'raw':>9} {'decimated':>9} {'library':>7} {'design s':>9} {'refine s (median)':>18} "
          f"{'min':>6} {'max':>6}  rel. error     steps")
    for n, m, lb, td, med, lo, hi, steps, e0, e1 in rows:
        print(f"{n:>9} {m:>9} {'yes' if lb else 'no':>7} {td:>9.2f} {med:>18.2f} {lo:>6.2f} "
              f"{hi:>6.2f}  {100 * e0:.2f}->{100 * e1:.2f} %  {steps}")
    print(f"\nratio 1e6/1e5 (median refine time, library): {rows[3][4] / rows[1][4]:.1f}")
    print(f"ratio library/no library at 1e6: {rows[3][4] / rows[2][4]:.1f}")
    robot_rows(args.repeat)


def robot_rows(repeat: int) -> None:
    """One joint of a 6-dof robot (the n-dof design is on another branch): the library step
    with the five other joints' q and dq as 'other' variables, on the decimated samples of
    1e6 raw samples (48 400 at decimation 20 after selection); joint j's residual depends on
    joint k's position. Times one step and a five-step budget (5 x the step)."""
    n, dt = 48_400, 0.02
    rng = np.random.default_rng(2)
    t = np.arange(n) * dt
    q = np.sin(2 * np.pi * 0.05 * t) + 0.5 * np.sin(2 * np.pi * 0.013 * t + 1.0)
    dq = np.gradient(q, t)
    ddq = np.gradient(dq, t)
    others = {}
    for j in range(2, 7):
        qj = 0.8 * np.sin(2 * np.pi * (0.02 + 0.007 * j) * t + j)
        others[f"q{j}"], others[f"dq{j}"] = qj, np.gradient(qj, t)
    W = np.column_stack((ddq, np.cos(q), np.sin(q), np.sign(dq), dq, np.ones(n)))
    r = 4.0 * others["q3"] * np.sign(dq) + rng.normal(0, 0.5, n)
    y = W @ np.array([10, 50, 0, 18, 5, 1.0]) + r
    z = np.zeros(n)
    # tau: the rigid-body torque (the load variable without tau_out falls back on it)
    s = Signals(t, q, dq, ddq, 10 * ddq + 50 * np.cos(q), z, z, np.zeros(n, int),
                revolute=True)
    times, res = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = library_step(y, W, s, r, tau_out=None, others=others)
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    sel = res.result.selected[0].key if res.result.selected else "-"
    print(f"\n6-dof joint (10 other variables), {n} decimated samples: library step "
          f"{med:.2f} s (min {min(times):.2f}), {len(res.result.tried)} structures scored, "
          f"selected: {sel}; five steps ~{5 * med:.1f} s per joint")


if __name__ == "__main__":
    main()
