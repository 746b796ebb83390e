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
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import numpy as np  # noqa: E402
from sigma_cases import friction_mask, gauged_truth, wrist_arm, wrist_signals  # noqa: E402

from ident.robot.estimate import RobotModel  # noqa: E402
from ident.robot.uncertainty import assess  # noqa: E402


def coverage(seeds, duration_s: float, blocks: int, iv: bool, say=print) -> dict:
    """Per seed (seed, hits analytic, hits honest, count, wrist hits a, h, count)."""
    params, reg, base = wrist_arm()
    rows = []
    for seed in seeds:
        t0 = time.monotonic()
        sig = wrist_signals(params, reg, seed, duration_s)
        m = RobotModel(reg, "paper", "wls", base=base).fit(sig)
        u = assess(m, sig, n_blocks=blocks, iv=iv, prune=False)
        tv = gauged_truth(m, params)
        mask = friction_mask(m)
        wrist = mask & np.array([n[-1] in "456" for n in m.names_])
        err = np.abs(m.coef_ - tv)
        ha, hh = err <= 2 * u.std_analytic, err <= 2 * u.std
        row = (seed, int(ha[mask].sum()), int(hh[mask].sum()), int(mask.sum()),
               int(ha[wrist].sum()), int(hh[wrist].sum()), int(wrist.sum()),
               sorted(j for j, f in u.flags.items() if f["errors_in_variables"]))
        rows.append(row)
        say(f"seed {seed}: analytic {row[1]}/{row[3]}, honest {row[2]}/{row[3]} "
            f"(wrists {row[4]}/{row[6]}, {row[5]}/{row[6]}); flagged {row[7]} "
            f"[{time.monotonic() - t0:.0f} s]")
    tot = np.array([r[1:7] for r in rows]).sum(axis=0)
    return {"rows": rows, "analytic": tot[0] / tot[2], "honest": tot[1] / tot[2],
            "wrist_analytic": tot[3] / tot[5], "wrist_honest": tot[4] / tot[5]}


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
