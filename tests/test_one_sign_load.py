"""A campaign whose load keeps one sign (found by a stranger's sweep): the example campaign
moved to q in [-1, 1.3] rad, below pi/2, where the gravity torque MX g cos q never changes
sign. The motor and the generator rows are then one direction each, so c_m, c_g and the
offset are (nearly) dependent: the elimination dropped c_g as "not significant" and reported
c_m 36.4 +- 0.9 (truth 21) and an offset of -7.4 (truth 10) with no word. The paper says it
(section III.B: the range must cross the position where the gravity torque changes sign); a
note now says it too. The example campaign itself (crossing pi/2) gets no such note."""

from __future__ import annotations

import tomllib

import pytest
from example_campaign import ROOT, payload_experiments

from daq.protocol.control import ControllerGains
from ident.fitting import fit_models
from sim_drivers.plant_config import load_plant
from trajectories.plan import plan_campaign
from trajectories.robot_campaign import RobotCampaign

NOTE = "paper model: the load tau_out keeps one sign"


def _fit(one_sided: bool, seed: int = 5, quick: bool = False,
         models: tuple[str, ...] = ("paper",)):
    with open(ROOT / "examples" / "campaign.toml", "rb") as fh:
        d = tomllib.load(fh)
    if one_sided:  # the sweep's campaign: every range below pi/2
        d["joint"]["limits"]["position"] = [-1.0, 1.3]
        ranges = [[0.2, 1.2], [-0.9, 1.2], [-0.9, 1.2]]
        for seg, r in zip([s for s in d["segments"] if s["kind"] == "trapezoid"], ranges,
                          strict=True):
            seg["range"] = r
        sine = next(s for s in d["segments"] if s["kind"] == "sine")
        sine.update(amplitude=1.0, center=0.15)
    camp = RobotCampaign.from_dict(d, "one-sided" if one_sided else "example")
    if quick:
        camp = camp.quick()
    plan = plan_campaign(camp)
    plant = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml")
    gains = ControllerGains(**camp.gains_kwargs())
    exps = payload_experiments(plant, plan, gains, seed, name="p{i}.csv")
    return fit_models(exps, models, table_iv=False)


@pytest.mark.slow
def test_one_sign_load_is_said():
    rep = _fit(True)
    assert any(n.startswith(NOTE) for n in rep.notes), rep.notes
    assert any(n.startswith(NOTE) for n in rep.to_json()["notes"])


@pytest.mark.slow
def test_the_example_campaign_crosses_and_gets_no_such_note():
    rep = _fit(False)
    assert not any(n.startswith(NOTE) for n in rep.notes), rep.notes


@pytest.mark.slow
def test_exactly_dependent_one_sign_load_is_dropped_and_said():
    """The quick campaign makes the dependence exact: one of c_m, c_g and the offset is
    dropped and reported as a combination of the other two (the single-joint rank rule
    before the first solve; until 2026-11-28 the paper model was refused here, as on the
    real KUKA axes: tests/test_kuka_single_joint.py checks the rest), and the note says why;
    asked with the usual model, both are kept."""
    rep = _fit(True, quick=True)
    dependent = [n for n, why in rep.models["paper"].removed_ if why.startswith("not sep")]
    assert len(dependent) == 1 and dependent[0] in ("c_m", "c_g", "tau_off")
    assert any(n.startswith(NOTE) for n in rep.notes)
    rep = _fit(True, quick=True, models=("usual", "paper"))
    assert list(rep.models) == ["usual", "paper"]
    assert any("keeps one sign" in n for n in rep.notes)
