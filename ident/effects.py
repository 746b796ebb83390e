"""Candidate effects: regressor terms the refinement loop may add to a declared model.

Every effect is a :class:`~ident.terms.Term` (columns linear in its parameters) that also
carries its nonlinear hyper-parameters (a ripple period, a Stribeck velocity q_s, a warm-up
time constant), so that :mod:`ident.refine` can scan them and report them with their 2σ.

==========================  ============  ==============================================
effect                      variable      columns (parameters)
==========================  ============  ==============================================
``position_ripple``         position      sin(2π q/P), cos(2π q/P)  (A, phase; P scanned)
``spring``                  position      q - q_c  (k_spring)
``position_smooth``         position      Legendre P_2..P_d of the scaled position
``directional_viscous``     direction     |q̇|/2  (dF_V = F_V+ - F_V-)
``quadratic_viscous``       velocity      q̇|q̇|  (F_VV)
``stribeck``                velocity      exp(-|q̇|/q_s) sign(q̇)  (F_S; q_s scanned, eq. 22)
``quadrant_load``           quadrant      sign(P) τ̂_out  (alpha_P, eq. 17-20, 26)
``quadrant_coulomb``        quadrant      sign(P) sign(q̇) / 2  (dF_Cq = c_m - c_g)
``quadrant_load_stribeck``  quadrant      sign(P) τ̂_out exp(-|q̇|/q_s)  (beta_P; eq. 24)
``warm_up``                 time          exp(-t/T_w) sign(q̇)  (dF_C_warm; T_w scanned)
``torque_lag``              acceleration  dτ̂/dt  (T_lag)
``generic_<variable>``      any           hinges max(x - k_j, 0) of the variable (× sign(q̇))
==========================  ============  ==============================================

``τ̂_out`` is the load torque predicted by the declared rigid-body terms with their current
coefficients (the terms whose ``variable`` is ``"model"``), see :class:`Prediction`; the
torque lag differentiates the whole current model prediction τ̂.
Nothing here touches files; everything is vectorised over samples.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .signals import Signals
from .terms import Term

VARIABLES = ("position", "velocity", "direction", "acceleration", "load", "quadrant", "time")


class Prediction:
    """A frozen linear combination of terms, evaluated on any signals: τ̂ = W(s) χ̂.

    Parameters
    ----------
    terms : sequence of Term
        The terms (e.g. the declared rigid body and payload), in order.
    coef : array_like, shape (sum of the terms' columns,)
        Their identified coefficients, in the same order.
    """

    def __init__(self, terms: Sequence[Term], coef: np.ndarray) -> None:
        self.terms = tuple(terms)
        self.coef = np.asarray(coef, dtype=float).copy()
        k = sum(len(t.names()) for t in self.terms)
        if k != self.coef.shape[0]:
            raise ValueError(f"Prediction: {k} columns but {self.coef.shape[0]} coefficients")

    def __call__(self, s: Signals) -> np.ndarray:
        """τ̂ [N m], shape ``(len(s),)``."""
        if not self.terms:
            return np.zeros(len(s))
        W = np.concatenate([t.columns(s) for t in self.terms], axis=1)
        return W @ self.coef


def _sign(x: np.ndarray) -> np.ndarray:
    return np.sign(x).astype(float)


def variable_values(variable: str, s: Signals, tau_out: Prediction | None = None) -> np.ndarray:
    """Samples of one candidate variable of the diagnosis.

    Parameters
    ----------
    variable : str
        One of :data:`VARIABLES`.
    s : Signals
        Samples.
    tau_out : Prediction, optional
        Load torque predictor τ̂_out; without it the measured torque τ stands for the load.

    Returns
    -------
    ndarray, shape (n,)
        position q, velocity q̇, direction sign(q̇), acceleration q̈, load τ_out,
        quadrant sign(P) = sign(τ q̇) (eq. 26), time t since the start of the run.
    """
    if variable == "position":
        return s.q
    if variable == "velocity":
        return s.dq
    if variable == "direction":
        return _sign(s.dq)
    if variable == "acceleration":
        return s.ddq
    if variable == "load":
        return tau_out(s) if tau_out is not None else s.tau
    if variable == "quadrant":
        return _sign(s.tau * s.dq)
    if variable == "time":
        return s.t
    raise ValueError(f"unknown candidate variable {variable!r}; expected one of {VARIABLES}")


class Effect(Term):
    """A candidate effect: a term plus its nonlinear hyper-parameters.

    Subclasses set :attr:`effect`, :attr:`variable`, :attr:`hyper_names` and implement
    :meth:`names`, :meth:`columns` and :meth:`with_hyper`. ``tag`` is appended to the
    parameter names so that the same effect can be added twice (two ripples).
    """

    #: Names of the nonlinear hyper-parameters, scanned by the refinement loop.
    hyper_names: tuple[str, ...] = ()

    def __init__(self, tag: str = "") -> None:
        self.tag = tag

    @property
    def hyper(self) -> dict[str, float]:
        """Current hyper-parameter values {name: value}."""
        return {h: float(getattr(self, h)) for h in self.hyper_names}

    def with_hyper(self, **values: float) -> Effect:
        """A copy with other hyper-parameter values."""
        raise NotImplementedError(f"{type(self).__name__} has no hyper-parameters")

    def with_tag(self, tag: str) -> Effect:
        """A copy whose parameter names carry ``tag``."""
        import copy

        other = copy.copy(self)
        other.tag = tag
        return other

    def parameters(self, coef: np.ndarray, cov: np.ndarray) -> dict[str, tuple[float, float]]:
        """Physical parameters with their 2σ from the coefficients of this term.

        Parameters
        ----------
        coef : ndarray, shape (k + h,)
            Coefficients of the term's columns followed by the hyper-parameters.
        cov : ndarray, shape (k + h, k + h)
            Their covariance.

        Returns
        -------
        dict
            ``{name: (value, two_sigma)}``; by default the coefficients as they are.
        """
        names = list(self.names()) + list(self.hyper_names)
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        return {n: (float(c), float(2 * d)) for n, c, d in zip(names, coef, sd, strict=True)}

    def _n(self, base: str) -> str:
        return base + self.tag


class PositionRipple(Effect):
    """Position-periodic torque A sin(2π q / P + φ) (cogging, gear mesh, screw pitch).

    Parameters
    ----------
    period : float
        Period P in position [rad or m]; a hyper-parameter refined on the residual.
    """

    effect = "position_ripple"
    variable = "position"
    hyper_names = ("period",)

    def __init__(self, period: float, tag: str = "") -> None:
        super().__init__(tag)
        if not period > 0:
            raise ValueError(f"PositionRipple: period must be > 0, got {period}")
        self.period = float(period)

    def with_hyper(self, **values: float) -> PositionRipple:
        return PositionRipple(values.get("period", self.period), self.tag)

    def names(self) -> tuple[str, ...]:
        return (self._n("ripple_sin"), self._n("ripple_cos"))

    def columns(self, s: Signals) -> np.ndarray:
        th = (2 * np.pi / self.period) * s.q
        return np.column_stack((np.sin(th), np.cos(th)))

    def parameters(self, coef, cov):
        a, b = float(coef[0]), float(coef[1])
        amp = math.hypot(a, b)
        # A sin(th + phi) = A cos(phi) sin(th) + A sin(phi) cos(th)
        g = np.zeros((2, len(coef)))
        if amp > 0:
            g[0, :2] = (a / amp, b / amp)
            g[1, :2] = (-b / amp**2, a / amp**2)
        sd = np.sqrt(np.clip(np.diag(g @ cov @ g.T), 0, None))
        out = {
            self._n("ripple_amplitude"): (amp, float(2 * sd[0])),
            self._n("ripple_phase"): (math.atan2(b, a), float(2 * sd[1])),
        }
        sdp = math.sqrt(max(float(cov[2, 2]), 0.0)) if len(coef) > 2 else 0.0
        out[self._n("ripple_period")] = (self.period, 2 * sdp)
        return out

    def describe(self) -> str:
        return f"position ripple A sin(2π q/{self.period:.6g} + φ)"


class Spring(Effect):
    """Linear position-dependent torque k (q - q_c) (spring, cable, gravity-model error).

    The constant -k q_c merges with the offset τ_off, so only k is identified.

    Parameters
    ----------
    q_center : float
        Reference position q_c [rad or m] (conditioning only).
    """

    effect = "spring"
    variable = "position"

    def __init__(self, q_center: float = 0.0, tag: str = "") -> None:
        super().__init__(tag)
        self.q_center = float(q_center)

    def names(self) -> tuple[str, ...]:
        return (self._n("k_spring"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (s.q - self.q_center)[:, None]

    def describe(self) -> str:
        return "spring k (q - q0)"


class PositionSmooth(Effect):
    """Smooth position-dependent torque: Legendre polynomials P_2..P_degree of the position
    scaled to [-1, 1] over [q_min, q_max] (the linear part is :class:`Spring`)."""

    effect = "position_smooth"
    variable = "position"

    def __init__(self, q_min: float, q_max: float, degree: int = 4, tag: str = "") -> None:
        super().__init__(tag)
        if not q_max > q_min:
            raise ValueError("PositionSmooth: q_max must exceed q_min")
        self.q_min, self.q_max, self.degree = float(q_min), float(q_max), int(degree)

    def names(self) -> tuple[str, ...]:
        return tuple(self._n(f"pos_P{k}") for k in range(2, self.degree + 1))

    def columns(self, s: Signals) -> np.ndarray:
        x = (2 * s.q - (self.q_max + self.q_min)) / (self.q_max - self.q_min)
        V = np.polynomial.legendre.legvander(x, self.degree)
        return V[:, 2:]

    def describe(self) -> str:
        return f"smooth position torque (Legendre degree 2..{self.degree})"


class DirectionalViscous(Effect):
    """Direction-dependent viscous friction F_V+ q̇ (q̇ > 0), F_V- q̇ (q̇ < 0).

    Added to a symmetric viscous term F_V q̇ through the column |q̇|/2, whose coefficient is
    dF_V = F_V+ - F_V-; the symmetric F_V then becomes (F_V+ + F_V-)/2.
    """

    effect = "directional_viscous"
    variable = "direction"

    def names(self) -> tuple[str, ...]:
        return (self._n("dF_V"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (0.5 * np.abs(s.dq))[:, None]

    def describe(self) -> str:
        return "direction-dependent viscous (F_V+ - F_V-) |dq|/2"


class QuadraticViscous(Effect):
    """Nonlinear viscous friction F_VV q̇|q̇|."""

    effect = "quadratic_viscous"
    variable = "velocity"

    def names(self) -> tuple[str, ...]:
        return (self._n("F_VV"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (s.dq * np.abs(s.dq))[:, None]

    def describe(self) -> str:
        return "quadratic viscous F_VV dq|dq|"


class Stribeck(Effect):
    """Stribeck velocity-dependent dry friction F_S exp(-|q̇|/q_s) sign(q̇) (eq. 22, 29).

    Parameters
    ----------
    qs : float
        Stribeck velocity q_s [rad/s or m/s]; a hyper-parameter scanned on the residual.
    """

    effect = "stribeck"
    variable = "velocity"
    hyper_names = ("qs",)

    def __init__(self, qs: float, tag: str = "") -> None:
        super().__init__(tag)
        if not qs > 0:
            raise ValueError(f"Stribeck: qs must be > 0, got {qs}")
        self.qs = float(qs)

    def with_hyper(self, **values: float) -> Stribeck:
        return Stribeck(values.get("qs", self.qs), self.tag)

    def names(self) -> tuple[str, ...]:
        return (self._n("F_S"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (np.exp(-np.abs(s.dq) / self.qs) * _sign(s.dq))[:, None]

    def describe(self) -> str:
        return f"Stribeck F_S exp(-|dq|/{self.qs:.4g}) sign(dq)"


class QuadrantLoad(Effect):
    """Load-dependent dry friction in the motor/generator quadrants (eq. 17-20, 26).

    Column sign(P) τ̂_out = sign(τ q̇) τ̂_out ≈ |τ̂_out| sign(q̇), with τ̂_out the load torque
    predicted by the declared rigid-body terms. Its coefficient alpha_P is the mean of the
    paper's alpha_m and alpha_g (their difference is absorbed by the rigid-body parameters).

    Parameters
    ----------
    tau_out : Prediction
        Load-torque predictor τ̂_out [N m].
    """

    effect = "quadrant_load"
    variable = "quadrant"

    def __init__(self, tau_out: Prediction, tag: str = "") -> None:
        super().__init__(tag)
        self.tau_out = tau_out

    def names(self) -> tuple[str, ...]:
        return (self._n("alpha_P"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (_sign(s.tau * s.dq) * self.tau_out(s))[:, None]

    def describe(self) -> str:
        return "load-dependent dry friction alpha_P sign(P) tau_out"


class QuadrantCoulomb(Effect):
    """Different dry friction in the motor and generator quadrants (c_m != c_g, eq. 25):
    (dF_Cq / 2) sign(P) sign(q̇) = (dF_Cq / 2) sign(τ) for q̇ != 0, with dF_Cq = c_m - c_g."""

    effect = "quadrant_coulomb"
    variable = "quadrant"

    def names(self) -> tuple[str, ...]:
        return (self._n("dF_Cq"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (0.5 * _sign(s.tau * s.dq) * _sign(s.dq))[:, None]

    def describe(self) -> str:
        return "quadrant dry friction (c_m - c_g) sign(P) sign(dq) / 2"


class QuadrantLoadStribeck(Effect):
    """Velocity dependence of the load-dependent dry friction (the b terms of eq. 24-25):
    beta_P sign(P) τ̂_out exp(-|q̇|/q_s), added after :class:`QuadrantLoad`.

    Parameters
    ----------
    tau_out : Prediction
        Load-torque predictor τ̂_out [N m].
    qs : float
        Stribeck velocity q_s [rad/s or m/s]; a hyper-parameter scanned on the residual.
    """

    effect = "quadrant_load_stribeck"
    variable = "quadrant"
    hyper_names = ("qs",)

    def __init__(self, tau_out: Prediction, qs: float, tag: str = "") -> None:
        super().__init__(tag)
        if not qs > 0:
            raise ValueError(f"QuadrantLoadStribeck: qs must be > 0, got {qs}")
        self.tau_out, self.qs = tau_out, float(qs)

    def with_hyper(self, **values: float) -> QuadrantLoadStribeck:
        return QuadrantLoadStribeck(self.tau_out, values.get("qs", self.qs), self.tag)

    def names(self) -> tuple[str, ...]:
        return (self._n("beta_P"),)

    def columns(self, s: Signals) -> np.ndarray:
        e = np.exp(-np.abs(s.dq) / self.qs)
        return (_sign(s.tau * s.dq) * self.tau_out(s) * e)[:, None]

    def describe(self) -> str:
        return (
            f"low-velocity load-dependent friction beta_P sign(P) tau_out exp(-|dq|/{self.qs:.4g})"
        )


class WarmUp(Effect):
    """Time drift of dry friction (warm-up): dF_C exp(-t/T_w) sign(q̇).

    With a plant friction F_C (1 + w exp(-t/T_w)) sign(q̇), dF_C_warm = w F_C.

    Parameters
    ----------
    T_w : float
        Warm-up time constant [s]; a hyper-parameter scanned on the residual.
    """

    effect = "warm_up"
    variable = "time"
    hyper_names = ("T_w",)

    def __init__(self, T_w: float, tag: str = "") -> None:
        super().__init__(tag)
        if not T_w > 0:
            raise ValueError(f"WarmUp: T_w must be > 0, got {T_w}")
        self.T_w = float(T_w)

    def with_hyper(self, **values: float) -> WarmUp:
        return WarmUp(values.get("T_w", self.T_w), self.tag)

    def names(self) -> tuple[str, ...]:
        return (self._n("dF_C_warm"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (np.exp(-s.t / self.T_w) * _sign(s.dq))[:, None]

    def describe(self) -> str:
        return f"warm-up dF_C exp(-t/{self.T_w:.4g}) sign(dq)"


def _time_derivative(x: np.ndarray, s: Signals) -> np.ndarray:
    """dx/dt per experiment (central differences), shape (n,)."""
    out = np.empty_like(x)
    exp = s.experiment
    if len(x) < 2:
        return np.zeros_like(x)
    cuts = np.flatnonzero(np.diff(exp) != 0) + 1
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(x)], strict=True):
        if b - a >= 2:
            out[a:b] = np.gradient(x[a:b], s.t[a:b])
        else:
            out[a:b] = 0.0
    return out


class TorqueLag(Effect):
    """First-order lag between the torque reference and the applied torque.

    τ_ref ≈ τ_model + T_lag dτ_model/dt; the column is the time derivative of the current
    model prediction τ̂ (not of the measured torque, which would put noise in the regressor).
    Reported under the variable ``"acceleration"`` (the rate of change of the dynamics).

    Parameters
    ----------
    tau_model : Prediction
        Current model prediction τ̂ [N m].
    """

    effect = "torque_lag"
    variable = "acceleration"

    def __init__(self, tau_model: Prediction, tag: str = "") -> None:
        super().__init__(tag)
        self.tau_model = tau_model

    def names(self) -> tuple[str, ...]:
        return (self._n("T_lag"),)

    def columns(self, s: Signals) -> np.ndarray:
        return _time_derivative(self.tau_model(s), s)[:, None]

    def describe(self) -> str:
        return "torque lag T_lag d(tau_model)/dt"


class GenericBasis(Effect):
    """Generic basis expansion in one variable: hinge functions max(x - k_j, 0) at the
    ``n_knots - 2`` interior knots of a uniform grid over [lo, hi] (x clipped to [lo, hi]),
    optionally multiplied by sign(q̇). Used when the residual depends on a variable but no
    named effect fits.

    The hinges span the piecewise-linear functions of x *without* their constant and linear
    parts, which the declared model usually carries already (offset, viscous, Coulomb), so
    the basis is not collinear with it; each parameter is the change of slope at a knot.

    Parameters
    ----------
    variable : str
        One of :data:`VARIABLES` with a continuous range (position, velocity,
        acceleration, load, time).
    lo, hi : float
        Knot range in the variable's unit.
    n_knots : int
        Number of grid points (≥ 3), ends included.
    signed : bool
        Multiply the hinges by sign(q̇) (a friction-like effect).
    tau_out : Prediction, optional
        Load predictor for ``variable="load"``.
    """

    def __init__(
        self,
        variable: str,
        lo: float,
        hi: float,
        n_knots: int = 12,
        signed: bool = False,
        tau_out: Prediction | None = None,
        tag: str = "",
    ) -> None:
        super().__init__(tag)
        if variable not in VARIABLES:
            raise ValueError(f"GenericBasis: unknown variable {variable!r}")
        if not hi > lo or n_knots < 3:
            raise ValueError("GenericBasis: need hi > lo and n_knots >= 3")
        self.variable = variable
        self.effect = f"generic_{variable}" + ("_signed" if signed else "")
        self.lo, self.hi, self.n_knots, self.signed = float(lo), float(hi), int(n_knots), signed
        self.tau_out = tau_out

    @property
    def knots(self) -> np.ndarray:
        """Interior knots k_j, shape (n_knots - 2,), in the variable's unit."""
        return np.linspace(self.lo, self.hi, self.n_knots)[1:-1]

    def names(self) -> tuple[str, ...]:
        v = self.variable[:3]
        return tuple(
            self._n(f"g{'s' if self.signed else ''}_{v}_{k}") for k in range(1, self.n_knots - 1)
        )

    def columns(self, s: Signals) -> np.ndarray:
        x = np.clip(variable_values(self.variable, s, self.tau_out), self.lo, self.hi)
        H = np.maximum(x[:, None] - self.knots[None, :], 0.0)
        if self.signed:
            H = H * _sign(s.dq)[:, None]
        return H

    def describe(self) -> str:
        sg = " x sign(dq)" if self.signed else ""
        return (
            f"generic basis in {self.variable}{sg}: {self.n_knots - 2} hinge functions "
            f"on [{self.lo:.4g}, {self.hi:.4g}] (no named effect fitted)"
        )
