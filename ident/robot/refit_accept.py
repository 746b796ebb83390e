"""Which found terms the n-dof model keeps: the refit judged on its held-out error.

:func:`ident.robot.refit.refit_robot` refits every term the per-joint refinements found
inside the n-dof model. Each term was accepted on its own joint's residual, with the other
joints' parameters held; inside the n-dof model it shares the base parameters with every
joint, and with few rows per parameter it can pull them away from what the other joints
need (the KUKA recording A, docs/refinement.md section 8.8: a 6-column library basis found
on A2's 71 rows raised the whole robot's held-out error 5.37 -> 5.73 % and A1's 8.28 ->
11.15 %). :func:`accept_refit` keeps a term only if it does not worsen the error on data
the fit was not made on -- the refit's own held-out error (:meth:`ident.robot.refit._System.
heldout`: the same folds for every refit, leave one run out or blocked folds of one run).
Two comparisons, each by the same conditions:

* **the refit against the n-dof fit** (the refit's ``heldout`` before/after), and
* **each term against the refit without it** (with two terms or more: a term that explains
  nothing can ride along with one that explains much, the whole robot's error falling
  anyway);

the conditions:

* **the whole robot**: the held-out error of every joint together (``all``) must not rise;
* **each joint j**: its held-out error may rise by at most ``1 / sqrt(2 m_j)`` of itself,
  m_j its rows. That is the relative standard deviation of an RMS figure over m_j white
  residuals (sum of squares ~ sigma^2 chi^2(m_j), relative std sqrt(2/m_j), halved by the
  square root): a rise within it is not evidence that the joint got worse (70 rows: 8.5 %;
  7000 rows: 0.85 %). Residuals correlated along the trajectory would widen it; it is not
  widened, so the rule leans towards refusing.

When a comparison fails, terms are dropped backward: each kept term is removed in turn and
the rest refitted; the removal that leaves the fewest failed conditions against the n-dof
fit, then the lowest whole-robot held-out error, is made; until both comparisons pass or no
term is left (then the n-dof model is the original fit: the refit without terms). Each
refused term is recorded with its reason in one line and the held-out figures that decided
it (``refused`` of the record, docs/robot-data.md). The validation files are not used to
choose (they stay the user's independent check); the rule reads no threshold tuned to a data
set.

Cost: with T found terms, T + 1 refits when every term is kept (one when T = 1), at most
T (T + 1) / 2 + 1 in all (the KUKA case: 2).
Pure numerics (no file access).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from .. import IdentError
from ..terms import Term
from .refit import RobotRefit, refit_robot

__all__ = ["accept_refit", "heldout_check", "joint_tolerance", "ALL_REFUSED"]

#: The record's note when every found term was refused.
ALL_REFUSED = ("every found term was refused (it raised the held-out error): the n-dof model "
               "is the original fit")


def joint_tolerance(rows: int) -> float:
    """Relative rise of a joint's held-out error within its noise: ``1 / sqrt(2 rows)``, the
    relative standard deviation of an RMS figure over ``rows`` white residuals (module doc);
    ``inf`` without rows."""
    return 1.0 / math.sqrt(2.0 * rows) if rows > 0 else math.inf


def heldout_check(rf: RobotRefit, before: dict[str, float] | None = None) -> list[str]:
    """The conditions of the module doc that ``rf`` fails, one short text each (empty: the
    refit is accepted), e.g. ``"all 5.404 -> 5.734 % (must not rise)"``,
    ``"A1 8.637 -> 11.149 % (+29.1 % > 8.1 %)"``: its held-out error (``after``) against
    ``before`` (default its own ``before``, the n-dof fit; or the held-out error of a refit
    with one term less). A joint or the whole robot whose "before" is not finite is not
    judged; a finite "before" and a non-finite "after" fails."""
    before = rf.heldout["before"] if before is None else before
    after = rf.heldout["after"]
    fails = []

    def bad(b: float, a: float, tol: float) -> bool:
        if not math.isfinite(b):
            return False
        return not math.isfinite(a) or a > b * (1.0 + tol)

    if bad(before["all"], after["all"], 0.0):
        fails.append(f"all {100 * before['all']:.3f} -> {100 * after['all']:.3f} % "
                     "(must not rise)")
    for j, m in rf.n_rows.items():
        tol = joint_tolerance(m)
        b, a = before[j], after[j]
        if bad(b, a, tol):
            fails.append(f"{j} {100 * b:.3f} -> {100 * a:.3f} % "
                         f"(+{100 * (a / b - 1):.1f} % > {100 * tol:.1f} %)")
    return fails


def _term_label(joint: str, term: Term) -> str:
    n = len(term.names())
    return f"{joint}: {term.effect} ({n} column{'s' if n != 1 else ''})"


def accept_refit(
    model: Any,
    signals: Any,
    terms: Sequence[tuple[int, Term]],
    *,
    progress: Any = None,
    **kwargs: Any,
) -> RobotRefit:
    """The n-dof refit of the found ``terms`` that the held-out check accepts (module doc).

    Parameters
    ----------
    model, signals, terms
        As :func:`ident.robot.refit.refit_robot`.
    progress : callable, optional
        Receives one line per refused term.
    **kwargs
        Passed to every :func:`~ident.robot.refit.refit_robot` call (``prediction``,
        ``keep``, ``revolute``, ``validation``, ...).

    Returns
    -------
    RobotRefit
        The refit with the accepted terms (every term when the check passes at once; none:
        the refit without terms, the n-dof fit); its ``refused`` lists the refused terms in
        the order they were dropped, each ``{"joint", "effect", "names", "reason",
        "heldout_rel_error": {"before", "with", "without"}}`` (the n-dof fit; the refit
        with the terms kept when it was dropped; the refit once it was dropped), and
        ``acceptance`` the rule and each joint's tolerance.

    Raises
    ------
    RobotIdentError
        As :func:`~ident.robot.refit.refit_robot` on the first refit (with every term).
    """
    say = progress or (lambda _m: None)

    def fit(ts: list[tuple[int, Term]]) -> RobotRefit | None:
        try:
            return refit_robot(model, signals, ts, **kwargs)
        except IdentError:  # a subset that cannot be refitted: not chosen
            return None

    kept = [(int(j), t) for j, t in terms]
    rf = refit_robot(model, signals, kept, **kwargs)
    refused: list[dict[str, Any]] = []
    while kept:
        # the refit against the n-dof fit, then each term against the refit without it
        # (one term: the n-dof fit itself, already judged)
        fails = heldout_check(rf)
        without = [fit(kept[:i] + kept[i + 1:]) if len(kept) > 1 else None
                   for i in range(len(kept))]
        own = [[] if w is None else heldout_check(rf, w.heldout["after"]) for w in without]
        if not fails and not any(own):
            break
        if len(kept) == 1:
            without = [fit([])]
        # drop the term whose removal helps most: fewest failed conditions left against the
        # n-dof fit, then the lowest whole-robot held-out error
        cands = [(len(heldout_check(w)), _finite(w.heldout["after"]["all"]), i)
                 for i, w in enumerate(without) if w is not None]
        if not cands:  # no subset refits: keep none
            kept, rf = [], refit_robot(model, signals, [], **kwargs)
            break
        i = min(cands)[2]
        j, t = kept[i]
        w = without[i]
        why = []
        if fails:
            why.append("the refit with it against the n-dof fit: " + "; ".join(fails))
        if own[i]:
            why.append("with it against without it: " + "; ".join(own[i]))
        if not why:
            why.append("another term's check failed and removing this one helps most")
        line = (f"{_term_label(model.joints_[j], t)} refused, held-out error "
                + " | ".join(why) + f" | without it all {100 * w.heldout['after']['all']:.3f} %")
        refused.append({"joint": model.joints_[j], "effect": t.effect,
                        "names": list(t.names()), "reason": line,
                        "heldout_rel_error": {"before": dict(rf.heldout["before"]),
                                              "with": dict(rf.heldout["after"]),
                                              "without": dict(w.heldout["after"])}})
        say(line)
        kept = kept[:i] + kept[i + 1:]
        rf = w
    rf.refused = refused
    rf.acceptance = {
        "rule": "a found term is kept only if the whole robot's held-out error does not rise "
                "and no joint's rises by more than 1/sqrt(2 rows) of itself, the refit "
                "against the n-dof fit and each term against the refit without it",
        "tolerance": {j: joint_tolerance(m) for j, m in rf.n_rows.items()},
        "all_refused": bool(refused) and not kept,
    }
    return rf


def _finite(v: float) -> float:
    return v if math.isfinite(v) else math.inf
