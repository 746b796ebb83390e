"""One conformance suite over every registered estimator (ident.estimators.ESTIMATORS).

Every estimator, on a synthetic linear problem y = W theta + e with white noise (two row
groups with different noise levels, the instruments Z = W plus an independent perturbation,
so they are correlated with W and not with e): the estimate lies within its stated standard
deviation of the truth over several seeds (a family-wise bound for the worst deviation and
the share within 2 sigma), the covariance is a symmetric (b, b) matrix, rank-deficient
input raises an error naming the columns, and the instrumental-variable estimate equals
least squares when the instruments are the regressors. The normal-equation entry used by
the n-dof Gauss-Newton gives the same estimate as the row solve.
"""

from __future__ import annotations

import argparse

import numpy as np
import pytest
import scipy.stats

from ident import DataError, IdentifiabilityError
from ident.cli import register
from ident.estimators import (
    ESTIMATORS,
    RCOND,
    Estimator,
    RankDeficientError,
    Solution,
    get_estimator,
)
from ident.robot.estimate import METHODS, RANK_TOL
from ident.vocab import METHOD_ALIASES

NAMES = ["J", "FV", "FC", "OFF", "M"]
THETA = np.array([0.02, 0.3, 1.5, -0.4, 12.0])
SCALES = np.array([50.0, 2.0, 1.0, 1.0, 1e-2])  # very different column norms
SIGMA = (0.05, 0.5)  # noise std of the two row groups
M = 400
SEEDS = range(40)


