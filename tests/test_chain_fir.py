"""The chain's optional FIR anti-alias filter (``ChainSettings.antialias = "fir"``): its
reach ends at its half-length, so a torque at a rejected sample leaves exactly nothing in
the rows the guard keeps (the Chebyshev's zero-phase tail reaches them); it meets the
Chebyshev's pass band and its attenuation where aliasing starts; the default stays the
Chebyshev, float for float."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from ident import DataError
from ident.chain import (
    RawExperiment,
    _antialias,
    _cheby_zero_phase_gain,
    decimate,
    decimation_index,
    fir_antialias,
    fir_half_length,
    resolve_settings,
    run_chain,
)

FS = 1000.0


def _motion(n: int = 8000) -> np.ndarray:
    """A slow back-and-forth position (n, 1) [rad], reversing every 2 s."""
    t = np.arange(n) / FS
    return (0.5 * np.sin(2 * np.pi * 0.25 * t))[:, None]


@pytest.mark.parametrize("r", [5, 10, 20, 40])
def test_fir_impulse_response_ends_at_its_half_length(r):
    n = 40 * r + 1
    m = fir_half_length(r)
    index = decimation_index(n, r)
    for k in (n // 2, n // 2 + 1, n // 2 + r // 2):
        x = np.zeros(n)
        x[k] = 1.0
        y, idx = decimate(x, r, "fir")
        assert np.array_equal(idx, index)
        near = np.abs(index - k) <= m
        assert np.all(y[~near] == 0.0)  # exactly: no sample beyond the taps' reach
        assert np.any(y[near] != 0.0)
        yc, _ = decimate(x, r)
        assert np.any(yc[~near] != 0.0)  # the Chebyshev's tail goes on


@pytest.mark.parametrize("r", [5, 10, 20, 40])
def test_fir_meets_the_chebyshev_pass_band_and_stop_band(r):
    h = fir_antialias(r)
    assert h.size % 2 == 1 and np.allclose(h, h[::-1]) and h.sum() == pytest.approx(1.0)
    w, H = scipy.signal.freqz(h, worN=np.linspace(0.0, np.pi, 4001))
    amp = np.abs(H)
    f = w / np.pi  # fraction of the full rate's Nyquist frequency
    cheby_pass = 10 ** (0.1 / 20) - 1  # the zero-phase Chebyshev's ripple: 0.05 dB per pass
    assert np.all(np.abs(amp[f <= 0.8 / r] - 1.0) <= cheby_pass)
    stop = amp[f >= 1.2 / r]
    assert np.max(stop) ** 2 <= _cheby_zero_phase_gain(1.2 / r, r) * 1.0001


def test_a_torque_at_a_rejected_sample_leaves_nothing_in_the_kept_rows():
    """The chain on a torque that is one impulse at a sample the builder rejects: with the
    FIR every kept decimated torque row is exactly 0, the guard covers its reach; with the
    Chebyshev and its own guard (3 r) the kept rows near it are not."""
    q = _motion()
    n = q.shape[0]
    dt = 1.0 / FS
    at = n // 2 + 7  # the rejected sample (raw index)
    tau = np.zeros((n, 1))
    tau[at, 0] = 1.0

    def build(_: int, f):  # noqa: ANN001 - FullRate
        bad = np.zeros((f.n, 1), dtype=bool)
        bad[at - f.keep.start, 0] = True
        return [], bad

    for name in ("fir", "cheby"):
        s = resolve_settings(q, dt, cutoff_hz=50.0, torque_delay=0.0, antialias=name)
        (b,), _ = run_chain([RawExperiment("impulse", q, tau)], dt, s, build)
        y = b.states()[0][:, 0]
        keep = b.keep[:, 0]
        assert not keep.all() and keep.sum() > 0.8 * keep.size
        if name == "fir":
            assert s.guard == fir_half_length(s.decimation) > 3 * s.decimation
            assert np.all(y[keep] == 0.0)
            # the rows the guard leaves out do carry it: the guard is not wider than needed
            assert np.any(y[~keep] != 0.0)
        else:
            assert s.guard == 3 * s.decimation
            assert np.max(np.abs(y[keep])) > 1e-6


def test_settings_with_the_fir():
    q = _motion()
    dt = 1.0 / FS
    s = resolve_settings(q, dt, cutoff_hz=50.0, antialias="fir")
    assert s.guard == max(3 * s.decimation, fir_half_length(s.decimation))
    assert s.as_dict()["antialias"] == "fir"
    wide = fir_half_length(s.decimation) + 5
    assert resolve_settings(q, dt, cutoff_hz=50.0, antialias="fir", guard=wide).guard == wide
    with pytest.raises(DataError, match="FIR anti-alias filter reaches"):
        resolve_settings(q, dt, cutoff_hz=50.0, antialias="fir", guard=3 * s.decimation)
    with pytest.raises(DataError, match="antialias 'butter'"):
        resolve_settings(q, dt, cutoff_hz=50.0, antialias="butter")


def test_the_default_is_the_chebyshev_float_for_float():
    q = _motion()
    s = resolve_settings(q, 1.0 / FS, cutoff_hz=50.0)
    assert s.antialias == "cheby" and "antialias" not in s.as_dict()
    assert s.guard == 3 * s.decimation
    rng = np.random.default_rng(3)
    x = rng.standard_normal(3001)
    for r in (10, 20):  # one stage, and two (10 then 2)
        y, index = decimate(x, r)
        ref = x
        for f in ((10,) if r == 10 else (10, 2)):
            sos = _antialias(f)
            ref = scipy.signal.sosfiltfilt(sos, ref, padlen=min(6 * len(sos), ref.size - 1))
            ref = ref[(ref.size - 1) % f::f]
        assert np.array_equal(index, decimation_index(x.size, r))
        np.testing.assert_allclose(y, ref, rtol=0, atol=1e-12)
        assert np.array_equal(decimate(x, r, "cheby")[0], y)
