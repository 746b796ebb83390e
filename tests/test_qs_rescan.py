"""The q_s rescan's fast designs are :func:`ident.fitting.with_qs`'s, bit for bit (issue 23:
the rescan builds only the columns that carry E = exp(-|dq|/q_s) for each q_s)."""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from daq.protocol.control import ControllerGains
from ident import DataError
from ident.fitting import fit_models, rescan_qs, with_qs
from ident.loaders import make_experiment
from ident.models import IdentModel, LoadDependent, QuadrantCoulomb
from ident.qs_scan import _e_columns, _QsDesigns, _QsErrors
from sim_drivers.offline import simulate
from sim_drivers.plant_config import load_plant
from trajectories.plan import plan_campaign
from trajectories.robot_campaign import RobotCampaign

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def runs():
    """Two payload runs of the quick example campaign, simulated offline, and their
    reference positions."""
    with open(ROOT / "examples" / "campaign.toml", "rb") as f:
        campaign = RobotCampaign.from_dict(tomllib.load(f), "examples/campaign.toml").quick()
    plan = plan_campaign(campaign)
    plant = load_plant(ROOT / "examples" / "plant_rx130l.toml")
    gains = ControllerGains(**campaign.gains_kwargs())
    exps = []
    for i, p in enumerate(plan.payloads[:2]):
        r = simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                     payload_arm=p.arm_m, seed=3 + i)
        exps.append(make_experiment(f"payload{i}", r.t, r.q, r.tau_ref,
                                    payload_mass=p.mass_kg, payload_arm=p.arm_m))
    return exps, [plan.reference.q] * 2


@pytest.fixture(scope="module")
def fitted(runs):
    """The paper model (with its ripple-free library) fitted with instruments on the runs."""
    exps, refs = runs
    return fit_models(exps, ("paper",), q_s=0.04, references=refs, table_iv=False,
                      torque_delay=0.5)


def test_refit_like_an_earlier_report_is_the_same_fit(runs, fitted):
    """fit_models(like=report) (the demo's refit with the adjusted q_s) takes the settled
    preprocessing and the sign check's load model from the report: the same fit as from
    scratch; a report on other data is refused."""
    exps, refs = runs
    kw = dict(references=refs, table_iv=False, torque_delay=0.5)
    a = fit_models(exps, ("usual", "paper"), q_s=0.031, **kw)
    b = fit_models(exps, ("usual", "paper"), q_s=0.031, like=fitted, **kw)
    assert "load_model" in fitted.settings  # the sign check ran
    for name in ("usual", "paper"):
        assert a.models[name].coef_ == b.models[name].coef_
        assert np.array_equal(a.designs[name].W, b.designs[name].W)
        assert np.array_equal(a.designs[name].Z, b.designs[name].Z)
    assert a.notes == b.notes and a.vmax == b.vmax
    with pytest.raises(DataError, match="like="):
        fit_models(exps[:1], ("paper",), q_s=0.031, like=fitted, **{**kw, "references": refs[:1]})


def test_the_e_columns_are_the_odd_ones(fitted):
    d = fitted.designs["paper"]
    s = d._blocks[0].full
    quad = [t for t in fitted.models["paper"].library.terms()
            if isinstance(t, LoadDependent | QuadrantCoulomb)]
    assert len(quad) == 2
    for t in quad:
        a = type(t)(t.inner, 0.01, t.load) if isinstance(t, LoadDependent) else \
            QuadrantCoulomb(0.01, t.load)
        b = type(t)(t.inner, 0.1, t.load) if isinstance(t, LoadDependent) else \
            QuadrantCoulomb(0.1, t.load)
        ca, cb = a.columns(s), b.columns(s)
        fixed, with_e = _e_columns(t)
        assert sorted(fixed + with_e) == list(range(ca.shape[1]))
        for i in fixed:
            assert np.array_equal(ca[:, i], cb[:, i]), (t, i)
        for i in with_e:  # (a payload column is zero on the run without payload)
            assert not np.allclose(ca[:, i], cb[:, i]) or not ca[:, i].any(), (t, i)
        assert any(not np.allclose(ca[:, i], cb[:, i]) for i in with_e)


def test_fast_designs_equal_with_qs_bit_for_bit(fitted):
    d, lib = fitted.designs["paper"], fitted.models["paper"].library
    assert d.Z is not None  # instruments: their rows are rebuilt too
    fast = _QsDesigns(d, lib)
    for q in (0.004, 0.03, 0.25):
        l1, d1 = with_qs(d, lib, q)
        l2, d2 = fast(q)
        assert l1.names() == l2.names() and d1.names == d2.names
        assert d1.library.names() == d2.library.names()
        for a, b in ((d1.W, d2.W), (d1.Z, d2.Z), (d1.Y, d2.Y)):
            assert np.array_equal(a, b) and b.flags.c_contiguous
        for b1, b2 in zip(d1._blocks, d2._blocks, strict=True):
            assert np.array_equal(b1.dec, b2.dec) and np.array_equal(b1.zdec, b2.zdec)
        m1 = IdentModel(l1, "paper").fit(d1, eliminate=False)
        m2 = IdentModel(l2, "paper").fit(d2, eliminate=False)
        assert m1.rel_error_ == m2.rel_error_ and m1.coef_ == m2.coef_


def test_rescan_keeps_its_result_and_refits_with_the_chosen_qs(fitted):
    d, m = fitted.designs["paper"], fitted.models["paper"]
    rs = rescan_qs(d, m, vmax=fitted.vmax)
    lq, dq_ = with_qs(d, m.library, rs.q_s)
    ref = IdentModel(lq, m.name).fit(dq_, eliminate=False)
    assert rs.model.rel_error_ == ref.rel_error_ == min(e for _, e in rs.scan)
    assert [q for q, _ in rs.scan] == sorted(q for q, _ in rs.scan)


def test_scan_errors_equal_the_fits_bit_for_bit(fitted):
    """The scan's error of each q_s (:class:`ident.fitting._QsErrors`, without the design
    nor the statistics) is the full-model fit's float, with and without instruments."""
    d, lib = fitted.designs["paper"], fitted.models["paper"].library
    for des in (d, replace(d, Z=None)):
        fast = _QsDesigns(des, lib)
        errors = _QsErrors(fast, lib.names())
        for q in (0.004, 0.03, 0.25):
            l1, d1 = fast(q)
            m = IdentModel(l1, "paper").fit(d1, eliminate=False)
            assert errors(q) == m.rel_error_, (q, des.Z is None)
