"""Base parameters confounded with the friction columns: a constant weight is an offset.

The base rule (:func:`trajectories.robot.base_parameters`) regroups the standard parameters
on the rigid-body columns alone. The n-dof fit adds per-joint friction columns (FC sign(dq),
FV dq and the offset OFF, eq. 5-6), and a rigid base column can be a combination of them and
of the other base columns on every possible trajectory. The case met in practice is a
prismatic axis whose direction never changes with respect to gravity (the vertical axis of a
cylindrical or gantry robot): the force of its own link's mass M is M (ddq + g), the column
of Ia (ddq) plus g times the offset's column (1), so M, Ia and OFF cannot be separated by any
data -- payload runs included, whose known weight is a known force. The fit ended in
"parameters not identifiable on these data (cond 3e+300); the weakest direction involves
['OFF2', 'M2', 'Ia2', 'M3']", with no hint of why or what to do.

:func:`regroup_friction` finds such columns on random states (those of the base rule) and
regroups them, as the base rule does, into the columns they are combinations of: the
friction columns first, then the base columns that carry no gravity, then those that do
(column-pivoted QR in that order), so that the weight is the parameter regrouped -- e.g.
``Ia2R = Ia2 + M2`` and the fitted ``OFF2`` standing for ``OFF2 + 9.81*M2``. The returned
:class:`FrictionRegrouping` holds the reduced base (a :class:`RegroupedBase`, which
:class:`~ident.robot.estimate.RobotModel` takes as ``base=``), the friction regroupings by
name and one line saying what is confounded with what and what separates it (the rotor
inertias given, ``--known-rotor-inertia``, when that removes the dependence on this robot).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from trajectories.robot import BaseParameters, RobotRegressor, base_parameters
from trajectories.robot.base import (
    qr_rule,
    random_states,
    regroup_expression,
    regrouped_names,
)

from . import RobotIdentError

__all__ = ["FrictionRegrouping", "RegroupedBase", "regroup_friction", "physical_friction"]

#: Columns whose norm at rest (dq = ddq = 0) is below this, relative to the largest base
#: column, carry no gravity (they are placed before the gravity columns in the QR).
_STATIC_TOL = 1e-9
#: Random states at rest on which a column's gravity part is looked for.
_STATIC_STATES = 20
#: Regrouping coefficients below this (relative to the largest) are rounding: set to 0.
_ZERO_COEF = 1e-9


@dataclass(frozen=True, eq=False)
class RegroupedBase(BaseParameters):
    """Base parameters of the rigid body with some regrouped into friction columns too.

    Attributes
    ----------
    friction : dict
        Fitted friction parameter -> {standard parameter: coefficient}: the fitted value is
        the friction parameter plus these standard parameters times their coefficients
        (``{"OFF2": {"M2": 9.81}}``: the fitted OFF2 is OFF2 + 9.81 M2 [N]).
    friction_expressions : tuple of str
        The same as text, ``"OFF2 (fitted) = OFF2 + 9.81*M2"``.
    """

    friction: dict[str, dict[str, float]] = field(default_factory=dict)
    friction_expressions: tuple[str, ...] = ()


@dataclass(frozen=True)
class FrictionRegrouping:
    """What :func:`regroup_friction` found.

    Attributes
    ----------
    base : RegroupedBase
        The base without the regrouped parameters (``removed``), their columns folded into
        the kept ones (``beta``, ``expressions``).
    removed : tuple of str
        Base parameters of the rigid-body rule regrouped away (``("M2",)``).
    note : str
        One line: which parameters are confounded with which, why, and what separates them.
    paper : str
        One line: why the paper model is not fitted (its load tau_out, eq. 17, must carry the
        weight the offset absorbs) and what separates them.
    """

    base: RegroupedBase
    removed: tuple[str, ...]
    note: str
    paper: str


def _columns(reg: RobotRegressor, base: BaseParameters, seed: int, n: int
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Base columns (n k, p_b), friction columns (n k, 3 k) and the base columns' norm at
    rest relative to the largest base column, on ``n`` random states of the base rule."""
    q, dq, ddq = random_states(reg, None, n, seed)
    wb = base.reduce(reg.rigid(q, dq, ddq)).reshape(-1, base.p_b)
    wf = reg.friction(dq).reshape(-1, 3 * reg.k)
    qs = q[:_STATIC_STATES]  # a few states tell whether a column is zero at rest
    zero = np.zeros_like(qs)
    static = base.reduce(reg.rigid(qs, zero, zero)).reshape(-1, base.p_b)
    scale = float(np.linalg.norm(wb, axis=0).max()) or 1.0
    return wb, wf, np.linalg.norm(static, axis=0) / scale


