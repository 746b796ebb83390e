"""The single-joint rigid-body and payload columns (:class:`ident.models.RigidBody`,
:class:`ident.models.Payload`) come from the robot model's one regressor on the joint as a
1-dof robot; they must equal the paper's eq. 31 and 34-35 written out by hand, on random
states, revolute and prismatic, with and without payload (issue 24)."""

from __future__ import annotations

import numpy as np
import pytest

from ident import DataError
from ident.models import Payload, RigidBody
from ident.signals import G, Signals
from trajectories import RobotError
from trajectories.robot import RobotRegressor, one_joint_robot


def _signals(rng: np.random.Generator, n: int, revolute: bool, payload: bool) -> Signals:
    """Random states over several runs of different payloads (runs concatenated)."""
    q = rng.uniform(-4.0, 4.0, n) if revolute else rng.uniform(-0.5, 0.5, n)
    dq = rng.normal(0.0, 1.0, n)
    ddq = rng.normal(0.0, 5.0, n)
    run = np.sort(rng.integers(0, 4, n))
    masses = np.array([0.0, 3.4584, 6.97, 1.5]) if payload else np.zeros(4)
    arms = np.array([1.277, 1.277, 0.8, -0.35])
    return Signals(t=np.arange(n) * 1e-3, q=q, dq=dq, ddq=ddq, tau=np.zeros(n),
                   payload_mass=masses[run], payload_arm=arms[run], experiment=run,
                   revolute=revolute)


def _eq31(s: Signals, revolute: bool | None) -> np.ndarray:
    """Eq. 31 by hand: [ddq, g cos q, g sin q] (J only when ``revolute`` is False; zero
    gravity columns on prismatic data)."""
    if revolute is False:
        return s.ddq[:, None].copy()
    g = 1.0 if s.revolute else 0.0
    return np.column_stack([s.ddq, g * G * np.cos(s.q), g * G * np.sin(s.q)])


def _eq35(s: Signals) -> np.ndarray:
    """Eq. 34-35 by hand: M_aw L_a (L_a ddq + g cos q); prismatic M_aw ddq."""
    if s.revolute:
        m, la = s.payload_mass, s.payload_arm
        return (m * la * (la * s.ddq + G * np.cos(s.q)))[:, None]
    return (s.payload_mass * s.ddq)[:, None]


def _rel(new: np.ndarray, ref: np.ndarray) -> float:
    """Largest difference relative to the largest reference entry, per column."""
    assert new.shape == ref.shape
    scale = np.maximum(np.abs(ref).max(axis=0), 1e-300)
    return float((np.abs(new - ref).max(axis=0) / scale).max())


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("revolute_data", [True, False])
@pytest.mark.parametrize("payload", [True, False])
def test_columns_equal_the_paper_formulas(seed, revolute_data, payload):
    rng = np.random.default_rng(seed)
    s = _signals(rng, 5000, revolute_data, payload)
    for kind in (None, True, False):
        got = RigidBody(kind).columns(s)
        ref = _eq31(s, kind)
        assert got.shape == ref.shape
        assert _rel(got, ref) < 1e-12, (kind, _rel(got, ref))
    got = Payload().columns(s)
    ref = _eq35(s)
    if payload:
        assert _rel(got, ref) < 1e-12, _rel(got, ref)
    else:
        assert not np.any(got)


def test_columns_on_a_selection_and_no_samples():
    """Rows picked out of order (a selection) and an empty selection keep their shape."""
    rng = np.random.default_rng(5)
    s = _signals(rng, 800, True, True)
    sel = s.take(rng.permutation(800)[:300])
    np.testing.assert_allclose(Payload().columns(sel), _eq35(sel), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(RigidBody().columns(sel), _eq31(sel, None), rtol=1e-12,
                               atol=1e-12)
    empty = s.take(np.zeros(800, bool))
    assert RigidBody().columns(empty).shape == (0, 3)
    assert Payload().columns(empty).shape == (0, 1)


def test_one_joint_robot_is_the_single_joint_model():
    """The 1-dof robot's regressor: J = ZZ1 + Ia1, gravity g (MX1 cos q - MY1 sin q);
    prismatic: M1 + Ia1 on ddq, no gravity."""
    q, dq, ddq = np.array([[0.3]]), np.array([[0.2]]), np.array([[1.5]])
    reg = RobotRegressor(one_joint_robot("revolute"))
    assert reg.joints == ("joint",) and reg.revolute == (True,)
    w = dict(zip(reg.standard_names, reg.rigid(q, dq, ddq)[0, 0], strict=True))
    assert w["ZZ1"] == pytest.approx(1.5) and w["Ia1"] == pytest.approx(1.5)
    assert w["MX1"] == pytest.approx(G * np.cos(0.3))
    assert w["MY1"] == pytest.approx(-G * np.sin(0.3))
    reg = RobotRegressor(one_joint_robot("prismatic", name="slide"))
    assert reg.joints == ("slide",) and reg.revolute == (False,)
    w = dict(zip(reg.standard_names, reg.rigid(q, dq, ddq)[0, 0], strict=True))
    assert w["M1"] == pytest.approx(1.5) and w["Ia1"] == pytest.approx(1.5)
    assert w["MX1"] == 0.0 and w["MY1"] == 0.0


def test_one_joint_robot_bad_kind_is_one_line():
    with pytest.raises(RobotError, match="kind: expected 'revolute' or 'prismatic', got 'hinge'"):
        one_joint_robot("hinge")


def test_payload_without_a_finite_arm_is_one_line():
    rng = np.random.default_rng(3)
    s = _signals(rng, 50, True, True)
    bad = Signals(**{**s.__dict__, "payload_arm": np.full(50, np.nan)})
    with pytest.raises(DataError, match=r"payload_arm: expected a finite lever arm \[m\]"):
        Payload().columns(bad)


@pytest.mark.parametrize("revolute", [True, False])
def test_negative_payload_mass_is_one_line(revolute):
    rng = np.random.default_rng(4)
    s = _signals(rng, 50, revolute, True)
    bad = Signals(**{**s.__dict__, "payload_mass": np.full(50, -2.0)})
    with pytest.raises(DataError, match=r"payload_mass: payload.mass: expected >= 0 \[kg\], "
                                        r"got -2.0"):
        Payload().columns(bad)
