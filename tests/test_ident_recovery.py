"""Acceptance: parameter recovery on the simulated joint (three payloads, no undeclared
effect, the drive chain's quantisation and torque noise), with the plant's truth.

The runs come from the offline closed-loop simulator (controller + plant, encoder counts,
per-mille torque reference), i.e. what ``jointid run`` logs minus the bus, with the planned
reference trajectory (the MCAP ``/setpoint`` channel) for the IDIM-IV instruments.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest
from example_campaign import simulate_example_campaign

from ident.fitting import fit_models
from ident.loaders import make_experiment

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def sim():
    plant, plan, runs = simulate_example_campaign(11)
    exps, refs = [], []
    for i, (p, r) in enumerate(zip(plan.payloads, runs, strict=True)):
        exps.append(make_experiment(f"payload{i}", r.t, r.q, r.tau_ref,
                                    payload_mass=p.mass_kg, payload_arm=p.arm_m))  # fmt: skip
        refs.append(plan.reference.q)
    return plant, exps, refs


#: The simulator's timing, like the runner's: the command computed from the position of
#: cycle k is held over cycle k (what ``torque_delay="auto"`` assumes for MCAP logs).
SIM = dict(torque_delay=0.5)


@pytest.fixture(scope="module")
def report(sim):
    plant, exps, refs = sim
    # the acceptance compares identified values with the truth: keep every identifiable
    # parameter (elimination drops weak but real terms, which then bias the others)
    return fit_models(exps, q_s=plant.joint.q_s, eliminate=False, references=refs, **SIM)


@pytest.fixture(scope="module")
def report_ols(sim):
    plant, exps, _ = sim
    return fit_models(exps, ("paper",), q_s=plant.joint.q_s, eliminate=False, references=None,
                      table_iv=False, **SIM)  # fmt: skip


def _z(model, truth):
    out = {}
    for n in model.names_:
        err = model.coef_[n] - truth[n]
        out[n] = (err / model.std_[n], abs(err) / abs(truth[n]))
    return out


def test_new_model_parameters_within_3_sigma_or_1_percent(sim, report):
    """Issue 5's acceptance, every parameter of eq. 43 included (the E_xp ddq ones too)."""
    plant, _, _ = sim
    m = report.models["paper"]
    assert m.estimator_ == "iv" and report.designs["paper"].settings()["instruments"] == "reference"
    truth = plant.truth()
    assert set(m.names_) == set(truth), "every parameter of eq. 43 is identifiable"
    z = _z(m, truth)
    bad = {n: z[n] for n in m.names_ if abs(z[n][0]) > 3 and z[n][1] > 0.01}
    assert not bad, f"outside 3 sigma and 1 %: {bad}"
    # the E_xp ddq terms are identified, not just wide: their 2 sigma is below 100 %
    assert all(m.rel_std_pct_[n] < 50 for n in ("b_m_J", "b_g_J"))


def test_ordinary_least_squares_is_biased_on_exp_inertia_terms(sim, report_ols):
    """Why the instruments: in closed loop the measured motion holds the response to the
    applied-torque noise, the logged torque reference does not (errors in variables). OLS
    puts b_m_J and b_g_J hundreds of percent (tens of sigma) off; the others stay close."""
    plant, _, _ = sim
    m = report_ols.models["paper"]
    assert m.estimator_ == "ls"
    z = _z(m, plant.truth())
    assert abs(z["b_m_J"][0]) > 10 and z["b_m_J"][1] > 1.0
    assert abs(z["b_g_J"][0]) > 10 and z["b_g_J"][1] > 1.0
    others = [n for n in m.names_ if n not in ("b_m_J", "b_g_J")]
    assert all(abs(z[n][0]) <= 3 or z[n][1] <= 0.01 for n in others)


def test_new_model_halves_low_velocity_error(report):
    eu, en = report.errors("usual"), report.errors("paper")
    assert en["low"] <= 0.5 * eu["low"]
    assert en["all"] < eu["all"]
    # Table IV is computed: the runs without payload alone
    assert report.table_iv is not None
    assert set(report.table_iv["without_payload"]) == {"usual", "paper"}


