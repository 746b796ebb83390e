"""Units of the interaction diagnosis, the library search and the naming
(ident/interactions.py, ident/library_search.py, ident/describe.py) on synthetic residuals:
the right variables over several seeds, periods and amplitudes, nothing on noise, the
"other variables" path a robot joint will use (joint k's position in joint j's residual),
the Holm correction, the reversal distance and the zero-order-hold naming.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ident import DataError
from ident.describe import describe_group, name_torque_lag
from ident.interactions import (
    continuous_values,
    diagnose_interactions,
    holm,
    reversal_distance,
    sign_values,
)
from ident.library_search import (
    LIBRARY_VARIABLES,
    Basis,
    Group,
    LibraryTerm,
    build_library,
    prune,
    search,
    time_folds,
)
from ident.signals import Signals


def _signals(seed: int = 0, n: int = 12000, dt: float = 0.02) -> Signals:
    """A joint moving both ways over [-1.5, 1.5] rad (two incommensurate sines), 50 Hz."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    f1, f2 = 0.05 + 0.01 * rng.random(), 0.013 + 0.004 * rng.random()
    q = 1.0 * np.sin(2 * np.pi * f1 * t) + 0.5 * np.sin(2 * np.pi * f2 * t + 1.0)
    dq = np.gradient(q, t)
    ddq = np.gradient(dq, t)
    tau = 50 * np.cos(q) + 10 * ddq + 18 * np.sign(dq) + 5 * dq
    z = np.zeros(n)
    return Signals(t, q, dq, ddq, tau, z, z, np.zeros(n, int), revolute=True)


def _W(s: Signals) -> np.ndarray:
    """A declared model's regressor: inertia, gravity, Coulomb, viscous, offset."""
    return np.column_stack((s.ddq, np.cos(s.q), np.sin(s.q), np.sign(s.dq), s.dq,
                            np.ones(len(s))))


def _values(s: Signals, others: dict | None = None) -> dict:
    v = continuous_values(s, None, others)
    v.update(sign_values(s))
    return v


def _noise(seed: int, n: int, sigma: float = 0.5) -> np.ndarray:
    """AR(1) noise (correlated like a decimated residual)."""
    rng = np.random.default_rng(100 + seed)
    e = rng.normal(0, sigma, n)
    out = np.empty(n)
    acc = 0.0
    for i in range(n):
        acc = 0.5 * acc + e[i]
        out[i] = acc
    return out


def test_holm_is_a_step_down_bonferroni():
    p = np.array([0.01, 0.04, 0.03, 0.005])
    adj = holm(p)
    assert adj[3] == pytest.approx(4 * 0.005)
    assert adj[0] == pytest.approx(3 * 0.01)
    assert np.all(adj >= p) and np.all(adj <= 1)
    order = np.argsort(p)
    assert np.all(np.diff(adj[order]) >= 0)


def test_reversal_distance_counts_from_the_last_extreme_and_ignores_noise_at_rest():
    t = np.linspace(0, 20, 20001)
    q = np.sin(t)
    q[5000:6000] = q[5000]  # a stop
    q = q + np.random.default_rng(0).normal(0, 1e-5, q.size)
    s = Signals(t, q, np.gradient(q, t), 0 * t, 0 * t, 0 * t, 0 * t, np.zeros(t.size, int))
    d = reversal_distance(s)
    k = int(np.argmin(np.abs(t - 3 * np.pi / 2 - 0.3)))  # 0.3 rad of time after the minimum
    assert d[k] == pytest.approx(q[k] + 1.0, abs=1e-3)
    # the stop is not a reversal: after it the distance keeps growing from the last extreme
    assert d[6100] > d[4900]
    # the same on every 20th sample (decimated): within the dead band
    sub = s.take(slice(None, None, 20))
    assert np.max(np.abs(reversal_distance(sub) - d[::20])) < 2e-3 * np.ptp(q) + 1e-3


@pytest.mark.parametrize("seed,period,amp", [(0, 1.57, 6.0), (1, 0.7, 3.0), (2, 0.4, 4.0)])
def test_position_dependent_friction_is_seen_as_position_times_direction(seed, period, amp):
    s = _signals(seed)
    r = amp * np.sin(2 * np.pi * s.q / period + seed) * np.sign(s.dq) + _noise(seed, len(s))
    D = diagnose_interactions(r, s)
    assert D.tests[0].variables[:2] in (("position", "direction"), ("position", "quadrant"))
    assert D.get("position", "direction").p_adjusted < 1e-6
    # binned on position alone it averages out (the joint passes both ways)
    assert D.get("position").explained < 0.5 * D.get("position", "direction").explained


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_noise_has_no_significant_interaction_and_no_selected_group(seed):
    s = _signals(seed)
    r = _noise(seed, len(s))
    D = diagnose_interactions(r, s)
    assert D.significant == [], D.format_table()
    vals = _values(s)
    W = _W(s)
    y = W @ np.array([10, 50, 0, 18, 5, 1.0]) + r
    Q, _ = np.linalg.qr(W / np.linalg.norm(W, axis=0))
    groups = build_library(vals, LIBRARY_VARIABLES, Q=Q)
    res = search(y, W, vals, groups, time_folds(s.experiment), min_gain=0.05)
    assert res.selected == []
    assert res.tried and all(t.reason for t in res.tried)


