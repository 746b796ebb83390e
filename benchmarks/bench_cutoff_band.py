"""The paper model's bias against the IV cut-off, at 1 kHz, 500 Hz and 250 Hz (the figures of
:data:`ident.chain.CUTOFF_MIN_IV_HZ`; tests/test_cutoff_band.py asserts the rule).

Usage: ``python benchmarks/bench_cutoff_band.py [--seed 6]``

The simulated joint (``sim_drivers/data/plant_default.toml``) runs the example campaign
(``examples/campaign.toml``, three payloads, offline closed loop at 1 kHz, noise seeds
10 seed + i); the runs are subsampled (every 2nd, every 4th sample) and the paper model is
fitted by IDIM-IV (instruments from the plan's reference, no elimination) at the default
cut-off ("default") and at given ones. Printed per case: the cut-off [Hz], the relative error,
the sum of z^2 = ((estimate - truth) / sigma)^2 over the model's parameters (about their
number when the sigmas hold) and the two largest |z|.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from ident.fitting import fit_models

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from test_cutoff_band import campaign, simulated, subsampled  # noqa: E402

#: (every n-th sample, cut-offs [Hz]; None: the default).
CASES = ((1, (62.5, None, 200.0)), (2, (62.5, 100.0, None, 150.0)), (4, (31.25, None)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=6)
    a = ap.parse_args()
    plant, plan, gains = campaign()
    runs = simulated(plant, plan, gains, a.seed)
    truth = plant.truth()
    print(f"seed {a.seed}: f_s [Hz], cut-off [Hz], error [%], sum z^2 / parameters, largest |z|")
    for every, cuts in CASES:
        exps = subsampled(plan, runs, every)
        for cut in cuts:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                rep = fit_models(exps, ("paper",), table_iv=False, eliminate=False,
                                 cutoff_hz=cut)
            m = rep.models["paper"]
            z = {n: (m.coef_[n] - truth[n]) / m.std_[n] for n in m.names_}
            top = sorted(z, key=lambda n: -abs(z[n]))[:2]
            c = rep.designs["paper"].settings()["cutoff_hz"]
            print(f"{1000 / every:6.0f} {c:7.2f}{' (default)' if cut is None else '          '}"
                  f" {100 * m.rel_error_:6.3f} {sum(v * v for v in z.values()):7.0f} / {len(z)}  "
                  + "  ".join(f"{n} {z[n]:+.1f}" for n in top))


if __name__ == "__main__":
    main()
