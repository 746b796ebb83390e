"""The time base of a measured run: irregular time stamps read onto a uniform grid
(:func:`uniform_grid`, the one resampling of the single-joint and the robot loaders,
:mod:`ident.loaders`, and of :func:`ident.chain.choose_cutoff`).

Three readings of irregular stamps are possible, and the data say which holds: the values
were taken at their stamps (interpolated onto the grid of the median period); the values
were sampled one per period and only the stamps err (jitter, or a drifting host clock: the
values kept, on the stamps' least-squares line); or the values were sampled on a fixed
period with a few samples lost and the stamps drift (the slots counted from the rounded
steps, :func:`counted_slots`: each value at its slot, the lost slots filled from their
neighbours as the stamp reading fills them, and named in the warning).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping

import numpy as np

__all__ = [
    "ACCUMULATING_LAG1",
    "GAP_PERIODS",
    "IRREGULAR_TOL",
    "MAX_LISTED_GAPS",
    "ResamplingWarning",
    "STEP_BAND",
    "counted_slots",
    "step_spread",
    "uniform_grid",
]

#: Relative spread of the sampling period above which a file is resampled.
IRREGULAR_TOL = 0.01
#: A step of the time column longer than this many median periods is a gap in the recording
#: (samples lost, logger paused): refused, never interpolated across.
GAP_PERIODS = 5.0
#: How far (a fraction of the median period) the stamps of one step may span from a whole
#: number (>= 1) of periods, and of two consecutive steps from the sum of theirs, for each
#: sample to hold its own slot (:func:`counted_slots`): then no sample was added (an added
#: sample's two steps of about half a period count two but span one), a step of about m
#: periods is m - 1 samples lost, and
#: the values may be taken as one sample per slot however far the stamps drift. Midway
#: between two whole numbers: a clock whose steps vary by s (std, normal) keeps all of 10^5
#: steps and pairs within it for s up to about 8 %, while an added sample's pair of steps
#: (one period, spread s sqrt(2)) falls within it of two with a probability below 1e-5 there.
STEP_BAND = 0.5
#: Most gaps (runs of lost slots) the warning of the counted-slot reading names (sample, stamp).
MAX_LISTED_GAPS = 5


class ResamplingWarning(UserWarning):
    """An experiment was irregularly sampled and has been resampled to a uniform grid."""


def _hf_noise(x: np.ndarray, dt: float) -> float:
    """Noise of positions ``x`` (shape (n,) or (n, k)) in the complement of the excitation
    band: per axis, the median power of the Hann-windowed position spectrum above f_s/4
    (where the motion of an identification trajectory has no content), summed in log over
    the axes (a ratio between two gridings of the same axes is a product of per-axis ratios).
    """
    a = np.asarray(x, dtype=float).reshape(len(x), -1)
    n = a.shape[0]
    f = np.fft.rfftfreq(n, dt)
    upper = f > 0.25 / dt
    win = np.hanning(n)
    out = 0.0
    for col in a.T:
        c = col - np.polyval(np.polyfit(np.arange(n), col, 1), np.arange(n))
        p = np.abs(np.fft.rfft(c * win)) ** 2
        out += float(np.log(max(float(np.median(p[upper])), 1e-300)))
    return out


def _reading_noise(x: np.ndarray, times: np.ndarray, dt: float) -> float:
    """Noise above f_s/4 (:func:`_hf_noise`) of positions ``x`` (shape (n,) or (n, k)) read at
    ``times`` [s]: of each sample's departure from the straight line through its two
    neighbours at their times. Neither reading of :func:`uniform_grid` is resampled to be
    judged: interpolating one of them would average its samples' own noise (white noise:
    down to a third at Nyquist) and favour it -- what read a simulated joint's uniformly
    sampled values under a 1 % random-walk clock at their stamps, at 4x its clean fit error.
    The measurement noise then weighs the same in both readings (neighbour weights near 1/2),
    and only the wrong times add q̇ x (their error's departure from its neighbours')."""
    a = np.asarray(x, dtype=float).reshape(len(x), -1)
    w = ((times[2:] - times[1:-1]) / (times[2:] - times[:-2]))[:, None]
    return _hf_noise(a[1:-1] - (w * a[:-2] + (1.0 - w) * a[2:]), dt)


#: Lag-1 autocorrelation of the time steps above which the stamp errors accumulate (a clock
#: whose every period errs on its own: consecutive steps uncorrelated, 0) rather than each
#: stamp erring about its own slot (white stamp jitter: -0.5); midway between the two.
ACCUMULATING_LAG1 = -0.25


def step_spread(d: np.ndarray) -> float:
    """Spread of the time steps ``d`` [s] as a fraction of their median: the standard
    deviation from the median absolute deviation (x 1.4826, so that an isolated lost sample
    does not count), the plain one where that is 0 (steps quantised to a few values)."""
    med = float(np.median(d))
    mad = 1.4826 * float(np.median(np.abs(d - med)))
    return (mad if mad > 0 else float(np.std(d))) / med


def counted_slots(d: np.ndarray, med: float) -> np.ndarray | None:
    """Slot of every sample counted from the time steps: each step ``d`` [s] divided by the
    period ``med`` [s] and rounded to a whole number of periods, accumulated (0 for the first
    sample). A slot per sample only when every step is within :data:`STEP_BAND` of a whole
    number m >= 1 of periods, every two consecutive steps within it of the sum of their m,
    and no step beyond :data:`GAP_PERIODS` periods; else None (a sample added, steps that are
    no whole numbers of periods -- sampling at irregular instants --, or a gap). A step of
    m >= 2 periods holds m - 1 lost samples; without one, the slots are the sample indices.
    (:func:`_slots_or_misfit`, which also says which step fails.)
    """
    return _slots_or_misfit(d, med)[0]


def _slots_or_misfit(d: np.ndarray, med: float) -> tuple[np.ndarray | None, str]:
    """The one rule of :func:`counted_slots`: ``(slots, "")``, or ``(None, words)`` with the
    warning's words for the first check that fails (a gap, a sample added, a step of no whole
    number of periods, a pair of steps off the sum of their counts)."""
    if d.size == 0 or not med > 0:
        return None, "no step of a positive period"
    r = d / med
    m = np.rint(r)
    if float(np.max(r)) > GAP_PERIODS:
        return None, f"a step of {float(np.max(r)):.3g} periods: a gap"
    if float(np.min(m)) < 1:
        return None, f"a step of {float(np.min(r)):.3g} periods: a sample added"
    i = int(np.argmax(np.abs(r - m)))
    if abs(r[i] - m[i]) >= STEP_BAND:
        return None, f"a step of {r[i]:.3g} periods: no whole number of periods"
    if d.size > 1:
        r2, m2 = r[1:] + r[:-1], m[1:] + m[:-1]
        i = int(np.argmax(np.abs(r2 - m2)))
        if abs(r2[i] - m2[i]) >= STEP_BAND:
            return None, (f"two steps of {r2[i]:.3g} periods, counted {m2[i]:.0f}: a sample "
                          f"{'added' if r2[i] < m2[i] else 'lost'}, or steps of no whole "
                          "number of periods")
    return np.r_[0.0, np.cumsum(m)], ""


def _lost_where(slots: np.ndarray, t: np.ndarray) -> str:
    """Where the samples the counted reading finds lost are: the index and the stamp ``t``
    [s] of the sample after which each gap of ``slots`` opens (as the file numbers and stamps
    it), with the gap's count of lost samples, the first :data:`MAX_LISTED_GAPS` listed."""
    gaps = np.flatnonzero(np.diff(slots) > 1)
    items = []
    for i in gaps[:MAX_LISTED_GAPS]:
        lost = int(slots[i + 1] - slots[i]) - 1
        items.append(f"{lost} after sample {i} (t={t[i]:.6g} s)")
    more = f" and {gaps.size - MAX_LISTED_GAPS} more gaps" if gaps.size > MAX_LISTED_GAPS else ""
    return ", ".join(items) + more


