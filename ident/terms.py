"""Composable regressor terms: a model is a sum of terms, W = [W_1 | W_2 | ...].

This is the contract shared by the model library (:mod:`ident.models`), the estimator
(:mod:`ident.estimate`) and the refinement loop (:mod:`ident.refine`): every physical
effect, declared or discovered, is a :class:`Term` that turns :class:`~ident.signals.Signals`
into regressor columns, linear in its parameters (paper eq. 10-11). Adding an effect to a
model is adding a term::

    usual = RigidBody() + Payload() + Coulomb() + Viscous() + Offset()
    refined = usual + PositionRipple(period=0.0628)

Terms are immutable; hyper-parameters fixed a priori (q_s of eq. 29, a ripple period) are
constructor arguments. Column scaling and estimation belong to the estimator, not here.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator

import numpy as np

from .signals import Signals


class Term(ABC):
    """A block of regressor columns, linear in its parameters.

    Subclasses set :attr:`variable` (the candidate variable of the residual diagnosis the
    effect depends on: ``"position"``, ``"velocity"``, ``"direction"``, ``"acceleration"``,
    ``"load"``, ``"quadrant"``, ``"time"``, or ``"model"`` for the declared rigid body) and
    implement :meth:`names` and :meth:`columns`.
    """

    #: Short identifier of the effect, used in reports and JSON (e.g. ``"viscous"``).
    effect: str = "term"
    #: Candidate variable the effect depends on (see class docstring).
    variable: str = "model"

    @abstractmethod
    def names(self) -> tuple[str, ...]:
        """Parameter names, one per column (e.g. ``("F_V",)``); unique within a model."""

    @abstractmethod
    def columns(self, s: Signals) -> np.ndarray:
        """Regressor columns, shape ``(len(s), len(self.names()))``, float64."""

    def describe(self) -> str:
        """One line saying what the term models, with its formula."""
        return self.effect

    def sigma_note(self) -> str | None:
        """What the parameters' 2σ leaves out, when measurements showed it (one line, printed
        with a refinement step and kept in its JSON as ``sigma_note``); None by default."""
        return None

    def __add__(self, other: Term) -> Library:
        return Library(*self.terms(), *other.terms())

    def terms(self) -> tuple[Term, ...]:
        """The elementary terms of this term (itself, for an elementary term)."""
        return (self,)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(self.names())})"


class Library(Term):
    """The sum of terms: their columns side by side, in order."""

    effect = "library"

    def __init__(self, *terms: Term) -> None:
        flat: list[Term] = []
        for t in terms:
            flat.extend(t.terms())
        self._terms = tuple(flat)
        seen: set[str] = set()
        for n in self.names():
            if n in seen:
                raise ValueError(f"parameter name {n!r} appears twice in the model")
            seen.add(n)

    def terms(self) -> tuple[Term, ...]:
        return self._terms

    def __iter__(self) -> Iterator[Term]:
        return iter(self._terms)

    def __len__(self) -> int:
        return len(self._terms)

    def names(self) -> tuple[str, ...]:
        return tuple(n for t in self._terms for n in t.names())

    def columns(self, s: Signals) -> np.ndarray:
        blocks = [t.columns(s) for t in self._terms]
        if not blocks:
            return np.empty((len(s), 0))
        return np.concatenate(blocks, axis=1)

    def slices(self) -> list[tuple[Term, slice]]:
        """Each term with the slice of its columns in :meth:`columns`."""
        out, start = [], 0
        for t in self._terms:
            k = len(t.names())
            out.append((t, slice(start, start + k)))
            start += k
        return out

    def describe(self) -> str:
        return " + ".join(t.describe() for t in self._terms)

    def __repr__(self) -> str:
        return " + ".join(repr(t) for t in self._terms)
