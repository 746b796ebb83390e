"""The n-dof refit of IDIM-IV fits (``ident.robot.refit.refit_robot`` with ``method="iv"``): the
terms the single-joint refinement finds refitted inside the robot model by one IV solve, as
the single-joint refinement refits them on the design (``ident.refine.refine``: IV on the
design, a term's instruments its own columns, or its columns with the reference's
acceleration for a term that reads the acceleration: ``Design.with_term``).

Data: the quick example campaign (examples/campaign.toml) simulated offline on
examples/plant_rx130l.toml, whose undeclared effect is a position ripple (2.5 N m, period
2 pi / 16 rad); the runs named ``.mcap`` with their references q_ref, so ``fit_models``
fits by IDIM-IV (as the IV configuration of benchmarks/fit_fingerprint.py). The one-joint
problem is fit_models' own (:class:`ident.one_joint.OneJointProblem`); the fits without
elimination, as the refinement refits (tests/test_robot_refit_products.py does the same).

Asserted, for the usual model and the paper model's products form, both fitted by IV:

* without extra terms the refit is the fit: the same error before and after, the fit's
  coefficients and deviations (also with parameters eliminated and held at 0);
* with a term's columns and instruments exactly as the single-joint design forms them
  (looked up per sample: the columns with the measured acceleration, the design's
  instruments with another one), the refit IS the single-joint IV refit of the design with
  that term, to round-off: the ripple (its own instruments) and a term reading the
  acceleration (ddq cos q, instruments on the reference's acceleration);
* with the term the single-joint refinement finds (the ripple), evaluated on the decimated
  states (``joint_columns``), the error is the refinement's final error within ERROR_RTOL
  (measured 3.0e-7 usual, 9.8e-8 products on seed 11: the columns differ by 0.08 %, the
  decimated sin(2 pi q / P) against the low-passed one) and the coefficients within 0.25
  sigma (measured at most 0.025 sigma usual, 0.033 sigma products; the deviations 0.05 %
  apart);
* the acceleration term evaluated on the decimated states has instruments other than its
  columns (the decimated q_ref differentiated twice, 1.2 % from the design's instruments,
  which differentiate at full rate then low-pass); its refit error is the single-joint
  refit's within ERROR_RTOL (measured 5.5e-6), its coefficient within 0.25 sigma (0.036);
* the products form fitted by IV on the decimated columns (its quadrant band left out)
  refits too, its instruments the columns chain's;
* without q_ref a term reading the acceleration is refused in one line, one that does not
  is refitted (its columns its instruments);
* the bilinear paper form fitted by IV refits by Gauss-Newton with IV steps (full steps, its
  quadrants held): without terms it is the fit; with the ripple, the plant's ripple within
  2 sigma of its truth (measured on seed 11: amplitude 2.530 +- 0.070 (2 sigma) against 2.5,
  phase 0.495 +- 0.028 against 0.5, 4 iterations) and within 0.25 (2 sigma) of the
  products form's IV refit (2.530, 0.496).
"""

from __future__ import annotations

import copy
import functools
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from test_robot_refit_products import _campaign

from ident.chain import default_torque_delay
from ident.fitting import fit_models
from ident.models import IdentModel
from ident.one_joint import OneJointProblem
from ident.refine import refine
from ident.robot import RobotIdentError
from ident.robot.design import joint_columns
from ident.robot.estimate import RobotModel
from ident.robot.refit import MAX_ITER, refit_robot
from ident.signals import Signals
from ident.terms import Library, Term
from sim_drivers.plant_config import load_plant

ROOT = Path(__file__).resolve().parents[1]
PLANT = ROOT / "examples" / "plant_rx130l.toml"
SEED = 11
NAMES = ("usual", "paper")
#: The refit's error against the single-joint refinement's with the term evaluated on the
#: decimated states (not filtered at full rate): relative tolerance.
ERROR_RTOL = 1e-4
#: The same terms' coefficients: at most this many of the single-joint refit's sigma apart.
COEF_SIGMA = 0.25


@functools.cache
def _problem():
    """The campaign on the RX130L plant as MCAP runs with references: fit_models' IV report
    (no elimination), its one-joint problem, and the signals each model was fitted on."""
    exps, refs = _campaign(SEED)  # the same simulated runs; references: IDIM-IV
    rep = fit_models(exps, NAMES, eliminate=False, table_iv=False, references=refs)
    prob = OneJointProblem(exps, revolute=rep.revolute, has_payload=True, references=refs,
                           paper=True,
                           torque_delay=default_torque_delay([e.source for e in exps]))
    sigs = {"usual": prob.signals, "paper": prob.products(rep.q_s)}
    for name in NAMES:  # the problem is fit_models' own: the same IV fit on these signals
        robot = rep.models[name].robot_
        assert robot.method == "iv"
        again = prob.fit(name, rep.q_s, eliminate=False).robot
        assert np.array_equal(again.coef_, robot.coef_)
    return rep, prob, sigs


