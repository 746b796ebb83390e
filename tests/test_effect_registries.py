"""Effects are found by registries: one module per effect on each side
(``ident/effects/``, ``sim_drivers/effects/``), and adding an effect is adding those two
files — shown by building the worked example of docs/refinement.md ("Adding an effect")
into a copy of the packages and checking that the refinement finds it in simulated data of
the single joint, that the n-dof arm simulator applies it (inverse model = applied torque),
and that the n-dof model fits it on a joint of the arm within 2σ of the truth
(``ident.robot.refit``)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import pytest

import ident.effects as ident_effects
import sim_drivers.effects as plant_effects
from sim_drivers import PlantConfigError
from sim_drivers.plant_config import EFFECT_TYPES, Effects, default_plant, plant_from_dict

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "refinement.md"


def _modules(folder: Path) -> set[str]:
    return {p.stem for p in folder.glob("*.py") if not p.stem.startswith("_")}


def test_ident_registry_is_exactly_the_effect_modules():
    regs = ident_effects.registry()
    assert {r.name for r in regs} == _modules(ROOT / "ident" / "effects")
    assert set(ident_effects.EFFECT_MODULES) == _modules(ROOT / "ident" / "effects")
    # one registration per module, named after it
    assert all(r.module == f"ident.effects.{r.name}" for r in regs)
    orders = [r.order for r in regs]
    assert orders == sorted(orders) and len(set(orders)) == len(orders)
    # the candidate order of the refinement loop (results depend on it)
    assert [r.name for r in regs] == [
        "position_ripple", "spring", "position_smooth", "directional_viscous",
        "quadratic_viscous", "stribeck", "warm_up", "quadrant_load", "quadrant_coulomb",
        "quadrant_load_stribeck", "torque_lag", "generic",
    ]


def test_plant_registry_is_exactly_the_effect_modules():
    regs = plant_effects.registry()
    names = [e.name for e in regs]
    assert set(names) == _modules(ROOT / "sim_drivers" / "effects")
    assert all(e.module == f"sim_drivers.effects.{e.name}" for e in regs)
    # the plant file, PlantParams.effects and with_effect know exactly these, in order
    assert list(EFFECT_TYPES) == names == [f.name for f in fields(Effects)]
    assert names == ["position_ripple", "spring", "warm_up", "asymmetric_viscous",
                     "quadratic_viscous", "torque_lag"]
    p = default_plant()
    assert list(p.as_dict()["effects"]) == names
    for e in regs:
        assert set(e.schema) == {f.name for f in fields(e.params)} - {"enabled"}
        assert p.with_effect(e.name).effects.enabled() == (e.name,)


def test_registering_twice_or_on_a_taken_order_is_refused():
    with pytest.raises(ValueError, match="order 20 already used by 'spring'"):
        ident_effects.register("another", order=20)(lambda ctx: [])
    spec = plant_effects.registry()[0]
    with pytest.raises(ValueError, match="registered twice"):
        plant_effects.register(type(spec)(**{**spec.__dict__, "module": "elsewhere"}))


def _doc_files() -> dict[str, str]:
    """The code blocks of docs/refinement.md whose first line names a file."""
    out = {}
    for block in re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S):
        first = block.splitlines()[0]
        if first.startswith("# ") and first.endswith(".py"):
            out[first[2:]] = block
    return out


SCRIPT = r"""
import json, sys, tomllib
from dataclasses import replace
import numpy as np
from daq.protocol.control import ControllerGains
import ident.effects, sim_drivers.effects
from ident.loaders import Experiment
from ident.api import JointModel
from sim_drivers.offline import simulate
from sim_drivers.plant_config import default_plant, plant_from_dict, PlantConfigError
from trajectories.robot_campaign import RobotCampaign
from trajectories.plan import plan_campaign

with open(sys.argv[1], "rb") as f:
    campaign = RobotCampaign.from_dict(tomllib.load(f), "campaign.toml").quick()
plan = plan_campaign(campaign)
p = default_plant()
# the usual friction (eq. 38): the new effect is the only undeclared one
f = replace(p.friction, a_m=1.0, a_g=1.0, b_m=0.0, b_g=0.0, c_m=18.0, c_g=18.0,
            d_m=0.0, d_g=0.0)
