"""A random-walk host clock on the real EMPS data (``../shared``; skipped without it): every
period of the stamps errs by s (1 % or 3 %, normal, seeds 1 and 2) on its own, so the stamps
drift off a uniform grid by more than half a period. Every step stays within half a period of
one period, so no sample was lost: the loader reads the values as uniformly sampled (their
noise above f_s/4 is hundreds of times lower than at the stamps), and its warning gives the
measured spread of the steps (the injected s within 5 %: the sample std of 24840 steps has a
relative sd of 0.45 %). The fit of that reading is in tests/test_clock_reading_drift.py.

An added sample (two steps of half a period) leaves no slot for every value: taken as
uniformly sampled, every later value would be a period off its time, so the stamp reading
stays (the safe behaviour). Its warning says why, that the errors accumulate, and that the
drive's cycle times are the remedy. A lost sample (a step of 2 periods) is counted: the slots
from the rounded steps (tests/test_clock_counted_slots.py) put every value at its slot, and
the stamps then fit as the drive's cycle times do (the lost cycle keeping its slot), 4.035 %
for 4.035 %, where the stamps read as instants gave 19.5 % (3 %, seed 1) before."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
import scipy.io as sio

from ident.api import JointModel, load
from ident.loaders import ResamplingWarning
from tests.conftest import shared_path

KW = dict(mapping={"q": "qm", "tau": "vir"}, gain="gtau", joint="prismatic")
# the reference script's preprocessing (tests/test_ident_emps.py)
FIT = dict(model="usual", cutoff=100, decimation=10, dq_min=0, sign_check=False)
LOST = 12000  # the index of the lost (or added) sample


def _copy(tmp_path, s: float, seed: int, change: str = "", cycles: bool = False):
    """DATA_EMPS.mat with t_k = t_0 + sum of dt (1 + s e_i), e normal. ``change``: "lost"
    drops sample LOST (its stamp and values), "added" inserts a sample midway between LOST - 1
    and LOST (stamp and values their mean); ``cycles``: the time column the drive's cycle
    numbers give instead (cycle x dt, the lost cycle's slot kept empty)."""
    m = sio.loadmat(shared_path("data", "emps") / "DATA_EMPS.mat")
    t = m["t"].ravel()
    dt = float(np.median(np.diff(t)))
    e = np.random.default_rng(seed).standard_normal(t.size - 1)
    cols = {k: v for k, v in m.items() if not k.startswith("__")}
    cols["t"] = (t[0] + dt * np.arange(t.size) if cycles else
                 np.r_[t[0], t[0] + np.cumsum(dt * (1 + s * e))])[:, None]
    for k in ("t", "qm", "qg", "vir"):
        a = cols[k]
        if change == "lost":
            cols[k] = np.delete(a, LOST, axis=0)
        elif change == "added":
            cols[k] = np.insert(a, LOST, 0.5 * (a[LOST - 1] + a[LOST]), axis=0)
    path = tmp_path / f"emps_rw_{s}_{seed}_{change}{'_cycles' if cycles else ''}.mat"
    sio.savemat(path, cols)
    return path


def _message(path) -> str:
    with pytest.warns(ResamplingWarning) as rec:
        load(path, **KW)
    (msg,) = [str(w.message) for w in rec if issubclass(w.category, ResamplingWarning)]
    return msg


@pytest.mark.parametrize("s", [0.01, 0.03])
@pytest.mark.parametrize("seed", [1, 2])
def test_random_walk_clock_warning_gives_the_spread_and_the_ratio(tmp_path, s, seed):
    msg = _message(_copy(tmp_path, s, seed))
    m = re.search(r"the steps vary ([0-9.]+) % of the period \(std\)", msg)
    assert m, msg
    assert float(m.group(1)) == pytest.approx(100 * s, rel=0.05), msg
    assert "a drifting clock's stamps of uniformly sampled values" in msg, msg
    assert "no sample lost or added" in msg, msg
    higher = float(re.search(r"noise above f_s/4 is ([0-9.e+]+)x higher", msg).group(1))
    assert higher > 10, msg


@pytest.mark.parametrize("seed", [1, 2])
def test_an_added_sample_keeps_the_stamp_reading(tmp_path, seed):
    msg = _message(_copy(tmp_path, 0.03, seed, "added"))
    assert "values taken at their stamps: some stamp is more than half a period off" in msg
    m = re.search(r"(a step|two steps) of ([0-9.]+) periods(?:, counted \d+)?: a sample "
                  r"(lost|added)", msg)
    assert m, msg
    periods = 1 if m.group(1) == "a step" else 2  # what each sample holding its own spans
    assert m.group(3) == "added" and abs(float(m.group(2)) - periods) >= 0.5, msg
    assert "accumulating" in msg and "give the drive's cycle times" in msg, msg


@pytest.mark.parametrize("seed", [1, 2])
def test_a_lost_sample_is_counted_and_fits_as_the_cycle_times(tmp_path, seed):
    """A sample lost under the drifting clock: the stamps, their slots counted from the
    steps, fit as the drive's cycle times (the lost cycle's slot kept) and as the original
    file; read as instants they gave 19.5 % for 4.04 % (seed 1)."""
    msg = _message(_copy(tmp_path, 0.03, seed, "lost"))
    assert "a drifting clock's stamps of uniformly sampled values with 1 sample(s) lost" in msg
    assert f"1 after sample {LOST - 1} " in msg, msg
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = JointModel(**FIT).fit(load(shared_path("data", "emps") / "DATA_EMPS.mat", **KW))
        stamped = JointModel(**FIT).fit(load(_copy(tmp_path, 0.03, seed, "lost"), **KW))
        cycles = JointModel(**FIT).fit(load(_copy(tmp_path, 0.03, seed, "lost", True), **KW))
    assert cycles.rel_error_ == pytest.approx(ref.rel_error_, rel=0.01)
    assert stamped.rel_error_ == pytest.approx(cycles.rel_error_, rel=0.01), (
        stamped.rel_error_, cycles.rel_error_)