def _drift_advice(t: np.ndarray, d: np.ndarray, pos: np.ndarray, b: float, med: float) -> str:
    """What the warning of :func:`uniform_grid` adds when the values are read at their stamps
    because the uniform reading was no candidate (some stamp more than half a period off a
    uniform grid and some step beyond :data:`STEP_BAND`): whether the stamp errors accumulate
    (a drifting clock: consecutive steps uncorrelated, :data:`ACCUMULATING_LAG1`) and, when the
    values as they are (the sample index as the time base) are quieter above f_s/4 than
    read at the stamps (the judge of the two readings, :func:`_reading_noise`), that the
    drive's cycle times are the remedy for values of a fixed-cycle clock (a lost cycle then
    keeps its slot; a uniform time column would shift every later value by a period)."""
    x = d - d.mean()
    xx = float(np.dot(x, x))
    lag1 = float(np.dot(x[1:], x[:-1])) / xx if xx > 0 and x.size > 1 else -0.5
    if lag1 <= ACCUMULATING_LAG1:
        return (f"; the steps anticorrelated (lag-1 {lag1:.2f}): not a drifting clock (stamps "
                "jittered about their slots, or a sample lost)")
    out = (f"; accumulating (consecutive steps uncorrelated, lag-1 {lag1:.2f}: a drifting "
           "clock, or values truly taken at irregular instants)")
    n_axes = int(pos.reshape(t.size, -1).shape[1])
    ti = t[0] + b * np.arange(t.size)
    ratio = float(np.exp((_reading_noise(pos, t, med) - _reading_noise(pos, ti, b)) / n_axes))
    if ratio > 1.0:
        out += (f"; taken as uniformly sampled, the positions' noise above f_s/4 would be "
                f"{ratio:.3g}x lower: if the values come from a fixed-cycle clock (a drive's) "
                "and the stamps from another, give the drive's cycle times as the time column "
                "(cycle number x period: a lost cycle keeps its slot)")
    return out


