"""The model-quadrant passes' one rule (``ident.quadrant_band``) is what both fits read: the
n-dof fit (``RobotModel``, ``QuadrantStore``) and the single joint's (``fit_models``). The
figures of each fit are in tests/test_band_stop.py, tests/test_robot_quadrants.py and
tests/test_friction_dominated.py; here the rule's own arithmetic, and that no fit keeps a
constant of its own."""

from __future__ import annotations

import numpy as np

import ident.fitting as fitting
import ident.robot.estimate as estimate
from ident import quadrant_band as qb
from ident.robot.estimate import RobotModel


def test_one_set_of_constants():
    assert fitting.REQUADRANT_PASSES == qb.MAX_PASSES
    assert fitting.QUADRANT_TOL is qb.QUADRANT_TOL
    assert estimate.QUADRANT_TOL is qb.QUADRANT_TOL and estimate.THETA_TOL is qb.THETA_TOL
    assert estimate.BAND_LEAVE is qb.BAND_LEAVE
    assert RobotModel(None, "paper").max_passes == qb.MAX_PASSES  # type: ignore[arg-type]


def test_band_hysteresis_keeps_an_edge_row_out_until_it_leaves_the_wider_edge():
    h = 2.0
    # one row's |load| over five decisions: enters (1.9 < h), stays out between h and 1.5 h,
    # returns at 1.5 h, enters again below h
    loads = np.array([[2.5], [1.9], [2.6], [2.99], [3.0], [1.0]])
    states = [qb.band_out(loads[: i + 1], h)[0][0] for i in range(len(loads))]
    assert states == [False, True, True, True, False, True]
    out, prev = qb.band_out(loads[:4], h)
    assert out[0] and prev[0]
    # without hysteresis (leave 1) the row would cycle with the load
    plain = [qb.band_out(loads[: i + 1], h, leave=1.0)[0][0] for i in range(len(loads))]
    assert plain == [False, True, False, False, False, True]
    # the store's distance to the edge where the row's state changes
    edge = qb.band_edge(np.array([2.6, 2.6]), np.array([True, False]), h)
    np.testing.assert_allclose(edge, [3.0 - 2.6, 2.6 - 2.0])


def test_stop_rule():
    assert qb.settled(2, 20_000, 5.0)  # 2 <= 1e-4 x 20 000
    assert not qb.settled(3, 20_000, 0.1)
    assert qb.settled(300, 20_000, 0.099)
    why = qb.unsettled_reason(300, 20_000, 0.5, 8)
    assert "max_passes=8" in why and "300 of 20000" in why
    rec = qb.QuadrantPasses(1)
    assert not rec.converged and rec.redecisions == 0 and "max_passes=1" in rec.reason
    rec = qb.QuadrantPasses(3)
    assert rec.converged and rec.redecisions == 2
    assert not rec.record(500, 1000, 1.0) and not rec.converged
    assert rec.record(0, 1000, 1.0) and rec.converged and rec.changes == [500, 0]
