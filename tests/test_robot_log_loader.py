"""The robot's MCAP loader reads a log once for all its axes
(:func:`daq.protocol.reader.read_runs`, called by :func:`ident.loaders.read_file`), and reads
what one scan per axis read (:func:`daq.protocol.reader.read_run`), on a real run log of the
simulated 3-dof arm, closed and cut as a killed writer leaves it.

Before: one scan of the file per axis (the truncation warning said once per scan, merged
afterwards); on a 6.6 MB log of the arm, read_file took 494 ms, 245 ms after (min of 7).
"""

from __future__ import annotations

import warnings
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from robot_campaigns import arm3_log

from daq.protocol.reader import RunArrays, read_metadata, read_run, read_runs
from ident import DataError
from ident.loaders import read_file

TRUNCATED = "truncated run log"


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    """A closed run log of the simulated arm (one multi-sine period) and its first 70 %."""
    out = tmp_path_factory.mktemp("arm_log")
    closed = arm3_log(out, seed=2)
    cut = out / "cut.mcap"
    cut.write_bytes(closed.read_bytes()[: int(0.7 * closed.stat().st_size)])
    return {"closed": closed, "truncated": cut}


def _same(a: RunArrays, b: RunArrays) -> None:
    for f in fields(RunArrays):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True), f.name
        elif isinstance(x, float) and np.isnan(x):
            assert np.isnan(y), f.name
        else:
            assert x == y, f.name


@pytest.mark.parametrize("kind", ["closed", "truncated"])
def test_one_scan_reads_what_one_scan_per_axis_read(logs, kind):
    path = logs[kind]
    with warnings.catch_warnings(record=True) as log:
        warnings.simplefilter("always")
        every = read_runs(path)  # every axis of the log
        chosen = read_runs(path, [2, 0])
    said = [str(w.message) for w in log if TRUNCATED in str(w.message)]
    assert len(said) == (2 if kind == "truncated" else 0), said  # once per read_runs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        one_by_one = [read_run(path, axis=i) for i in range(3)]
    assert len(every) == 3
    for a, b in zip(every, one_by_one, strict=True):
        _same(a, b)
    _same(chosen[0], one_by_one[2])
    _same(chosen[1], one_by_one[0])
    assert every[0].metadata is not every[1].metadata  # each run its own, as read_run's


@pytest.mark.parametrize("kind", ["closed", "truncated"])
def test_robot_read_file_stacks_the_axes(logs, kind):
    path = logs[kind]
    joints = tuple(read_metadata(logs["closed"])[f"drive{i}"]["joint"] for i in range(3))
    with warnings.catch_warnings(record=True) as log:
        warnings.simplefilter("always")
        run = read_file(path, joints)
    said = [str(w.message) for w in log if TRUNCATED in str(w.message)]
    assert len(said) == (1 if kind == "truncated" else 0), said
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its truncation, counted above for the robot's
        axis0 = read_file(path, None, axis=0)  # the single-joint reading of axis 0
    assert run.q.shape[1] == 3
    np.testing.assert_array_equal(run.t, axis0.t)
    np.testing.assert_array_equal(run.q[:, :1], axis0.q)
    with pytest.raises(DataError, match=r"the log has 3 axes \(/joint/0\.\.2/state\), the "
                                        r"robot moves 2 joints"):
        read_file(path, joints[:2])
