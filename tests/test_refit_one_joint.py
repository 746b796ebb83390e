"""The single-joint refinement's loop closes inside the robot model (issue 24): the terms
:func:`ident.refine.refine` found are refitted, with every parameter, by the joint's
:class:`~ident.robot.estimate.RobotModel` (:func:`ident.robot.refit.refit_robot`, what
``jointid fit --robot --refine`` does for every joint), and the refinement's record carries
that refit (``refit``, docs/fit-json.md).

On the refinement's own columns (its final design's, formed at full rate and decimated with
the torque) the robot refit IS the refinement's final fit: the same error, coefficients and
deviations, computed by the other model class from its own rows. Evaluated on the decimated
states instead (``joint_columns``, the n-dof refit's default), a term reading the load sees
each run's lever-arm payload too (it was dropped, which doubled the error after the usual
model's refinement on the example campaign).
"""

from __future__ import annotations

import pytest
from example_campaign import simulate_example_campaign

from ident.api import JointModel
from ident.loaders import make_experiment


def _experiments(seed: int, iv: bool = False) -> list:
    """The example campaign's runs: CSV-named (least squares), or MCAP-named with their
    reference trajectory (IDIM-IV, the half-cycle torque timing of jointid's logs)."""
    _, plan, sims = simulate_example_campaign(seed)
    return [make_experiment(f"payload{i}.{'mcap' if iv else 'csv'}", r.t, r.q, r.tau_ref,
                            payload_mass=p.mass_kg, payload_arm=p.arm_m,
                            q_ref=plan.reference.q[r.cycle.clip(0, plan.reference.q.size - 1)]
                            if iv else None)
            for i, (p, r) in enumerate(zip(plan.payloads, sims, strict=True))]


@pytest.fixture(scope="module", params=[(11, False), (12, False), (11, True)],
                ids=["ls-11", "ls-12", "iv-11"])
def refined(request):
    """The usual model refined on the example campaign, whose plant has the paper's friction:
    the refinement finds load-dependent friction terms, which read the load tau_out (the
    payload's lever arm included). Least squares on two seeds; IDIM-IV (the refit's
    instruments: the design's) on one."""
    seed, iv = request.param
    est = JointModel(model="usual").fit(_experiments(seed, iv))
    assert est.estimator_ == ("iv" if iv else "ls")
    return est, est.refine(max_steps=2)


def test_refit_inside_the_robot_model_is_the_refinement_s_final_fit(refined):
    est, ref_est = refined
    ref = ref_est.refinement_
    assert ref.steps, "the refinement found nothing: the check below would be empty"
    rec = ref_est.refinement_json()["refit"]
    assert "error" not in rec, rec
    err = rec["rel_error"]
    assert err["before"]["all"] == pytest.approx(ref.rel_error_initial, rel=1e-9)
    assert err["after"]["all"] == pytest.approx(ref.rel_error_final, rel=1e-9)
    fm = ref.final_model
    pars = rec["parameters"]
    extra = {n.split(":", 1)[1]: v for n, v in pars.items() if ":" in n}
    for n in fm.names_:
        got = pars[n] if n in pars else extra[n]  # single-joint names; extras "<joint>:<name>"
        assert abs(got["value"] - fm.coef_[n]) <= 1e-6 * fm.std_[n], n
        assert got["std"] == pytest.approx(fm.std_[n], rel=1e-6), n
    # every found term is an extra of the refit, with its Wald test
    assert [x["effect"] for x in rec["extras"]] == [t.effect for t in ref.terms]
    assert all(x["wald"] is not None for x in rec["extras"])


def test_terms_on_the_decimated_states_see_the_payload_lever_arm(refined):
    """Without the design's columns the terms are evaluated on the robot signals' decimated
    states (``joint_columns``): not the same floats as the design's full-rate columns, but the
    same load variable, so the refit lands near the refinement's error (with the lever arm
    dropped it came out 1.8 times it on seed 11)."""
    est, ref_est = refined
    ref = ref_est.refinement_
    if not any(t.effect.startswith("quadrant_load") for t in ref.terms):
        pytest.skip("no load-reading term found on this seed")
    rec = est.report_.refit_found_terms("usual", ref.terms)  # no design: joint_columns
    assert "error" not in rec, rec
    ratio = rec["rel_error"]["after"]["all"] / ref.rel_error_final
    assert 0.9 < ratio < 1.1, ratio


@pytest.mark.parametrize("iv", [False, True], ids=["ls", "iv"])
def test_paper_model_with_eliminated_parameters(iv):
    """The paper model (products form) as the demo fits it: its elimination fixed some
    parameters at 0 as not significant, while the refinement refits without elimination; the
    refit estimates them again (``refit_eliminated``), so its result is the refinement's
    final one -- least squares and IDIM-IV (the design's instruments), on the quick example
    campaign on the RX130L plant, whose undeclared ripple the refinement finds. "before" is
    the fit as reported (with its elimination)."""
    from test_robot_refit_products import _campaign

    from ident.fitting import fit_models
    from ident.refine import refine

    exps, refs = _campaign(11)
    rep = fit_models(exps, ("paper",), table_iv=False, references=refs if iv else None)
    m = rep.models["paper"]
    assert m.estimator_ == ("iv" if iv else "ls")
    assert any(why.startswith("not significant") for _, why in m.removed_)
    R = refine(rep.designs["paper"], m, max_steps=1, vmax=rep.vmax)
    assert [st.effect for st in R.steps] == ["position_ripple"]
    rec = rep.refit_found_terms("paper", R.terms, R.final_design)
    assert rec["rel_error"]["before"]["all"] == pytest.approx(m.rel_error_, rel=1e-9)
    assert rec["rel_error"]["after"]["all"] == pytest.approx(R.rel_error_final, rel=1e-9)
    fm = R.final_model
    pars = rec["parameters"]
    for n in fm.names_:
        got = pars[n] if n in pars else pars[f"joint:{n}"]
        assert abs(got["value"] - fm.coef_[n]) <= 1e-6 * fm.std_[n], n
