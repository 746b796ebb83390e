"""The robot path's columns chain (ident.robot.design) is the single-joint chain: on the
example campaign of the single-joint simulator (RX130L joint 3, three payloads) the robot path
with joints 1, 2, 4, 5, 6 locked gives the numbers of ``ident.fitting.fit_models`` -- same
rows, same columns, the payload ratio identified (eq. 35), the sign check of the paper model
included. The demo's MCAP logs (IDIM-IV, half-cycle torque delay) are checked end to end in
``tests/test_demo_e2e.py``."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from example_campaign import simulate_example_campaign
from one_joint_products import products_as_single

from ident.cli_robot import fit_robot
from ident.estimate import fit_least_squares
from ident.fitting import SIGN_CHECK_MIN_KEPT, fit_models
from ident.loaders import make_experiment
from ident.robot import RobotIdentError
from ident.robot import design as design_mod
from ident.robot.base import single_joint_map
from ident.robot.design import design_runs, resolve_design, sign_checked
from ident.robot.estimate import RobotModel
from ident.robot.loaders import RawRobotRun
from ident.robot.regressor import RobotRegressor
from ident.robot.signals import RobotPayloadData
from trajectories.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
FRICTION = {"F_C": "FC3", "F_V": "FV3", "tau_off": "OFF3", "Ma_ratio": "Ma_ratio"}


@pytest.fixture(scope="module")
def campaign_runs():
    """The example campaign simulated offline (seeds 11-13): single-joint experiments and the
    same arrays as one-joint robot runs (the payload as the log gives it: mass, lever arm)."""
    _, plan, sims = simulate_example_campaign(11)
    exps, runs = [], []
    for i, (p, r) in enumerate(zip(plan.payloads, sims, strict=True)):
        exps.append(make_experiment(f"payload{i}.csv", r.t, r.q, r.tau_ref,
                                    payload_mass=p.mass_kg, payload_arm=p.arm_m))
        pay = RobotPayloadData(p.mass_kg, arm_m=p.arm_m) if p.mass_kg else RobotPayloadData()
        runs.append(RawRobotRun(f"payload{i}.csv", r.t, r.q[:, None], r.tau_ref[:, None],
                                payload=pay))
    robot = load_robot(ROOT / "examples" / "robots" / "rx130l.toml")
    return exps, runs, robot


def _single_joint_values(est: RobotModel) -> dict[str, float]:
    """J, MX, MY (single_joint_map of the base parameters) and the friction by the
    single-joint names."""
    smap = single_joint_map(est.base_, est.regressor_)
    out = smap.values(est.coef_[:est.n_base_])
    out.update({n: est.params_[r] for n, r in FRICTION.items()})
    return out


@pytest.mark.slow
def test_columns_chain_gives_the_single_joint_fit(campaign_runs):
    exps, runs, robot = campaign_runs
    single = fit_models(exps, models=["usual", "paper"])
    rec = fit_robot(robot, runs, models=("usual", "paper"), method="ls")
    assert rec["payload"] == "ratio"  # lever-arm payloads: the ratio is identified (eq. 35)
    d = single.designs["usual"]
    for k in ("cutoff_hz", "decimation", "trim", "guard", "torque_delay", "dq_min"):
        assert rec["preprocessing"][k] == d.settings()[k], k
    est = rec["_estimators"]["usual"]
    assert int(est.n_samples_[0]) == len(d)  # same rows (stiction area + sign check)
    ours = _single_joint_values(est)
    ref = single.models["usual"]
    assert set(ours) == set(ref.coef_)
    for n, v in ref.coef_.items():
        assert ours[n] == pytest.approx(v, rel=1e-8, abs=1e-10), n
        assert f"{ours[n]:.6g}" == f"{v:.6g}", n
    # the paper model is fitted on the same rows (its bilinear form is not eq. 42's products,
    # so its numbers are its own: tests/test_robot_fit.py compares them on exact data)
    assert rec["models"]["paper"]["samples"]["j3"] == len(d)


def test_columns_chain_products_form_is_eq42_on_the_decimated_samples(campaign_runs):
    """The paper model's products form (``form="products"``, eq. 42 on every joint) through
    the columns chain on a one-joint robot, against the single-joint paper fit
    (``fit_models``: sign check, LS, nothing eliminated on these data).

    Same rows (the stiction area, the guard and the sign check of a first usual fit), same
    quadrant decisions (sign(tau_out_hat dq) of the usual fit, on every row), same columns
    J, MX, MY, payload, sign, dq, 1. But the single-joint chain forms the columns of eq. 42
    -- P+ W, P+ E W, P- W, -P- E W and the quadrant Coulomb columns -- at FULL rate and then
    low-passes and decimates them, whereas the robot path (``JointMoments``) weights the
    decimated columns by P and E of the decimated samples: filt(P E w) != P filt(E) filt(w)
    wherever P or E varies within the filter's window. Measured on this campaign (26769
    rows, q_s 0.03 rad/s): no row changes quadrant, but 2189 rows of the full-rate P+
    columns are fractional (the low-pass mixes both quadrants there); the P columns differ by
    0.2-1.0 % in norm, the E ddq columns by 50-67 % (E varies fast at low velocity, where the
    acceleration is large), the other E columns by 0.8-2.7 %. So equality to 1e-8 is impossible
    without forming the quadrant and E columns at full rate in the robot chain; what holds:

    * exactly (1e-8, values, deviations and relative error): the robot estimate is eq. 42's
      least squares on the single-joint (usual) design's decimated columns with P and E taken
      on the decimated samples -- the single-joint model on the robot path's samples;
    * against the single-joint paper fit: the products without E (a_*, c_*, F_V, tau_off)
      agree within 1e-2 relative (measured max 2.0e-3: a_g_MY), the relative error within
      5 % (measured 0.003539 against 0.003654: -3.2 %); the E products differ more
      (measured up to 82 %, b_g_J: 61.8 against 34.0, std 1.0 -- both many sigma from the
      simulator's b_g J = 0.25 x 31 = 7.75: the E ddq columns are biased in both chains)."""
    exps, runs, robot = campaign_runs
    single = fit_models(exps, models=["usual", "paper"])
    ref, du, dp = single.models["paper"], single.designs["usual"], single.designs["paper"]
    assert not ref.removed_ and single.settings.get("load_model") is not None
    reg = RobotRegressor(robot)
    design = resolve_design(runs)
    sig, dq_min = design_runs(runs, reg, design)
    design = replace(design, dq_min=dq_min)
    for k in ("cutoff_hz", "decimation", "trim", "guard", "torque_delay", "dq_min"):
        assert design.as_dict()[k] == du.settings()[k], k
    # the sign check of fit_robot: a first usual fit (payload ratio, as the single joint)
    first = RobotModel(reg, "usual", payload_ratio=True).fit(sig)
    sig, _ = sign_checked(sig, runs, design, first.load_torque, SIGN_CHECK_MIN_KEPT)
    est = RobotModel(reg, "paper", form="products", q_s=single.q_s,
                     quadrant_band=0.0).fit(sig)
    assert int(est.n_samples_[0]) == len(dp) == len(du)  # same rows
    ours, ours_std = products_as_single(est, single_joint_map(est.base_, est.regressor_))
    assert set(ours) == set(ref.coef_)
    # eq. 42 on the single-joint design's decimated columns, P and E of the decimated samples
    inner, chi = single.settings["load_model"]
    Wl = du.W[:, [du.names.index(n) for n in inner.names()]]
    dq = du.signals.dq
    pp = 0.5 * (1.0 + np.sign(Wl @ np.asarray(chi) * dq))
    pm = 1.0 - pp
    e = np.exp(-np.abs(dq) / single.q_s)
    sg, n = du.W[:, du.names.index("F_C")], Wl.shape[1]
    W42 = np.empty((dq.size, 4 * n + 6))
    W42[:, 0:2 * n:2], W42[:, 1:2 * n:2] = pp[:, None] * Wl, (pp * e)[:, None] * Wl
    W42[:, 2 * n:4 * n:2], W42[:, 2 * n + 1:4 * n:2] = pm[:, None] * Wl, -(pm * e)[:, None] * Wl
    W42[:, 4 * n:] = np.column_stack([pp * sg, pp * e * sg, pm * sg, pm * e * sg,
                                      du.W[:, du.names.index("F_V")], np.ones(dq.size)])
    exact = fit_least_squares(W42, du.Y, ref.names_, eliminate=False)
    for name, v, sd in zip(exact.names, exact.chi, exact.std, strict=True):
        assert ours[name] == pytest.approx(v, rel=1e-8), name
        assert ours_std[name] == pytest.approx(sd, rel=1e-8), name
    assert est.rel_error_["j3"] == pytest.approx(exact.rel_error, rel=1e-8)
    # the same quadrant decisions as the single-joint columns (full rate, then low-passed)
    pfull = dp.W[:, dp.names.index("c_m")] / sg
    np.testing.assert_array_equal(np.round(pfull), pp)
    # the closest true statement against the single-joint paper fit (docstring)
    for name, v in ref.coef_.items():
        if not name.startswith(("b_", "d_")):
            assert ours[name] == pytest.approx(v, rel=1e-2), name
    assert est.rel_error_["j3"] == pytest.approx(ref.rel_error_, rel=0.05)


def test_payload_ratio_needs_a_payload(campaign_runs):
    _, runs, robot = campaign_runs
    reg = RobotRegressor(robot)
    empty = [RawRobotRun(r.source, r.t[:4000], r.q[:4000], r.tau[:4000]) for r in runs[:1]]
    sig, _ = design_runs(empty, reg, resolve_design(empty))
    with pytest.raises(RobotIdentError, match="no experiment carries a payload"):
        RobotModel(reg, payload_ratio=True).fit(sig)


def test_design_errors_are_one_line_naming_the_run(campaign_runs, monkeypatch):
    _, runs, robot = campaign_runs
    reg = RobotRegressor(robot)
    short = [RawRobotRun("short.csv", runs[0].t[:40], runs[0].q[:40], runs[0].tau[:40])]
    with pytest.raises(RobotIdentError, match=r"short\.csv: 40 samples, too few"):
        design_runs(short, reg, resolve_design(short))
    with pytest.raises(RobotIdentError, match=r"payload0\.csv: no reference trajectory"):
        design_runs(runs[:1], reg, resolve_design(runs[:1]), instruments=True)
    monkeypatch.setattr(design_mod, "MAX_BYTES", 1000)
    with pytest.raises(RobotIdentError, match=r"payload0\.csv: the full-rate regressor needs"):
        design_runs(runs[:1], reg, resolve_design(runs[:1]))
    with pytest.raises(RobotIdentError, match="torque_delay"):
        resolve_design(runs, torque_delay=1.5)


def test_decimated_columns_equal_the_single_joint_design_columns(campaign_runs):
    """Linear columns commute with the filters: the decimated inertia column is the decimated
    ddq; sign(dq) is decided at full rate (not the sign of the decimated dq); rows of the
    stiction area and of the edges are not kept."""
    _, runs, robot = campaign_runs
    reg = RobotRegressor(robot)
    part = [RawRobotRun(r.source, r.t[:20000], r.q[:20000], r.tau[:20000], payload=r.payload)
            for r in runs]
    settings = resolve_design(part)
    sig, dq_min = design_runs(part, reg, settings)
    cols = sig.columns
    assert cols is not None and cols.W.shape == (1, reg.p, sig.n)
    assert settings.torque_delay == 0.0  # not jointid MCAP logs: unknown timing
    # 1 % of the largest full-rate |dq| (DQ_MIN_FRACTION), close to the decimated one's
    assert dq_min == pytest.approx(0.01 * np.abs(sig.dq).max(), rel=0.02)
    zz = list(reg.standard_names).index("ZZ3")
    np.testing.assert_allclose(cols.W[0, zz], sig.ddq[:, 0], rtol=1e-9, atol=1e-9)
    smeared = np.abs(cols.sign[:, 0]) < 0.9
    assert smeared.any()  # sign(dq) filtered at full rate: fractional near reversals
    assert not np.any(cols.keep[smeared, 0])  # ... and such rows are not kept
    assert not cols.keep[0, 0] and not cols.keep[-1, 0]  # the edges
    # at full rate the stiction area |dq| < dq_min is out; the decimated |dq| of a kept row
    # is then about above it (the anti-alias filter smooths the differentiated quantisation)
    assert np.abs(sig.dq[cols.keep[:, 0], 0]).min() > 0.5 * dq_min
