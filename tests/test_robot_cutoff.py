"""The chain's default cut-off over several axes (ident.chain.axes_cutoff): the largest
choose_cutoff over the axes that found a motion bandwidth; an axis whose velocity spectrum is
noise up to the Nyquist frequency (its choice at the upper bound 0.4 f_s) is left out, with a
warning naming it, unless every axis is. On the simulated UR10 demo campaign one wrist set
200 Hz for all six joints and the paper model's c_m, c_g of the vertical shoulder_pan axis
came out 15 sigma off (docs/robot-identification.md)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from ident.chain import axes_cutoff, choose_cutoff
from ident.robot.design import resolve_design
from ident.robot.loaders import RawRobotRun

DT = 0.002  # [s]
STEP = 1.5e-5  # encoder step [rad]


def _axes(n_noise: int, n_smooth: int = 1, seed: int = 1) -> np.ndarray:
    """(n, k) [rad]: smooth quantised motions (0.5 and 1.3 Hz), then random walks of
    1e-4 rad per sample (velocity noise up to the Nyquist frequency)."""
    t = np.arange(0.0, 20.0, DT)
    rng = np.random.default_rng(seed)
    cols = [np.round((0.5 * np.sin(2 * np.pi * 0.5 * t + i) + 0.2 * np.sin(2 * np.pi * 1.3 * t))
                     / STEP) * STEP for i in range(n_smooth)]
    cols += [np.cumsum(rng.standard_normal(t.size)) * 1e-4 for _ in range(n_noise)]
    return np.stack(cols, axis=1)


def _run(q: np.ndarray) -> RawRobotRun:
    t = np.arange(q.shape[0]) * DT
    return RawRobotRun("run.csv", t, q, np.zeros_like(q))


def test_a_noise_axis_does_not_set_the_robot_cut_off():
    q = _axes(n_noise=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        own = [choose_cutoff(q[:, j], DT) for j in range(2)]
    assert own[1] == pytest.approx(0.4 / DT)  # the noise axis alone: the upper bound
    assert own[0] < 0.4 / DT
    with pytest.warns(UserWarning, match=r"run\.csv: axis 2: .*left out of the chain's "
                                         r"cut-off"):
        s = resolve_design([_run(q)])
    assert s.cutoff_hz == pytest.approx(own[0])  # the motion's, not 0.4 f_s (old rule)
    assert s.decimation == round(1.0 / DT / own[0])


def test_every_axis_noise_keeps_the_upper_bound():
    q = _axes(n_noise=2, n_smooth=0)
    with pytest.warns(UserWarning, match="upper bound 0.4 f_s"):
        assert axes_cutoff(q, DT) == pytest.approx(0.4 / DT)


def test_one_axis_is_choose_cutoff_and_a_given_cut_off_is_kept():
    q = _axes(n_noise=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert axes_cutoff(q, DT) == choose_cutoff(q[:, 0], DT)
    q2 = _axes(n_noise=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a given cut-off: no choice, no warning
        assert resolve_design([_run(q2)], cutoff_hz=40.0).cutoff_hz == 40.0
