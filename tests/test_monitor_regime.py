"""Regime thresholds of the torque monitor (docs/monitoring.md, issue 25): bands per bin of
each joint's moving time (time since its last reversal, start or rest), from the validation
residual's statistics per bin, checked per cycle by :class:`TorqueMonitor`; the thresholds
file (format /2, /1 still read)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from daq import ConfigError
from daq.runtime.monitor import (
    _SAMPLE_DTYPE,
    TorqueMonitor,
    moving_seconds,
)
from ident import DataError
from ident.monitor import DEFAULT_EDGES_S, Thresholds, thresholds_from_residual

CYCLE_S = 0.001
V_REST = 0.05  # [rad/s]


class _Log:
    """What TorqueMonitor writes into a run log: its MonitorSample messages per channel and
    its events."""

    start_ns, cycle_ns = 0, 1_000_000

    def __init__(self) -> None:
        self._w = self
        self.events: list[tuple[int, str, int]] = []
        self.msgs: dict[int, list[bytes]] = {}

    # the writer's part
    def register_schema(self, *a) -> int:
        return 1

    def register_channel(self, topic, *a) -> int:
        self.msgs[len(self.msgs)] = []
        return len(self.msgs) - 1

    def add_metadata(self, *a) -> None:
        pass

    def _add(self, chan, ts, data, now_ns, cycle) -> None:
        self.msgs[chan].append(data)

    def event(self, cycle, t, kind, message, axis=-1) -> None:
        self.events.append((cycle, kind, axis))

    def samples(self, j: int) -> np.ndarray:
        return np.frombuffer(b"".join(self.msgs[j]), _SAMPLE_DTYPE)


def _motion(seconds: float, seed: int, bump_nm: float, steps=()) -> tuple[np.ndarray, ...]:
    """One joint swinging dq = 0.5 sin(2 pi 0.25 t) [rad/s] (a reversal every 2 s); its
    measured torque = white noise (0.2 N m) + a bump of ``bump_nm`` for 10 ms where the
    joint breaks away after each reversal (|dq| reaches V_REST: what the model misses) +
    ``steps`` (t0 [s], N m, duration [s]); the model predicts 0."""
    t = np.arange(int(seconds / CYCLE_S)) * CYCLE_S
    dq = 0.5 * np.sin(2 * np.pi * 0.25 * t)
    tau = np.random.default_rng(seed).normal(0.0, 0.2, t.size)
    fast = np.abs(dq) >= V_REST
    starts = np.flatnonzero(fast[1:] & ~fast[:-1]) + 1
    for i in starts:
        tau[i:i + 10] += bump_nm * np.sign(dq[i])
    for t0, nm, dt in steps:
        tau[(t >= t0) & (t < t0 + dt)] += nm
    return t, dq, tau


def _run(mon: TorqueMonitor, t, dq, tau, log: _Log | None = None) -> _Log:
    return _run_velocity(mon, t, dq, tau, log)[0]


def _run_velocity(mon: TorqueMonitor, t, dq, tau,
                  log: _Log | None = None) -> tuple[_Log, np.ndarray]:
    """The monitor over the motion: its log, and its filtered velocity each cycle [rad/s]."""
    log = _Log() if log is None else log
    mon.begin(0, None, log)
    dqf = []
    for c in range(t.size):
        mon.step(c, t[c], [0.0], [dq[c]], [tau[c]], log)
        dqf.append(mon.velocity[0])
    return log, np.array(dqf)


def _zero(payload):
    return lambda q, dq, ddq: ([0.0], [0.0])


@pytest.fixture(scope="module")
def validation() -> Thresholds:
    """Thresholds of an 80 s validation run: 40 breakaways with a 2 N m bump each (every bin
    entered 40 times, more than DEFAULT_MIN_EPISODES)."""
    mon = TorqueMonitor(_zero, ["a"], CYCLE_S, rest_velocity=[V_REST])
    log = _run(mon, *_motion(80.0, 1, 2.0))
    s = log.samples(0)
    armed = s["armed"].astype(bool)
    return thresholds_from_residual(s["residual"][armed, None], ["a"], 6.0, "synthetic",
                                    1.5, s["moving_s"][armed, None])


def test_moving_time_online_is_the_offline_rule():
    """The moving time the monitor logs every cycle is :func:`moving_seconds` of its
    filtered velocity: 0 at a reversal and below the rest velocity, one cycle more else."""
    t, dq, tau = _motion(6.0, 2, 0.0)
    mon = TorqueMonitor(_zero, ["a"], CYCLE_S, rest_velocity=[V_REST])
    log, dqf = _run_velocity(mon, t, dq, tau)
    logged = log.samples(0)["moving_s"]
    np.testing.assert_allclose(logged, moving_seconds(dqf[:, None], [V_REST],
                                                      CYCLE_S)[:, 0], atol=1e-12)
    assert logged.max() > 1.5  # one swing, 2 s less the time near rest
    reset = np.flatnonzero(logged == 0.0)
    assert np.all(np.abs(np.array(dqf)[reset[1:]]) < V_REST + 0.002)  # rest or reversal


def test_regime_band_is_wide_only_where_the_validation_residual_is(validation):
    """The breakaway bumps widen the first bin's band only: the steady bins' bands are a
    few times narrower than the constant band, which the bumps set for every regime."""
    th = validation
    assert th.regime and th.edges_s == DEFAULT_EDGES_S
    lo, hi = (np.array(x[0]) for x in th.bands())
    half = (hi - lo) / 2
    assert all(th.bin_used[0][1:]) and th.bin_samples[0][0] > 0
    const = th.half_width[0]
    assert half[0] >= 0.9 * const  # the bumps are in the first bin
    assert np.all(half[2:] < const / 3)  # steady motion: noise only
    assert half[-1] == pytest.approx(th.bin_sigma[0][-1] * max(
        6.0, 1.5 * th.bin_peak[0][-1]))


def test_push_in_steady_motion_flagged_reversal_peak_not(validation):
    """The monitored run repeats the validation's bumps at every breakaway (another noise
    seed) and carries a 1 N m step for 0.1 s while the joint moves steadily: with the
    regime bands exactly one crossing, within 50 ms of the step; the constant band of the
    same statistics (the /1 semantics) misses the step."""
    t0 = 5.0  # dq = 0.5 sin(pi/2 t): at its peak at 5 s, 1 s after the last reversal
    run = _motion(12.0, 7, 2.0, steps=[(t0, 1.0, 0.1)])
    lo, hi = validation.bands()
    mon = TorqueMonitor(_zero, ["a"], CYCLE_S, lower=lo, upper=hi,
                        edges_s=validation.edges_s, rest_velocity=[V_REST])
    log = _run(mon, *run)
    hits = [c for c, kind, _ in log.events if kind == "collision"]
    assert len(hits) == 1 and 0 <= hits[0] * CYCLE_S - t0 <= 0.05, hits
    c = validation.constant()
    mon = TorqueMonitor(_zero, ["a"], CYCLE_S, lower=c.lower, upper=c.upper,
                        rest_velocity=[V_REST])
    assert not [e for e in _run(mon, *run).events if e[1] == "collision"]


def test_sparse_bins_take_the_constant_band():
    """A bin with fewer validation samples than min_samples, or entered fewer times than
    min_episodes (separate motions), takes the joint's constant band, whatever its own
    spread, when no pool with shorter bins has enough (the first bin has none; here every
    bin was entered 50 times, fewer than 51)."""
    rng = np.random.default_rng(3)
    m = np.tile(np.arange(100) * 0.02, 50)[:, None]  # 50 motions of 2 s each
    r = rng.normal(0.0, 0.1, m.shape)
    r[m < 0.1] *= 0.01  # narrow in the first bin: its own band would be tiny
    th = thresholds_from_residual(r, ["a"], 6.0, moving_s=m, edges_s=(0.1, 1.0),
                                  min_samples=300, min_episodes=20)
    assert th.bin_samples[0] == (250, 2250, 2500) and th.bin_episodes[0] == (50, 50, 50)
    lo, hi = th.bands()
    assert th.bin_used[0] == [False, True, True]  # 250 samples < 300
    assert (lo[0][0], hi[0][0]) == (th.lower[0], th.upper[0])
    assert hi[0][1] != th.upper[0]
    few = thresholds_from_residual(r, ["a"], 6.0, moving_s=m, edges_s=(0.1, 1.0),
                                   min_samples=300, min_episodes=51)
    assert few.bin_used[0] == [False, False, False]  # 50 motions < 51
    assert few.bands() == ([few.lower * 3], [few.upper * 3])
    with pytest.raises(DataError, match="moving_s"):
        thresholds_from_residual(r, ["a"], 6.0, moving_s=m[:10])
    with pytest.raises(DataError, match="edges"):
        thresholds_from_residual(r, ["a"], 6.0, moving_s=m, edges_s=(1.0, 0.5))


def _thin_last_bin(seed: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Validation residual (n, 1) [N m] and moving time (n, 1) [s] of 60 motions, 50 of 0.5 s
    and 10 of 2 s (edges 0.1, 1 s: the last bin entered 10 times): wide in the first 0.1 s
    of each motion (sd 1 N m, the start transient), narrow after (sd 0.1 N m)."""
    rng = np.random.default_rng(seed)
    m = np.concatenate([np.arange(n) * 0.01 for n in [50] * 50 + [200] * 10])[:, None]
    r = np.where(m < 0.1, rng.normal(0.0, 1.0, m.shape), rng.normal(0.05, 0.1, m.shape))
    return r, m


