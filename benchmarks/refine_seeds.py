"""Issue 20's acceptance table: every simulated case of ``tests/refine_cases.py`` (clean, each
undeclared plant effect, position-dependent dry friction, load-dependent viscous friction, two
effects at once) over noise seeds 0-4: the refined error, the true structure's error on the
same samples, their ratio, the estimated noise floor and the steps taken. The figures quoted in
README.md and docs/refinement.md ("ratio 1.000 in all 50 cases", the true structure's error
over the noise floor estimated on the declared model's residual) come from this script;
``tests/test_refine_seeds.py`` asserts the [0.95, 1.10] band.

Usage: ``python benchmarks/refine_seeds.py [CASE,CASE|all] [SEED,SEED]`` (about 15 min on 2
cores).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from refine_cases import CASES, case_design, refined, true_structure_error  # noqa: E402


def main(argv: list[str]) -> int:
    cases = list(CASES) if len(argv) < 1 or argv[0] == "all" else argv[0].split(",")
    seeds = [int(x) for x in argv[1].split(",")] if len(argv) > 1 else [0, 1, 2, 3, 4]
    ratios, floors = [], []
    for c in cases:
        for sd in seeds:
            t0 = time.perf_counter()
            R = refined(c, sd)
            tr = true_structure_error(c, sd)
            ratios.append(R.rel_error_final / tr)
            names = [st.named_effect or st.effect for st in R.steps]
            floors.append(tr / R.noise_floor_initial)
            print(f"{c:20s} seed {sd}: final {R.rel_error_final:.5f} true {tr:.5f} "
                  f"ratio {ratios[-1]:.3f} floor {R.noise_floor:.5f} (true / initial floor "
                  f"{floors[-1]:.2f}) steps {names} "
                  f"{time.perf_counter() - t0:.1f} s", flush=True)
            refined.cache_clear()
            case_design.cache_clear()
    print(f"{len(ratios)} cases: ratio {min(ratios):.3f} .. {max(ratios):.3f}; true structure "
          f"/ floor estimated on the declared model's residual {min(floors):.2f} .. "
          f"{max(floors):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
