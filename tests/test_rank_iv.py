"""IDIM-IV's rank rule judges what IV solves (issue 24, "one rank rule").

IDIM-IV solves Z^T W theta = Z^T y: least squares on the regressor projected on the
instruments, P_Z W (C_theta = sigma^2 (W^T P_Z W)^-1). A column can be well separated in
W^T W (the measured column varies) and not in P_Z W (the instruments are weak in that
direction). Two such cases, built from a reference trajectory (the instruments) and its
measurement (the reference plus noise, the regressor):

* ``constant``: a column nearly constant on the reference (relative variation ``delta``) but
  varying in the measured one: on the instruments it is the offset's column;
* ``duplicate``: a column equal to another one on the reference up to ``delta``, each measured
  with its own noise.

The rows' rule (W^T W) keeps both columns (the noise separates them); IDIM-IV cannot: before
this change the single-joint rows fit refused the whole fit ("instruments: ..."), and the
n-dof path -- the rows' rule, then the solver's test on the singular values of the scaled
Z^T W against RCOND^2 -- keeps the column with a sigma 10^3 to 10^4 times the others' and its
value anywhere inside it (delta = 3e-7, seeds 0-2: ``constant`` k = 0.571 +- 1.55, 0.078 +- 10.4,
0.341 +- 1.38; ``duplicate`` k4 = 0.489 +- 1.21, 0.607 +- 1.57, -1.82 +- 13.0, truth 0.7,
against +- 0.0008 to 0.0015 for every parameter once the rule leaves it out; at delta = 1e-8,
seed 2, its variance came out negative. :func:`test_the_n_dof_path_without_the_iv_rule_keeps_it`
prints them with ``-s``; the n-dof drop, ``RobotModel._rank_fix``, called the rows' rule
only, and now calls ``rank_drops`` after it). The rule now leaves it out with its
reason (:data:`ident.estimators.WEAK_PREFIX`, the partner named), on rows
(:func:`ident.estimate.fit_instrumental`, ``IV.solve``) and on moments summed chunk by chunk
(``Estimator.rank_drops``, the n-dof entry) alike; the kept parameters then come out within
3 of their stated sigma of the truth their columns carry (a dropped column's share goes to
its partner: the offset, or the duplicate). With good instruments (or Z = W) the rule is the
rows' one: nothing more is left out.
"""

from __future__ import annotations

import numpy as np
import pytest

from ident import IdentifiabilityError
from ident.estimate import fit_instrumental
from ident.estimators import (
    RCOND,
    WEAK_PREFIX,
    RankDeficientError,
    get_estimator,
    instrumented_gram,
    rank_rule,
)

THETA = np.array([0.5, 2.0, -1.0, 0.7])
SEEDS = (0, 1, 2)
#: Relative variation of the weak direction on the reference: well below RCOND (1e-6) and
#: just below it (the n-dof solver's RCOND^2 test kept such a column).
DELTAS = (1e-8, 3e-7)


def _case(kind: str, delta: float, seed: int, m: int = 3000, noise: float = 0.02):
    """(W measured, y, Z reference, names, truth of the kept columns after the drop, the
    column IV cannot determine, its partner)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 30.0, m)
    ones, s, wiggle = np.ones(m), np.sin(1.3 * t), np.sin(2.9 * t + seed)
    if kind == "constant":
        other = np.cos(0.7 * t)
        weak = 1.0 + delta * wiggle
        names = ["off", "a", "b", "k"]
        kept_truth = {"off": THETA[0] + THETA[3], "a": THETA[1], "b": THETA[2]}
        partner = "off"
    else:
        other = np.sin(0.37 * t) * np.cos(0.11 * t)
        weak = other + delta * wiggle
        names = ["off", "a", "k3", "k4"]
        kept_truth = {"off": THETA[0], "a": THETA[1], "k3": THETA[2] + THETA[3]}
        partner = "k3"
    Z = np.column_stack([ones, s, other, weak])
    W = Z + noise * rng.standard_normal(Z.shape) * np.r_[0.0, 1.0, 1.0, 1.0]
    y = Z @ THETA + 0.01 * rng.standard_normal(m)
    return W, y, Z, names, kept_truth, names[3], partner


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("delta", DELTAS)
@pytest.mark.parametrize("kind", ["constant", "duplicate"])
def test_iv_leaves_out_a_column_its_instruments_do_not_determine(kind, delta, seed):
    W, y, Z, names, truth, weak, partner = _case(kind, delta, seed)
    # the rows' rule alone keeps every column: the measured columns are separable
    assert rank_rule(W.T @ W)[0].size == 0
    res = fit_instrumental(W, y, Z, names, eliminate=False)
    assert [n for n, _ in res.removed] == [weak]
    why = res.removed[0][1]
    assert why.startswith(WEAK_PREFIX) and partner in why, why
    for n, v, sd in zip(res.names, res.chi, res.std, strict=True):
        assert abs(v - truth[n]) < 3 * sd, (n, v, sd, truth[n])
    # the n-dof entry: the same rule on moments summed chunk by chunk
    A, C, G = (sum(P[i:i + 500].T @ Q[i:i + 500] for i in range(0, len(y), 500))
               for P, Q in ((Z, W), (Z, Z), (W, W)))
    drops = get_estimator("iv").rank_drops(G, names, A=A, C=C)
    assert [(names[k], r) for k, r in drops] == res.removed
    # the estimators without instruments keep it (their rule is the rows')
    assert get_estimator("ls").rank_drops(G, names, A=A, C=C) == []
    # IV.solve on all the columns refuses, naming it and why
    with pytest.raises(RankDeficientError) as info:
        get_estimator("iv").solve(W, y, instruments=Z, names=names)
    assert info.value.names == [weak] and WEAK_PREFIX in str(info.value)
    with pytest.raises(IdentifiabilityError, match="instruments"):
        fit_instrumental(W, y, Z, names, eliminate=False, drop_unidentifiable=False)


@pytest.mark.parametrize("seed", SEEDS)
def test_good_instruments_leave_out_what_the_rows_rule_does(seed):
    """Instruments strong in every direction (delta = 1: the weak column varies on the
    reference too) or equal to the regressor: IV's rule leaves out exactly the rows' rule's
    columns, zero and dependent ones included, with the rows' reasons."""
    W, y, Z, names, _, _, _ = _case("constant", 1.0, seed)
    iv = get_estimator("iv")
    assert iv.rank_drops(W.T @ W, names, A=Z.T @ W, C=Z.T @ Z) == []
    fit = fit_instrumental(W, y, Z, names, eliminate=False)
    assert fit.removed == [] and fit.names == tuple(names)
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((400, 6))
    X[:, 4] = 2 * X[:, 1] - X[:, 2]
    X[:, 5] = 0.0
    nm = [f"c{i}" for i in range(6)]
    G = X.T @ X
    ls = get_estimator("ls").rank_drops(G, nm)
    assert [k for k, _ in ls] == rank_rule(G)[0].tolist() and len(ls) == 2 and ls[1][0] == 5
    assert iv.rank_drops(G, nm, A=G, C=G) == ls


