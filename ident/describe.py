"""Name or describe what a library search selected.

(Past 600 lines: the named forms, their cross-joint terms and the words fallback share the
fitting helpers and the matching rule; split, each would import the others.)

A selected group (:mod:`ident.library_search`) is a piecewise-linear function of one or two
variables times a modifier. This module

* tries the named physical forms that have the same variables and modifier, fitted with
  the current regressor on the same samples, their nonlinear parameter scanned:

  ==================================  ====================  ==================================
  form                                group                 columns
  ==================================  ====================  ==================================
  ``position_periodic_dry_friction``  position x direction  [sin, cos](2π q/P) sign(q̇)
  (eccentric or worn transmission)
  ``periodic_<variable>[_<mod>]``     x [x modifier]        [sin, cos](2π x/P) [m]
  ``linear_q<m>[_<mod>]``             another joint's q/dq  (x - x̄) [m]
  ``polynomial_q<m>[_<mod>]``         (``q<m>``, ``dq<m>``) (x - x̄)^k, k = 1..2 (or 3) [m]
  ``reversal_hysteresis``             reversal x direction  exp(-s/L) sign(q̇), s the distance
  (Dahl-like pre-sliding)                                   since the last reversal
  ``load_dependent_viscous``          velocity x load_quad. |τ̂_out| q̇
                                      or velocity x load
  ``quadrant_load_velocity``          velocity x load_quad. [1, exp(-|q̇|/q_s)] sign(P) τ̂_out
  (the paper's eq. 24)
  ==================================  ====================  ==================================

  and names the group by the form when the form removes at least :data:`MATCH_SHARE` of what
  the group removes (parameters with 2σ from the linearised least squares);
* otherwise describes the fitted function in words a mechanical engineer reads ("dry
  friction varies with position, period ≈ 1.57 rad, ±38 % of F_C");
* names a torque lag of half a control cycle "zero-order hold" (:func:`name_torque_lag`).

:func:`ident.refine_plots.plot_structure` draws the profile.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import optimize

from trajectories.friction import stribeck_exp

from . import DataError
from .effects import Effect, Prediction, amplitude_phase, variable_values
from .interaction_effects import (
    LoadVelocityDryFriction,
    LoadViscous,
    PositionDryFriction,
    ReversalHysteresis,
)
from .library_search import FoldGram, Group
from .signals import Signals

#: A named form must remove this share of what the library group removes.
MATCH_SHARE = 0.9

_UNITS = {"position": "rad", "velocity": "rad/s", "load": "N m", "time": "s",
          "reversal": "rad", "acceleration": "rad/s^2"}
#: Other joints' positions and velocities (``q<m>``, ``dq<m>``: ident.robot.refine_joint).
_OTHER_UNITS = ((re.compile(r"q\d+"), "rad"), (re.compile(r"dq\d+"), "rad/s"))


def _unit(var: str) -> str:
    """Unit of a variable, other joints' states included ("" when unknown)."""
    if var in _UNITS:
        return _UNITS[var]
    return next((u for pat, u in _OTHER_UNITS if pat.fullmatch(var)), "")


def _is_other(var: str) -> bool:
    """``q<m>`` or ``dq<m>``: another joint's state (:mod:`ident.robot.refine_joint`)."""
    return var not in _UNITS and any(p.fullmatch(var) for p, _ in _OTHER_UNITS)


#: Modifiers a cross-joint term can carry (read from the states: no load prediction).
_TERM_MODIFIERS = ("none", "direction")


class _CrossJoint(Effect):
    """A named form in another joint's state ``var`` (``Signals.extra[var]``) times the
    modifier (``"none"`` or ``"direction"``: sign(q̇) of the joint)."""

    def __init__(self, var: str, modifier: str, tag: str = "") -> None:
        super().__init__(tag)
        if modifier not in _TERM_MODIFIERS:
            raise ValueError(f"{type(self).__name__}: modifier {modifier!r} not in "
                             f"{_TERM_MODIFIERS}")
        self.var, self.modifier = var, modifier
        self.variable = var

    def _x_m(self, s: Signals) -> tuple[np.ndarray, np.ndarray]:
        if s.extra is None or self.var not in s.extra:
            raise DataError(f"{self.effect}: the signals have no extra[{self.var!r}] (the "
                            f"other joint's {'position' if self.var[0] == 'q' else 'velocity'})")
        x = np.asarray(s.extra[self.var], dtype=float)
        m = (np.ones_like(x) if self.modifier == "none"
             else variable_values(self.modifier, s))
        return x, m

    def _suffix(self) -> str:
        return "" if self.modifier == "none" else f"_{self.modifier}"


