"""Refinement on real data: the EMPS benchmark (Janot, Gautier & Brunot 2019).

From the usual model (M ddq + F_C sign + F_V dq + offset) the first step must find
direction-dependent viscous friction and lower the relative error from about 4.0 % to about
3.1 %, and the cross-test error on DATA_EMPS_PULSES.mat from about 6.0 % to about 5.3 %.
"""

from __future__ import annotations

import functools

import pytest
from conftest import shared_path

from ident.loaders import concat, load_experiment
from ident.models import IdentModel, usual_model
from ident.preprocess import build_design
from ident.refine import refine

# the EMPS reference script: Butterworth at 5 x 20 Hz, decimation round(0.8 * 500 / 40)
SETTINGS = dict(cutoff_hz=100.0, decimation=10)


def _signals(name: str):
    path = shared_path("data", "emps", name)
    exp = load_experiment(path, mapping={"q": "qm", "tau": "vir"}, gain="gtau",
                          joint="prismatic")
    return concat([exp])


@functools.cache
def _refined():
    lib = usual_model(False, payload=False)
    d = build_design(lib, _signals("DATA_EMPS.mat"), **SETTINGS)
    v = build_design(lib, _signals("DATA_EMPS_PULSES.mat"), **SETTINGS)
    return refine(d, IdentModel(lib, "usual"), validation=v, max_steps=4)


def test_emps_first_step_is_direction_dependent_viscous():
    R = _refined()
    assert R.rel_error_initial == pytest.approx(0.040, abs=0.002)
    assert R.validation_rel_error_initial == pytest.approx(0.060, abs=0.002)
    s = R.steps[0]
    assert (s.effect, s.variable) == ("directional_viscous", "direction")
    assert s.rel_error_before == pytest.approx(0.040, abs=0.002)
    assert s.rel_error_after == pytest.approx(0.031, abs=0.002)
    assert s.validation_rel_error_before == pytest.approx(0.060, abs=0.002)
    assert s.validation_rel_error_after == pytest.approx(0.053, abs=0.002)
    # the axis is slower forwards: F_V+ < F_V-, both well determined
    fp, fn = s.parameters["F_V_pos"], s.parameters["F_V_neg"]
    assert fp["value"] < fn["value"]
    assert fn["value"] - fp["value"] > 10 * s.parameters["dF_V"]["std2"]


def test_emps_further_steps_are_confirmed_by_validation():
    R = _refined()
    # every accepted step lowered the validation error; rejected ones say why
    for s in R.steps:
        assert s.validation_rel_error_after < s.validation_rel_error_before
    assert R.validation_rel_error_final < R.validation_rel_error_initial
    assert R.rel_error_final < R.steps[0].rel_error_after
    for r in R.rejected:
        assert r.reason
    js = R.to_json()
    assert js["steps"][0]["validation_rel_error_after"] == pytest.approx(
        R.steps[0].validation_rel_error_after)
