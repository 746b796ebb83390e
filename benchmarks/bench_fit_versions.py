"""CPU time of ``fit_models`` in two checkouts of jointid, interleaved in one shell.

    python benchmarks/bench_fit_versions.py OLD_TREE NEW_TREE [--rounds 2] [--repeat 3]

Each round runs this script's worker once with OLD_TREE, then once with NEW_TREE, first on
``sys.path`` (a fresh process each: no module of the other version is loaded). The worker
simulates the example campaign (seed 11, ``tests/example_campaign.py`` of that tree, the
runs of ``fit_fingerprint.campaign_runs``), then times ``fit_models`` on its three payload
runs: LS (CSV-named runs, no reference), IDIM-IV (MCAP-named runs with their references,
half-cycle torque delay) and LS with ``q_s="scan"``; the best of ``--repeat`` process-CPU
times per case. Printed: one line per tree and round, and the NEW/OLD ratio of the per-case
minima over the rounds (issue 24's measurement of the single chain: the single-joint design
built on the robot chain's full-rate signals).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

CASES = ("ls", "iv", "scan")


def _worker(tree: Path, repeat: int) -> None:
    import time
    import warnings

    sys.path[:0] = [str(tree), str(tree / "tests"), str(Path(__file__).resolve().parent)]
    warnings.simplefilter("ignore")
    from fit_fingerprint import campaign_runs  # imports the tree's ident and example_campaign

    from ident.fitting import fit_models

    ls, iv = campaign_runs()
    kwargs = {"ls": {"data": ls}, "iv": {"data": iv}, "scan": {"data": ls, "q_s": "scan"}}
    out = {}
    for case in CASES:
        ts = []
        for _ in range(repeat):
            t0 = time.process_time()
            fit_models(**kwargs[case])
            ts.append(time.process_time() - t0)
        out[case] = min(ts)
    print(json.dumps(out))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker is not None:
        _worker(a.worker.resolve(), a.repeat)
        return
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    best: dict[str, dict[str, float]] = {"old": {}, "new": {}}
    for r in range(a.rounds):
        for label, tree in (("old", a.old), ("new", a.new)):
            res = subprocess.run([sys.executable, __file__, str(a.old), str(a.new),
                                  "--repeat", str(a.repeat), "--worker", str(tree)],
                                 capture_output=True, text=True, env=env, check=True)
            t = json.loads(res.stdout.strip().splitlines()[-1])
            print(f"round {r + 1} {label:3s} " + "  ".join(f"{c} {t[c]:.3f} s" for c in CASES))
            for c in CASES:
                best[label][c] = min(best[label].get(c, float("inf")), t[c])
    print("new/old " + "  ".join(f"{c} {best['new'][c] / best['old'][c]:.2f}" for c in CASES))


if __name__ == "__main__":
    main()
