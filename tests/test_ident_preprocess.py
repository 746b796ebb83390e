"""Preprocessing: central differences, decimation (MATLAB behaviour), parallel filtering of
Y and W, selection masks, Design.with_term / without."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.signal

from ident import DataError
from ident.loaders import concat, make_experiment
from ident.models import Coulomb, IdentModel, Offset, RigidBody, Viscous, usual_model
from ident.preprocess import build_design, choose_cutoff, decimate, diffcent


def test_diffcent_matches_matlab_definition():
    y = np.array([0.0, 1.0, 4.0, 9.0, 16.0])
    np.testing.assert_allclose(diffcent(y, 0.5), [2.0, 4.0, 8.0, 12.0, 14.0])


def test_decimate_passes_band_kills_alias_and_keeps_last_sample():
    fs, r = 1000.0, 10
    t = np.arange(10001) / fs
    low = np.sin(2 * np.pi * 3.0 * t)
    high = np.sin(2 * np.pi * 180.0 * t)  # above the new Nyquist (50 Hz)
    y, idx = decimate(np.column_stack([low, high]), r)
    assert idx[-1] == t.size - 1 and np.all(np.diff(idx) == r)
    inner = slice(20, -20)
    # MATLAB/scipy decimate: Chebyshev I (0.05 dB ripple) forward-backward, same samples,
    # but normalised to unit DC gain (scipy's design has 10^(-0.05/20) per pass)
    ref = scipy.signal.decimate(low, r, ftype="iir", zero_phase=True) / 10 ** (-0.1 / 20)
    np.testing.assert_allclose(y[50:-50, 0], ref[50:-50], atol=2e-4)
    np.testing.assert_allclose(y[inner, 0], low[idx][inner], atol=0.012)  # ripple^2 <= 1.2 %
    assert np.max(np.abs(y[inner, 1])) < 1e-3
    # unit DC gain: a constant and a ramp (slow position) come out unscaled, in one stage
    # and in two (r = 40: 10 x 4)
    for rr in (10, 40):
        ramp = 0.3 + 0.5 * t
        yc, ic = decimate(np.column_stack([np.full_like(t, 2.5), ramp]), rr)
        np.testing.assert_allclose(yc[30:-30, 0], 2.5, rtol=1e-9)
        np.testing.assert_allclose(yc[30:-30, 1], ramp[ic][30:-30], rtol=1e-5)
    # staged decimation for factors above 13
    y2, idx2 = decimate(low, 40)
    assert np.all(np.diff(idx2) == 40)
    np.testing.assert_allclose(y2[5:-5], low[idx2][5:-5], atol=0.025)


def test_cutoff_never_below_a_twentieth_of_fs():
    t = np.arange(20000) * 1e-3
    assert choose_cutoff(np.sin(0.5 * t), 1e-3) == pytest.approx(50.0)


def test_cutoff_warns_at_its_bound_unless_told_not_to():
    """The bound's warning names the bound; ``warn=False`` (the refinement's motion band,
    which must not wrap the call in catch_warnings) gives the same value silently."""
    q = np.sin(0.5 * np.arange(20000) * 1e-3)
    with pytest.warns(UserWarning, match=r"is the lower bound 0\.05 f_s"):
        loud = choose_cutoff(q, 1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert choose_cutoff(q, 1e-3, warn=False) == loud


def _exp(seed=0, n=8000, dt=1e-3, mass=0.0):
    t = np.arange(n) * dt
    q = 0.8 * np.sin(1.3 * t) + 0.2 * np.sin(5.1 * t + seed)
    dq = 0.8 * 1.3 * np.cos(1.3 * t) + 0.2 * 5.1 * np.cos(5.1 * t + seed)
    ddq = -0.8 * 1.69 * np.sin(1.3 * t) - 0.2 * 26.01 * np.sin(5.1 * t + seed)
    tau = 30 * ddq + 200 * np.cos(q) + 40 * dq + 20 * np.sign(dq) + 10
    return make_experiment(f"e{seed}", t, q, tau, payload_mass=mass, payload_arm=1.0)


def test_build_design_recovers_smooth_model_and_shapes():
    s = concat([_exp(0), _exp(1)])
    lib = RigidBody() + Viscous() + Offset()
    d = build_design(lib, s, cutoff_hz=50, decimation=5, trim=100, guard=0)
    assert d.W.shape == (d.Y.size, 5) and d.names == lib.names()
    assert len(d.signals) == d.Y.size
    # per experiment: (n - 2 trim) / r samples
    assert d.Y.size == 2 * len(range((8000 - 200 - 1) % 5, 8000 - 200, 5))
    assert set(np.unique(d.signals.experiment)) == {0, 1}
    m = IdentModel(lib + Coulomb()).fit(d.with_term(Coulomb()), eliminate=False)
    assert m.coef_["J"] == pytest.approx(30, rel=2e-3)
    assert m.coef_["MX"] == pytest.approx(200 / 9.81, rel=2e-3)
    assert m.coef_["F_V"] == pytest.approx(40, rel=5e-3)


def test_selection_mask_is_shared_by_y_and_every_column():
    s = concat([_exp(0)])
    d = build_design(usual_model(payload=False), s, cutoff_hz=50, decimation=5, dq_min=0.3)
    full = build_design(usual_model(payload=False), s, cutoff_hz=50, decimation=5)
    assert d.Y.size < full.Y.size
    assert np.all(np.abs(d.signals.dq) >= 0.3)
    # the kept samples are a subset of the unselected design, identical in Y and every column
    key = {round(t, 9): i for i, t in enumerate(full.signals.t)}
    rows = [key[round(t, 9)] for t in d.signals.t]
    np.testing.assert_array_equal(d.Y, full.Y[rows])
    np.testing.assert_array_equal(d.W, full.W[rows])


def test_with_term_equals_building_with_the_term_and_without_drops():
    s = concat([_exp(0), _exp(2)])
    kw = dict(cutoff_hz=50, decimation=5, dq_min=0.1, trim=40)
    base = build_design(RigidBody() + Offset(), s, **kw)
    both = build_design(RigidBody() + Offset() + Coulomb(), s, **kw)
    added = base.with_term(Coulomb())
    assert added.names == both.names
    np.testing.assert_allclose(added.W, both.W, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(added.Y, both.Y)
    dropped = added.without(["F_C"])
    assert dropped.names == base.names
    np.testing.assert_array_equal(dropped.W, base.W)
    with pytest.raises(DataError, match="already"):
        added.with_term(Coulomb())
    with pytest.raises(DataError, match="not in the design"):
        added.without(["nope"])


def test_too_few_samples_after_trim_is_a_clear_error():
    s = concat([_exp(0, n=300)])
    with pytest.raises(DataError, match="too few"):
        build_design(usual_model(), s, cutoff_hz=50, decimation=10, trim=140)


def test_shift_interpolates_half_a_sample_exactly_for_cubics():
    from ident.preprocess import shift

    dt = 1e-3
    t = np.arange(200) * dt
    for d in (0.5, 0.25):
        cubic = 3 + 2 * t - 40 * t**2 + 900 * t**3
        tt = t + d * dt
        np.testing.assert_allclose(
            shift(cubic, d)[1:-2], (3 + 2 * tt - 40 * tt**2 + 900 * tt**3)[1:-2], rtol=1e-12
        )
    x = np.sin(2 * np.pi * 5 * t)
    assert shift(x, 0.0) is x or np.array_equal(shift(x, 0.0), x)
    with pytest.raises(DataError, match="torque_delay"):
        shift(x, 1.0)


def test_torque_delay_aligns_a_held_command_with_the_motion():
    """A zero-order-held torque over [t_k, t_k+dt] from an exact integration: with the
    half-cycle delay the inertia and viscous terms come out right, without it F_V is off
    by J/T-scale terms (the lag of dq, ddq behind the torque)."""
    dt, n = 1e-3, 20000
    rng = np.random.default_rng(4)
    J, fv = 30.0, 40.0
    k = np.arange(n)
    tau = 300 * np.sin(2 * np.pi * 1.3 * k * dt) + 200 * np.sin(2 * np.pi * 7.1 * k * dt + 1)
    tau += rng.normal(0, 5, n)
    q, v = np.zeros(n), 0.0
    a_ = np.exp(-fv / J * dt)
    qk = 0.0
    for i in range(n):  # exact solution of J ddq + fv dq = tau_i over the cycle
        q[i] = qk
        vinf = tau[i] / fv
        v_new = vinf + (v - vinf) * a_
        qk += vinf * dt + (v - vinf) * (1 - a_) * J / fv
        v = v_new
    e = make_experiment("held", k * dt, q, tau, revolute=False)
    s = concat([e])
    lib = RigidBody(False) + Viscous()
    fits = {}
    for d in (0.0, 0.5):
        des = build_design(lib, s, cutoff_hz=100, decimation=10, torque_delay=d)
        fits[d] = IdentModel(lib).fit(des, eliminate=False).coef_
        assert des.settings()["torque_delay"] == d
    assert fits[0.5]["J"] == pytest.approx(J, rel=2e-3)
    assert fits[0.5]["F_V"] == pytest.approx(fv, rel=2e-3)
    assert abs(fits[0.0]["F_V"] - fv) > 5 * abs(fits[0.5]["F_V"] - fv)


def test_reference_instruments_follow_the_design_through_its_edits():
    s = concat([_exp(0), _exp(2)])
    kw = dict(cutoff_hz=50, decimation=5, dq_min=0.1, trim=40)
    ref = s.q + 1e-3 * np.sin(7 * s.t)  # a reference close to the motion
    base = build_design(RigidBody() + Offset(), s, reference=ref, **kw)
    both = build_design(RigidBody() + Offset() + Coulomb(), s, reference=ref, **kw)
    assert base.Z.shape == base.W.shape and base.settings()["instruments"] == "reference"
    # only the acceleration column differs from W; the others are the same samples
    j = base.names.index("J")
    others = [i for i in range(len(base.names)) if i != j]
    np.testing.assert_array_equal(base.Z[:, others], base.W[:, others])
    assert not np.allclose(base.Z[:, j], base.W[:, j])
    added = base.with_term(Coulomb())
    np.testing.assert_allclose(added.Z, both.Z, rtol=1e-12, atol=1e-12)
    dropped = added.without(["F_C"])
    np.testing.assert_array_equal(dropped.Z, base.Z)
    sel = base.select(dq_min=0.3)
    assert sel.Z.shape == sel.W.shape and sel.Z.shape[0] < base.Z.shape[0]
    # without a cut-off the floor rises to f_s/8 with instruments (f_s/20 without)
    assert build_design(RigidBody(), s, reference=ref).cutoff_hz == pytest.approx(125.0)
    assert build_design(RigidBody(), s).cutoff_hz == pytest.approx(50.0)
    with pytest.raises(DataError, match="reference has"):
        build_design(RigidBody(), s, reference=ref[:-1])
    bad = ref.copy()
    bad[5] = np.nan
    with pytest.raises(DataError, match=r"references: 1 NaN/inf values \(first in experiment "
                                        f"{int(s.experiment[5])};"):
        build_design(RigidBody(), s, reference=bad)
