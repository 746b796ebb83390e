"""Cross-validation outside the fit's positions (found on the real KUKA KR300 axis A1: the
fit's rows span q = 0..46 deg, the validation files -34..0 deg; the gravity columns of the
narrow range were nearly collinear with the friction constants and the CV read 4778 %).
``jointid fit`` now splits the validation error by the fit's position range and says so when
more than :data:`ident.results.POSITION_OUTSIDE_SHARE` of the validation rows lie outside.

Synthetic: the example campaign (examples/campaign.toml) with every segment moved to
q >= 0.6 rad for the fit (it still crosses pi/2, where the gravity torque changes sign), and
validated on the full campaign (q down to -0.9 rad: rows the fit never visited) or on the
moved campaign again (another seed: inside). The share is computed here from the designs'
positions and, independently, from the simulated runs' positions."""

from __future__ import annotations

import json
import re
import tomllib

import numpy as np
import pytest
from example_campaign import ROOT, payload_experiments

from daq.app.cli import main
from daq.protocol.control import ControllerGains
from ident.api import load
from ident.cli_robot import fit_files
from ident.fitting import fit_models
from ident.loaders import parse_mapping
from ident.results import POSITION_OUTSIDE_SHARE, position_split
from ident.robot.loaders import RawRobotRun, RobotPayloadData
from sim_drivers.plant_config import load_plant
from tests.conftest import shared_path
from trajectories.plan import plan_campaign
from trajectories.robot import load_robot
from trajectories.robot_campaign import RobotCampaign

NOTE = "validation, paper model: "
LOW = 0.6  # [rad] the moved campaign's lower end


def _moving_q(files: list[str], kw: dict) -> np.ndarray:
    """The files' positions while the axis moves (|dq| above 2 % of its peak, by finite
    differences), loaded with ``kw``."""
    qs = []
    for e in load(files, **kw):
        dq = np.abs(np.gradient(e.q, e.t))
        qs.append(e.q[dq > 0.02 * dq.max()])
    return np.concatenate(qs)


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
    plan = plan_campaign(camp)
    plant = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml")
    gains = ControllerGains(**camp.gains_kwargs())
    return payload_experiments(plant, plan, gains, seed,
                               name=f"{'m' if moved else 'e'}{seed}p{{i}}.csv")


@pytest.fixture(scope="module")
def fit_runs():
    return _runs(True, 5)


@pytest.mark.parametrize("seed", [21, 33])
def test_validation_outside_the_fit_positions_is_said(fit_runs, seed):
    val = _runs(False, seed)
    rep = fit_models(fit_runs, ("paper",), validation=val, table_iv=False)
    d, vd = rep.designs["paper"], rep.validation_designs["paper"]
    lo, hi = d.signals.q.min(), d.signals.q.max()
    share = float(np.mean((vd.signals.q < lo) | (vd.signals.q > hi)))
    # independently: the simulated runs' positions against the fit runs' range
    qf = np.concatenate([e.q for e in fit_runs])
    qv = np.concatenate([e.q for e in val])
    raw = float(np.mean((qv < qf.min()) | (qv > qf.max())))
    assert share > POSITION_OUTSIDE_SHARE and abs(share - raw) < 0.05, (share, raw)
    # the fit's rows reach the moved campaign's lower end but for the turn-around rows
    # slower than the design's dq_min
    assert LOW <= lo < LOW + 0.1, lo
    notes = [n for n in rep.notes if n.startswith(NOTE)]
    assert len(notes) == 1, rep.notes
    assert f"{100 * share:.0f} % of the rows of " in notes[0], notes[0]
    js = rep.to_json()["models"]["paper"]["validation_position_split"]
    assert js["share_outside"] == pytest.approx(share)
    assert js["q_fit_range"] == pytest.approx([lo, hi])
    # the two parts recompose the headline validation error (the same rows, not changed)
    rho = vd.Y - rep.models["paper"].predict(vd)
    out = (vd.signals.q < lo) | (vd.signals.q > hi)
    y2 = np.sum(vd.Y ** 2)
    whole = np.sqrt((js["error_outside"] ** 2 * np.sum(vd.Y[out] ** 2)
                     + js["error_inside"] ** 2 * np.sum(vd.Y[~out] ** 2)) / y2)
    assert whole == pytest.approx(np.linalg.norm(rho) / np.sqrt(y2), rel=1e-9)
    assert whole == pytest.approx(rep.errors("paper")["validation"], rel=1e-9)


