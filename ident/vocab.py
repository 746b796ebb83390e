"""One vocabulary for the single-joint and the n-dof fits (issue 24): the model and estimator
names, and the deprecated spellings still accepted on input, in this one table.

Outputs (CLI text, JSON, API attributes, reports) use the canonical names only; the entry
points (``jointid fit``, :class:`ident.api.JointModel`, :class:`ident.api_robot.RobotFit`,
``jointid report`` / ``export-model`` reading an old JSON record) map the aliases here.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Mapping
from typing import Any

from . import DataError

#: Friction models: ``usual`` (eq. 38-39) and ``paper`` (load- and velocity-dependent dry
#: friction, eq. 42-43).
MODEL_NAMES = ("usual", "paper")

#: Deprecated model names accepted on input -> canonical name.
MODEL_ALIASES = {"new": "paper"}

#: Estimators: least squares (eq. 12), weighted per joint, instrumental variables (IDIM-IV).
METHOD_NAMES = ("ls", "wls", "iv")

#: Deprecated estimator names accepted on input -> canonical name.
METHOD_ALIASES = {"ols": "ls"}

#: Deprecated JSON keys of a fit record -> canonical key (read by :func:`upgrade_record`).
KEY_ALIASES = {"qs": "q_s", "qs_scan": "q_s_scan"}

#: Deprecated Python keywords -> canonical keyword (``JointModel``, ``RobotFit``,
#: ``RobotModel``, ``fit_models``; their ``set_params`` too).
KEYWORD_ALIASES = {"qs": "q_s"}


#: The words ``q_s`` takes instead of a velocity (``jointid fit --q-s``, ``JointModel`` and
#: ``RobotFit(q_s=...)``): ``scan``, one q_s for every joint chosen by the paper fit's error
#: (:func:`ident.qs_scan.scan_qs`); ``scan-joints``, one q_s per joint
#: (:func:`ident.qs_scan.scan_qs_joints`; a single joint, a 1-dof robot, scans as ``scan``).
QS_WORDS = ("scan", "scan-joints")


def qs_value(value: Any, *, what: str = "q_s") -> float | str:
    """``q_s`` as given on input: a finite velocity > 0 [rad/s or m/s] (number or numeric
    string), or one of :data:`QS_WORDS` (case and surrounding blanks ignored). The one rule
    of ``jointid fit --q-s`` (:func:`ident.cli.parse_qs`), :class:`ident.api_robot.RobotFit`
    and :func:`ident.fitting.fit_models`.

    Parameters
    ----------
    value : float, str
        The given q_s.
    what : str
        The option's name in the message (``"q_s"``, ``"--q-s"``).

    Returns
    -------
    float or str
        The velocity [rad/s], or the word in its canonical spelling.

    Raises
    ------
    DataError
        Anything else, one line listing the accepted words.
    """
    words = ", ".join(repr(w) for w in QS_WORDS[:-1]) + f" or {QS_WORDS[-1]!r}"
    if isinstance(value, str):
        word = value.strip().lower()
        if word in QS_WORDS:
            return word
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise DataError(f"{what} {value!r}: expected a number [rad/s], {words}") from None
    if not (math.isfinite(v) and v > 0):
        raise DataError(f"{what} {value!r}: expected a number > 0 [rad/s], {words}")
    return v


def renamed_keywords(owner: str, kwargs: Mapping[str, Any], *, strict: bool = True
                     ) -> dict[str, Any]:
    """``kwargs`` with the deprecated keywords renamed (``qs`` -> ``q_s``), each with a
    :class:`DeprecationWarning`.

    Parameters
    ----------
    owner : str
        The class or function, for the messages (``"JointModel"``).
    kwargs : mapping
        Keyword arguments not in the signature (``strict``), or all of them (``set_params``:
        the others are passed through unchanged).

    Raises
    ------
    TypeError
        With ``strict``, a keyword that is no deprecated alias (as Python raises for an
        unknown keyword).
    """
    out: dict[str, Any] = {}
    for key, value in kwargs.items():
        new = KEYWORD_ALIASES.get(key)
        if new is None:
            if strict:
                raise TypeError(f"{owner}: unexpected keyword argument {key!r}")
            out[key] = value
            continue
        warnings.warn(f"{owner}: keyword {key!r} is deprecated, use {new!r}",
                      DeprecationWarning, stacklevel=3)
        out[new] = value
    return out


def model_name(name: str, *, extra: tuple[str, ...] = ()) -> str:
    """The canonical model name of ``name`` (``"new"`` -> ``"paper"``).

    Parameters
    ----------
    name : str
        A model name or a deprecated alias.
    extra : tuple of str
        Further accepted values (e.g. ``"both"``), returned unchanged.

    Raises
    ------
    DataError
        ``name`` is neither a model, an alias nor one of ``extra``.
    """
    name = MODEL_ALIASES.get(name, name)
    if name not in MODEL_NAMES + extra:
        expected = ", ".join(repr(n) for n in MODEL_NAMES + extra)
        raise DataError(f"model {name!r}: expected one of {expected}")
    return name


def warn_unused_qs(owner: str, model: str, q_s: Any, default: float) -> None:
    """The Python API's ``q_s`` is the paper model's (eq. 29): set away from its default with
    ``model="usual"`` (no q_s-dependent term) it is ignored, and a warning says so (as
    scikit-learn does for a hyper-parameter the chosen variant does not use, so a parameter
    grid over both models stays valid; ``jointid fit --q-s`` with ``--model usual`` is
    refused). ``model`` resolved by :func:`model_name`."""
    if model == "usual" and not (isinstance(q_s, (int, float)) and float(q_s) == default):
        warnings.warn(f"{owner}: q_s={q_s!r} is ignored: it is the paper model's Stribeck "
                      "velocity (eq. 29) and model='usual' has none", UserWarning, stacklevel=3)


def refined_model(fitted: Iterable[str]) -> str:
    """The fitted model a refinement refines when none is named, one rule for the single
    joint (:class:`ident.api.JointModel`, ``jointid fit --refine``) and the robot
    (:func:`ident.cli_robot.refine_robot`, ``jointid fit --robot --refine``): the paper model
    when it was fitted, else the first model fitted.

    The paper model first: the usual model's residual still holds the load-dependent dry
    friction (eq. 24), which a refinement would spend its first steps on, and whose
    time x load-quadrant remainder biases the other effects it finds (on the demo's logs
    as a 1-dof robot: the ripple 5-7 sigma off refining the usual model, within 1 sigma
    refining the paper model).

    Raises
    ------
    DataError
        No model was fitted.
    """
    names = [model_name(n) for n in fitted]
    if not names:
        raise DataError("refine: no model was fitted")
    return "paper" if "paper" in names else names[0]


def method_name(name: str, *, extra: tuple[str, ...] = (), what: str = "method") -> str:
    """The canonical estimator name of ``name`` (``"ols"`` -> ``"ls"``); see :func:`model_name`.

    ``what`` names the option in the error (``"method"``, ``"estimator"``, ``"--method"``).
    """
    name = METHOD_ALIASES.get(name, name)
    if name not in METHOD_NAMES + extra:
        expected = ", ".join(repr(n) for n in METHOD_NAMES + extra)
        raise DataError(f"{what} {name!r}: expected one of {expected}")
    return name


def upgrade_record(rec: dict[str, Any]) -> dict[str, Any]:
    """A fit JSON record with the deprecated spellings of older records renamed.

    ``models.new`` -> ``models.paper``, ``"new"`` as a model value -> ``"paper"``, ``qs`` ->
    ``q_s``, ``estimator``/``method`` ``"ols"`` -> ``"ls"``, at any depth; a record already
    in the current spelling comes back equal. The input is not modified.
    """

    def walk(x: Any, key: str = "") -> Any:
        if isinstance(x, list):
            return [walk(v, key) for v in x]
        if isinstance(x, str) and key in ("model", "models"):
            return MODEL_ALIASES.get(x, x)
        if isinstance(x, str) and key in ("estimator", "method"):
            return METHOD_ALIASES.get(x, x)
        if not isinstance(x, dict):
            return x
        out: dict[str, Any] = {}
        for k, v in x.items():
            k2 = MODEL_ALIASES.get(k, KEY_ALIASES.get(k, k))
            out[k2 if k2 == k or k2 not in x else k] = walk(v, k2)
        return out

    return walk(rec)