def test_thin_bin_is_pooled_with_the_nearest_shorter_bins():
    """A bin entered too few times (the last: 10 of 20 motions reach it) takes the band of
    its samples pooled with the nearest shorter bin that makes the pool enough (mean and
    spread those of the pooled samples; every one of them inside): a few times narrower
    than the constant band, which the start transients set, so a 1 N m step while the joint
    has moved for more than 1 s is outside it (inside the constant band, the ``constant``
    rule); the pool never widens a band beyond the constant one."""
    r, m = _thin_last_bin()
    th = thresholds_from_residual(r, ["a"], 6.0, moving_s=m, edges_s=(0.1, 1.0),
                                  min_samples=300, min_episodes=20, peak_margin=1.5)
    assert th.thin_bins == "pooled"
    assert th.bin_episodes[0] == (60, 60, 10) and th.bin_used[0] == [True, True, False]
    lo, hi = (np.array(x[0]) for x in th.bands())
    pool = r[m >= 0.1]  # bins 1 and 2: the thin bin and its shorter neighbour
    assert (lo[2] + hi[2]) / 2 == pytest.approx(pool.mean(), abs=1e-12)
    assert np.all((pool > lo[2]) & (pool < hi[2]))  # every validation sample of the pool
    half = (hi[2] - lo[2]) / 2
    assert half >= 1.5 * np.abs(pool - pool.mean()).max() - 1e-12  # peak margin kept
    assert half >= 6.0 * pool.std() - 1e-12
    assert half < th.half_width[0] / 3
    step = 0.05 + 1.0  # the residual's mean in steady motion plus a 1 N m push
    assert step > hi[2] and th.lower[0] < step < th.upper[0]
    const = dataclasses.replace(th, thin_bins="constant")
    assert [x[0][2] for x in const.bands()] == [th.lower[0], th.upper[0]]
    assert const.bands()[0][0][:2] == th.bands()[0][0][:2]  # own bins unchanged
    # a thin bin right after the wide first one (one sample per motion): pooled with the
    # start transients, 6 sigma of the pool is wider than the constant band (its peak;
    # narrow samples dominate its sigma): the band stays the constant one
    t2 = thresholds_from_residual(r, ["a"], 6.0, moving_s=m, edges_s=(0.1, 0.105, 1.0),
                                  min_samples=300, min_episodes=20, peak_margin=1.0)
    assert t2.bin_used[0] == [True, False, True, False]
    n0, n1 = t2.bin_samples[0][:2]
    sd01 = math.sqrt((n0 * (t2.bin_sigma[0][0] ** 2 + t2.bin_mean[0][0] ** 2) + n1 * (
        t2.bin_sigma[0][1] ** 2 + t2.bin_mean[0][1] ** 2)) / (n0 + n1))  # about the pool's 0
    assert 6.0 * sd01 > 1.3 * t2.half_width[0]  # the pool alone would widen bin 1
    lo2, hi2 = (x[0] for x in t2.bands())
    assert (lo2[1], hi2[1]) == (t2.lower[0], t2.upper[0])
    assert hi2[3] < t2.upper[0] / 2  # the last bin pooled with the third (narrow)
    with pytest.raises(DataError, match="thin_bins"):
        thresholds_from_residual(r, ["a"], 6.0, moving_s=m, thin_bins="widest")


