"""Does the paper model's estimate hold its sigma against the sign check's row selection? A
truth-free check of the robot fit (docs/robot-identification.md, "The default cut-off on logs
slower than 1 kHz", the 250 Hz shoulder).

The sign check leaves out the rows where sign(tau_j) differs from sign(tau_out_hat_j) of a
first usual fit (:func:`ident.robot.design.sign_checked`). If the model and its sigma were
right, the estimate on all the rows and the one on the checked rows would differ by less than
a few sigma of the checked fit (the rows of one are a subset of the other's: the variance of
the difference is at most the subset's, Hausman's argument). On the simulated arm3 at 250 Hz
they differ by up to 60 sigma (the shoulder's a_m2, a_g2), where the checked estimate is 59
sigma from the truth and the unchecked one within a few: a shift far beyond the sigma says
the sigma does not cover the choice of rows, whichever of the two is nearer the truth.

The second fit is the paper model with the same settings on the rows before the check; its
estimate is compared, parameter by parameter, with the reported (checked, pruned) fit's,
in units of the reported honest sigma: z = (unchecked - checked) / sigma_checked. Pruned
parameters (held at 0 in the reported fit) are not compared.

A joint is a 1-dof robot: :func:`ident.fitting.fit_models` applies the same rule to the
single-joint paper model (:meth:`ident.one_joint.OneJointProblem.unchecked_fit`, the same q_s,
estimator, quadrants and elimination on the rows before the check; z against eq. 15's std of
the record, ``FitReport.sign_check_shift``; the parameters eliminated in either fit are not
compared).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

#: A parameter that moves by more than this many of its reported sigma when the sign check's
#: rows are kept names the paper model's sigma as not covering the selection (conservative:
#: under a right model the shift's own sigma is at most the reported one).
SHIFT_Z = 4.0


def selection_shift(reported: Mapping[str, Mapping[str, Any]],
                    unchecked: Any) -> dict[str, float]:
    """z = (unchecked value - reported value) / reported std per parameter.

    Parameters
    ----------
    reported : mapping
        The reported fit's ``parameters`` record: name -> ``value``, ``std`` (and
        ``pruned``): the robot record's (:func:`ident.robot.uncertainty.parameter_records`,
        the honest std) or the single-joint record's (:func:`ident.results.parameters_json`,
        eq. 15's std; the eliminated parameters are not in it).
    unchecked : RobotModel or mapping
        The same model fitted on the rows before the sign check: a fitted model
        (``names_``, ``coef_`` arrays) or its values by name (the single-joint
        ``IdentModel.coef_``).

    Returns
    -------
    dict
        Parameter name -> z, for the parameters both fits have, not pruned, with a
        positive finite std.
    """
    if isinstance(unchecked, Mapping):
        other = {str(n): float(v) for n, v in unchecked.items()}
    else:
        other = dict(zip(unchecked.names_, np.asarray(unchecked.coef_, dtype=float),
                         strict=True))
    out = {}
    for name, rec in reported.items():
        std = rec.get("std")
        if rec.get("pruned") or name not in other or not std or not np.isfinite(std):
            continue
        out[name] = float((other[name] - rec["value"]) / std)
    return out


def shift_note(z: Mapping[str, float]) -> str | None:
    """The fit's one-line warning when a parameter moved by more than :data:`SHIFT_Z`
    (None otherwise)."""
    big = sorted((n for n, v in z.items() if abs(v) > SHIFT_Z), key=lambda n: -abs(z[n]))
    if not big:
        return None
    top = ", ".join(f"{n} {z[n]:+.0f}" for n in big[:3])
    return (f"paper model: {len(big)} parameter(s) move beyond {SHIFT_Z:g} sigma when the "
            f"sign check's rows are kept ({top} sigma): its stated sigma does not cover the "
            "choice of rows, read it as a lower bound (docs/robot-identification.md, 'The "
            "sign-check shift'); the record's sign_check_shift has every z")
