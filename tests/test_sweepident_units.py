"""``jointid fit --robot`` prints dq_min in the moving joints' unit (found by the
identification sweep: the EMPS axis as a one-joint prismatic robot file printed "dq_min 0
rad/s, 2478 samples x 1 joints")."""

from __future__ import annotations

import numpy as np

from ident.cli_robot import fit_robot, format_report
from ident.loaders import RawRobotRun
from trajectories.robot import load_robot

AXIS = """
[robot]
name = "axis"
[[joints]]
name = "x"
type = "prismatic"
alpha = 1.5707963267948966
"""


def test_prismatic_robot_prints_m_per_s(tmp_path):
    path = tmp_path / "axis.toml"
    path.write_text(AXIS)
    robot = load_robot(path)
    dt = 0.001  # [s]
    t = np.arange(0.0, 6.0, dt)
    q = 0.1 * np.sin(2 * np.pi * 0.5 * t) + 0.03 * np.sin(2 * np.pi * 1.7 * t)  # [m]
    dq = np.gradient(q, dt)
    ddq = np.gradient(dq, dt)
    rng = np.random.default_rng(0)
    force = 95.0 * ddq + 200.0 * dq + 20.0 * np.sign(dq) + rng.normal(0.0, 0.5, t.size)  # [N]
    run = RawRobotRun("axis.csv", t, q[:, None], force[:, None])
    out = fit_robot(robot, [run], models=("usual",), feasibility=False, sigma_blocks=0)
    line = format_report(out).splitlines()[1]
    assert " m/s, " in line and "rad/s" not in line, line
    assert "samples x 1 joint;" in line, line
    assert out["models"]["usual"]["parameters"]["FV1"]["value"] > 0  # the fit ran
