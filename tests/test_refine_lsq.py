"""The residual-only least squares of the refinement and the q_s scan
(:func:`ident.refine_lsq.quick_residual`) gives :func:`ident.estimate.fit_least_squares`'s
floats, and declines (None) whenever that fit would drop a column or raise; the
decimation's filter with its cached initial state is scipy's ``sosfiltfilt``, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from ident.estimate import fit_least_squares
from ident.preprocess import _antialias, _decimate_rows, _factors
from ident.refine_lsq import quick_residual


def _data(rng, n=3000, p=6):
    W = rng.normal(size=(n, p)) * np.logspace(0, 3, p)
    chi = rng.normal(size=p)
    Y = W @ chi + rng.normal(0, 0.1, n)
    Z = W + rng.normal(0, 0.05, (n, p)) * np.logspace(0, 3, p)
    return W, Y, Z


@pytest.mark.parametrize("iv", [False, True])
def test_same_floats_as_the_fit(iv):
    rng = np.random.default_rng(4)
    W, Y, Z = _data(rng)
    names = [f"c{i}" for i in range(W.shape[1])]
    res = fit_least_squares(W, Y, names, eliminate=False, Z=Z if iv else None)
    out = quick_residual(W, Y, Z if iv else None)
    assert out is not None
    chi, rho, rel = out
    assert np.array_equal(chi, res.chi) and np.array_equal(rho, res.residual)
    assert rel == res.rel_error


@pytest.mark.parametrize("iv", [False, True])
def test_declines_where_the_fit_drops_or_raises(iv):
    rng = np.random.default_rng(5)
    W, Y, Z = _data(rng)
    dep = W.copy()
    dep[:, 2] = W[:, 0] + 2 * W[:, 1]  # a dependent column: the fit drops it
    zero = W.copy()
    zero[:, 3] = 0.0  # a zero column: dropped too
    for bad in (dep, zero):
        assert quick_residual(bad, Y, bad if iv else None) is None
    assert quick_residual(W[:5], Y[:5], None) is None  # 5 samples for 6 parameters
    nan = W.copy()
    nan[0, 0] = np.nan
    assert quick_residual(nan, Y, Z if iv else None) is None
    if iv:
        zbad = Z.copy()
        zbad[:, 1] = zbad[:, 0]  # singular instruments: the fit raises
        assert quick_residual(W, Y, zbad) is None


@pytest.mark.parametrize(("shape", "r"), [((3, 1000), 8), ((1, 50), 8), ((5, 20000), 20),
                                          ((2, 30), 40), ((4, 7), 8)])
def test_decimation_filter_is_scipys_sosfiltfilt(shape, r):
    x = np.random.default_rng(6).normal(size=shape)
    y, _ = _decimate_rows(x, r)
    ref = x
    for f in _factors(r):
        sos = _antialias(f).copy()
        padlen = min(3 * 2 * len(sos), ref.shape[-1] - 1)
        ref = scipy.signal.sosfiltfilt(sos, ref, axis=-1, padlen=padlen)
        ref = np.ascontiguousarray(ref[:, (ref.shape[-1] - 1) % f::f])
    assert np.array_equal(y, ref)