p = replace(p, friction=f).with_effect("position_coulomb", amplitude_Nm=6.0, phase_rad=0.5)
raw = p.as_dict()
raw["effects"]["position_coulomb"]["amplitude_Nm"] = -1.0
try:
    plant_from_dict(raw, "p.toml")
    error = None
except PlantConfigError as exc:
    error = str(exc)
gains = ControllerGains(**campaign.gains_kwargs())
runs = []
for i, pl in enumerate(plan.payloads):
    r = simulate(p, plan.reference, gains, payload_mass=pl.mass_kg, payload_arm=pl.arm_m,
                 seed=i)
    runs.append(Experiment(f"run{i}", r.t, r.q, r.tau_ref, pl.mass_kg, pl.arm_m))
est = JointModel(model="usual").fit(runs)
ref = est.refine(max_steps=1).refinement_
print(json.dumps({
    "ident": [r.name for r in ident.effects.registry()],
    "plant": [e.name for e in sim_drivers.effects.registry()],
    "error": error,
    "truth": p.truth_effects()["position_coulomb"],
    "steps": [s.to_json() for s in ref.steps],
    "rel_error": [ref.rel_error_initial, ref.rel_error_final],
}))
"""


ARM_SCRIPT = r"""
import dataclasses, json, sys
import numpy as np
from ident.effects.position_coulomb import PositionCoulomb
from ident.robot.base import base_parameters
from ident.robot.estimate import RobotModel
from ident.robot.refit import extra_name, refit_robot
from ident.robot.regressor import RobotRegressor
from ident.robot.signals import RobotPayloadData, RobotSignals
from sim_drivers.arm import (ArmEffects, ArmGains, ArmParams, Payload, inverse_arm_torque,
                             model_reference, simulate_arm)
from trajectories.robot import load_robot

robot = load_robot(sys.argv[1])
c = ArmParams.from_robot(robot).friction.c_m
usual = dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0, d_m=0.0, d_g=0.0, c_g=c)
A, PH, J = 0.5, 0.5, 0  # the docs' effect on joint 1 of the arm (yaw: the widest sweep)
params = dataclasses.replace(ArmParams.from_robot(robot, usual), effects=ArmEffects.make(
    3, position_coulomb={J: {"amplitude_Nm": A, "phase_rad": PH}}))
try:
    ArmEffects.make(3, position_coulomb={J: {"amplitude_Nm": -1.0}})
    error = None
except Exception as exc:
    error = f"{type(exc).__name__}: {exc}"
pays = (None, Payload(5.0, [0.0, 0.0, 0.05]))
ref = model_reference(params.model, center=[0.0, -1.9, 0.6], fraction=0.9, duration_s=10.0,
                      seed=3)
runs = [simulate_arm(params, ref, ArmGains.for_params(params, payload=p), payload=p,
                     seed=30 + i) for i, p in enumerate(pays)]
# the inverse model carries the effect: the applied torque on sliding samples
inv, eff = [], []
for r, p in zip(runs, pays):
    tau = inverse_arm_torque(params, r.q_true, r.dq_true, r.ddq_true, p, r.t)
    bare = inverse_arm_torque(dataclasses.replace(params, effects=None), r.q_true, r.dq_true,
                              r.ddq_true, p, r.t)
    sl = r.sliding
    inv.append(float(np.max(np.abs(tau - r.tau_applied)[sl])))
    want = A * np.cos(r.q_true[:, J] - PH) * np.sign(r.dq_true[:, J])
    eff.append(float(np.max(np.abs((tau - bare)[:, J] - want))))
    eff.append(float(np.max(np.abs(np.delete(tau - bare, J, axis=1)))))
reg = RobotRegressor(robot)
rng = np.random.default_rng(0)
noise = 0.01 * params.drive.torque_noise_std_Nm / 0.01
parts = {k: [] for k in ("t", "q", "dq", "ddq", "tau", "experiment")}
for i, r in enumerate(runs):
    tau = r.tau_applied + rng.standard_normal(r.tau_applied.shape) * noise
    for k, v in (("t", r.t), ("q", r.q_true), ("dq", r.dq_true), ("ddq", r.ddq_true),
                 ("tau", tau), ("experiment", np.full(r.t.size, i))):
        parts[k].append(v[::5])
