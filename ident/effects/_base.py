"""Base of the candidate effects: :class:`Effect`, :class:`Prediction`, the diagnosis
variables, and the registry through which every effect module offers itself to the
refinement loop (:mod:`ident.refine`).

An effect module (one file in ``ident/effects/``, see docs/refinement.md "Adding an effect")
defines its :class:`Effect` subclass (a regressor term linear in its parameters, with its
nonlinear hyper-parameters) and one proposal function decorated with :func:`register`::

    @register("spring", order=20)
    def propose(ctx: Context) -> list[Candidate]:
        if ctx.span > 0 and "spring" not in ctx.effects:
            return [ctx.candidate(Spring(float(np.mean(ctx.s.q))))]
        return []

At each refinement step the loop calls every registered proposal function in increasing
``order`` with a :class:`Context` (the decimated signals, the residual diagnosis, the
current library and coefficients, the load prediction τ̂_out, the scorer) and collects the
candidates. Nothing here touches files; everything is vectorised over samples.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..signals import Signals
from ..terms import Library, Term

if TYPE_CHECKING:  # pragma: no cover
    from ..diagnose import Diagnosis
    from ..preprocess import Design
    from ._scan import Columns

__all__ = [
    "VARIABLES",
    "Prediction",
    "amplitude_phase",
    "available_variables",
    "model_quadrant",
    "variable_values",
    "Effect",
    "Setting",
    "Candidate",
    "Context",
    "Registration",
    "register",
    "registry",
    "rigid_prediction",
    "model_prediction",
    "unique_tag",
]

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


def model_quadrant(s: Signals, tau_out: Prediction) -> np.ndarray:
    """sign(P_out) = sign(τ̂_out q̇) of the model's own load prediction (the quadrant of
    eq. 17-20 as the n-dof fit decides it), shape (n,). The paper's proxy sign(τ q̇) of
    eq. 26 reads the measured torque and is never a candidate variable."""
    return _sign(tau_out(s) * s.dq)


def available_variables(tau_out: Prediction | None) -> tuple[str, ...]:
    """The candidate variables that exist without reading the measured torque: ``load``
    and ``quadrant`` need the model's load prediction τ̂_out."""
    if tau_out is not None:
        return VARIABLES
    return tuple(v for v in VARIABLES if v not in ("load", "quadrant"))


def variable_values(variable: str, s: Signals, tau_out: Prediction | None = None) -> np.ndarray:
    """Samples of one candidate variable of the diagnosis.

    No variable reads the measured torque: ``load`` is the model's prediction τ̂_out and
    ``quadrant`` the model quadrant sign(τ̂_out q̇) (:func:`model_quadrant`).

    Parameters
    ----------
    variable : str
        One of :data:`VARIABLES`, or a key of ``s.extra``.
    s : Signals
        Samples (a :meth:`~ident.signals.Signals.states` view is enough).
    tau_out : Prediction, optional
        Load torque predictor τ̂_out; without it ``load`` and ``quadrant`` do not exist
        (:func:`available_variables`).

    Returns
    -------
    ndarray, shape (n,)
        position q, velocity q̇, direction sign(q̇), acceleration q̈, load τ̂_out,
        quadrant sign(τ̂_out q̇), time t since the start of the run.

    Raises
    ------
    KeyError
        ``load`` or ``quadrant`` without a load predictor.
    ValueError
        Unknown variable.
    """
    if variable == "position":
        return s.q
    if variable == "velocity":
        return s.dq
    if variable == "direction":
        return np.asarray(s.direction, dtype=float)
    if variable == "acceleration":
        return s.ddq
    if variable in ("load", "quadrant"):
        if tau_out is None:
            raise KeyError(f"{variable!r} needs the model's load prediction tau_out (the model "
                           "has no rigid body or payload term)")
        return tau_out(s) if variable == "load" else model_quadrant(s, tau_out)
    if variable == "time":
        return s.t
    if s.extra is not None and variable in s.extra:  # another joint's state (Signals.extra)
        return s.extra[variable]
    raise ValueError(f"unknown candidate variable {variable!r}; expected one of {VARIABLES}")


