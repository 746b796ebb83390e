"""The paper model's truth-free warning of quadrants blended by the low-pass
(:mod:`ident.robot.load_jitter`): on the simulated arm3 (paper friction on every joint, the
drives' log) the gravity-free base yaw, whose inertial load jitters across zero under the
closed loop, has more than :data:`JITTER_SHARE` of its rows within the torque's jitter above
the cut-off and is named; the shoulder and elbow, whose gravity load stays away from zero,
are not. docs/robot-identification.md, "Known limit: quadrants blended by the low-pass"."""

from __future__ import annotations

import json
import warnings

import pytest
from example_campaign import example_gains, payload_experiments, simulate_example_campaign
from test_robot_cutoff_band import logged, simulated

from daq.app.cli import main
from ident.cli_robot import fit_files
from ident.fitting import fit_models
from ident.robot.load_jitter import JITTER_SHARE
from tests.conftest import shared_path


@pytest.mark.parametrize("seed", [1, 2])
def test_the_fit_names_the_joint_whose_load_jitters_across_zero(seed):
    params, reg, runs, _ = simulated("paper", seed, 8.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = fit_files(reg.robot, logged(params, runs, 1), model="both", sigma_blocks=0,
                        feasibility=False, prune=False)
    share = out["models"]["paper"]["quadrant_jitter_share"]
    assert set(share) == {"j1", "j2", "j3"} and all(0 <= x <= 1 for x in share.values())
    assert share["j1"] > JITTER_SHARE, share
    assert share["j2"] < JITTER_SHARE / 2 and share["j3"] < JITTER_SHARE / 2, share
    named = [n for n in out["notes"] if "jitter above the cut-off" in n]
    assert len(named) == 1 and named[0].startswith("paper model, j1: "), named
    # the usual model has no quadrants: no share in its record
    assert "quadrant_jitter_share" not in out["models"]["usual"]


def test_single_joint_fit_applies_the_same_rule(tmp_path):
    """A joint is a 1-dof robot: ``jointid fit`` gives the same note. The example campaign's
    joint (gravity keeps its load away from zero) is not named; the real EMPS (a prismatic
    axis whose load is inertial only, long constant-velocity phases) is."""
    plant, plan, _ = simulate_example_campaign()
    exps = payload_experiments(plant, plan, example_gains(), 11, name="p{i}.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep = fit_models(exps, models=("usual", "paper"))
    assert not [n for n in rep.notes if "jitter above the cut-off" in n], rep.notes
    emps = shared_path("data", "emps")  # skips with a reason where ../shared is absent
    out = tmp_path / "emps.json"
    assert main(["fit", str(emps / "DATA_EMPS.mat"), "--joint", "prismatic", "--map",
                 "q=qm,tau=vir", "--gain", "gtau", "--json", str(out)]) == 0
    named = [n for n in json.loads(out.read_text())["notes"] if "jitter above the cut-off" in n]
    assert len(named) == 1 and named[0].startswith("paper model: "), named
