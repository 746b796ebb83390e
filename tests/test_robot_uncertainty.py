"""Issue 22 items 4 and 6: honest sigma (jackknife over blocks, IDIM-IV check), the
errors-in-variables flag and the pruning of the paper model (ident.robot.uncertainty).

Fast tests on a short simulated 3-dof arm (sim_drivers.arm, examples/robots/arm3.toml) whose
friction is the usual model's exactly (a = 1, b = d = 0, c_m = c_g): the estimator reads the
true states and the applied torque plus white noise (clean: eq. 13 holds, no flag), or the
same with a white noise on the measured acceleration (errors in variables: the least-squares
inertias are biased towards zero, the IDIM-IV ones, on the reference acceleration, are not;
the flag must fire and name the numbers).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import ident.robot.uncertainty as unc
from daq.app.cli import main
from ident.robot import RobotIdentError
from ident.robot.base import base_parameters
from ident.robot.estimate import RobotModel
from ident.robot.regressor import RobotRegressor
from ident.robot.signals import RobotSignals
from ident.robot.uncertainty import PRUNABLE, RATIO_FLAG, Z_IV, assess, jackknife_units
from sim_drivers.arm import ArmGains, ArmParams, model_reference, simulate_arm
from trajectories.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def arm3_usual():
    robot = load_robot(ROOT / "examples" / "robots" / "arm3.toml")
    f0 = ArmParams.from_robot(robot).friction
    friction = dict(a_m=1.0, a_g=1.0, b_m=0.0, b_g=0.0, d_m=0.0, d_g=0.0, c_g=f0.c_m)
    params = ArmParams.from_robot(robot, friction)
    ref = model_reference(params.model, center=[0.0, -1.9, 0.6], fraction=0.9,
                          duration_s=6.0, seed=3)
    run = simulate_arm(params, ref, ArmGains.for_params(params), seed=4)
    reg = RobotRegressor(robot)
    return params, reg, base_parameters(reg), run


def _signals(params, reg, run, seed: int, ddq_noise: float = 0.0, stride: int = 4):
    rng = np.random.default_rng(seed)
    s = slice(None, None, stride)
    tau = run.tau_applied + rng.standard_normal(run.tau_applied.shape) * (
        params.drive.torque_noise_std_Nm)
    tau = np.where(run.sliding, tau, np.nan)[s]
    ddq = run.ddq_true[s]
    if ddq_noise:
        ddq = ddq + rng.standard_normal(ddq.shape) * ddq_noise * ddq.std(axis=0)
    return RobotSignals(t=run.t[s], q=run.q_true[s], dq=run.dq_true[s], ddq=ddq, tau=tau,
                        joints=reg.joints, q_ref=run.q_ref[s], source="sim arm3")


def test_jackknife_units_cover_every_row_once(arm3_usual):
    params, reg, base, run = arm3_usual
    sig = _signals(params, reg, run, 0)
    units, text = jackknife_units([sig, sig], 7)
    assert len(units) == 8 and "4 contiguous blocks of each of 2 experiments" in text
    assert sum(u.n for u in units) == 2 * sig.n
    np.testing.assert_array_equal(np.concatenate([u.t for u in units[:4]]), sig.t)
    units, text = jackknife_units([sig, sig], 2)
    assert len(units) == 2 and text == "2 experiments"


def test_clean_data_not_flagged_and_sigma_kept(arm3_usual):
    params, reg, base, run = arm3_usual
    sig = _signals(params, reg, run, 1)
    m = RobotModel(reg, "usual", "ls", base=base).fit(sig)
    coef = m.coef_.copy()
    u = assess(m, sig, n_blocks=20)
    np.testing.assert_array_equal(m.coef_, coef)  # the usual model is never pruned
    assert u.n_replicates == 20 and u.n_failed == 0 and u.z_iv is not None
    flags = {j: f["errors_in_variables"] for j, f in u.flags.items()}
    assert not any(flags.values()), {j: f["reason"] for j, f in u.flags.items()}
    # white errors: the jackknife agrees with eq. 15 (within its own sampling spread)
    ratio = u.std_jackknife / u.std_analytic
    assert 0.5 < np.median(ratio) < 1.6, ratio
    # the honest sigma: max(robust eq. 15, jackknife), raised where |z_iv| > Z_IV
    big = np.abs(np.nan_to_num(u.z_iv)) > Z_IV
    np.testing.assert_array_equal(u.std[~big], np.fmax(u.std_robust, u.std_jackknife)[~big])
    rec = u.to_json()
    assert set(rec["joints"]) == set(reg.joints) and rec["pruned"] == []


def test_errors_in_variables_flagged_with_numbers(arm3_usual):
    params, reg, base, run = arm3_usual
    sig = _signals(params, reg, run, 1, ddq_noise=0.5)
    m = RobotModel(reg, "usual", "ls", base=base).fit(sig)
    u = assess(m, sig, n_blocks=20)
    flagged = [j for j, f in u.flags.items() if f["errors_in_variables"]]
    assert flagged, u.flags
    for j in flagged:
        f = u.flags[j]
        assert f["reason"].startswith("errors-in-variables:"), f
        assert f["z_iv"] > Z_IV or f["sigma_ratio"] > RATIO_FLAG, f
    # where the fit and IV disagree the honest sigma covers the difference
    big = np.abs(np.nan_to_num(u.z_iv)) > Z_IV
    d = np.abs(m.coef_ - u.coef_iv)
    assert np.all(u.std[big] >= d[big])
    truth = m.truth_vector(params.truth(None))
    ok = np.isfinite(truth)
    z_a = np.abs(m.coef_ - truth)[ok] / u.std_analytic[ok]
    z_h = np.abs(m.coef_ - truth)[ok] / u.std[ok]
    print(f"\nEIV: |z| > 2 with the analytic sigma {np.mean(z_a > 2):.0%}, honest "
          f"{np.mean(z_h > 2):.0%}")
    assert np.mean(z_a > 2) > 0.3  # the analytic sigma understates
    assert np.mean(z_h > 2) <= 0.2


def test_bad_blocks_one_line(arm3_usual):
    params, reg, base, run = arm3_usual
    sig = _signals(params, reg, run, 1, stride=20)
    m = RobotModel(reg, "usual", "ls", base=base).fit(sig)
    with pytest.raises(RobotIdentError, match="expected 0 .no jackknife"):
        assess(m, sig, n_blocks=1)
    with pytest.raises(RobotIdentError, match="not fitted"):
        assess(RobotModel(reg), sig)


def test_paper_model_pruned_terms_left_out_of_the_prediction(arm3_usual):
    """Truth b = d = 0 (no Stribeck, no load-dependent Stribeck): the paper model's b, d have
    a relative sigma far above the threshold; they are pruned (held at 0, the model refitted),
    the prediction no longer depends on q_s on the joints whose b, d are all pruned, and the
    error on held-out rows (another noise draw) is not worse than the unpruned fit's."""
    params, reg, base, run = arm3_usual
    sig = _signals(params, reg, run, 1, stride=8)
    held = _signals(params, reg, run, 7, stride=8)
    full = RobotModel(reg, "paper", "wls", base=base).fit(sig)
    m = RobotModel(reg, "paper", "wls", base=base).fit(sig)
    np.testing.assert_array_equal(m.coef_, full.coef_)
    u = assess(m, sig, n_blocks=10, iv=False)
    names = list(m.names_)
    stribeck = [n for n in names if n.rstrip("0123456789") in ("b_m", "b_g", "d_m", "d_g")]
    assert len(set(u.pruned) & set(stribeck)) >= 0.75 * len(stribeck), u.pruned
    assert all(n.rstrip("0123456789") in PRUNABLE for n in u.pruned), u.pruned
    for n in u.pruned:
        i = names.index(n)
        assert m.coef_[i] == 0.0 and m.std_[i] == 0.0 and u.std[i] == 0.0, n
        assert n not in u.unidentified
    assert u.to_json()["pruned"] == u.pruned and m.pruned_ == u.pruned
    # every prunable parameter left is within the threshold (honest sigma)
    rel = 100 * u.std / np.abs(np.where(m.coef_ != 0, m.coef_, np.nan))
    for i, n in enumerate(names):
        if n.rstrip("0123456789") in PRUNABLE and n not in u.pruned:
            assert rel[i] <= u.threshold_pct, (n, rel[i])
    # joints with every b, d pruned: E = exp(-|dq|/q_s) no longer acts
    gone = [j for j, num in zip(range(len(reg.joints)), m.numbers_, strict=True)
            if all(f"{p}{num}" in u.pruned for p in ("b_m", "b_g", "d_m", "d_g"))]
    assert gone
    before = m.predict(held)
    m.q_s_ = m.q_s_ * 3.0
    after = m.predict(held)
    m.q_s_ = m.q_s_ / 3.0
    np.testing.assert_allclose(after[:, gone], before[:, gone], rtol=1e-12, atol=1e-12)
    e_full, e_pruned = full.rel_error(held), m.rel_error(held)
    # a fit whose quadrant passes do not settle (converged_ False: at max_passes with rows
    # still moving; rows at the band's edge cycled so before the band's hysteresis,
    # 2026-11-29) has a held-out error that moves from one capped pass to the next (j2:
    # 0.4 % then): the pruning may not add more than that jitter, measured over the caps 5
    # to 10; a settled fit gets none
    jitter = dict.fromkeys(reg.joints, 0.0)
    if not full.converged_:
        errs = [RobotModel(reg, "paper", "wls", base=base, max_passes=k).fit(sig).rel_error(held)
                for k in range(5, 11)]
        jitter = {j: max(e[j] for e in errs) - min(e[j] for e in errs) for j in reg.joints}
    for j in reg.joints:
        assert e_pruned[j] <= e_full[j] * 1.002 + jitter[j], (j, e_pruned[j], e_full[j], jitter)


