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
from ident.models import IdentModel
from ident.robot import RobotIdentError
from ident.robot import design as design_mod
from ident.robot.base import base_parameters, single_joint_map
from ident.robot.design import design_runs, products_columns, resolve_design, sign_checked
from ident.robot.estimate import RobotModel
from ident.robot.loaders import RawRobotRun
from ident.robot.regressor import RobotRegressor
from ident.robot.signals import RobotPayloadData
from trajectories.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
FRICTION = {"F_C": "FC3", "F_V": "FV3", "tau_off": "OFF3", "Ma_ratio": "Ma_ratio"}


@pytest.fixture(scope="module")
def campaign_runs():
    """The example campaign: :func:`example_campaign_runs`."""
    return example_campaign_runs()


def example_campaign_runs():
    """The example campaign simulated offline (seeds 11-13): single-joint experiments and the
    same arrays as one-joint robot runs (the payload as the log gives it: mass, lever arm),
    each run's reference position (the planned trajectory at its cycles) [rad], and the
    robot (examples/robots/rx130l.toml)."""
    _, plan, sims = simulate_example_campaign(11)
    exps, runs, refs = [], [], []
    for i, (p, r) in enumerate(zip(plan.payloads, sims, strict=True)):
        exps.append(make_experiment(f"payload{i}.csv", r.t, r.q, r.tau_ref,
                                    payload_mass=p.mass_kg, payload_arm=p.arm_m))
        pay = RobotPayloadData(p.mass_kg, arm_m=p.arm_m) if p.mass_kg else RobotPayloadData()
        runs.append(RawRobotRun(f"payload{i}.csv", r.t, r.q[:, None], r.tau_ref[:, None],
                                payload=pay))
        refs.append(plan.reference.q[np.minimum(r.cycle, plan.reference.q.size - 1)])
    robot = load_robot(ROOT / "examples" / "robots" / "rx130l.toml")
    return exps, runs, robot, refs


def _single_joint_values(est: RobotModel) -> dict[str, float]:
    """J, MX, MY (single_joint_map of the base parameters) and the friction by the
    single-joint names."""
    smap = single_joint_map(est.base_, est.regressor_)
    out = smap.values(est.coef_[:est.n_base_])
    out.update({n: est.params_[r] for n, r in FRICTION.items()})
    return out


@pytest.mark.slow
def test_columns_chain_gives_the_single_joint_fit(campaign_runs):
    exps, runs, robot, _ = campaign_runs
    single = fit_models(exps, models=["usual", "paper"])
    rec = fit_robot(robot, runs, models=("usual", "paper"), method="ls")
    assert rec["payload"] == "ratio"  # lever-arm payloads: the ratio is identified (eq. 35)
    d = single.designs["usual"]
    for k in ("cutoff_hz", "decimation", "trim", "guard", "torque_delay", "dq_min"):
        assert rec["preprocessing"][k] == d.settings()[k], k
    est = rec["_estimators"]["usual"]
    assert int(est.n_samples_[0]) == len(d)  # same rows (stiction area + sign check)
    ours = _single_joint_values(est)
    # the single-joint least squares on the design's Term columns (fit_models' own estimate
    # is RobotModel's now: not an independent reference)
    ref = IdentModel(single.models["usual"].library, "usual").fit(d, eliminate=False)
    assert set(ours) == set(ref.coef_)
    for n, v in ref.coef_.items():
        assert ours[n] == pytest.approx(v, rel=1e-8, abs=1e-10), n
        assert f"{ours[n]:.6g}" == f"{v:.6g}", n
    # the paper model is fitted on the same rows (its bilinear form is not eq. 42's products,
    # so its numbers are its own: tests/test_robot_fit.py compares them on exact data)
    assert rec["models"]["paper"]["samples"]["j3"] == len(d)