def test_instrumented_gram_is_the_projected_regressors():
    """W^T P_Z W from (Z^T W, Z^T Z) is the Gram matrix of P_Z W computed by QR of Z."""
    rng = np.random.default_rng(5)
    Z = rng.standard_normal((300, 4)) * np.array([1.0, 1e3, 1e-3, 7.0])
    W = Z @ rng.standard_normal((4, 4)) + 0.1 * rng.standard_normal((300, 4))
    Q, _ = np.linalg.qr(Z)
    PW = Q @ (Q.T @ W)
    np.testing.assert_allclose(instrumented_gram(Z.T @ W, Z.T @ Z), PW.T @ PW, rtol=1e-9)
    # nearly dependent instruments (within RCOND) span one direction less: P_Z W loses a
    # column by the rule, which the full instruments' P_Z W does not
    norms = np.linalg.norm(W, axis=0)
    assert rank_rule(PW.T @ PW, norms=norms)[0].size == 0
    Z[:, 3] = Z[:, 0] * (1.0 + 0.1 * RCOND * rng.standard_normal(300))
    assert rank_rule(instrumented_gram(Z.T @ W, Z.T @ Z), norms=norms)[0].size == 1


def _normal_fit(W, y, Z, keep):
    """The n-dof path on the columns ``keep``: the estimator's ``solve_normal`` on the
    column-scaled Z^T W (its RCOND^2 test), then ``normal_covariance`` (the IV sandwich)."""
    iv = get_estimator("iv")
    W, Z = W[:, keep], Z[:, keep]
    A = Z.T @ W
    d = np.sqrt(np.abs(np.diag(A)))
    theta = iv.solve_normal(A / d[:, None] / d[None, :], Z.T @ y / d) / d
    r = y - W @ theta
    cov = iv.normal_covariance(A, Z.T @ Z, float(r @ r) / (len(y) - len(keep)))
    return theta, np.sqrt(np.abs(np.diag(cov)))


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("kind", ["constant", "duplicate"])
def test_the_n_dof_path_without_the_iv_rule_keeps_it(kind, seed):
    """The n-dof path as ``RobotModel._rank_fix`` ran it (the rows' rule on W^T W only) keeps
    the column IV cannot determine: the solver accepts it, its sigma over 100 times the
    largest of the fit after ``rank_drops``, whose kept values are within 3 sigma of their
    truth."""
    W, y, Z, names, truth, weak, _ = _case(kind, 3e-7, seed)
    assert rank_rule(W.T @ W)[0].size == 0
    theta0, sd0 = _normal_fit(W, y, Z, [0, 1, 2, 3])
    drops = get_estimator("iv").rank_drops(W.T @ W, names, A=Z.T @ W, C=Z.T @ Z)
    keep = [i for i in range(4) if i not in {k for k, _ in drops}]
    theta, sd = _normal_fit(W, y, Z, keep)
    fmt = {"float_kind": lambda v: f"{v:.2g}"}
    print(f"\n{kind} seed {seed}: rows' rule only: {weak} = {theta0[3]:.3g} +- {sd0[3]:.3g} "
          f"(truth {THETA[3]}), sigmas {np.array2string(sd0, formatter=fmt)}; IV's rule: "
          f"{[names[i] for i in keep]} sigmas {np.array2string(sd, formatter=fmt)}")
    assert [names[i] for i in keep] == [n for n in names if n != weak]
    assert sd0[3] > 100 * sd.max()
    for i, v, s in zip(keep, theta, sd, strict=True):
        assert abs(v - truth[names[i]]) < 3 * s, (names[i], v, s)
