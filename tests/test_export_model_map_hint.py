"""``jointid export-model`` on a record of a MAT/CSV fit made with ``--map``/``--q-unit``.

A record written before ``"reading"`` does not keep the fit's ``--map`` and ``--q-unit``;
export-model reads the inputs again, so without them the read fails. The refusal must say
what to do (give export-model the fit's ``--map``/``--q-unit``), in one line, exit 2, nothing
written (README, "Commands"; docs/model-export.md). A newer record keeps them and
export-model reads the inputs with them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from daq.app.cli import main

ROOT = Path(__file__).resolve().parents[1]
ARM3 = ROOT / "examples" / "robots" / "arm3.toml"


def _record(tmp_path: Path) -> Path:
    """A robot record whose input is a CSV with its own column names (read with --map)."""
    t = np.arange(200) * 1e-3
    cols = {"time": t}
    for j in (1, 2, 3):
        cols[f"pos{j}"] = np.sin(t * j)
        cols[f"trq{j}"] = np.cos(t * j)
    csv = tmp_path / "run.csv"
    np.savetxt(csv, np.column_stack(list(cols.values())), delimiter=",",
               header=",".join(cols), comments="")
    rec = {"format": "jointid-robot-fit/2",
           "robot": {"name": "arm3", "source": str(ARM3), "path": str(ARM3),
                     "moving": ["j1", "j2", "j3"], "numbers": [1, 2, 3]},
           "inputs": [str(csv)], "validation_inputs": [], "method": "wls", "q_s": 0.03,
           "preprocessing": {}, "models": {"usual": {"parameters": {"FV1": {"value": 1.0}}}}}
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(rec))
    return path


def test_export_model_without_the_fits_map_says_to_give_it(tmp_path, capfd):
    fit = _record(tmp_path)
    out = tmp_path / "model"
    assert main(["export-model", str(fit), "-o", str(out)]) == 2
    err = capfd.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert str(fit) in err and "--map" in err and "--q-unit" in err
    assert "give export-model" in err, err
    assert not out.exists() and not list(tmp_path.glob(".model.part-*"))


def test_export_model_given_a_binary_file_is_one_line(tmp_path, capfd):
    """A log (or any non-text file) given as FIT.json: one line naming it and what was
    expected, exit 2, nothing written (before: a UnicodeDecodeError traceback, exit 1)."""
    log = tmp_path / "run_payload0.mcap"
    log.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)))
    out = tmp_path / "model"
    assert main(["export-model", str(log), "-o", str(out)]) == 2
    err = capfd.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert str(log) in err and "jointid fit --robot" in err, err
    assert not out.exists()


def test_the_record_keeps_the_fits_map_and_export_model_reads_with_it(tmp_path):
    """``jointid fit --robot`` keeps its ``--map``/``--q-unit`` in the record (``"reading"``)
    and export-model reads the inputs again with them when not given: the same runs as with
    the options given."""
    from ident.cli_export_model import _read_inputs
    from ident.cli_robot import fit_files
    from ident.loaders import parse_mapping
    from trajectories.robot import load_robot

    rec = json.loads(_record(tmp_path).read_text())
    robot = load_robot(ARM3)
    mapping = parse_mapping(["t=time", "q1=pos1,q2=pos2,q3=pos3",
                             "tau1=trq1,tau2=trq2,tau3=trq3"], robot=True)
    given = _read_inputs(tmp_path / "fit.json", rec, robot, "usual", mapping, "rad")
    rec["reading"] = json.loads(json.dumps({"map": mapping, "q_unit": "rad"}))  # as written
    kept = _read_inputs(tmp_path / "fit.json", rec, robot, "usual", None, None)
    assert len(kept) == len(given) == 1
    np.testing.assert_array_equal(kept[0].q, given[0].q)
    np.testing.assert_array_equal(kept[0].tau, given[0].tau)
    # fit_files writes it, as the JSON keeps it
    from robot_campaigns import write_arm_csv

    from tests.test_qs_joints_refine import drag_runs
    csv = write_arm_csv(drag_runs(11)[0], tmp_path / "arm.csv")
    out = fit_files(robot, [csv], model="usual", q_unit="rad", prune=False,
                    feasibility=False, sigma_blocks=0)
    assert out["reading"] == {"map": None, "q_unit": "rad"}