def test_columns_chain_products_form_is_the_single_joint_paper_fit(campaign_runs):
    """The paper model's products form (``form="products"``, eq. 42 on every joint) through
    the columns chain on a one-joint robot IS the single-joint paper fit (``fit_models``: the
    sign check and the quadrants of a first usual fit, LS, nothing eliminated on these data)
    when its columns are formed at full rate (``products_columns``), as the single-joint chain
    forms them: P+ W, P+ E W, P- W, -P- E W and the quadrant Coulomb columns, P from
    sign(tau_out_hat dq) of the first usual fit and E = exp(-|dq| / q_s) at full rate, then
    low-passed and decimated with the torque. Same rows, same columns, so the same linear
    least squares: values, standard deviations (eq. 15) and relative error to 1e-8 (measured:
    4e-13 at worst, b_m_MY).

    Without them (``columns.products`` None) the products form weights the DECIMATED columns
    by P and E of the decimated samples: filt(P E w) != P filt(E) filt(w) wherever P or E
    varies within the filter's window. Then what holds exactly is eq. 42's least squares on
    the single-joint (usual) design's decimated columns with P and E of the decimated
    samples; against the single-joint paper fit the products without E agree within 1e-2
    (measured 2.0e-3), the E products do not (measured up to 82 %, b_g_J): the 50-67 %
    difference of the E ddq columns at low velocity."""
    exps, runs, robot, _ = campaign_runs
    single = fit_models(exps, models=["usual", "paper"])
    du, dp = single.designs["usual"], single.designs["paper"]
    # the reference: the single-joint least squares (QR) on the single-joint design's
    # columns (ident.models' Terms), not fit_models' estimate (which is this very fit now)
    ref = IdentModel(single.models["paper"].library, "paper").fit(dp, eliminate=False)
    assert not single.models["paper"].removed_ and single.settings.get("load_model") is not None
    reg = RobotRegressor(robot)
    design = resolve_design(runs)
    sig, dq_min = design_runs(runs, reg, design)
    design = replace(design, dq_min=dq_min)
    for k in ("cutoff_hz", "decimation", "trim", "guard", "torque_delay", "dq_min"):
        assert design.as_dict()[k] == du.settings()[k], k
    # the sign check of fit_robot: a first usual fit (payload ratio, as the single joint)
    first = RobotModel(reg, "usual", payload_ratio=True).fit(sig)
    sig, _ = sign_checked(sig, runs, design, first.load_torque, SIGN_CHECK_MIN_KEPT)
    smap = single_joint_map(base_parameters(reg), reg)

    # the columns formed at full rate: the single-joint paper fit
    full = products_columns(sig, runs, reg, design, first.load_torque, single.q_s)
    est = RobotModel(reg, "paper", form="products", q_s=single.q_s).fit(full)
    assert est.full_rate_products_ and est.quadrant_from_ is None
    assert int(est.n_samples_[0]) == len(dp) == len(du)  # same rows
    ours, ours_std = products_as_single(est, smap)
    assert set(ours) == set(ref.coef_)
    for name, v in ref.coef_.items():
        assert ours[name] == pytest.approx(v, rel=1e-8), name
        assert ours_std[name] == pytest.approx(ref.std_[name], rel=1e-8), name
    assert est.rel_error_["j3"] == pytest.approx(ref.rel_error_, rel=1e-8)
    # ... its columns are the single-joint design's (the Coulomb ones by name), and the
    # prediction on them gives the fit's relative error
    prod = full.columns.products
    keep = full.columns.keep[:, 0]
    for i, name in enumerate(("c_m", "d_m", "c_g", "d_g")):
        np.testing.assert_allclose(prod.coulomb[i, keep, 0], dp.W[:, dp.names.index(name)],
                                   rtol=1e-9, atol=1e-12)
    rho = est.residual(full)[keep, 0]
    assert np.linalg.norm(rho) / np.linalg.norm(full.tau[keep, 0]) == pytest.approx(
        est.rel_error_["j3"], rel=1e-9)

    # without them: eq. 42 on the decimated samples (P and E of the decimated samples)
    est = RobotModel(reg, "paper", form="products", q_s=single.q_s,
                     quadrant_band=0.0).fit(sig)
    assert not est.full_rate_products_ and int(est.n_samples_[0]) == len(dp)
    dec, dec_std = products_as_single(est, smap)
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
        assert dec[name] == pytest.approx(v, rel=1e-8), name
        assert dec_std[name] == pytest.approx(sd, rel=1e-8), name
    assert est.rel_error_["j3"] == pytest.approx(exact.rel_error, rel=1e-8)
    # the same quadrant decisions as the full-rate columns on every row (none changes
    # quadrant on these data), though the low-pass blends both quadrants on some rows
    np.testing.assert_array_equal(np.round(prod.pplus[keep, 0]), pp)
    assert np.any(np.abs(prod.pplus[keep, 0] - pp) > 1e-3)
    for name, v in ref.coef_.items():
        if not name.startswith(("b_", "d_")):
            assert dec[name] == pytest.approx(v, rel=1e-2), name


