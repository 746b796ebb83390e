"""Coverage of the friction parameters' 2-sigma intervals over noise seeds, analytic sigma
(eq. 15) against the honest sigma of ident.robot.uncertainty (issue 22 item 4).

    python benchmarks/sigma_coverage.py [--seeds 20] [--duration 10] [--blocks 10] [--no-iv]

Data: tests/sigma_cases.py (UR10, friction-dominated wrists, 0.5 N m drive noise on the wrists
acting before the friction's quadrant decision, one 5 kg payload run). Per seed: simulate,
fit the paper model (IDIM-WLS, as the CLI), assess (no pruning: the coverage of the fitted
parameters); then per seed and overall the share of the free friction parameters whose
|estimate - truth| <= 2 sigma (truth in the model's gauge), all joints and wrists only.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from sigma_cases import coverage  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--blocks", type=int, default=10)
    ap.add_argument("--no-iv", action="store_true")
    a = ap.parse_args()
    out = coverage(range(100, 100 + a.seeds), a.duration, a.blocks, not a.no_iv,
                   say=lambda m: print(m, flush=True))
    print(f"\nshare of 2-sigma intervals containing the truth over {a.seeds} seeds "
          f"(friction parameters of the paper model)")
    print(f"{'':<10}{'analytic':>10}{'honest':>10}")
    print(f"{'all':<10}{out['analytic']:>10.1%}{out['honest']:>10.1%}")
    print(f"{'wrists':<10}{out['wrist_analytic']:>10.1%}{out['wrist_honest']:>10.1%}")


if __name__ == "__main__":
    main()
