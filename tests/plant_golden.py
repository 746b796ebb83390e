"""Reference runs of the single-joint simulator, and the file that pins their numbers.

``tests/data/plant_golden.npz`` holds the outputs of these scenarios computed by the
single-joint plant as it was before it computed through the n-dof plant (issue 24: commit
b31155c, ``sim_drivers/plant.py`` with its own friction, stiction and integration). The test
``tests/test_plant_golden.py`` recomputes them with the code of today and compares.

Regenerate (only when a change of the numbers is intended and explained), here from the
sources of b31155c::

    mkdir /tmp/base && git archive b31155c | tar x -C /tmp/base
    cp tests/plant_golden.py /tmp/base/tests/ && (cd /tmp/base && python -m tests.plant_golden
    --write) && cp /tmp/base/tests/data/plant_golden.npz tests/data/

Scenarios: every undeclared effect on, stiction at reversals, a payload, the prismatic joint,
several noise seeds, a run started at rest inside the static band, the torque-driven
``JointPlant`` and the closed loop ``simulate`` / ``simulate_payloads``, and the inverse
model (``inverse_torque``, ``effect_torques``) on the recorded states.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from daq.protocol.control import ControllerGains
from sim_drivers.offline import simulate, simulate_payloads
from sim_drivers.plant import JointPlant, effect_torques, inverse_torque
from sim_drivers.plant_config import default_plant, plant_from_dict

GOLDEN = Path(__file__).parent / "data" / "plant_golden.npz"
#: Every STRIDE-th record is stored (a difference anywhere propagates through the state).
STRIDE = 5


def all_effects(p=None):
    """The default plant (or ``p``) with every undeclared effect on."""
    p = default_plant() if p is None else p
    p = p.with_effect("position_ripple", amplitude_Nm=5.0, period_rad=0.3927, phase_rad=0.5)
    p = p.with_effect("spring", stiffness_Nm_per_rad=40.0, rest_position_rad=0.1)
    p = p.with_effect("warm_up", fraction=0.3, time_constant_s=2.0)
    p = p.with_effect("asymmetric_viscous", F_V_pos=45.0, F_V_neg=35.0)
    p = p.with_effect("quadratic_viscous", F_VV=10.0)
    return p.with_effect("torque_lag", time_constant_s=0.002)


def prismatic():
    """A prismatic joint (no gravity) with ripple and asymmetric viscous friction."""
    raw = default_plant().as_dict()
    raw["joint"]["kind"] = "prismatic"
    raw["body"] = {"J": 12.0}
    raw["effects"] = {"position_ripple": {"enabled": True, "amplitude_Nm": 3.0,
                                          "period_rad": 0.05, "phase_rad": 0.2},
                      "asymmetric_viscous": {"enabled": True, "F_V_pos": 44.0,
                                             "F_V_neg": 30.0}}
    return plant_from_dict(raw, "<prismatic>")


def _reference(seconds: float, amp: float, f_hz: float, q0: float):
    t = np.arange(int(round(seconds * 1000))) * 0.001
    w = 2 * np.pi * f_hz
    return SimpleNamespace(t=t, q=q0 + amp * np.sin(w * t), dq=amp * w * np.cos(w * t),
                           ddq=-amp * w * w * np.sin(w * t))


GAINS = ControllerGains(kp=20000.0, kd=1000.0, J_ff=31.0, MX_ff=21.1, MY_ff=-0.8, Fc_ff=25.0,
                        Fv_ff=40.0)
GAINS_P = ControllerGains(kp=20000.0, kd=1000.0, J_ff=12.0, Fc_ff=25.0, Fv_ff=40.0)


def _stepped(params, q0: float, tau, *, seed: int, payload=(0.0, 0.0), substeps: int = 10):
    """JointPlant stepped with a torque profile: its per-cycle record (n, 9)."""
    jp = JointPlant(params, 0.001, substeps=substeps, seed=seed)
    jp.set_payload(*payload)
    jp.reset(q0)
    out = np.empty((len(tau), 9))
    for i, x in enumerate(tau):
        jp.step(float(x))
        out[i] = (jp.q, jp.dq, jp.ddq, jp.tau_applied, jp.regime, jp.ddq_start,
                  jp.tau_applied_start, jp.regime_start, jp.encoder_counts)
    return out


def _run_arrays(run) -> np.ndarray:
    return np.column_stack([run.counts, run.x, run.tau_applied, run.tau_noise, run.q_true,
                            run.dq_true, run.ddq_true, run.regime])


def _inverse(params, run) -> np.ndarray:
    args = (params, run.q_true, run.dq_true, run.ddq_true, run.payload_mass_kg,
            run.payload_arm_m, run.t)
    eff = effect_torques(*args)
    return np.column_stack([inverse_torque(*args), inverse_torque(*args, effects=False),
                            *[eff[k] for k in sorted(eff)]])


def compute() -> dict[str, np.ndarray]:
    """Every scenario's arrays, by name."""
    out: dict[str, np.ndarray] = {}
    t = np.arange(6000) * 0.001
    tau = 100 + 70 * np.sin(2 * np.pi * 0.4 * t) + 20 * np.sin(2 * np.pi * 2.3 * t)
    out["step_all_effects"] = _stepped(all_effects(), -1.0, tau, seed=3, payload=(3.4584, 1.277))
    out["step_default_20sub"] = _stepped(default_plant(), -1.0, tau, seed=4, substeps=20)
    hold = np.full(500, 250.0)  # inside the static band at q = 0.3: stays stuck
    out["step_stuck"] = _stepped(all_effects(), 0.3, hold, seed=5)
    hold_release = np.concatenate([hold, np.full(300, 450.0), np.full(300, -100.0)])
    out["step_stuck_plain"] = _stepped(default_plant(), 0.3, hold_release, seed=5)
    out["step_prismatic"] = _stepped(prismatic(), 0.0, 60 * np.sin(2 * np.pi * 0.7 * t),
                                     seed=6, payload=(2.0, 0.5))
    p = all_effects()
    ref = _reference(5.0, 0.8, 0.3, 0.2)
    run = simulate(p, ref, GAINS, payload_mass=3.4584, payload_arm=1.277, seed=7)
    out["sim_all_effects"] = _run_arrays(run)
    out["inv_all_effects"] = _inverse(p, run)
    for seed in (0, 11):
        run = simulate(default_plant(), ref, GAINS, seed=seed)
        out[f"sim_default_seed{seed}"] = _run_arrays(run)
    pp = prismatic()
    run = simulate(pp, _reference(4.0, 0.3, 0.5, 0.0), GAINS_P, payload_mass=2.0, seed=8)
    out["sim_prismatic"] = _run_arrays(run)
    out["inv_prismatic"] = _inverse(pp, run)
    pay = [SimpleNamespace(mass_kg=0.0, arm_m=0.0), (3.4584, 1.277)]
    runs = simulate_payloads(default_plant().with_effect("spring", stiffness_Nm_per_rad=30.0,
                                                         rest_position_rad=0.0),
                             _reference(3.0, 0.6, 0.4, -0.3), GAINS, pay, seed=9)
    for i, r in enumerate(runs):
        out[f"payloads_{i}"] = _run_arrays(r)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description="write tests/data/plant_golden.npz")
    ap.add_argument("--write", action="store_true")
    a = ap.parse_args()
    arrays = compute()
    if a.write:
        GOLDEN.parent.mkdir(exist_ok=True)
        np.savez_compressed(GOLDEN, **{k: v[::STRIDE] for k, v in arrays.items()})
        print(f"wrote {GOLDEN} ({GOLDEN.stat().st_size} bytes)")
    for k, v in arrays.items():
        print(k, v.shape)


if __name__ == "__main__":
    main()