class CrossJointPeriodic(_CrossJoint):
    """``periodic_<var>[_direction]``: A sin(2π x/P + φ) [sign(q̇)], x another joint's state
    (a cable or a bearing load following that joint; ``sim_drivers.arm_effects`` "dry
    coupling")."""

    hyper_names = ("period",)

    def __init__(self, var: str, modifier: str, period: float, tag: str = "") -> None:
        super().__init__(var, modifier, tag)
        if not period > 0:
            raise ValueError(f"CrossJointPeriodic: period must be > 0, got {period}")
        self.period = float(period)
        self.effect = f"periodic_{var}{self._suffix()}"

    def with_hyper(self, **values: float) -> CrossJointPeriodic:
        return CrossJointPeriodic(self.var, self.modifier, values.get("period", self.period),
                                  self.tag)

    def names(self) -> tuple[str, ...]:
        return (self._n(f"{self.var}_sin"), self._n(f"{self.var}_cos"))

    def columns(self, s: Signals) -> np.ndarray:
        x, m = self._x_m(s)
        th = (2 * np.pi / self.period) * x
        return np.column_stack((np.sin(th) * m, np.cos(th) * m))

    def parameters(self, coef, cov):
        amp, amp2, phase, phase2 = amplitude_phase(coef, cov)
        sdp = math.sqrt(max(float(cov[2, 2]), 0.0)) if len(coef) > 2 else 0.0
        return {self._n(f"{self.var}_amplitude"): (amp, amp2),
                self._n(f"{self.var}_phase"): (phase, phase2),
                self._n(f"{self.var}_period"): (self.period, 2 * sdp)}

    def describe(self) -> str:
        m = "" if self.modifier == "none" else " sign(dq)"
        return f"A sin(2π {self.var}/{self.period:.6g} + φ){m} ({self.var}: another joint)"


class CrossJointPolynomial(_CrossJoint):
    """``linear_<var>[_direction]`` (degree 1) or ``polynomial_<var>[_direction]`` (2, 3):
    sum_k c_k ((x - x̄)^k - mean) [sign(q̇)], x another joint's state, x̄ and the means fixed
    on the identification samples."""

    def __init__(self, var: str, modifier: str, degree: int, centre: float,
                 offsets: tuple[float, ...], tag: str = "") -> None:
        super().__init__(var, modifier, tag)
        if degree not in (1, 2, 3) or len(offsets) != degree:
            raise ValueError(f"CrossJointPolynomial: degree {degree} with {len(offsets)} "
                             "offsets")
        self.degree, self.centre, self.offsets = int(degree), float(centre), tuple(offsets)
        kind = "linear" if degree == 1 else "polynomial"
        self.effect = f"{kind}_{var}{self._suffix()}"

    def names(self) -> tuple[str, ...]:
        return tuple(self._n(f"{self.var}_c{k}") for k in range(1, self.degree + 1))

    def columns(self, s: Signals) -> np.ndarray:
        x, m = self._x_m(s)
        xc = x - self.centre
        return np.column_stack([(xc**k - o) * m
                                for k, o in zip(range(1, self.degree + 1), self.offsets,
                                                strict=True)])

    def describe(self) -> str:
        m = "" if self.modifier == "none" else " sign(dq)"
        return (f"polynomial of degree {self.degree} in {self.var} - {self.centre:.4g}{m} "
                f"({self.var}: another joint)")


def _poly_columns(x: np.ndarray, m: np.ndarray, degree: int) -> tuple[np.ndarray, float,
                                                                        tuple[float, ...]]:
    centre = float(np.mean(x))
    xc = x - centre
    offsets = tuple(float(np.mean(xc**k)) for k in range(1, degree + 1))
    C = np.column_stack([(xc**k - o) * m
                         for k, o in zip(range(1, degree + 1), offsets, strict=True)])
    return C, centre, offsets


_WHAT = {
    "none": "the torque",
    "direction": "dry friction",
    "quadrant": "the motor/generator dry-friction difference",
    "load": "the load gain (efficiency)",
    "load_quadrant": "the load-dependent friction coefficient",
}


