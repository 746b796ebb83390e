"""Interaction diagnosis: does the residual depend on a *product* of variables?

:func:`ident.diagnose.diagnose` bins the residual ρ = Y - W χ̂ (eq. 12-13) against one
variable at a time. An effect that lives in an interaction escapes it: a dry friction whose
level varies along the position, F_C(q) sign(q̇), averages out in every position bin when
the joint passes both ways. This module tests, with the same effective-sample F test:

* ``single``: ρ binned on each variable (as :func:`ident.diagnose.dependence`);
* ``signed``: ρ · d binned on each continuous variable x, for d = sign(q̇) (``direction``)
  and d = sign(P) (``quadrant``, eq. 26): F_C(q) sign(q̇) shows as a dependence of
  ρ sign(q̇) on q;
* ``pair``: ρ on 2-D equal-count bins of two continuous variables, after removing the
  additive main effects of both (backfitted bin means), so that only the interaction
  counts (load x velocity, position x other joint's position);
* ``signed_pair``: the same for ρ · sign(q̇).

The p-values are corrected for the number of tests tried (Holm's step-down procedure, which
controls the family-wise error like Bonferroni and is uniformly more powerful).

Continuous variables: position, velocity, acceleration, load (τ̂_out), time, and
``reversal`` — the distance travelled since the last reversal of the motion (hysteresis,
pre-sliding); plus any "other" variables given as arrays (on a robot: the other joints'
positions and velocities). Pure numerics.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy import special

from .diagnose import effective_n
from .effects import Prediction, variable_values
from .signals import Signals

#: Continuous variables computed from the signals.
CONTINUOUS = ("position", "velocity", "acceleration", "load", "time", "reversal")
#: Discrete (sign) variables the residual is multiplied by.
SIGNS = ("direction", "quadrant")


def reversal_distance(s: Signals, deadband: float | None = None) -> np.ndarray:
    """Distance travelled since the last reversal of the motion, per experiment.

    A reversal is recognised on the position alone (a play operator): while moving
    forwards the running maximum is tracked, and the motion has reversed once the position
    falls ``deadband`` below it (conversely backwards); the distance is then counted from
    that extreme. Using q and a dead band, not sign(q̇), keeps the variable identical on
    full-rate and decimated samples and insensitive to velocity noise at low speed and at
    rest.

    Parameters
    ----------
    s : Signals
        Samples (full rate, or decimated and selected; in time order within an experiment).
    deadband : float, optional
        [rad or m]; default 2e-3 x the position range of the samples (at least 1e-9).

    Returns
    -------
    ndarray, shape (n,)
        |q - q_r| [rad or m], q_r the position of the last reversal (the first sample of
        the experiment before the first one).
    """
    hit = _REVERSAL_CACHE.get(id(s))
    if deadband is None and hit is not None and hit[0] is s:
        return hit[1]
    q = np.asarray(s.q, dtype=float)
    n = q.shape[0]
    out = np.zeros(n)
    if n == 0:
        return out
    cache = deadband is None
    if deadband is None:
        deadband = max(2e-3 * float(np.ptp(q)), 1e-9)
    exp = np.asarray(s.experiment)
    cuts = np.flatnonzero(np.diff(exp) != 0) + 1
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, n], strict=True):
        out[a:b] = _play_distance(q[a:b].tolist(), float(deadband))
    if cache:
        if len(_REVERSAL_CACHE) >= 4:
            _REVERSAL_CACHE.pop(next(iter(_REVERSAL_CACHE)))
        out.setflags(write=False)
        _REVERSAL_CACHE[id(s)] = (s, out)
    return out


#: The last few signals' reversal distances (the refinement asks for the same samples at
#: every step); keyed by id, checked by identity.
_REVERSAL_CACHE: dict[int, tuple[Signals, np.ndarray]] = {}


def _play_distance(q: list[float], db: float) -> np.ndarray:
    """Distance from the last reversal (dead band ``db``) of one experiment; the samples
    between an extreme and the recognition of the reversal are counted from the extreme."""
    out = [0.0] * len(q)
    if not q:
        return np.asarray(out)
    ref = hi = lo = q[0]
    i_hi = i_lo = 0
    direction = 0  # +1 forwards, -1 backwards, 0 not yet moving
    for i, x in enumerate(q):
        if direction >= 0:
            if x > hi:
                hi, i_hi = x, i
            if hi - x > db:  # reversed: forwards -> backwards at hi
                ref, direction, lo, i_lo = hi, -1, x, i
                for k in range(i_hi, i):
                    out[k] = abs(q[k] - ref)
            elif direction == 0 and x - ref > db:
                direction = 1
        if direction < 0:
            if x < lo:
                lo, i_lo = x, i
            if x - lo > db:  # backwards -> forwards at lo
                ref, direction, hi, i_hi = lo, 1, x, i
                for k in range(i_lo, i):
                    out[k] = abs(q[k] - ref)
        if direction == 0 and ref - x > db:
            direction, lo, i_lo = -1, x, i
        out[i] = abs(x - ref)
    return np.asarray(out)


def continuous_values(
    s: Signals,
    tau_out: Prediction | None = None,
    others: Mapping[str, np.ndarray] | None = None,
) -> dict[str, np.ndarray]:
    """The continuous variables on the samples ``s`` (see :data:`CONTINUOUS`) plus ``others``.

    Parameters
    ----------
    others : mapping of str to ndarray, shape (n,), optional
        Extra variables on the same samples (e.g. ``{"q2": ..., "dq2": ...}``).
    """
    out: dict[str, np.ndarray] = {}
    for v in CONTINUOUS:
        if v == "load" and tau_out is None:
            continue  # no load without the model's load prediction
        out[v] = reversal_distance(s) if v == "reversal" else variable_values(v, s, tau_out)
    for k, v in (others or {}).items():
        v = np.asarray(v, dtype=float)
        if v.shape != (len(s),):
            raise ValueError(f"other variable {k!r}: expected shape ({len(s)},), got {v.shape}")
        out[k] = v
    return out


def sign_values(s: Signals, tau_out: Prediction | None = None) -> dict[str, np.ndarray]:
    """sign(q̇) (``direction``) and the model quadrant sign(τ̂_out q̇) (``quadrant``, eq.
    17-20; only with a load prediction ``tau_out``)."""
    out = {"direction": variable_values("direction", s)}
    if tau_out is not None:
        out["quadrant"] = variable_values("quadrant", s, tau_out)
    return out


@dataclass(frozen=True)
class InteractionTest:
    """One binned test of the residual.

    Attributes
    ----------
    variables : tuple of str
        The variables binned on (one or two), then the sign the residual was multiplied by
        (``"direction"`` or ``"quadrant"``) for the signed kinds.
    kind : str
        ``"single"``, ``"signed"``, ``"pair"`` or ``"signed_pair"``.
    explained : float
        Share of the (signed) residual variance the bin means explain, in [0, 1].
    statistic : float
        F statistic (effective-sample corrected).
    p_value : float
        Raw p-value.
    p_adjusted : float
        Holm-adjusted p-value over every test of the diagnosis.
    n_bins : int
        Non-empty bins (cells for a pair).
    """

    variables: tuple[str, ...]
    kind: str
    explained: float
    statistic: float
    p_value: float
    p_adjusted: float
    n_bins: int

    @property
    def label(self) -> str:
        """Readable name, e.g. ``position x direction`` or ``load x velocity``."""
        return " x ".join(self.variables)

    def to_json(self) -> dict:
        return {
            "variables": list(self.variables),
            "kind": self.kind,
            "explained": float(self.explained),
            "statistic": float(self.statistic),
            "p_value": float(self.p_value),
            "p_adjusted": float(self.p_adjusted),
        }


@dataclass(frozen=True)
class InteractionDiagnosis:
    """Every test tried, most significant first, with the family-wise level ``alpha``."""

    tests: list[InteractionTest]
    n_eff: float
    alpha: float = 1e-3
    _by_key: dict = field(default_factory=dict, repr=False)

    @property
    def significant(self) -> list[InteractionTest]:
        """Tests whose Holm-adjusted p-value is below ``alpha``."""
        return [t for t in self.tests if t.p_adjusted < self.alpha]

    def get(self, *variables: str) -> InteractionTest:
        """The test on exactly these variables (order as in :attr:`InteractionTest.variables`)."""
        for t in self.tests:
            if t.variables == tuple(variables):
                return t
        raise KeyError(variables)

    def format_table(self, top: int = 12) -> str:
        lines = [f"{'interaction':<34}{'kind':<12}{'explained':>10}{'F':>10}{'p (Holm)':>11}"]
        for t in self.tests[:top]:
            lines.append(
                f"{t.label:<34}{t.kind:<12}{100 * t.explained:>9.2f}%{t.statistic:>10.3g}"
                f"{t.p_adjusted:>11.2e}"
            )
        lines.append(f"({len(self.tests)} tests, Holm correction, alpha {self.alpha:g})")
        return "\n".join(lines)

    def to_json(self) -> list[dict]:
        return [t.to_json() for t in self.tests]


def quantile_bins(x: np.ndarray, bins: int) -> np.ndarray:
    """Equal-count bin index of each sample, shape (n,), values in [0, bins)."""
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)[1:-1]))
    return np.searchsorted(edges, x, side="right")


def binned_f(
    r: np.ndarray, idx: np.ndarray, n_eff: float | None = None, df_between: int | None = None
) -> tuple[float, float, float, int]:
    """η², F and p of the bin means of ``r`` (bin index ``idx``) against noise.

    The F statistic is scaled by n_eff / n and its second degree of freedom is n_eff - k,
    as in :func:`ident.diagnose.dependence`; by default n_eff is that of the residual
    *within* the bins (``r`` minus its bin means, in sample order): the autocorrelation of
    the noise, not of the structure the bins explain (a strong smooth effect makes the raw
    residual look like a handful of independent samples). ``df_between`` overrides k - 1
    (interaction of a 2-D table after removing both main effects: (k1 - 1)(k2 - 1)).

    Returns
    -------
    explained, F, p, k
    """
    n = r.shape[0]
    k = int(idx.max()) + 1 if n else 0
    cnt = np.bincount(idx, minlength=k).astype(float)
    ok = cnt > 0
    kb = int(ok.sum())
    sums = np.bincount(idx, weights=r, minlength=k)
    means = np.where(ok, sums / np.maximum(cnt, 1.0), 0.0)
    mu = float(r.mean()) if n else 0.0
    ss_tot = float(((r - mu) ** 2).sum())
    ss_b = float((cnt * (means - mu) ** 2)[ok].sum())
    d1 = kb - 1 if df_between is None else int(df_between)
    if n_eff is None:
        n_eff = effective_n(r - means[idx])
    n_eff = min(float(n_eff), float(n))
    d2 = n_eff - kb
    if d1 < 1 or d2 < 1 or ss_tot <= 0:
        return 0.0, 0.0, 1.0, kb
    ss_w = max(ss_tot - ss_b, 1e-300)
    F = (ss_b / d1) / (ss_w / max(n - kb, 1)) * (n_eff / n)
    # scipy.stats.f.sf(F, d1, d2) is this function behind argument checks that cost more than
    # it (1 500 calls per refinement step of a robot joint); F >= 0, d1, d2 >= 1 here
    return ss_b / ss_tot, float(F), float(special.fdtrc(d1, d2, F)), kb


def _remove_main_effects(r: np.ndarray, i1: np.ndarray, i2: np.ndarray, iters: int = 2):
    """Residual minus additive bin means of two variables (backfitting)."""
    out = r - r.mean()
    for _ in range(iters):
        for idx in (i1, i2):
            k = int(idx.max()) + 1
            cnt = np.maximum(np.bincount(idx, minlength=k), 1)
            out = out - (np.bincount(idx, weights=out, minlength=k) / cnt)[idx]
    return out


def holm(p: np.ndarray) -> np.ndarray:
    """Holm step-down adjusted p-values (family-wise error), same order as ``p``."""
    p = np.asarray(p, dtype=float)
    m = p.size
    order = np.argsort(p)
    adj = np.minimum(1.0, (m - np.arange(m)) * p[order])
    adj = np.maximum.accumulate(adj)
    out = np.empty(m)
    out[order] = adj
    return out


def diagnose_interactions(
    residual: np.ndarray,
    s: Signals,
    *,
    tau_out: Prediction | None = None,
    others: Mapping[str, np.ndarray] | None = None,
    bins: int = 24,
    bins2: int = 8,
    alpha: float = 1e-3,
    pairs: bool = True,
) -> InteractionDiagnosis:
    """Test the residual against single variables, signed products and pairs.

    Parameters
    ----------
    residual : ndarray, shape (n,)
        ρ = Y - W χ̂ on the samples ``s`` [N m].
    s : Signals
        The samples (len n).
    tau_out : Prediction, optional
        Load-torque predictor for the ``load`` variable (default: the measured torque).
    others : mapping of str to ndarray, optional
        Extra continuous variables on the same samples (other joints' q, q̇ on a robot);
        they enter every kind of test like the joint's own variables.
    bins : int
        Equal-count bins of a single variable.
    bins2 : int
        Bins per axis of a pair (bins2² cells).
    alpha : float
        Family-wise level of :attr:`InteractionDiagnosis.significant` (Holm).
    pairs : bool
        Include the 2-D tests.

    Returns
    -------
    InteractionDiagnosis
    """
    r = np.asarray(residual, dtype=float)
    if r.shape != (len(s),):
        raise ValueError(f"diagnose_interactions: residual has shape {r.shape}, signals {len(s)}")
    n_eff = effective_n(r)  # of the raw residual, for the record
    cont = {k: v for k, v in continuous_values(s, tau_out, others).items() if np.ptp(v) > 0}
    signs = sign_values(s, tau_out)
    raw: list[tuple[tuple[str, ...], str, float, float, float, int]] = []
    idx1 = {k: quantile_bins(v, bins) for k, v in cont.items()}
    for k, idx in idx1.items():
        raw.append(((k,), "single", *binned_f(r, idx)))
    for k, d in signs.items():
        _, idx = np.unique(d, return_inverse=True)
        raw.append(((k,), "single", *binned_f(r, idx)))
    for sk, d in signs.items():
        rd = r * d
        for k, idx in idx1.items():
            raw.append(((k, sk), "signed", *binned_f(rd, idx)))
    if pairs:
        names = list(cont)
        idx2 = {k: quantile_bins(cont[k], bins2) for k in names}
        rd = r * signs["direction"]
        for a in range(len(names)):
            for b in range(a + 1, len(names)):
                i1, i2 = idx2[names[a]], idx2[names[b]]
                k1, k2 = int(i1.max()) + 1, int(i2.max()) + 1
                cell = i1 * k2 + i2
                # the rank of each cell among the occupied ones (np.unique's inverse, without
                # its sort: the cell numbers are small integers)
                occupied = np.bincount(cell, minlength=k1 * k2) > 0
                cell = (np.cumsum(occupied) - 1)[cell]
                df = (k1 - 1) * (k2 - 1)
                for kind, rr in (("pair", r), ("signed_pair", rd)):
                    resid = _remove_main_effects(rr, i1, i2)
                    e, F, p, kb = binned_f(resid, cell, df_between=df)
                    # share of the (signed) residual variance, not of the de-meaned remainder
                    tot = float(((rr - rr.mean()) ** 2).sum())
                    e = e * float(resid @ resid) / tot if tot > 0 else 0.0
                    vars_ = (names[a], names[b]) + (("direction",) if kind == "signed_pair" else ())
                    raw.append((vars_, kind, e, F, p, kb))
    padj = holm(np.array([x[4] for x in raw]))
    tests = [
        InteractionTest(v, kind, e, F, p, pa, kb)
        for (v, kind, e, F, p, kb), pa in zip(raw, padj, strict=True)
    ]
    tests.sort(key=lambda t: (t.p_adjusted, -t.statistic))
    return InteractionDiagnosis(tests, n_eff, alpha)
