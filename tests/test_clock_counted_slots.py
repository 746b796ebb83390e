"""The third reading of irregular stamps (:func:`ident.timebase.uniform_grid`): a drifting
host clock stamping uniformly sampled values, with a few samples lost. The slots are counted
from the steps (each step divided by the period and rounded, accumulated:
:func:`ident.timebase.counted_slots`), each value is put at its slot, the lost slots are filled
from their neighbours, and one warning says how many were lost and where.

* The real EMPS run (``../shared``; skipped without it) under a random-walk clock (s = 3 %,
  seeds 1 and 2; s = 1 %, seed 1) with 1 sample lost, 5 spread, or a burst of 10 (every other
  sample over 20) fits as the original file (within 1.1x of its 4.035 %; read at the stamps,
  before this reading: 7.7 % at 1 %, 19.5-20.0 % at 3 %); ten lost in a row are a gap, still
  refused in one line.
* Values genuinely taken at irregular instants are not forced onto slots: the simulated joint's
  values taken at the instants of a random-walk clock with samples skipped (steps near whole
  numbers of periods: the counted reading is a candidate) keep the stamp reading, chosen by
  the noise; steps that are no whole numbers of periods (uniform in 0.6-1.4 periods, every
  tenth in 1.6-2.4) are not counted at all. Both fit as the clean file.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
import scipy.io as sio

from ident import DataError
from ident.api import load
from ident.loaders import ResamplingWarning
from ident.timebase import counted_slots, uniform_grid
from tests.test_clock_reading_drift import (  # noqa: F401 (fixtures)
    _fit,
    _sim_fit,
    emps_data,
    quick_runs,
    random_walk,
)

KW = dict(mapping={"q": "qm", "tau": "vir"}, gain="gtau", joint="prismatic")
LOST = {
    "one": (12000,),
    "five spread": (4000, 8000, 12000, 16000, 20000),
    "burst of ten": tuple(range(12000, 12020, 2)),
}


@pytest.fixture(scope="module")
def emps():
    """DATA_EMPS.mat and its fit error as read (``test_clock_reading_drift``'s settings)."""
    return emps_data()


def _drifted(m: dict, path, s: float, seed: int, lost: tuple[int, ...]):
    """DATA_EMPS.mat under a random-walk clock (steps dt (1 + s e)), samples ``lost`` dropped
    (stamps and values)."""
    t = m["t"].ravel()
    cols = {k: v for k, v in m.items() if not k.startswith("__")}
    cols["t"] = (t[0] + random_walk(t.size, s, seed, float(np.median(np.diff(t)))))[:, None]
    for k in ("t", "qm", "qg", "vir"):
        cols[k] = np.delete(cols[k], list(lost), axis=0)
    sio.savemat(path, cols)
    return path


@pytest.mark.parametrize("lost", list(LOST))
@pytest.mark.parametrize(("s", "seed"), [(0.03, 1), (0.03, 2), (0.01, 1)])
def test_lost_samples_under_a_drifting_clock_are_counted_into_their_slots(
        emps, tmp_path, lost, s, seed):
    m, ref = emps
    idx = LOST[lost]
    path = _drifted(m, tmp_path / "rw_lost.mat", s, seed, idx)
    with pytest.warns(ResamplingWarning) as rec:
        (e,) = load(path, **KW)
    msgs = [str(w.message) for w in rec if issubclass(w.category, ResamplingWarning)]
    assert len(msgs) == 1 and "\n" not in msgs[0], msgs  # once, one line
    msg = msgs[0]
    assert f"with {len(idx)} sample(s) lost: 1 after sample " in msg, msg
    # where: the sample before each gap as the file numbers and stamps it (the first five)
    ts = sio.loadmat(path)["t"].ravel()
    for j, (row, stamp) in enumerate(re.findall(r"1 after sample (\d+) \(t=([0-9.e+-]+) s\)",
                                                msg)):
        assert int(row) == idx[j] - j - 1, msg
        assert float(stamp) == pytest.approx(ts[int(row)], rel=1e-5), msg
    qm = m["qm"].ravel()
    assert e.q.size == qm.size  # every slot, the lost ones too
    np.testing.assert_array_equal(np.delete(e.q, idx), np.delete(qm, idx))  # values as sampled
    for i in idx:  # a lost slot filled from its neighbours
        assert min(e.q[i - 1], e.q[i + 1]) <= e.q[i] <= max(e.q[i - 1], e.q[i + 1])
    err = _fit([e])
    assert err <= 1.1 * ref, (err, ref, msg)


def test_ten_lost_in_a_row_are_a_gap_refused_as_before(emps, tmp_path):
    m, _ = emps
    path = _drifted(m, tmp_path / "rw_gap.mat", 0.03, 1, tuple(range(12000, 12010)))
    with pytest.raises(DataError, match=r"gap in the recording at t=.*split the file") as exc:
        load(path, **KW)
    assert "\n" not in str(exc.value)


def test_counted_slots_counts_lost_samples_and_refuses_what_is_no_slot_count():
    rng = np.random.default_rng(5)
    dt = 1e-3
    for s in (0.01, 0.03, 0.06):
        t = random_walk(5000, s, int(100 * s), dt)
        kept = np.delete(np.arange(t.size), [100, 2000, 2001, 4000])
        slots = counted_slots(np.diff(t[kept]), dt)
        assert slots is not None, s
        np.testing.assert_array_equal(slots, kept - kept[0])
    # an added sample: two steps of about one period together
    t = random_walk(5000, 0.03, 7, dt)
    assert counted_slots(np.diff(np.insert(t, 2500, 0.5 * (t[2499] + t[2500]))), dt) is None
    # steps that are no whole numbers of periods: instants, not slots
    d = dt * rng.uniform(0.55, 2.45, 5000)
    assert counted_slots(d, float(np.median(d))) is None
    # a step beyond GAP_PERIODS periods is a gap, not lost samples to fill
    assert counted_slots(np.r_[np.full(100, dt), 6 * dt, np.full(100, dt)], dt) is None


def test_the_counted_reading_keeps_every_axis_and_fills_the_lost_slots():
    """Two axes (a robot's run) under a 3 % random-walk clock, samples 1000, 2500 and 2501
    lost: every kept value at its slot unchanged, the three lost slots filled, one note naming
    both gaps."""
    rng = np.random.default_rng(1)
    n, dt = 4000, 1e-3
    t = random_walk(n, 0.03, 11, dt)
    k = dt * np.arange(n)
    q = np.column_stack([np.sin(2 * np.pi * 0.7 * k), np.cos(2 * np.pi * 1.3 * k)])
    q += 1e-6 * rng.standard_normal(q.shape)
    lost = [1000, 2500, 2501]
    keep = np.delete(np.arange(n), lost)
    tg, out, note = uniform_grid(t[keep], {"q": q[keep], "tau": q[keep, 0], "dq": None},
                                 warn=False)
    assert tg.size == n and out["q"].shape == (n, 2) and out["tau"].shape == (n,)
    assert out["dq"] is None
    np.testing.assert_array_equal(out["q"][keep], q[keep])
    np.testing.assert_array_equal(out["tau"][keep], q[keep, 0])
    # filled from the neighbours: within the motion over a slot of the truth
    np.testing.assert_allclose(out["q"][lost], q[lost], atol=2 * np.pi * 1.3 * dt * 3)
    assert "with 3 sample(s) lost: 1 after sample 999 " in note, note
    assert "2 after sample 2498 " in note, note
    np.testing.assert_allclose(np.diff(tg), np.diff(tg)[0], rtol=1e-9)  # one period


def _csv(path, t, q, tau, mass, arm):
    np.savetxt(path, np.column_stack([t, q, tau, np.full(t.size, mass), np.full(t.size, arm)]),
               delimiter=",", fmt="%.10g", header="t,q,tau,payload_kg,payload_arm_m",
               comments="")
    return path


@pytest.mark.parametrize("kind", ["skipped instants", "no whole periods"])
@pytest.mark.parametrize("seed", [1, 2])
def test_values_taken_at_irregular_instants_are_not_forced_onto_slots(quick_runs, tmp_path,  # noqa: F811
                                                                      kind, seed):
    """Stamps true: the simulated joint's position (the true one, encoder-quantised) and
    torque reference taken at the stamps. ``skipped instants``: a 3 % random-walk clock whose
    every 500th instant is skipped (steps near whole numbers of periods: the counted reading
    is a candidate and loses on the noise); ``no whole periods``: steps uniform in 0.6-1.4
    periods, every tenth in 1.6-2.4 (no slot count). The stamp reading stays and fits as the
    clean file."""
    runs, cpr = quick_runs
    clean, files = [], []
    rng = np.random.default_rng(seed)
    for i, (r, p) in enumerate(runs):
        dt = float(np.median(np.diff(r.t)))
        clean.append(_csv(tmp_path / f"clean_{i}.csv", r.t, r.q, r.tau_ref, p.mass_kg, p.arm_m))
        if kind == "skipped instants":
            ts = r.t[0] + random_walk(r.t.size, 0.03, 100 * seed + i, dt)
            ts = np.delete(ts, np.arange(250, ts.size, 500))
        else:
            steps = rng.uniform(0.6, 1.4, r.t.size)
            steps[::10] += 1.0  # every tenth 1.6-2.4 periods: lost samples, were they slots
            ts = r.t[0] + np.r_[0.0, np.cumsum(dt * steps)]
        ts = ts[ts <= r.t[-1]]
        q = np.round(np.interp(ts, r.t, r.q_true) * cpr) / cpr
        tau = np.interp(ts, r.t, r.tau_ref)
        files.append(_csv(tmp_path / f"{i}.csv", ts, q, tau, p.mass_kg, p.arm_m))
    with pytest.warns(ResamplingWarning) as rec:
        load(files[0])
    (msg,) = [str(w.message) for w in rec if issubclass(w.category, ResamplingWarning)]
    assert "values taken at their stamps" in msg and "irregular time stamps" not in msg, msg
    if kind == "skipped instants":
        assert re.search(r"noise above f_s/4 is [0-9.e+]+x lower than taken as uniformly "
                         r"sampled with \d+ sample\(s\) lost", msg), msg
    else:
        assert "no whole number of periods" in msg, msg
    ref = _sim_fit(clean)
    err = _sim_fit(files)
    assert err <= 1.1 * ref, (err, ref, msg)