@dataclass
class Description:
    """What a selected group is.

    Attributes
    ----------
    name : str or None
        Named form (``"position_periodic_dry_friction"``, ...) or None.
    sentence : str
        One line in words.
    parameters : dict
        ``{name: {"value": v, "std2": 2σ}}`` of the named form (empty without one).
    share : float
        RSS removed by the named form / RSS removed by the group (nan without one).
    grid : tuple of ndarray
        Profile abscissa(s) (one array, or two for a pair).
    profile : ndarray
        Fitted function of the variable(s) (without the modifier) on the grid [N m or N m per
        unit of the modifier].
    """

    name: str | None
    sentence: str
    parameters: dict[str, dict[str, float]] = field(default_factory=dict)
    share: float = math.nan
    grid: tuple[np.ndarray, ...] = field(default=(), repr=False)
    profile: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    group_key: str = ""
    #: The named form as a regressor term (None without one, or when the form has no term).
    term: Effect | None = field(default=None, repr=False)

    def to_json(self) -> dict:
        return {
            "structure": self.group_key,
            "named_effect": self.name,
            "description": self.sentence,
            "parameters": self.parameters,
            "named_share": None if not math.isfinite(self.share) else float(self.share),
        }


# ----------------------------------------------------------------------------- fitting
def _rss_with(y: np.ndarray, Q: np.ndarray, C: np.ndarray) -> float:
    """RSS of y on [span(Q), C] (Q orthonormal)."""
    r = y - Q @ (Q.T @ y)
    C = C - Q @ (Q.T @ C)
    beta, *_ = np.linalg.lstsq(C, r, rcond=None)
    e = r - C @ beta
    return float(e @ e)


