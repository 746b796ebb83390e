"""Residual diagnosis: which variable does the residual of a fitted model depend on?

Pure numerics on arrays (the decimated samples a model was fitted on, and its residual
ρ = Y - W χ̂, paper eq. 12-13):

* :func:`dependence` — the share of the residual variance explained by binned means of one
  variable (η² = SS_between / SS_total) with an F test against noise whose degrees of
  freedom use the effective sample size of an autocorrelated residual;
* :func:`diagnose` — that test for the seven candidate variables, ranked, plus
  :func:`periodogram` of the residual against position (unknown periods: cogging, gear mesh,
  screw pitch) and against time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from .effects import Prediction, available_variables, effective_n, variable_values
from .signals import Signals

DISCRETE = ("direction", "quadrant")


@dataclass(frozen=True)
class Dependence:
    """How much of the residual one variable explains.

    Attributes
    ----------
    variable : str
        Candidate variable name.
    explained : float
        η² = SS_between / SS_total, share of the residual variance explained by the binned
        means of the variable, in [0, 1].
    statistic : float
        F statistic of the binned means against noise (effective-sample corrected).
    p_value : float
        Probability of an F at least this large if the residual did not depend on the
        variable.
    n_bins : int
        Number of non-empty bins.
    centers : ndarray, shape (n_bins,)
        Mean of the variable in each bin.
    means : ndarray, shape (n_bins,)
        Mean residual in each bin [N m].
    """

    variable: str
    explained: float
    statistic: float
    p_value: float
    n_bins: int
    centers: np.ndarray = field(repr=False)
    means: np.ndarray = field(repr=False)

    @property
    def significant(self) -> bool:
        """p_value below 1e-3 (the default level of :func:`diagnose`)."""
        return self.p_value < 1e-3


def _bin_index(x: np.ndarray, bins: int, discrete: bool) -> np.ndarray:
    if discrete:
        _, idx = np.unique(x, return_inverse=True)
        return idx
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)[1:-1]))
    return np.searchsorted(edges, x, side="right")


def dependence(
    residual: np.ndarray,
    x: np.ndarray,
    *,
    variable: str = "x",
    bins: int = 24,
    discrete: bool = False,
    n_eff: float | None = None,
) -> Dependence:
    """Binned-means dependence of the residual on one variable, with an F test.

    Parameters
    ----------
    residual : ndarray, shape (n,)
        Residual ρ [N m].
    x : ndarray, shape (n,)
        The candidate variable.
    variable : str
        Its name, for the result.
    bins : int
        Number of equal-count (quantile) bins for a continuous variable.
    discrete : bool
        Bin by the distinct values of ``x`` instead (direction, quadrant).
    n_eff : float, optional
        Effective number of independent samples (default :func:`effective_n`); the F
        statistic is scaled by n_eff / n, which accounts for correlated samples.

    Returns
    -------
    Dependence
    """
    r = np.asarray(residual, dtype=float)
    x = np.asarray(x, dtype=float)
    n = r.shape[0]
    idx = _bin_index(x, bins, discrete)
    k = int(idx.max()) + 1 if n else 0
    cnt = np.bincount(idx, minlength=k).astype(float)
    ok = cnt > 0
    sum_r = np.bincount(idx, weights=r, minlength=k)
    sum_x = np.bincount(idx, weights=x, minlength=k)
    means = sum_r[ok] / cnt[ok]
    centers = sum_x[ok] / cnt[ok]
    kb = int(ok.sum())
    mu = r.mean() if n else 0.0
    ss_tot = float(((r - mu) ** 2).sum())
    ss_b = float((cnt[ok] * (means - mu) ** 2).sum())
    ss_w = max(ss_tot - ss_b, 1e-300)
    if n_eff is None:
        n_eff = effective_n(r)
    n_eff = min(float(n_eff), float(n))
    d1, d2 = kb - 1, n_eff - kb
    if d1 < 1 or d2 < 1 or ss_tot <= 0:
        return Dependence(variable, 0.0, 0.0, 1.0, kb, centers, means)
    F = (ss_b / d1) / (ss_w / (n - kb)) * (n_eff / n)
    p = float(stats.f.sf(F, d1, d2))
    return Dependence(variable, ss_b / ss_tot, float(F), p, kb, centers, means)


@dataclass(frozen=True)
class Periodogram:
    """Lomb-Scargle periodogram of the residual against a variable (position or time).

    Attributes
    ----------
    against : str
        ``"position"`` or ``"time"``.
    periods : ndarray, shape (m,)
        Periods scanned [rad, m or s].
    power : ndarray, shape (m,)
        Normalised power in [0, 1]: share of the residual variance a sinusoid of that period
        explains.
    peak_period : float
        Period of the largest peak.
    peak_power : float
        Its normalised power.
    false_alarm : float
        Probability that noise gives a peak this high somewhere in the scanned band
        (Bonferroni over the independent frequencies, effective-sample corrected).
    """

    against: str
    periods: np.ndarray = field(repr=False)
    power: np.ndarray = field(repr=False)
    peak_period: float
    peak_power: float
    false_alarm: float


def _sinusoid_share(r: np.ndarray, x: np.ndarray, period: float) -> float:
    """Share of the variance of ``r`` explained by a sinusoid of ``period`` in ``x``."""
    th = (2 * np.pi / period) * x
    A = np.column_stack((np.sin(th), np.cos(th), np.ones_like(x)))
    c, *_ = np.linalg.lstsq(A, r, rcond=None)
    fit = A @ c - c[2]
    den = float(r @ r)
    return float(fit @ fit / den) if den > 0 else 0.0


def periodogram(
    residual: np.ndarray,
    x: np.ndarray,
    *,
    against: str = "position",
    min_period: float | None = None,
    max_period: float | None = None,
    n_eff: float | None = None,
) -> Periodogram:
    """Periodogram of the residual against an unevenly sampled variable ``x``.

    The residual is averaged on a uniform grid of ``x`` (bins of a fifth of the shortest
    period), the grid is Fourier transformed with 4x zero padding, and the share of the
    residual variance explained by a sinusoid is then computed by least squares on the
    samples themselves at the three highest peaks. Cost O(n + m log m): no Lomb-Scargle
    double loop.

    Parameters
    ----------
    residual : ndarray, shape (n,)
        Residual [N m].
    x : ndarray, shape (n,)
        Position [rad or m] or time [s].
    against : str
        Name of ``x``, for the result.
    min_period, max_period : float, optional
        Band of periods; default from range/1000 to range/3 (at least three periods).
    n_eff : float, optional
        Effective number of independent samples (default :func:`effective_n`).
    """
    r = np.asarray(residual, dtype=float)
    x = np.asarray(x, dtype=float)
    r = r - r.mean() if r.size else r
    span = float(x.max() - x.min()) if x.size else 0.0
    if span <= 0 or r.size < 16 or not np.any(r):
        z = np.ones(1)
        return Periodogram(against, z, 0 * z, float("nan"), 0.0, 1.0)
    if max_period is None:
        max_period = span / 3
    if min_period is None:
        min_period = span / 1000
    min_period = max(min_period, 2 * span / r.size)
    if max_period <= min_period:
        max_period = 2 * min_period
    m = int(min(2**18, 2 ** np.ceil(np.log2(5 * span / min_period))))
    h = span / m
    idx = np.minimum(((x - x.min()) / h).astype(np.int64), m - 1)
    cnt = np.bincount(idx, minlength=m)
    g = np.bincount(idx, weights=r, minlength=m)
    g[cnt > 0] /= cnt[cnt > 0]
    nfft = 4 * m
    P = np.abs(np.fft.rfft(g, nfft)) ** 2
    freq = np.fft.rfftfreq(nfft, d=h)
    band = (freq >= 1 / max_period) & (freq <= 1 / min_period)
    if not band.any():
        z = np.ones(1)
        return Periodogram(against, z, 0 * z, float("nan"), 0.0, 1.0)
    fb, pb = freq[band], P[band]
    power = pb / max(float(pb.max()), 1e-300)
    # the three highest local maxima, judged on the samples themselves
    loc = np.flatnonzero((pb[1:-1] >= pb[:-2]) & (pb[1:-1] >= pb[2:])) + 1
    if loc.size == 0:
        loc = np.array([int(np.argmax(pb))])
    top = loc[np.argsort(pb[loc])[::-1][:3]]
    shares = [_sinusoid_share(r, x, 1 / fb[i]) for i in top]
    j = int(np.argmax(shares))
    share, period = shares[j], float(1 / fb[top[j]])
    power = power * share / max(float(power[top[j]]), 1e-300)
    if n_eff is None:
        n_eff = effective_n(r)
    n_eff = min(float(n_eff), float(r.size))
    # noise: the variance share of one sinusoid ~ Beta(1, (N - 3) / 2)
    p1 = float(stats.beta.sf(share, 1.0, max((n_eff - 3) / 2, 1.0)))
    n_ind = max(span * (1 / min_period - 1 / max_period), 1.0)
    fa = float(min(1.0, p1 * n_ind))
    return Periodogram(against, 1 / fb, power, period, share, fa)


@dataclass(frozen=True)
class Diagnosis:
    """Ranked dependence of a residual on the candidate variables, and periodograms.

    Attributes
    ----------
    table : list of Dependence
        One row per candidate variable, most significant first (largest F statistic).
    position_periodogram, time_periodogram : Periodogram
        Residual spectra against position and time.
    rel_error : float
        ||ρ|| / ||Y|| of the diagnosed fit.
    n_eff : float
        Effective number of independent residual samples.
    acceleration : {"measured", "reference"}
        Which acceleration the ``acceleration`` row is binned on (:func:`diagnose`).
    """

    table: list[Dependence]
    position_periodogram: Periodogram
    time_periodogram: Periodogram
    rel_error: float
    n_eff: float
    alpha: float = 1e-3
    acceleration: str = "measured"

    def get(self, variable: str) -> Dependence:
        """The row of one variable."""
        for d in self.table:
            if d.variable == variable:
                return d
        raise KeyError(variable)

    @property
    def significant(self) -> list[Dependence]:
        """Rows whose p-value is below ``alpha`` (Bonferroni over the variables)."""
        return [d for d in self.table if d.p_value < self.alpha / len(self.table)]

    def format_table(self) -> str:
        """The ranked table as text."""
        lines = [f"{'variable':<13}{'explained':>10}{'F':>11}{'p-value':>11}  bins"]
        for d in self.table:
            lines.append(
                f"{d.variable:<13}{100 * d.explained:>9.2f}%{d.statistic:>11.3g}"
                f"{d.p_value:>11.2e}  {d.n_bins}"
            )
        if self.acceleration == "reference":
            lines.append("(acceleration: the reference trajectory's, as the IDIM-IV "
                         "instruments read it; the measured one's noise stays in an IV "
                         "residual, where it is errors in variables, not an effect)")
        pp = self.position_periodogram
        lines.append(
            f"position periodogram: peak period {pp.peak_period:.6g}, "
            f"power {100 * pp.peak_power:.2f}%, false-alarm p {pp.false_alarm:.2e}"
        )
        return "\n".join(lines)

    def to_json(self) -> list[dict]:
        """JSON-ready rows."""
        return [
            {
                "variable": d.variable,
                "explained": d.explained,
                "statistic": d.statistic,
                "p_value": d.p_value,
            }
            for d in self.table
        ]


def candidate_variables(s: Signals, tau_out: Prediction | None = None) -> dict[str, np.ndarray]:
    """The candidate variables on the samples ``s`` (see :func:`variable_values`): all seven
    with a load prediction, without ``load`` and ``quadrant`` otherwise."""
    return {v: variable_values(v, s, tau_out) for v in available_variables(tau_out)}


def diagnose(
    residual: np.ndarray,
    s: Signals,
    *,
    Y: np.ndarray | None = None,
    tau_out: Prediction | None = None,
    bins: int = 24,
    alpha: float = 1e-3,
    acceleration: np.ndarray | None = None,
) -> Diagnosis:
    """Diagnose the residual of a fit against the seven candidate variables.

    Parameters
    ----------
    residual : ndarray, shape (n,)
        ρ = Y - W χ̂ on the decimated samples the model was fitted on [N m].
    s : Signals
        Those samples (len n).
    Y : ndarray, shape (n,), optional
        Measured torque, for the relative error (default ``s.tau``).
    tau_out : Prediction, optional
        Load-torque predictor for the ``load`` variable.
    bins : int
        Quantile bins per continuous variable.
    alpha : float
        Family-wise significance level of :attr:`Diagnosis.significant`.
    acceleration : ndarray, shape (n,), optional
        The acceleration the ``acceleration`` row is binned on instead of ``s.ddq``: the
        reference trajectory's on an IDIM-IV fit (:meth:`ident.preprocess.Design.
        reference_acceleration`). The IV residual keeps the part of the torque that follows
        the measured acceleration's noise (errors in variables: the instruments are blind
        to it), so binned on the measured acceleration it "explains" a share no term can
        take (27.7 % on the demo's quick logs, where a generic acceleration term is
        rejected by the IV fit).
    """
    r = np.asarray(residual, dtype=float)
    if r.shape[0] != len(s):
        raise ValueError(f"diagnose: residual has {r.shape[0]} samples, signals {len(s)}")
    n_eff = effective_n(r)
    rows = []
    values = candidate_variables(s, tau_out)
    if acceleration is not None:
        acc = np.asarray(acceleration, dtype=float)
        if acc.shape != r.shape:
            raise ValueError(f"diagnose: acceleration has shape {acc.shape}, expected {r.shape}")
        values["acceleration"] = acc
    for v, x in values.items():
        rows.append(dependence(r, x, variable=v, bins=bins, discrete=v in DISCRETE, n_eff=n_eff))
    rows.sort(key=lambda d: (d.p_value, -d.statistic))
    if Y is None and not s.has_output:
        raise ValueError("diagnose: give Y on a states-only view of the signals")
    y = s.tau if Y is None else Y
    rel = float(np.linalg.norm(r) / max(np.linalg.norm(y), 1e-300))
    moving = np.abs(s.dq) > 0
    qp = periodogram(r[moving], s.q[moving], against="position", n_eff=n_eff)
    tp = periodogram(r, s.t, against="time", n_eff=n_eff)
    return Diagnosis(rows, qp, tp, rel, n_eff, alpha,
                     "measured" if acceleration is None else "reference")
