"""Issue 24: the terms found on one joint refitted inside the one robot model class, for the
paper model's products form (eq. 42, ``RobotModel(model="paper", form="products")``, what
:func:`ident.fitting.fit_models` fits a joint with through :class:`ident.one_joint.
OneJointProblem`): ``ident.robot.refit.refit_robot`` on the products formed at full rate.

Data: the quick example campaign (examples/campaign.toml) simulated offline on
examples/plant_rx130l.toml, whose undeclared effect is a position ripple of 2.5 N m, period
2 pi / 16 rad, phase 0.5 rad. The runs are named ``.mcap`` without references: LS with the
half-cycle torque delay of jointid logs (the simulator holds each command over the next
cycle, as the drives do).

Asserted:

* without extra terms the refit is the fit (errors, coefficients, deviations; the
  parameters the first fit held at 0 stay there), with and without elimination;
* with the ripple's columns exactly as the single-joint design forms them (filtered at full
  rate, looked up by sample), the refit IS the single-joint refit of the design with that term
  (the refinement's final model): the same error and coefficients to round-off;
* with the term itself (its columns on the decimated states, ``joint_columns``), the error is
  that of the single-joint refit within 1e-3 relative (measured 1.2e-4 on seed 11; the columns
  differ by 0.4 % relative: sin(2 pi q / P) of the filtered, decimated q against the
  low-passed sin of the full-rate q) and the coefficients within one standard deviation;
* the same for the term the single-joint refinement finds;
* over two seeds the ripple's amplitude and phase within 2 sigma of the plant's truth; WLS
  (one joint: one scalar weight) gives the LS refit's numbers;
* the products form on the decimated columns (no full-rate products) refits too;
* a full-rate products model on signals without the products: a one-line error (IDIM-IV
  fits refit too: tests/test_robot_refit_iv.py).
"""

from __future__ import annotations

import functools
import tomllib
from pathlib import Path

import numpy as np
import pytest

from daq.protocol.control import ControllerGains
from ident.chain import default_torque_delay
from ident.effects.position_ripple import PositionRipple
from ident.fitting import fit_models
from ident.loaders import make_experiment
from ident.models import IdentModel
from ident.one_joint import OneJointProblem
from ident.refine import refine
from ident.robot import RobotIdentError
from ident.robot.design import joint_columns
from ident.robot.estimate import RobotModel
from ident.robot.refit import refit_robot
from ident.signals import Signals
from ident.terms import Library, Term
from sim_drivers.offline import simulate
from sim_drivers.plant_config import load_plant
from trajectories.plan import plan_campaign
from trajectories.robot_campaign import RobotCampaign

ROOT = Path(__file__).resolve().parents[1]
PLANT = ROOT / "examples" / "plant_rx130l.toml"
SEEDS = (11, 21)
#: The refit's error against the single-joint refit's with the term's own columns (computed
#: on the decimated states instead of filtered at full rate): relative tolerance.
ERROR_RTOL = 1e-3


@functools.cache
def _campaign(seed: int) -> tuple[list, list]:
    """The quick example campaign on the RX130L plant: experiments (LS, ``.mcap`` names)
    and the reference position of each."""
    with open(ROOT / "examples" / "campaign.toml", "rb") as fh:
        campaign = RobotCampaign.from_dict(tomllib.load(fh), "examples/campaign.toml").quick()
    plan = plan_campaign(campaign)
    plant = load_plant(PLANT)
    gains = ControllerGains(**campaign.gains_kwargs())
    exps, refs = [], []
    for i, p in enumerate(plan.payloads):
        r = simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                     payload_arm=p.arm_m, seed=seed + i)
        exps.append(make_experiment(f"payload{i}.mcap", r.t, r.q, r.tau_ref,
                                    payload_mass=p.mass_kg, payload_arm=p.arm_m))
        refs.append(plan.reference.q[np.minimum(r.cycle, plan.reference.q.size - 1)])
    return exps, refs


@functools.cache
def _fitted(seed: int, eliminate: bool = False):
    """fit_models' paper model (its products-form RobotModel ``robot_``), the same joint's
    problem as fit_models builds it, and its products signals at the fit's q_s."""
    exps, _ = _campaign(seed)
    rep = fit_models(exps, ("paper",), eliminate=eliminate, table_iv=False)
    prob = OneJointProblem(exps, revolute=rep.revolute, has_payload=True, references=None,
                           paper=True,
                           torque_delay=default_torque_delay([e.source for e in exps]))
    sig = prob.products(rep.q_s)
    robot = rep.models["paper"].robot_
    # the problem is fit_models' own: the same fit on these signals
    again = prob.fit("paper", rep.q_s, eliminate=eliminate).robot
    assert np.array_equal(again.coef_, robot.coef_)
    return rep, prob, sig, robot