def _fit_form(
    y: np.ndarray,
    W: np.ndarray,
    Q: np.ndarray,
    make: Callable[[float], np.ndarray],
    lo: float | None,
    hi: float | None,
) -> tuple[float, float | None, np.ndarray, np.ndarray]:
    """Fit W + make(h) by least squares, h scanned on a log grid then refined.

    Returns
    -------
    rss, h, coef (of the form's columns, then h), cov (same order)
    """
    h = None
    if lo is not None and hi is not None:
        grid = np.geomspace(lo, hi, 40)
        rss = np.array([_rss_with(y, Q, make(g)) for g in grid])
        i = int(np.argmin(rss))
        a, b = math.log(grid[max(i - 1, 0)]), math.log(grid[min(i + 1, grid.size - 1)])
        res = optimize.minimize_scalar(lambda lh: _rss_with(y, Q, make(math.exp(lh))),
                                       bounds=(a, b), method="bounded",
                                       options={"xatol": 1e-6})
        h = math.exp(res.x) if res.fun < rss[i] else float(grid[i])
    C = make(h if h is not None else 1.0)
    X = np.column_stack((W, C))
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ beta
    rss = float(r @ r)
    k = C.shape[1]
    cols = [X]
    if h is not None:
        dh = 1e-6 * h
        J = (make(h + dh) - make(h - dh)) @ beta[-k:] / (2 * dh)
        cols.append(J[:, None])
    A = np.column_stack(cols)
    norms = np.linalg.norm(A, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    sigma2 = rss / max(len(y) - A.shape[1], 1)
    cov = sigma2 * np.linalg.pinv((A / norms).T @ (A / norms)) / np.outer(norms, norms)
    idx = list(range(W.shape[1], A.shape[1]))
    coef = np.r_[beta[-k:], [h] if h is not None else []]
    return rss, h, coef, cov[np.ix_(idx, idx)]


def _sd(cov: np.ndarray) -> np.ndarray:
    return np.sqrt(np.clip(np.diag(cov), 0.0, None))


def _p(v: float, s2: float) -> dict[str, float]:
    return {"value": float(v), "std2": float(s2)}


# ----------------------------------------------------------------------------- profile
def profile(group: Group, coef: np.ndarray, n: int = 200) -> tuple[tuple[np.ndarray, ...],
                                                                     np.ndarray]:
    """The fitted function of the group's variable(s) on a grid (modifier = 1)."""
    grids = tuple(np.linspace(b.lo, b.hi, n if len(group.bases) == 1 else 40)
                  for b in group.bases)
    if len(grids) == 1:
        vals = {group.variables[0]: grids[0]}
    else:
        X1, X2 = np.meshgrid(grids[0], grids[1], indexing="ij")
        vals = {group.variables[0]: X1.ravel(), group.variables[1]: X2.ravel()}
    one = np.ones(vals[group.variables[0]].shape[0])
    for m in ("direction", "quadrant", "load"):
        vals[m] = one
    f = group.columns(vals) @ coef
    return grids, f if len(grids) == 1 else f.reshape(len(grids[0]), len(grids[1]))


def _sinusoid_share(f: np.ndarray, x: np.ndarray) -> tuple[float, float, float]:
    """Best single sinusoid of a uniformly sampled profile: (share, period, amplitude)."""
    f = f - f.mean()
    den = float(f @ f)
    if den <= 0 or x.size < 8:
        return 0.0, math.nan, 0.0
    span = float(x[-1] - x[0])
    best = (0.0, math.nan, 0.0)
    for P in np.geomspace(span / 40, 2 * span, 400):
        th = 2 * np.pi * x / P
        A = np.column_stack((np.sin(th), np.cos(th), np.ones_like(x)))
        c, *_ = np.linalg.lstsq(A, f, rcond=None)
        e = A @ c - c[2]
        sh = float(e @ e) / den
        if sh > best[0]:
            best = (sh, float(P), math.hypot(c[0], c[1]))
    return best


# ----------------------------------------------------------------------------- describe
#: A revolute joint's units in the sentences and a prismatic joint's: longest first.
_PRISMATIC_UNITS = ((re.compile(r"\bN m\b"), "N"), (re.compile(r"\brad/s\^2\b"), "m/s^2"),
                    (re.compile(r"\brad/s\b"), "m/s"), (re.compile(r"\brad\b"), "m"))


def prismatic_units(sentence: str) -> str:
    """A sentence written in a revolute joint's units ([rad], [rad/s], [rad/s^2], [N m]) in
    a prismatic joint's ([m], [m/s], [m/s^2], [N])."""
    for pat, unit in _PRISMATIC_UNITS:
        sentence = pat.sub(unit, sentence)
    return sentence


def describe_group(
    group: Group,
    coef: np.ndarray,
    y: np.ndarray,
    W: np.ndarray,
    values: Mapping[str, np.ndarray],
    *,
    reference: Mapping[str, float] | None = None,
    tau_out: Prediction | None = None,
    folds: np.ndarray | None = None,
    min_gain: float = 0.05,
    revolute: bool = True,
    load_dependent: bool = False,
) -> Description:
    """Name (with parameters ± 2σ) or describe a selected group (its sentence in the
    joint's units: ``revolute`` False, a prismatic joint's [m], [m/s], [N]); the parameters
    as :func:`_describe_group` gives them. ``load_dependent``: the model already has the
    load-dependent dry friction of eq. 24 (the paper model, or a step that added it), so
    the group is not named ``quadrant_load_velocity`` (its columns would repeat the model's)."""
    d = _describe_group(group, coef, y, W, values, reference=reference, tau_out=tau_out,
                        folds=folds, min_gain=min_gain, load_dependent=load_dependent)
    return d if revolute else replace(d, sentence=prismatic_units(d.sentence))


def _describe_group(
    group: Group,
    coef: np.ndarray,
    y: np.ndarray,
    W: np.ndarray,
    values: Mapping[str, np.ndarray],
    *,
    reference: Mapping[str, float] | None = None,
    tau_out: Prediction | None = None,
    folds: np.ndarray | None = None,
    min_gain: float = 0.05,
    load_dependent: bool = False,
) -> Description:
    """Name (with parameters ± 2σ) or describe a selected group, in a revolute joint's units.

    Parameters
    ----------
    group : Group
        The selected group.
    coef : ndarray, shape (group.size,)
        Its fitted coefficients.
    y : ndarray, shape (n,)
        Measured torque on the samples.
    W : ndarray, shape (n, p)
        The regressor the group was added to.
    values : mapping
        Variable arrays on the samples (as for the search).
    tau_out : Prediction, optional
        Load predictor, for the term of ``load_dependent_viscous``.
    folds : ndarray of int, shape (n,), optional
        Cross-validation folds of the samples: the shares are then ratios of held-out sums of
        squares (a form with fewer parameters is not penalised for the noise the basis fits).
    min_gain : float
        With folds, a named form is also taken when the basis does not lower its held-out
        error by this share (the library search's own selection rule).
    reference : mapping, optional
        Current model coefficients; ``F_C`` (Coulomb) scales the "±x %" of a dry-friction
        variation.
    load_dependent : bool
        The model has eq. 24's load-dependent dry friction already: no
        ``quadrant_load_velocity`` form (:func:`describe_group`).
    """
    reference = reference or {}
    # the named forms are scanned on at most ~8000 samples (regular stride)
    stride = max(1, math.ceil(y.shape[0] / 8000))
    if stride > 1:
        y, W = y[::stride], W[::stride]
        values = {k: np.asarray(v)[::stride] for k, v in values.items()}
        folds = None if folds is None else folds[::stride]
    fg = FoldGram(W, y, folds) if folds is not None else None
    norms = np.linalg.norm(W, axis=0)
    Q, _ = np.linalg.qr(W / np.where(norms > 0, norms, 1.0))
    r0 = y - Q @ (Q.T @ y)
    rss0 = float(r0 @ r0)
    rss_g = _rss_with(y, Q, group.columns(values))
    gain_g = max(rss0 - rss_g, 1e-300)
    if fg is not None:
        yy = float(y @ y)
        cv0 = fg.cv()[0] ** 2 * yy
        cv_g = fg.cv(group.columns(values))[0]
        cv_gain_g = max(cv0 - cv_g**2 * yy, 1e-300)

    def share(rss: float, C: np.ndarray) -> float:
        """Share of the group's gain a named form (columns C) reaches; at least
        MATCH_SHARE when the basis is not min_gain better on held-out data."""
        if fg is None:
            return (rss0 - rss) / gain_g
        cv_n = fg.cv(C)[0]
        sh = (cv0 - cv_n**2 * yy) / cv_gain_g
        return max(sh, MATCH_SHARE) if cv_g >= cv_n * (1 - min_gain) else sh
    grids, f = profile(group, coef)
    var, mod = group.variables[0], group.modifier
    what = _WHAT.get(mod, "the torque")
    unit = _unit(var)
    F_C = reference.get("F_C")
    sgn = values.get("direction")

    def rel(amp: float) -> str:
        if mod == "direction" and F_C:
            return f", ±{100 * amp / abs(F_C):.0f} % of F_C = {abs(F_C):.3g} N m"
        return ""

    # ---- named forms
    tried: list[tuple[str, float, dict]] = []
    if len(group.variables) == 1 and var != "reversal":
        x = values[var]
        m = np.ones_like(x) if mod == "none" else (
            values["load"] * values["quadrant"] if mod == "load_quadrant" else values[mod])
        span = float(np.ptp(x))

        def make_sin(P, x=x, m=m):
            th = 2 * np.pi * x / P
            return np.column_stack((np.sin(th) * m, np.cos(th) * m))

        if span > 0:
            rss, P, c, cov = _fit_form(y, W, Q, make_sin, span / 40, 2 * span)
            amp, amp2, ph, ph2 = amplitude_phase(c, cov)
            sd = _sd(cov)
            name = ("position_periodic_dry_friction" if (var, mod) == ("position", "direction")
                    else f"periodic_{var}" + ("" if mod == "none" else f"_{mod}"))
            pars = {"amplitude": _p(amp, amp2), "period": _p(P, 2 * sd[2]),
                    "phase": _p(ph, ph2)}
            if mod == "direction" and F_C:
                pars["relative_amplitude"] = _p(amp / abs(F_C), amp2 / abs(F_C))
            sent = (f"{what} varies periodically with {var}: period {P:.4g} ± {2 * sd[2]:.2g} "
                    f"{unit}, amplitude {amp:.3g} ± {amp2:.2g} N m{rel(amp)}")
            term = PositionDryFriction(P) if name == "position_periodic_dry_friction" else (
                CrossJointPeriodic(var, mod, P)
                if _is_other(var) and mod in _TERM_MODIFIERS else None)
            tried.append((name, share(rss, make_sin(P)), {"p": pars, "s": sent, "t": term}))
    if group.variables == ("reversal",) and mod == "direction" and sgn is not None:
        s_rev = values["reversal"]
        span = float(np.quantile(s_rev, 0.995))

        def make_exp(L, s_rev=s_rev, sgn=sgn):
            return (np.exp(-s_rev / L) * sgn)[:, None]

        if span > 0:
            rss, L, c, cov = _fit_form(y, W, Q, make_exp, span / 1000, span)
            sd = _sd(cov)
            pars = {"hysteresis_drop": _p(c[0], 2 * sd[0]), "hysteresis_length": _p(L, 2 * sd[1])}
            sent = (f"dry friction builds up after each reversal (hysteresis): it starts "
                    f"{abs(c[0]):.3g} ± {2 * sd[0]:.2g} N m "
                    f"{'below' if c[0] < 0 else 'above'} its sliding value and converges "
                    f"over {L:.3g} ± {2 * sd[1]:.2g} rad of travel (Dahl-like pre-sliding)")
            tried.append(("reversal_hysteresis", share(rss, make_exp(L)),
                          {"p": pars, "s": sent, "t": ReversalHysteresis(L)}))
    if "velocity" in group.variables and (
        (group.variables == ("velocity",) and mod == "load_quadrant")
        or set(group.variables) == {"velocity", "load"}
    ):
        C = (np.abs(values["load"]) * values["velocity"])[:, None]
        rss, _h, c, cov = _fit_form(y, W, Q, lambda _h, C=C: C, None, None)
        sd = _sd(cov)
        pars = {"F_V_load": _p(c[0], 2 * sd[0])}
        sent = (f"viscous friction grows with the load: F_V_load |tau_out| dq with F_V_load = "
                f"{c[0]:.3g} ± {2 * sd[0]:.2g} 1/(rad/s)")
        term = LoadViscous(tau_out) if tau_out is not None else None
        tried.append(("load_dependent_viscous", share(rss, C),
                      {"p": pars, "s": sent, "t": term}))
    if group.variables == ("velocity",) and mod == "load_quadrant" and not load_dependent:
        lq = values["load"] * values["quadrant"]
        adq = np.abs(values["velocity"])
        vmax = float(np.max(adq))

        def make_lv(q_s, lq=lq, adq=adq):
            return np.column_stack((lq, lq * stribeck_exp(adq, q_s)))

        if vmax > 0:
            rss, q_s, c, cov = _fit_form(y, W, Q, make_lv, vmax / 1000, vmax / 2)
            sd = _sd(cov)
            pars = {"alpha_P": _p(c[0], 2 * sd[0]), "beta_P": _p(c[1], 2 * sd[1]),
                    "q_s": _p(q_s, 2 * sd[2])}
            sent = (f"the load-dependent dry friction coefficient depends on the velocity "
                    f"(eq. 24): {c[0]:.3g} ± {2 * sd[0]:.2g} at speed, "
                    f"{c[0] + c[1]:.3g} near rest, transition q_s = {q_s:.3g} ± {2 * sd[2]:.2g}"
                    f" {unit}")
            term = LoadVelocityDryFriction(tau_out, q_s) if tau_out is not None else None
            tried.append(("quadrant_load_velocity", share(rss, make_lv(q_s)),
                          {"p": pars, "s": sent, "t": term}))
    linear = None
    if len(group.variables) == 1 and var not in _UNITS:
        # another joint's state (q<m>, dq<m>): a linear dependence, one column, is preferred
        # to the periodic form (which a long period can bend into a line) when it matches
        linear = _linear(var, values, mod, y, W, Q, share, what, rel, F_C)
        tried.append(linear)
        if linear[1] < MATCH_SHARE:
            tried.append(_polynomial(var, values, mod, y, W, Q, share, what, rel))
    elif len(group.variables) == 2 and mod in _TERM_MODIFIERS:
        # a pair in another joint's state: its one-variable named forms (the search's pair
        # holds each variable's own basis; a sinusoid of the other joint's position that does
        # as well on held-out data is what the pair found)
        for v in group.variables:
            if not _is_other(v):
                continue
            tried.append(_periodic(v, values, mod, y, W, Q, share, what, rel, F_C))
            lin = _linear(v, values, mod, y, W, Q, share, what, rel, F_C)
            tried.append(lin)
            if lin[1] >= MATCH_SHARE and (linear is None or lin[1] > linear[1]):
                linear = lin
            if lin[1] < MATCH_SHARE:
                tried.append(_polynomial(v, values, mod, y, W, Q, share, what, rel))
    if linear is not None and linear[1] >= MATCH_SHARE:
        name, share, info = linear
        return Description(name, info["s"], info["p"], share, grids, f, group.key, info["t"])
    if tried:
        name, share, info = max(tried, key=lambda t: t[1])
        if share >= MATCH_SHARE:
            return Description(name, info["s"], info["p"], share, grids, f, group.key,
                               info["t"])
        best_share = share
    else:
        best_share = math.nan

    # ---- words
    if len(group.variables) == 1:
        x = grids[0]
        amp = 0.5 * float(np.ptp(f))
        sh, P, a_s = _sinusoid_share(f, x)
        if var == "reversal":
            half = f[-1] + 0.5 * (f[0] - f[-1])
            k = int(np.argmax((f - half) * np.sign(f[0] - f[-1]) <= 0))
            sent = (f"{what} changes with the distance travelled since the last reversal by "
                    f"{abs(f[0] - f[-1]):.3g} N m, half of it within {x[k]:.3g} rad")
        elif sh > 0.8 and P < 0.9 * float(np.ptp(x)):
            sent = (f"{what} varies with {var}, period ≈ {P:.3g} {unit}, amplitude "
                    f"≈ {a_s:.3g} N m{rel(a_s)}")
        else:
            slope = np.polyfit(x, f, 1)[0]
            trend = "rises" if slope > 0 else "falls"
            sent = (f"{what} varies with {var} ({trend} overall), ±{amp:.3g} N m over "
                    f"[{x[0]:.3g}, {x[-1]:.3g}] {unit}{rel(amp)}")
    else:
        a, b = group.variables
        ones = dict(values)
        for m_ in ("direction", "quadrant", "load"):
            ones[m_] = np.ones_like(values[a])
        fs = group.columns(ones) @ coef  # on the samples: no corner of the grid never visited
        lo_, hi_ = np.quantile(fs, [0.005, 0.995])
        sent = (f"{what} varies with {a} and {b} jointly (interaction): ±"
                f"{0.5 * float(hi_ - lo_):.3g} N m over the samples")
    if math.isfinite(best_share):
        sent += f" (no named form fits: best explains {100 * best_share:.0f} % of it)"
    return Description(None, sent, {}, best_share, grids, f, group.key)


def _modifier(values: Mapping[str, np.ndarray], mod: str, x: np.ndarray) -> np.ndarray:
    if mod == "none":
        return np.ones_like(x)
    if mod == "load_quadrant":
        return values["load"] * values["quadrant"]
    return values[mod]


def _term_or_none(var: str, mod: str, make: Callable[[], Effect]) -> Effect | None:
    return make() if _is_other(var) and mod in _TERM_MODIFIERS else None


def _periodic(var: str, values: Mapping[str, np.ndarray], mod: str, y: np.ndarray,
              W: np.ndarray, Q: np.ndarray, share: Callable[[float, np.ndarray], float],
              what: str, rel: Callable[[float], str], F_C: float | None,
              ) -> tuple[str, float, dict]:
    """``periodic_<var>[_<mod>]``: [sin, cos](2π x/P) times the modifier, P scanned."""
    x = values[var]
    m = _modifier(values, mod, x)
    span = float(np.ptp(x))
    name = f"periodic_{var}" + ("" if mod == "none" else f"_{mod}")
    if span <= 0:
        return (name, -math.inf, {})

    def make_sin(P, x=x, m=m):
        th = 2 * np.pi * x / P
        return np.column_stack((np.sin(th) * m, np.cos(th) * m))

    rss, P, c, cov = _fit_form(y, W, Q, make_sin, span / 40, 2 * span)
    amp, amp2, ph, ph2 = amplitude_phase(c, cov)
    sd = _sd(cov)
    pars = {"amplitude": _p(amp, amp2), "period": _p(P, 2 * sd[2]), "phase": _p(ph, ph2)}
    if mod == "direction" and F_C:
        pars["relative_amplitude"] = _p(amp / abs(F_C), amp2 / abs(F_C))
    unit = _unit(var)
    sent = (f"{what} varies periodically with {var}: period {P:.4g} ± {2 * sd[2]:.2g} "
            f"{unit}, amplitude {amp:.3g} ± {amp2:.2g} N m{rel(amp)}")
    term = _term_or_none(var, mod, lambda: CrossJointPeriodic(var, mod, P))
    return (name, share(rss, make_sin(P)), {"p": pars, "s": sent, "t": term})


def _linear(var: str, values: Mapping[str, np.ndarray], mod: str, y: np.ndarray,
            W: np.ndarray, Q: np.ndarray, share: Callable[[float, np.ndarray], float],
            what: str, rel: Callable[[float], str], F_C: float | None,
            ) -> tuple[str, float, dict]:
    """``linear_<var>[_<mod>]``: (x - x̄) times the modifier."""
    x = values[var]
    m = _modifier(values, mod, x)
    C, centre, offsets = _poly_columns(x, m, 1)
    rss, _h, c, cov = _fit_form(y, W, Q, lambda _h, C=C: C, None, None)
    sd = _sd(cov)
    name = f"linear_{var}" + ("" if mod == "none" else f"_{mod}")
    pars = {"slope": _p(c[0], 2 * sd[0])}
    if mod == "direction" and F_C:
        pars["relative_slope"] = _p(c[0] / abs(F_C), 2 * sd[0] / abs(F_C))
    half = 0.5 * abs(c[0]) * float(np.ptp(x))
    unit = _unit(var)
    sent = (f"{what} varies linearly with {var}: slope {c[0]:.3g} ± {2 * sd[0]:.2g} "
            f"N m/{unit or 'unit'}, ±{half:.3g} N m over [{float(np.min(x)):.3g}, "
            f"{float(np.max(x)):.3g}] {unit}{rel(half)}")
    term = _term_or_none(var, mod, lambda: CrossJointPolynomial(var, mod, 1, centre, offsets))
    return (name, share(rss, C), {"p": pars, "s": sent, "t": term})


def _polynomial(var: str, values: Mapping[str, np.ndarray], mod: str, y: np.ndarray,
                W: np.ndarray, Q: np.ndarray, share: Callable[[float, np.ndarray], float],
                what: str, rel: Callable[[float], str]) -> tuple[str, float, dict]:
    """``polynomial_<var>[_<mod>]``: another joint's state in a polynomial of degree 2, or 3
    when the quadratic does not match (:data:`MATCH_SHARE`), centred on its mean, times the
    modifier (a cable or bearing load that bends over the other joint's range)."""
    x = values[var]
    m = _modifier(values, mod, x)
    unit = _unit(var)
    best: tuple[str, float, dict] = ("", -math.inf, {})
    for deg in (2, 3):
        C, centre, offsets = _poly_columns(x, m, deg)
        rss, _h, c, cov = _fit_form(y, W, Q, lambda _h, C=C: C, None, None)
        sd = _sd(cov)
        half = 0.5 * float(np.ptp(_poly_columns(x, np.ones_like(x), deg)[0] @ c))
        pars = {f"c{k}": _p(c[k - 1], 2 * sd[k - 1]) for k in range(1, deg + 1)}
        pars["centre"] = _p(centre, 0.0)
        pars["degree"] = _p(deg, 0.0)
        sent = (f"{what} varies with {var} as a polynomial of degree {deg} about "
                f"{centre:.3g} {unit}: ±{half:.3g} N m over "
                f"[{float(np.min(x)):.3g}, {float(np.max(x)):.3g}] {unit}{rel(half)}")
        term = _term_or_none(var, mod, lambda deg=deg, centre=centre, offsets=offsets:
                             CrossJointPolynomial(var, mod, deg, centre, offsets))
        best = (f"polynomial_{var}" + ("" if mod == "none" else f"_{mod}"), share(rss, C),
                {"p": pars, "s": sent, "t": term})
        if best[1] >= MATCH_SHARE:
            break
    return best


def name_torque_lag(T_lag: float, std2: float, cycle_s: float | None) -> tuple[str, str]:
    """Name a fitted torque lag: a zero-order hold when it is half a control cycle.

    A command held over one cycle acts, on average, half a cycle after the measurement it
    was computed from: τ_meas ≈ τ_model + (T_s/2) dτ_model/dt. A lag within 2σ (or 25 %) of
    T_s/2 is named ``zero_order_hold``.

    Returns
    -------
    name, sentence
    """
    if cycle_s and cycle_s > 0:
        half = 0.5 * cycle_s
        if abs(T_lag - half) <= max(std2, 0.25 * half):
            return ("zero_order_hold",
                    f"zero-order hold: the command acts half a cycle ({1e3 * half:.3g} ms) after "
                    f"the measurement (T_lag = {1e3 * T_lag:.3g} ± {1e3 * std2:.2g} ms)")
    return ("torque_lag", f"torque lag T_lag = {1e3 * T_lag:.3g} ± {1e3 * std2:.2g} ms")
