"""``full_rate`` of ``jointid fit --robot``'s chain (:func:`ident.cli_robot.fit_robot`,
``RobotFit(full_rate=True)``; ``run`` reads ``args.full_rate``): the paper model's quadrant
and E products formed at full rate (``RobotModel(full_rate=True)``, docs/refinement.md
section 8.9), opt-in.

Data: tests/test_drag_chain.py's simulated 3-dof arm (seed 11, three payload runs of 10 s as
robot CSVs, load-dependent friction, the true q_s per joint). Asserted: by default nothing
changes (``"full_rate"`` False, the model's ``full_rate_paper_`` False); with the option the
paper model is the one ``RobotModel(full_rate=True)`` fits on the same signals (the same
coefficients), the record says it applied, the usual model is not affected; on the states
chain, which has no full-rate source, it falls back to the decimated products with a note.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
from robot_campaigns import ARM3, write_arm_csv

from daq.app.cli import main
from ident.api_robot import RobotFit
from ident.cli_robot import fit_files
from ident.robot.estimate import RobotModel
from tests.test_qs_joints_refine import QS_DISTINCT, drag_runs
from trajectories.robot import load_robot

KW = dict(q_s=list(QS_DISTINCT), prune=False, feasibility=False, sigma_blocks=0)


@functools.cache
def _files(root: Path) -> list[Path]:
    return [write_arm_csv(r, root / f"p{i}.csv") for i, r in enumerate(drag_runs(11))]


def test_full_rate_reaches_the_paper_model_only_when_asked(tmp_path):
    files = _files(tmp_path)
    robot = load_robot(ARM3)
    base = fit_files(robot, files, model="both", **KW)
    full = fit_files(robot, files, model="both", full_rate=True, **KW)
    assert base["full_rate"] is False and full["full_rate"] is True
    assert "full_rate_applied" not in base["models"]["paper"]
    assert full["models"]["paper"]["full_rate_applied"] is True
    b, f = base["_estimators"], full["_estimators"]
    assert not b["paper"].full_rate_paper_ and f["paper"].full_rate_paper_
    # the usual model is not affected
    assert not f["usual"].full_rate
    np.testing.assert_array_equal(f["usual"].coef_, b["usual"].coef_)
    # the paper model is RobotModel(full_rate=True) on the same signals
    ref = RobotModel(**{**b["paper"].get_params(), "full_rate": True}).fit(
        base["_identification"])
    assert ref.full_rate_paper_
    np.testing.assert_allclose(f["paper"].coef_, ref.coef_, rtol=1e-9, atol=1e-12)
    assert not np.allclose(f["paper"].coef_, b["paper"].coef_, rtol=1e-6)


def test_full_rate_on_the_states_chain_falls_back_with_a_note(tmp_path):
    out = fit_files(load_robot(ARM3), _files(tmp_path), model="paper", chain="states",
                    full_rate=True, **KW)
    assert out["models"]["paper"]["full_rate_applied"] is False
    assert not out["_estimators"]["paper"].full_rate_paper_
    assert any(n.startswith("--full-rate:") and "decimated columns" in n for n in out["notes"])


def test_robot_fit_keyword():
    est = RobotFit(ARM3, full_rate=True)
    assert est.get_params()["full_rate"] is True
    assert RobotFit(ARM3).get_params()["full_rate"] is False
    assert "full_rate=True" in repr(est)


def test_full_rate_flag_of_jointid_fit(tmp_path, capfd):
    """``jointid fit --robot ... --full-rate`` reaches the paper model; without ``--robot``
    it is refused in one line."""
    files = _files(tmp_path)
    out = tmp_path / "fit.json"
    code = main(["fit", "--robot", str(ARM3), *map(str, files), "--model", "paper",
                 "--q-s", "0.05", "--no-prune", "--no-consistency",
                 "--sigma-blocks", "0", "--full-rate", "--json", str(out)])
    err = capfd.readouterr().err
    assert code == 0, err
    rec = json.loads(out.read_text())
    assert rec["full_rate"] is True and rec["models"]["paper"]["full_rate_applied"] is True
    code = main(["fit", str(files[0]), "--full-rate"])
    err = capfd.readouterr().err
    assert code != 0 and "--full-rate: applies to --robot fits only" in err
    assert len(err.strip().splitlines()) == 1, err
