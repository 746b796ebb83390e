"""The single-joint position-split notes and record (ident.fitting.fit_models,
ident.results.position_split_notes): the JSON's split is the one the note was made from, the
notes name the axis, and the validation files are named once per fit.

Simulated runs of examples/campaign.toml (the rx130l plant, sim_drivers.offline): the fit's
runs over a moved range (q >= 0.6 rad), the validation runs over the example campaign's, so
that a share of the validation rows lies outside the fit's positions (as
tests/test_position_extrapolation.py)."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from example_campaign import ROOT, payload_experiments

from daq.protocol.control import ControllerGains
from ident.cli_robot import fit_files
from ident.fitting import fit_models
from ident.results import POSITION_OUTSIDE_SHARE, position_split_notes
from ident.robot.loaders import RawRobotRun, RobotPayloadData
from sim_drivers.plant_config import load_plant
from trajectories.plan import plan_campaign
from trajectories.robot import load_robot
from trajectories.robot_campaign import RobotCampaign

LOW = 0.6  # [rad] the moved campaign's lower end


def _runs(moved: bool, seed: int):
    with open(ROOT / "examples" / "campaign.toml", "rb") as fh:
        d = tomllib.load(fh)
    if moved:
        for seg in d["segments"]:
            if seg["kind"] == "trapezoid":
                seg["range"] = [max(LOW, seg["range"][0]), seg["range"][1]]
            else:
                seg.update(amplitude=0.8, center=1.45)
    camp = RobotCampaign.from_dict(d, "moved" if moved else "example").quick()
    plant = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml")
    gains = ControllerGains(**camp.gains_kwargs())
    return payload_experiments(plant, plan_campaign(camp), gains, seed,
                               name=f"{'m' if moved else 'e'}{seed}p{{i}}.csv")


@pytest.fixture(scope="module")
def outside_fit():
    """Both models fitted on the moved runs, validated on the example campaign's."""
    fit, val = _runs(True, 5), _runs(False, 21)
    return fit_models(fit, ("usual", "paper"), validation=val, table_iv=False), fit, val


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.3g} %"


def test_json_split_is_the_notes(outside_fit):
    """``validation_position_split`` of each model is the split ``fit_models`` computed for
    its note (carried on the report, ``position_splits``), and the note's figures are the
    JSON's; the share is checked independently against the simulated runs' positions."""
    rep, fit, val = outside_fit
    js = rep.to_json()
    qf = np.concatenate([e.q for e in fit])
    qv = np.concatenate([e.q for e in val])
    raw = float(np.mean((qv < qf.min()) | (qv > qf.max())))
    assert set(rep.position_splits) == set(rep.models), rep.position_splits
    for name in rep.models:
        sp = js["models"][name]["validation_position_split"]
        kept = rep.position_splits[name]
        assert sp == kept, (name, sp, kept)  # the same figures, bit for bit
        assert abs(sp["share_outside"] - raw) < 0.05, (name, sp, raw)
        assert sp["share_outside"] > POSITION_OUTSIDE_SHARE
        (note,) = [n for n in rep.notes if n.startswith("validation, ")
                   and f"{name} model" in n.split(":")[0]]
        lo, hi = sp["q_fit_range"]
        assert f": {100 * sp['share_outside']:.0f} % of the rows of " in note, note
        assert f"q = {lo:.3g}..{hi:.3g} rad" in note, note
        assert f"their error {_pct(sp['error_outside'])}" in note, note
        assert f"inside {_pct(sp['error_inside'])}" in note, note


def _robot_runs(exps):
    return [RawRobotRun(e.source, e.t, e.q[:, None], e.tau[:, None],
                        payload=(RobotPayloadData(float(e.payload_mass),
                                                  arm_m=float(e.payload_arm))
                                 if e.payload_mass else RobotPayloadData()))
            for e in exps]


def test_one_builder_of_the_note_text(outside_fit):
    """The single-joint fit and the robot fit (``fit_files`` on the same runs as a one-joint
    robot) take their notes from the one builder, ``position_split_notes``: the notes are
    its text on the splits each path recorded, the files' names joined there."""
    rep, fit, val = outside_fit
    files = [e.source for e in val]
    mine = [n for n in rep.notes if n.startswith("validation, ")]
    assert mine == position_split_notes(
        [(f"{n} model", rep.position_splits[n]) for n in rep.models], files), mine
    assert ", ".join(files) in mine[0], mine  # the names, joined by the builder
    robot = load_robot(ROOT / "examples" / "robots" / "rx130l.toml")
    out = fit_files(robot, _robot_runs(fit), _robot_runs(val), model="paper")
    (joint,) = out["models"]["paper"]["validation_position_split"]
    sp = out["models"]["paper"]["validation_position_split"][joint]
    theirs = [n for n in out["notes"] if n.startswith("validation, ")]
    assert theirs == position_split_notes([(f"{joint} (paper model)", sp)], files), theirs
