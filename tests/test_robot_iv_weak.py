"""A weak instrument through ``RobotModel.fit`` itself: IDIM-IV leaves out the column its
instruments do not determine, in the usual model and in the paper model's products form
(issue 24, "one rank rule"; the rule on matrices: tests/test_rank_iv.py).

Data: the RX130L's joint 3 alone (examples/robots/rx130l.toml, a 1-dof robot: base columns
ZZ3R = ddq, MX3, MY3 the gravity columns) following a reference whose acceleration is, on
every sample, C times the MY3 column plus a wiggle of relative size DELTA (below RCOND =
1e-6): a swing about the hanging position, but not the arm's own free swing (its load
changes sign with q). The reference is built so that IDIM-IV's instrument acceleration
(``q_ref`` differentiated twice, as the fit does) is exactly that: the discrete recurrence of
np.gradient twice, the first and last two samples left out (NaN torque). The robot follows
the reference exactly; q and dq are read exactly, the acceleration with a white noise of
ACC_NOISE of its spread (the errors in variables IDIM-IV is for). The torque: the rigid body
at the reference's acceleration, the usual friction (FC, FV, OFF; in the paper's form a_m =
a_g = 1, b = d = 0, c_m = c_g = FC, so that any quadrant decision is the truth's) and a
white noise of 1 N m.

So on the instruments ZZ3R's column is C times MY3's to DELTA: IDIM-IV cannot separate them
(its estimate solves least squares on the regressor projected on the instruments), while
the measured columns are separable (the acceleration's noise): the rows' rule keeps ZZ3R
(the LS fit keeps it). The fit leaves ZZ3R out with the IV reason naming MY3, in the usual
model (``eliminate``: the rank rule before the first solve) and in the products form
(its load columns' rule, always: every product of ZZ3R, each naming the same product of
MY3), and the other parameters come out within their stated sigma of the truth their
columns carry, MY3's being MY3 + C ZZ3R (the share of the column left out), over 3 seeds
(the family-wise bound of tests/test_robot_fit.py). Before the load columns' rule took the
instruments (``RobotModel._fit_products`` judged them on W^T W only) the products form kept
ZZ3R's products, and before the IV step pivoted by the instrumented length alone the usual
model kept ZZ3R (sigma 359 against 0.005 for MX3, seed 0): the base parameters pivoted first
left the dependence to a friction column's rounding.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
import scipy.stats

from ident.estimators import WEAK_PREFIX, ZERO_COLUMN
from ident.robot.base import base_parameters
from ident.robot.estimate import RobotModel
from ident.robot.regressor import RobotRegressor
from ident.robot.signals import RobotSignals
from trajectories.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
SEEDS = (0, 1, 2)
DT = 0.005  # sample time [s]
M = 12000  # samples (60 s)
C = 0.5  # reference acceleration = C x the MY3 column (+ the wiggle) [1/kg m]
DELTA = 3e-7  # the wiggle's size, relative to the acceleration's
ACC_NOISE = 0.05  # measured acceleration's noise, fraction of its standard deviation
FRICTION = {"FC3": 20.0, "FV3": 40.0, "OFF3": 10.0}  # [N m], [N m s/rad], [N m]
Q_S = 0.3  # Stribeck velocity of the paper model [rad/s] (its E columns excited)


@functools.cache
def _robot():
    reg = RobotRegressor(load_robot(ROOT / "examples" / "robots" / "rx130l.toml"))
    base = base_parameters(reg)
    assert base.names == ("ZZ3R", "MX3", "MY3")
    return reg, base, dict(zip(base.names, base.values(reg.standard_values()), strict=True))


def _columns(q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
    """The base columns (m, 3) of joint 3 at these states."""
    reg, base, _ = _robot()
    return base.reduce(reg.rigid(q[:, None], dq[:, None], ddq[:, None]))[:, 0, :]


@functools.cache
def _signals(seed: int) -> tuple[RobotSignals, np.ndarray]:
    """The run (module doc) and the instruments' acceleration (the fit's own)."""
    t = np.arange(M) * DT
    wiggle = np.sin(2.9 * t + seed)
    zero = np.zeros(1)
    q = np.empty(M)
    q[:4] = -np.pi / 2 + 1.1 * np.cos(np.sqrt(9.81 * C) * t[:4])
    amp = DELTA * 9.81 * C * 0.7  # the wiggle against the acceleration's scale
    for i in range(2, M - 2):  # (q[i+2] - 2 q[i] + q[i-2]) / (2 DT)^2 = ddq_ref[i]
        my = _columns(q[i:i + 1], zero, zero)[0, 2]
        q[i + 2] = 2 * q[i] - q[i - 2] + 4 * DT**2 * (C * my + amp * wiggle[i])
    ddq_ref = np.gradient(np.gradient(q, t), t)  # RobotModel's _ref_acceleration
    dq = np.gradient(q, t)
    _, _, chi = _robot()
    rng = np.random.default_rng(seed)
    tau = (_columns(q, dq, ddq_ref) @ np.array(list(chi.values())) + FRICTION["FC3"] * np.sign(dq)
           + FRICTION["FV3"] * dq + FRICTION["OFF3"] + rng.standard_normal(M))
    tau[[0, 1, M - 2, M - 1]] = np.nan  # np.gradient's one-sided ends
    ddq = ddq_ref + ACC_NOISE * np.std(ddq_ref) * rng.standard_normal(M)
    reg, _, _ = _robot()
    sig = RobotSignals(t=t, q=q[:, None], dq=dq[:, None], ddq=ddq[:, None], tau=tau[:, None],
                       joints=reg.joints, q_ref=q[:, None], source=f"weak reference {seed}")
    return sig, ddq_ref


def _truth_usual() -> dict[str, float]:
    """The truth the kept columns carry once ZZ3R is left out: MY3 takes C ZZ3R."""
    _, _, chi = _robot()
    return {"MX3": chi["MX3"], "MY3": chi["MY3"] + C * chi["ZZ3R"], **FRICTION}


def _truth_products(names: tuple[str, ...]) -> dict[str, float]:
    """The products form's truth (a = 1, b = d = 0, c_m = c_g = FC) by name."""
    tu = _truth_usual()
    out = {}
    for n in names:
        if n in ("FV3", "OFF3"):
            out[n] = tu[n]
        elif n in ("c_m3", "c_g3"):
            out[n] = tu["FC3"]
        elif n in ("d_m3", "d_g3") or n.startswith(("b_m_", "b_g_")):
            out[n] = 0.0
        elif n.startswith(("a_m_", "a_g_")):
            out[n] = tu.get(n[4:-2], np.nan)  # a_m_MY3_3 -> MY3 (ZZ3R's: left out)
    return out


