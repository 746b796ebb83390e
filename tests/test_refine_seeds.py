"""Issue 20's acceptance over noise seeds: on simulated joints (clean; each undeclared plant
effect; position-dependent dry friction; load-dependent viscous friction; two effects at
once), the refined model's error is within [0.95, 1.1] x the error of the true structure
fitted on the same samples, for five seeds each; clean data get nothing (or only the plant's
real half-sample hold), and no error goes below the estimated noise floor.
"""

from __future__ import annotations

import pytest
from refine_cases import CASES, case_design, refined, true_structure_error

from ident.unseen import LEAK_RATIO

SEEDS = (0, 1, 2, 3, 4)


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_refinement_reaches_the_true_structure_on_every_seed(case):
    for seed in SEEDS:
        R = refined(case, seed)
        true = true_structure_error(case, seed)
        ratio = R.rel_error_final / true
        assert 0.95 <= ratio <= 1.10, (case, seed, ratio, R.format_report())
        assert R.rel_error_final >= LEAK_RATIO * R.noise_floor, (case, seed)
        if case == "clean":
            assert {st.named_effect for st in R.steps} <= {"zero_order_hold"}, (
                seed, R.format_report())
        for st in R.steps:
            assert st.heldout_rel_error_after < st.heldout_rel_error_before
        refined.cache_clear()  # the designs of 50 runs do not all fit in memory at once
        case_design.cache_clear()