def _ripple() -> PositionRipple:
    """The plant's undeclared effect as a single-joint term, at its true period."""
    return PositionRipple(load_plant(PLANT).truth_effects()["position_ripple"]["period_rad"])


class _Given(Term):
    """A term whose columns are given per sample (looked up by its decimated (q, dq), which
    are the single-joint design's own floats): the design's columns of ``term``, filtered at
    full rate, inside the robot refit."""

    effect = "given"

    def __init__(self, names: tuple[str, ...], q: np.ndarray, dq: np.ndarray,
                 W: np.ndarray) -> None:
        self._names = names
        self._at = {(a, b): w for a, b, w in zip(q.tolist(), dq.tolist(), W, strict=True)}
        self.found = 0

    def names(self) -> tuple[str, ...]:
        return self._names

    def columns(self, s: Signals) -> np.ndarray:
        out = np.zeros((s.q.size, len(self._names)))
        for i, key in enumerate(zip(s.q.tolist(), s.dq.tolist(), strict=True)):
            if key in self._at:
                out[i] = self._at[key]
                self.found += 1
        return out


def _single_refit(rep, term: Term) -> tuple[IdentModel, object]:
    """The single-joint refit of the design with ``term`` (the refinement's fit of a step:
    ``IdentModel(...).fit(design.with_term(term, states_only=True), eliminate=False)``)."""
    d = rep.designs["paper"].with_term(term, states_only=True)
    lib = Library(*rep.models["paper"].library.terms(), term)
    return IdentModel(lib, "paper").fit(d, eliminate=False), d


@pytest.mark.parametrize("eliminate", [False, True])
def test_no_terms_is_the_fit(eliminate):
    """Without extra terms the products-form refit is the first fit: the same rows, error,
    coefficients and deviations, the eliminated parameters held at 0."""
    _, _, sig, robot = _fitted(SEEDS[0], eliminate)
    assert robot.form == "products" and robot.full_rate_products_
    rf = refit_robot(robot, sig, [])
    (joint,) = robot.joints_
    assert rf.n_rows == {joint: int(robot.n_samples_[0])}
    for when in ("before", "after"):
        assert rf.rel_error[when][joint] == pytest.approx(robot.rel_error_[joint], rel=1e-9)
    assert rf.heldout["after"][joint] == pytest.approx(rf.heldout["before"][joint], rel=1e-9)
    assert rf.names_ == robot.names_
    free = np.array([n not in robot.fixed_ for n in robot.names_])
    assert np.all(np.abs(rf.coef_ - robot.coef_)[free] <= 1e-6 * robot.std_[free])
    assert np.allclose(rf.std_[free], robot.std_[free], rtol=1e-6)
    assert np.all(rf.coef_[~free] == 0) and np.all(rf.std_[~free] == 0)
    if eliminate:
        assert not free.all()  # the threshold elimination held parameters here


def test_given_columns_are_the_single_joint_refit():
    """The design's own term columns (filtered at full rate) inside the robot refit give the
    single-joint refit of the design with the term: the products rows are the design's."""
    rep, _, sig, robot = _fitted(SEEDS[0])
    term = _ripple()
    single, d = _single_refit(rep, term)
    names = term.names()
    W = d.W[:, [d.names.index(n) for n in names]]
    given = _Given(names, d.signals.q, d.signals.dq, W)
    rf = refit_robot(robot, sig, [(0, given)])
    (joint,) = robot.joints_
    assert given.found >= len(d)  # every row of the design found (once per term evaluation)
    assert rf.n_rows[joint] == len(d)
    assert rf.rel_error["after"][joint] == pytest.approx(single.rel_error_, rel=1e-8)
    assert rf.rel_error["before"][joint] == pytest.approx(rep.models["paper"].rel_error_,
                                                          rel=1e-8)
    (ex,) = rf.extras
    for n, v, s in zip(names, ex["values"], ex["std"], strict=True):
        assert abs(v - single.coef_[n]) <= 1e-6 * single.std_[n]
        assert s == pytest.approx(single.std_[n], rel=1e-6)


