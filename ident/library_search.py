"""Library search: which feature group, built from the variables and their products, lowers
the *held-out* error of the current model?

A PySINDy-style candidate library, organised in groups (one group = one physical structure,
kept or dropped as a whole):

* one variable x (position, velocity, load, time, reversal distance, or any "other"
  variable such as another joint's position) expanded in hat functions (degree-1 B-splines)
  on knots uniform over the 0.5-99.5 % range (uniform in log(1 + x/x0) for the reversal
  distance, whose structure sits near 0), at 6, 12 or 24 knots (the resolution is chosen by
  the held-out error like everything else). Hats have local support: a hat a training fold
  never visits gets a zero weight instead of extrapolating;
* times a modifier m: 1, sign(q̇) (``direction``), sign(P) (``quadrant``, eq. 26),
  τ̂_out (``load``) or τ̂_out sign(P) = |τ̂_out| sign(q̇) (``load_quadrant``, eq. 19);
* two variables: the tensor product B(x) ⊗ B(y) (5 knots each), times 1 or sign(q̇).

Columns that make the group collinear with the current regressor (the hats sum to 1, which
is τ_off's column; times sign(q̇) they sum to F_C's) are dropped from the group, one at a
time, until [W | group] has full rank.

Selection is grouped forward selection scored by blocked cross-validation: the samples are
cut into contiguous time blocks (several seconds each; 6 blocks per fold, interleaved over 5
folds so that every fold sees every part of the trajectory; or one fold per run) and each
group is refitted with the current regressor on 4/5 of the data and scored on the held-out
fifth, from per-fold Gram matrices (one pass over the samples per group). A group is selected
only when the held-out relative error falls by ``min_gain`` (relative); the search stops when
no group does. Every group tried is returned with its held-out error, so that a report can say
why each was rejected.

Why not pysindy or scikit-learn: the library needs grouped selection (a basis is kept or
dropped as a whole, as in group lasso), columns orthogonal to an existing regression, and a
CV that reuses per-fold Gram matrices so that 10⁶ samples stay within a few seconds; STLSQ /
SR3 in pysindy select single columns and refit on the full data, and scikit-learn's
``SequentialFeatureSelector`` refits every candidate per fold from the samples. The forward
selection below is ~60 lines of numpy.

Pure numerics; :class:`LibraryTerm` turns a selected group into a regressor term that
:meth:`ident.preprocess.Design.with_term` can add (columns computed at full rate).

(Past 600 lines: the groups' bases, their pruning against the current regressor, the
per-fold Gram matrices and the forward search are one pipeline over the same arrays, and
:class:`LibraryTerm` rebuilds a selected group's columns with the same bases; apart, the
basis rules would be written twice.)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from . import DataError
from .effects import Effect, Prediction, variable_values
from .interactions import CONTINUOUS, reversal_distance
from .signals import Signals

#: Variables the library expands. Acceleration is left out: the rigid body is exactly linear in
#: q̈ and a residual nonlinear in q̈ alone is the closed-loop correlation of the measured q̈ with
#: the controller's torque (seen on clean simulated data), not a missing effect; q̈ still enters
#: through the load τ̂_out.
LIBRARY_VARIABLES = ("position", "velocity", "load", "time", "reversal")
#: Modifiers a one-variable basis is multiplied by.
MODIFIERS = ("none", "direction", "quadrant", "load", "load_quadrant")
#: Modifiers of a two-variable tensor basis.
PAIR_MODIFIERS = ("none", "direction")
#: Knots per one-variable basis (the held-out error chooses).
KNOTS = (6, 12, 24)
#: Time is expanded at the coarsest resolution only: a physical drift (warm-up, temperature)
#: is slow, and a fine time basis stands in for anything locked to the trajectory when every
#: run replays the same excitation (a position effect seen through q(t)).
TIME_KNOTS = "coarsest of KNOTS"
#: Knots per axis of a tensor basis.
KNOTS_2D = 5
#: A group's columns projected off the current regressor must keep a condition number below
#: 1 / PRUNE_TOL; the design's columns are filtered at full rate and the search's are computed
#: on decimated signals, so a dependency (hats summing to the Coulomb column) is only near-exact.
PRUNE_TOL = 1e-3
#: Short names for parameter names.
_ABBR = {"position": "q", "velocity": "dq", "acceleration": "ddq", "load": "ld", "time": "t",
         "reversal": "rv", "none": "", "direction": "s", "quadrant": "P", "load_quadrant": "LP"}


# ----------------------------------------------------------------------------- bases
@dataclass(frozen=True)
class Basis:
    """Hat functions (degree-1 B-splines) of one variable on ``knots`` knots uniform in u over
    [lo, hi], u = x or log(1 + (x - lo) / x0) (``log=True``, x0 = (hi - lo)/100); x is clipped
    to [lo, hi]. The hats sum to 1 and span the piecewise-linear functions on the knots.
    """

    lo: float
    hi: float
    knots: int
    log: bool = False

    def _u(self, x: np.ndarray) -> np.ndarray:
        x = np.clip(x, self.lo, self.hi)
        if self.log:
            x0 = (self.hi - self.lo) / 100
            return np.log1p((x - self.lo) / x0)
        return x

    def grid(self) -> np.ndarray:
        """Knots in u, shape (knots,)."""
        ends = self._u(np.array([self.lo, self.hi]))
        return np.linspace(ends[0], ends[1], self.knots)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Columns, shape (n, knots)."""
        u = self._u(np.asarray(x, dtype=float))
        g = self.grid()
        h = g[1] - g[0]
        return np.maximum(1.0 - np.abs(u[:, None] - g[None, :]) / h, 0.0)

    @property
    def size(self) -> int:
        return self.knots


