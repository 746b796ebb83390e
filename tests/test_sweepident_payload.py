"""``--payload mass`` with a validation file whose payload is none of the fit's: one line
naming the file, before fitting (found by the identification sweep: the estimator's error
came after the fit, "payload of 5.0 kg: not one of the fitted payloads [4.0, 9.0] kg", naming
neither the file nor the option)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ident import DataError
from ident.cli_robot import fit_robot
from ident.loaders import RawRobotRun
from trajectories.robot import RobotPayloadData, load_robot

ARM3 = Path(__file__).resolve().parents[1] / "examples" / "robots" / "arm3.toml"
DT = 0.002  # [s]


def _run(name: str, mass: float, seed: int) -> RawRobotRun:
    """Sines within arm3's limits; the torque is noise (the check reads the payloads only)."""
    t = np.arange(0.0, 8.0, DT)
    rng = np.random.default_rng(seed)
    centre, amp = np.array([0.0, -1.4, 1.4]), np.array([1.0, 0.6, 0.8])
    q = centre + amp * np.sin(2 * np.pi * np.outer(t, [0.3, 0.41, 0.53]) + rng.uniform(0, 6, 3))
    pay = RobotPayloadData(mass, np.array([0.0, 0.0, 0.05])) if mass else RobotPayloadData()
    return RawRobotRun(name, t, q, rng.standard_normal(q.shape), payload=pay)


def test_payload_mass_refuses_a_validation_payload_the_fit_does_not_identify():
    robot = load_robot(ARM3)
    runs = [_run("p0.csv", 0.0, 0), _run("p1.csv", 4.0, 1), _run("p2.csv", 9.0, 2)]
    with pytest.raises(DataError, match=r"^val\.csv: payload of 5 kg: with --payload mass a "
                                        r"validation file must carry one of the payloads the "
                                        r"fit identifies \(4, 9 kg\) or none$"):
        fit_robot(robot, runs, [_run("val.csv", 5.0, 3)], models=("usual",), payload="mass",
                  feasibility=False, sigma_blocks=0)
    # a validation payload the fit identifies (or none) is taken
    out = fit_robot(robot, runs, [_run("v4.csv", 4.0, 4), _run("v0.csv", 0.0, 5)],
                    models=("usual",), payload="mass", feasibility=False, sigma_blocks=0)
    assert "validation_rel_error" in out["models"]["usual"]
