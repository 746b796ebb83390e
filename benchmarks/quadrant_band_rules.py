"""The paper model's quadrant band under one rule or two (issue 24): the single joint's
``ident.one_joint.SKIPPED_CHECK_BAND`` (10 % of the RMS load, only where the sign check is
skipped) against the robot path's ``RobotModel.quadrant_band`` (3 %, on top of the sign
check), each tried at the other's value.

- ``joint``: the friction-dominated joint of ``tests/test_friction_dominated.py`` (seeds 1
  and 21), paper model, with the single joint's band at each value of ``--bands``: the
  error and every friction parameter against the plant's truth, in sigmas and per cent.
- ``kuka``: ``jointid fit --robot`` on the KUKA recording A (``--model both --method wls
  --validate B C``, docs/robot-data.md) with the robot path's band (the CLI's 3 %) at each
  value: the paper model's per-axis fit error and band share, or its error.

Measured 2026-11-28 (the figures in ``ident/one_joint.py`` at ``SKIPPED_CHECK_BAND``).

Usage::

    python benchmarks/quadrant_band_rules.py joint --bands 0.03,0.10
    python benchmarks/quadrant_band_rules.py kuka --bands 0.03,0.10
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import sys
import tempfile
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
KUKA_DATA = ROOT.parent / "shared" / "data" / "kuka_kr300_weigand2021"
KUKA_MAP = "t=rec.time_cont,q=rec.act_pos_mot_deg,tau=rec.act_torque_abs_nm,q_ref=rec.ref_pos_deg"


def joint(bands: list[float], seeds: tuple[int, ...] = (1, 21)) -> None:
    """The friction-dominated joint's paper fit with the single joint's band at ``bands``."""
    sys.path.insert(0, str(ROOT / "tests"))
    from test_friction_dominated import TRUTH, friction_dominated

    import ident.one_joint as one_joint
    from ident.fitting import fit_models
    from ident.loaders import make_experiment
    from sim_drivers.offline import simulate

    txt = (ROOT / "sim_drivers" / "data" / "plant_default.toml").read_text()
    with tempfile.TemporaryDirectory() as tmp:
        plant, plan, gains = friction_dominated(txt, Path(tmp) / "plant.toml",
                                                "friction-dominated")
    saved = one_joint.SKIPPED_CHECK_BAND
    try:
        for seed in seeds:
            runs = [simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                             payload_arm=p.arm_m, seed=seed + i)
                    for i, p in enumerate(plan.payloads)]
            exps = [make_experiment(f"p{i}.csv", r.t, r.q, r.tau_ref, payload_mass=p.mass_kg,
                                    payload_arm=p.arm_m)
                    for i, (p, r) in enumerate(zip(plan.payloads, runs, strict=True))]
            for band in bands:
                one_joint.SKIPPED_CHECK_BAND = band
                rep = fit_models(exps, ("paper",), table_iv=False)
                m = rep.models["paper"]
                pars = ", ".join(
                    f"{n} {m.coef_[n]:.4g} ({(m.coef_[n] - TRUTH[n]) / m.std_[n]:+.1f} sigma, "
                    f"{100 * (m.coef_[n] / TRUTH[n] - 1):+.1f} %)"
                    for n in ("a_m", "a_g", "b_m", "b_g", "c_m", "c_g", "d_m", "d_g", "F_V"))
                passes = any("decided again" in n for n in rep.notes)
                print(f"seed {seed}, band {100 * band:g} %: error {100 * m.rel_error_:.2f} %, "
                      f"band rows {100 * (1 - rep_band_kept(rep)):.1f} %, requadranted "
                      f"{passes}; {pars}", flush=True)
    finally:
        one_joint.SKIPPED_CHECK_BAND = saved


def rep_band_kept(rep) -> float:  # noqa: ANN001 - a FitReport
    """The share of the rows the band keeps, from the fit's note (1 without a band)."""
    for n in rep.notes:
        hit = re.search(r"RMS load: ([0-9.]+) % of the rows", n)
        if hit:
            return 1 - float(hit.group(1)) / 100
    return 1.0


def kuka(bands: list[float]) -> None:
    """The KUKA recording A's paper model with the robot path's band at ``bands``."""
    import ident.robot.estimate as estimate
    from daq.app.cli import main

    if not KUKA_DATA.is_dir():
        raise SystemExit(f"{KUKA_DATA}: absent")
    init = estimate.RobotModel.__init__
    for band in bands:

        def patched(self, *a, _band=band, **kw) -> None:  # noqa: ANN001, ANN002, ANN003
            if kw.get("quadrant_band", 0.03) == 0.03:  # the CLI's n-dof value
                kw["quadrant_band"] = _band
            init(self, *a, **kw)

        estimate.RobotModel.__init__ = patched
        try:
            with tempfile.TemporaryDirectory() as tmp:
                out = Path(tmp) / "kuka.json"
                with contextlib.redirect_stdout(io.StringIO()):
                    code = main(["fit", "--robot",
                                 str(ROOT / "examples" / "robots" / "kuka_kr300_r2500.toml"),
                                 str(KUKA_DATA / "recorded_2020-10-21_FF_A_08ms.mat"),
                                 "--q-unit", "deg", "--map", KUKA_MAP, "--model", "both",
                                 "--method", "wls", "--validate",
                                 str(KUKA_DATA / "recorded_2020-10-21_FF_B_08ms.mat"),
                                 str(KUKA_DATA / "recorded_2020-10-21_FF_C_08ms.mat"),
                                 "--json", str(out)])
                paper = json.loads(out.read_text())["models"]["paper"]
        finally:
            estimate.RobotModel.__init__ = init
        if "error" in paper:
            print(f"band {100 * band:g} % (exit {code}): paper model refused: "
                  f"{paper['error'][:200]}", flush=True)
            continue
        fit = {a: round(100 * v, 1) for a, v in paper["rel_error"].items()}
        share = {a: round(100 * v, 1) for a, v in paper["quadrant_band_share"].items()}
        cv = {a: round(100 * v, 1) for a, v in paper["validation_rel_error"].items()}
        print(f"band {100 * band:g} %: fit (A) {fit}; CV (B+C) {cv}; rows in the band [%] "
              f"{share}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", choices=("joint", "kuka"))
    ap.add_argument("--bands", default="0.03,0.10", help="fractions of the RMS load")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    bands = [float(x) for x in args.bands.split(",")]
    (joint if args.case == "joint" else kuka)(bands)


if __name__ == "__main__":
    main()
