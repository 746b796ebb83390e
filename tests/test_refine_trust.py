"""Refinement a scientist can trust: no candidate is built from the measured torque, an error
below the estimated noise floor is refused as a leak, every step is judged on data it was not
fitted on, and a named effect outside its physical range is not reported under its name.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np
import pytest
from test_refine_sim import SETTINGS, _plan, _signals, _usual_plant

from ident import OutputLeakError
from ident.diagnose import diagnose
from ident.effects import (
    Columns,
    Context,
    Effect,
    Prediction,
    Scorer,
    Setting,
    TorqueLag,
    WarmUp,
    registry,
    rigid_prediction,
)
from ident.interactions import continuous_values, sign_values
from ident.library_search import LibraryTerm, build_library
from ident.models import IdentModel, RigidBody, new_model, usual_model
from ident.preprocess import build_design
from ident.refine import refine
from ident.refine_result import ONE_TRAJECTORY_NOTE
from ident.signals import Signals
from ident.unseen import LEAK_RATIO, heldout_error, heldout_kind, noise_floor, one_trajectory
from sim_drivers.plant_config import default_plant


@functools.cache
def _design(model: str, payloads: int):
    plant = default_plant() if model == "new" else _usual_plant()
    s = _signals(plant, _plan().payloads[:payloads])
    lib = (new_model(0.03, True, payload=payloads > 1) if model == "new"
           else usual_model(True, payload=payloads > 1))
    return build_design(lib, s, **SETTINGS), lib


def _noisy(s: Signals, seed: int) -> Signals:
    """The same samples with the measured torque replaced by independent noise."""
    rng = np.random.default_rng(seed)
    return replace(s, tau=rng.normal(0.0, float(np.std(s.tau)) + 1.0, len(s)))


def test_a_states_view_hides_the_measured_torque():
    d, _ = _design("usual", 1)
    st = d.signals.states()
    assert not st.has_output and d.signals.has_output
    for use in (lambda: st.tau * st.dq, lambda: np.sign(st.tau), lambda: st.tau[0],
                lambda: np.asarray(st.tau), lambda: st.tau + 1.0, lambda: abs(st.tau)):
        with pytest.raises(OutputLeakError):
            use()
    # the view follows row selections
    assert not st.take(np.arange(10)).has_output


class _ReadsTorque(Effect):
    effect = "reads_torque"
    variable = "load"

    def names(self):
        return ("leak",)

    def columns(self, s):
        return (s.tau * np.sign(s.dq))[:, None]

    def describe(self):
        return "tau sign(dq)"


def test_a_candidate_term_that_reads_the_torque_fails_loudly():
    d, _ = _design("usual", 1)
    d.with_term(_ReadsTorque())  # a declared term may (the paper's own eq. 26 proxy)
    with pytest.raises(OutputLeakError):
        d.with_term(_ReadsTorque(), states_only=True)


@pytest.mark.parametrize("model,payloads", [("usual", 1), ("new", 3)])
def test_no_candidate_changes_when_the_torque_is_replaced_by_noise(model, payloads):
    """Every registered effect's candidates, the diagnosis variables and every library
    group: their columns on the true samples equal their columns on the same samples whose
    torque is independent noise."""
    d, lib = _design(model, payloads)
    m = IdentModel(lib).fit(d, eliminate=False, drop_unidentifiable=True)
    s_true, s_noise = d.signals, _noisy(d.signals, 7)
    tau_out = rigid_prediction(lib, m.coef_)
    assert tau_out is not None  # the paper model's load prediction comes from its inner terms
    kept = [d.names.index(n) for n in m.names_]
    diag = diagnose(m.residual_, s_true.states(), Y=d.Y, tau_out=tau_out)
    cols = Columns(s_true.states(), Scorer(d.W[:, kept], m.residual_))
    ctx = Context(cols, diag, lib, m.coef_, 1e-3, 12)
    cands = [c for reg in registry() for c in reg.propose(ctx)]
    assert len(cands) >= 5
    for c in cands:
        a, b = c.effect.columns(s_true), c.effect.columns(s_noise)
        np.testing.assert_array_equal(a, b, err_msg=c.effect.effect)
    # diagnosis and library variables
    for fn in (lambda s: continuous_values(s, tau_out), lambda s: sign_values(s, tau_out)):
        va, vb = fn(s_true), fn(s_noise)
        assert va.keys() == vb.keys() and {"load"} & set(va) | {"quadrant"} & set(va)
        for k in va:
            np.testing.assert_array_equal(va[k], vb[k], err_msg=k)
    values = {**continuous_values(s_true, tau_out), **sign_values(s_true, tau_out)}
    noise_values = {**continuous_values(s_noise, tau_out), **sign_values(s_noise, tau_out)}
    groups = build_library(values, ["position", "velocity", "load", "time"])
    assert any(g.modifier in ("quadrant", "load_quadrant") for g in groups)
    for g in groups:
        np.testing.assert_array_equal(g.columns(values), g.columns(noise_values))
        t = LibraryTerm(g, tau_out)
        np.testing.assert_array_equal(t.columns(s_true), t.columns(s_noise))


def test_without_a_load_model_there_is_no_load_variable():
    d, _ = _design("usual", 1)
    v = continuous_values(d.signals)
    assert "load" not in v and "quadrant" not in sign_values(d.signals)
    assert "load" not in {r.variable for r in diagnose(d.Y * 0 + 1, d.signals, Y=d.Y).table}


def _leaky_design(seed: int):
    """A synthetic joint whose torque noise is also offered as an 'other joint' variable:
    a basis in it would rebuild the noise from the output."""
    n, dt = 6000, 0.01
    t = np.arange(n) * dt
    q = 1.2 * np.sin(0.31 * t) + 0.3 * np.sin(1.3 * t + 0.5)
    dq = np.gradient(q, t)
    ddq = np.gradient(dq, t)
    noise = np.random.default_rng(seed).normal(0, 1.0, n)
    tau = 30 * ddq + 200 * np.cos(q) + 20 * np.sign(dq) + 5 * dq + noise
    z = np.zeros(n)
    s = Signals(t, q, dq, ddq, tau, z, z, np.zeros(n, int), revolute=True,
                extra={"oracle": noise})
    lib = usual_model(True, payload=False)
    return build_design(lib, s, decimation=1, dq_min=0.02), lib


@pytest.mark.parametrize("seed", [0, 1])
def test_a_term_that_explains_the_noise_is_refused_as_a_leak(seed):
    d, lib = _leaky_design(seed)
    R = refine(d, IdentModel(lib, "usual"), max_steps=2, others=["oracle"])
    assert all("oracle" not in st.variables for st in R.steps), R.format_report()
    leaks = [r for r in R.rejected if r.reason.startswith("leak")]
    assert leaks, R.format_report()
    assert "noise floor" in leaks[0].reason
    # the floor is the noise (sigma 1 N m) relative to ||Y||, within the estimate's spread
    true_floor = 1.0 * math.sqrt(len(d)) / float(np.linalg.norm(d.Y))
    assert 0.8 * true_floor < R.noise_floor < 1.2 * true_floor
    assert R.rel_error_final >= LEAK_RATIO * R.noise_floor


def test_noise_floor_and_heldout_helpers():
    rng = np.random.default_rng(3)
    m = 4000
    x = np.linspace(0, 20, m)
    y = 50 * np.sin(x) + 3.0
    e = rng.normal(0, 0.5, m)
    smooth = 2.0 * np.sin(0.7 * x)  # an unexplained smooth effect barely moves the floor
    fl = noise_floor(e + smooth, y + e, np.zeros(m, int))
    assert fl == pytest.approx(0.5 * math.sqrt(m) / np.linalg.norm(y + e), rel=0.1)
    W = np.column_stack([np.sin(x), np.ones(m)])
    runs = np.repeat([0, 1], m // 2)
    assert heldout_kind(runs) == "leave one run out"
    assert heldout_kind(np.zeros(m, int)) == "blocked folds"
    h = heldout_error(W, y + e, runs)
    assert h == pytest.approx(0.5 / np.sqrt(np.mean((y + e) ** 2)), rel=0.1)
    # a column that only one run excites is not predicted on the other
    W2 = np.column_stack([W, np.where(runs == 1, np.cos(x), 0.0)])
    assert heldout_error(W2, y + e + 5 * W2[:, 2], runs) > 3 * h


def test_named_effects_declare_their_physical_range():
    pred = Prediction([RigidBody(True)], np.ones(3))
    setting = Setting(cycle_s=0.01, run_s=120.0, excitation_s=4.0)
    lag = TorqueLag(pred)
    assert lag.physical_range({"T_lag": {"value": 0.005, "std2": 0.001}}, setting) is None
    # a real arm's shoulder at 100 Hz: a 119 ms "lag" is the controller's, not the joint's
    why = lag.physical_range({"T_lag": {"value": 0.119, "std2": 0.004}}, setting)
    assert why and "119 ms" in why
    assert lag.physical_range({"T_lag": {"value": -0.004, "std2": 0.001}}, setting)
    w = WarmUp(20.0)
    assert w.physical_range({"T_w": {"value": 20.0, "std2": 1.0}}, setting) is None
    assert "excitation" in w.physical_range({"T_w": {"value": 2.0, "std2": 0.1}}, setting)
    assert "run" in w.physical_range({"T_w": {"value": 500.0, "std2": 9.0}}, setting)


def test_one_trajectory_tells_a_replayed_path_from_another():
    """Runs that replay one trajectory (tracking errors that differ with the load) are told
    from runs of another trajectory: another multi-sine, the same one delayed beyond
    MAX_START_OFFSET (a recording started a little earlier or later replays the same path),
    one joint of several that differs; one run is never "one trajectory"."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 20.0, 0.01)

    def path(seed: int, delay: float = 0.0) -> np.ndarray:
        r = np.random.default_rng(seed)
        a, w, ph = r.uniform(0.2, 1.0, 4), r.uniform(0.3, 2.0, 4), r.uniform(0, 6.3, 4)
        return sum(ai * np.sin(wi * (t - delay) + pi) for ai, wi, pi in zip(a, w, ph, strict=True))

    q0 = path(1)
    track = [q0 + 0.002 * rng.standard_normal(t.size) + 0.003 * np.sin(3 * t + k)
             for k in range(3)]  # one path, three loads
    tt, runs = np.tile(t, 3), np.repeat([0, 1, 2], t.size)
    assert one_trajectory(tt, np.concatenate(track), runs)
    assert not one_trajectory(t, q0, np.zeros(t.size, int))
    assert not one_trajectory(tt, np.concatenate([track[0], path(2), track[2]]), runs)
    # a recording started earlier or later replays the same path (the start is aligned, up
    # to MAX_START_OFFSET of the duration, either way); beyond it, it is another trajectory
    for delay in (0.5, -0.5, 1.7):
        assert one_trajectory(tt, np.concatenate([track[0], track[1], path(1, delay)]), runs)
    assert not one_trajectory(tt, np.concatenate([track[0], track[1], path(1, 5.0)]), runs)
    # rows left out (the stiction area) do not matter; one joint of two that differs does
    keep = rng.random(tt.size) > 0.3
    assert one_trajectory(tt[keep], np.concatenate(track)[keep], runs[keep])
    q2 = np.column_stack([np.concatenate(track), np.concatenate([q0, q0, path(3)])])
    assert not one_trajectory(tt, q2, runs)
    assert one_trajectory(tt, q2[:, :1], runs)


def test_refinement_says_when_leaving_a_run_out_cannot_reject_a_path_locked_term():
    """The example campaign's payload runs replay one plan: the refinement records it and,
    without validation data, its report says that only another trajectory can test the
    added terms; given validation data it does not."""
    d, lib = _design("new", 2)
    R = refine(d, IdentModel(lib, "paper"), max_steps=0)
    assert R.heldout_kind == "leave one run out" and R.heldout_one_trajectory
    assert R.to_json()["heldout_one_trajectory"] is True
    assert ONE_TRAJECTORY_NOTE in R.format_report()
    v = refine(d, IdentModel(lib, "paper"), max_steps=0, validation=d)
    assert v.heldout_one_trajectory and ONE_TRAJECTORY_NOTE not in v.format_report()
