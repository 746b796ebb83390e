"""The library-search step of the refinement loop (glue between :mod:`ident.refine`,
:mod:`ident.interactions`, :mod:`ident.library_search` and :mod:`ident.describe`).

At each refinement step, on the current fit:

1. :func:`~ident.interactions.diagnose_interactions` tests the residual against the single
   variables, their products with sign(q̇) and sign(P), and pairs (Holm-corrected);
2. the library (one-variable bases x modifiers, two-variable tensor bases) is searched by
   grouped forward selection (one group: the refinement adds one effect per step) scored by
   blocked cross-validation;
3. the selected group is named (:func:`~ident.describe.describe_group`): when a named form
   explains as much, the candidate is that form's term (fewer parameters, 2σ on physical
   parameters); otherwise a :class:`~ident.library_search.LibraryTerm` described in words.

The candidate then competes with the named effects and the generic bases of
:mod:`ident.refine`, where every candidate must also lower the held-out error
(:meth:`LibraryStep.heldout`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from .describe import Description, describe_group
from .effects import Effect, Prediction
from .interactions import (
    InteractionDiagnosis,
    continuous_values,
    diagnose_interactions,
    sign_values,
)
from .library_search import (
    LIBRARY_VARIABLES,
    FoldGram,
    Group,
    LibraryTerm,
    SearchResult,
    build_library,
    search,
    time_folds,
)
from .signals import Signals

#: Samples used by the library search and the held-out scores (regular stride above it).
MAX_SAMPLES = 8000
#: Groups selected ahead (forward) before the one most needed is offered to the loop.
LOOKAHEAD = 2
#: Up to this many continuous variables every pair gets a tensor basis; beyond, only the
#: pairs the interaction diagnosis found significant.
MAX_ALL_PAIRS = 6


@dataclass
class LibraryStep:
    """Outcome of the library search at one refinement step.

    Attributes
    ----------
    interactions : InteractionDiagnosis
        Every binned test tried on the residual.
    result : SearchResult
        The grouped forward selection (``selected`` empty when no group lowered the held-out
        error enough; ``tried`` lists every structure with its held-out error and reason).
    description : Description or None
        What the selected group is.
    candidate : Effect or None
        The term to offer: the named form's term, or the library basis.
    generic : bool
        True when the candidate is a library basis (no named form).
    n_hyper : int
        Scanned hyper-parameters of the candidate (named forms: 1).
    """

    interactions: InteractionDiagnosis
    result: SearchResult | None
    description: Description | None
    candidate: Effect | None
    generic: bool
    n_hyper: int
    _fg: FoldGram = field(repr=False)
    _stride: int = 1
    #: the group offered to the loop (None when nothing was selected)
    group: Group | None = None

    @property
    def heldout_before(self) -> float:
        """Held-out relative error of the current model (blocked CV)."""
        return self.result.cv_path[0] if self.result is not None else self._fg.cv()[0]

    @property
    def stride(self) -> int:
        """Stride of the samples the held-out errors are computed on."""
        return self._stride

    def heldout(self, C: np.ndarray, strided: bool = False) -> float:
        """Held-out relative error of the current model plus columns ``C`` (n, k) — or
        (n / stride, k) already taken every ``stride`` samples — on the same folds."""
        C = np.asarray(C, dtype=float)
        if C.ndim == 1:
            C = C[:, None]
        return self._fg.cv(C if strided else C[:: self._stride])[0]

    def tried_json(self) -> list[dict]:
        """Every structure scored, selected or not, with its held-out error and reason; the
        one offered to the loop says so."""
        out = []
        for t in self.result.tried if self.result else []:
            js = t.to_json()
            simplified = self.result is not None and self.group is not None and not any(
                g is self.group for g in self.result.selected)
            if t.group is self.group:
                js["reason"] = ("selected; offered to the refinement" if t.selected else
                                "offered to the refinement: a selected pair in its variable "
                                "does not lower its held-out error enough (simpler structure)")
            elif t.selected and simplified and len(t.group.variables) == 2:
                js["reason"] = ("selected, not offered: a one-variable structure in one of its "
                                "variables is as good on held-out data")
            elif t.selected:
                js["reason"] = ("selected ahead (forward look), not offered: the offered "
                                "structure is needed more")
            out.append(js)
        return out


def library_step(
    y: np.ndarray,
    W: np.ndarray,
    s: Signals,
    residual: np.ndarray,
    *,
    tau_out: Prediction | None,
    reference: Mapping[str, float] | None = None,
    others: Mapping[str, np.ndarray] | None = None,
    min_gain: float = 0.05,
    alpha: float = 1e-3,
    max_samples: int = MAX_SAMPLES,
    load_dependent: bool = False,
) -> LibraryStep:
    """Run the interaction diagnosis and the library search on the current fit.

    Parameters
    ----------
    y : ndarray, shape (n,)
        Measured torque of the design.
    W : ndarray, shape (n, p)
        Current regressor (kept columns).
    s : Signals
        The design's decimated samples.
    residual : ndarray, shape (n,)
        Current residual.
    tau_out : Prediction, optional
        Load predictor of the current fit.
    reference : mapping, optional
        Current coefficients (``F_C`` scales dry-friction descriptions).
    others : mapping, optional
        Extra continuous variables (other joints' states, :attr:`Signals.extra
        <ident.signals.Signals.extra>`), aligned with the samples; diagnosed and searched
        like the others, a group using them becomes a
        :class:`~ident.library_search.LibraryTerm` that reads them from the signals by name.
    min_gain : float
        Relative decrease of the held-out error a group must bring.
    alpha : float
        Family-wise level of the interaction diagnosis.
    load_dependent : bool
        The model already has eq. 24's load-dependent dry friction
        (:func:`~ident.describe.describe_group`'s).
    """
    n = y.shape[0]
    stride = max(1, math.ceil(n / max_samples))
    idiag = diagnose_interactions(residual, s, tau_out=tau_out, others=others, alpha=alpha)
    values = continuous_values(s, tau_out, others)
    values.update(sign_values(s, tau_out))
    folds = time_folds(s.experiment)
    Ws = W[::stride]
    # the rank test of the groups' columns needs few samples
    ps = max(1, math.ceil(n / 3000))
    sub = {k: v[::ps] for k, v in values.items()}
    Wp = W[::ps]
    norms = np.linalg.norm(Wp, axis=0)
    Q, _ = np.linalg.qr(Wp / np.where(norms > 0, norms, 1.0))
    variables = list(LIBRARY_VARIABLES) + list(others or {})
    pairs = None
    if len(variables) > MAX_ALL_PAIRS:
        # many variables (a robot joint with the other joints' states): only the pairs the
        # interaction diagnosis found significant get a tensor basis
        pairs = sorted({t.variables[:2] for t in idiag.significant
                        if t.kind in ("pair", "signed_pair")
                        and all(v in variables for v in t.variables[:2])})
    groups = build_library(sub, variables, Q=Q, pairs=pairs)
    res = search(y, W, values, groups, folds, max_groups=LOOKAHEAD, min_gain=min_gain,
                 max_samples=max_samples)
    fg = FoldGram(Ws, y[::stride], folds[::stride])
    desc = cand = None
    generic, n_hyper = True, 0
    pick = _most_needed(res, fg, values, stride)
    if pick is not None:
        g, c = res.selected[pick], res.coef[pick]
        simple = _simplest(res, g, min_gain)
        simple = _plainer(res, simple or g, min_gain) or simple
        if simple is not None:
            g = simple
            X = np.column_stack((W, g.columns(values)))
            c = np.linalg.lstsq(X, y, rcond=None)[0][W.shape[1]:]
        desc = describe_group(g, c, y, W, values, reference=reference, tau_out=tau_out,
                              folds=folds, min_gain=min_gain, revolute=bool(s.revolute),
                              load_dependent=load_dependent)
        if desc.term is not None:
            cand, generic, n_hyper = desc.term, False, len(desc.term.hyper_names)
        elif all(v in LIBRARY_VARIABLES or v in (others or {}) for v in g.variables):
            cand = LibraryTerm(g, tau_out)
    return LibraryStep(idiag, res, desc, cand, generic, n_hyper, fg, stride,
                       None if pick is None else g)


def _simplest(res: SearchResult, g: Group, min_gain: float) -> Group | None:
    """A one-variable group, in one of the variables of the selected pair ``g`` and with its
    modifier, scored in the same round, whose held-out error the pair does not lower by
    ``min_gain`` (the rule :func:`~ident.describe.describe_group` applies to named forms):
    the simpler structure is offered instead (a pair contains each variable's own basis, and
    at a few tenths of a percent of held-out error it wins by its extra columns' luck)."""
    if len(g.variables) != 2:
        return None
    mine = next((t for t in res.tried if t.group is g), None)
    if mine is None:
        return None
    best = None
    for t in res.tried:
        h = t.group
        if (t.round == mine.round and len(h.variables) == 1 and h.variables[0] in g.variables
                and h.modifier == g.modifier and mine.cv_after >= t.cv_after * (1 - min_gain)
                and (best is None or t.cv_after < best.cv_after)):
            best = t
    return None if best is None else best.group


#: A modifier and the plainer one offered in its place when it does as well: the model
#: quadrant sign(τ̂_out q̇) is sign(q̇) times the sign of the load, a function of the
#: position where gravity dominates, so "x quadrant" and "x direction" can fit alike.
PLAINER_MODIFIER = {"quadrant": "direction"}


def _plainer(res: SearchResult, g: Group, min_gain: float) -> Group | None:
    """The group in the same variables with the plainer modifier
    (:data:`PLAINER_MODIFIER`), scored in the same round, whose held-out error ``g`` does not
    lower by ``min_gain``; None when there is none."""
    plain = PLAINER_MODIFIER.get(g.modifier)
    mine = next((t for t in res.tried if t.group is g), None)
    if plain is None or mine is None:
        return None
    best = None
    for t in res.tried:
        h = t.group
        if (t.round == mine.round and h.variables == g.variables and h.modifier == plain
                and mine.cv_after >= t.cv_after * (1 - min_gain)
                and (best is None or t.cv_after < best.cv_after)):
            best = t
    return None if best is None else best.group


def _most_needed(res: SearchResult, fg: FoldGram, values: Mapping[str, np.ndarray],
                 stride: int) -> int | None:
    """Index of the selected group whose removal from the selected set raises the held-out
    error most (forward selection, then a backward look: with several effects at once the
    first group taken can be a stand-in for the others)."""
    if not res.selected:
        return None
    if len(res.selected) == 1:
        return 0
    sub = {k: np.asarray(v)[::stride] for k, v in values.items()}
    cols = [g.columns(sub) for g in res.selected]
    worst = []
    for i in range(len(cols)):
        rest = [c for j, c in enumerate(cols) if j != i]
        worst.append(fg.cv(np.column_stack(rest))[0])
    return int(np.argmax(worst))
