"""A run log with a damaged chunk: ``jointid fit``'s loader keeps the longest stretch of
consecutive cycles and never interpolates across the lost ones (real runner log, real MCAP)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from damaged_logs import damage_chunk
from test_daq_run import small_campaign

from daq.protocol.reader import read_run
from daq.runtime.runner import run_campaign
from ident.loaders import ResamplingWarning, _longest_true_run, load_experiment, lost_cycle_breaks
from sim_drivers.plant_config import default_plant


def test_longest_stretch_never_spans_a_break():
    m = np.ones(10, bool)
    m[2] = False
    breaks = np.zeros(9, bool)
    breaks[5] = True  # sample 6 does not follow sample 5
    assert _longest_true_run(m) == slice(3, 10)
    assert _longest_true_run(m, breaks) == slice(6, 10)
    assert _longest_true_run(np.zeros(4, bool), np.zeros(3, bool)) == slice(0, 0)
    assert np.array_equal(lost_cycle_breaks(np.array([0, 1, 2, 5, 6])), [0, 0, 1, 0])


@pytest.fixture(scope="module")
def damaged_log(tmp_path_factory):
    out = tmp_path_factory.mktemp("lost")
    c = small_campaign(n_payloads=1, periods=2, freq=1.0, amplitude=0.1)
    r = run_campaign(c, out_dir=out, simulate=default_plant(), yes=True)
    assert r.ok, r.reason
    path = r.runs[0].path
    return path, damage_chunk(path, out / "bad_payload0.mcap", at=1 / 3, min_chunks=4)


def test_fit_loader_keeps_consecutive_cycles_only(damaged_log):
    good, bad = damaged_log
    with pytest.warns(RuntimeWarning, match="damaged"):
        run = read_run(bad)
    (first, last), = run.lost_cycles
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        exp = load_experiment(bad)
    msgs = [str(w.message) for w in rec]
    assert not [w for w in rec if issubclass(w.category, ResamplingWarning)], msgs
    assert any("lost cycles (never interpolated across)" in m for m in msgs), msgs
    dt = np.diff(exp.t)
    assert np.ptp(dt) < 1e-9 * max(1.0, float(np.max(dt)))  # one uniform stretch
    # the stretch kept lies wholly before or wholly after the lost cycles
    assert exp.t.size < load_experiment(good).t.size
    before, after = first, int(run.cycle[-1]) - last
    assert exp.t.size <= max(before, after)
