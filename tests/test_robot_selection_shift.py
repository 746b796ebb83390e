"""The paper model's truth-free check against the sign check's row choice
(:mod:`ident.robot.selection_shift`): on the simulated arm3 with the usual friction (a = 1,
b = d = 0, c_g = c_m: the paper model right, with more parameters) at 1 kHz the paper model
holds its sigma against the truth and the check stays silent; on the same runs subsampled to
250 Hz the paper model misses its sigma and the check says so (docs/robot-identification.md,
"The sign-check shift")."""

from __future__ import annotations

import warnings

import pytest
import scipy.stats
from test_robot_cutoff_band import logged, simulated, z_scores

from ident.cli_robot import fit_files
from ident.robot.selection_shift import SHIFT_Z


def _fit(params, reg, runs, every):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fit_files(reg.robot, logged(params, runs, every), model="both",
                         feasibility=False)


def _shift_notes(out):
    return [n for n in out["notes"] if "sign check's rows are kept" in n]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_silent_where_the_paper_model_holds_its_sigma(seed):
    params, reg, runs, truth = simulated("usual", seed, 8.0)
    out = _fit(params, reg, runs, 1)
    z, _ = z_scores(out, "paper", truth)
    assert sum(v * v for v in z.values()) < scipy.stats.chi2.ppf(0.999, len(z)), z
    shift = out["models"]["paper"]["sign_check_shift"]
    assert shift and max(abs(v) for v in shift.values()) < SHIFT_Z, shift
    assert _shift_notes(out) == []


@pytest.mark.slow
def test_named_where_the_paper_model_misses_its_sigma():
    params, reg, runs, truth = simulated("usual", 1, 8.0)
    out = _fit(params, reg, runs, 4)  # 250 Hz, the default cut-off 12.5 Hz
    z, _ = z_scores(out, "paper", truth)
    assert sum(v * v for v in z.values()) > scipy.stats.chi2.ppf(0.999, len(z)), z
    shift = out["models"]["paper"]["sign_check_shift"]
    assert max(abs(v) for v in shift.values()) > SHIFT_Z, shift
    (note,) = _shift_notes(out)
    assert note.startswith("paper model: ") and "sigma does not cover" in note, note
    # the usual model is not compared (the check is the paper model's)
    assert "sign_check_shift" not in out["models"]["usual"]
