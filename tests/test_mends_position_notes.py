"""The single-joint position-split notes and record (ident.fitting.fit_models,
ident.results.position_split_notes): the JSON's split is the one the note was made from, the
notes name the axis, and the validation files are named once per fit.

Simulated runs of examples/campaign.toml (the rx130l plant, sim_drivers.offline): the fit's
runs over a moved range (q >= 0.6 rad), the validation runs over the example campaign's, so
that a share of the validation rows lies outside the fit's positions (as
tests/test_position_extrapolation.py)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from example_campaign import ROOT

from daq.app.cli import main
from ident.cli_robot import fit_files
from ident.fitting import fit_models
from ident.loaders import parse_mapping
from ident.results import POSITION_OUTSIDE_SHARE, position_split_notes
from ident.robot.loaders import RawRobotRun, RobotPayloadData
from tests.conftest import shared_path
from tests.test_position_extrapolation import _moving_q, _runs
from trajectories.robot import load_robot


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


def test_notes_name_the_axis_and_the_files_once(outside_fit):
    """``fit_models(axis=...)``: each model's note names the axis; the validation files are
    named in the first note only, the next says "the same files"."""
    _, fit, val = outside_fit
    rep = fit_models(fit, ("usual", "paper"), validation=val, table_iv=False, axis="axis 2")
    notes = [n for n in rep.notes if n.startswith("validation, ")]
    assert [n.split(":")[0] for n in notes] == ["validation, axis 2 (usual model)",
                                                "validation, axis 2 (paper model)"], notes
    files = ", ".join(e.source for e in val)
    assert sum(n.count(files) for n in notes) == 1 and files in notes[0], notes
    assert "of the rows of the same files lie outside" in notes[1], notes


KUKA = ["recorded_2020-10-21_FF_A_08ms.mat", "recorded_2020-10-21_FF_B_08ms.mat",
        "recorded_2020-10-21_FF_C_08ms.mat"]


@pytest.mark.parametrize("row", [0, 3])
def test_kuka_single_joint_notes_name_the_axis(tmp_path, capfd, row):
    """The real KUKA KR300 (``../shared``; skipped without it), ``jointid fit`` on one axis
    of the 6-axis MAT files (row ``row`` of the maps: A1, A4), both models, A fitted, B and C
    validated: every position note names the axis by its mapped path, the files are named
    once, and the share in the notes is the files' own (positions where the axis moves)."""
    data = shared_path("data", "kuka_kr300_weigand2021")
    a, b, c = (str(data / f) for f in KUKA)
    maps = [f"t=rec.time_cont,q=rec.act_pos_mot_deg[{row}],q_ref=rec.ref_pos_deg[{row}]",
            f"tau=rec.act_torque_abs_nm[{row}]"]
    out = tmp_path / "fit.json"
    code = main(["fit", a, "--model", "both", "--q-unit", "deg", "--gain", f"para.u[{row}]",
                 "--map", maps[0], "--map", maps[1], "--cutoff", "5", "--decimation", "4",
                 "--validate", b, c, "--json", str(out)])
    _, err = capfd.readouterr()
    assert code == 0, err
    rec = json.loads(out.read_text())
    notes = [n for n in rec["notes"] if n.startswith("validation, ")]
    kw = dict(mapping=parse_mapping(maps), gain=f"para.u[{row}]", q_unit="deg")
    qf, qv = _moving_q([a], kw), _moving_q([b, c], kw)
    raw = float(np.mean((qv < qf.min()) | (qv > qf.max())))
    assert raw > POSITION_OUTSIDE_SHARE + 0.05, raw  # both models get a note
    axis = f"axis rec.act_pos_mot_deg[{row}]"
    assert [n.split(":")[0] for n in notes] == [f"validation, {axis} (usual model)",
                                                f"validation, {axis} (paper model)"], notes
    names = f"{KUKA[1]}, {KUKA[2]}"
    assert sum(n.count(names) for n in notes) == 1 and names in notes[0], notes
    for n, name in zip(notes, ("usual", "paper"), strict=True):
        share = int(re.search(r": (\d+) % of the rows", n).group(1))
        sp = rec["models"][name]["validation_position_split"]
        assert share == round(100 * sp["share_outside"]), (n, sp)
        assert abs(sp["share_outside"] - raw) < 0.05, (sp, raw)


def test_kuka_robot_fit_names_the_files_once():
    """The real KUKA KR300 through the robot path, both models (``../shared``; skipped
    without it): the joints' position notes of both models name the validation files once,
    in the first; each note names its joint and model."""
    data = shared_path("data", "kuka_kr300_weigand2021")
    a, b, c = (str(data / f) for f in KUKA)
    robot = load_robot(ROOT / "examples" / "robots" / "kuka_kr300_r2500.toml")
    out = fit_files(robot, [a], [b, c], model="both", q_unit="deg", mapping=parse_mapping(
        ["t=rec.time_cont,q=rec.act_pos_mot_deg,tau=rec.act_torque_abs_nm,"
         "q_ref=rec.ref_pos_deg"], robot=True))
    notes = [n for n in out["notes"] if n.startswith("validation, ")]
    noted = {(n.split(" ")[1], n.split("(")[1].split(" ")[0]) for n in notes}
    for name in ("usual", "paper"):
        for joint, sp in out["models"][name]["validation_position_split"].items():
            assert ((joint, name) in noted) == (sp["share_outside"] > POSITION_OUTSIDE_SHARE)
    assert len({m for _, m in noted}) == 2, notes  # notes of both models
    names = f"{KUKA[1]}, {KUKA[2]}"
    assert sum(n.count(names) for n in notes) == 1 and names in notes[0], notes
    assert all("of the rows of the same files" in n for n in notes[1:]), notes