def test_thresholds_file_v2_round_trip_v1_read_bad_regime(tmp_path, validation):
    p = tmp_path / "th.json"
    d = validation.to_json()
    assert d["format"] == "jointid-monitor-thresholds/2"
    p.write_text(json.dumps(d))
    back = Thresholds.read(p)
    assert back == validation and back.bands() == validation.bands()
    # format /1: the constant band
    v1 = {k: v for k, v in d.items() if k != "regime"}
    v1["format"] = "jointid-monitor-thresholds/1"
    p.write_text(json.dumps(v1))
    old = Thresholds.read(p)
    assert not old.regime and old.bands() == ([[x] for x in validation.lower],
                                               [[x] for x in validation.upper])
    # a /2 file written before the thin-bin rule: its thin bins keep the constant band
    r, m = _thin_last_bin()
    th = thresholds_from_residual(r, ["a"], 6.0, moving_s=m, edges_s=(0.1, 1.0),
                                  min_samples=300, min_episodes=20)
    dt = th.to_json()
    assert dt["regime"]["thin_bins"] == "pooled"
    p.write_text(json.dumps(dt))
    assert Thresholds.read(p) == th
    p.write_text(json.dumps({**dt, "regime": {k: v for k, v in dt["regime"].items()
                                              if k != "thin_bins"}}))
    before = Thresholds.read(p)
    assert before.thin_bins == "constant" and before.bands()[1][0][2] == th.upper[0]
    assert before.bands()[1][0][2] > th.bands()[1][0][2]
    bad = tmp_path / "bad.json"
    for reg, what in (({**d["regime"], "sigma": [[1.0]]}, "regime.sigma"),
                      ({**d["regime"], "thin_bins": "widest"}, "regime.thin_bins"),
                      ({**d["regime"], "edges_s": [0.5, 0.1, 1, 2]}, "edges_s"),
                      ({**d["regime"], "variable": "speed"}, "variable")):
        bad.write_text(json.dumps({**d, "regime": reg}))
        with pytest.raises(DataError, match=what) as e:
            Thresholds.read(bad)
        assert len(str(e.value).splitlines()) == 1 and str(bad) in str(e.value)


def test_monitor_rejects_a_table_of_the_wrong_size():
    with pytest.raises(ConfigError, match="regime bin"):
        TorqueMonitor(_zero, ["a"], CYCLE_S, lower=[[-1.0, -2.0]], upper=[[1.0, 2.0]],
                      edges_s=(0.1, 0.2))
    mon = TorqueMonitor(_zero, ["a"], CYCLE_S, lower=[-1.0], upper=[1.0], edges_s=(0.1,))
    assert mon.lower == [[-1.0, -1.0]] and math.isinf(TorqueMonitor(
        _zero, ["a"], CYCLE_S).upper[0][0])