def make_basis(name: str, x: np.ndarray, knots: int) -> Basis | None:
    """A basis over the 0.5-99.5 % range of ``x`` (log-spaced for the reversal distance)."""
    lo, hi = (float(v) for v in np.quantile(x, [0.005, 0.995]))
    if name == "reversal":
        lo = 0.0
    if not hi > lo:
        return None
    return Basis(lo, hi, knots, log=name == "reversal")


# ----------------------------------------------------------------------------- groups
@dataclass(frozen=True)
class Group:
    """One candidate structure: a basis in one or two variables times a modifier.

    Attributes
    ----------
    variables : tuple of str
        One or two variable names.
    modifier : str
        One of :data:`MODIFIERS`.
    bases : tuple of Basis
        One basis per variable.
    keep : tuple of int or None
        Indices of the raw columns kept (None: all), see :func:`prune`.
    """

    variables: tuple[str, ...]
    modifier: str
    bases: tuple[Basis, ...]
    keep: tuple[int, ...] | None = None

    @property
    def key(self) -> str:
        v = " x ".join(self.variables)
        return v if self.modifier == "none" else f"{v} x {self.modifier}"

    @property
    def knots(self) -> tuple[int, ...]:
        return tuple(b.knots for b in self.bases)

    def raw(self, values: Mapping[str, np.ndarray], cache: dict | None = None) -> np.ndarray:
        """All columns of the basis times the modifier, shape (n, prod(knots)).

        ``cache``: a dict that keeps the hat columns of each (variable, basis) between calls
        on the same ``values`` (the groups of a library share their bases across modifiers).
        """
        B = _hats(self.bases[0], self.variables[0], values, cache)
        if len(self.bases) == 2:
            B2 = _hats(self.bases[1], self.variables[1], values, cache)
            B = (B[:, :, None] * B2[:, None, :]).reshape(B.shape[0], -1)
        m = modifier_values(self.modifier, values)
        return B if m is None else B * m[:, None]

    def columns(self, values: Mapping[str, np.ndarray], cache: dict | None = None
                ) -> np.ndarray:
        """The kept columns (:meth:`raw`, ``cache`` as there)."""
        C = self.raw(values, cache)
        return C if self.keep is None else C[:, list(self.keep)]

    @property
    def size(self) -> int:
        return len(self.keep) if self.keep is not None else int(np.prod(self.knots))


def _hats(basis: Basis, variable: str, values: Mapping[str, np.ndarray],
          cache: dict | None) -> np.ndarray:
    """``basis(values[variable])``, kept in ``cache`` (None: not kept) by (variable, basis)."""
    if cache is None:
        return basis(values[variable])
    key = (variable, basis)
    B = cache.get(key)
    if B is None:
        B = cache[key] = basis(values[variable])
    return B


def modifier_values(modifier: str, values: Mapping[str, np.ndarray]) -> np.ndarray | None:
    """The modifier column (None for ``"none"``) from a values mapping."""
    if modifier == "none":
        return None
    if modifier == "load_quadrant":
        return values["load"] * values["quadrant"]
    return values[modifier]


