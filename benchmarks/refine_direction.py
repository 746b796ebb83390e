"""The refinement's terms on a robot fit's decimated rows: the Coulomb coefficient after the
n-dof refit of the terms the refinement finds, on both chains (docs/robot-identification.md,
"The direction on the fit's rows").

Usage: ``python benchmarks/refine_direction.py [SEEDS]`` (default ``0,1``)

The simulated 3-dof arm (examples/robots/arm3.toml) with symmetric Stribeck friction the
usual model lacks, (c + d exp(-|dq|/0.03)) sign(dq) (c_g = c_m, d_g = d_m, a = 1, b = 0);
three payload runs of 12 s at 1 kHz (excitation seed 3), 1 % torque noise (noise seeds as
given). Per seed and chain (``columns``, the default; ``states``, ``--chain states``): the
usual model fitted by LS, each joint refined (``refine_joint``, 2 steps, as ``jointid fit
--robot --refine`` does on the fit's rows), the found terms refitted inside the n-dof model
(``refit_robot``); printed: the terms and their q_s, and FC_j's z-score against the truth
before (the n-dof fit) and after the refit. The terms read ``Signals.direction``: the fit's
own decimated sign column.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from robot_campaigns import ARM3_CENTRE, ARM3_PAYLOADS  # noqa: E402
from test_robot_states_chain import noisy_chains  # noqa: E402

from ident.robot.base import base_parameters  # noqa: E402
from ident.robot.estimate import RobotModel  # noqa: E402
from ident.robot.refine_joint import joint_coulomb, refine_joint  # noqa: E402
from ident.robot.refit import refit_robot  # noqa: E402
from ident.robot.regressor import RobotRegressor  # noqa: E402
from sim_drivers.arm import ArmGains, ArmParams, model_reference, simulate_arm  # noqa: E402
from trajectories.robot import load_robot  # noqa: E402

DURATION_S = 12.0  # [s]
EXCITATION_SEED = 3


def main(seeds: list[int]) -> None:
    warnings.simplefilter("ignore", UserWarning)
    robot = load_robot(ROOT / "examples" / "robots" / "arm3.toml")
    f0 = ArmParams.from_robot(robot).friction
    params = ArmParams.from_robot(robot, dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0,
                                              c_g=f0.c_m, d_g=f0.d_m))
    ref = model_reference(params.model, center=ARM3_CENTRE, fraction=0.9,
                          duration_s=DURATION_S, seed=EXCITATION_SEED)
    runs = [simulate_arm(params, ref, ArmGains.for_params(params, payload=p), payload=p,
                         seed=10 * EXCITATION_SEED + i) for i, p in enumerate(ARM3_PAYLOADS)]
    reg = RobotRegressor(robot)
    base = base_parameters(reg)
    c = params.friction.c_m  # [N m] the true Coulomb level per joint
    print(f"true c {np.round(c, 4)}, d {np.round(params.friction.d_m, 4)}, "
          f"q_s {float(params.friction.q_s[0])} rad/s")
    for seed in seeds:
        columns, states = noisy_chains(params, reg, runs, seed)
        chains = {"columns": columns, "states": states}
        for name, sig in chains.items():
            fit = RobotModel(reg, "usual", "ls", base=base).fit(sig)
            keep, pred = fit.fitted_rows(sig), fit.predict(sig)
            terms, found = [], []
            for j in range(3):
                vmax = float(np.abs(sig.dq[keep[:, j], j]).max())
                r_ = refine_joint(sig, pred, j, vmax=vmax, max_steps=2,
                                  coulomb=joint_coulomb(fit, j), keep=keep, cycle_s=0.001)
                terms += [(j, s.term) for s in r_.steps]
                found.append(", ".join(
                    s.named_effect + (f" q_s {s.term.q_s:.4f}" if hasattr(s.term, "q_s")
                                      else "") for s in r_.steps) or "-")
            rf = refit_robot(fit, sig, terms, prediction=pred, keep=keep)
            zs = []
            for j in range(3):
                n = f"FC{j + 1}"
                z0 = (fit.params_[n] - c[j]) / fit.std_[fit.names_.index(n)]
                k = rf.names_.index(n)
                zs.append(f"{n} z {z0:+6.2f} -> {(rf.coef_[k] - c[j]) / rf.std_[k]:+6.2f}")
            print(f"[{name} seed {seed}] found: " + " | ".join(found) + "\n    "
                  + "; ".join(zs), flush=True)


if __name__ == "__main__":
    main([int(x) for x in (sys.argv[1] if len(sys.argv) > 1 else "0,1").split(",")])
