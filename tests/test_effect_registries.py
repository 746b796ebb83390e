"""Effects are found by registries: one module per effect on each side
(``ident/effects/``, ``sim_drivers/effects/``), and adding an effect is adding those two
files — shown by building the worked example of docs/refinement.md ("Adding an effect")
into a copy of the packages and checking that the refinement finds it in simulated data."""

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
from trajectories.campaign import Campaign
from trajectories.plan import plan_campaign

with open(sys.argv[1], "rb") as f:
    campaign = Campaign.from_dict(tomllib.load(f), "campaign.toml").quick()
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
gains = ControllerGains(**campaign.control.gains_kwargs())
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


def test_the_example_effect_is_not_in_the_packages():
    # the worked example stays in the docs: the registries above are the shipped effects
    assert "position_coulomb" not in {r.name for r in ident_effects.registry()}
    with pytest.raises(PlantConfigError, match="effects.position_coulomb"):
        plant_from_dict({**default_plant().as_dict(),
                         "effects": {"position_coulomb": {}}}, "p.toml")