def _dependent(reg: RobotRegressor, base: BaseParameters, seed: int
               ) -> tuple[list[str], np.ndarray, np.ndarray, list[int]] | None:
    """The QR of [friction | base without gravity | base with gravity] (module doc): the
    ordered names, its kept columns, beta, and the base indices regrouped; None when every
    base column is independent of the friction columns."""
    nf = 3 * reg.k
    n = max(60, 2 * (base.p_b + nf))  # k n rows for p_b + 3 k columns
    wb, wf, static = _columns(reg, base, seed, n)
    order = sorted(range(base.p_b), key=lambda i: (static[i] > _STATIC_TOL, i))
    names = list(reg.friction_names) + [base.names[i] for i in order]
    w = np.concatenate([wf, wb[:, order]], axis=1)
    kept, beta, _, _, zero = qr_rule(w, tuple(names), base.rtol)
    dep = [order[c - nf] for c in range(nf, nf + base.p_b) if c not in set(kept) and not zero[c]]
    if not dep:
        return None
    return names, kept, beta, dep


def regroup_friction(reg: RobotRegressor, base: BaseParameters | None = None, *,
                     seed: int = 0, joints: tuple[str, ...] | None = None
                     ) -> FrictionRegrouping | None:
    """Regroup the base parameters that the friction columns confound (module doc).

    Parameters
    ----------
    reg : RobotRegressor
        The fit's regressor (with ``known_rotor_inertia`` if the fit has it).
    base : BaseParameters or None
        The rigid-body base; default ``base_parameters(reg)``.
    seed : int
        Seed of the random states.
    joints : tuple of str or None
        Joint names for the note (default ``reg.joints``).

    Returns
    -------
    FrictionRegrouping or None
        None when no base column is a combination of friction columns and other base columns.
    """
    base = base_parameters(reg) if base is None else base
    if isinstance(base, RegroupedBase):
        return None
    found = _dependent(reg, base, seed)
    if found is None:
        return None
    names, kept, beta, dep = found
    nf = 3 * reg.k
    col = {n: i for i, n in enumerate(names)}
    keep_b = [i for i in range(base.p_b) if i not in dep]
    std = base.standard_names
    # chi_b(kept) += coef * chi_b(dep): the base rows in standard parameters
    new_beta = base.beta[keep_b].copy()
    fric: dict[str, np.ndarray] = {}
    for d in dep:
        coefs = beta[:, col[base.names[d]]]
        for r, c in enumerate(kept):
            coef = float(coefs[r])
            if abs(coef) < _ZERO_COEF * max(1.0, float(np.abs(coefs).max())):
                continue
            if c < nf:
                fname = names[c]
                fric[fname] = fric.get(fname, np.zeros(len(std))) + coef * base.beta[d]
            else:
                i = keep_b.index(base.names.index(names[c]))
                new_beta[i] += coef * base.beta[d]
    new_beta[np.abs(new_beta) < _ZERO_COEF] = 0.0
    columns = base.columns[keep_b]
    new_names, exprs = regrouped_names(std, columns, new_beta)
    friction: dict[str, dict[str, float]] = {}
    fexprs = []
    for fname, vec in fric.items():
        terms = {std[j]: float(v) for j, v in enumerate(vec) if abs(v) > _ZERO_COEF}
        friction[fname] = terms
        fexprs.append(regroup_expression(f"{fname} (fitted)", fname, list(terms.items())))
    removed = tuple(base.names[d] for d in dep)
    out = RegroupedBase(std, tuple(new_names), columns, new_beta, tuple(exprs),
                        base.unidentifiable, base.rtol, base.seed, base.n_samples,
                        friction, tuple(fexprs))
    note, paper = _note(reg, removed, out, joints or tuple(reg.joints), seed)
    return FrictionRegrouping(out, removed, note, paper)


