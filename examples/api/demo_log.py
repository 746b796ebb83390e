"""Fit and refine MCAP logs of ``jointid run`` / ``jointid demo`` with the Python API.

::

    python examples/api/demo_log.py runs/*.mcap        # logs you recorded
    python examples/api/demo_log.py                    # records a quick simulated campaign

Without arguments it first records, in the current folder (about a minute)::

    jointid run examples/campaign.toml --simulate examples/plant_rx130l.toml --quick \\
        --yes --overwrite --out runs-api-example

whose plant has one undeclared effect, a position ripple, that the refinement finds.
"""

from __future__ import annotations

import sys
from pathlib import Path

from daq.app.cli import main as jointid
from ident.api import JointModel, load

EXAMPLES = Path(__file__).resolve().parents[1]


def record(out: Path) -> list[Path]:
    """Run the quick example campaign against the simulated plant (the ``jointid run``
    command of the module docstring, in this process); its MCAP logs."""
    args = ["run", str(EXAMPLES / "campaign.toml"), "--simulate",
            str(EXAMPLES / "plant_rx130l.toml"), "--quick", "--yes", "--overwrite", "--out",
            str(out)]
    print("recording: jointid", " ".join(args), flush=True)
    if jointid(args) != 0:
        raise SystemExit("jointid run failed")
    return sorted(out.glob("*.mcap"))


def main(argv: list[str]) -> int:
    paths = [Path(a) for a in argv] or record(Path("runs-api-example"))
    runs = load(paths)   # MCAP: SI units, payloads and reference trajectory from the log
    for r in runs:
        print(f"{r.source}: {len(r)} samples, payload {r.payload_mass:g} kg")

    # the paper's model (eq. 42-43) with its a-priori q_s (section III.D)
    est = JointModel(model="paper", q_s=0.03).fit(runs)
    print(f"\n{est!r}\n  estimator {est.estimator_}, {est.n_samples_} equations, "
          f"relative error {est.rel_error_:.4f} (low velocity "
          f"{est.rel_error_bands_['low']:.4f}, high {est.rel_error_bands_['high']:.4f})")
    for name in ("a_m", "a_g", "c_m", "c_g", "F_V"):
        if name in est.params_:
            print(f"  {name:<6} = {est.params_[name]:9.4f} ± {2 * est.params_std_[name]:.3g} "
                  "(2σ)")

    refined = est.refine(max_steps=3)
    print()
    print(refined.refinement_.format_report())
    tau_hat = refined.predict(runs[:1])
    print(f"\nrefined model on {runs[0].source}: {tau_hat.size} predicted samples, "
          f"score {refined.score(runs[:1]):.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