sig = RobotSignals(**{k: np.concatenate(v) for k, v in parts.items()}, joints=reg.joints,
                   payloads=tuple(RobotPayloadData() if p is None else
                                  RobotPayloadData(p.mass, p.com, p.inertia) for p in pays),
                   source="arm3")
fit = RobotModel(reg, "usual", base=base_parameters(reg), dq_min=0.02).fit(sig)
rf = refit_robot(fit, sig, [(J, PositionCoulomb())])
out = {}
for n, true in (("F_Cq_cos", A * np.cos(PH)), ("F_Cq_sin", A * np.sin(PH))):
    i = rf.names_.index(extra_name(reg.joints[J], n))
    out[n] = [float(rf.coef_[i]), float(rf.std_[i]), float(true)]
print(json.dumps({"error": error, "inverse": inv, "effect": eff, "params": out,
                  "rel_error": [rf.rel_error["before"], rf.rel_error["after"]]}))
"""


def test_adding_an_effect_is_adding_two_files(tmp_path):
    files = _doc_files()
    assert set(files) == {"ident/effects/position_coulomb.py",
                          "sim_drivers/effects/position_coulomb.py"}
    for pkg in ("ident", "sim_drivers", "daq", "trajectories"):
        shutil.copytree(ROOT / pkg, tmp_path / pkg,
                        ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(ROOT / "examples", tmp_path / "daq" / "examples", dirs_exist_ok=True)
    for rel, code in files.items():
        assert not (ROOT / rel).exists()
        (tmp_path / rel).write_text(code)
    env = dict(os.environ, PYTHONPATH=str(tmp_path), OPENBLAS_NUM_THREADS="1")
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(ROOT / "examples" / "campaign.toml")],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert "position_coulomb" in res["ident"] and "position_coulomb" in res["plant"]
    assert res["error"].startswith("p.toml: effects.position_coulomb.amplitude_Nm: expected")
    step = res["steps"][0]
    assert (step["effect"], step["variable"]) == ("position_coulomb", "position")
    for name in ("F_Cq_cos", "F_Cq_sin"):
        got, true = step["parameters"][name], res["truth"][name]
        assert abs(got["value"] - true) < got["std2"] + 0.05 * 6.0, (name, got, true)
    assert res["rel_error"][1] < 0.9 * res["rel_error"][0]
    # the same two files: the n-dof arm simulator applies the effect (inverse model and
    # forward dynamics agree on the sliding samples), and the n-dof model fits it on any
    # joint (ident.robot.refit: the term's columns on joint 1, refitted with everything)
    out = subprocess.run(
        [sys.executable, "-c", ARM_SCRIPT, str(ROOT / "examples" / "robots" / "arm3.toml")],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    arm = json.loads(out.stdout.strip().splitlines()[-1])
    print("\narm:", arm)
    assert arm["error"].startswith("SimError: ArmEffects: position_coulomb.amplitude_Nm: "
                                   "expected"), arm["error"]
    assert max(arm["inverse"]) < 1e-8 and max(arm["effect"]) < 1e-12
    for name, (got, sd, true) in arm["params"].items():
        assert abs(got - true) <= 2 * sd, (name, got, sd, true)
    # over the yaw's +-1 rad sweep cos q stays close to a constant, so F_Cq_cos shares its
    # column with F_C (a large sigma); sin q does not: that coefficient is seen, and the refit
    # lowers the joint's error
    got, sd, _ = arm["params"]["F_Cq_sin"]
    assert abs(got) > 2 * sd
    assert arm["rel_error"][1]["j1"] < arm["rel_error"][0]["j1"]


def test_the_example_effect_is_not_in_the_packages():
    # the worked example stays in the docs: the registries above are the shipped effects
    assert "position_coulomb" not in {r.name for r in ident_effects.registry()}
    with pytest.raises(PlantConfigError, match="effects.position_coulomb"):
        plant_from_dict({**default_plant().as_dict(),
                         "effects": {"position_coulomb": {}}}, "p.toml")
