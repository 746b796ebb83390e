"""Unit tests of the residual diagnosis, the candidate-effect terms, and the refinement
loop on synthetic signals (an effect outside the named list is caught by a generic basis)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ident.diagnose import dependence, diagnose, effective_n, periodogram
from ident.effects import (
    VARIABLES,
    DirectionalViscous,
    GenericBasis,
    PositionRipple,
    PositionSmooth,
    Prediction,
    QuadrantCoulomb,
    QuadrantLoad,
    QuadraticViscous,
    Spring,
    Stribeck,
    TorqueLag,
    WarmUp,
)
from ident.models import Coulomb, IdentModel, Offset, RigidBody, Viscous, usual_model
from ident.preprocess import build_design
from ident.refine import refine
from ident.signals import Signals
from ident.terms import Library


def _signals(n=4000, dt=0.01, seed=0) -> Signals:
    t = np.arange(n) * dt
    q = 1.2 * np.sin(0.31 * t) + 0.3 * np.sin(1.3 * t + 0.5)
    dq = np.gradient(q, t)
    ddq = np.gradient(dq, t)
    rng = np.random.default_rng(seed)
    tau = 30 * ddq + 200 * np.cos(q) + 20 * np.sign(dq) + rng.normal(0, 1, n)
    z = np.zeros(n)
    return Signals(t, q, dq, ddq, tau, z, z, np.zeros(n, int), revolute=True)


def test_effect_columns_follow_their_formulas():
    s = _signals(500)
    sg = np.sign(s.dq)
    np.testing.assert_allclose(PositionRipple(0.1).columns(s)[:, 0], np.sin(20 * np.pi * s.q))
    np.testing.assert_allclose(PositionRipple(0.1).columns(s)[:, 1], np.cos(20 * np.pi * s.q))
    np.testing.assert_allclose(Spring(0.2).columns(s)[:, 0], s.q - 0.2)
    np.testing.assert_allclose(DirectionalViscous().columns(s)[:, 0], 0.5 * np.abs(s.dq))
    np.testing.assert_allclose(QuadraticViscous().columns(s)[:, 0], s.dq * np.abs(s.dq))
    np.testing.assert_allclose(Stribeck(0.05).columns(s)[:, 0],
                               np.exp(-np.abs(s.dq) / 0.05) * sg)
    np.testing.assert_allclose(WarmUp(7.0).columns(s)[:, 0], np.exp(-s.t / 7.0) * sg)
    rb = RigidBody(True)
    pred = Prediction([rb], np.array([30.0, 20.0, 0.0]))
    tau_out = rb.columns(s) @ np.array([30.0, 20.0, 0.0])
    np.testing.assert_allclose(pred(s), tau_out)
    # the quadrant is the model's, sign(tau_out dq), never the measured sign(tau dq)
    np.testing.assert_allclose(QuadrantCoulomb(pred).columns(s)[:, 0],
                               0.5 * np.sign(tau_out * s.dq) * sg)
    np.testing.assert_allclose(QuadrantLoad(pred).columns(s)[:, 0],
                               np.sign(tau_out * s.dq) * tau_out)
    lag = TorqueLag(pred).columns(s)[:, 0]
    np.testing.assert_allclose(lag[1:-1], np.gradient(tau_out, s.t)[1:-1])
    for e in (PositionSmooth(-1.5, 1.5, 4), GenericBasis("velocity", -1, 1, 8, True)):
        c = e.columns(s)
        assert c.shape == (len(s), len(e.names()))
        assert np.all(np.isfinite(c))


def test_generic_hinges_exclude_constant_and_linear_parts():
    s = _signals()
    g = GenericBasis("position", -1.2, 1.2, 9)
    H = g.columns(s)
    np.testing.assert_allclose(g.knots, np.linspace(-1.2, 1.2, 9)[1:-1])
    np.testing.assert_allclose(H[:, 2], np.maximum(np.clip(s.q, -1.2, 1.2) - g.knots[2], 0))
    assert H.shape == (len(s), 7) and len(g.names()) == 7
    # not collinear with the model's offset and linear columns
    A = np.column_stack([np.ones(len(s)), s.q, H])
    assert np.linalg.matrix_rank(A) == A.shape[1]
    gs = GenericBasis("velocity", -1, 1, 6, signed=True)
    np.testing.assert_allclose(gs.columns(s)[:, 0],
                               np.sign(s.dq) * np.maximum(np.clip(s.dq, -1, 1) + 0.6, 0))
    assert g.variable == "position" and g.effect == "generic_position"
    assert GenericBasis("time", 0, 1, signed=True).effect == "generic_time_signed"
    with pytest.raises(ValueError, match="unknown variable"):
        GenericBasis("temperature", 0, 1)


def test_tags_make_names_unique_and_every_effect_has_a_valid_variable():
    a, b = PositionRipple(0.1), PositionRipple(0.05).with_tag("_2")
    lib = Library(usual_model(True, payload=False), a, b)
    assert len(set(lib.names())) == len(lib.names())
    assert b.period == 0.05 and b.names() == ("ripple_sin_2", "ripple_cos_2")
    for e in (a, Spring(), DirectionalViscous(), QuadraticViscous(), Stribeck(0.1),
              WarmUp(1.0), QuadrantCoulomb(Prediction([RigidBody(True)], np.ones(3)))):
        assert e.variable in VARIABLES
        assert e.describe()


def test_ripple_parameters_amplitude_phase_and_their_uncertainty():
    A, phi = 2.0, 0.7
    coef = np.array([A * math.cos(phi), A * math.sin(phi), 0.1])
    cov = np.diag([1e-4, 1e-4, 1e-8])
    par = PositionRipple(0.1).parameters(coef, cov)
    assert par["ripple_amplitude"][0] == pytest.approx(A)
    assert par["ripple_phase"][0] == pytest.approx(phi)
    assert par["ripple_amplitude"][1] == pytest.approx(2 * 1e-2, rel=1e-6)
    assert par["ripple_period"] == (0.1, pytest.approx(2e-4))


def test_dependence_finds_a_binned_effect_and_not_noise():
    rng = np.random.default_rng(1)
    n = 5000
    x = rng.uniform(-1, 1, n)
    noise = rng.normal(0, 1, n)
    d = dependence(noise + 0.5 * x**2, x, variable="velocity")
    assert d.p_value < 1e-10
    assert 0.015 < d.explained < 0.05  # var(0.5 x^2) / var(total) = 0.022 / 1.022
    assert d.variable == "velocity" and d.n_bins == 24
    # the bin means follow the effect (up to the mean of the residual)
    assert np.corrcoef(d.means, d.centers**2)[0, 1] > 0.9
    pv = [dependence(rng.normal(0, 1, n), x).p_value for _ in range(20)]
    assert min(pv) > 1e-4  # 20 noise draws: none looks significant
    s = np.sign(x)
    dd = dependence(noise + 0.3 * s, s, discrete=True)
    assert dd.n_bins == 2 and dd.p_value < 1e-10


def test_effective_n_of_correlated_noise():
    rng = np.random.default_rng(2)
    e = rng.normal(0, 1, 20000)
    assert effective_n(e) == pytest.approx(20000, rel=0.05)
    ar = np.empty_like(e)
    ar[0] = e[0]
    for i in range(1, e.size):
        ar[i] = 0.9 * ar[i - 1] + e[i]
    assert effective_n(ar) == pytest.approx(20000 * 0.1 / 1.9, rel=0.15)


def test_periodogram_recovers_an_unknown_period_on_uneven_samples():
    rng = np.random.default_rng(3)
    q = np.sort(rng.uniform(0, 3.0, 6000))
    r = 0.3 * np.sin(2 * np.pi * q / 0.0731 + 1.0) + rng.normal(0, 1, q.size)
    pg = periodogram(r, q)
    assert pg.peak_period == pytest.approx(0.0731, rel=0.01)
    assert pg.false_alarm < 1e-6
    assert 0.02 < pg.peak_power < 0.08  # 0.045 / 1.045 of the variance
    noise = periodogram(rng.normal(0, 1, q.size), q)
    assert noise.false_alarm > 1e-3


def test_diagnose_ranks_the_variable_the_residual_depends_on():
    s = _signals()
    rng = np.random.default_rng(4)
    r = 2.0 * np.exp(-s.t / 8.0) + rng.normal(0, 1, len(s))
    diag = diagnose(r, s)
    assert diag.table[0].variable == "time"
    assert [d.variable for d in diag.significant][:1] == ["time"]
    # without the model's load prediction there is no load nor quadrant (never the torque)
    assert {d.variable for d in diag.table} == set(VARIABLES) - {"load", "quadrant"}
    pred = Prediction([RigidBody(True)], np.array([30.0, 200.0, 0.0]))
    assert {d.variable for d in diagnose(r, s, tau_out=pred).table} == set(VARIABLES)
    assert "time" in diag.format_table()
    assert diag.to_json()[0]["variable"] == "time"


def _bump_design(with_bump: bool):
    """A revolute joint whose torque holds a localised position bump nobody declares."""
    n, dt = 60000, 0.001
    t = np.arange(n) * dt
    q = 1.0 * np.sin(2 * np.pi * 0.1 * t) + 0.2 * np.sin(2 * np.pi * 0.37 * t)
    dq = np.gradient(q, t)
    ddq = np.gradient(dq, t)
    rng = np.random.default_rng(5)
    tau = (10 * ddq + 50 * np.cos(q) + 5 * np.sign(dq) + 3 * dq + 1.0
           + rng.normal(0, 0.5, n))
    if with_bump:
        tau = tau + 4.0 * np.exp(-(((q - 0.3) / 0.15) ** 2))
    z = np.zeros(n)
    s = Signals(t, q, z, z, tau, z, z, np.zeros(n, int), revolute=True)
    lib = Library(RigidBody(True), Coulomb(), Viscous(), Offset())
    return build_design(lib, s, cutoff_hz=10.0, decimation=10, dq_min=0.02), lib


def test_unnamed_effect_is_caught_by_a_generic_basis_and_said_so():
    d, lib = _bump_design(True)
    R = refine(d, IdentModel(lib), max_steps=3)
    assert R.steps, R.format_report()
    first = R.steps[0]
    # the generic hinge basis or the library's position basis (they compete on held-out error)
    assert first.generic and first.effect.startswith(("generic_position", "library_position"))
    assert first.variable == "position"
    assert "generic basis" in R.format_report()
    assert R.rel_error_final < 0.8 * R.rel_error_initial
    assert R.to_json()["steps"][0]["generic"] is True


def test_clean_synthetic_data_get_no_step_and_max_steps_zero_is_a_plain_fit():
    d, lib = _bump_design(False)
    R = refine(d, IdentModel(lib), max_steps=3)
    assert R.steps == [], R.format_report()
    R0 = refine(d, lib, max_steps=0)
    assert R0.steps == [] and R0.final_model.rel_error_ == pytest.approx(R.rel_error_initial)
    assert "step limit" in R0.stop_reason


def test_plots_are_written_for_every_step_and_the_final_residual(tmp_path):
    from ident.refine_plots import plot_refinement

    d, lib = _bump_design(True)
    R = refine(d, IdentModel(lib), max_steps=1)
    paths = plot_refinement(R, tmp_path / "plots")
    names = [p.name for p in paths]
    # a structure found by the library search also gets its profile
    structure = ["refine_step1_structure.png"] if R.steps[0].effect.startswith("library") else []
    assert names == ["refine_step1_residual.png", "refine_step1_periodogram.png", *structure,
                     "refine_final_residual.png", "refine_final_periodogram.png"]
    for p in paths:
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000


def test_f_test_of_a_larger_model_that_fits_worse_is_zero_not_negative():
    """A candidate whose exact refit leaves more residual than the current model (its rows or
    q_s differ) gives no evidence: F = 0, p = 1, never a negative F in the report."""
    from ident.refine import _f_test

    F, p = _f_test(10.0, 10.5, 2, 5, 1000, 800.0)
    assert (F, p) == (0.0, 1.0)
    F, p = _f_test(10.0, 9.0, 2, 5, 1000, 1000.0)
    assert F > 0 and 0.0 < p < 1.0
    assert F == pytest.approx((1.0 / 2) / (9.0 / 993))