def test_columns_chain_products_form_is_the_single_joint_iv_paper_fit(campaign_runs):
    """The same with IDIM-IV (the reference trajectory of each run given to both paths):
    ``products_columns(instruments=True)`` forms the instruments as the single-joint chain
    does (the load columns on the reference acceleration times the same P and E), and the
    products form's IV estimate is ``fit_models``' paper fit: values, standard deviations
    and relative error to 1e-8 (measured 1.0e-12)."""
    _, runs, robot, refs = campaign_runs
    exps = [make_experiment(r.source, r.t, r.q[:, 0], r.tau[:, 0], q_ref=q,
                            payload_mass=r.payload.mass, payload_arm=r.payload.arm_m or 0.0)
            for r, q in zip(runs, refs, strict=True)]
    runs = [replace(r, q_ref=q[:, None]) for r, q in zip(runs, refs, strict=True)]
    single = fit_models(exps, models=["usual", "paper"])
    dp = single.designs["paper"]
    # the single-joint IDIM-IV on the design's columns and instruments (not fit_models')
    ref = IdentModel(single.models["paper"].library, "paper").fit(dp, eliminate=False)
    assert dp.Z is not None and not single.models["paper"].removed_  # nothing eliminated
    reg = RobotRegressor(robot)
    design = resolve_design(runs, instruments=True)
    sig, dq_min = design_runs(runs, reg, design, instruments=True)
    design = replace(design, dq_min=dq_min)
    first = RobotModel(reg, "usual", "iv", payload_ratio=True).fit(sig)
    sig, _ = sign_checked(sig, runs, design, first.load_torque, SIGN_CHECK_MIN_KEPT)
    full = products_columns(sig, runs, reg, design, first.load_torque, single.q_s,
                            instruments=True)
    est = RobotModel(reg, "paper", "iv", form="products", q_s=single.q_s).fit(full)
    assert int(est.n_samples_[0]) == len(dp)
    ours, ours_std = products_as_single(est, single_joint_map(est.base_, est.regressor_))
    assert set(ours) == set(ref.coef_)
    for name, v in ref.coef_.items():
        assert ours[name] == pytest.approx(v, rel=1e-8), name
        assert ours_std[name] == pytest.approx(ref.std_[name], rel=1e-8), name
    assert est.rel_error_["j3"] == pytest.approx(ref.rel_error_, rel=1e-8)


def test_payload_ratio_needs_a_payload(campaign_runs):
    _, runs, robot, _ = campaign_runs
    reg = RobotRegressor(robot)
    empty = [RawRobotRun(r.source, r.t[:4000], r.q[:4000], r.tau[:4000]) for r in runs[:1]]
    sig, _ = design_runs(empty, reg, resolve_design(empty))
    with pytest.raises(RobotIdentError, match="no experiment carries a payload"):
        RobotModel(reg, payload_ratio=True).fit(sig)


def test_design_errors_are_one_line_naming_the_run(campaign_runs, monkeypatch):
    _, runs, robot, _ = campaign_runs
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