def signal_values(
    s: Signals, names: Sequence[str], tau_out: Prediction | None
) -> dict[str, np.ndarray]:
    """The named variables (continuous, signs, load) computed from signals."""
    out: dict[str, np.ndarray] = {}
    for v in set(names):
        if v == "reversal":
            out[v] = reversal_distance(s)
        elif v == "load_quadrant" or (v in ("load", "quadrant") and tau_out is None):
            continue
        else:
            out[v] = variable_values(v, s, tau_out)
    return out


def prune(group: Group, values: Mapping[str, np.ndarray], Q: np.ndarray | None,
          cache: dict | None = None) -> Group | None:
    """Drop raw columns of ``group`` until [Q | group] has full rank.

    Empty columns go first; then, while the columns projected off span(Q) have a (nearly)
    null direction, the column that weighs most in it is dropped (the hats sum to 1, the
    offset's column; times sign(q̇) to the Coulomb column).

    Parameters
    ----------
    Q : ndarray, shape (n, p) or None
        Orthonormal basis of the current regressor on the same samples.
    cache : dict, optional
        Hat columns shared between calls on the same ``values`` (:meth:`Group.raw`).

    The rank test is the SVD's; the Gram matrix of the columns only skips the SVD when its
    smallest eigenvalue shows a full rank with a wide margin (:data:`GRAM_MARGIN`), so that
    the columns dropped are the same.
    """
    C = group.raw(values, cache)
    norms = np.linalg.norm(C, axis=0)
    keep = [j for j in range(C.shape[1]) if norms[j] > 1e-9 * max(float(norms.max()), 1e-300)]
    if not keep:
        return None
    Cn = C[:, keep] / norms[keep]
    if Q is not None and Q.size:
        Cn = Cn - Q @ (Q.T @ Cn)
    G = Cn.T @ Cn
    while keep:
        if _surely_full_rank(G):
            break
        _, sv, Vt = np.linalg.svd(Cn, full_matrices=False)
        if sv[-1] > PRUNE_TOL * max(float(sv[0]), 1e-300):
            break
        j = int(np.argmax(np.abs(Vt[-1])))
        del keep[j]
        Cn = np.delete(Cn, j, axis=1)
        G = np.delete(np.delete(G, j, axis=0), j, axis=1)
    if not keep:
        return None
    return Group(group.variables, group.modifier, group.bases, tuple(keep))


#: :func:`prune` skips the SVD when the Gram matrix's smallest eigenvalue exceeds
#: GRAM_MARGIN x PRUNE_TOL² x its largest: the smallest singular value is then 10x above the
#: rank threshold (the eigenvalues' rounding, ~1e-16 of the largest, is far below either).
GRAM_MARGIN = 100.0


def _surely_full_rank(G: np.ndarray) -> bool:
    """True when the columns of Gram matrix ``G`` certainly pass the rank test of
    :func:`prune` (False: let the SVD decide)."""
    if G.shape[0] == 0:
        return False
    w = np.linalg.eigvalsh(G)
    return bool(w[0] > GRAM_MARGIN * PRUNE_TOL**2 * max(float(w[-1]), 1e-300))


def build_library(
    values: Mapping[str, np.ndarray],
    continuous: Sequence[str],
    *,
    pairs: Sequence[tuple[str, str]] | None = None,
    modifiers: Sequence[str] = MODIFIERS,
    knots: Sequence[int] = KNOTS,
    Q: np.ndarray | None = None,
) -> list[Group]:
    """The candidate groups.

    Parameters
    ----------
    values : mapping
        Variable arrays on the samples: every name of ``continuous`` plus ``direction``,
        ``quadrant`` and ``load`` (for the modifiers).
    continuous : sequence of str
        Variables to expand.
    pairs : sequence of (str, str), optional
        Pairs for tensor bases (default: every pair of ``continuous``).
    modifiers : sequence of str
        Modifiers of the one-variable groups.
    knots : sequence of int
        Resolutions of the one-variable groups.
    Q : ndarray, optional
        Orthonormal basis of the current regressor (columns in its span are dropped).
    """
    out: list[Group] = []
    # without the model's load prediction there is no load nor quadrant (never the torque)
    have = set(values) | {"none"} | ({"load_quadrant"} if {"load", "quadrant"} <= set(values)
                                     else set())
    continuous = [v for v in continuous if v in values]
    modifiers = [m for m in modifiers if m in have]
    cache: dict = {}
    bases: dict[tuple[str, int], Basis | None] = {}

    def basis(v: str, k: int) -> Basis | None:
        if (v, k) not in bases:
            bases[v, k] = make_basis(v, values[v], k)
        return bases[v, k]

    for v in continuous:
        for m in modifiers:
            # sign(q̇) is a function of q̇; |τ_out| sign(q̇) of τ_out and q̇: same span
            if (v, m) in (("velocity", "direction"), ("load", "load"), ("load", "direction"),
                          ("load", "load_quadrant")):
                continue
            for k in knots:
                if v == "time" and k > min(knots):
                    continue  # see TIME_KNOTS
                b = basis(v, k)
                if b is None:
                    continue
                g = prune(Group((v,), m, (b,)), values, Q, cache)
                if g is not None:
                    out.append(g)
    if pairs is None:
        pairs = [(a, b) for i, a in enumerate(continuous) for b in continuous[i + 1:]]
    for a, b in pairs:
        ba, bb = basis(a, KNOTS_2D), basis(b, KNOTS_2D)
        if ba is None or bb is None:
            continue
        for m in PAIR_MODIFIERS:
            g = prune(Group((a, b), m, (ba, bb)), values, Q, cache)
            if g is not None:
                out.append(g)
    return out


