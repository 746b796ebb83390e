"""One vocabulary (issue 24): model ``paper`` (``new`` deprecated), estimators ``ls|wls|iv``
(``ols`` deprecated), ``q_s`` in JSON; the deprecated spellings are mapped in ident.vocab and
older JSON records read as current ones; E = exp(-|dq|/q_s) is one function, and so are the
quadrant weights P+, P- (eq. 27-28)."""

from __future__ import annotations

import numpy as np
import pytest

from ident import DataError
from ident.vocab import method_name, model_name, upgrade_record
from trajectories.friction import DEFAULT_Q_S, quadrant_weights, stribeck_exp


def test_aliases_map_to_the_one_name_and_unknown_names_are_refused():
    assert model_name("new") == model_name("paper") == "paper"
    assert model_name("usual") == "usual"
    assert model_name("both", extra=("both",)) == "both"
    assert method_name("ols") == method_name("ls") == "ls"
    assert [method_name(m) for m in ("wls", "iv")] == ["wls", "iv"]
    with pytest.raises(DataError, match=r"^model 'old': expected one of 'usual', 'paper'$"):
        model_name("old")
    with pytest.raises(DataError, match=r"^--method 'gls': expected one of 'ls', 'wls', 'iv'$"):
        method_name("gls", what="--method")
    with pytest.raises(DataError):
        model_name("both")  # only where the caller allows it


def test_an_old_fit_record_reads_as_a_current_one():
    old = {
        "format": "jointid-fit/1", "qs": 0.03,
        "qs_scan": [{"qs": 0.02, "rel_error": 0.1}],
        "models": {"usual": {"estimator": "ols", "rel_error": 0.2},
                   "new": {"estimator": "iv", "qs": 0.03, "parameters": {"a_m_J": 1.0}}},
        "table_iv": {"with_payloads": {"usual": 0.2, "new": 0.1}},
        "refinement": {"model": "new", "steps": []},
        "figures": {"new": [{"file": "a.png"}]},
    }
    new = upgrade_record(old)
    assert new == {
        "format": "jointid-fit/1", "q_s": 0.03,
        "q_s_scan": [{"q_s": 0.02, "rel_error": 0.1}],
        "models": {"usual": {"estimator": "ls", "rel_error": 0.2},
                   "paper": {"estimator": "iv", "q_s": 0.03, "parameters": {"a_m_J": 1.0}}},
        "table_iv": {"with_payloads": {"usual": 0.2, "paper": 0.1}},
        "refinement": {"model": "paper", "steps": []},
        "figures": {"paper": [{"file": "a.png"}]},
    }
    assert old["models"].keys() == {"usual", "new"}  # the input is left as it was
    assert upgrade_record(new) == new  # a current record is unchanged


def test_stribeck_exp_is_the_expression_it_replaced():
    rng = np.random.default_rng(3)
    dq = rng.normal(0.0, 0.5, 1000)
    assert np.array_equal(stribeck_exp(dq, DEFAULT_Q_S), np.exp(-np.abs(dq) / 0.03))
    qs = np.array([0.02, 0.05])
    assert np.array_equal(stribeck_exp(dq[:, None][:10], qs), np.exp(-np.abs(dq[:10, None]) / qs))
    assert stribeck_exp(0.0, 0.03) == 1.0


def test_quadrant_weights_are_the_expressions_they_replaced():
    """P+ = (1 + sign P)/2 and P- = (1 - sign P)/2 bit for bit, P- = 1 - P+ (the form the n-dof
    code wrote), 1/2 each at P = 0, the same from P or from sign(P)."""
    rng = np.random.default_rng(4)
    power = rng.normal(0.0, 1.0, 1000)
    power[:7] = 0.0
    pp, pm = quadrant_weights(power)
    assert np.array_equal(pp, 0.5 * (1.0 + np.sign(power)))
    assert np.array_equal(pm, 0.5 * (1.0 - np.sign(power)))
    assert np.array_equal(pm, 1.0 - pp)
    assert np.all(pp[:7] == 0.5) and np.all(pm[:7] == 0.5)
    assert np.array_equal(pp[7:], (power[7:] > 0).astype(float))  # 1 in the motor quadrant
    for a, b in zip(quadrant_weights(np.sign(power)), (pp, pm), strict=True):
        assert np.array_equal(a, b)
    assert np.isnan(quadrant_weights(np.nan)).all()


def test_the_older_keyword_qs_is_renamed_with_a_warning_everywhere_and_typos_still_fail():
    from ident.api import JointModel, RobotFit
    from ident.robot.estimate import RobotModel

    for make in (lambda **kw: JointModel("paper", **kw), lambda **kw: RobotFit("r.toml", **kw),
                 lambda **kw: RobotModel(None, "paper", **kw)):
        with pytest.warns(DeprecationWarning, match="'qs' is deprecated, use 'q_s'"):
            est = make(qs=0.05)
        assert est.q_s == 0.05 and "qs" not in est.get_params()
        with pytest.raises(TypeError, match="unexpected keyword argument 'q_ss'"):
            make(q_ss=0.05)
    for est in (JointModel(), RobotFit("r.toml")):
        with pytest.warns(DeprecationWarning):
            assert est.set_params(qs=0.07).q_s == 0.07
