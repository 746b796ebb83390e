"""The Python API (ident.api.JointModel): fit returns self, fitted attributes equal the
``jointid fit`` JSON record on the same files, predict/score agree with the residual and the
validation error, refine returns a new fitted estimator with the effect the plant has."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from daq.app.cli import main
from daq.protocol.control import ControllerGains
from ident import DataError
from ident.api import JointModel, load
from ident.loaders import Experiment
from sim_drivers.offline import simulate
from sim_drivers.plant_config import load_plant
from trajectories.plan import plan_campaign
from trajectories.robot_campaign import RobotCampaign

ROOT = Path(__file__).resolve().parents[1]
RIPPLE = dict(amplitude_Nm=4.0, period_rad=2 * np.pi / 16, phase_rad=0.3)  # undeclared


@pytest.fixture(scope="module")
def csv_runs(tmp_path_factory):
    """Three payload runs and a validation run of the quick example campaign on the default
    plant plus a position ripple, as CSV files (t, q, tau, payload_kg, payload_arm_m)."""
    with open(ROOT / "examples" / "campaign.toml", "rb") as f:
        campaign = RobotCampaign.from_dict(tomllib.load(f), "campaign.toml").quick()
    plan = plan_campaign(campaign)
    plant = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml").with_effect(
        "position_ripple", **RIPPLE)
    gains = ControllerGains(**campaign.gains_kwargs())
    d = tmp_path_factory.mktemp("api")
    files = []
    for i, p in enumerate([*plan.payloads, plan.payloads[1]]):
        r = simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                     payload_arm=p.arm_m, seed=70 + i)
        path = d / f"run{i}.csv"
        cols = [r.t, r.q, r.tau_ref, np.full(len(r), p.mass_kg), np.full(len(r), p.arm_m)]
        np.savetxt(path, np.column_stack(cols), delimiter=",", fmt="%.10g",
                   header="t,q,tau,payload_kg,payload_arm_m", comments="")
        files.append(path)
    return files


@pytest.fixture(scope="module")
def fitted(csv_runs):
    train, val = load(csv_runs[:3]), load(csv_runs[3])
    est = JointModel(model="both")
    assert est.fit(train, validation=val) is est
    return est, train, val


def test_fitted_attributes_equal_the_cli_json(fitted, csv_runs, tmp_path):
    est, _, _ = fitted
    js = tmp_path / "fit.json"
    assert main(["fit", *map(str, csv_runs[:3]), "--validate", str(csv_runs[3]),
                 "--json", str(js)]) == 0
    rec = json.loads(js.read_text())["models"]["paper"]
    assert est.name_ == "paper" and set(est.models_) == {"usual", "paper"}
    assert list(est.coef_names_) == list(rec["parameters"])
    assert list(est.params_) == list(rec["parameters"])
    for k, n in enumerate(est.coef_names_):
        assert est.coef_[k] == rec["parameters"][n]["value"]
        assert est.std_[k] == rec["parameters"][n]["std"]
        assert est.rel_std_pct_[k] == rec["parameters"][n]["rel_std_pct"]
    for n, p in rec["parameters"].items():
        assert est.params_[n] == p["value"] and est.params_std_[n] == p["std"]
    assert est.rel_error_ == rec["rel_error"]
    assert est.validation_rel_error_ == rec["validation_rel_error"]
    assert est.rel_error_bands_["low"] == rec["rel_error_low_velocity"]
    assert est.n_samples_ == rec["samples"] == est.residual_.shape[0] == est.design_.Y.shape[0]
    assert est.estimator_ == rec["estimator"] == "ls" and est.q_s_ == 0.03
    assert est.report_.to_json()["models"]["paper"] == rec


def test_predict_and_score_agree_with_the_fit(fitted):
    est, train, val = fitted
    np.testing.assert_allclose(est.predict(train), est.design_.Y - est.residual_,
                               rtol=0, atol=1e-9 * np.abs(est.design_.Y).max())
    assert est.rel_error(train) == pytest.approx(est.rel_error_, rel=1e-12)
    # validation through predict/score is the JSON's validation error
    assert est.score(val) == pytest.approx(1.0 - est.validation_rel_error_, rel=1e-12)
    d = est.transform(val)
    assert est.predict(val).shape == d.Y.shape
    # the usual model is worse than the new one on the plant's new friction
    usual = JointModel(model="usual").fit(train, validation=val)
    assert usual.rel_error_ > est.rel_error_ and "F_C" in usual.params_
    assert usual.score(val) < est.score(val)


def test_refine_returns_a_new_estimator_with_the_ripple(fitted):
    est, train, val = fitted
    refined = est.refine(max_steps=1)
    assert refined is not est and not hasattr(est, "refinement_")
    step = refined.refinement_.steps[0]
    assert step.effect == "position_ripple"
    amp, period = step.parameters["ripple_amplitude"], step.parameters["ripple_period"]
    assert abs(amp["value"] - RIPPLE["amplitude_Nm"]) < amp["std2"] + 0.05 * RIPPLE["amplitude_Nm"]
    assert period["value"] == pytest.approx(RIPPLE["period_rad"], rel=2e-3)
    assert {"ripple_sin", "ripple_cos"} <= set(refined.coef_names_)
    assert "ripple_sin" not in est.params_
    assert refined.rel_error_ < est.rel_error_
    assert refined.validation_rel_error_ == refined.refinement_.validation_rel_error_final
    assert refined.validation_rel_error_ < est.validation_rel_error_
    # the refined estimator predicts with the added term's columns
    assert refined.score(val) == pytest.approx(1.0 - refined.validation_rel_error_, rel=1e-12)
    assert refined.predict(train).shape == (refined.n_samples_,)
    rec = refined.refinement_json()
    assert rec["model"] == "paper" and rec["steps"][0]["effect"] == "position_ripple"


def test_paths_and_signals_are_accepted(fitted, csv_runs):
    est, train, _ = fitted
    again = JointModel(model="both").fit([str(p) for p in csv_runs[:3]])
    np.testing.assert_array_equal(again.coef_, est.coef_)
    assert again.params_ == est.params_
    one = JointModel(model="usual").fit(train[0])
    assert isinstance(train[0], Experiment) and one.n_samples_ > 100


def test_bad_use_is_one_line_error(fitted):
    est, train, _ = fitted
    with pytest.raises(DataError, match="model 'bogus'"):
        JointModel(model="bogus").fit(train)
    with pytest.raises(DataError, match="estimator='iv' needs the reference"):
        JointModel(model="usual", estimator="iv").fit(train)
    with pytest.raises(DataError, match="not fitted"):
        JointModel().predict(train)
    with pytest.raises(DataError, match="no refinement"):
        est.refinement_json()
    with pytest.raises(DataError, match="expected Experiment objects"):
        JointModel().fit([1, 2])
    assert "model='paper'" in repr(JointModel())


# ---------------------------------------------------------------- scikit-learn conventions
_GIVEN = dict(model="usual", q_s="scan", joint="revolute", cutoff=12.5, decimation=7,
              dq_min=0.0, trim=3, estimator="ls", eliminate=False, threshold=25.0)


def test_get_set_params_and_clone_semantics():
    est = JointModel(**_GIVEN)
    for deep in (True, False):
        params = est.get_params(deep=deep)
        assert {k: params[k] for k in _GIVEN} == _GIVEN
        assert set(params) == set(JointModel().get_params())  # every constructor parameter
    assert est.get_params() == est.get_params(deep=False)
    # a clone built from the parameters holds the very same objects, unfitted
    twin = type(est)(**est.get_params(deep=False))
    assert all(twin.get_params()[k] is v for k, v in est.get_params().items())
    assert est.set_params(q_s=0.05, model="new") is est
    assert est.q_s == 0.05 and est.model == "new" and twin.q_s == "scan"
    with pytest.raises(DataError, match=r"unknown hyper-parameter 'q_ss' \(expected one of "):
        est.set_params(q_ss=0.05)
    assert est.q_s == 0.05


def test_sklearn_clone_and_grid_search(fitted):
    from sklearn.base import clone
    from sklearn.model_selection import GridSearchCV

    est, train, _ = fitted
    c = clone(est)
    assert c is not est and c.get_params() == est.get_params()
    assert not hasattr(c, "coef_") and hasattr(est, "coef_")
    # coef_ is an array aligned with coef_names_, the dict view kept as params_
    assert isinstance(est.coef_, np.ndarray) and est.coef_.shape == est.coef_names_.shape
    assert est.std_.shape == est.rel_std_pct_.shape == est.coef_.shape
    assert dict(zip(est.coef_names_, est.coef_, strict=True)) == est.params_
    # grid search over q_s, leaving one payload run out per fold (score: 1 - ||rho||/||Y||)
    grid = GridSearchCV(JointModel(model="paper"), {"q_s": [0.01, 0.2]}, cv=3, error_score="raise")
    grid.fit(train)
    assert grid.best_params_["q_s"] in (0.01, 0.2)
    scores = grid.cv_results_["mean_test_score"]
    assert np.all(np.isfinite(scores)) and np.all(scores > 0.5) and scores[0] != scores[1]
    assert isinstance(grid.best_estimator_, JointModel) and grid.best_estimator_.coef_.size