@functools.cache
def _refinement(name: str):
    rep, _, _ = _problem()
    return refine(rep.designs[name], rep.models[name], max_steps=1, vmax=rep.vmax)


class _AccelerationTerm(Term):
    """A term that reads the acceleration: ddq cos(q) (a position-dependent inertia)."""

    effect = "inertia_cos"
    variable = "acceleration"

    def names(self) -> tuple[str, ...]:
        return ("J_cos",)

    def columns(self, s: Signals) -> np.ndarray:
        return (np.asarray(s.ddq) * np.cos(np.asarray(s.q)))[:, None]


class _Given(Term):
    """A term whose columns are given per sample, looked up by the decimated (q, dq) (the
    single-joint design's own floats): the design's columns when called with the design's
    acceleration, its instruments with any other (the reference's)."""

    effect = "given"

    def __init__(self, names: tuple[str, ...], s: Any, W: np.ndarray,
                 Z: np.ndarray) -> None:
        self._names = names
        self._at = {(a, b): (c, w, z) for a, b, c, w, z in
                    zip(s.q.tolist(), s.dq.tolist(), s.ddq.tolist(), W, Z, strict=True)}
        self.found = {"columns": 0, "instruments": 0}

    def names(self) -> tuple[str, ...]:
        return self._names

    def columns(self, s: Signals) -> np.ndarray:
        out = np.zeros((s.q.size, len(self._names)))
        for i, (a, b, c) in enumerate(zip(s.q.tolist(), s.dq.tolist(), s.ddq.tolist(),
                                          strict=True)):
            hit = self._at.get((a, b))
            if hit is not None:
                same = hit[0] == c
                out[i] = hit[1] if same else hit[2]
                self.found["columns" if same else "instruments"] += 1
        return out


def _single_refit(name: str, term: Term) -> tuple[IdentModel, object]:
    """The single-joint refit of the design with ``term`` (the refinement's fit of a step),
    IDIM-IV: the design carries the reference's instruments."""
    rep, _, _ = _problem()
    d = rep.designs[name].with_term(term, states_only=True)
    assert d.Z is not None
    lib = Library(*rep.models[name].library.terms(), term)
    return IdentModel(lib, name).fit(d, eliminate=False), d


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("eliminate", [False, True])
def test_no_terms_is_the_iv_fit(name, eliminate):
    """Without extra terms the IV refit is the IV fit: error before = after = the fit's,
    its coefficients and deviations (the IV sandwich), eliminated parameters held at 0."""
    rep, prob, sigs = _problem()
    robot = rep.models[name].robot_ if not eliminate else prob.fit(name, rep.q_s).robot
    assert robot.method == "iv"
    rf = refit_robot(robot, sigs[name], [])
    (joint,) = robot.joints_
    assert rf.n_rows == {joint: int(robot.n_samples_[0])}
    for when in ("before", "after"):
        assert rf.rel_error[when][joint] == pytest.approx(robot.rel_error_[joint], rel=1e-9)
    assert rf.names_ == robot.names_
    free = np.array([n not in robot.fixed_ for n in robot.names_])
    assert np.all(np.abs(rf.coef_ - robot.coef_)[free] <= 1e-6 * robot.std_[free])
    assert np.allclose(rf.std_[free], robot.std_[free], rtol=1e-6)
    assert np.all(rf.coef_[~free] == 0) and np.all(rf.std_[~free] == 0)
    if eliminate and name == "paper":
        assert not free.all()  # the threshold elimination held products at 0 here
    # not the LS solution: the IV refit keeps the fit's instruments
    ls = RobotModel(prob.reg, robot.model, "ls", base=prob.base, form=robot.form,
                    q_s=robot.q_s_[0], payload_ratio=robot.payload_ratio,
                    eliminate=True, threshold_pct=np.inf).fit(sigs[name])
    assert np.max(np.abs(ls.coef_ - rf.coef_)[free] / robot.std_[free]) > 0.1


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("term", [None, _AccelerationTerm()], ids=["ripple", "ddq_cos_q"])
def test_given_columns_are_the_single_joint_iv_refit(name, term):
    """The design's own term columns and instruments inside the robot refit: the single-joint
    IV refit of the design with the term, to round-off (the ripple: instruments = columns;
    ddq cos q: instruments on the reference's acceleration)."""
    rep, _, sigs = _problem()
    term = _refinement(name).steps[0].term if term is None else term
    single, d = _single_refit(name, term)
    assert single.estimator_ == "iv"
    names = term.names()
    idx = [d.names.index(n) for n in names]
    reads_ddq = not np.array_equal(d.Z[:, idx], d.W[:, idx])
    assert reads_ddq == isinstance(term, _AccelerationTerm)
    given = _Given(names, d.signals, d.W[:, idx], d.Z[:, idx])
    robot = rep.models[name].robot_
    rf = refit_robot(robot, sigs[name], [(0, given)])
    (joint,) = robot.joints_
    assert rf.n_rows[joint] == len(d)
    assert given.found["columns"] >= len(d)
    # the instruments: every term evaluated with the reference's acceleration (for the
    # ripple the design's instruments are its columns)
    assert given.found["instruments"] >= len(d)
    assert rf.rel_error["before"][joint] == pytest.approx(rep.models[name].rel_error_, rel=1e-8)
    assert rf.rel_error["after"][joint] == pytest.approx(single.rel_error_, rel=1e-8)
    (ex,) = rf.extras
    for n, v, s in zip(names, ex["values"], ex["std"], strict=True):
        assert abs(v - single.coef_[n]) <= 1e-6 * single.std_[n]
        assert s == pytest.approx(single.std_[n], rel=1e-6)


