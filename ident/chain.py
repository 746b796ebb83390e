"""The one preprocessing chain, from one joint to n (paper section IV.B).

(Past 600 lines: the filters, the decimation, the settings they read and the per-experiment
loop that runs them are one chain, documented here in the order the steps run; each step is
its own function.)

Per experiment of k axes (k = 1 for a single joint), with one :class:`ChainSettings`:

0. alignment (``torque_delay``): when the torque reference of sample k is computed from the
   position of sample k and held by the drive over the following cycle [t_k, t_k + dt]
   (jointid's runner and simulators), the motion it explains is the one of the cycle's
   middle, and q is interpolated to t_k + dt/2 (:func:`shift`, cubic Lagrange) before
   anything else. Without it dq and ddq lag the torque by dt/2, which biases F_V and the
   inertia terms by a few 0.1 % (simulated joint: F_V -0.2 % at 3.5 sigma, gone with the
   shift). Files of unknown timing are processed like the MATLAB reference scripts (0; on
   EMPS the shift moves F_V by +2 %): :func:`default_torque_delay`;
1. zero-phase Butterworth low-pass of q (order 4), axis by axis, central differences for dq
   and ddq; tau is low-pass filtered the same way only for the selection and for the
   columns' sign(P) = sign(tau dq) (eq. 26); the reference trajectory (IDIM-IV) is
   processed exactly as q;
2. the model's columns at full rate on these filtered signals: a *column builder* given by
   the caller (:func:`run_chain`; the single joint's ``Term`` columns in
   :func:`ident.preprocess.build_design`, the n-dof regressor in
   :func:`ident.robot.design.design_runs`);
3. edge trimming (``trim`` full-rate samples at both ends of each experiment);
4. parallel filtering and decimation of the raw torque, the states and every column, as
   MATLAB's ``decimate`` does (Chebyshev I order 8, 0.05 dB ripple, cut-off 0.8 f_s/(2 r),
   zero phase, keeping the last sample), in one call on the stacked rows; optionally
   (``ChainSettings.antialias = "fir"``) a Kaiser FIR of compact support instead, the guard
   then at least its half-length (:func:`fir_antialias`);
5. the selection, per axis: the stiction area |dq| < ``dq_min`` (plus what the builder
   rejects) evaluated at full rate, dilated by ``guard`` full-rate samples, with the first
   and last ``guard`` samples (:func:`guarded_keep`); what a model rejects besides --
   |tau| < ``tau_min``, the sign check sign(tau) != sign(tau_out_hat) and the quadrant band
   -- is the one rule :func:`rejected`, for one joint (:mod:`ident.preprocess`) and for n
   (:func:`ident.robot.design.sign_checked`).

The settings are resolved once, by :func:`resolve_settings`, with the same rules for one
joint and for n (cut-off: the largest :func:`choose_cutoff` over the axes of the first
experiment, at least :func:`iv_floor` f_s with instruments; r = round(f_s / cut-off);
trim = max(ceil(3 f_s / cut-off), 2 r); guard = 3 r). Pure numerics: no file access.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.signal

from . import DataError
from .loaders import uniform_grid
from .timing import shift

__all__ = [
    "BUTTER_ORDER",
    "CUTOFF_FLOOR_IV",
    "CUTOFF_MIN_IV_HZ",
    "TORQUE_DELAY",
    "axes_cutoff",
    "ChainBlock",
    "ChainSettings",
    "FullRate",
    "RawExperiment",
    "chain_blocks",
    "choose_cutoff",
    "ANTIALIAS",
    "decimate",
    "decimation_index",
    "fir_antialias",
    "fir_half_length",
    "default_rates",
    "filter_chain",
    "check_torque_delay",
    "default_torque_delay",
    "diffcent",
    "filter_experiment",
    "guarded_keep",
    "iv_band_note",
    "iv_floor",
    "keep_rows",
    "lowpass",
    "rejected",
    "resolve_settings",
    "run_chain",
    "selection",
    "shift",
]

BUTTER_ORDER = 4
#: Delay of the torque reference's effective instant after its position sample, in samples,
#: for jointid's logs: a command computed from the position of cycle k and held over the
#: cycle acts on the motion of the cycle's middle (zero-order hold: the runner with the
#: simulated drive, the offline simulator). ``build_design`` defaults to 0 (unknown timing).
#: A log that states a longer timing (``campaign.torque_delay_cycles``, e.g. 1.5 for the
#: simulated arm) is re-paired at load time so that this half cycle completes it
#: (:func:`ident.timing.align_to_torque`).
TORQUE_DELAY = 0.5
#: Relative excess of 3 f_s / cut-off over a whole number that the default trim's ceil
#: ignores (:func:`default_rates`): a rounding of the stored period, not a sample.
TRIM_RTOL = 1e-6
#: Lower bound of the default cut-off, as a fraction of f_s, when instruments are built.
#: The columns are nonlinear in the filtered signals (E_xp ddq, sign(P)): a narrow band
#: smears the breakaway and reversal transients, a bias no estimator removes (simulated
#: joint, true position and applied torque: b_m_J -139 % at f_s/20, +5 % at f_s/10). A
#: wider band lets more quantisation and torque noise into W, which biases OLS but not IV.
#: Measured with IV on five noise seeds of the simulated campaign (largest |z| over the new
#: model's parameters; relative error; low-velocity error new/usual): 0.1 f_s: 2.2-4.7
#: (b_g_J -30 to -70 %), 0.75 %, 0.31; 0.125 f_s: 1.2-2.9, 1.1 %, 0.43; 0.15 f_s: 0.8-2.4,
#: 1.4 %, 0.52. The residual grows with the band because W then holds more of the encoder
#: quantisation (amplified twice by differentiation), which OLS would absorb as bias.
CUTOFF_FLOOR_IV = 0.125
#: Lowest default cut-off [Hz] with instruments (up to 0.4 f_s). The bias of the narrow band
#: depends on the band in Hz, not on its fraction of f_s: the reversals' transients have their
#: own time scale. Measured with IV on the simulated joint's campaign subsampled to 500 and
#: 250 Hz (``benchmarks/bench_cutoff_band.py``; sum of z^2 over the new model's 22 parameters,
#: 22 expected, and the largest |z|; seed 6): at 1 kHz 62.5 Hz gives 356 (b_m_J -14.7),
#: 125 Hz 23, 200 Hz 11; at 500 Hz 62.5 Hz (0.125 f_s) 288 (b_m_J -12.7), 100 Hz 36, 125 Hz
#: 21, 150 Hz 9; at 250 Hz 31.25 Hz 359 (b_m_J -14.7), 100 Hz (0.4 f_s, the most the chain
#: takes) 36 (F_V -3.9).
#: Below 312.5 Hz the rule cannot be met and :func:`resolve_settings` warns.
CUTOFF_MIN_IV_HZ = 125.0


def iv_floor(fs: float) -> float:
    """Lower bound of the default cut-off with instruments, as a fraction of ``fs`` [Hz]:
    :data:`CUTOFF_FLOOR_IV`, raised to :data:`CUTOFF_MIN_IV_HZ` up to 0.4 f_s."""
    return max(CUTOFF_FLOOR_IV, min(CUTOFF_MIN_IV_HZ / fs, 0.4))


def iv_band_note(cutoff_hz: float) -> str | None:
    """What an IV default cut-off [Hz] below :data:`CUTOFF_MIN_IV_HZ` costs (the warning of
    :func:`resolve_settings` and the fit report's note), or None when it is not below."""
    if cutoff_hz >= CUTOFF_MIN_IV_HZ:
        return None
    return (f"IV cut-off {cutoff_hz:g} Hz (0.4 f_s, the most the chain takes) is below the "
            f"{CUTOFF_MIN_IV_HZ:g} Hz the friction's reversal terms need (the paper model's "
            "b_m_J, b_g_J, F_V): their estimates may lie beyond their standard deviations; "
            f"log at {CUTOFF_MIN_IV_HZ / 0.4:g} Hz or faster (docs/robot-data.md)")


def diffcent(y: np.ndarray, dt: float) -> np.ndarray:
    """Central differences along axis 0, one-sided at both ends (MATLAB ``diffcent``).

    Parameters
    ----------
    y : ndarray, shape (n, ...)
        Samples with period ``dt`` [s].
    dt : float
        Sampling period [s].

    Returns
    -------
    ndarray, shape (n, ...)
        dy/dt.
    """
    y = np.asarray(y, dtype=float)
    out = np.empty_like(y)
    out[1:-1] = (y[2:] - y[:-2]) / (2.0 * dt)
    out[0] = (y[1] - y[0]) / dt
    out[-1] = (y[-1] - y[-2]) / dt
    return out


def lowpass(x: np.ndarray, cutoff_hz: float, fs: float, order: int = BUTTER_ORDER) -> np.ndarray:
    """Zero-phase Butterworth low-pass (MATLAB ``filtfilt(butter(order, fc/fnyq), x)``)."""
    wn = cutoff_hz / (fs / 2.0)
    if not 0 < wn < 1:
        raise DataError(
            f"cut-off {cutoff_hz:g} Hz must lie between 0 and the Nyquist frequency {fs / 2:g} Hz"
        )
    sos = scipy.signal.butter(order, wn, output="sos")
    return scipy.signal.sosfiltfilt(sos, x, axis=0)


def _factors(r: int) -> list[int]:
    out, rest = [], r
    while rest > 13:
        for f in range(13, 1, -1):
            if rest % f == 0:
                out.append(f)
                rest //= f
                break
        else:
            break
    out.append(rest)
    return [f for f in out if f > 1]


@functools.lru_cache(maxsize=32)
def _antialias(f: int) -> np.ndarray:
    """Anti-alias filter of one decimation stage by ``f``, second-order sections.

    MATLAB's Chebyshev type I design (order 8, 0.05 dB ripple, cut-off 0.8 (f_s/2)/f)
    normalised to unit gain at DC: an even-order Chebyshev I filter has its DC gain at the
    bottom of the pass-band ripple (10^(-0.05/20) = 0.99426), so the raw design, applied
    forward and backward, would scale slowly varying signals by 0.9886 per stage (0.977 for
    two stages). The pass band then lies between 1 and 10^(0.05/20) per pass.
    """
    sos = scipy.signal.cheby1(8, 0.05, 0.8 / f, output="sos")
    dc = float(np.prod(sos[:, :3].sum(axis=1) / sos[:, 3:].sum(axis=1)))
    sos[0, :3] /= dc
    return sos


#: Anti-alias filters :func:`decimate` takes: ``"cheby"`` (MATLAB's, the default) or
#: ``"fir"`` (:func:`fir_antialias`: compact support, for a guard that contains its reach).
ANTIALIAS = ("cheby", "fir")


def _cheby_zero_phase_gain(w: float, r: int) -> float:
    """|H(w)|^2 of :func:`decimate`'s Chebyshev stages, forward and backward, at ``w``
    (a fraction of the Nyquist frequency of the full rate)."""
    g, before = 1.0, 1
    for f in _factors(r):  # each stage runs at the rate the stages before it left
        _, h = scipy.signal.sosfreqz(_antialias(f), worN=[np.pi * w * before])
        g *= float(np.abs(h[0])) ** 2
        before *= f
    return g


@functools.lru_cache(maxsize=32)
def fir_antialias(r: int) -> np.ndarray:
    """Taps (odd length L, symmetric, unit DC gain) of :func:`decimate`'s ``"fir"`` filter.

    A Kaiser-window low-pass (``scipy.signal.firwin``) meeting the Chebyshev's specification
    for the same r: pass band up to 0.8 (f_s/2)/r, stop band from 1.2 (f_s/2)/r (the lowest
    frequency that aliases into that pass band once decimated by r) with the attenuation the
    zero-phase Chebyshev has there (63 dB for r = 20; the Kaiser ripple, 0.0007 there, is also
    below the Chebyshev's 0.05 dB per pass in the pass band). Applied once, centred: linear
    phase made zero phase, and an output sample depends on the inputs within (L - 1) / 2
    samples of it only (:func:`fir_half_length`), none beyond (an IIR's tail has no end).
    """
    if r <= 1:
        return np.ones(1)
    atten = -10.0 * np.log10(_cheby_zero_phase_gain(1.2 / r, r))
    numtaps, beta = scipy.signal.kaiserord(atten, 0.4 / r)
    numtaps += 1 - numtaps % 2  # odd: a whole-sample centre
    h = scipy.signal.firwin(numtaps, 1.0 / r, window=("kaiser", beta), scale=True)
    h.flags.writeable = False
    return h


def fir_half_length(r: int) -> int:
    """(L - 1) / 2 of :func:`fir_antialias` (r) [full-rate samples]: its reach each side."""
    return (fir_antialias(r).size - 1) // 2


def decimate(x: np.ndarray, r: int, filter: str = "cheby") -> tuple[np.ndarray, np.ndarray]:
    """Anti-alias filter and downsample by ``r`` along axis 0 (MATLAB ``decimate``).

    Chebyshev type I, order 8, 0.05 dB ripple, cut-off 0.8 (f_s/2)/r, applied forward and
    backward (zero phase); factors above 13 are done in stages. Like MATLAB, the kept
    samples end on the last one. Unlike MATLAB's and scipy's design, each stage is
    normalised to unit DC gain (see :func:`_antialias`): constants and slow signals
    (positions, velocities) come out unscaled, so nonlinear functions of the decimated
    signals (sin(2 pi q / P), exp(-|dq| / q_s)) are right. Y and every column of W share
    the filter, so least-squares estimates do not depend on this gain.

    ``filter="fir"``: :func:`fir_antialias` (r) instead, in one stage, applied once centred
    (odd extension of (L - 1) / 2 samples at both ends, as ``filtfilt`` pads), the same
    kept samples. A kept sample then depends on the samples within :func:`fir_half_length`
    of it only: a guard at least that long leaves no trace of a rejected sample in the rows
    kept (the Chebyshev's, zero phase, reaches every sample).

    Parameters
    ----------
    x : ndarray, shape (n,) or (n, k)
        Samples (columns filtered independently).
    r : int
        Decimation factor.
    filter : {"cheby", "fir"}
        The anti-alias filter (:data:`ANTIALIAS`).

    Returns
    -------
    y : ndarray, shape (~n/r,) or (~n/r, k)
        Decimated samples.
    index : ndarray of int
        Indices of the kept samples in ``x``.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        y, index = _decimate_rows(x[None, :], r, filter)
        return y[0], index
    y, index = _decimate_rows(np.ascontiguousarray(x.T), r, filter)
    return y.T, index


def decimation_index(n: int, r: int) -> np.ndarray:
    """Indices of the samples :func:`decimate` keeps of n by r (each stage keeps every f-th
    sample ending on the last one)."""
    index = np.arange(n)
    if r > 1:
        for f in _factors(r):
            index = index[(index.size - 1) % f::f]
    return index


def _decimate_rows(x: np.ndarray, r: int, filter: str = "cheby") -> tuple[np.ndarray, np.ndarray]:
    """:func:`decimate` along the last axis of a C-contiguous (k, n) array (2x faster
    than filtering along a strided axis 0)."""
    index = decimation_index(x.shape[-1], r)
    if r <= 1:
        return x, index
    if filter == "fir":
        return _fir_rows(x, r, index), index
    if filter != "cheby":
        raise ValueError(f"anti-alias filter {filter!r}: expected one of {ANTIALIAS}")
    y = x
    for f in _factors(r):
        sos = _antialias(f).copy()
        padlen = min(3 * 2 * len(sos), y.shape[-1] - 1)
        y = _sosfiltfilt(sos, _antialias_zi(f), y, padlen)
        y = np.ascontiguousarray(y[:, (y.shape[-1] - 1) % f::f])
    return y, index


def _fir_rows(x: np.ndarray, r: int, index: np.ndarray) -> np.ndarray:
    """:func:`fir_antialias` (r) applied centred along the last axis of ``x`` (k, n), at the
    samples ``index`` only (an odd extension of the half-length at both ends).

    Direct sums over each kept sample's window (not by FFT, whose round-off would put
    nonzero values beyond the taps' reach): a kept sample's value is exactly that of the
    samples within the half-length."""
    h = fir_antialias(r)
    m = (h.size - 1) // 2
    n = x.shape[-1]
    pad = min(m, n - 1)
    ext = scipy.signal._arraytools.odd_ext(x, pad, axis=-1) if pad > 0 else x
    if pad < m:  # shorter than the filter: zeros beyond the odd extension
        ext = np.pad(ext, ((0, 0), (m - pad, m - pad)))
    # out[i] = sum_k h[k] x[i + k - m] (h symmetric); the kept samples are every r-th
    step = int(index[1] - index[0]) if index.size > 1 else r
    windows = np.lib.stride_tricks.sliding_window_view(ext, h.size, axis=-1)
    windows = windows[:, int(index[0])::step][:, :index.size]
    out = np.empty((x.shape[0], index.size))
    chunk = max(1, 2**22 // max(1, x.shape[0] * h.size))  # about 32 MB of window at a time
    for a in range(0, index.size, chunk):
        out[:, a:a + chunk] = windows[:, a:a + chunk] @ h
    return out


@functools.lru_cache(maxsize=32)
def _antialias_zi(f: int) -> np.ndarray:
    """``scipy.signal.sosfilt_zi`` of :func:`_antialias` (f), shape (sections, 2)."""
    zi = scipy.signal.sosfilt_zi(_antialias(f))
    zi.flags.writeable = False
    return zi


def _sosfiltfilt(sos: np.ndarray, zi: np.ndarray, x: np.ndarray, padlen: int) -> np.ndarray:
    """``scipy.signal.sosfiltfilt(sos, x, axis=-1, padlen=padlen)`` (odd padding) of a 2-D
    ``x`` with the steady-state ``zi = sosfilt_zi(sos)`` given: the same operations, so the
    same floats, without computing ``zi`` again at every call (a fifth of the time on the
    columns of one q_s of a scan)."""
    n = sos.shape[0]
    ext = scipy.signal._arraytools.odd_ext(x, padlen, axis=-1) if padlen > 0 else x
    z = zi.reshape(n, 1, 2)
    y, _ = scipy.signal.sosfilt(sos, ext, axis=-1, zi=z * ext[:, :1])
    y, _ = scipy.signal.sosfilt(sos, y[:, ::-1], axis=-1, zi=z * y[:, -1:])
    y = y[:, ::-1]
    return y[:, padlen:-padlen] if padlen > 0 else y


def _upper_cutoff(fs: float, min_fraction: float) -> float:
    """:func:`choose_cutoff`'s upper bound [Hz]: 0.4 f_s (or the lower bound, if above)."""
    return max(min_fraction, 0.4) * fs


def choose_cutoff(q: np.ndarray, dt: float, min_fraction: float = 0.05,
                  t: np.ndarray | None = None, source: str = "", warn: bool = True) -> float:
    """Low-pass cut-off [Hz] chosen from the bandwidth of the measured motion.

    The velocity spectrum (differences of q) is compared with its noise floor (median power
    in the upper half of the band); the motion bandwidth f_b holds 99.5 % of the energy
    above the floor, and the cut-off is 5 f_b (the paper's practice: about 5 times the
    bandwidth of the dynamics), but never below f_s/20: stiction, reversals and the
    position loop put content well above the trajectory's own bandwidth (the EMPS
    reference script uses 100 Hz at 1 kHz for its 20 Hz position loop; pass it
    explicitly). At most 0.4 f_s. ``min_fraction`` is that lower bound as a fraction of f_s
    (:func:`resolve_settings` raises it to :func:`iv_floor` with instruments).

    ``t`` (the samples' time stamps [s], optional): irregular stamps are first put on a
    uniform grid by :func:`ident.loaders.uniform_grid` (the loaders' one resampling: values
    interpolated at their stamps, or taken as uniformly sampled under jittered stamps,
    whichever leaves less noise above f_s/4): differences of q over jittered instants taken
    as uniform are broadband noise. When the rule above reaches 0.4 f_s (its floor, a
    median over the upper half of the band, is below the top of a noise spectrum that rises
    with f, as differenced white position noise does), the floor is taken again in the
    position spectrum, where such noise is flat, from the band's complement of the motion
    (above f_s/4), and differenced. A choice at a bound is warned about, with the reason
    (``source`` names the data in the message), unless ``warn`` is False (a caller that
    measures the motion band for itself and whose data the chain has warned about).
    """
    fs = 1.0 / dt
    q = np.asarray(q, dtype=float)
    if t is not None and q.size >= 2:
        tu, grid, note = uniform_grid(t, {"q": q}, warn=False)
        if note is not None:
            q = grid["q"]
            dt = float((tu[-1] - tu[0]) / (tu.size - 1))
    lo, hi = min_fraction * fs, _upper_cutoff(fs, min_fraction)
    v = np.diff(q) / dt
    v = v - v.mean()
    n = v.size
    if n < 16:
        return lo
    win = np.hanning(n)
    p = np.abs(np.fft.rfft(v * win)) ** 2
    f = np.fft.rfftfreq(n, dt)
    upper = f > fs / 4
    floor = float(np.median(p[upper])) if np.any(upper) else 0.0
    e = np.clip(p - floor, 0, None)
    c = np.cumsum(e)
    if c[-1] <= 0:
        return lo
    fb = float(f[int(np.searchsorted(c, 0.995 * c[-1]))])
    why = "no motion above the noise floor of the velocity spectrum"
    if 5.0 * fb >= hi and np.any(upper):
        # white position noise: |1 - exp(-i w dt)|^2 / dt^2 times a flat floor of q
        x = q[1:] - q[1:].mean()
        pq = np.abs(np.fft.rfft(x * win)) ** 2
        gain = (2.0 * np.sin(np.pi * f * dt)) ** 2 / dt**2
        e2 = np.clip(p - float(np.median(pq[upper])) * gain, 0, None)
        c2 = np.cumsum(e2)
        if c2[-1] > 0:
            fb = float(f[int(np.searchsorted(c2, 0.995 * c2[-1]))])
        # broadband: position or quantisation noise; jittered stamps are put on a uniform grid
        # before (the loaders, ``t`` here), with their own ResamplingWarning, and a log timed
        # by the SYNC counter (lockstep) has none: jitter is not named as the cause here
        why = ("the velocity spectrum stays above its noise floor up to the Nyquist frequency "
               "(broadband noise on the position: encoder, quantisation or measurement noise; "
               "irregular time stamps would have their own resampling warning)")
    cut = float(f"{np.clip(5.0 * fb, lo, hi):.6g}")
    where = f"{source}: " if source else ""
    if not warn:  # a caller measuring the band for itself (the refinement's motion band)
        return cut
    if 5.0 * fb >= hi:
        warnings.warn(f"{where}cut-off {cut:g} Hz is the upper bound 0.4 f_s: {why}; "
                      "give --cutoff", stacklevel=2)
    elif 5.0 * fb < lo and 5.0 * fb < 0.5 * lo:
        also = ", here also the upper bound 0.4 f_s" if lo >= hi else ""
        warnings.warn(f"{where}cut-off {cut:g} Hz is the lower bound {min_fraction:g} f_s{also} "
                      f"(5 x the motion bandwidth is {5.0 * fb:.3g} Hz); give --cutoff to "
                      "filter more", stacklevel=2)
    return cut



def _dilate(bad: np.ndarray, k: int) -> np.ndarray:
    """True within k samples of a True sample."""
    if k <= 0 or not bad.any():
        return bad
    c = np.concatenate([[0], np.cumsum(bad, dtype=np.int64)])
    n = bad.size
    i = np.arange(n)
    hi = np.minimum(i + k + 1, n)
    lo = np.maximum(i - k, 0)
    return (c[hi] - c[lo]) > 0


def guarded_keep(bad: np.ndarray, guard: int, index: np.ndarray) -> np.ndarray:
    """Kept decimated samples ``index`` of one experiment: not within ``guard`` full-rate
    samples of a ``bad`` one (shape (n,)) nor of the experiment's edges (transients of the
    decimation filter); see ``guard`` of :func:`build_design`."""
    bad = bad.copy()
    if guard > 0:
        bad[:guard] = True
        bad[-guard:] = True
    return ~_dilate(bad, guard)[index]


def default_rates(fs: float, cutoff_hz: float, decimation: int | None = None,
                  trim: int | None = None, guard: int | None = None) -> tuple[int, int, int]:
    """(decimation, trim, guard) with the defaults of :func:`build_design` for the None ones:
    r = round(f_s / cut-off) (at least 1), trim = max(ceil(3 f_s / cut-off), 2 r), guard = 3 r.
    The ceil ignores a relative excess below :data:`TRIM_RTOL` (a period stored to 10 digits,
    0.0039999999 s for 4 ms, gives 60.0000015 samples: the trim is 60, as with exactly 4 ms).
    Given values are returned as int, unchecked."""
    r = max(1, int(round(fs / cutoff_hz))) if decimation is None else int(decimation)
    if trim is None:
        # ceil to the next whole sample, but not past a whole number that a stored period
        # misses by a rounding (0.0039999999 s for 4 ms: 60.0000015 samples, not 61)
        x = 3 * fs / cutoff_hz
        trim = max(int(np.ceil(x - TRIM_RTOL * x)), 2 * r)
    return r, int(trim), 3 * r if guard is None else int(guard)


def default_torque_delay(sources: Iterable[str]) -> float:
    """:data:`TORQUE_DELAY` when every source is a jointid MCAP log (commands held over the
    next cycle), else 0 (files of unknown timing, processed like the MATLAB scripts)."""
    names = [str(x) for x in sources]
    return TORQUE_DELAY if names and all(x.lower().endswith(".mcap") for x in names) else 0.0


def check_torque_delay(value: float | str | None, what: str = "torque_delay") -> float | None:
    """The torque delay a caller gives [samples], checked: None or ``"auto"`` for the
    default (:func:`default_torque_delay`), else a number in [0, 1) (the bound of
    :func:`resolve_settings`: a longer timing is whole cycles the log states,
    ``campaign.torque_delay_cycles``, paired at load time). The single-joint and the robot
    fit, their command lines (before any file is read) and APIs read it here.

    Raises
    ------
    DataError
        One line naming ``what`` and the value.
    """
    if value is None or (isinstance(value, str) and value == "auto"):
        return None
    try:
        d = float(value)
    except (TypeError, ValueError):
        raise DataError(f"{what} {value!r}: expected a delay in [0, 1) samples of the log's "
                        "period, or 'auto'") from None
    if not 0.0 <= d < 1.0:  # NaN fails too
        raise DataError(f"{what} {d:g}: expected a delay in [0, 1) samples of the log's period "
                        "(e.g. 0.125: half a 1 kHz cycle in a log at 250 Hz)")
    return d



def axes_cutoff(q0: np.ndarray, dt: float, min_fraction: float = 0.05,
                source: str = "") -> float:
    """The chain's default cut-off [Hz] on the axes of ``q0`` (n, k) [rad or m] sampled every
    ``dt`` [s]: the largest :func:`choose_cutoff` over the axes whose choice found a motion
    bandwidth, i.e. stayed below the upper bound 0.4 f_s. An axis at that bound (its velocity
    spectrum above its noise floor up to the Nyquist frequency: noise, not motion) is left
    out, with a warning naming it, unless every axis is: taking its bound for every joint
    leaves the accelerations of the other joints unfiltered, and on a joint whose load is
    inertial only (a vertical axis) the noise of tau_out_hat then decides the paper model's
    quadrant and biases c_m down and c_g up (docs/robot-identification.md). One axis: its
    :func:`choose_cutoff`.
    """
    q0 = np.asarray(q0, dtype=float)
    q0 = q0[:, None] if q0.ndim == 1 else q0
    hi = float(f"{_upper_cutoff(1.0 / dt, min_fraction):.6g}")  # as choose_cutoff rounds
    # choose_cutoff's own warnings pass as they are (no catch_warnings: it would reset the
    # once-per-location registry and repeat them on every fit of a process)
    k = q0.shape[1]
    where = f"{source}: " if source else ""
    # several axes: each one's bound warning names the file and the axis (three identical
    # "cut-off 12.5 Hz is the lower bound" lines on the KUKA recording said neither)
    cuts = [choose_cutoff(q0[:, j], dt, min_fraction,
                          source=f"{where}axis {j + 1}" if k > 1 else source)
            for j in range(k)]
    found = [j for j, c in enumerate(cuts) if c < hi]
    if not found:
        return max(cuts)
    cut = max(cuts[j] for j in found)
    for j in sorted(set(range(len(cuts))) - set(found)):
        warnings.warn(f"{where}axis {j + 1}: its velocity spectrum stays above its noise "
                      f"floor up to the Nyquist frequency (cut-off {cuts[j]:g} Hz, the "
                      f"upper bound 0.4 f_s): left out of the chain's cut-off, {cut:g} Hz "
                      "from the other axes; give --cutoff to choose another", stacklevel=4)
    return cut


# -- the settings ------------------------------------------------------------------------


@dataclass(frozen=True)
class ChainSettings:
    """Resolved settings of the chain (:func:`resolve_settings`).

    Attributes
    ----------
    cutoff_hz : float
        Butterworth cut-off on q [Hz].
    decimation : int
        Decimation factor r.
    trim : int
        Full-rate samples cut at both ends of each experiment.
    guard : int
        Full-rate samples around a rejected one that are rejected too.
    torque_delay : float
        Instant of the torque after the position sample [samples].
    dq_min : float or None
        Stiction threshold [rad/s]; None: ``dq_min_rel`` of :func:`run_chain` (a fraction
        of the largest full-rate |dq|), or no stiction criterion without it.
    antialias : {"cheby", "fir"}
        The decimation's anti-alias filter (:func:`decimate`); with ``"fir"`` the guard is
        at least :func:`fir_half_length` (r).
    """

    cutoff_hz: float
    decimation: int
    trim: int
    guard: int
    torque_delay: float
    dq_min: float | None = None
    antialias: str = "cheby"

    def as_dict(self) -> dict[str, float | int | str | None]:
        """The settings, for reports and JSON (``antialias`` only when not the default)."""
        out: dict[str, float | int | str | None] = {
            "cutoff_hz": self.cutoff_hz, "decimation": self.decimation, "trim": self.trim,
            "guard": self.guard, "torque_delay": self.torque_delay, "dq_min": self.dq_min}
        if self.antialias != "cheby":
            out["antialias"] = self.antialias
        return out


def resolve_settings(
    q0: np.ndarray,
    dt: float,
    *,
    instruments: bool = False,
    cutoff_hz: float | None = None,
    decimation: int | None = None,
    trim: int | None = None,
    guard: int | None = None,
    torque_delay: float | None = None,
    dq_min: float | None = None,
    antialias: str = "cheby",
    sources: Iterable[str] = (),
    error: type[Exception] = DataError,
) -> ChainSettings:
    """The chain's settings, the ``None`` ones chosen from the data (module doc).

    Parameters
    ----------
    q0 : ndarray, shape (n,) or (n, k)
        Positions of the first experiment (the default cut-off: :func:`axes_cutoff` of
        its axes).
    dt : float
        Sampling period [s] of every experiment.
    instruments : bool
        IDIM-IV instruments are built: the default cut-off is at least :func:`iv_floor`
        f_s (warned about where that stays below :data:`CUTOFF_MIN_IV_HZ`).
    cutoff_hz, decimation, trim, guard, dq_min
        Given values (checked), or None for the defaults (:func:`default_rates`).
    torque_delay : float or None
        [samples]; None: :func:`default_torque_delay` of ``sources``.
    antialias : {"cheby", "fir"}
        The decimation's anti-alias filter (:func:`decimate`). With ``"fir"`` the default
        guard is the larger of 3 r and :func:`fir_half_length` (r), and a given one shorter
        than that half-length is refused: rows within it of a rejected sample would carry
        that sample's torque.
    sources : iterable of str
        File names of the experiments (for the default torque delay; the first names the
        data in :func:`axes_cutoff`'s warning).
    error : exception class
        Raised, with one line naming the setting, for a bad one (the caller's package's).
    """
    fs = 1.0 / dt
    q0 = np.asarray(q0, dtype=float)
    q0 = q0[:, None] if q0.ndim == 1 else q0
    sources = list(sources)
    if cutoff_hz is None:
        floor = iv_floor(fs) if instruments else 0.05
        cutoff_hz = axes_cutoff(q0, dt, floor, sources[0] if sources else "")
        note = iv_band_note(cutoff_hz) if instruments else None
        if note:
            where = f"{sources[0]}: " if sources else ""
            warnings.warn(f"{where}sampled at {fs:g} Hz: {note}", stacklevel=2)
    cutoff_hz = float(cutoff_hz)
    if not 0 < cutoff_hz < fs / 2:
        raise error(f"cut-off {cutoff_hz:g} Hz: expected between 0 and the Nyquist "
                    f"frequency {fs / 2:g} Hz")
    if decimation is not None and int(decimation) < 1:
        raise error(f"decimation must be a positive integer, got {int(decimation)}")
    if antialias not in ANTIALIAS:
        raise error(f"antialias {antialias!r}: expected one of {', '.join(ANTIALIAS)}")
    given_guard = guard
    r, trim, guard = default_rates(fs, cutoff_hz, decimation, trim, guard)
    if trim < 0:
        raise error(f"trim must be >= 0, got {trim}")
    if guard < 0:
        raise error(f"guard must be >= 0, got {guard}")
    if antialias == "fir":
        reach = fir_half_length(r)
        if given_guard is not None and guard < reach:
            raise error(f"guard {guard}: the FIR anti-alias filter reaches {reach} samples "
                        f"each side (decimation {r}); expected a guard of at least {reach}")
        guard = max(guard, reach)
    if torque_delay is None:
        torque_delay = default_torque_delay(sources)
    torque_delay = float(torque_delay)
    if not 0 <= torque_delay < 1:
        raise error(f"torque_delay must lie in [0, 1) samples, got {torque_delay}")
    if dq_min is not None and not dq_min >= 0:
        raise error(f"dq_min must be >= 0 [rad/s], got {dq_min}")
    return ChainSettings(cutoff_hz, r, trim, guard, torque_delay,
                         None if dq_min is None else float(dq_min), antialias)


# -- the per-experiment loop -------------------------------------------------------------


@dataclass(frozen=True)
class RawExperiment:
    """One experiment as the chain reads it.

    Attributes
    ----------
    label : str
        Names it in error messages (a file name, ``experiment 2``).
    q, tau : ndarray, shape (n, k)
        Positions [rad or m] and torques [N m or N], sampled with the common period.
    ref : ndarray, shape (n, k), or None
        Reference (planned) positions, processed exactly as q.
    dq, ddq : ndarray, shape (n, k), or None
        Derivatives the file gives: when both are given, q, dq and ddq are taken as they are
        (not shifted, filtered nor differentiated) by the states chain
        (:func:`ident.robot.loaders.preprocess_runs`).
    """

    label: str
    q: np.ndarray
    tau: np.ndarray
    ref: np.ndarray | None = None
    dq: np.ndarray | None = None
    ddq: np.ndarray | None = None


@dataclass
class FullRate:
    """One experiment at full rate after steps 0-1 and the edge trim (step 3).

    Attributes
    ----------
    keep : slice
        The full-rate samples kept by the trim, in the raw experiment.
    tau : ndarray, shape (n_f, k)
        Raw torque (the paper's Y before decimation).
    tau_f : ndarray, shape (n_f, k)
        Low-passed torque (selection, sign(P)).
    q, dq, ddq : ndarray, shape (n_f, k)
        Filtered position and its central differences.
    ref : ndarray, shape (n_f, k), or None
        Filtered reference position.
    ref_ddq : ndarray, shape (n_f, k), or None
        Its second central difference (IDIM-IV instruments only).
    """

    keep: slice
    tau: np.ndarray
    tau_f: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    ref: np.ndarray | None = None
    ref_ddq: np.ndarray | None = None

    @property
    def n(self) -> int:
        """Full-rate samples."""
        return int(self.q.shape[0])


def _axes(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    """``f`` applied to every column of x (n, k), side by side (the one-axis calls, so the
    floats are the same for one joint and for n)."""
    return np.column_stack([f(x[:, j]) for j in range(x.shape[1])])


def filter_experiment(
    exp: RawExperiment,
    dt: float,
    settings: ChainSettings,
    *,
    instruments: bool = False,
    error: type[Exception] = DataError,
) -> FullRate:
    """Steps 0, 1 and 3 of the module doc on one experiment (q, dq, ddq as given when the
    experiment carries both derivatives).

    Raises ``error`` when the experiment is too short for the trim and the decimation.
    """
    s = settings
    n = exp.q.shape[0]
    if n - 2 * s.trim < max(4 * s.decimation, 10):
        raise error(f"{exp.label}: {n} samples, too few after trimming {s.trim} at each end "
                    f"and decimating by {s.decimation}")
    fs = 1.0 / dt

    def smooth(x: np.ndarray) -> np.ndarray:
        return lowpass(shift(x, s.torque_delay), s.cutoff_hz, fs)

    def diff(x: np.ndarray) -> np.ndarray:
        return diffcent(x, dt)

    keep = slice(s.trim, n - s.trim if s.trim else n)
    if exp.dq is not None and exp.ddq is not None:
        q, dq, ddq = (np.asarray(x, dtype=float) for x in (exp.q, exp.dq, exp.ddq))
    else:
        q = _axes(smooth, exp.q)
        dq = _axes(diff, q)
        ddq = _axes(diff, dq)
    tau_f = _axes(lambda x: lowpass(x, s.cutoff_hz, fs), exp.tau)
    ref = ref_ddq = None
    if exp.ref is not None:
        rf = _axes(smooth, exp.ref)
        ref = rf[keep]
        if instruments:
            ref_ddq = _axes(diff, _axes(diff, rf))[keep]
    return FullRate(keep=keep, tau=np.asarray(exp.tau, dtype=float)[keep], tau_f=tau_f[keep],
                    q=q[keep], dq=dq[keep], ddq=ddq[keep], ref=ref, ref_ddq=ref_ddq)


def keep_rows(bad: np.ndarray, guard: int, index: np.ndarray) -> np.ndarray:
    """Kept decimated rows (m, k), axis by axis: :func:`guarded_keep` of each column of
    ``bad`` (n_f, k)."""
    return np.column_stack([guarded_keep(bad[:, j], guard, index)
                            for j in range(bad.shape[1])])


def rejected(tau_f: np.ndarray, *, tau_min: float | None = None,
             load: np.ndarray | None = None,
             band: tuple[np.ndarray, float] | None = None) -> np.ndarray | None:
    """Step 5's model criteria: the full-rate samples a model rejects besides the stiction
    area (the ``bad`` of :func:`selection`), axis by axis, for one joint and for n.

    Parameters
    ----------
    tau_f : ndarray, shape (n_f,) or (n_f, k)
        The low-passed torque at full rate [N m] (``FullRate.tau_f``).
    tau_min : float or None
        Reject |tau_f| < ``tau_min`` [N m]: the sign of P = tau dq unreliable (eq. 26).
    load : ndarray, shape of ``tau_f``, or None
        tau_out_hat of a load model [N m]: reject sign(tau_f) != sign(tau_out_hat), the sign
        check (the paper's stiction-area rectangle, Fig. 2.b, where eq. 26's proxy
        sign(tau dq) is not sign(P_out)).
    band : (ndarray, float) or None
        (tau_out_hat of a load model [N m], shape of ``tau_f``; h [N m]): reject
        |tau_out_hat| < h, the paper model's quadrant band.

    Returns
    -------
    ndarray of bool, shape of ``tau_f``, or None
        The rejected samples; None when no criterion is given.
    """
    if tau_min is None and load is None and band is None:
        return None
    tau_f = np.asarray(tau_f)
    bad = np.zeros(tau_f.shape, dtype=bool)
    if tau_min is not None:
        bad |= np.abs(tau_f) < tau_min
    if load is not None:
        bad |= np.sign(tau_f) != np.sign(load)
    if band is not None:
        bad |= np.abs(band[0]) < band[1]
    return bad


def selection(dq: np.ndarray, dq_min: float | None, guard: int, index: np.ndarray,
              bad: np.ndarray | None = None) -> np.ndarray:
    """Step 5: the decimated rows ``index`` kept (m, k), axis by axis: not within ``guard``
    full-rate samples of the stiction area |dq| < ``dq_min`` (none when None), of a ``bad``
    sample (n_f, k; what the model rejects besides) or of the edges."""
    reject = np.zeros(dq.shape, dtype=bool) if bad is None else bad
    if dq_min is not None:
        reject = reject | (np.abs(dq) < dq_min)
    return keep_rows(reject, guard, index)


@dataclass
class ChainBlock:
    """One experiment after the chain.

    Attributes
    ----------
    full : FullRate
        Its full-rate signals (steps 0-3).
    index : ndarray of int
        Full-rate samples (into ``full``) kept by the decimation.
    dec : ndarray, shape (4 k + c, m)
        Decimated rows: raw tau, q, dq, ddq (k rows each), then the builder's c rows in
        the order it gave them (:meth:`columns`).
    keep : ndarray of bool, shape (m, k)
        Selection per axis (step 5).
    sizes : tuple of int
        Rows of each of the builder's arrays.
    """

    full: FullRate
    index: np.ndarray
    dec: np.ndarray
    keep: np.ndarray
    sizes: tuple[int, ...]

    def states(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Decimated raw tau, q, dq, ddq, each (m, k)."""
        k = self.full.q.shape[1]
        return tuple(self.dec[i * k:(i + 1) * k].T for i in range(4))  # type: ignore[return-value]

    def columns(self) -> list[np.ndarray]:
        """The builder's arrays, decimated: one (rows, m) view each, in its order."""
        out, a = [], 4 * self.full.q.shape[1]
        for size in self.sizes:
            out.append(self.dec[a:a + size])
            a += size
        return out


#: A column builder: (experiment index, its full-rate signals) -> the arrays (rows, n_f) to
#: filter and decimate with the torque, and the full-rate samples it rejects (n_f, k) or None.
ColumnBuilder = Callable[[int, FullRate], tuple[list[np.ndarray], np.ndarray | None]]


def run_chain(
    experiments: Sequence[RawExperiment],
    dt: float,
    settings: ChainSettings,
    build: ColumnBuilder,
    *,
    instruments: bool = False,
    dq_min_rel: float | None = None,
    check: Callable[[int, RawExperiment], None] | None = None,
    error: type[Exception] = DataError,
) -> tuple[list[ChainBlock], float | None]:
    """The chain (module doc) on every experiment.

    Parameters
    ----------
    experiments : sequence of RawExperiment
        Sampled with the common period ``dt`` [s].
    dt : float
        Sampling period [s].
    settings : ChainSettings
        From :func:`resolve_settings`.
    build : callable
        The model's column builder, called once per experiment after every experiment is
        filtered (so that ``dq_min_rel`` sees all of them): (i, full) -> (rows, bad), rows a
        list of (c_i, n_f) arrays, bad an (n_f, k) boolean array of rejected full-rate
        samples or None.
    instruments : bool
        Compute the reference's acceleration (``FullRate.ref_ddq``).
    dq_min_rel : float or None
        With ``settings.dq_min`` None, the stiction threshold is this fraction of the
        largest full-rate |dq| of all experiments and axes.
    check : callable or None
        Called on each experiment before it is filtered (e.g. a memory bound).
    error : exception class
        Raised for too short experiments.

    Returns
    -------
    blocks : list of ChainBlock
        One per experiment.
    dq_min : float or None
        The stiction threshold used [rad/s].
    """
    fulls, dq_min = filter_chain(experiments, dt, settings, instruments=instruments,
                                 dq_min_rel=dq_min_rel, check=check, error=error)
    return chain_blocks(fulls, settings, dq_min, build), dq_min


def filter_chain(
    experiments: Sequence[RawExperiment],
    dt: float,
    settings: ChainSettings,
    *,
    instruments: bool = False,
    dq_min_rel: float | None = None,
    check: Callable[[int, RawExperiment], None] | None = None,
    error: type[Exception] = DataError,
) -> tuple[list[FullRate], float | None]:
    """The first half of :func:`run_chain` (same parameters): every experiment at full rate
    (:func:`filter_experiment`) and the stiction threshold [rad/s] they give (``settings.dq_min``,
    else ``dq_min_rel`` of the largest full-rate |dq|, else None)."""
    fulls = []
    for i, exp in enumerate(experiments):
        if check is not None:
            check(i, exp)
        fulls.append(filter_experiment(exp, dt, settings, instruments=instruments,
                                       error=error))
    dq_min = settings.dq_min
    if dq_min is None and dq_min_rel is not None:
        dq_min = dq_min_rel * max(float(np.max(np.abs(f.dq))) for f in fulls)
    return fulls, dq_min


def chain_blocks(
    fulls: Sequence[FullRate],
    settings: ChainSettings,
    dq_min: float | None,
    build: ColumnBuilder,
) -> list[ChainBlock]:
    """The second half of :func:`run_chain`: on experiments already at full rate (the output
    of :func:`filter_chain`, possibly kept from an earlier chain on the same data), the
    model's columns, the decimation in parallel with the torque and the selection. Another
    model's columns on the same samples thus need no second filtering (issue 24: the
    single-joint design built on the robot chain's full-rate signals)."""
    blocks = []
    for i, full in enumerate(fulls):
        rows, bad = build(i, full)
        sizes = tuple(int(r.shape[0]) for r in rows)
        stack = np.concatenate([full.tau.T, full.q.T, full.dq.T, full.ddq.T, *rows], axis=0)
        del rows
        dec, index = _decimate_rows(np.ascontiguousarray(stack), settings.decimation,
                                    settings.antialias)
        del stack
        blocks.append(ChainBlock(full=full, index=index, dec=dec, sizes=sizes,
                                 keep=selection(full.dq, dq_min, settings.guard, index, bad)))
    return blocks
