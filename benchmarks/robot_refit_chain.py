"""A cross-joint coupling and a per-joint drag inside the n-dof model, through the default
chain from files (docs/refinement.md section 8.10; tests/test_robot_refit_chain.py asserts
seeds 11-13 of the usual-friction arm).

usage: python benchmarks/robot_refit_chain.py {usual,paper} SEED...

The offline closed-loop 3-dof arm with the usual friction (``usual``) or the simulator's
default paper friction (``paper``, fitted with the paper model), plus joint 1's dry coupling
to q3 and F_VV = 3 on joint 3; three payload runs of 12 s as robot CSVs; ``fit_files`` (LS),
``refine_robot`` (2 steps per joint), the n-dof refit. One JSON line per seed: the found
effects, the refit's extra parameters [value, sigma], its error per joint against the true
structure's (the n-dof model plus the true columns, refitted on the same rows), and the true
structure's coupling and F_VV [value, sigma, truth].
"""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from ident.cli_robot import fit_files, refine_robot  # noqa: E402
from ident.robot.refit import extra_name, refit_robot  # noqa: E402
from tests.test_robot_refit import F_VV, _TrueDrag, _TrueLine  # noqa: E402
from tests.test_robot_refit_chain import ARM3, _files  # noqa: E402
from trajectories.robot import load_robot  # noqa: E402


def main(model: str, seeds: list[int]) -> None:
    for seed in seeds:
        with tempfile.TemporaryDirectory() as d:
            files, truth_c = _files(seed, Path(d), paper=model == "paper")
            out = fit_files(load_robot(ARM3), files, model=model, method="ls",
                            feasibility=False)
            fit = refine_robot(out, max_steps=2)["refit"]
            est, sig = out["_estimators"][model], out["_identification"]
            true = refit_robot(est, sig, [(0, _TrueLine()), (2, _TrueDrag())],
                               keep=est.fitted_rows(sig), prediction=est.predict(sig))
            res = {"seed": seed, "model": model,
                   "found": sorted(f"{x['joint']}:{x['effect']}" for x in fit["extras"]),
                   "after": {k: round(v, 5) for k, v in fit["rel_error"]["after"].items()},
                   "true_after": {k: round(v, 5) for k, v in true.rel_error["after"].items()}}
            res.update({n: [round(p["value"], 4), round(p["std"], 4)]
                        for n, p in fit["parameters"].items() if ":" in n})
            i = true.names_.index(extra_name("j1", "true_c"))
            k = true.names_.index(extra_name("j3", "true_F_VV"))
            res["true_struct_c"] = [round(float(true.coef_[i]), 4),
                                    round(float(true.std_[i]), 4), round(truth_c, 4)]
            res["true_struct_FVV"] = [round(float(true.coef_[k]), 4),
                                      round(float(true.std_[k]), 4), F_VV]
            print(json.dumps(res), flush=True)


if __name__ == "__main__":
    if len(sys.argv) < 3 or sys.argv[1] not in ("usual", "paper"):
        sys.exit("usage: python benchmarks/robot_refit_chain.py {usual,paper} SEED...")
    main(sys.argv[1], [int(s) for s in sys.argv[2:]])
