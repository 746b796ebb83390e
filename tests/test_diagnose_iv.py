"""The residual diagnosis of an IDIM-IV fit bins the acceleration on the reference's.

An IV residual keeps the part of the torque that follows the measured acceleration's noise
(errors in variables: the instruments, built on the reference trajectory, are blind to it).
Binned on the measured acceleration that part looks like an effect -- on the quick example
campaign (the RX130L plant, MCAP-named runs with their references, as
tests/test_robot_refit_iv.py) the measured acceleration "explained" about a quarter of the
paper model's residual while a generic acceleration term is rejected by the IV fit. The
diagnosis of an IV design (and the refinement's "remaining residual" table) bins it on
``Design.reference_acceleration()``, the acceleration the instruments read.

Asserted: the reference acceleration is the design's instrument of the J column, to the
last bit; on the usual and the paper model's IV residual the measured acceleration is
significant and explains > 10 % of the residual left after the ripple, the reference's a
tenth of that at most (not significant on the paper model's); the refinement's diagnoses
say which acceleration they binned; an OLS design keeps the measured one (no reference
acceleration).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_robot_refit_iv import _problem, _refinement

from ident.diagnose import diagnose
from ident.fitting import fit_models
from ident.refine import refine


@pytest.mark.parametrize("name", ["usual", "paper"])
def test_iv_residual_is_binned_on_the_reference_acceleration(name):
    """After the refinement's ripple step (what the plant hides), the measured acceleration
    "explains" a large share of the IV residual (measured 17 % usual, 27 % paper), the
    reference's a tenth of it at most (0.7 %, 0.2 %); on the paper model's residual, which
    has nothing left to explain, the reference's is not significant."""
    rep, _, _ = _problem()
    usual = rep.designs["usual"]
    j = usual.names.index("J")
    np.testing.assert_array_equal(usual.reference_acceleration(), usual.Z[:, j])
    np.testing.assert_array_equal(usual.W[:, j], usual.signals.ddq)
    ref = _refinement(name)
    assert [st.effect for st in ref.steps] == ["position_ripple"]
    d, m = ref.final_design, ref.final_model
    assert d.Z is not None and m.estimator_ == "iv"
    za = d.reference_acceleration()
    assert za.shape == (len(d),)
    s = d.signals.states()
    measured = diagnose(m.residual_, s, Y=d.Y)
    reference = diagnose(m.residual_, s, Y=d.Y, acceleration=za)
    acc_m, acc_r = measured.get("acceleration"), reference.get("acceleration")
    assert any(x.variable == "acceleration" for x in measured.significant), acc_m
    assert acc_m.explained > 0.1, acc_m
    assert acc_r.explained < 0.1 * acc_m.explained, (acc_m, acc_r)
    if name == "paper":
        assert all(x.variable != "acceleration" for x in reference.significant), acc_r
    assert measured.acceleration == "measured" and reference.acceleration == "reference"
    assert "reference trajectory's" in reference.format_table()
    assert ref.final_diagnosis.get("acceleration").statistic == acc_r.statistic
    # the other variables are binned as before
    for v in ("position", "velocity", "time"):
        assert reference.get(v).statistic == measured.get(v).statistic


def test_refinement_diagnoses_say_which_acceleration():
    rep, _, _ = _problem()
    ref = refine(rep.designs["paper"], rep.models["paper"], max_steps=1, vmax=rep.vmax)
    assert ref.final_diagnosis.acceleration == "reference"
    assert all(st.diagnosis.acceleration == "reference" for st in ref.steps)
    assert "reference trajectory's" in ref.format_report()


def test_ols_design_keeps_the_measured_acceleration():
    from test_robot_refit_products import _campaign

    exps, _ = _campaign(11)
    rep = fit_models(exps, ("usual",), eliminate=False, table_iv=False)
    d = rep.designs["usual"]
    assert d.Z is None and d.reference_acceleration() is None
    ref = refine(d, rep.models["usual"], max_steps=1, vmax=rep.vmax)
    assert ref.final_diagnosis.acceleration == "measured"
