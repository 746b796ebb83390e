"""``jointid fit --robot --validate``: a validation file sampled at another rate than the
identification files is refused in one line naming it (found by the identification sweep:
a 500 Hz validation file of 1 kHz fits was processed with the decimation, trim and guard
resolved in samples on the 1 kHz files, in silence; identification files at two rates were
already refused)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ident import IdentError
from ident.cli_robot import fit_robot
from ident.loaders import RawRobotRun
from trajectories.robot import load_robot

ARM3 = Path(__file__).resolve().parents[1] / "examples" / "robots" / "arm3.toml"


def _run(name: str, dt: float, seed: int) -> RawRobotRun:
    """Sines within arm3's limits sampled every ``dt`` [s]; noise as torque."""
    t = np.arange(0.0, 8.0, dt)
    rng = np.random.default_rng(seed)
    q = np.array([0.0, -1.4, 1.4]) + np.array([1.0, 0.6, 0.8]) * np.sin(
        2 * np.pi * np.outer(t, [0.3, 0.41, 0.53]) + rng.uniform(0, 6, 3))
    return RawRobotRun(name, t, q, rng.standard_normal(q.shape))


def test_validation_file_at_another_rate_is_refused():
    robot = load_robot(ARM3)
    runs = [_run("p0.csv", 0.001, 0), _run("p1.csv", 0.001, 1)]
    with pytest.raises(IdentError, match=r"^v500\.csv: sampling period 0\.002 s differs from "
                                         r"p0\.csv \(0\.001 s\)$"):
        fit_robot(robot, runs, [_run("v500.csv", 0.002, 2)], models=("usual",),
                  feasibility=False, sigma_blocks=0)
    # at the same rate it is taken
    out = fit_robot(robot, runs, [_run("v1k.csv", 0.001, 3)], models=("usual",),
                    feasibility=False, sigma_blocks=0)
    assert "validation_rel_error" in out["models"]["usual"]