def test_products_columns_errors_are_one_line(campaign_runs, monkeypatch):
    """products_columns and the products form on them refuse, in one line, what does not
    fit: unresolved settings, other runs, a bad load torque, too much memory, another q_s,
    the options that would re-decide the quadrants, signals without them."""
    _, runs, robot, _ = campaign_runs
    reg = RobotRegressor(robot)
    part = [RawRobotRun(r.source, r.t[:6000], r.q[:6000], r.tau[:6000], payload=r.payload)
            for r in runs[:2]]
    settings = resolve_design(part, cutoff_hz=50.0)
    sig, dq_min = design_runs(part, reg, settings)
    resolved = replace(settings, dq_min=dq_min)

    def load(s):
        return s.ddq  # an inertial load: both signs, a quadrant on every row

    cases = [
        (lambda: products_columns(sig, part, reg, settings, load), "resolved settings"),
        (lambda: products_columns(sig, part[:1], reg, resolved, load), "2 experiments, 1 run"),
        (lambda: products_columns(sig, part, reg, resolved, lambda s: s.ddq[:, :0]),
         r"payload0\.csv: load_torque gave"),
        (lambda: products_columns(sig, part, reg, resolved, load, q_s=-1.0), "q_s: expected"),
    ]
    for call, match in cases:
        with pytest.raises(RobotIdentError, match=match) as err:
            call()
        assert "\n" not in str(err.value)
    full = products_columns(sig, part, reg, resolved, load, q_s=0.05)
    with pytest.raises(RobotIdentError, match="formed with q_s") as err:
        RobotModel(reg, "paper", form="products").fit(full)  # default q_s 0.03
    for kw, match in (({"quadrant": "measured"}, "quadrant='measured' does not apply"),
                      ({"method": "iv"}, "method='iv'")):
        with pytest.raises(RobotIdentError, match=match) as err:
            RobotModel(reg, "paper", form="products", q_s=0.05, **kw).fit(full)
        assert "\n" not in str(err.value)
    fitted = RobotModel(reg, "paper", form="products", q_s=0.05).fit(full)
    assert fitted.full_rate_products_ and np.all(np.isfinite(fitted.predict(full)))
    with pytest.raises(RobotIdentError, match="predict needs signals carrying them"):
        fitted.predict(sig)
    # the usual model (and the bilinear form) ignore them: the same fit as without
    a = RobotModel(reg, "usual").fit(full)
    np.testing.assert_array_equal(a.coef_, RobotModel(reg, "usual").fit(sig).coef_)
    monkeypatch.setattr(design_mod, "MAX_BYTES", 1000)
    with pytest.raises(RobotIdentError, match=r"payload0\.csv: the full-rate products need") \
            as err:
        products_columns(sig, part, reg, resolved, load)
    assert "\n" not in str(err.value)


def test_decimated_columns_equal_the_single_joint_design_columns(campaign_runs):
    """Linear columns commute with the filters: the decimated inertia column is the decimated
    ddq; sign(dq) is decided at full rate (not the sign of the decimated dq); rows of the
    stiction area and of the edges are not kept."""
    _, runs, robot, _ = campaign_runs
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


def test_products_cache_gives_the_same_floats(campaign_runs):
    """``products_columns(cache=...)`` (the q_s scan of the single-joint fit) keeps, per run,
    what does not depend on q_s and forms only the E products again: for each q_s, with the
    instruments, every array equals the uncached one bit for bit -- whichever q_s filled the
    cache -- and the cache is used (a load model changed after it was filled is not seen)."""
    _, runs, robot, refs = campaign_runs
    reg = RobotRegressor(robot)
    part = [RawRobotRun(r.source, r.t[:6000], r.q[:6000], r.tau[:6000], payload=r.payload,
                        q_ref=q[:6000, None]) for r, q in zip(runs[:2], refs[:2], strict=True)]
    settings = resolve_design(part, cutoff_hz=50.0, instruments=True)
    sig, dq_min = design_runs(part, reg, settings, instruments=True, keep_full=True)
    resolved = replace(settings, dq_min=dq_min)

    def load(s):
        return s.ddq  # an inertial load: both signs, a quadrant on every row

    cache: dict = {}
    for q_s in (0.05, 0.02, 0.05):
        fresh = products_columns(sig, part, reg, resolved, load, q_s, instruments=True)
        cached = products_columns(sig, part, reg, resolved, load, q_s, instruments=True,
                                  cache=cache)
        a, b = fresh.columns.products, cached.columns.products
        assert a.q_s == b.q_s
        for x, y in zip((*a.loads, *a.loads_z, a.coulomb, a.pplus),
                        (*b.loads, *b.loads_z, b.coulomb, b.pplus), strict=True):
            np.testing.assert_array_equal(x, y)
    assert set(cache) == {0, 1}
    other = products_columns(sig, part, reg, resolved, lambda s: -s.ddq, 0.05,
                             instruments=True, cache=cache)
    np.testing.assert_array_equal(other.columns.products.pplus, b.pplus)  # from the cache