@dataclass(frozen=True)
class Setting:
    """Facts of the data a named effect's physical range is checked against.

    Attributes
    ----------
    cycle_s : float or None
        Sampling period of the raw log [s] (not the decimated one).
    run_s : float
        Longest run of the design [s].
    excitation_s : float
        Median time between two reversals of the motion [s] (the excitation's time scale).
    """

    cycle_s: float | None
    run_s: float
    excitation_s: float


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

    def extra_parameters(
        self,
        coef: dict[str, float],
        names: list[str],
        cov: np.ndarray,
        params: dict[str, dict[str, float]],
    ) -> dict[str, dict[str, float]]:
        """Derived parameters that need the rest of the model (e.g. F_V+ and F_V- from F_V).

        Parameters
        ----------
        coef : dict[str, float]
            Coefficients of the fitted model holding this term.
        names : list of str
            Their names in the order of ``cov``'s first rows.
        cov : ndarray, shape (p + h, p + h)
            Covariance of the model's coefficients followed by this term's hyper-parameters.
        params : dict
            ``{name: {"value", "std2"}}`` of :meth:`parameters`.

        Returns
        -------
        dict
            More ``{name: {"value", "std2"}}`` entries for the report (none by default).
        """
        return {}

    def jackknife(self, design: Design, names: Sequence[str]) -> dict[str, float] | None:
        """Twice the block-jackknife standard deviation of the parameters of
        :meth:`parameters`, the hyper-parameter's scan redone in every replicate
        (:func:`ident.effects._jackknife.hyper_jackknife`); None: not made (the default:
        the linearised 2σ stands alone).

        Parameters
        ----------
        design : Design
            The design with this term's columns (the fit's rows, instruments if any).
        names : sequence of str
            The fitted model's kept columns, in the order of its fit.
        """
        return None

    def physical_range(self, parameters: dict[str, dict[str, float]],
                       setting: Setting) -> str | None:
        """Why the fitted parameters leave the range where this effect's physics holds, or
        None when they are inside it (default: no declared range).

        Parameters
        ----------
        parameters : dict
            ``{name: {"value", "std2"}}`` of the fitted step.
        setting : Setting
            Sampling period, run length and excitation time scale of the data.
        """
        return None

    def _n(self, base: str) -> str:
        return base + self.tag


# ----------------------------------------------------------------------------- registry
@dataclass
class Candidate:
    """A candidate effect scored on the current residual.

    Attributes
    ----------
    effect : Effect
        The term, hyper-parameters set.
    gain : float
        Residual sum of squares its columns remove [N² m²] (:class:`ident.effects.Scorer`).
    n_hyper : int
        Number of scanned hyper-parameters (extra degrees of freedom of the F test).
    generic : bool
        A generic basis (competes with the named effects under a margin).
    n_eff : float
        Effective sample size of the residual left after the candidate
        (:meth:`ident.effects.Scorer.n_eff_after`), set by the loop when the F pre-test
        needs it; 0 when unknown.
    """

    effect: Effect
    gain: float
    n_hyper: int
    generic: bool = False
    n_eff: float = 0.0


def unique_tag(names: tuple[str, ...], existing: set[str]) -> str:
    """``""`` if none of ``names`` is taken, else the first suffix ``_2``, ``_3``... that
    makes them all new."""
    if not set(names) & existing:
        return ""
    k = 2
    while True:
        tag = f"_{k}"
        if not {n + tag for n in names} & existing:
            return tag
        k += 1


def rigid_prediction(lib: Library, coef: dict[str, float]) -> Prediction | None:
    """τ̂_out, the model's own load prediction: the declared rigid-body and payload terms of
    ``lib`` with their current coefficients (eq. 31, 34), or, in the paper model, the inner
    terms of its load-dependent friction (eq. 42) with the mean of their motor and generator
    products, (a_m χ + a_g χ) / 2 ≈ χ; None when there are none (or all are zero).

    Never the measured torque: without a rigid body the model has no load variable.
    """
    terms = [t for t in lib.terms() if t.effect in ("rigid_body", "payload")]
    if terms:
        c = np.array([coef.get(n, 0.0) for t in terms for n in t.names()])
    else:
        dep = next((t for t in lib.terms() if t.effect == "load_dependent"), None)
        if dep is None:
            return None
        terms = list(dep.inner.terms())
        names = dep.names()
        k = len(names) // 4  # [a_m, b_m] per inner column, then [a_g, b_g] per column
        vals = []
        for i in range(k):
            pair = [coef[n] for n in (names[2 * i], names[2 * k + 2 * i])
                    if n in coef and coef[n] != 0.0]
            vals.append(float(np.mean(pair)) if pair else 0.0)
        c = np.array(vals)
    if not np.any(c):
        return None
    return Prediction(terms, c)


def model_prediction(lib: Library, coef: dict[str, float]) -> Prediction:
    """τ̂ of the whole current model, a function of the states only: terms whose quadrant is
    the paper's proxy sign(τ q̇) (eq. 26: the declared paper model) decide it with the model's
    load prediction instead (:func:`rigid_prediction`)."""
    load = rigid_prediction(lib, coef)
    terms = []
    for t in lib.terms():
        if hasattr(t, "load") and getattr(t, "load", None) is None and load is not None:
            t = copy.copy(t)
            t.load = load
        terms.append(t)
    return Prediction(terms, np.array([coef.get(n, 0.0) for n in lib.names()]))


