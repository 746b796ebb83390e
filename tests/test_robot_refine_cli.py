"""Issue 22 items 5-6: ``jointid fit --robot ... --refine`` refines every joint on the fit's own
rows, and every error is also given on all rows with the share each figure leaves out.

Data: the offline 3-dof arm simulator (sim_drivers.arm, examples/robots/arm3.toml) with the
usual friction and the simulator's "dry coupling" (sim_drivers.arm_effects): joint 1's dry
friction scaled by 1 + 0.5 sin(2 pi q2 / 0.5 rad + 0.5), a cable following the shoulder. Three
payload runs written as CSV files (as tests/test_robot_cli.py), read back by the loaders, fitted
on the columns chain (decimated, stiction area, guard and sign check left out).

Asserted:

* the refinement's design is exactly the fit's rows (Y = the decimated torque on the kept
  rows, as many rows as the n-dof fit used);
* joint 1's first accepted step is named ``periodic_q2_direction`` and its final error is
  within 1.1 x the error of the exact structure (declared model + the true coupling column)
  on the same design; the uncoupled joints get no term in another joint's variables;
* through the CLI: per-joint before/after figures (fit, held-out, noise floor) in the JSON and
  on stdout; every error also on all rows with the share of rows it leaves out (the all-rows
  figures equal the estimator's error on every decimated row); paper-model parameters above
  the pruning threshold pruned (or flagged as unidentified when not prunable);
* a torque lag of half the raw cycle is named a zero-order hold against the raw period given
  (``cycle_s``), not against the design's (decimated) period.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from robot_campaigns import write_arm_csv

from daq.app.cli import main
from ident import DataError
from ident.cli_robot import fit_robot, format_refinement, kept_rows, refine_robot
from ident.estimate import DEFAULT_THRESHOLD_PCT
from ident.loaders import concat, make_experiment
from ident.models import Coulomb, IdentModel, Offset, RigidBody, Viscous
from ident.refine import refine
from ident.refine_result import ONE_TRAJECTORY_NOTE
from ident.robot.loaders import load_robot_runs
from ident.robot.refine_joint import fit_rows_design
from ident.signals import Signals
from ident.terms import Library, Term
from sim_drivers.arm import ArmEffects, ArmGains, ArmParams, Payload, model_reference, simulate_arm
from trajectories.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
ARM3 = ROOT / "examples" / "robots" / "arm3.toml"
PAYLOADS = (None, Payload(5.0, [0.0, 0.0, 0.05]),
            Payload(10.0, [0.02, 0.0, 0.1], [0.02, 0.0, 0.0, 0.02, 0.0, 0.03]))
#: Joint 1 (index 0) coupled to joint 2's position (index 1).
COUPLING = {"amplitude": 0.5, "period_rad": 0.5, "phase_rad": 0.5}
WITHIN = 1.10


class _TrueCoupling(Term):
    """The exact coupling column sin(2 pi q2 / P + phi) sign(dq1) (amplitude fitted)."""

    effect = "true_coupling"
    variable = "other"

    def names(self) -> tuple[str, ...]:
        return ("true_coupling",)

    def columns(self, s: Signals) -> np.ndarray:
        g = np.sin(2 * np.pi * s.extra["q2"] / COUPLING["period_rad"] + COUPLING["phase_rad"])
        return (g * np.sign(s.dq))[:, None]


@pytest.fixture(scope="module")
def coupled_files(tmp_path_factory):
    """Three payload runs of the coupled arm as CSV files (t, q, tau, q_ref, payload)."""
    robot = load_robot(ARM3)
    c = ArmParams.from_robot(robot).friction.c_m
    usual = dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0, d_m=0.0, d_g=0.0, c_g=c)
    params = dataclasses.replace(ArmParams.from_robot(robot, usual),
                                 effects=ArmEffects.make(3, dry_coupling={(0, 1): COUPLING}))
    ref = model_reference(params.model, center=[0.0, -1.9, 0.6], fraction=0.9,
                          duration_s=10.0, seed=3)
    d = tmp_path_factory.mktemp("coupled")
    files = []
    for i, pay in enumerate(PAYLOADS):
        run = simulate_arm(params, ref, ArmGains.for_params(params, payload=pay), payload=pay,
                           seed=30 + i)
        files.append(write_arm_csv(run, d / f"p{i}.csv"))
    return robot, files


def test_cross_joint_sine_named_on_the_fit_rows(coupled_files):
    robot, files = coupled_files
    runs = load_robot_runs(files, robot.moving)
    out = fit_robot(robot, runs, models=("usual",), method="ls", feasibility=False)
    rec = refine_robot(out, max_steps=2, joints=["j1"])
    ref = out["_refinements"]["j1"]
    sig, est = out["_identification"], out["_estimators"]["usual"]
    keep = out["_keep"][:, 0]
    # the refinement's rows are the fit's: the decimated torque on the kept rows
    assert rec["joints"]["j1"]["rows"] == int(est.n_samples_[0]) == len(ref.final_design)
    np.testing.assert_array_equal(ref.final_design.Y, sig.tau[keep, 0])
    assert rec["cycle_s"] == pytest.approx(float(np.median(np.diff(runs[0].t))))
    first = ref.steps[0] if ref.steps else None
    assert first is not None, [(x.effect, x.reason) for x in ref.rejected]
    assert first.named_effect == "periodic_q2_direction", (first.named_effect, first.structure)
    assert all(v in ("q2", "direction") for s in ref.steps for v in s.variables), [
        s.variables for s in ref.steps]
    # the exact structure on the same design
    added = [n for s in ref.steps for n in s.term.names()]
    d0 = ref.final_design.without(added)
    lib = Library(*d0.library.terms(), _TrueCoupling())
    exact = IdentModel(lib, "exact").fit(d0.with_term(_TrueCoupling()), eliminate=False,
                                         drop_unidentifiable=True).rel_error_
    ratio = ref.rel_error_final / exact
    print(f"\nj1: {ref.rel_error_initial:.4%} -> {ref.rel_error_final:.4%}, exact column "
          f"{exact:.4%}, ratio {ratio:.3f}; held-out {ref.heldout_rel_error_initial:.4%} -> "
          f"{ref.heldout_rel_error_final:.4%}, floor {ref.noise_floor:.4%}; steps "
          f"{[(s.named_effect, s.variables, s.generic) for s in ref.steps]}; first term "
          f"{rec['joints']['j1']['refinement']['steps'][0].get('parameters')}")
    assert ratio <= WITHIN
    assert ref.rel_error_initial > 2 * exact  # the coupling was there to find
    j = rec["joints"]["j1"]
    assert j["fit"]["after"] == pytest.approx(ref.rel_error_final)
    assert j["heldout"]["after"] < j["heldout"]["before"]
    assert j["added"][0]["named_effect"] == "periodic_q2_direction"


def test_cli_refine_and_all_rows_figures(coupled_files, tmp_path, capfd):
    robot, files = coupled_files
    js = tmp_path / "fit.json"
    code = main(["fit", "--robot", str(ARM3), *map(str, files), "--model", "both", "--method",
                 "ls", "--no-consistency", "--refine", "--max-steps", "1", "--json", str(js)])
    text, err = capfd.readouterr()
    assert code == 0, err
    rec = json.loads(js.read_text())
    ref = rec["refinement"]
    # the paper model when fitted, as the single joint's (ident.vocab.refined_model)
    assert ref["model"] == "paper" and ref["max_steps"] == 1
    assert set(ref["joints"]) == set(robot.moving)
    for joint, r in ref["joints"].items():
        for fig in ("fit", "heldout", "noise_floor"):
            assert math.isfinite(r[fig]["before"]) and math.isfinite(r[fig]["after"]), (joint, r)
        assert r["fit"]["after"] <= r["fit"]["before"] + 1e-12
        assert len(r["added"]) <= 1
        assert r["rows"] == rec["models"]["paper"]["samples"][joint]
        if joint != "j1":  # no term in another joint's variables on the uncoupled joints
            assert not any(v.startswith("q") or v.startswith("dq") for a in r["added"]
                           for v in a["variables"]), (joint, r["added"])
    assert ref["joints"]["j1"]["added"][0]["named_effect"] == "periodic_q2_direction"
    assert "refinement of the paper model" in text and "periodic_q2_direction" in text
    j1 = ref["joints"]["j1"]
    print(f"\nj1 (paper model): {j1['fit']['before']:.4%} -> {j1['fit']['after']:.4%}, "
          f"held-out {j1['heldout']['before']:.4%} -> {j1['heldout']['after']:.4%}, floor "
          f"{j1['noise_floor']['before']:.4%} -> {j1['noise_floor']['after']:.4%}; "
          + "; ".join(f"{j}: {r['fit']['before']:.4%} -> {r['fit']['after']:.4%} "
                      f"(floor {r['noise_floor']['after']:.4%})"
                      for j, r in ref["joints"].items() if j != "j1")
          + f"; n-dof refit j1 {ref['refit']['rel_error']['before']['j1']:.4%} -> "
          f"{ref['refit']['rel_error']['after']['j1']:.4%}")
    # the loop closed in the n-dof model: the coupling refitted with every parameter lowers
    # j1's error below the joint's own two-stage refinement
    fit = ref["refit"]
    assert "error" not in fit, fit
    assert fit["rel_error"]["after"]["j1"] < j1["fit"]["after"]
    assert fit["rel_error"]["before"]["j1"] == pytest.approx(j1["fit"]["before"], rel=1e-6)
    # the three payload runs replay one trajectory, no validation file: said once
    assert all(r["heldout"]["one_trajectory"] for r in ref["joints"].values())
    assert text.count(ONE_TRAJECTORY_NOTE) == 1
    # all rows: the estimator's error on every decimated row; shares left out in (0, 1)
    n = rec["preprocessing"]["samples"]
    for name in ("usual", "paper"):
        m = rec["models"][name]
        for joint in robot.moving:
            out = m["rows_left_out"][joint]
            assert out == pytest.approx(1 - m["samples"][joint] / n)
            assert 0 < out < 1
            assert math.isfinite(m["rel_error_all_rows"][joint])
        t3 = rec["table_iii"]
        assert set(t3["fit_all_rows"]) == set(robot.moving)
        for joint in robot.moving:
            # Table III's "all" band on every row is the model's all-rows error
            assert t3["fit_all_rows"][joint][name]["all"] == pytest.approx(
                m["rel_error_all_rows"][joint])
            left = rec["rows_left_out"]["fit"][joint]
            assert left["high"] < left["low"]  # the stiction area is at low velocity
            if name == "usual":  # the selected Table III leaves out the usual fit's rows
                assert left["all"] == pytest.approx(m["rows_left_out"][joint])
    # the paper model's parameters above the threshold are pruned (held at 0) or, when not
    # prunable, flagged; the others not
    paper = rec["models"]["paper"]
    for p, v in paper["parameters"].items():
        rs = v["rel_std_pct"]
        if v["pruned"]:
            assert v["value"] == 0.0 and not v["unidentified"], (p, v)
            assert p in paper["uncertainty"]["pruned"]
            continue
        # or c_m, c_g, OFF of a joint whose load keeps one sign (not separable: flagged)
        one_sign = any(p in (f"c_m{n}", f"c_g{n}", f"OFF{n}") for j, n in
                       zip(rec["robot"]["moving"], rec["robot"]["numbers"], strict=True)
                       if j in paper["one_signed_load"])
        assert v["unidentified"] == (rs is None or rs > DEFAULT_THRESHOLD_PCT or one_sign), (
            p, v)
    assert paper["unidentified"] == [p for p, v in paper["parameters"].items()
                                     if v["unidentified"]]
    for p in paper["unidentified"]:
        assert any(line.startswith(p) and line.endswith("unidentified")
                   for line in text.splitlines()), p
    assert "usual all" in text and "out %" in text


def test_all_rows_equal_the_estimator_on_every_row(coupled_files):
    robot, files = coupled_files
    runs = load_robot_runs(files[:1], robot.moving)
    out = fit_robot(robot, runs, validation=load_robot_runs(files[1:2], robot.moving),
                    models=("usual",), method="ls", feasibility=False)
    est, sig = out["_estimators"]["usual"], out["_identification"]
    rec = out["models"]["usual"]
    every = est.rel_error(sig)
    assert rec["rel_error_all_rows"] == pytest.approx(every)
    assert out["table_iii"]["fit_all_rows"]["j2"]["usual"]["all"] == pytest.approx(every["j2"])
    keep = kept_rows(sig, 0.0)
    assert np.array_equal(keep, sig.columns.keep)
    val = out["_validation_all"]
    assert rec["validation_rel_error_all_rows"] == pytest.approx(est.rel_error(val))
    v_out = rec["validation_rows_left_out"]
    assert v_out["j1"] == pytest.approx(1 - val.columns.keep[:, 0].mean())


def _lagged(seed: int, lag_s: float, dt: float = 0.01, n: int = 3000) -> Signals:
    """One joint sampled every dt whose torque leads its model (J ddq + F_C sign + F_V dq)
    by lag_s, as a command held over a cycle does; the states given as they are."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    w = 2 * np.pi * np.array([0.37, 0.83, 1.3])
    a = np.array([0.8, 0.3, 0.1])

    def motion(tt):
        q = (a * np.sin(np.outer(tt, w))).sum(1)
        dq = (a * w * np.cos(np.outer(tt, w))).sum(1)
        ddq = -(a * w**2 * np.sin(np.outer(tt, w))).sum(1)
        return q, dq, ddq

    q, dq, ddq = motion(t)
    _, dql, ddql = motion(t + lag_s)
    tau = 2.0 * ddql + 1.5 * np.tanh(dql / 0.05) + 3.0 * dql + 2e-3 * rng.standard_normal(n)
    s = concat([make_experiment(f"lag {seed}", t, q, tau)])
    return dataclasses.replace(s, dq=dq, ddq=ddq)


