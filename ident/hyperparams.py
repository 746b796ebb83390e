"""The scikit-learn hyper-parameter protocol shared by the estimators of :mod:`ident.api`
(:class:`~ident.api.JointModel`, :class:`~ident.api_robot.RobotFit`).

The hyper-parameters are the keyword parameters of ``__init__`` (stored there as given, so
scikit-learn's ``clone`` and grid search work); ``set_params`` also takes the deprecated
spellings of :mod:`ident.vocab` (``qs`` -> ``q_s``).
"""

from __future__ import annotations

import inspect
from typing import Any

from . import DataError
from .vocab import renamed_keywords

__all__ = ["HyperParameters"]


class HyperParameters:
    """Mixin: ``get_params``/``set_params`` from the signature of ``__init__``."""

    @classmethod
    def _get_param_names(cls) -> list[str]:
        """The hyper-parameters: the keyword parameters of ``__init__`` (not ``**``)."""
        sig = inspect.signature(cls.__init__)
        return [n for n, p in sig.parameters.items() if n != "self" and p.kind != p.VAR_KEYWORD]

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The hyper-parameters, as given to ``__init__`` (scikit-learn convention).

        Parameters
        ----------
        deep : bool
            Accepted for scikit-learn; no hyper-parameter is itself an estimator, so
            ``deep`` changes nothing.
        """
        del deep
        return {k: getattr(self, k) for k in self._get_param_names()}

    def set_params(self, **params: Any) -> Any:
        """Set hyper-parameters by name (scikit-learn convention); returns ``self``.

        Values are stored as given and checked by ``fit``, like the constructor's. A fitted
        estimator keeps its fitted attributes until the next ``fit``.

        Raises
        ------
        DataError
            A name that is not a hyper-parameter (the message lists them).
        """
        owner = f"{type(self).__name__}.set_params"
        valid = self._get_param_names()
        params = renamed_keywords(owner, params, strict=False)
        for k, v in params.items():
            if k not in valid:
                raise DataError(f"{owner}: unknown hyper-parameter {k!r} "
                                f"(expected one of {', '.join(valid)})")
            setattr(self, k, v)
        return self