# ----------------------------------------------------------------------------- CV
def time_folds(experiment: np.ndarray, n_folds: int = 5, chunks_per_fold: int = 6,
               by_run: bool = False) -> np.ndarray:
    """Fold index of every sample, shape (n,).

    ``by_run``: one fold per experiment (needs at least two). Otherwise the samples (in their
    order: runs one after the other, each in time order) are cut into
    ``n_folds * chunks_per_fold`` contiguous blocks, block b going to fold b mod n_folds.
    """
    exp = np.asarray(experiment)
    n = exp.shape[0]
    if by_run:
        _, f = np.unique(exp, return_inverse=True)
        if f.max() >= 1:
            return f
    nb = n_folds * chunks_per_fold
    block = (np.arange(n) * nb) // max(n, 1)
    return block % n_folds


class FoldGram:
    """Per-fold Gram matrices of a base design [W | y] and cheap CV of W + extra columns."""

    def __init__(self, W: np.ndarray, y: np.ndarray, folds: np.ndarray, ridge: float = 1e-5):
        self.folds = folds
        self.k = int(folds.max()) + 1
        self.idx = [np.flatnonzero(folds == f) for f in range(self.k)]
        X = np.column_stack((W, y))
        self.X = X
        self._Xf = [X[i] for i in self.idx]  # each fold's rows, taken once
        # X[i].T @ X[i] on two copies (a general product, as before the rows were kept: the
        # same array twice would take the symmetric product, rounded differently)
        self.G = np.stack([X[i].T @ X[i] for i in self.idx])  # (k, p+1, p+1)
        self.p = W.shape[1]
        self.ridge = ridge
        self.yy = float(y @ y)

    def cv(self, C: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """Held-out relative error of [W | C] and the per-fold test SSE."""
        p = self.p
        if C is None or C.shape[1] == 0:
            G = self.G
        else:
            k = C.shape[1]
            G = np.empty((self.k, p + k + 1, p + k + 1))
            G[:, :p, :p] = self.G[:, :p, :p]
            G[:, -1, -1] = self.G[:, p, p]
            G[:, :p, -1] = G[:, -1, :p] = self.G[:, :p, p]
            for f, i in enumerate(self.idx):
                Ci = C[i]
                cx = Ci.T @ self._Xf[f]  # (k, p+1)
                G[f, p:p + k, :p] = cx[:, :p]
                G[f, :p, p:p + k] = cx[:, :p].T
                G[f, p:p + k, -1] = G[f, -1, p:p + k] = cx[:, p]
                G[f, p:p + k, p:p + k] = Ci.T @ Ci
        tot = G.sum(axis=0)
        m = tot.shape[0] - 1
        d = np.sqrt(np.maximum(np.diag(tot)[:m], 1e-300))
        sse = np.empty(self.k)
        # every fold's training system at once (one batched solve; the same LAPACK solve
        # per fold as one call each)
        A = (tot[None, :m, :m] - G[:, :m, :m]) / np.outer(d, d)
        b = (tot[None, :m, m] - G[:, :m, m]) / d
        A[:, np.arange(m), np.arange(m)] += self.ridge
        try:
            betas = np.linalg.solve(A, b[:, :, None])[:, :, 0] / d
        except np.linalg.LinAlgError:  # pragma: no cover - one fold at a time, least squares
            betas = np.stack([self._solve(A[f], b[f]) for f in range(self.k)]) / d
        for f in range(self.k):
            beta = betas[f]
            Gf = G[f]
            sse[f] = Gf[m, m] - 2 * beta @ Gf[:m, m] + beta @ Gf[:m, :m] @ beta
        sse = np.maximum(sse, 0.0)
        return math.sqrt(float(sse.sum()) / max(self.yy, 1e-300)), sse

    @staticmethod
    def _solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:  # pragma: no cover - singular
        try:
            return np.linalg.solve(A, b)
        except np.linalg.LinAlgError:
            return np.linalg.lstsq(A, b, rcond=None)[0]


# ----------------------------------------------------------------------------- search
@dataclass
class Tried:
    """One group scored in a round of the search."""

    group: Group
    round: int
    cv_before: float
    cv_after: float
    fit_after: float
    selected: bool = False
    reason: str = ""

    def to_json(self) -> dict:
        return {
            "structure": self.group.key,
            "variables": list(self.group.variables),
            "modifier": self.group.modifier,
            "knots": list(self.group.knots),
            "columns": self.group.size,
            "round": self.round,
            "heldout_rel_error_before": self.cv_before,
            "heldout_rel_error_after": self.cv_after,
            "rel_error_after": self.fit_after,
            "selected": self.selected,
            "reason": self.reason,
        }


@dataclass
class SearchResult:
    """Outcome of :func:`search`.

    Attributes
    ----------
    selected : list of Group
        Selected groups, in order.
    coef : list of ndarray
        Least-squares coefficients of each selected group (full data, with W).
    tried : list of Tried
        Every group scored, per round (the best resolution of each structure per round).
    cv_path, fit_path : list of float
        Held-out and in-sample relative errors (on the scoring samples): W alone, then after
        each selection.
    folds : ndarray
        Fold of every sample.
    """

    selected: list[Group]
    coef: list[np.ndarray]
    tried: list[Tried]
    cv_path: list[float]
    fit_path: list[float]
    folds: np.ndarray = field(repr=False)

    def rejected(self) -> list[Tried]:
        return [t for t in self.tried if not t.selected]


def _fit_rel(X: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray]:
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ beta
    return float(np.linalg.norm(r) / max(np.linalg.norm(y), 1e-300)), beta


def search(
    y: np.ndarray,
    W: np.ndarray,
    values: Mapping[str, np.ndarray],
    groups: Sequence[Group],
    folds: np.ndarray,
    *,
    max_groups: int = 3,
    min_gain: float = 0.02,
    max_samples: int = 8000,
) -> SearchResult:
    """Grouped forward selection by held-out error.

    Parameters
    ----------
    y : ndarray, shape (n,)
        Measured torque Y [N m].
    W : ndarray, shape (n, p)
        Current regressor (the declared model and the terms already added).
    values : mapping
        Variable arrays on the samples (see :func:`build_library`).
    groups : sequence of Group
        Candidates.
    folds : ndarray of int, shape (n,)
        Fold of each sample (:func:`time_folds`).
    max_groups : int
        Maximum number of groups selected.
    min_gain : float
        A group is selected only if it lowers the held-out relative error by this share.
    max_samples : int
        Scoring uses at most this many samples (regular stride; decimated residuals are
        autocorrelated, a stride loses little); the final coefficients use all.

    Returns
    -------
    SearchResult
    """
    y = np.asarray(y, dtype=float)
    n = y.shape[0]
    stride = max(1, math.ceil(n / max_samples))
    sl = slice(None, None, stride)
    vals = {k: np.asarray(v)[sl] for k, v in values.items()}
    cache: dict = {}
    cols = {id(g): g.columns(vals, cache) for g in groups}
    base_W = W[sl]
    fg = FoldGram(base_W, y[sl], folds[sl])
    cv0, _ = fg.cv()
    fit0, _ = _fit_rel(W[sl], y[sl])
    cv_path, fit_path = [cv0], [fit0]
    ys = y[sl]
    selected: list[Group] = []
    tried: list[Tried] = []
    remaining = list(groups)
    for rnd in range(1, max_groups + 1):
        scores = []
        for g in remaining:
            cv, _ = fg.cv(cols[id(g)])
            scores.append((cv, g))
        if not scores:
            break
        # best resolution per structure
        best: dict[str, tuple[float, Group]] = {}
        for cv, g in scores:
            if g.key not in best or cv < best[g.key][0]:
                best[g.key] = (cv, g)
        ranked = sorted(best.values(), key=lambda t: t[0])
        cv_b, g_b = ranked[0]
        ok = cv_b < cv_path[-1] * (1 - min_gain)
        S = [base_W] + [cols[id(g)] for g in selected]
        for cv, g in ranked:
            fit, _ = _fit_rel(np.column_stack(S + [cols[id(g)]]), ys) if g is g_b else (
                math.nan, None)
            t = Tried(g, rnd, cv_path[-1], cv, fit)
            if g is g_b and ok:
                t.selected = True
                t.reason = "selected"
            elif cv >= cv_path[-1]:
                t.reason = (f"held-out error not lowered ({100 * cv_path[-1]:.3f} % -> "
                            f"{100 * cv:.3f} %)")
            elif g is g_b:
                t.reason = (f"held-out error lowered by less than {100 * min_gain:g} % "
                            f"({100 * cv_path[-1]:.3f} % -> {100 * cv:.3f} %)")
            else:
                t.reason = (f"held-out error {100 * cv:.3f} % above the best candidate's "
                            f"{100 * cv_b:.3f} % ({g_b.key})")
            tried.append(t)
        if not ok:
            break
        selected.append(g_b)
        fit, _ = _fit_rel(np.column_stack(S + [cols[id(g_b)]]), ys)
        cv_path.append(cv_b)
        fit_path.append(fit)
        C_new = cols[id(g_b)]
        fg = FoldGram(np.column_stack((fg.X[:, :-1], C_new)), y[sl], folds[sl])
        remaining = [g for g in remaining if g.key != g_b.key]
    coef: list[np.ndarray] = []
    if selected:
        X = np.column_stack([W] + [g.columns(values) for g in selected])
        _, beta = _fit_rel(X, y)
        off = W.shape[1]
        for g in selected:
            coef.append(beta[off:off + g.size])
            off += g.size
    return SearchResult(selected, coef, tried, cv_path, fit_path, folds)


# ----------------------------------------------------------------------------- term
class LibraryTerm(Effect):
    """A selected library group as a regressor term (columns linear in its weights).

    Parameters
    ----------
    group : Group
        The structure (variables, modifier, bases, kept columns).
    tau_out : Prediction, optional
        Load predictor τ̂_out for the ``load`` variable and the load modifiers.

    A variable is one of :data:`CONTINUOUS` (computed from the signals) or an "other"
    variable (another joint's state) read from :attr:`Signals.extra
    <ident.signals.Signals.extra>` by name: signals without it cannot give the columns
    (:class:`~ident.DataError` naming the variable, e.g. validation data lacking the other
    joints).
    """

    def __init__(self, group: Group, tau_out: Prediction | None = None, tag: str = "") -> None:
        super().__init__(tag)
        self.group = group
        self.tau_out = tau_out
        self.variable = group.variables[0]
        self.variables = group.variables
        self.effect = "library_" + "_x_".join(group.variables) + (
            "" if group.modifier == "none" else f"_x_{group.modifier}")

    def names(self) -> tuple[str, ...]:
        g = self.group
        base = "lb_" + "_".join(_ABBR.get(v, v) for v in g.variables)
        if g.modifier != "none":
            base += "_" + _ABBR[g.modifier]
        return tuple(self._n(f"{base}_{j}") for j in range(g.size))

    def _values(self, s: Signals) -> dict[str, np.ndarray]:
        g = self.group
        missing = [v for v in g.variables if v not in CONTINUOUS
                   and (s.extra is None or v not in s.extra)]
        if missing:
            raise DataError(f"library term {self.effect}: the signals have no variable "
                            f"{', '.join(missing)} (Signals.extra: "
                            f"{sorted(s.extra or {}) or 'none'})")
        need = list(g.variables)
        if g.modifier in ("direction", "quadrant", "load"):
            need.append(g.modifier)
        elif g.modifier == "load_quadrant":
            need += ["load", "quadrant"]
        return signal_values(s, need, self.tau_out)

    def columns(self, s: Signals) -> np.ndarray:
        return self.group.columns(self._values(s))

    def describe(self) -> str:
        g = self.group
        k = "x".join(str(b.knots) for b in g.bases)
        mod = "" if g.modifier == "none" else f" x {g.modifier}"
        return (f"library basis in {' x '.join(g.variables)}{mod}: {g.size} hat functions "
                f"({k} knots)")