@pytest.mark.parametrize("seed,period,amp", [(3, 1.2, 5.0), (4, 0.6, 4.0)])
def test_library_search_finds_and_names_position_dependent_friction(seed, period, amp):
    s = _signals(seed)
    W = _W(s)
    y = (W @ np.array([10, 50, 0, 18, 5, 1.0])
         + amp * np.sin(2 * np.pi * s.q / period) * np.sign(s.dq) + _noise(seed, len(s)))
    vals = _values(s)
    Q, _ = np.linalg.qr(W / np.linalg.norm(W, axis=0))
    groups = build_library(vals, LIBRARY_VARIABLES, Q=Q)
    folds = time_folds(s.experiment)
    res = search(y, W, vals, groups, folds, max_groups=2, min_gain=0.05)
    assert res.selected and res.selected[0].key == "position x direction"
    assert res.cv_path[1] < 0.5 * res.cv_path[0]
    desc = describe_group(res.selected[0], res.coef[0], y, W, vals, folds=folds,
                          reference={"F_C": 18.0})
    assert desc.name == "position_periodic_dry_friction"
    assert desc.parameters["period"]["value"] == pytest.approx(period, rel=0.02)
    assert desc.parameters["amplitude"]["value"] == pytest.approx(amp, rel=0.10)
    assert "% of F_C" in desc.sentence


def test_unnamed_structure_is_described_in_words():
    s = _signals(5)
    W = _W(s)
    bump = 6.0 * np.exp(-((s.q - 0.4) / 0.25) ** 2) * np.sign(s.dq)
    y = W @ np.array([10, 50, 0, 18, 5, 1.0]) + bump + _noise(5, len(s))
    vals = _values(s)
    Q, _ = np.linalg.qr(W / np.linalg.norm(W, axis=0))
    folds = time_folds(s.experiment)
    res = search(y, W, vals, build_library(vals, LIBRARY_VARIABLES, Q=Q), folds)
    g = res.selected[0]
    # here sign(tau) is mostly a function of q (gravity dominates): sign(P) = sign(tau dq)
    # carries the same information as sign(dq) along q, and either may win
    assert g.key in ("position x direction", "position x quadrant")
    desc = describe_group(g, res.coef[0], y, W, vals, folds=folds)
    assert desc.name is None
    assert "varies with position" in desc.sentence
    if g.modifier == "direction":
        assert desc.sentence.startswith("dry friction varies with position")
        x, f = desc.grid[0], desc.profile
        assert abs(x[np.argmax(f)] - 0.4) < 0.2  # the profile peaks near the bump


@pytest.mark.parametrize("seed", [0, 1])
def test_other_joint_position_is_diagnosed_and_searched(seed):
    """The robot path: joint j's residual depends on joint k's position (given as 'others')."""
    s = _signals(seed)
    rng = np.random.default_rng(seed)
    t = s.t
    q2 = 0.8 * np.sin(2 * np.pi * 0.031 * t + rng.random())
    dq2 = np.gradient(q2, t)
    others = {"q2": q2, "dq2": dq2}
    # dry friction of joint j grows with joint k's position (a cable, a coupled load)
    r = 4.0 * (q2 + 0.2 * q2**2) * np.sign(s.dq) + _noise(seed, len(s))
    D = diagnose_interactions(r, s, others=others)
    assert D.tests[0].variables[:2] in (("q2", "direction"), ("q2", "quadrant")), D.format_table()
    W = _W(s)
    y = W @ np.array([10, 50, 0, 18, 5, 1.0]) + r
    vals = _values(s, others)
    Q, _ = np.linalg.qr(W / np.linalg.norm(W, axis=0))
    groups = build_library(vals, list(LIBRARY_VARIABLES) + ["q2", "dq2"], Q=Q)
    res = search(y, W, vals, groups, time_folds(s.experiment), min_gain=0.05)
    assert res.selected and res.selected[0].variables == ("q2",)
    assert res.selected[0].modifier == "direction"
    # a group in another joint's variable is a term reading it from Signals.extra; signals
    # without it (validation data lacking the other joints) are refused naming the variable
    term = LibraryTerm(res.selected[0])
    np.testing.assert_array_equal(term.columns(dataclasses.replace(s, extra=others)),
                                  res.selected[0].columns(vals))
    assert term.names()[0].startswith("lb_q2_s_")
    with pytest.raises(DataError, match="no variable q2"):
        term.columns(s)


def test_prune_drops_the_hat_collinear_with_the_coulomb_column():
    s = _signals(0)
    vals = _values(s)
    W = _W(s)
    Q, _ = np.linalg.qr(W / np.linalg.norm(W, axis=0))
    b = Basis(float(s.q.min()), float(s.q.max()), 8)
    g = prune(Group(("position",), "direction", (b,)), vals, Q)
    assert g is not None and g.size == 7  # the 8 hats x sign(dq) sum to the Coulomb column
    X = np.column_stack((W, g.columns(vals)))
    assert np.linalg.matrix_rank(X) == X.shape[1]


def test_time_folds_interleave_blocks_or_follow_runs():
    f = time_folds(np.zeros(3000, int))
    assert set(f) == set(range(5))
    for k in range(5):  # every fold has blocks at the start and at the end
        idx = np.flatnonzero(f == k)
        assert idx.min() < 600 and idx.max() > 2400
    runs = np.repeat([0, 1, 2], 100)
    assert list(np.unique(time_folds(runs, by_run=True))) == [0, 1, 2]


def test_torque_lag_of_half_a_cycle_is_named_zero_order_hold():
    name, text = name_torque_lag(0.00048, 0.00005, 0.001)
    assert name == "zero_order_hold" and "half a cycle" in text
    assert name_torque_lag(0.003, 0.0001, 0.001)[0] == "torque_lag"
    assert name_torque_lag(0.0005, 0.0001, None)[0] == "torque_lag"