def test_term_on_decimated_states_is_the_single_joint_refit_within_tolerance():
    """The term's own columns (joint_columns, on the decimated states) differ from the
    design's by the filtering only: the error within ERROR_RTOL and the coefficients within
    one standard deviation of the single-joint refit."""
    rep, _, sig, robot = _fitted(SEEDS[0])
    term = _ripple()
    single, d = _single_refit(rep, term)
    rf = refit_robot(robot, sig, [(0, term)], validation=(sig, None, None))
    (joint,) = robot.joints_
    names = term.names()
    for when in ("before", "after"):  # validation on the same samples: the same errors
        assert rf.validation[when][joint] == pytest.approx(rf.rel_error[when][joint], rel=1e-9)
    rows = robot.fitted_rows(sig)[:, 0]
    X = joint_columns(sig, robot.predict(sig), [(0, term)])[0][rows]
    W = d.W[:, [d.names.index(n) for n in names]]
    gap = np.linalg.norm(X - W) / np.linalg.norm(W)
    assert 0 < gap < 0.02  # measured 0.4 %
    after = rf.rel_error["after"][joint]
    assert after == pytest.approx(single.rel_error_, rel=ERROR_RTOL)
    assert after < 0.5 * rf.rel_error["before"][joint]
    (ex,) = rf.extras
    assert ex["effect"] == "position_ripple" and ex["significant"]
    for n, v in zip(names, ex["values"], strict=True):
        assert abs(v - single.coef_[n]) <= single.std_[n]
    assert set(ex["parameters"]) >= {"ripple_amplitude", "ripple_phase"}
    assert rf.heldout["after"][joint] < rf.heldout["before"][joint]


def test_the_refinement_s_term_refitted():
    """The term the single-joint refinement finds, refitted in the robot model: its error is
    the refinement's final error within ERROR_RTOL, its coefficients within one sigma."""
    rep, _, sig, robot = _fitted(SEEDS[0])
    ref = refine(rep.designs["paper"], rep.models["paper"], max_steps=2, vmax=rep.vmax)
    assert ref.steps and ref.steps[0].term.effect == "position_ripple"
    terms = [(0, s.term) for s in ref.steps]
    rf = refit_robot(robot, sig, terms)
    (joint,) = robot.joints_
    assert rf.rel_error["before"][joint] == pytest.approx(ref.rel_error_initial, rel=1e-8)
    assert rf.rel_error["after"][joint] == pytest.approx(ref.final_model.rel_error_,
                                                         rel=ERROR_RTOL)
    fm = ref.final_model
    for ex in rf.extras:
        for n, v in zip(ex["names"], ex["values"], strict=True):
            assert abs(v - fm.coef_[n]) <= fm.std_[n]


@pytest.mark.parametrize("seed", SEEDS)
def test_ripple_truth_recovered(seed):
    """The plant's ripple (amplitude, phase) within 2 sigma of its truth after the refit;
    WLS on one joint (one scalar weight) is the LS refit."""
    _, prob, sig, robot = _fitted(seed)
    truth = load_plant(PLANT).truth_effects()["position_ripple"]
    rf = refit_robot(robot, sig, [(0, _ripple())])
    par = rf.extras[0]["parameters"]
    for key, true in (("ripple_amplitude", truth["amplitude_Nm"]),
                      ("ripple_phase", truth["phase_rad"])):
        value, two_sigma = par[key]
        assert abs(value - true) <= two_sigma, (key, value, two_sigma, true)
    wls = RobotModel(prob.reg, "paper", "wls", base=prob.base, form="products",
                     q_s=robot.q_s_[0], eliminate=True, threshold_pct=np.inf).fit(sig)
    rw = refit_robot(wls, sig, [(0, _ripple())])
    assert np.allclose(rw.coef_, rf.coef_, rtol=1e-9, atol=1e-12)
    assert np.allclose(rw.std_, rf.std_, rtol=1e-6)
    for when in ("before", "after"):
        assert rw.rel_error[when] == pytest.approx(rf.rel_error[when], rel=1e-9)


def test_products_on_decimated_columns():
    """The products form fitted on the decimated columns (no full-rate products; its
    quadrants the usual fit's) refits too: no terms, the fit; the ripple lowers the error."""
    _, prob, _, robot = _fitted(SEEDS[0])
    sig = prob.signals
    dec = RobotModel(prob.reg, "paper", "ls", base=prob.base, form="products",
                     q_s=robot.q_s_[0], payload_ratio=False).fit(sig)
    assert not dec.full_rate_products_
    (joint,) = dec.joints_
    rf = refit_robot(dec, sig, [])
    assert rf.rel_error["after"][joint] == pytest.approx(dec.rel_error_[joint], rel=1e-9)
    assert rf.rel_error["before"][joint] == pytest.approx(dec.rel_error_[joint], rel=1e-9)
    assert np.allclose(rf.coef_, dec.coef_, rtol=1e-7, atol=1e-9 * np.abs(dec.coef_).max())
    rt = refit_robot(dec, sig, [(0, _ripple())])
    assert rt.rel_error["after"][joint] < 0.5 * rf.rel_error["after"][joint]


def test_refused_in_one_line():
    """A model fitted on the full-rate products cannot be refitted on signals without
    them."""
    _, prob, _, robot = _fitted(SEEDS[0])
    bare = prob.signals  # the chain's signals, no columns.products
    assert bare.columns.products is None
    for pred in (None, np.zeros(bare.tau.shape)):
        with pytest.raises(RobotIdentError, match="columns.products") as e:
            refit_robot(robot, bare, [(0, _ripple())], prediction=pred)
        assert "\n" not in str(e.value)
