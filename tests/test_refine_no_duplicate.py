"""The refinement does not add to a model a term it already has (found by a stranger's sweep).

The paper model holds eq. 24's load-dependent dry friction (a and b per quadrant). The library
search can still select "velocity x load_quadrant" on its residual, and it used to name it
``quadrant_load_velocity`` -- alpha_P sign(P) tau_out + beta_P sign(P) tau_out E, the same
columns again up to filtering: on the quick example campaign on the RX130L plant (seed 1,
least squares) it was accepted as step 2 (0.355 % -> 0.332 %) and the paper model's a, b
lost their meaning (the sweep's CAN-bus logs: a_m 5.03 +- 8.16, b 15-21 sigma off). The
registered ``quadrant_load`` effect already stood aside for such a model; the library's
naming now does too (``describe_group(load_dependent=True)``): the basis is left to compete as
a generic one, and on these data it is rejected.
"""

from __future__ import annotations

import pytest
from test_robot_refit_products import _campaign

from ident.fitting import fit_models
from ident.refine import LOAD_DEPENDENT, refine


@pytest.mark.parametrize("seed", [1, 11])
def test_paper_model_is_not_given_its_own_load_dependent_friction_again(seed):
    exps, _ = _campaign(seed)
    rep = fit_models(exps, ("paper",), table_iv=False)
    assert rep.models["paper"].estimator_ == "ls"
    R = refine(rep.designs["paper"], rep.models["paper"], max_steps=3, vmax=rep.vmax)
    effects = [st.effect for st in R.steps]
    assert effects and effects[0] == "position_ripple", effects  # the plant's effect
    assert not set(effects) & set(LOAD_DEPENDENT), effects
