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
import tomllib
import warnings
from pathlib import Path

from daq.protocol.control import ControllerGains
from ident.fitting import fit_models
from ident.loaders import make_experiment
from sim_drivers.offline import simulate
from sim_drivers.plant_config import load_plant
from trajectories.plan import plan_campaign
from trajectories.robot_campaign import RobotCampaign

ROOT = Path(__file__).resolve().parents[1]
#: (every n-th sample, cut-offs [Hz]; None: the default).
CASES = ((1, (62.5, None, 200.0)), (2, (62.5, 100.0, None, 150.0)), (4, (31.25, None)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=6)
    a = ap.parse_args()
    plant = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml")
    with open(ROOT / "examples" / "campaign.toml", "rb") as fh:
        camp = RobotCampaign.from_dict(tomllib.load(fh), "cut-off band")
    plan = plan_campaign(camp)
    gains = ControllerGains(**camp.gains_kwargs())
    runs = [simulate(plant, plan.reference, gains, payload_mass=p.mass_kg, payload_arm=p.arm_m,
                     seed=10 * a.seed + i) for i, p in enumerate(plan.payloads)]
    truth = plant.truth()
    print(f"seed {a.seed}: f_s [Hz], cut-off [Hz], error [%], sum z^2 / parameters, largest |z|")
    for every, cuts in CASES:
        exps = [make_experiment(f"run{i}.csv", r.t[::every], r.q[::every], r.tau_ref[::every],
                                payload_mass=p.mass_kg, payload_arm=p.arm_m,
                                q_ref=plan.reference.q[: r.t.size][::every])
                for i, (p, r) in enumerate(zip(plan.payloads, runs, strict=True))]
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
