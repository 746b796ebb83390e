"""The one rule of the paper model's model-quadrant passes, from one joint to n: the quadrant
band's hysteresis and when the passes stop (issue 24).

With model quadrants the quadrant of a row is sign(tau_out_hat dq) (eq. 26-28 with the model's
load torque), so it moves with the estimate; the fits decide it, fit, and decide it again with
the new estimate. Both fits -- the n-dof one (:class:`ident.robot.estimate.RobotModel`, its
bilinear paper form; :class:`ident.robot.quadrants.QuadrantStore` between its data passes) and
the single joint's (:func:`ident.fitting.fit_models` where the sign check was skipped,
:class:`ident.one_joint.OneJointProblem`) -- read this module:

* **The band.** Rows whose |tau_out_hat| is below the band h [N m] are left out (their
  quadrant is uncertain; a wrong one costs the dry friction's jump c_m - c_g, eq. 30). h is
  decided once, by the first load model (the usual fit's), and kept over the passes. A row
  enters the band where |tau_out_hat| < h and returns to the fit only where it reaches
  :data:`BAND_LEAVE` x h, its state carried over the load models that decided the passes, in
  order (:func:`band_out`): without the hysteresis rows at the band's edge entered and left it
  at every pass as the estimate moved by a fraction of its sigma. The band and its hysteresis
  are this package's, not the paper's (its quadrants are sign(P) on every row outside the
  stiction area).
* **The stop.** The passes stop, settled, once at most :data:`QUADRANT_TOL` of the rows moved
  at the last re-decision -- changed quadrant, or entered or left the band (a row leaving the
  fit changes the estimate as a flip does; with a band rows cross it long before they flip)
  -- or once no parameter moved by :data:`THETA_TOL` of its standard deviation since the
  previous re-decision (:func:`settled`). Stopped by the cap (:data:`MAX_PASSES` decisions,
  the first load model's included) otherwise: the fit is not converged and says why
  (:func:`unsettled_reason`, :class:`QuadrantPasses`).

Figures: docs/robot-identification.md, "Quadrants" (the 3-dof arm, KUKA) and "The single-joint
fit is this one" (the friction-dominated joint).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

__all__ = ["BAND_LEAVE", "MAX_PASSES", "QUADRANT_TOL", "THETA_TOL", "QuadrantPasses",
           "band_edge", "band_out", "band_step", "never_redecided", "settled",
           "unsettled_reason"]

#: Fraction of the rows that may still move when the passes stop settled: change quadrant, or
#: enter or leave the quadrant band; such rows have tau_out ~ 0 (or ~ the band's edge), where
#: the quadrant hardly matters.
QUADRANT_TOL = 1e-4

#: The passes also stop when no parameter moved by more than this fraction of its standard
#: deviation (eq. 15) since the previous pass: the rows still moving then barely change the
#: estimate.
THETA_TOL = 0.1

#: A row in the quadrant band (|tau_out_hat| < h) returns to the fit only where its
#: |tau_out_hat| reaches this multiple of the band (the band's hysteresis): a row at the
#: band's edge no longer enters and leaves it at every pass as the estimate moves by a
#: fraction of its sigma (the 3-dof arm cycled so, docs/robot-identification.md "Quadrants").
#: Not the paper's: its quadrants are sign(P) with no band (eq. 26-28).
BAND_LEAVE = 1.5

#: Quadrant decisions at most (the first load model's included): ``RobotModel(max_passes=)``'s
#: default and the single-joint fit's (``ident.fitting.REQUADRANT_PASSES``).
MAX_PASSES = 8


def band_step(load: np.ndarray, out: np.ndarray | None, band: float,
              leave: float = BAND_LEAVE) -> np.ndarray:
    """The rows the band leaves out at a new decision: |``load``| [N m] < ``band``, or left
    out at the previous decision (``out``, bool, the shape of ``load``; None: none) and still
    below ``leave`` x ``band``."""
    a = np.abs(load)
    if out is None:
        return a < band
    return (a < band) | (out & (a < leave * band))


def band_out(loads: Iterable[np.ndarray], band: float,
             leave: float = BAND_LEAVE) -> tuple[np.ndarray, np.ndarray]:
    """The rows the band leaves out after the decisions by ``loads`` (tau_out_hat [N m] of
    each load model that decided a pass, in order; each of one shape, or a (passes, m) array)
    with the hysteresis (:func:`band_step`): that mask at the last load and at the one before
    (the previous decision's; the same with one load), bool each."""
    out = prev = None
    for x in loads:
        prev, out = out, band_step(x, out, band, leave)
    if out is None:
        raise ValueError("band_out: no load model")
    return out, out if prev is None else prev


def band_edge(load: np.ndarray, out: np.ndarray, band: float,
              leave: float = BAND_LEAVE) -> np.ndarray:
    """How far [N m] each row's |``load``| is from the edge where its band state changes:
    ``band`` for a row in the fit (it enters the band there, and flips only beyond),
    ``leave`` x ``band`` for a row left out (``out``: it returns there)."""
    return np.abs(np.abs(load) - np.where(out, leave * band, band))


def settled(changed: int, rows: int, step: float) -> bool:
    """Whether the passes stop settled after a re-decision that moved ``changed`` of ``rows``
    rows (into another quadrant, or across the band) and a refit whose parameters moved by
    ``step`` of their standard deviation at most (inf while a direction is unexcited)."""
    return changed <= QUADRANT_TOL * rows or step < THETA_TOL


def unsettled_reason(changed: int, rows: int, step: float, max_passes: int) -> str:
    """One line saying why the passes stopped at the cap ``max_passes`` unsettled
    (:func:`settled` False); "" when settled."""
    if settled(changed, rows, step):
        return ""
    return (f"the quadrant passes stopped at max_passes={int(max_passes)} "
            f"with {changed} of {rows} rows still changing quadrant or crossing "
            f"the quadrant band at the last one (settled: at most "
            f"{QUADRANT_TOL:g} of them) and the parameters moving "
            f"{step:.3g} sigma (settled: below {THETA_TOL:g})")


def never_redecided(max_passes: int) -> str:
    """The reason when the cap allowed no re-decision (``max_passes`` <= 1)."""
    return (f"max_passes={int(max_passes)}: the quadrants of the usual fit's theta were never "
            "re-decided with the paper fit's")


class QuadrantPasses:
    """The record of one fit's quadrant passes under the rule (module doc).

    Parameters
    ----------
    max_passes : int
        Decisions at most, the first load model's included.

    Attributes
    ----------
    changes : list of int
        Rows that moved at each re-decision (another quadrant, or across the band).
    steps : list of float
        The largest parameter change at each re-decision, in standard deviations.
    reason : str
        Why the passes are not settled ("" when they are).
    """

    def __init__(self, max_passes: int = MAX_PASSES) -> None:
        self.max_passes = int(max_passes)
        self.changes: list[int] = []
        self.steps: list[float] = []
        self.reason = never_redecided(self.max_passes) if self.max_passes <= 1 else ""

    @property
    def redecisions(self) -> int:
        """Re-decisions allowed (the cap less the first decision)."""
        return max(self.max_passes - 1, 0)

    def record(self, changed: int, rows: int, step: float) -> bool:
        """Record a re-decision and its refit; True when the passes stop settled."""
        self.changes.append(int(changed))
        self.steps.append(float(step))
        self.reason = unsettled_reason(changed, rows, step, self.max_passes)
        return not self.reason

    @property
    def converged(self) -> bool:
        """The passes settled (or none was asked)."""
        return not self.reason
