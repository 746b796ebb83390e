"""The n-dof standard-parameter regressor (trajectories.robot.regressor) against pinocchio, the
known payload torque (eq. 34-35 generalised), and the base parameters (trajectories.robot.base)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from ident.models import RigidBody
from ident.robot import RobotIdentError
from ident.robot.base import single_joint_map
from ident.signals import Signals
from trajectories.robot import (
    LINK_NAMES,
    Robot,
    RobotError,
    RobotPayloadData,
    RobotRegressor,
    base_parameters,
    from_pinocchio_order,
    load_robot,
)

ROBOTS = Path(__file__).resolve().parents[1] / "examples" / "robots"

_PRISMATIC_CHAIN = """
[robot]
name = "prr"
gravity = [0.0, 0.0, -9.81]
[[joints]]                 # vertical slide
name = "lift"
type = "prismatic"
alpha = 0.0
d = 0.0
theta = 0.0
r = 0.4
mass = 8.0
com = [0.05, 0.0, -0.1]
inertia = [0.2, 0.01, 0.0, 0.25, 0.0, 0.1]
[[joints]]                 # horizontal revolute
name = "shoulder"
alpha = 1.5707963267948966
d = 0.2
theta = 0.3
r = 0.1
mass = 5.0
com = [0.25, 0.02, 0.01]
inertia = [0.02, 0.001, -0.01, 0.35, 0.002, 0.34]
[[joints]]                 # telescopic arm along z3
name = "reach"
type = "prismatic"
alpha = -1.5707963267948966
d = 0.5
theta = 0.0
r = 0.0
mass = 3.0
com = [0.0, 0.01, 0.15]
inertia = [0.09, 0.0, 0.0, 0.09, 0.001, 0.01]
[[joints]]                 # wrist
name = "wrist"
alpha = 0.7
d = 0.05
theta = -0.4
r = 0.12
mass = 1.0
com = [0.01, 0.02, 0.05]
inertia = [0.006, 0.0001, 0.0002, 0.005, 0.0003, 0.002]
"""


def _prismatic_chain(tmp_path: Path) -> Robot:
    p = tmp_path / "prr.toml"
    p.write_text(_PRISMATIC_CHAIN, encoding="utf-8")
    return load_robot(p)


def _unaligned_chain() -> Robot:
    """A pinocchio chain with unaligned revolute/prismatic axes and random placements."""
    rng = np.random.default_rng(7)
    m = pin.Model()
    parent = 0
    for i, kind in enumerate(("RZ", "RU", "PU", "RY", "PX")):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        jm = {"RZ": pin.JointModelRZ(), "RY": pin.JointModelRY(), "PX": pin.JointModelPX(),
              "RU": pin.JointModelRevoluteUnaligned(axis),
              "PU": pin.JointModelPrismaticUnaligned(axis)}[kind]
        pl = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(scale=0.3, size=3))
        parent = m.addJoint(parent, jm, pl, f"q{i + 1}")
        m.appendBodyToJoint(parent, pin.Inertia.Random(), pin.SE3.Identity())
    return Robot.from_pinocchio(m, name="unaligned")


def _robots(tmp_path: Path) -> dict[str, Robot]:
    arm3 = load_robot(ROBOTS / "arm3.toml")
    return {
        "ur10": load_robot(ROBOTS / "ur10.toml"),
        "arm3": arm3,
        "arm3-j2j3": arm3.with_motion(["j2", "j3"], {"j1": 0.4}),
        "prr": _prismatic_chain(tmp_path),
        "unaligned": _unaligned_chain(),
        "rx130l": load_robot(ROBOTS / "rx130l.toml"),
        "ur10-wrist-locked": load_robot(ROBOTS / "ur10.toml").with_motion(
            ["shoulder_lift_joint", "elbow_joint", "wrist_2_joint"],
            {"shoulder_pan_joint": 0.3, "wrist_1_joint": -1.2, "wrist_3_joint": 0.5}),
    }


def _states(k: int, n: int, seed: int):
    rng = np.random.default_rng(seed)
    return (rng.uniform(-math.pi, math.pi, (n, k)), rng.normal(scale=1.5, size=(n, k)),
            rng.normal(scale=4.0, size=(n, k)))


# --------------------------------------------------------------------------- vs pinocchio
@pytest.mark.parametrize("name", ["ur10", "arm3", "arm3-j2j3", "prr", "unaligned", "rx130l",
                                  "ur10-wrist-locked"])
def test_regressor_matches_pinocchio_torque_regressor(tmp_path, name):
    robot = _robots(tmp_path)[name]
    reg = RobotRegressor(robot)
    k = reg.k
    assert reg.standard_names[:11] == tuple(f"{p}{reg.numbers[0]}" for p in
                                            (*LINK_NAMES, "Ia"))
    q, dq, ddq = _states(k, 40, seed=len(name))
    W = reg.rigid(q, dq, ddq)
    assert W.shape == (40, k, 11 * k)
    model, data = reg.model, reg.model.createData()
    inertial = [c for c in range(11 * k) if c % 11 != 10]
    worst = 0.0
    for t in range(40):
        Y = from_pinocchio_order(pin.computeJointTorqueRegressor(model, data, q[t], dq[t],
                                                                 ddq[t]))
        worst = max(worst, float(np.abs(W[t][:, inertial] - Y).max()))
        # rotor columns: Ia_j ddq_j on joint j only
        np.testing.assert_array_equal(W[t][:, 10::11], np.diag(ddq[t]))
    assert worst < 1e-9
    # the standard values of the model reproduce its inverse dynamics (plus Ia ddq)
    ia = np.linspace(0.5, 1.5, k)
    chi = reg.standard_values(Ia=ia)
    tau = np.einsum("nkp,p->nk", W, chi)
    rnea = np.array([pin.rnea(model, data, q[t], dq[t], ddq[t]) for t in range(40)])
    np.testing.assert_allclose(tau, rnea + ia * ddq, rtol=1e-10, atol=1e-8)


def test_blocks_and_layout_do_not_change_the_result():
    reg = RobotRegressor(load_robot(ROBOTS / "arm3.toml"))
    q, dq, ddq = _states(3, 9000, seed=1)  # more than one internal block
    W = reg.rigid(q, dq, ddq)
    np.testing.assert_array_equal(W[8000:], reg.rigid(q[8000:], dq[8000:], ddq[8000:]))
    kpn = reg.rigid_kpn(q[:10], dq[:10], ddq[:10])
    assert kpn.flags.c_contiguous and kpn.shape == (3, 33, 10)
    np.testing.assert_array_equal(kpn.transpose(2, 0, 1), W[:10])
    assert [s.stop for s in reg.chunks(9000, 4000)] == [4000, 8000, 9000]
    # a reused output buffer (stale content) and a column subset give the same numbers
    buf = np.full((3, 33, 10), np.nan)
    np.testing.assert_array_equal(reg.rigid_kpn(q[:10], dq[:10], ddq[:10], out=buf), kpn)
    base = base_parameters(reg)
    np.testing.assert_array_equal(reg.rigid(q[:10], dq[:10], ddq[:10], columns=base.columns),
                                  base.reduce(W[:10]))
    with pytest.raises(RobotError, match="out: expected"):
        reg.rigid_kpn(q[:10], dq[:10], ddq[:10], out=np.zeros((3, 33, 11)))


def test_gravity_comes_from_the_robot_file(tmp_path):
    text = (ROBOTS / "arm3.toml").read_text(encoding="utf-8")
    sideways = tmp_path / "arm3x.toml"
    sideways.write_text(text.replace("gravity = [0.0, 0.0, -9.81]", "gravity = [9.81, 0.0, 0.0]"),
                        encoding="utf-8")
    weightless = tmp_path / "arm3g0.toml"
    weightless.write_text(text.replace("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, 0.0]"),
                          encoding="utf-8")
    q = np.array([[0.3, -1.0, 1.2]])
    z = np.zeros_like(q)
    r0 = RobotRegressor(load_robot(weightless))
    np.testing.assert_array_equal(r0.rigid(q, z, z), 0.0)
    rx = RobotRegressor(load_robot(sideways))
    tau_x = rx.rigid(q, z, z)[0] @ rx.standard_values()
    # base yaw now carries gravity (horizontal g): compare with pinocchio's static torque
    m = rx.model
    assert np.allclose(m.gravity.linear, [9.81, 0, 0])
    np.testing.assert_allclose(tau_x, pin.computeGeneralizedGravity(m, m.createData(), q[0]),
                               atol=1e-10)
    assert abs(tau_x[0]) > 1.0


def test_bad_shapes_are_named():
    reg = RobotRegressor(load_robot(ROBOTS / "arm3.toml"))
    with pytest.raises(RobotError, match=r"dq: expected shape \(n, 3\)"):
        reg.rigid(np.zeros((5, 3)), np.zeros((5, 2)), np.zeros((5, 3)))
    with pytest.raises(RobotError, match="flange 'nope'"):
        RobotRegressor(load_robot(ROBOTS / "arm3.toml"), flange="nope")


# --------------------------------------------------------------------------- payload
def _with_payload(model: pin.Model, frame: str | None, payload: RobotPayloadData) -> pin.Model:
    m = pin.Model(model)
    xx, xy, xz, yy, yz, zz = payload.inertia
    inert = pin.Inertia(payload.mass, payload.com,
                        np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]))
    last = m.njoints - 1
    pl = pin.SE3.Identity() if frame is None else m.frames[m.getFrameId(frame)].placement
    m.inertias[last] = m.inertias[last] + pl.act(inert)
    return m


@pytest.mark.parametrize("name, flange", [("ur10", None), ("ur10", "tool0"),
                                          ("rx130l", "j6"), ("arm3-j2j3", None)])
def test_payload_torque_is_the_inverse_dynamics_of_the_payload(tmp_path, name, flange):
    robot = _robots(tmp_path)[name]
    reg = RobotRegressor(robot, flange=flange)
    pay = RobotPayloadData(4.0, [0.02, -0.03, 0.12], [0.02, 0.001, -0.002, 0.03, 0.003, 0.01])
    q, dq, ddq = _states(reg.k, 20, seed=5)
    tau = reg.payload_torque(q, dq, ddq, pay)
    m0, m1 = reg.model, _with_payload(reg.model, flange, pay)
    d0, d1 = m0.createData(), m1.createData()
    ref = np.array([pin.rnea(m1, d1, q[t], dq[t], ddq[t]) - pin.rnea(m0, d0, q[t], dq[t], ddq[t])
                    for t in range(20)])
    np.testing.assert_allclose(tau, ref, rtol=1e-10, atol=1e-9)
    np.testing.assert_array_equal(reg.payload_torque(q, dq, ddq, RobotPayloadData()), 0.0)


def test_payload_torque_is_eq34_for_a_point_mass_along_arm3_of_the_rx130l():
    """Paper eq. 34: a mass M_a at L_a from joint 3, on the arm's axis, adds
    M_a L_a (L_a ddq + g cos q) (the arm points along -y3 in this MDH table)."""
    reg = RobotRegressor(load_robot(ROBOTS / "rx130l.toml"))
    ma, la = 6.970, 1.277
    pay = RobotPayloadData(ma, [0.0, -la, 0.0])
    q, dq, ddq = _states(1, 50, seed=2)
    tau = reg.payload_torque(q, dq, ddq, pay)[:, 0]
    np.testing.assert_allclose(tau, ma * la * (la * ddq[:, 0] + 9.81 * np.cos(q[:, 0])),
                               rtol=1e-12, atol=1e-9)


# --------------------------------------------------------------------------- base parameters
def test_arm3_base_parameters_follow_khalils_regrouping_rules():
    """Vertical j1, horizontal parallel j2 and j3 with d3 = 0.6 m: ZZ1R gathers Ia1, YY2, YY3
    and d3^2 M3; XX3R = XX3 - YY3; MX2R = MX2 + d3 M3; M2, M3, MZ2, MZ3 and every link-1
    parameter but ZZ1 disappear (Khalil & Dombre's rules)."""
    reg = RobotRegressor(load_robot(ROBOTS / "arm3.toml"))
    base = base_parameters(reg)
    ex = dict(e.split(" = ", 1) for e in base.expressions)
    assert ex["ZZ1R"] == "ZZ1 + Ia1 + YY2 + YY3 + 0.36*M3"
    assert ex["XX3R"] == "XX3 - YY3" and ex["MX2R"] == "MX2 + 0.6*M3"
    assert ex["ZZ2R"] == "ZZ2 + Ia2 + 0.36*M3"
    for gone in ("M2", "M3", "MZ2", "MZ3", "XX1", "MX1", "YY2", "YY3", "Ia1", "Ia2"):
        assert not any(n.rstrip("R") == gone for n in base.names)
    assert {"XX1", "XY1", "MX1", "M1"} <= set(base.unidentifiable)


@pytest.mark.parametrize("name", ["arm3", "ur10", "prr", "unaligned", "rx130l",
                                  "ur10-wrist-locked"])
def test_base_regressor_is_full_rank_and_reproduces_every_torque(tmp_path, name):
    reg = RobotRegressor(_robots(tmp_path)[name])
    base = base_parameters(reg, seed=0, friction=True)
    p = len(reg.standard_names) + len(reg.friction_names)
    assert base.beta.shape == (base.p_b, p) and base.p_b == len(set(base.names))
    np.testing.assert_array_equal(base.beta[np.arange(base.p_b), base.columns], 1.0)
    # other states than the QR's (another seed): W chi = W_b (beta chi), W_b of full rank
    q, dq, ddq = _states(reg.k, max(200, base.p_b), seed=99)
    W = np.concatenate([reg.rigid(q, dq, ddq), reg.friction(dq)], axis=-1)
    chi = np.random.default_rng(1).normal(size=p)
    np.testing.assert_allclose(base.reduce(W) @ base.values(chi), W @ chi, rtol=1e-9,
                               atol=1e-9 * np.abs(W @ chi).max())
    wb = base.reduce(W).reshape(-1, base.p_b)
    assert np.linalg.matrix_rank(wb) == base.p_b
    assert np.linalg.matrix_rank(W.reshape(-1, p)) == base.p_b
    # deterministic for a seed, the same parameters for another seed
    again = base_parameters(reg, seed=0, friction=True)
    assert again.expressions == base.expressions
    np.testing.assert_array_equal(again.beta, base.beta)
    assert base_parameters(reg, seed=3, friction=True).names == base.names


def test_values_by_name_and_missing_names():
    reg = RobotRegressor(load_robot(ROBOTS / "arm3.toml"))
    base = base_parameters(reg)
    chi = reg.standard_values()
    by_name = dict(zip(reg.standard_names, chi, strict=True))
    np.testing.assert_allclose(base.values(by_name), base.values(chi))
    del by_name["YY3"]
    with pytest.raises(RobotError, match="missing standard parameters.*YY3"):
        base.values(by_name)
    with pytest.raises(RobotError, match="expected 33 columns"):
        base.reduce(np.zeros((4, 3, 30)))


# --------------------------------------------------------------------------- 1-dof case
def test_rx130l_joint3_alone_is_todays_single_joint_model():
    """RX130L with joints 1, 2, 4, 5, 6 locked (links 1-2 vertical, wrist in line): the base
    parameters are ZZ3R = ZZ3 + Ia3, MX3, MY3 (+ FC3, FV3, OFF3), spanning exactly the
    columns of ident.models.RigidBody (J ddq + MX g cos q + MY g sin q) and the usual
    friction: J = ZZ3R, MX = -MY3, MY = -MX3."""
    robot = load_robot(ROBOTS / "rx130l.toml")
    reg = RobotRegressor(robot)
    base = base_parameters(reg, friction=True)
    assert base.names == ("ZZ3R", "MX3", "MY3", "FC3", "FV3", "OFF3")
    assert base.expressions[0] == "ZZ3R = ZZ3 + Ia3"
    mp = single_joint_map(base, reg)
    assert mp.names == ("J", "MX", "MY", "F_C", "F_V", "tau_off") and mp.residual < 1e-10
    assert mp.expressions[:3] == ("J = ZZ3R", "MX = -MY3", "MY = -MX3")
    # the same numbers through today's RigidBody term
    q, dq, ddq = _states(1, 300, seed=4)
    n = q.shape[0]
    sig = Signals(t=np.arange(n) * 1e-3, q=q[:, 0], dq=dq[:, 0], ddq=ddq[:, 0],
                  tau=np.zeros(n), payload_mass=np.zeros(n), payload_arm=np.zeros(n),
                  experiment=np.zeros(n, dtype=int))
    chi_b = base.values(np.concatenate([reg.standard_values(), [20.0, 40.0, 10.0]]))
    single = mp.values(chi_b)
    tau_single = RigidBody().columns(sig) @ [single["J"], single["MX"], single["MY"]]
    tau_robot = reg.rigid(q, dq, ddq)[:, 0, :] @ reg.standard_values()
    np.testing.assert_allclose(tau_single, tau_robot, rtol=1e-10, atol=1e-8)
    assert single["J"] == pytest.approx(robot.drives["j3"].Ia + reg.standard_values()[5])
    assert (single["F_C"], single["F_V"], single["tau_off"]) == pytest.approx((20, 40, 10))


def test_single_joint_map_needs_one_joint():
    reg = RobotRegressor(load_robot(ROBOTS / "arm3.toml"))
    with pytest.raises(RobotIdentError, match="expected one moving joint"):
        single_joint_map(base_parameters(reg), reg)
