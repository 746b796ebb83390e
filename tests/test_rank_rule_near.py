"""One rank rule for the n-dof fit's refusal and its drop, on a near-dependence.

The n-dof fit refused a design by the solver's test (``Estimator.solve_normal``: on the
column-scaled normal matrix lambda_min <= RANK_TOL lambda_max, RANK_TOL = RCOND^2) while its
drop (:func:`ident.estimators.rank_rule`, the pivoted Cholesky, a pivot <= RCOND^2 on unit
columns) found nothing to drop: a column whose residual on the others lies between RCOND and
RCOND sqrt(lambda_max) is refused by the first and kept by the second. The real KUKA KR300
at ``--trim 73`` (tests/test_kuka_robot_rank.py): lambda_min 3.6e-13 <= 1e-12 x 22.1 (cond
6.2e13, MY4R and MY6 nearly collinear on A4's rows), while rank_rule's pivots, the base
columns first, all exceeded 1e-12 (in plain greedy order the smallest is 7.3e-13, MY4R).
:meth:`ident.robot.estimate.RobotModel._rank_fix` now continues the pivots with the solver's
own test (:func:`ident.robot.estimate._near_dependent`): what the solver refuses gets its
nearly dependent column named.

Synthetic case: the base regressor of the simulated 3-dof arm (tests/test_robot_fit.py's
``arm3_usual_data``, the rows of one run) with one more column, a combination of three of
its base columns (drawn per seed) plus a component orthogonal to all of them whose size puts
the column's residual on the others at RCOND sigma_max / 2 (inside the gap, from the
tolerance, not from the data) -- a payload column that is almost a combination of the base
ones. Both forms are checked: the solver refuses and the old rule names nothing (the
disagreement), the new rule names exactly that column with its partners and the kept columns
pass the solver. At 10 RCOND sigma_max (outside the gap; at 2 one draw is still refused:
lambda_min lies below the column's squared residual) the solver accepts and the rule names
nothing: a drop only where the solver refuses.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_robot_fit import arm3_usual_data

from ident.estimators import ESTIMATORS, RankDeficientError, rank_rule
from ident.robot.estimate import RANK_TOL, _near_dependent

SEEDS = (0, 1, 2)


@pytest.fixture(scope="module")
def arm3_base_rows():
    """Unit-norm base regressor columns (rows of every joint at every sample) of one
    simulated arm3 run."""
    _, reg, base, runs = arm3_usual_data()
    r = runs[0]
    W = base.reduce(reg.rows(r.q_true, r.dq_true, r.ddq_true, friction=False))
    W = W[:, np.linalg.norm(W, axis=0) > 0]
    return W / np.linalg.norm(W, axis=0)


def _with_near_column(Ws: np.ndarray, seed: int, factor: float) -> tuple[np.ndarray, list]:
    """Ws plus a unit column whose residual on Ws is ``factor`` RCOND sigma_max of the result
    (sigma_max^2 = lambda_max of the scaled Gram matrix), and the partners' indices."""
    rng = np.random.default_rng(seed)
    partners = sorted(rng.choice(Ws.shape[1], size=3, replace=False).tolist())
    comb = Ws[:, partners] @ (rng.uniform(0.5, 1.5, size=3) * rng.choice([-1, 1], size=3))
    comb /= np.linalg.norm(comb)
    u = rng.standard_normal(Ws.shape[0])
    u -= Ws @ np.linalg.lstsq(Ws, u, rcond=None)[0]  # orthogonal to every base column
    u /= np.linalg.norm(u)
    lam = np.linalg.eigvalsh(Ws.T @ Ws)[-1] + 1.0  # the new column adds at most 1
    for _ in range(3):  # lambda_max hardly moves with the residual: a fixed point
        eps = factor * np.sqrt(RANK_TOL * lam)
        c = np.sqrt(1 - eps**2) * comb + eps * u  # unit norm, residual eps on Ws
        W = np.column_stack([Ws, c])
        lam = np.linalg.eigvalsh(W.T @ W)[-1]
    return W, partners


@pytest.mark.parametrize("seed", SEEDS)
def test_near_dependent_column_refused_by_the_solver_is_named_by_the_rule(arm3_base_rows, seed):
    W, partners = _with_near_column(arm3_base_rows, seed, 0.5)
    G = W.T @ W
    b = G.shape[0] - 1  # the new column; the base columns are pivoted first
    solver = ESTIMATORS["ls"]()
    # the two forms of before: the solver refuses, the pivots name nothing
    with pytest.raises(RankDeficientError):
        solver.solve_normal(G, np.zeros(b + 1))
    dep, _ = rank_rule(G, first=b)
    assert dep.size == 0, dep
    # the rule now: the pivots, then the solver's test on what they keep
    near, cond = _near_dependent(G, np.arange(b + 1), b)
    assert list(near) == [b], near
    assert set(partners) <= set(near[b]), (partners, near[b])
    ev = np.linalg.eigvalsh(G)
    assert cond == pytest.approx(ev[-1] / ev[0], rel=1e-3) and cond > 1 / RANK_TOL
    keep = np.arange(b)
    solver.solve_normal(G[np.ix_(keep, keep)], np.zeros(b))  # the kept columns pass


@pytest.mark.parametrize("seed", SEEDS)
def test_no_drop_where_the_solver_accepts(arm3_base_rows, seed):
    W, _ = _with_near_column(arm3_base_rows, seed, 10.0)
    G = W.T @ W
    b = G.shape[0] - 1
    ESTIMATORS["ls"]().solve_normal(G, np.zeros(b + 1))  # accepted
    near, _ = _near_dependent(G, np.arange(b + 1), b)
    assert near == {}
    assert rank_rule(G, first=b)[0].size == 0