@pytest.mark.parametrize(("cycle_s", "name"), [(0.01, "zero_order_hold"),
                                               (0.001, "torque_lag")])
def test_zero_order_hold_named_against_the_raw_cycle(cycle_s, name):
    """A 5 ms lag on 10 ms samples: half of a 10 ms raw cycle (a zero-order hold), but ten
    half-cycles of a 1 ms raw cycle (a torque lag)."""
    s = _lagged(0, 0.005)
    lib = Library(RigidBody(revolute=False), Coulomb(), Viscous(), Offset())
    design = fit_rows_design(lib, s, np.abs(s.dq) > 0.15)
    ref = refine(design, IdentModel(lib), max_steps=2, library=False, cycle_s=cycle_s)
    lags = [st for st in ref.steps if st.effect == "torque_lag"]
    assert lags, [(x.effect, x.reason) for x in ref.rejected]
    assert lags[0].named_effect == name, lags[0].structure


def test_refinement_judged_on_validation_files_too(coupled_files):
    """With validation files, joint 1's step lowers their error too (rows selected alike),
    and the record gives it before and after; a joint that is not moving is refused."""
    robot, files = coupled_files
    runs = load_robot_runs(files[:2], robot.moving)
    val = load_robot_runs(files[2:], robot.moving)
    out = fit_robot(robot, runs, val, models=("usual",), method="ls", feasibility=False)
    rec = refine_robot(out, max_steps=1, joints=["j1"])
    j1 = rec["joints"]["j1"]
    assert j1["added"][0]["named_effect"] == "periodic_q2_direction", j1["added"]
    v = j1["validation"]
    assert v is not None and v["after"] < 0.5 * v["before"], v
    assert ONE_TRAJECTORY_NOTE not in format_refinement(rec)
    ref = out["_refinements"]["j1"]
    vkeep = out["_validation_all"].columns.keep[:, 0]
    assert len(ref.final_validation_design) == int(vkeep.sum())
    with pytest.raises(DataError, match=r"joints \['j9'\] are not moving joints"):
        refine_robot(out, joints=["j9"])


def test_states_chain_refines_on_its_own_rows(coupled_files):
    """On the states chain the fit's rows are |dq_j| > dq_min of the decimated states: the
    refinement uses exactly those, and finds the same named coupling."""
    robot, files = coupled_files
    out = fit_robot(robot, load_robot_runs(files, robot.moving), models=("usual",),
                    method="ls", feasibility=False, chain="states")
    rec = refine_robot(out, max_steps=1, joints=["j1"])
    est, sig = out["_estimators"]["usual"], out["_identification"]
    assert sig.columns is None
    dq_min = out["preprocessing"]["dq_min"]
    assert rec["joints"]["j1"]["rows"] == int(est.n_samples_[0]) == int(
        (np.abs(sig.dq[:, 0]) > dq_min).sum())
    assert rec["joints"]["j1"]["added"][0]["named_effect"] == "periodic_q2_direction"