def uniform_grid(
    t: np.ndarray,
    arrays: Mapping[str, np.ndarray | None],
    *,
    source: str = "",
    judge: str = "q",
    warn: bool = True,
    stacklevel: int = 2,
) -> tuple[np.ndarray, dict[str, np.ndarray | None], str | None]:
    """Put samples with irregular time stamps on a uniform grid (the one resampling of the
    single-joint and the robot loaders, and of :func:`ident.chain.choose_cutoff`).

    Stamps whose steps stay within :data:`IRREGULAR_TOL` of their median are regular:
    returned as given. Otherwise the stamps may be read in three ways, and the data say
    which holds:

    * the values were taken at their stamps (irregular sampling instants): linear
      interpolation onto the grid of the median period;
    * the values were sampled uniformly and only the stamps err (a host clock stamping a
      drive's cycles): the values as they are, on the least-squares line through the stamps
      (t ≈ a + b k). A candidate only when each sample holds its own period: every stamp
      within half a period of its slot on that line (white jitter), or the slots counted
      from the steps (:func:`counted_slots`: every step within :data:`STEP_BAND` of a whole
      number of periods, every two consecutive steps within it of their sum) one per step (a
      clock that drifts, e.g. a random walk whose stamps wander several periods off the
      line);
    * the same with a few samples lost: the counted slots skip some (a step of about m
      periods holds m - 1 lost samples). Each value is put at its slot on the stamps'
      least-squares line over the slots (t ≈ a + b slot), and the lost slots are filled by
      linear interpolation from their neighbours, as the first reading fills a short gap
      (gaps beyond :data:`GAP_PERIODS` periods are refused by the callers, and never counted
      here); the warning says how many samples were lost and where. Without the count,
      taken as uniformly sampled every value after a lost sample would be a period off its
      time. An added sample (two steps of about one period together) leaves no slot count:
      the values are read at their stamps.

    The reading whose positions (``arrays[judge]``) have less noise in the complement of the
    excitation band (:func:`_reading_noise`: spectrum above f_s/4 of each sample's departure
    from its neighbours, at that reading's times; neither reading resampled) is taken: reading
    values at the wrong instants adds q̇ × (stamp error) there, broadband noise that no
    cut-off chosen from the data survives; reading values taken at irregular instants as
    uniform adds the same, the other way. A :class:`ResamplingWarning` names the reading and
    the noise ratio that chose it. On a copy of the real EMPS run whose stamps are a
    random-walk clock (steps dt (1 + s e), s = 1 % and 3 %, seeds 1-3) the stamps wander up
    to several periods off the line; the values are read as uniformly sampled and fitted as
    the original (4.035 %) where the stamps read as instants gave 7.7-20.1 %
    (tests/test_clock_reading_drift.py); with 1 to 10 of its samples lost, the counted slots
    fit as the original too (tests/test_clock_counted_slots.py).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Strictly increasing time stamps [s] (gaps refused by the callers beforehand).
    arrays : mapping of str to ndarray (shape (n,) or (n, k)) or None
        The signals sampled at ``t``; None entries are passed through.
    source : str
        Names the data in the warning.
    judge : str
        The key of the positions the readings are compared on.
    warn : bool
        Warn when the stamps are irregular.
    stacklevel : int
        Of the warning.

    Returns
    -------
    t : ndarray, shape (m,)
        Uniform time [s] (m = n for regular stamps and for the uniform reading, n plus the
        lost samples for the counted slots).
    arrays : dict
        The signals on ``t``.
    note : str or None
        What was done (the warning's text), None for regular stamps.
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    out: dict[str, np.ndarray | None] = dict(arrays)
    d = np.diff(t)
    med = float(np.median(d))
    if d.size == 0 or np.max(np.abs(d - med)) <= IRREGULAR_TOL * med:
        return t, out, None
    where = f"{source}: " if source else ""
    spread = step_spread(d)
    span = (f"period {d.min():.3g}..{d.max():.3g} s, the steps vary {100 * spread:.3g} % of "
            "the period (std)")
    n = int(round((t[-1] - t[0]) / med)) + 1
    tu = t[0] + med * np.arange(n)
    tu = tu[tu <= t[-1] + 1e-12 * abs(t[-1])]

    def on_grid(a: np.ndarray, grid: np.ndarray, at: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=float)
        if a.ndim == 1:
            return np.interp(grid, at, a)
        return np.column_stack([np.interp(grid, at, a[:, j]) for j in range(a.shape[1])])

    slots, misfit = _slots_or_misfit(d, med)
    k = np.arange(t.size, dtype=float) if slots is None else slots
    b, a0 = np.polyfit(k, t, 1)
    ti = a0 + b * k
    off = float(np.max(np.abs(t - ti))) / b if b > 0 else np.inf  # [periods]
    lost = 0 if slots is None else int(slots[-1]) + 1 - t.size
    in_slots = off < 0.5
    counted = b > 0 and slots is not None
    pos = arrays.get(judge)
    if (in_slots or counted) and pos is not None and t.size >= 16:
        noise_stamps = _reading_noise(pos, t, med)
        noise_index = _reading_noise(pos, ti, b)
        n_axes = int(np.asarray(pos).reshape(t.size, -1).shape[1])
        ratio = float(np.exp((noise_stamps - noise_index) / n_axes))  # per axis, geometric
        if ratio > 1.0:
            higher = f"read at the stamps, the positions' noise above f_s/4 is {ratio:.3g}x higher"
            if lost == 0:
                how = ("jitter of uniformly sampled values" if in_slots else
                       "a drifting clock's stamps of uniformly sampled values (up to "
                       f"{off:.3g} periods off a uniform grid, every step within {STEP_BAND:g} "
                       "period of one and every two of two: no sample lost or added)")
                note = (f"{where}irregular time stamps ({span}) taken as {how}, on a uniform "
                        f"grid of {t.size} samples at {b:.6g} s: {higher}")
                if warn:
                    warnings.warn(note, ResamplingWarning, stacklevel=stacklevel)
                return ti, out, note
            slot = np.arange(int(k[-1]) + 1, dtype=float)  # k: the counted slots
            tg = a0 + b * slot
            for name, a in arrays.items():  # exact at the counted slots, the lost ones filled
                out[name] = None if a is None else on_grid(a, slot, k)
            clock = "jittered" if in_slots else "a drifting clock's"
            note = (f"{where}irregular time stamps ({span}) taken as {clock} stamps of "
                    f"uniformly sampled values with {lost} sample(s) lost: "
                    f"{_lost_where(k, t)} (the slots counted from the steps, up to "
                    f"{off:.3g} periods off a uniform grid: every step within {STEP_BAND:g} "
                    "period of a whole number of periods and every two of their sum), each "
                    f"value at its slot on a uniform grid of {tg.size} samples at {b:.6g} s, "
                    "the lost slots interpolated linearly from their neighbours (the torque "
                    f"too): {higher}")
            if warn:
                warnings.warn(note, ResamplingWarning, stacklevel=stacklevel)
            return tg, out, note
        why = (f" (values taken at their stamps: their noise above f_s/4 is {1 / ratio:.3g}x "
               "lower than taken as uniformly sampled"
               + (f" with {lost} sample(s) lost)" if lost else ")"))
    else:
        why = ("" if pos is None or t.size < 16 else
               " (values taken at their stamps: some stamp is more than half a period off "
               f"a uniform grid ({off:.3g} periods at most) and {misfit}, or a "
               "clock too irregular to tell"
               f"{_drift_advice(t, d, np.asarray(pos, dtype=float), b, med)})")
    for name, a in arrays.items():
        out[name] = None if a is None else on_grid(a, tu, t)
    # the torque is interpolated with the positions: its noise is averaged between
    # neighbouring samples (white noise: variance x 2/3 on average), so the fit's error and
    # noise floor measure that smoothed torque, below what the same samples on their own give
    note = (f"{where}irregular sampling ({span}), resampled to {tu.size} samples at {med:.6g} s"
            f"{why}; every signal interpolated, the torque too: its noise averaged between "
            "neighbouring samples, the fit's error and noise floor measure that smoother torque")
    if warn:
        warnings.warn(note, ResamplingWarning, stacklevel=stacklevel)
    return tu, out, note