def test_usual_model_payload_ratio_and_json_record(report):
    u = report.models["usual"]
    assert u.coef_["Ma_ratio"] == pytest.approx(1.0, abs=0.02)
    js = report.to_json()
    for name in ("usual", "paper"):
        rec = js["models"][name]
        for key in ("rel_error", "rel_error_low_velocity", "rel_error_high_velocity"):
            assert 0 < rec[key] < 0.1
        p = rec["parameters"]["F_V"]
        assert p["std2"] == pytest.approx(2 * p["std"]) and p["rel_std_pct"] > 0
    assert js["models"]["paper"]["q_s"] == 0.03


def test_default_elimination_keeps_parameters_significant(sim):
    plant, exps, refs = sim
    rep = fit_models(exps[:2], models=("paper",), q_s=plant.joint.q_s, references=refs[:2], **SIM)
    m = rep.models["paper"]
    assert all(v <= 30 for v in m.rel_std_pct_.values())
    assert all("relative deviation" in why for _, why in m.removed_)
    assert np.isfinite(m.rel_error_)


def test_qs_rescanned_after_refinement_recovers_the_plant():
    """The demo's situation: quick campaign, a position ripple no model declares, q_s
    scanned. The scan with the declared model alone is pulled off by the ripple left in the
    residual (+36 % here); once refinement has modelled the ripple,
    :meth:`ident.fitting.FitReport.rescan_found_terms` (the found term refitted inside the
    joint's robot model at each q_s) brings q_s back to +10 % and the q_s-sensitive b terms
    of eq. 42 much closer. What is left is the quick campaign's own limit: little data near
    q_s, and the residual criterion then lands 5-15 % high (0.0326 on these runs without any
    effect; the full campaign gives 0.0300), so b_m_MX stays 3.5 sigma off."""
    from daq.protocol.control import ControllerGains
    from ident.refine import refine
    from sim_drivers.offline import simulate
    from sim_drivers.plant_config import load_plant
    from trajectories.plan import plan_campaign
    from trajectories.robot_campaign import RobotCampaign

    with open(ROOT / "examples" / "campaign.toml", "rb") as f:
        campaign = RobotCampaign.from_dict(tomllib.load(f), "examples/campaign.toml").quick()
    plan = plan_campaign(campaign)
    plant = load_plant(ROOT / "examples" / "plant_rx130l.toml")
    assert plant.effects.position_ripple.enabled
    gains = ControllerGains(**campaign.gains_kwargs())
    exps = []
    for i, p in enumerate(plan.payloads):
        r = simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                     payload_arm=p.arm_m, seed=11 + i)  # fmt: skip
        exps.append(make_experiment(f"payload{i}", r.t, r.q, r.tau_ref,
                                    payload_mass=p.mass_kg, payload_arm=p.arm_m))  # fmt: skip
    rep = fit_models(exps, ("paper",), q_s="scan", references=[plan.reference.q] * 3,
                     table_iv=False, **SIM)  # fmt: skip
    ref = refine(rep.designs["paper"], rep.models["paper"], vmax=rep.vmax)
    assert "position_ripple" in [s.term.effect for s in ref.steps]
    rs = rep.rescan_found_terms("paper", ref.terms, ref.final_design)
    q_s = plant.joint.q_s
    # the quick campaign has little data near q_s: without any effect its scan lands 5-10 %
    # high (0.0326 on these runs), with the ripple left in the residual 36 % high
    assert abs(rep.q_s / q_s - 1) > 0.2 and abs(rs.q_s / q_s - 1) < 0.15
    assert [q for q, _ in rs.scan] == sorted(q for q, _ in rs.scan)
    truth = plant.truth()

    def rel_err(coef):
        return {n: abs(coef[n] - t) / abs(t) for n, t in truth.items()}

    pars = rs.record["parameters"]
    before = rel_err(ref.final_model.coef_)
    after = rel_err({n: p["value"] for n, p in pars.items()})
    sensitive = ("b_m_MX", "b_g_MX", "b_m", "b_g", "b_m_J")
    assert all(after[n] < before[n] for n in sensitive)
    assert sum(after[n] for n in sensitive) < 0.5 * sum(before[n] for n in sensitive)
    z = {n: abs(pars[n]["value"] - t) / pars[n]["std"] for n, t in truth.items()}
    assert max(z.values()) < 4.5, z
