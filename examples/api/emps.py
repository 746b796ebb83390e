"""EMPS benchmark with the Python API: the usual model, the published comparison, refinement.

Run from a checkout (the data live in ../shared/data/emps, or give their folder)::

    python examples/api/emps.py [DATA_DIR]

Same numbers as ``jointid fit DATA_EMPS.mat --joint prismatic --map q=qm,tau=vir --gain gtau
--model usual --cutoff 100 --decimation 10 --dq-min 0 --no-sign-check --validate
DATA_EMPS_PULSES.mat --refine --max-steps 4`` (README, "Fitting foreign data").
"""

from __future__ import annotations

import sys
from pathlib import Path

from ident.api import JointModel, load

#: The reference identification of Janot, Gautier & Brunot (2019), EMPS script outputs:
#: M [kg], F_V [N s/m], F_C [N], offset [N].
PUBLISHED = {"J": 95.1089, "F_V": 203.5034, "F_C": 20.3935, "tau_off": -3.1648}


def main(argv: list[str]) -> int:
    here = Path(__file__).resolve()
    data = Path(argv[0]) if argv else here.parents[3] / "shared" / "data" / "emps"
    if not (data / "DATA_EMPS.mat").exists():
        print(f"EMPS data not found in {data}; pass their folder as argument")
        return 1
    # MATLAB variables: position qm [m], force reference vir times the gain gtau [N]
    kw = dict(mapping={"q": "qm", "tau": "vir"}, gain="gtau", joint="prismatic")
    train = load(data / "DATA_EMPS.mat", **kw)
    valid = load(data / "DATA_EMPS_PULSES.mat", **kw)

    # the benchmark's preprocessing: 100 Hz Butterworth, decimation 10, no stiction removal
    est = JointModel(model="usual", joint="prismatic", cutoff=100.0, decimation=10,
                     dq_min=0.0, sign_check=False)
    est.fit(train, validation=valid)

    print(f"{'parameter':<10}{'jointid':>12}{'2 sigma':>10}{'published':>12}{'diff %':>9}")
    for name, ref in PUBLISHED.items():
        v, s = est.params_[name], 2 * est.params_std_[name]
        print(f"{name:<10}{v:>12.4f}{s:>10.3f}{ref:>12.4f}{100 * (v - ref) / abs(ref):>9.3f}")
    print(f"relative error {est.rel_error_:.4f} on {est.n_samples_} samples, "
          f"validation {est.validation_rel_error_:.4f} (score {est.score(valid):.4f})")

    refined = est.refine(max_steps=4)
    print()
    for s in refined.refinement_.steps:
        print(f"step: {s.effect:<26} {s.rel_error_before:.4f} -> {s.rel_error_after:.4f}  "
              f"validation {s.validation_rel_error_before:.4f} -> "
              f"{s.validation_rel_error_after:.4f}")
    print(f"refined: relative error {refined.rel_error_:.4f}, "
          f"validation {refined.validation_rel_error_:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
