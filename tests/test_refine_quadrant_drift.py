"""The refinement says when the declared model's quadrants are not its own (found by a
stranger's sweep): on a friction-dominated joint without any undeclared effect (c_m = 60 N m
against MX g = 20 N m, tests/test_friction_dominated.py) the paper model's P+/P- columns took
their quadrant from a first usual fit's load, which puts MX at 3.35 kg m (true 2.0; the paper
fit's own MX is 2.1). On the 2.4 % of the rows whose quadrant the paper fit's own load
decides otherwise, its dry friction acts with the other quadrant's values, and the refinement
added a 10-hinge basis in position (2.26 % -> 1.99 %) to a plant that has no position effect.
The refinement measures that share (``quadrant_drift``) and its report says that an added term
may stand in for those rows; and :func:`ident.fitting.fit_models` now leaves the paper
model's rows near zero load out where the sign check is skipped (the quadrant band), and
decides the quadrants again by the paper fit's own load if they still differ
(``REQUADRANT_PASSES``): the same data then have no drift and no position basis. What the
refinement then still added there (seeds 4 and 6: a torque lag of about 4 ms; seed 4: 0.81 ->
0.76 %) did not come from the rows near zero load (the refinement judges the band's rows
only) but from the plant's applied-torque noise, which in closed loop is both in the
residual and, through the measured acceleration, in the lag's column dtau_hat/dt (without
that noise no lag is proposed); a torque lag must now also pass the error rule with its
column on the motion band (``ident.refine._MotionPart``), and nothing is added (seeds 4, 6,
11). Positive controls on the same joint: a 5 ms torque lag and the example's ripple are
found (docs/refinement.md, section 6).
"""

from __future__ import annotations

import re
import tomllib

import pytest
from example_campaign import ROOT, payload_experiments
from test_friction_dominated import FRICTION_DOMINATED

from daq.protocol.control import ControllerGains
from ident.fitting import fit_models
from ident.models import IdentModel
from ident.refine import quadrant_drift, refine
from ident.refine_result import QUADRANT_DRIFT_SHOWN
from sim_drivers.plant_config import load_plant
from trajectories.plan import plan_campaign
from trajectories.robot_campaign import RobotCampaign

#: Undeclared effects switched on for the positive controls: a plant-file table each (the
#: example plant's own ripple table, 2.5 N m, period 2 pi / 16 rad, phase 0.5 rad, is kept
#: on for ``position_ripple``).
EFFECTS = {
    "torque_lag": "\n[effects.torque_lag]\nenabled = true\ntime_constant_s = 0.005\n",
    "position_ripple": "",
}


def _plant_and_plan(tmp_path, friction_dominated: bool, effect: str = ""):
    """The example plant without its ripple (no undeclared effect) or with ``effect`` (a key
    of :data:`EFFECTS`) alone, friction-dominated or not, and the example campaign (its
    feed-forward matched to the plant)."""
    txt = (ROOT / "examples" / "plant_rx130l.toml").read_text()
    if effect != "position_ripple":
        txt = txt.replace("enabled = true", "enabled = false")
    with open(ROOT / "examples" / "campaign.toml", "rb") as fh:
        d = tomllib.load(fh)
    if friction_dominated:
        for k, v in FRICTION_DOMINATED.items():
            txt, n = re.subn(rf"^{k} = [-0-9.]+", f"{k} = {v}", txt, flags=re.M)
            assert n == 1, k
        d["control"]["feedforward"].update(J=3.0, MX=2.0, Fc=60.0, Fv=20.0)
    path = tmp_path / "plant.toml"
    path.write_text(txt + EFFECTS.get(effect, ""))
    plant = load_plant(path)
    assert plant.effects.enabled() == ((effect,) if effect else ())  # only that one
    camp = RobotCampaign.from_dict(d, "quadrant-drift")
    return plant, plan_campaign(camp), ControllerGains(**camp.gains_kwargs())


def _refined(tmp_path, friction_dominated: bool, seed: int, first_quadrants: bool = False,
             effect: str = ""):
    plant, plan, gains = _plant_and_plan(tmp_path, friction_dominated, effect)
    exps = payload_experiments(plant, plan, gains, 10 * seed, name="p{i}.csv")
    if not first_quadrants:
        rep = fit_models(exps, ("paper",), table_iv=False)
    else:  # the first usual fit's quadrants on every row, as before the band and the passes
        import ident.fitting as fitting
        import ident.one_joint as one_joint

        saved = fitting.REQUADRANT_PASSES, one_joint.SKIPPED_CHECK_BAND
        fitting.REQUADRANT_PASSES, one_joint.SKIPPED_CHECK_BAND = 0, 0.0
        try:
            rep = fit_models(exps, ("paper",), table_iv=False)
        finally:
            fitting.REQUADRANT_PASSES, one_joint.SKIPPED_CHECK_BAND = saved
    d, m = rep.designs["paper"], rep.models["paper"]
    R = refine(d, IdentModel(m.library, "paper"), max_steps=1)
    return rep, R