def _problem(seed: int):
    rng = np.random.default_rng(seed)
    W = rng.standard_normal((M, len(THETA))) * SCALES
    W[:, 3] = 1.0  # an offset column
    groups = np.repeat([0, 1], M // 2)
    noise = rng.standard_normal(M) * np.asarray(SIGMA)[groups]
    y = W @ THETA + noise
    Z = W + 0.3 * rng.standard_normal(W.shape) * SCALES
    Z[:, 3] = 1.0
    return W, y, Z, groups


def _solve(est: Estimator, W, y, Z, groups) -> Solution:
    return est.solve(W, y, instruments=Z if est.needs_instruments else None, groups=groups,
                     names=NAMES)


@pytest.fixture(params=sorted(ESTIMATORS))
def est(request) -> Estimator:
    return get_estimator(request.param)


def test_registry_is_the_source_of_the_choices():
    assert METHODS == tuple(ESTIMATORS) and set(METHODS) >= {"ls", "wls", "iv"}
    for name, cls in ESTIMATORS.items():
        assert issubclass(cls, Estimator) and cls.name == name
    # one rank rule: the n-dof normal-matrix tolerance is the squared singular-value one
    assert RANK_TOL == RCOND**2
    with pytest.raises(DataError, match="'ls', 'wls', 'iv'"):
        get_estimator("ols2")


def test_cli_method_choices_are_the_registry():
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    choices = {a.dest: a.choices for p in sub.choices.values() for a in p._actions}
    # the registry's names, then the deprecated aliases (ident.vocab)
    assert tuple(choices["method"]) == (*ESTIMATORS, *METHOD_ALIASES)


def test_recovers_theta_within_its_stated_sigma(est):
    z = []
    for seed in SEEDS:
        sol = _solve(est, *_problem(seed))
        z.append((sol.theta - THETA) / sol.std)
    z = np.concatenate(z)
    n = z.size
    bound = scipy.stats.norm.ppf(1 - 0.01 / (2 * n))  # family-wise 1 % over all comparisons
    assert np.max(np.abs(z)) < bound, z
    # the stated sigma is honest: ~95 % within 2 sigma (binomial, n = 200: 90 % is 3.4 sd
    # below); the mean of z^2 within 0.56 .. 1.56 (4.4 and 5.6 of its sd sqrt(2 / n) away)
    assert np.mean(np.abs(z) < 2) >= 0.90, z
    rms = float(np.sqrt(np.mean(z**2)))
    assert 0.75 < rms < 1.25, rms


def test_solution_shapes_and_symmetric_covariance(est):
    W, y, Z, g = _problem(0)
    sol = _solve(est, W, y, Z, g)
    b = len(THETA)
    assert sol.theta.shape == (b,) and sol.cov.shape == (b, b)
    assert np.allclose(sol.cov, sol.cov.T, rtol=1e-10, atol=0)
    assert np.all(np.linalg.eigvalsh(sol.cov) > 0)
    assert sol.rank == b and sol.dof == M - b and sol.residual.shape == (M,)
    assert np.allclose(sol.residual, y - W @ sol.theta)
    assert sol.sigma2 > 0 and sol.cond >= 1 and sol.cond_raw >= 1


def test_rank_deficient_input_names_the_columns(est):
    W, y, Z, g = _problem(1)
    W = W.copy()
    W[:, 4] = 2 * W[:, 1] - W[:, 2]  # M is a combination of FV and FC
    with pytest.raises(RankDeficientError) as info:
        _solve(est, W, y, W if est.needs_instruments else Z, g)
    msg = str(info.value)
    assert isinstance(info.value, IdentifiabilityError)
    assert "\n" not in msg and "rank deficient" in msg
    dep = info.value.names
    assert len(dep) == 1 and dep[0] in {"M", "FV", "FC"}
    assert all(n in msg for n in ("M", "FV", "FC")), msg
    W[:, 4] = 0.0
    with pytest.raises(RankDeficientError, match="M has a zero column"):
        _solve(est, W, y, Z, g)


def test_rank_deficient_normal_equations_name_the_weakest_direction(est):
    W, y, Z, _ = _problem(2)
    W = W.copy()
    W[:, 4] = 2 * W[:, 1] - W[:, 2]
    A = W.T @ W
    d = np.sqrt(np.diag(A))
    with pytest.raises(RankDeficientError, match="not identifiable") as info:
        est.solve_normal(A / d[:, None] / d[None, :], W.T @ y / d, NAMES)
    assert {"M", "FV", "FC"} <= set(info.value.names)


def test_normal_equations_give_the_row_estimate(est):
    """The n-dof path's entry (solve_normal on the column-scaled normal equations, then the
    covariance from them) gives the row solve's estimate and covariance (one group)."""
    W, y, Z, _ = _problem(3)
    sol = _solve(est, W, y, Z, None)
    L = Z if est.needs_instruments else W
    A, gv = L.T @ W, L.T @ y
    d = np.sqrt(np.abs(np.diag(A)))
    theta = est.solve_normal(A / d[:, None] / d[None, :], gv / d, NAMES) / d
    assert np.allclose(theta, sol.theta, rtol=1e-8, atol=0)
    r = y - W @ theta
    cov = est.normal_covariance(A, L.T @ L if est.needs_instruments else None,
                                float(r @ r) / (M - len(THETA)))
    assert np.allclose(cov, sol.cov, rtol=1e-7, atol=0)


def test_iv_equals_ls_when_instruments_are_the_regressors():
    W, y, _, _ = _problem(4)
    ls = get_estimator("ls").solve(W, y, names=NAMES)
    for name, cls in ESTIMATORS.items():
        if not cls.needs_instruments:
            continue
        iv = cls().solve(W, y, instruments=W, names=NAMES)
        assert np.allclose(iv.theta, ls.theta, rtol=1e-10, atol=0), name
        assert np.allclose(iv.cov, ls.cov, rtol=1e-8, atol=0), name
    assert any(c.needs_instruments for c in ESTIMATORS.values())


def test_one_group_reweighting_is_least_squares(est):
    """Weights per group change nothing with a single group (every estimator)."""
    W, y, Z, _ = _problem(5)
    a = _solve(est, W, y, Z, None)
    b = _solve(est, W, y, Z, np.zeros(M, dtype=int))
    assert np.allclose(a.theta, b.theta, rtol=1e-12, atol=0)
    assert np.allclose(a.cov, b.cov, rtol=1e-10, atol=0)


def test_wls_beats_ls_on_unequal_groups():
    """With one noisy group, WLS's stated sigma is smaller than LS's, and its weights are
    1 / sigma_g^2 of the first LS fit's residuals per group (eq. 13-16)."""
    W, y, _, g = _problem(6)
    ls = get_estimator("ls").solve(W, y, groups=g)
    wls = get_estimator("wls").solve(W, y, groups=g)
    assert np.all(wls.std < ls.std)
    assert wls.weights is not None
    b = len(THETA)
    sg = [np.sqrt(np.sum(ls.residual[g == k] ** 2) / (np.sum(g == k) - b)) for k in (0, 1)]
    assert np.allclose(wls.weights, 1 / np.square(sg), rtol=1e-10)
    assert wls.weights[0] > 10 * wls.weights[1]  # noise ratio 10: weight ratio ~100


def test_bad_input_is_a_clear_error(est):
    W, y, Z, g = _problem(7)
    with pytest.raises(DataError, match="more samples than parameters"):
        est.solve(W[:3], y[:3], instruments=Z[:3])
    bad = W.copy()
    bad[0, 0] = np.nan
    with pytest.raises(DataError, match="NaN"):
        est.solve(bad, y, instruments=Z)
    if est.needs_instruments:
        with pytest.raises(DataError, match="needs instruments"):
            est.solve(W, y)
        with pytest.raises(DataError, match="instruments have shape"):
            est.solve(W, y, instruments=Z[:, :2])
