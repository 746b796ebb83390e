"""What no model can explain, and errors on data a fit never saw (the refinement's guards).

Two numbers guard every refinement step (:func:`ident.refine.refine`, docs/refinement.md
"Noise floor and unseen data"):

* the **noise floor** (:func:`noise_floor`): the relative error ||e|| / ||Y|| of the part of
  the residual that changes from one decimated sample to the next. Two estimates of a white
  noise level, each inflated by a different structure, and the lower one is kept: the second
  differences of the residual, robustly (median absolute deviation; for white noise of
  standard deviation σ, Δ²e has standard deviation √6 σ, while every effect of the states
  varies smoothly along the trajectory and contributes little to Δ²; a closed-loop
  oscillation near the Nyquist frequency inflates it), and the median level of the residual's
  spectrum above a tenth of the sampling rate (robust to lines; broadband effects inflate
  it). A model error below
  the floor means that the model explains noise: a leak of the output into the regressor
  (a column computed from the measured torque), never a result. A step whose fit or
  held-out error falls below :data:`LEAK_RATIO` times the floor is refused and named a leak;
  the ratio allows for the estimate's own spread (measured on simulated joints: 0.8 to 1.1
  times the true structure's error);
* the **unseen-data error** (:func:`heldout_error`): every run fitted on the others and
  predicted (leave one run out) when the design has two runs or more, else five contiguous
  blocks of the single run (blocked folds). A step is kept only if it lowers it. When every
  run replays one trajectory (:func:`one_trajectory`: the payload runs of the paper's
  campaign), the held-out run follows the path the others were fitted on, so a term locked
  to that path (a function of the time since the start, or of the position along it) passes
  this test as well as a property of the joint does; only data of another trajectory (a
  validation file) can tell them apart, and the refinement says so.

Pure numerics (no file access).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

__all__ = ["LEAK_RATIO", "MAX_START_OFFSET", "N_BLOCKS", "TRAJECTORY_TOL", "heldout_error",
           "heldout_kind", "noise_floor", "one_trajectory"]

#: A fit or held-out error below this fraction of the estimated noise floor is a leak.
LEAK_RATIO = 0.5

#: Lower edge of the residual's spectrum the floor's second estimate reads [cycles/sample].
SPECTRUM_BAND = 0.1

#: Contiguous folds of a single run (blocked cross-validation).
N_BLOCKS = 5

#: Two runs replay one trajectory when the RMS difference of their positions at the same time
#: since their (aligned) start is below this fraction of the positions' standard deviation.
#: (Measured: about 1e-3 for the payload runs of one plan, whose tracking errors differ with
#: the load; about 1 for two multi-sines of other seeds.)
TRAJECTORY_TOL = 0.05

#: Largest start offset between runs :func:`one_trajectory` aligns, as a fraction of the first
#: run's duration (the demo's payload logs start 0.20 s apart in 199 s).
MAX_START_OFFSET = 0.1


def _mad(x: np.ndarray) -> float:
    return 1.4826 * float(np.median(np.abs(x - np.median(x)))) if x.size else math.nan


def noise_floor(residual: np.ndarray, y: np.ndarray, experiment: np.ndarray) -> float:
    """Estimated relative error of the unexplainable noise, ||e|| / ||Y||.

    Parameters
    ----------
    residual : ndarray, shape (m,)
        Residual of a fit on the decimated samples [N m].
    y : ndarray, shape (m,)
        Measured torque of those samples [N m].
    experiment : ndarray of int, shape (m,)
        Run of each sample; differences and spectra are taken within runs only.

    Returns
    -------
    float
        sqrt(m) σ̂ / ||Y|| with σ̂ the lower of MAD(Δ²ρ) / √6 and the square root of half the
        median one-sided spectral density of ρ over [0.1, 0.5] cycles per sample
        (:data:`SPECTRUM_BAND`); NaN with fewer than 10 samples.
    """
    r = np.asarray(residual, dtype=float)
    exp = np.asarray(experiment)
    parts, psd = [], []
    for e in np.unique(exp):
        x = r[exp == e]
        if x.size >= 3:
            parts.append(np.diff(x, 2))
        if x.size >= 32:
            f, p = signal.welch(x - x.mean(), fs=1.0, nperseg=min(256, x.size))
            psd.append(p[f >= SPECTRUM_BAND])
    d2 = np.concatenate(parts) if parts else np.empty(0)
    ny = float(np.linalg.norm(y))
    if d2.size < 10 or ny <= 0:
        return math.nan
    sigma = _mad(d2) / math.sqrt(6.0)
    if psd:
        sigma = min(sigma, math.sqrt(0.5 * float(np.median(np.concatenate(psd)))))
    return sigma * math.sqrt(r.size) / ny


def heldout_kind(experiment: np.ndarray) -> str:
    """``"leave one run out"`` with two runs or more, else ``"blocked folds"``."""
    return "leave one run out" if np.unique(experiment).size >= 2 else "blocked folds"


def _start_offset(t0: np.ndarray, q0: np.ndarray, tr: np.ndarray, qr: np.ndarray,
                  spread: np.ndarray, max_shift: float) -> float:
    """The delay [s] of run r's start against the first run's that best aligns their
    positions: the least mean squared difference of the normalised positions (summed over
    joints) over the time both cover, on a uniform grid at the first run's median period,
    for every delay within +-``max_shift`` with at least half the shorter run in common (all
    delays at once by FFT cross-correlations)."""
    dt = float(np.median(np.diff(t0))) if t0.size > 1 else 0.0
    if not dt > 0:
        return 0.0
    grid0 = np.arange(t0[0], t0[-1] + 0.5 * dt, dt)
    gridr = np.arange(tr[0], tr[-1] + 0.5 * dt, dt)
    n = grid0.size + gridr.size

    def xcorr(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        # c[k] = sum_i y[i + k] x[i] (k < 0 wrapped to the end)
        return np.fft.irfft(np.fft.rfft(y, n) * np.conj(np.fft.rfft(x, n)), n)

    ones0, onesr = np.ones(grid0.size), np.ones(gridr.size)
    common = xcorr(ones0, onesr)
    sq = np.zeros(n)
    for j in range(q0.shape[1]):
        a = np.interp(grid0, t0, q0[:, j]) / spread[j]
        b = np.interp(gridr, tr, qr[:, j]) / spread[j]
        sq += xcorr(a * a, onesr) + xcorr(ones0, b * b) - 2.0 * xcorr(a, b)
    lags = np.arange(n)
    lags = np.where(lags > n // 2, lags - n, lags)
    offsets = lags * dt + (gridr[0] - grid0[0])
    ok = (np.abs(offsets) <= max_shift) & (common >= 0.5 * min(grid0.size, gridr.size) - 0.5)
    if not ok.any():
        return 0.0
    msd = sq[ok] / common[ok]
    return float(offsets[ok][int(np.argmin(msd))])


def one_trajectory(t: np.ndarray, q: np.ndarray, experiment: np.ndarray,
                   tol: float = TRAJECTORY_TOL) -> bool:
    """Whether every run replays the first run's trajectory (two runs or more).

    Parameters
    ----------
    t : ndarray, shape (m,)
        Time since the start of the sample's own run [s] (``Signals.t``).
    q : ndarray, shape (m,) or (m, k)
        Positions [rad or m] (k joints: all compared).
    experiment : ndarray of int, shape (m,)
        Run of each sample.
    tol : float
        :data:`TRAJECTORY_TOL`.

    Returns
    -------
    bool
        True when, for every run after the first, the RMS difference between its positions
        and the first run's, once its start is aligned with the first run's (the delay that
        best matches them, at most :data:`MAX_START_OFFSET` of the first run's duration:
        logs whose recording starts a little earlier or later replay the same path), over
        the time both cover, is at most ``tol`` times the standard deviation of the positions
        (per joint); False with one run, or when a run shares less than half its time span
        with the first.
    """
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    q = q[:, None] if q.ndim == 1 else q
    exp = np.asarray(experiment)
    runs = np.unique(exp)
    if runs.size < 2:
        return False
    spread = np.std(q, axis=0)
    if not np.all(spread > 0):
        return False
    first = exp == runs[0]
    t0, q0 = t[first], q[first]
    order = np.argsort(t0)
    t0, q0 = t0[order], q0[order]
    max_shift = MAX_START_OFFSET * float(np.ptp(t0))
    for r in runs[1:]:
        m = exp == r
        order = np.argsort(t[m])
        tr, qr = t[m][order], q[m][order]
        tr = tr - _start_offset(t0, q0, tr, qr, spread, max_shift)
        inside = (tr >= t0[0]) & (tr <= t0[-1])
        if inside.sum() < 2 or np.ptp(tr[inside]) < 0.5 * np.ptp(tr):
            return False
        for j in range(q.shape[1]):
            d = qr[inside, j] - np.interp(tr[inside], t0, q0[:, j])
            if math.sqrt(float(np.mean(d * d))) > tol * spread[j]:
                return False
    return True


def _folds(experiment: np.ndarray) -> np.ndarray:
    exp = np.asarray(experiment)
    runs = np.unique(exp)
    if runs.size >= 2:
        return np.searchsorted(runs, exp)
    m = exp.size
    return np.minimum((np.arange(m) * N_BLOCKS) // max(m, 1), N_BLOCKS - 1)


def heldout_error(W: np.ndarray, y: np.ndarray, experiment: np.ndarray) -> float:
    """Relative error of predictions on data the fit never saw, ||y - ŷ_out|| / ||y||.

    Each fold (a run, or one of :data:`N_BLOCKS` contiguous blocks of a single run) is
    predicted by the least-squares fit of ``W`` on the other folds (columns scaled to unit
    norm, minimum-norm solution where the other folds leave a column unidentified).

    Parameters
    ----------
    W : ndarray, shape (m, p)
        Regressor of the model (decimated, selected samples).
    y : ndarray, shape (m,)
        Measured torque [N m].
    experiment : ndarray of int, shape (m,)
        Run of each sample.

    Returns
    -------
    float
    """
    W = np.asarray(W, dtype=float)
    y = np.asarray(y, dtype=float)
    folds = _folds(experiment)
    norms = np.linalg.norm(W, axis=0)
    Ws = W / np.where(norms > 0, norms, 1.0)
    G = Ws.T @ Ws
    b = Ws.T @ y
    out = np.empty_like(y)
    for f in np.unique(folds):
        m = folds == f
        Wf = Ws[m]
        Gf, bf = G - Wf.T @ Wf, b - Wf.T @ y[m]
        c = np.linalg.lstsq(Gf, bf, rcond=1e-10)[0]
        out[m] = y[m] - Wf @ c
    ny = float(np.linalg.norm(y))
    return float(np.linalg.norm(out)) / ny if ny > 0 else math.nan