def test_validation_inside_the_fit_positions_gets_no_note(fit_runs):
    val = _runs(True, 41)
    rep = fit_models(fit_runs, ("paper",), validation=val, table_iv=False)
    assert not any(n.startswith(NOTE) for n in rep.notes), rep.notes
    js = rep.to_json()["models"]["paper"]["validation_position_split"]
    assert js["share_outside"] <= POSITION_OUTSIDE_SHARE


def test_position_split_counts_only_positions():
    """The split reads q alone: the torque and residual only enter the errors."""
    q_fit = np.linspace(0.0, 1.0, 50)
    q_val = np.array([-0.5, 0.2, 0.5, 1.5])
    y = np.array([1.0, 2.0, 2.0, 1.0])
    rho = np.array([1.0, 0.2, 0.0, 1.0])
    sp = position_split(q_fit, q_val, y, rho)
    assert sp["share_outside"] == 0.5 and sp["rows_outside"] == 2
    assert sp["error_outside"] == pytest.approx(1.0)
    assert sp["error_inside"] == pytest.approx(0.2 / np.sqrt(8))
    assert sp["q_fit_range"] == [0.0, 1.0]


def test_kuka_a1_validation_outside_the_fit_positions(tmp_path, capfd):
    """The real KUKA KR300 axis A1, single-joint paper model fit on file A, validated on B
    and C (``../shared``; skipped without it): A moves A1 over q = 0..46 deg, B and C over
    -34..0 deg. The note gives the share of the validation rows outside (about 96 %: checked
    against the files' own positions here) and the error of each part; the one-sign note
    reads the model's quadrant (the load of A1 keeps one sign on the fit's rows, which is
    why tau_off is not separable from c_m, c_g; eq. 26's proxy sign(tau dq) of the measured
    torque put 43 % of them on the other side and no note was given)."""

    data = shared_path("data", "kuka_kr300_weigand2021")
    a, b, c = (str(data / f"recorded_2020-10-21_FF_{x}_08ms.mat") for x in "ABC")
    maps = ["t=rec.time_cont,q=rec.act_pos_mot_deg[0],q_ref=rec.ref_pos_deg[0]",
            "tau=rec.act_torque_abs_nm[0]"]
    out = tmp_path / "a1.json"
    code = main(["fit", a, "--model", "paper", "--q-unit", "deg", "--gain", "para.u[0]",
                 "--map", maps[0], "--map", maps[1], "--cutoff", "5", "--decimation", "4",
                 "--validate", b, c, "--json", str(out)])
    _, err = capfd.readouterr()
    assert code == 0, err
    rec = json.loads(out.read_text())
    # the command line names the axis by its mapped position (ident.cli._axis_label)
    notes = [n for n in rec["notes"]
             if n.startswith("validation, axis rec.act_pos_mot_deg[0] (paper model): ")]
    assert len(notes) == 1, rec["notes"]
    js = rec["models"]["paper"]["validation_position_split"]
    # independently: the files' own positions where the axis moves (|dq| above 2 % of its
    # peak, by finite differences; the fit leaves the rows at rest out, and B and C rest
    # at q = 0, inside A's range); 0.05: the fit's own velocity threshold and filter differ
    kw = dict(mapping=parse_mapping(maps), gain="para.u[0]", q_unit="deg")

    qf, qv = _moving_q([a], kw), _moving_q([b, c], kw)
    raw = float(np.mean((qv < qf.min()) | (qv > qf.max())))
    assert raw > 0.9 and abs(js["share_outside"] - raw) < 0.05, (js, raw)
    share = int(re.search(r": (\d+) % of the rows", notes[0]).group(1))
    assert share == round(100 * js["share_outside"])
    # the rows outside carry the cross-validation error, the few inside far less of it
    assert js["error_outside"] > 10 * js["error_inside"]
    assert js["error_outside"] >= rec["models"]["paper"]["validation_rel_error"]
    assert any("keeps one sign" in n for n in rec["notes"])


