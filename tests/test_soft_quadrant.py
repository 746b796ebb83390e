"""trajectories.friction.soft_quadrant_weights: the hard quadrant weights' expectation under a
Gaussian jitter of the load, checked against a Monte-Carlo mean of quadrant_weights itself."""

from __future__ import annotations

import numpy as np
import pytest

from trajectories.friction import quadrant_weights, soft_quadrant_weights


@pytest.mark.parametrize("seed", [1, 2])
def test_expectations_are_the_monte_carlo_means_of_the_hard_weights(seed):
    rng = np.random.default_rng(seed)
    s = rng.normal(0.0, 2.0, 40)  # the model's load [N m]
    dq = rng.normal(0.0, 1.0, 40)  # [rad/s]
    sigma = 0.8
    draws = 200_000
    x = s[None, :] + sigma * rng.standard_normal((draws, s.size))  # the true load
    hp, hm = quadrant_weights(x * dq[None, :])
    pp, pm, r = soft_quadrant_weights(s, dq, sigma)
    # Monte-Carlo standard errors: at most 0.5 / sqrt(draws) for the weights and
    # (|s| + sigma) / sqrt(draws) for the products; 5 of them
    tol_w = 5 * 0.5 / np.sqrt(draws)
    tol_x = 5 * (np.abs(s) + sigma) / np.sqrt(draws)
    assert np.all(np.abs(hp.mean(0) - pp) < tol_w)
    assert np.all(np.abs(hm.mean(0) - pm) < tol_w)
    assert np.all(np.abs((hp * x).mean(0) - (pp * s + r)) < tol_x)
    assert np.all(np.abs((hm * x).mean(0) - (pm * s - r)) < tol_x)


def test_small_jitter_gives_the_hard_weights_and_zero_velocity_counts_half():
    s = np.array([2.0, -1.0, 0.5, -3.0, 1.0])
    dq = np.array([1.0, 1.0, -2.0, -0.5, 0.0])
    pp, pm, r = soft_quadrant_weights(s, dq, 1e-6)
    hp, hm = quadrant_weights(s * dq)
    np.testing.assert_allclose(pp, hp, atol=1e-12)
    np.testing.assert_allclose(pm, hm, atol=1e-12)
    np.testing.assert_allclose(r, 0.0, atol=1e-12)
    assert (pp[-1], pm[-1], r[-1]) == (0.5, 0.5, 0.0)


@pytest.mark.parametrize("sigma", [0.0, -1.0, float("nan"), float("inf")])
def test_a_jitter_that_is_not_positive_is_one_clear_error(sigma):
    with pytest.raises(ValueError, match="sigma: expected a positive jitter RMS"):
        soft_quadrant_weights([1.0], [1.0], sigma)
