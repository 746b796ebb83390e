"""Regime thresholds of the torque monitor (docs/monitoring.md, issue 25): bands per bin of
each joint's moving time (time since its last reversal, start or rest), from the validation
residual's statistics per bin, checked per cycle by :class:`TorqueMonitor`; the thresholds
file (format /2, /1 still read)."""

from __future__ import annotations

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


def _run(mon: TorqueMonitor, t, dq, tau) -> _Log:
    log = _Log()
    mon.begin(0, None, log)
    for c in range(t.size):
        mon.step(c, t[c], [0.0], [dq[c]], [tau[c]], log)
    return log


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
    log = _Log()
    mon.begin(0, None, log)
    dqf = []
    for c in range(t.size):
        mon.step(c, t[c], [0.0], [dq[c]], [tau[c]], log)
        dqf.append(mon.velocity[0])
    logged = log.samples(0)["moving_s"]
    np.testing.assert_allclose(logged, moving_seconds(np.array(dqf)[:, None], [V_REST],
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
    spread."""
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
    bad = tmp_path / "bad.json"
    for reg, what in (({**d["regime"], "sigma": [[1.0]]}, "regime.sigma"),
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