def _robot_runs(exps):
    return [RawRobotRun(e.source, e.t, e.q[:, None], e.tau[:, None],
                        payload=(RobotPayloadData(float(e.payload_mass), arm_m=float(e.payload_arm))
                                 if e.payload_mass else RobotPayloadData()))
            for e in exps]


@pytest.mark.parametrize("outside", [True, False])
def test_robot_fit_splits_the_validation_by_position(fit_runs, outside):
    """``jointid fit --robot`` (``fit_files``) on the same runs as one-joint robot runs: the
    per-joint split in each model's record, the note for the validation outside (share
    computed here from the simulated runs' positions) and none for the one inside."""
    robot = load_robot(ROOT / "examples" / "robots" / "rx130l.toml")
    val = _runs(not outside, 21 if outside else 41)
    out = fit_files(robot, _robot_runs(fit_runs), _robot_runs(val), model="paper")
    (joint,) = out["models"]["paper"]["validation_position_split"]
    sp = out["models"]["paper"]["validation_position_split"][joint]
    notes = [n for n in out["notes"] if n.startswith(f"validation, {joint} (paper model): ")]
    if outside:
        qf = np.concatenate([e.q for e in fit_runs])
        qv = np.concatenate([e.q for e in val])
        raw = float(np.mean((qv < qf.min()) | (qv > qf.max())))
        assert abs(sp["share_outside"] - raw) < 0.05, (sp, raw)
        assert len(notes) == 1 and f"{100 * sp['share_outside']:.0f} % of the rows" in notes[0]
    else:
        assert sp["share_outside"] <= POSITION_OUTSIDE_SHARE and not notes, (sp, notes)


def test_kuka_robot_fit_splits_each_joint():
    """The real KUKA KR300 recordings through the robot path (A fitted, B and C validated,
    ``--model paper``; ``../shared``, skipped without it): A1 moves over 0..45 deg in A and
    below 0 in B and C (every validation row outside: a note), A5 inside (no note). The
    shares are checked against the files' own positions where each axis moves."""
    data = shared_path("data", "kuka_kr300_weigand2021")
    a, b, c = (str(data / f"recorded_2020-10-21_FF_{x}_08ms.mat") for x in "ABC")
    robot = load_robot(ROOT / "examples" / "robots" / "kuka_kr300_r2500.toml")
    out = fit_files(robot, [a], [b, c], model="paper", q_unit="deg", mapping=parse_mapping(
        ["t=rec.time_cont,q=rec.act_pos_mot_deg,tau=rec.act_torque_abs_nm,"
         "q_ref=rec.ref_pos_deg"], robot=True))
    split = out["models"]["paper"]["validation_position_split"]
    noted = {n.split(" ")[1] for n in out["notes"] if n.startswith("validation, ")}
    for k, joint in ((0, "A1"), (4, "A5")):
        kw = dict(mapping=parse_mapping([f"t=rec.time_cont,q=rec.act_pos_mot_deg[{k}]",
                                         f"tau=rec.act_torque_abs_nm[{k}]"]), q_unit="deg")

        qf, qv = _moving_q([a], kw), _moving_q([b, c], kw)
        raw = float(np.mean((qv < qf.min()) | (qv > qf.max())))
        assert abs(split[joint]["share_outside"] - raw) < 0.05, (joint, split[joint], raw)
        assert (joint in noted) == (raw > POSITION_OUTSIDE_SHARE), (joint, noted)
