"""The Python API's q_s is the paper model's Stribeck velocity (eq. 29): ``jointid fit --q-s``
with ``--model usual`` is refused, and the API ignored the same setting without a word (a
stranger's grid over q_s with the usual model got identical fits). A warning names it now,
before any file is read (not an error: a scikit-learn grid over both models stays valid);
the default q_s, and any q_s with the paper model, pass without it."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from ident import DataError
from ident.api import JointModel
from ident.api_robot import RobotFit
from ident.robot import RobotIdentError

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("q_s", [0.05, "scan"])
def test_joint_model_warns_of_q_s_with_the_usual_model(tmp_path, q_s):
    with pytest.warns(UserWarning, match=r"JointModel: q_s=.* ignored.* model='usual' has none"):
        with pytest.raises(DataError, match="absent.csv"):
            JointModel(model="usual", q_s=q_s).fit(tmp_path / "absent.csv")


def test_robot_fit_warns_of_q_s_with_the_usual_model(tmp_path):
    est = RobotFit(ROOT / "examples" / "robots" / "arm3.toml", model="usual", q_s=0.05)
    with pytest.warns(UserWarning, match=r"RobotFit: q_s=0.05 is ignored"):
        with pytest.raises(RobotIdentError, match="absent.csv"):
            est.fit(tmp_path / "absent.csv")


@pytest.mark.parametrize("model", ["paper", "both"])
def test_q_s_with_the_paper_model_reaches_the_data(tmp_path, model):
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        with pytest.raises(DataError, match="absent.csv"):
            JointModel(model=model, q_s=0.05).fit(tmp_path / "absent.csv")
        with pytest.raises(DataError, match="absent.csv"):
            JointModel(model="usual").fit(tmp_path / "absent.csv")
