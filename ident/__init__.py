"""Identification: loading, preprocessing, composable regressor terms, least squares,
residual diagnosis and refinement (Hamon, Gautier & Garrec, eq. 10-16 and 30-44).

Numerical modules touch no files and no bus; file access lives in :mod:`ident.loaders`
and :mod:`ident.report` only.
Exception tree: every error raised on purpose derives from :class:`IdentError`.
"""


class IdentError(Exception):
    """Root of every error raised on purpose by :mod:`ident`."""


class DataError(IdentError, ValueError):
    """Input data are unusable (missing column, NaN, non-monotonic time, too few samples)."""


class IdentifiabilityError(IdentError):
    """The regressor is rank-deficient; the message says which parameters cannot be separated."""


class OutputLeakError(IdentError, TypeError):
    """A candidate term, variable or basis read the measured torque (the output it is fitted
    to): refinement candidates see :meth:`ident.signals.Signals.states` only."""