@pytest.mark.slow
@pytest.mark.parametrize("seed", [4, 6, 11])
def test_friction_dominated_joint_settles_its_quadrants(tmp_path, seed):
    """The fit decides its quadrants by its own load: no drift, no note, no position basis
    (the false discovery of the first fit's quadrants); and the plant has no undeclared
    effect, so nothing is added: the torque lag that stood in for the applied-torque noise
    shared by the residual and dtau_hat/dt (4 ms on seeds 4 and 6) is refused, its column
    on the motion band explaining almost nothing (seed 11 was not looked at while the rule
    was written)."""
    rep, R = _refined(tmp_path, True, seed)
    assert any(n.startswith("sign check skipped") for n in rep.notes), rep.notes
    assert any(n.startswith("paper model: rows near zero load left out") for n in rep.notes)
    assert R.quadrant_drift_initial is not None
    assert R.quadrant_drift_initial < QUADRANT_DRIFT_SHOWN
    assert "own fitted load puts" not in R.format_report()
    assert R.steps == [], R.format_report()
    lag = [r for r in R.rejected if r.effect == "torque_lag"]
    if lag:  # where the lag passed the error rule, the motion band refused it
        assert all("motion band" in r.reason or "F test" in r.reason
                   or "less than" in r.reason for r in lag), [r.reason for r in lag]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [4, 6, 11])
def test_friction_dominated_joint_finds_a_real_lag(tmp_path, seed):
    """Positive control of the motion-band rule: the same joint with a 5 ms torque lag in the
    plant. The lag is found at step 1 and named; its estimate is biased high on this light
    arm (measured 7.22 +- 0.12 ms (2 sigma) on seed 4, docs/refinement.md): the test checks
    it is found and lies between the truth and twice it, not within its sigma. No estimate
    measured is within 2 sigma of 5 ms (benchmarks/refine_lag_noise.py, seeds 4, 6, 11):
    instrumental variables with the lag's motion band as instrument give 6.84 +- 0.18 ms,
    with the reference trajectory's states 6.27 +- 0.25 (seed 4); without the plant's noise
    the estimates span 4.92 to 6.31 ms (the held command's half cycle, 0.5 ms, adds to the
    staged lag, and the first-order form is itself off by about 0.5 ms)."""
    rep, R = _refined(tmp_path, True, seed, effect="torque_lag")
    assert R.steps, R.format_report()
    st = R.steps[0]
    assert st.effect == "torque_lag" and st.physical_range is None, R.format_report()
    T = st.parameters["T_lag"]["value"]
    assert 0.005 < T < 0.010, R.format_report()
    # the user is told that the 2 sigma does not cover this bias: report text and JSON
    assert "note: T_lag's 2σ covers the estimate's noise, not the lag model's" in (
        R.format_report()), R.format_report()
    assert st.to_json()["sigma_note"].startswith("T_lag's 2σ covers")


@pytest.mark.slow
def test_friction_dominated_joint_finds_a_real_ripple(tmp_path):
    """Positive control: the same joint with the example's position ripple (2.5 N m, period
    2 pi / 16 rad, phase 0.5 rad): found at step 1, its amplitude within 2 sigma (seed 4:
    2.511 +- 0.012), its period within 1 % as the demo's test asks (0.39292 +- 0.00014 for
    0.39270: 3 sigma, the linearised sigma of the scanned period is optimistic)."""
    rep, R = _refined(tmp_path, True, 4, effect="position_ripple")
    assert R.steps, R.format_report()
    st = R.steps[0]
    assert st.effect == "position_ripple", R.format_report()
    par = st.parameters
    amp = par["ripple_amplitude"]
    assert abs(amp["value"] - 2.5) < amp["std2"], amp
    assert par["ripple_period"]["value"] == pytest.approx(0.39269908169872414, rel=0.01)


@pytest.mark.slow
def test_friction_dominated_joint_reports_its_unsettled_quadrants(tmp_path):
    """The quadrants left as the first usual fit's load decided them (no re-decision): the
    report says an added term may stand in for the rows in another quadrant."""
    seed = 4
    rep, R = _refined(tmp_path, True, seed, first_quadrants=True)
    assert any(n.startswith("sign check skipped") for n in rep.notes), rep.notes
    # some rows change quadrant under the paper fit's own load: the first fit's MX is far
    # from the truth (2.0) where the dry friction dominates
    assert R.quadrant_drift_initial is not None
    assert R.quadrant_drift_initial >= QUADRANT_DRIFT_SHOWN
    text = R.format_report()
    js = R.to_json()
    assert js["quadrant_drift_initial"] == pytest.approx(R.quadrant_drift_initial)
    # the plant has no undeclared effect: a step is added only with the note saying why
    if R.steps:
        assert "own fitted load puts" in text and "may stand in" in text, text
    assert f"{100 * R.quadrant_drift_initial:.1f} % of the rows" in text


@pytest.mark.slow
def test_settled_quadrants_add_no_note_and_nothing(tmp_path):
    """The example joint (load well above the friction, sign check applied) has no
    undeclared effect here: its quadrants are its own (0.004 % of the rows move, a few
    where the load is near zero), no note, no step."""
    rep, R = _refined(tmp_path, False, 2)
    assert not any(n.startswith("sign check skipped") for n in rep.notes), rep.notes
    # a few rows where the load is near zero, below the report's 0.1 % precision
    assert 0.0 <= R.quadrant_drift_initial < QUADRANT_DRIFT_SHOWN
    assert "own fitted load puts" not in R.format_report()
    assert R.steps == [], R.format_report()


def test_a_design_without_fixed_quadrants_has_no_drift():
    from refine_cases import case_design

    d, lib = case_design("clean", 0)
    m = IdentModel(lib, "usual").fit(d, eliminate=False)
    assert quadrant_drift(d, lib, m.coef_) is None