@pytest.mark.parametrize("name", NAMES)
def test_the_refinement_s_term_refitted(name):
    """The term the single-joint IV refinement finds (the ripple), refitted in the robot
    model on the decimated states: the refinement's final error within ERROR_RTOL, its
    coefficients within COEF_SIGMA of its sigma, the deviations within 10 %."""
    rep, _, sigs = _problem()
    ref = _refinement(name)
    assert [s.term.effect for s in ref.steps] == ["position_ripple"]
    robot = rep.models[name].robot_
    rf = refit_robot(robot, sigs[name], [(0, ref.steps[0].term)])
    (joint,) = robot.joints_
    assert rf.rel_error["before"][joint] == pytest.approx(ref.rel_error_initial, rel=1e-8)
    fm = ref.final_model
    assert fm.estimator_ == "iv"
    after = rf.rel_error["after"][joint]
    assert after == pytest.approx(fm.rel_error_, rel=ERROR_RTOL)
    assert after < 0.9 * rf.rel_error["before"][joint]
    (ex,) = rf.extras
    assert ex["significant"]
    for n, v, s in zip(ex["names"], ex["values"], ex["std"], strict=True):
        assert abs(v - fm.coef_[n]) <= COEF_SIGMA * fm.std_[n]
        assert s == pytest.approx(fm.std_[n], rel=0.1)
    assert rf.heldout["after"][joint] < rf.heldout["before"][joint]


def test_acceleration_term_instruments():
    """ddq cos q evaluated on the decimated states: its instruments are its columns with the
    reference's acceleration (the decimated q_ref differentiated twice), not its columns;
    the refit's error is the single-joint IV refit's within ERROR_RTOL."""
    rep, _, sigs = _problem()
    sig, robot, term = sigs["usual"], rep.models["usual"].robot_, _AccelerationTerm()
    single, _ = _single_refit("usual", term)
    rf = refit_robot(robot, sig, [(0, term)])
    (joint,) = robot.joints_
    assert rf.rel_error["after"][joint] == pytest.approx(single.rel_error_, rel=ERROR_RTOL)
    (ex,) = rf.extras
    (n,) = term.names()
    assert abs(ex["values"][0] - single.coef_[n]) <= COEF_SIGMA * single.std_[n]
    # the same columns as their own instruments (looked up, whatever the acceleration):
    # another IV solution, so the reference's acceleration was used
    X = joint_columns(sig, robot.predict(sig), [(0, term)])[0]
    s = SimpleNamespace(q=sig.q[:, 0], dq=sig.dq[:, 0], ddq=sig.ddq[:, 0])
    own = refit_robot(robot, sig, [(0, _Given(term.names(), s, X, X))])
    assert own.rel_error["after"][joint] != rf.rel_error["after"][joint]
    assert abs(own.extras[0]["values"][0] - ex["values"][0]) > 1e-3 * ex["std"][0]


