"""A robot's default cut-off: each axis's bound warning names the file and the axis (found by
the identification sweep: `jointid fit --robot kuka_kr300_r2500.toml A.mat` printed three
lines "cut-off 12.5 Hz is the lower bound 0.05 f_s (...)" naming neither)."""

from __future__ import annotations

import warnings

import numpy as np

from ident.robot.design import resolve_design
from ident.robot.loaders import RawRobotRun

DT = 0.004  # [s], 250 Hz as the KUKA recordings


def test_lower_bound_warnings_name_the_file_and_the_axis():
    t = np.arange(0.0, 10.0, DT)
    # two slow axes of different bandwidths: each one's rule is below half of f_s/20
    q = np.stack([0.4 * np.sin(2 * np.pi * 0.1 * t), 0.3 * np.sin(2 * np.pi * 0.2 * t + 1.0)],
                 axis=1)
    run = RawRobotRun("A.mat", t, q, np.zeros_like(q))
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        s = resolve_design([run])
    assert s.cutoff_hz == 12.5  # f_s / 20
    lower = [str(w.message) for w in got if "lower bound" in str(w.message)]
    assert len(lower) == 2, lower
    assert lower[0].startswith("A.mat: axis 1: cut-off 12.5 Hz is the lower bound"), lower
    assert lower[1].startswith("A.mat: axis 2: cut-off 12.5 Hz is the lower bound"), lower
