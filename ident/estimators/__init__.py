"""Estimators as objects, shared by every model (issue 24, item 3).

A new estimator is one module here with a subclass of :class:`Estimator` and one row in
:data:`ESTIMATORS`; the CLI's choices (``jointid fit --robot --method``) and
``RobotModel.method`` come from that table.

Modules: :mod:`~ident.estimators.base` (the contract, :class:`Solution`, the rank rule
``RCOND``; ``Estimator.rank_drops``: on W^T W, and for IV on the projected regressor P_Z W),
:mod:`~ident.estimators.ls` (IDIM-LS), :mod:`~ident.estimators.wls` (IDIM-WLS, per-group
weights), :mod:`~ident.estimators.iv` (IDIM-IV).
"""

from __future__ import annotations

from .. import DataError
from .base import (
    DEPENDENT_PREFIX,
    PARTNER_TOL,
    RCOND,
    WEAK_PREFIX,
    ZERO_COLUMN,
    Estimator,
    RankDeficientError,
    Solution,
    dependent_columns,
    dependent_reason,
    instrumented_gram,
    rank_rule,
    weak_instruments,
    weak_reason,
)
from .iv import IV
from .ls import LS
from .wls import WLS

__all__ = ["DEPENDENT_PREFIX", "ESTIMATORS", "PARTNER_TOL", "RCOND", "WEAK_PREFIX", "ZERO_COLUMN",
           "Estimator", "IV", "LS", "RankDeficientError", "Solution", "WLS",
           "dependent_columns", "dependent_reason", "get_estimator", "instrumented_gram",
           "rank_rule", "weak_instruments", "weak_reason"]

#: name -> class: the registered estimators (the CLI choices, in this order).
ESTIMATORS: dict[str, type[Estimator]] = {cls.name: cls for cls in (LS, WLS, IV)}


def get_estimator(name: str) -> Estimator:
    """The estimator registered under ``name``.

    Raises
    ------
    DataError
        Unknown name (the message lists the registered ones).
    """
    try:
        return ESTIMATORS[name]()
    except (KeyError, TypeError):
        raise DataError(f"estimator {name!r}: expected one of "
                        f"{', '.join(repr(k) for k in ESTIMATORS)}") from None