def _separated_by_known_rotor_inertia(reg: RobotRegressor, seed: int) -> bool:
    """Whether the rotor inertias of the robot file, known, remove every dependence."""
    if np.any(reg.known_Ia > 0):
        return False  # they are known already
    known = RobotRegressor(reg.robot, known_rotor_inertia=True)
    if not np.any(known.known_Ia > 0):
        return False  # the robot file gives none
    return _dependent(known, base_parameters(known), seed) is None


def _note(reg: RobotRegressor, removed: tuple[str, ...], base: RegroupedBase,
          joints: tuple[str, ...], seed: int) -> tuple[str, str]:
    """Two lines: what is confounded with what, why, as what it is fitted and what separates
    it; and why the paper model is not fitted."""
    regrouped = [e for e in base.expressions
                 if set(removed) & set(re.split(r"[ *]+", e.split("=", 1)[1]))]
    partners = [e.split(" =", 1)[0].removesuffix("R") for e in regrouped] + list(base.friction)
    why = []
    for fname, terms in base.friction.items():
        number = int("".join(ch for ch in fname if ch.isdigit()) or -1)
        if number in reg.numbers:
            i = reg.numbers.index(number)
            axis = f"{'' if reg.revolute[i] else 'prismatic '}axis {joints[i]}"
        else:
            axis = fname
        if fname.startswith("OFF"):
            why.append(f"on the {axis} the weight of {', '.join(terms)} is a constant force, "
                       f"the column of {fname}")
        else:  # no robot met so far: said as it is
            why.append(f"on the {axis} {', '.join(terms)} act through the column of {fname}")
    because = "; ".join(why) or "a combination of the friction columns"
    known = _separated_by_known_rotor_inertia(reg, seed)
    how = ("to identify them separately give the rotor inertias (--known-rotor-inertia, "
           "[joints.drive] rotor_inertia of the robot file)" if known else
           "no data separate them")
    note = (f"{', '.join(removed)} confounded with {', '.join(partners)} on any data "
            f"({because}): fitted as {'; '.join([*regrouped, *base.friction_expressions])}; "
            f"{how}; payload runs do not separate them (a known payload's weight is a known "
            "force)" + ("" if known else ": the regrouped sums are what is identified"))
    paper = (f"paper model not fitted: its load tau_out (eq. 17) must carry the weight of "
             f"{', '.join(removed)}, confounded with {', '.join(base.friction)} ({because}); "
             + ("give the rotor inertias (--known-rotor-inertia) to fit it" if known else
                "no data separate them; fit the usual model"))
    return note, paper


def physical_friction(values: dict[str, float], standard: dict[str, float],
                      friction: dict[str, dict[str, float]] | None) -> dict[str, float]:
    """The friction parameters of ``values`` with the regrouped standard parameters taken out
    (``OFF2 = fitted OFF2 - 9.81 M2`` for ``friction = {"OFF2": {"M2": 9.81}}``), given the
    standard values ``standard`` (e.g. a consistent estimate's).

    Raises
    ------
    RobotIdentError
        A standard parameter of a regrouping missing from ``standard``.
    """
    out = dict(values)
    for fname, terms in (friction or {}).items():
        if fname not in out:
            continue
        try:
            out[fname] = float(out[fname]) - sum(c * float(standard[s]) for s, c in terms.items())
        except KeyError as e:
            raise RobotIdentError(f"friction regrouping of {fname}: standard parameter "
                                  f"{e.args[0]} missing") from None
    return out