def _fit(seed: int, kind: str, method: str = "iv") -> RobotModel:
    reg, base, _ = _robot()
    sig, _ = _signals(seed)
    if kind == "usual":
        m = RobotModel(reg, "usual", method, base=base, eliminate=True, threshold_pct=np.inf)
    else:  # the load columns' rule acts without eliminate
        m = RobotModel(reg, "paper", method, base=base, form="products", q_s=Q_S)
    return m.fit(sig)


def test_the_reference_makes_zz3r_a_duplicate_on_the_instruments():
    """The construction: on the instruments' acceleration ZZ3R's column is C x MY3's to
    about DELTA (below RCOND); on the measured one it is not (the noise)."""
    for seed in SEEDS:
        sig, ddq_ref = _signals(seed)
        ok = np.isfinite(sig.tau[:, 0])
        q, dq = sig.q[ok, 0], sig.dq[ok, 0]
        for acc, lo, hi in ((ddq_ref[ok], 0.1 * DELTA, 1e-6), (sig.ddq[ok, 0], 1e-3, 1.0)):
            W = _columns(q, dq, acc)
            rest = W[:, 1:]
            r = W[:, 0] - rest @ np.linalg.lstsq(rest, W[:, 0], rcond=None)[0]
            assert lo < np.linalg.norm(r) / np.linalg.norm(W[:, 0]) < hi


@pytest.mark.parametrize("kind", ["usual", "products"])
def test_iv_leaves_out_the_column_its_instruments_do_not_determine(kind):
    fits = [_fit(s, kind) for s in SEEDS]
    n_free = sum(v not in m.fixed_ for m in fits for v in m.names_)
    z_fw = max(3.0, float(scipy.stats.norm.ppf(1 - 0.01 / (2 * n_free))))
    zs = []
    for m in fits:
        why = dict(m.removed_)
        if kind == "usual":
            assert list(why) == ["ZZ3R"], m.removed_
            assert why["ZZ3R"].startswith(WEAK_PREFIX) and "MY3" in why["ZZ3R"], why
            truth = _truth_usual()
        else:
            zz = [f"{p}_ZZ3R_3" for p in ("a_m", "b_m", "a_g", "b_g")]
            pay = [f"{p}3" for p in ("a_m", "b_m", "a_g", "b_g")]  # no payload: zero
            assert set(why) == {*zz, *pay}, m.removed_
            for n in zz:  # each product names the same product of MY3
                assert why[n] == (f"{WEAK_PREFIX}its instrumented column is a linear "
                                  f"combination of those of {n.replace('ZZ3R', 'MY3')}"), why
            assert all(why[n] == ZERO_COLUMN for n in pay)
            truth = _truth_products(m.names_)
        assert all(m.params_[n] == 0.0 for n in why)
        for n, v, sd in zip(m.names_, m.coef_, m.std_, strict=True):
            if n in why:
                continue
            assert sd > 0 and np.isfinite(truth[n]), (n, sd)
            zs.append((n, (v - truth[n]) / sd))
    bad = [(n, round(float(z), 2)) for n, z in zs if abs(z) > z_fw]
    assert not bad, f"outside {z_fw:.2f} sigma: {bad}"
    within = np.mean([abs(z) <= 3 for _, z in zs])
    assert within >= 0.95, f"only {within:.0%} within 3 sigma"


def test_least_squares_keeps_the_column():
    """The rows' rule alone (LS: no instruments) keeps ZZ3R: the drop is IV's."""
    for kind in ("usual", "products"):
        m = _fit(SEEDS[0], kind, "ls")
        assert not any("ZZ3R" in n for n, _ in m.removed_), m.removed_
