"""The q_s rescan after refinement: through the design (the former single-joint path,
``ident.models.IdentModel`` on ``with_qs`` designs, given as a copy of that module: ``--old
FILE``) and through the robot model (:meth:`ident.fitting.FitReport.rescan_found_terms`, the
n-dof refit of the found terms at each q_s), on the same fit and refinement, in the same
process, timed alternately (``--repeat``); prints both scans' errors per q_s, the chosen q_s,
the refit's parameters against the plant's truth, and the times.

Usage::

    git show 8d0c9ea:ident/qs_scan.py | sed -e 's/^from \\. import/from ident import/' \\
        -e 's/^from \\.\\([a-z_]*\\) import/from ident.\\1 import/' > /tmp/old_qs.py
    python benchmarks/qs_rescan_robot.py LOGDIR [--old /tmp/old_qs.py] [--repeat 2]

(8d0c9ea: the last tree with the rescan through the design.)

LOGDIR holds the MCAP logs of ``jointid demo --out DIR`` (DIR/logs); the truth is the demo
plant's (examples/plant_rx130l.toml), as the demo's report shows it.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

from ident.fitting import fit_models
from ident.loaders import load_experiments
from ident.refine import refine
from sim_drivers.plant_config import load_plant

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", type=Path)
    ap.add_argument("--old", type=Path, default=None)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--q-s", type=float, default=0.04, help="a-priori q_s [rad/s] (the demo's)")
    a = ap.parse_args()
    exps = load_experiments([str(p) for p in sorted(a.logs.glob("*.mcap"))], joint="revolute")
    rep = fit_models(exps, ("usual", "paper"), q_s=a.q_s)
    ref = refine(rep.designs["paper"], rep.models["paper"], max_steps=3, vmax=rep.vmax)
    print(f"refinement: {ref.rel_error_initial:.4f} -> {ref.rel_error_final:.4f}, "
          f"terms {[t.effect for t in ref.terms]}")
    old = None
    if a.old is not None:
        spec = importlib.util.spec_from_file_location("old_qs_scan", a.old)
        old = importlib.util.module_from_spec(spec)
        sys.modules["old_qs_scan"] = old  # (its dataclass looks itself up there)
        spec.loader.exec_module(old)
    times: dict[str, list[float]] = {"design": [], "robot": []}
    res = {}
    for _ in range(a.repeat):
        for kind in (("design", "robot") if old is not None else ("robot",)):
            t0 = time.perf_counter()
            if kind == "design":
                res[kind] = old.rescan_qs(ref.final_design, ref.final_model, vmax=rep.vmax)
            else:
                res[kind] = rep.rescan_found_terms("paper", ref.terms, ref.final_design)
            times[kind].append(time.perf_counter() - t0)
    new = res["robot"]
    if old is not None:
        before = dict(res["design"].scan)
        worst = 0.0
        for q, e in new.scan:
            if q in before:
                worst = max(worst, abs(e / before[q] - 1))
        print(f"design path: q_s {res['design'].q_s:.6g} rad/s, {len(before)} fits")
        print(f"same q_s in both scans: {sum(q in before for q, _ in new.scan)} of "
              f"{len(new.scan)}; largest relative difference of their errors {worst:.2e}")
    print(f"robot path:  q_s {new.q_s:.6g} rad/s, {len(new.scan)} refits, error "
          f"{min(e for _, e in new.scan):.6f}")
    truth = load_plant(ROOT / "examples" / "plant_rx130l.toml").truth()
    pars = new.record["parameters"]
    print(f"{'parameter':<10}{'truth':>11}{'robot':>11}{'2 sigma':>10}"
          + (f"{'design':>11}" if old is not None else ""))
    for n, t in truth.items():
        line = f"{n:<10}{t:>11.5g}{pars[n]['value']:>11.5g}{2 * pars[n]['std']:>10.2g}"
        if old is not None:
            line += f"{res['design'].model.coef_[n]:>11.5g}"
        print(line)
    print(f"plant q_s {load_plant(ROOT / 'examples' / 'plant_rx130l.toml').joint.q_s:g} rad/s")
    for kind, ts in times.items():
        if ts:
            print(f"time {kind}: " + ", ".join(f"{t:.2f}" for t in ts) + " s")
    if old is not None:
        print(f"ratio robot / design: {sum(times['robot']) / sum(times['design']):.2f}")


if __name__ == "__main__":
    main()
