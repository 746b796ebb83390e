"""The ripple's period searched on every row against on the subsample only (docs/refinement.md,
"The ripple's 2σ"): estimates, 2σ and z = (estimate - truth)/σ of amplitude, period and phase,
and the refinement's CPU time, both scans in one process.

    python benchmarks/ripple_period_scan.py SEED...     # about 3-8 CPU minutes a seed

Data: ``examples/campaign.toml`` (full, three payload runs) simulated offline on
``examples/plant_rx130l.toml`` (ripple 2.5 N m, period 2π/16 rad, phase 0.5 rad), noise seed
1000 SEED + payload index; the paper model at q_s = 0.03 rad/s by IDIM-IV (instruments on the
reference) and by least squares; one refinement step (``refine(max_steps=1)``) with
:func:`ident.effects.position_ripple.scan_period` (grid on ``Columns.fast``, bounded search on
every row) and with :func:`subsample_scan` (the same grid, the bounded search on
``Columns.fast`` too: the scan before). One JSON line per seed and fit.
"""

from __future__ import annotations

import json
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

import ident.effects.position_ripple as pr
from daq.protocol.control import ControllerGains
from ident.effects import Columns
from ident.effects._base import Effect
from ident.effects._scan import refine_1d
from ident.effects.position_ripple import PositionRipple
from ident.fitting import fit_models
from ident.refine import refine
from sim_drivers.plant_config import load_plant
from trajectories.plan import plan_campaign
from trajectories.robot_campaign import RobotCampaign

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from example_campaign import payload_experiments  # noqa: E402  (the tests' simulation)

KEYS = {"ripple_amplitude": "amplitude_Nm", "ripple_period": "period_rad",
        "ripple_phase": "phase_rad"}


def subsample_scan(cols: Columns, p0: float, span: float, tag: str) -> tuple[Effect, float]:
    """The scan before: grid and bounded search both on ``Columns.fast``."""
    f0, df = 1 / p0, 1.5 / span
    lo, hi = max(f0 - df, 0.5 * f0), f0 + df
    fast = cols.fast
    fgrid = np.linspace(lo, hi, 31)
    gains = np.array([fast.gain(PositionRipple(1 / f, tag)) for f in fgrid])
    i = int(np.argmax(gains))
    a, b = fgrid[max(i - 1, 0)], fgrid[min(i + 1, len(fgrid) - 1)]
    e, g = refine_1d(fast, lambda f: PositionRipple(1 / f, tag), a, b, fgrid[i],
                     float(gains[i]), 1e-7 * f0)
    return (e, g) if fast is cols else (e, cols.gain(e))


def main() -> None:
    with open(ROOT / "examples" / "campaign.toml", "rb") as f:
        campaign = RobotCampaign.from_dict(tomllib.load(f), "examples/campaign.toml")
    plan = plan_campaign(campaign)
    plant = load_plant(ROOT / "examples" / "plant_rx130l.toml")
    truth = plant.truth_effects()["position_ripple"]
    gains = ControllerGains(**campaign.gains_kwargs())
    scans = {"subsample": subsample_scan, "every_row": pr.scan_period}
    for seed in map(int, sys.argv[1:]):
        exps = payload_experiments(plant, plan, gains, 1000 * seed)
        for est in ("iv", "ls"):
            refs = [plan.reference.q] * 3 if est == "iv" else None
            rep = fit_models(exps, ("paper",), q_s=0.03, references=refs, table_iv=False)
            d, m = rep.designs["paper"], rep.models["paper"]
            row: dict = {"seed": seed, "est": est, "rows": len(d)}
            for name, scan in scans.items():
                pr.scan_period = scan  # propose() and the jackknife both call it
                try:
                    t0 = time.process_time()
                    ref = refine(d, m, max_steps=1)
                    cpu = time.process_time() - t0
                finally:
                    pr.scan_period = scans["every_row"]
                st = ref.steps[0] if ref.steps else None
                if st is None or st.effect != "position_ripple":
                    row[name] = {"error": "no ripple step", "cpu": cpu}
                    continue
                par = st.parameters
                row[name] = {"cpu": cpu, **{
                    k: [par[k]["value"], par[k]["std2"],
                        (par[k]["value"] - truth[v]) / (par[k]["std2"] / 2)]
                    for k, v in KEYS.items()}}
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