def test_without_references():
    """Signals without q_ref (the columns carry the model's instruments): a term that reads
    the acceleration is refused in one line; one that does not is refitted, its columns
    its instruments (the refit with q_ref gives the same numbers)."""
    rep, _, sigs = _problem()
    robot = rep.models["usual"].robot_
    bare = replace(sigs["usual"], q_ref=None)
    with pytest.raises(RobotIdentError, match="reads the acceleration") as e:
        refit_robot(robot, bare, [(0, _AccelerationTerm())])
    assert "\n" not in str(e.value) and "q_ref" in str(e.value)
    ripple = _refinement("usual").steps[0].term
    a = refit_robot(robot, bare, [(0, ripple)])
    b = refit_robot(robot, sigs["usual"], [(0, ripple)])
    assert np.array_equal(a.coef_, b.coef_) and np.array_equal(a.std_, b.std_)


def test_bilinear_iv():
    """The paper model's bilinear form fitted by IV: Gauss-Newton with IV steps (Z^T J,
    full steps, as the model's own fit), its quadrants the fit's, held. Without terms the
    refit is the fit; with the refinement's ripple the plant's ripple (amplitude, phase) is
    within 2 sigma of its truth, and within half a sigma of the products form's IV refit
    (the same data, the linear form of the same model). An unknown method: one line."""
    rep, prob, sigs = _problem()
    bil = RobotModel(prob.reg, "paper", "iv", base=prob.base, q_s=rep.q_s).fit(prob.signals)
    assert bil.form != "products" and bil.method == "iv"
    (joint,) = bil.joints_
    rf = refit_robot(bil, prob.signals, [])
    free = np.array([n not in bil.fixed_ for n in bil.names_])
    for when in ("before", "after"):
        assert rf.rel_error[when][joint] == pytest.approx(bil.rel_error_[joint], rel=1e-9)
    assert np.all(np.abs(rf.coef_ - bil.coef_)[free] <= 1e-6 * bil.std_[free])
    assert np.allclose(rf.std_[free], bil.std_[free], rtol=1e-6)
    ripple = _refinement("paper").steps[0].term
    rt = refit_robot(bil, prob.signals, [(0, ripple)])
    assert rt.n_iter < MAX_ITER  # converged
    assert rt.rel_error["after"][joint] < 0.9 * rt.rel_error["before"][joint]
    truth = load_plant(PLANT).truth_effects()["position_ripple"]
    par = rt.extras[0]["parameters"]
    prod = refit_robot(rep.models["paper"].robot_, sigs["paper"], [(0, ripple)])
    ppar = prod.extras[0]["parameters"]
    for key, true in (("ripple_amplitude", truth["amplitude_Nm"]),
                      ("ripple_phase", truth["phase_rad"])):
        value, two_sigma = par[key]
        assert abs(value - true) <= two_sigma, (key, value, two_sigma, true)
        assert abs(value - ppar[key][0]) <= 0.25 * two_sigma, (key, value, ppar[key])
    odd = copy.copy(rep.models["usual"].robot_)
    odd.method = "gls"
    with pytest.raises(RobotIdentError, match="'gls' is not supported") as e:
        refit_robot(odd, prob.signals, [])
    assert "\n" not in str(e.value)


def test_products_on_decimated_columns_iv():
    """The products form fitted by IV on the decimated columns (no full-rate products; the
    usual fit's quadrants, its band left out): its instruments are the columns chain's;
    without terms the refit is the fit, the ripple lowers the error."""
    rep, prob, _ = _problem()
    sig = prob.signals
    dec = RobotModel(prob.reg, "paper", "iv", base=prob.base, form="products",
                     q_s=rep.q_s, payload_ratio=False).fit(sig)
    assert not dec.full_rate_products_ and dec.method == "iv"
    (joint,) = dec.joints_
    rf = refit_robot(dec, sig, [])
    assert rf.n_rows[joint] == int(dec.n_samples_[0])
    for when in ("before", "after"):
        assert rf.rel_error[when][joint] == pytest.approx(dec.rel_error_[joint], rel=1e-9)
    free = np.array([n not in dec.fixed_ for n in dec.names_])
    assert np.all(np.abs(rf.coef_ - dec.coef_)[free] <= 1e-6 * dec.std_[free])
    assert np.allclose(rf.std_[free], dec.std_[free], rtol=1e-6)
    rt = refit_robot(dec, sig, [(0, _refinement("paper").steps[0].term)])
    assert rt.rel_error["after"][joint] < 0.9 * rf.rel_error["after"][joint]