class Context:
    """What a proposal function sees at one refinement step.

    Parameters
    ----------
    cols : Columns
        Scorer on the decimated signals (``cols.gain(effect)``).
    diag : Diagnosis
        Diagnosis of the current residual (:func:`ident.diagnose.diagnose`).
    lib : Library
        The current library (declared model + accepted effects).
    coef : dict[str, float]
        Its current coefficients.
    alpha : float
        Family-wise test level of the loop.
    generic_knots : int
        Knots of a generic basis.

    Attributes
    ----------
    s : Signals
        The decimated signals, shape (m,) each.
    names, effects : set of str
        Parameter names and effect names of ``lib``.
    span : float
        Position range max q - min q [rad or m].
    vmax : float
        max |q̇| [rad/s or m/s].
    tmax : float
        max t [s].
    tau_out : Prediction or None
        τ̂_out of the declared rigid body and payload (:func:`rigid_prediction`).
    """

    def __init__(
        self,
        cols: Columns,
        diag: Diagnosis,
        lib: Library,
        coef: dict[str, float],
        alpha: float,
        generic_knots: int,
    ) -> None:
        self.cols, self.diag, self.lib, self.coef = cols, diag, lib, coef
        self.alpha, self.generic_knots = alpha, generic_knots
        self.s = cols.s
        self.names = set(lib.names())
        self.effects = {t.effect for t in lib.terms()}
        self.span = float(self.s.q.max() - self.s.q.min())
        self.vmax = float(np.max(np.abs(self.s.dq)))
        self.tmax = float(self.s.t.max())
        self.tau_out = rigid_prediction(lib, coef)

    def has(self, *effects: str) -> bool:
        """Whether the library holds a term of one of these effect names."""
        return any(t.effect in effects for t in self.lib.terms())

    def candidate(self, e: Effect, generic: bool = False) -> Candidate:
        """``e`` (tagged if its parameter names are taken) scored, no scanned
        hyper-parameter."""
        tag = unique_tag(e.names(), self.names)
        if tag:
            e = e.with_tag(tag)
        return Candidate(e, self.cols.gain(e), 0, generic)


@dataclass(frozen=True)
class Registration:
    """One registered effect module: its name, rank and proposal function."""

    name: str
    order: int
    propose: Callable[[Context], list[Candidate]]
    module: str


_REGISTRY: dict[str, Registration] = {}


def register(
    name: str, *, order: int
) -> Callable[[Callable[[Context], list[Candidate]]], Callable[[Context], list[Candidate]]]:
    """Decorator registering a proposal function ``propose(ctx) -> list[Candidate]``.

    Parameters
    ----------
    name : str
        Effect name (the module's effect, e.g. ``"spring"``); unique.
    order : int
        Rank: the loop calls the proposal functions by increasing ``order`` (ties are
        not allowed), which fixes the order of the candidates.
    """

    def deco(fn: Callable[[Context], list[Candidate]]) -> Callable[[Context], list[Candidate]]:
        old = _REGISTRY.get(name)
        if old is not None and old.module != fn.__module__:
            raise ValueError(f"effect {name!r} registered twice ({old.module}, {fn.__module__})")
        clash = [r.name for r in _REGISTRY.values() if r.order == order and r.name != name]
        if clash:
            raise ValueError(f"effect {name!r}: order {order} already used by {clash[0]!r}")
        _REGISTRY[name] = Registration(name, order, fn, fn.__module__)
        return fn

    return deco


def registry() -> list[Registration]:
    """The registered effects, by increasing order."""
    return sorted(_REGISTRY.values(), key=lambda r: r.order)


def amplitude_phase(coef: np.ndarray, cov: np.ndarray) -> tuple[float, float, float, float]:
    """Amplitude and phase of ``a sin th + b cos th = A sin(th + phi)`` from the first two
    coefficients, with twice their standard deviations by the delta method.

    Parameters
    ----------
    coef : ndarray, shape (p,)
        ``a``, ``b`` first (further entries, e.g. a period, are not used).
    cov : ndarray, shape (p, p)
        Covariance of ``coef``.

    Returns
    -------
    (A, 2 sigma_A, phi [rad], 2 sigma_phi)
    """
    a, b = float(coef[0]), float(coef[1])
    amp = math.hypot(a, b)
    g = np.zeros((2, len(coef)))
    if amp > 0:
        g[0, :2] = (a / amp, b / amp)
        g[1, :2] = (-b / amp**2, a / amp**2)
    sd = np.sqrt(np.clip(np.diag(g @ cov @ g.T), 0, None))
    return amp, 2 * float(sd[0]), math.atan2(b, a), 2 * float(sd[1])
