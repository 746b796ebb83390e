"""The diagnostics ``jointid fit --robot`` runs on the paper model, on a soft-quadrant fit
(``--quadrants soft``, :mod:`ident.robot.soft_fit`), on the simulated arm3 logs of
tests/test_robot_soft_refusals.py (3 payload runs, 4 s): the sign check's selection-shift
refit is soft (like with like), the one-signed-load check reads the soft weights, the
consistency check's d^2 is the convex program's on the soft estimate, and the diagnostics of
the hard quadrants (quadrant drift, the load-jitter warning) are not given
(docs/robot-identification.md, "The stages after the fit read the paper model with hard
quadrants")."""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest
from robot_campaigns import write_arm_csv
from scipy.special import ndtr
from test_robot_cutoff_band import simulated

import ident.cli_robot as cli_robot
from ident.cli_robot import _one_signed_loads, fit_files
from ident.robot.consistency import ConsistencyReport, check_consistency
from ident.robot.estimate import THIN_QUADRANT
from ident.robot.load_jitter import JITTER_SHARE
from ident.robot.selection_shift import selection_shift


@pytest.fixture(scope="module")
def soft_out(tmp_path_factory):
    """The soft paper fit of the arm3 logs through the API (``fit_files``, the CLI's path),
    with the consistency check, and the model the sign check's shift was refitted with."""
    d = tmp_path_factory.mktemp("softdiag")
    _params, reg, runs, _truth = simulated("paper", 3, 4.0)
    files = [str(write_arm_csv(r, d / f"p{i}.csv")) for i, r in enumerate(runs)]
    refits = []
    real = cli_robot.selection_shift

    def spy(reported, unchecked):  # the real function; only its second fit is kept
        refits.append(unchecked)
        return real(reported, unchecked)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cli_robot, "selection_shift", spy)
        out = fit_files(reg.robot, files, model="paper", quadrants="soft", sigma_blocks=0)
    return out, refits


def test_selection_shift_refits_soft(soft_out):
    out, refits = soft_out
    rec = out["models"]["paper"]
    assert rec["quadrants"] == "soft"
    # the sign check left rows out on these logs (else there is no shift to compare)
    assert any(n.startswith("sign check, joint") for n in out["notes"]), out["notes"]
    assert len(refits) == 1
    other = refits[0]
    assert other.quadrants == "soft"
    assert np.all(np.isfinite(other.quadrant_sigma_)) and np.all(other.quadrant_sigma_ > 0)
    assert rec["sign_check_shift"] == selection_shift(rec["parameters"], other)


def test_soft_fit_gives_no_quadrant_drift(soft_out):
    out, _ = soft_out
    rec = out["models"]["paper"]
    assert rec["converged"] is True
    assert "quadrant_drift" not in rec and "rel_error_own_quadrants" not in rec
    assert not any("did not settle" in n or "evaluation limit" in n for n in out["notes"])


def test_soft_fit_gives_no_load_jitter_warning(soft_out):
    out, _ = soft_out
    share = out["models"]["paper"]["quadrant_jitter_share"]
    # the share is the data's (the first usual fit's load): above the hard fit's warning here
    assert share["j1"] > JITTER_SHARE
    assert not any("within the torque's jitter" in n for n in out["notes"]), out["notes"]


def test_one_signed_load_reads_the_soft_weights(soft_out):
    """j1's rows with a negative model load left out: their hard count is one-signed, the
    soft weight (fitted sigma_j1) gives them both signs; at sigma_j1's lower bound (the hard
    limit) the soft check flags j1 as the hard one does."""
    out, _ = soft_out
    est = out["_estimators"]["paper"]
    sig = out["_signals"][0]
    load = est.load_torque(sig)
    tau = sig.tau.copy()
    tau[~(load[:, 0] > 0), 0] = np.nan
    rows_sig = replace(sig, tau=tau)
    rows = est.fitted_rows(rows_sig)[:, 0]
    lj = load[rows, 0]
    assert rows.sum() > 100 and np.all(lj > 0)
    sigma = float(est.quadrant_sigma_[0])
    neg = float(np.mean(ndtr(-lj / sigma)))  # the soft weight's expected share of x < 0
    assert neg > THIN_QUADRANT, neg

    def flagged(model):
        rec = copy.deepcopy(out["models"]["paper"])
        notes: list[str] = []
        _one_signed_loads(model, rec, rows_sig, est.joints_, notes)
        return rec, notes

    rec, notes = flagged(est)
    assert "j1" not in rec["one_signed_load"], notes
    hard_limit = copy.copy(est)
    hard_limit.quadrant_sigma_ = est.quadrant_sigma_bounds_[:, 0].copy()
    rec, notes = flagged(hard_limit)
    assert "j1" in rec["one_signed_load"]
    assert {"c_m1", "c_g1", "OFF1"} <= set(rec["unidentified"])
    line = next(n for n in notes if n.startswith("paper model, j1: its load"))
    assert "expected, load jitter sigma" in line and "100.0 % of its fitted rows" in line


def test_consistency_of_a_soft_fit_is_the_convex_program(soft_out):
    out, _ = soft_out
    est = out["_estimators"]["paper"]
    cons = out["models"]["paper"]["consistency"]
    rep = check_consistency(est, tau_peak=out["_tau_peak"])
    assert rep.soft and rep.method == "lmi"  # not the local search's fallback
    assert cons["d2"] == pytest.approx(rep.d2, rel=1e-6, abs=1e-9)
    # the convex program's minimum is global: the local search cannot go below it
    local = check_consistency(est, tau_peak=out["_tau_peak"], method="cholesky")
    assert local.method == "cholesky"
    assert rep.d2 <= local.d2 + 1e-6 * max(local.d2, 1.0)
    assert cons["feasible"] is (rep.d2 <= rep.d2_limit)


def test_infeasible_soft_report_offers_no_export():
    hard = ConsistencyReport(feasible=False, d2=50.0, d2_limit=30.0).format()
    soft = ConsistencyReport(feasible=False, d2=50.0, d2_limit=30.0, soft=True).format()
    assert "jointid export-model (ident.robot.consistent_fit" in hard
    assert "export-model (" not in soft and "not for a soft-quadrant fit" in soft
