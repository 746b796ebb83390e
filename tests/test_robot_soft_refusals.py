"""The stages after ``jointid fit --robot`` that read the paper model with hard quadrants
refuse a soft one (``--quadrants soft``, :mod:`ident.robot.soft_fit`) in one line, non-zero
exit, nothing written: ``--refine``, ``--consistent``, ``jointid export-model``; the quadrant
band's share and note are not given for a soft fit (it has no band)."""

from __future__ import annotations

import json

import pytest
from robot_campaigns import ARM3, write_arm_csv
from test_robot_cutoff_band import simulated

from daq.app.cli import main
from ident import DataError
from ident.cli_robot import fit_files, refine_robot
from ident.robot import RobotIdentError
from ident.robot.consistent_fit import fit_consistent
from ident.robot.refit import refit_robot


@pytest.fixture(scope="module")
def soft_fit(tmp_path_factory):
    """The simulated arm3 logs (3 payload runs, 4 s) as CSV and the soft paper fit's
    ``--json`` record."""
    d = tmp_path_factory.mktemp("soft")
    _params, reg, runs, _truth = simulated("paper", 3, 4.0)
    files = [str(write_arm_csv(r, d / f"p{i}.csv")) for i, r in enumerate(runs)]
    fit_json = d / "fit.json"
    code = main(["fit", "--robot", str(ARM3), *files, "--model", "paper", "--quadrants",
                 "soft", "--sigma-blocks", "0", "--no-consistency", "--json", str(fit_json)])
    assert code == 0
    return reg, files, fit_json


def _one_line(capfd) -> str:
    _out, err = capfd.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, lines
    return lines[0]


@pytest.mark.parametrize("flag, words", [
    ("--refine", "jointid fit --robot: --refine is not available with --quadrants soft"),
    ("--consistent", "jointid fit --robot: --consistent is not available with --quadrants "
                     "soft"),
])
def test_fit_robot_refuses_refine_and_consistent_with_soft(soft_fit, tmp_path, capfd, flag,
                                                           words):
    _reg, files, _fit_json = soft_fit
    capfd.readouterr()
    out_json = tmp_path / "refused.json"
    code = main(["fit", "--robot", str(ARM3), *files, "--model", "paper", "--quadrants",
                 "soft", "--sigma-blocks", "0", "--no-consistency", flag, "--json",
                 str(out_json)])
    line = _one_line(capfd)
    assert code != 0 and words in line and "hard quadrants" in line, line
    assert not out_json.exists()


def test_export_model_refuses_a_soft_record(soft_fit, tmp_path, capfd):
    _reg, _files, fit_json = soft_fit
    rec = json.loads(fit_json.read_text())
    assert rec["models"]["paper"]["quadrants"] == "soft"
    capfd.readouterr()
    outdir = tmp_path / "model"
    code = main(["export-model", str(fit_json), "-o", str(outdir)])
    line = _one_line(capfd)
    assert code != 0, line
    assert (f"{fit_json}: model 'paper' was fitted with soft quadrants; export-model writes "
            "hard-quadrant friction only") in line
    assert not outdir.exists()


def test_soft_record_has_no_quadrant_band_share(soft_fit):
    _reg, _files, fit_json = soft_fit
    rec = json.loads(fit_json.read_text())
    assert "quadrant_band_share" not in rec["models"]["paper"]
    assert not any("within the quadrant band" in n for n in rec["notes"]), rec["notes"]


def test_api_stages_refuse_a_soft_model(soft_fit):
    """The Python API's own paths (``fit_files(consistent=True)``, :func:`refine_robot`,
    :func:`refit_robot`, :func:`fit_consistent`) refuse the soft model too."""
    reg, files, _fit_json = soft_fit
    with pytest.raises(DataError, match="--consistent is not available with --quadrants soft"):
        fit_files(reg.robot, files, model="paper", quadrants="soft", consistent=True,
                  feasibility=False, sigma_blocks=0)
    out = fit_files(reg.robot, files, model="paper", quadrants="soft", feasibility=False,
                    sigma_blocks=0)
    est = out["_estimators"]["paper"]
    assert est.quadrants == "soft"
    with pytest.raises(DataError, match="refine: the paper model was fitted with soft "
                                        "quadrants"):
        refine_robot(out, max_steps=1)
    assert "refinement" not in out
    sig = out["_identification"]
    with pytest.raises(RobotIdentError, match="refit_robot: the model was fitted with soft"):
        refit_robot(est, sig, [])
    with pytest.raises(RobotIdentError, match="fit_consistent: the model was fitted with soft"):
        fit_consistent(est, out["_signals"][0])