def test_cli_sigma_options(arm3_usual, tmp_path, capfd):
    """``jointid fit --robot``: the honest sigma with its block in the JSON and the table;
    ``--sigma-blocks 0`` is eq. 15 alone; a bad count or the options without --robot: one
    line, non-zero exit, nothing written."""
    params, reg, base, run = arm3_usual
    f = tmp_path / "run.csv"
    run.to_csv(f)
    robot = ROOT / "examples" / "robots" / "arm3.toml"

    def cli(*argv):
        code = main(["fit", *map(str, argv)])
        out, err = capfd.readouterr()
        return code, out, err

    js = tmp_path / "fit.json"
    code, out, err = cli("--robot", robot, f, "--model", "usual", "--no-consistency",
                         "--json", js)
    assert code == 0, err
    rec = json.loads(js.read_text())["models"]["usual"]
    block = rec["uncertainty"]
    assert block["n_replicates"] == 10 and block["iv"] is not None  # the CSV has q_ref
    assert set(block["joints"]) == set(reg.joints)
    for v in rec["parameters"].values():
        # the honest sigma: max(robust eq. 15, jackknife) (the robust one may be below eq. 15
        # on the joints quieter than the pooled residual variance says)
        assert v["std"] >= max(v["std_robust"], v["std_jackknife"]) and v["pruned"] is False
    assert set(block["long_run_factor"]) == set(reg.joints)
    assert "std eq15" in out and "jackknife replicates" in out and "robust eq. 15" in out
    code, out, err = cli("--robot", robot, f, "--model", "usual", "--no-consistency",
                         "--sigma-blocks", "0", "--json", js)
    assert code == 0, err
    rec = json.loads(js.read_text())["models"]["usual"]
    assert rec["uncertainty"]["n_replicates"] == 0 and rec["uncertainty"]["iv"] is None
    assert all(v["std"] == v["std_robust"] for v in rec["parameters"].values())
    for bad, what in ((["--sigma-blocks", "-1"], "--sigma-blocks"),
                      (["--sigma-blocks", "1"], "--sigma-blocks")):
        js2 = tmp_path / "bad.json"
        code, out, err = cli("--robot", robot, f, "--model", "usual", *bad, "--json", js2)
        assert code != 0 and what in err and len(err.strip().splitlines()) == 1, err
        assert not js2.exists()
    code, out, err = cli(f, "--no-prune")
    assert code != 0 and "--no-prune" in err and len(err.strip().splitlines()) == 1, err


def test_progress_lines_once_slow(arm3_usual, monkeypatch):
    """Progress lines go to the callback only once the assessment has run for
    PROGRESS_AFTER_S (here 0: every step); none when it is fast."""
    params, reg, base, run = arm3_usual
    sig = _signals(params, reg, run, 1, stride=8)
    m = RobotModel(reg, "usual", "ls", base=base).fit(sig)
    lines: list[str] = []
    assess(m, sig, n_blocks=4, progress=lines.append)
    assert lines == []
    monkeypatch.setattr(unc, "PROGRESS_AFTER_S", 0.0)
    assess(m, sig, n_blocks=4, progress=lines.append)
    assert any(ln.startswith("sigma: jackknife replicate") and ln.endswith(" s)")
               for ln in lines), lines
