"""Acceptance: parameter recovery on the simulated joint (three payloads, no undeclared
effect, the drive chain's quantisation and torque noise), with the plant's truth.

The runs come from the offline closed-loop simulator (controller + plant, encoder counts,
per-mille torque reference), i.e. what ``jointid run`` logs minus the bus.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from ident.fitting import fit_models
from ident.loaders import make_experiment

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def sim():
    from daq.control import ControllerGains
    from sim_drivers.offline import simulate
    from sim_drivers.plant_config import load_plant
    from trajectories.campaign import Campaign
    from trajectories.plan import plan_campaign

    with open(ROOT / "examples" / "campaign.toml", "rb") as f:
        campaign = Campaign.from_dict(tomllib.load(f), "examples/campaign.toml")
    plan = plan_campaign(campaign)
    plant = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml")
    gains = ControllerGains(**campaign.control.gains_kwargs())
    exps = []
    for i, p in enumerate(plan.payloads):
        r = simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                     payload_arm=p.arm_m, seed=11 + i)  # fmt: skip
        exps.append(make_experiment(f"payload{i}", r.t, r.q, r.tau_ref,
                                    payload_mass=p.mass_kg, payload_arm=p.arm_m))  # fmt: skip
    return plant, exps


@pytest.fixture(scope="module")
def report(sim):
    plant, exps = sim
    # the acceptance compares identified values with the truth: keep every identifiable
    # parameter (elimination drops weak but real terms, which then bias the others)
    return fit_models(exps, qs=plant.joint.q_s, eliminate=False)


def _z(model, truth):
    out = {}
    for n in model.names_:
        err = model.coef_[n] - truth[n]
        out[n] = (err / model.std_[n], abs(err) / abs(truth[n]))
    return out


#: E_xp * ddq columns (b_m_J, b_g_J) live on the low-velocity accelerations: breakaway from
#: stiction, reversals, quadrant changes, where ddq jumps. The q low-pass smears these
#: jumps (the columns are nonlinear in the filtered signals) and a wider band lets the
#: encoder quantisation and the applied-torque noise (absent from the logged reference, a
#: closed-loop errors-in-variables effect) in. Measured on this campaign: with the true
#: position and torque, b_m_J is off by 24 % at 100 Hz and 330 % at 50 Hz; with the measured
#: ones by 300-800 % at either cut-off. Both are biased, the rest is not.
KNOWN_BIASED = ("b_m_J", "b_g_J")


def test_new_model_parameters_within_3_sigma_or_1_percent(sim, report):
    plant, _ = sim
    m = report.models["new"]
    truth = plant.truth()
    assert set(m.names_) == set(truth), "every parameter of eq. 43 is identifiable"
    z = _z(m, truth)
    bad = {
        n: z[n] for n in m.names_ if n not in KNOWN_BIASED and abs(z[n][0]) > 3 and z[n][1] > 0.01
    }
    assert not bad, f"outside 3 sigma and 1 %: {bad}"


@pytest.mark.xfail(
    strict=True, reason="E_xp ddq terms: filter smear vs noise at low-velocity transients"
)
def test_new_model_exp_inertia_terms(sim, report):
    plant, _ = sim
    z = _z(report.models["new"], plant.truth())
    assert all(abs(z[n][0]) <= 3 or z[n][1] <= 0.01 for n in KNOWN_BIASED), {
        n: z[n] for n in KNOWN_BIASED
    }


def test_new_model_halves_low_velocity_error(report):
    eu, en = report.errors("usual"), report.errors("new")
    assert en["low"] <= 0.5 * eu["low"]
    assert en["all"] < eu["all"]
    # Table IV is computed: the runs without payload alone
    assert report.table_iv is not None
    assert set(report.table_iv["without_payload"]) == {"usual", "new"}


def test_usual_model_payload_ratio_and_json_record(report):
    u = report.models["usual"]
    assert u.coef_["Ma_ratio"] == pytest.approx(1.0, abs=0.02)
    js = report.to_json()
    for name in ("usual", "new"):
        rec = js["models"][name]
        for key in ("rel_error", "rel_error_low_velocity", "rel_error_high_velocity"):
            assert 0 < rec[key] < 0.1
        p = rec["parameters"]["F_V"]
        assert p["std2"] == pytest.approx(2 * p["std"]) and p["rel_std_pct"] > 0
    assert js["models"]["new"]["qs"] == 0.03


def test_default_elimination_keeps_parameters_significant(sim):
    plant, exps = sim
    rep = fit_models(exps[:2], models=("new",), qs=plant.joint.q_s)
    m = rep.models["new"]
    assert all(v <= 30 for v in m.rel_std_pct_.values())
    assert all("relative deviation" in why for _, why in m.removed_)
    assert np.isfinite(m.rel_error_)
