"""Robot files (ROBOT_FORMAT, docs/robot-format.md): MDH TOML and URDF -> trajectories.robot.Robot,
the MDH frame convention, merged inertias of locked links, drive data, and one-line errors."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from ident.robot.regressor import RobotRegressor
from ident.robot.signals import RobotPayloadData
from sim_drivers.arm_params import ArmParams, Payload
from sim_drivers.arm_plant import output_arm_torque
from trajectories import TrajectoryError
from trajectories.robot import (
    JointDrive,
    Robot,
    RobotError,
    RobotLimits,
    load_robot,
    mdh_placement,
)
from trajectories.robot_campaign import campaign_from_dict

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = ROOT / "examples" / "robots"


def _write(tmp_path: Path, text: str, name: str = "robot.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


# --------------------------------------------------------------------------- MDH files
def test_arm3_file_reads_with_drives_limits_and_inertias():
    r = load_robot(ROBOTS / "arm3.toml")
    assert r.name == "arm3" and r.joint_names == ("j1", "j2", "j3")
    assert r.moving == ("j1", "j2", "j3") and dict(r.locked) == {}
    assert r.types == ("revolute",) * 3 and r.inertial
    assert r.drives["j3"] == JointDrive(gear_ratio=80.0, rotor_inertia=0.9e-4)
    assert r.drives["j3"].Ia == pytest.approx(80.0**2 * 0.9e-4)
    assert r.limits["j2"] == RobotLimits(-2.4, -0.3, 1.2, 4.0, 40.0, 400.0)
    np.testing.assert_array_equal(r.gravity, [0.0, 0.0, -9.81])
    assert r.numbers == (1, 2, 3)
    # the file's standard parameters are pinocchio's inertia about the joint-frame origin
    phi = r.model.inertias[2].toDynamicParameters()  # m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, ...
    np.testing.assert_allclose(phi, [10.0, 3.0, 0.0, 0.2, 0.03, 0.0, 1.21, -0.06, 0.0, 1.20],
                               atol=1e-12)


def test_the_campaign_robot_file_matches_the_campaign():
    path = ROOT / "examples" / "campaign_robot3.toml"
    camp = campaign_from_dict(tomllib.loads(path.read_text(encoding="utf-8")), str(path))
    robot = load_robot(ROOT / "examples" / camp.robot_file)
    assert camp.moving == robot.moving
    for j in camp.joints:
        lim = robot.limits[j.name]
        assert lim.q_min <= j.limits.position[0] and j.limits.position[1] <= lim.q_max
        assert j.limits.max_velocity <= lim.dq_max and j.limits.max_torque <= lim.tau_max


def test_mdh_joint_frames_are_the_khalil_frames(tmp_path):
    """Frame j-1 -> j = Rot(x, alpha) Trans(x, d) Rot(z, theta + q) Trans(z, r) (revolute) and
    the joint variable adds to r (prismatic), compared with a direct product of 4x4 matrices."""
    text = """
[robot]
name = "chain"
[[joints]]
name = "a"
alpha = 0.3
d = 0.2
theta = 0.4
r = 0.1
[[joints]]
name = "b"
type = "prismatic"
alpha = -1.5707963267948966
d = 0.5
theta = 0.7
r = 0.25
[[joints]]
name = "c"
alpha = 1.1
d = 0.0
theta = -0.2
r = 0.3
"""
    r = load_robot(_write(tmp_path, text))
    assert r.types == ("revolute", "prismatic", "revolute") and not r.inertial

    def h(alpha, d, theta, rr):
        ca, sa, ct, st = math.cos(alpha), math.sin(alpha), math.cos(theta), math.sin(theta)
        rx = np.array([[1, 0, 0, 0], [0, ca, -sa, 0], [0, sa, ca, 0], [0, 0, 0, 1.0]])
        tx = np.eye(4)
        tx[0, 3] = d
        rz = np.array([[ct, -st, 0, 0], [st, ct, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
        tz = np.eye(4)
        tz[2, 3] = rr
        return rx @ tx @ rz @ tz

    q = np.array([0.8, 0.15, -1.3])
    data = r.model.createData()
    pin.forwardKinematics(r.model, data, q)
    t = (h(0.3, 0.2, 0.4 + q[0], 0.1) @ h(-math.pi / 2, 0.5, 0.7, 0.25 + q[1])
         @ h(1.1, 0.0, -0.2 + q[2], 0.3))
    np.testing.assert_allclose(data.oMi[3].homogeneous, t, atol=1e-12)
    np.testing.assert_allclose(mdh_placement(0.3, 0.2, 0.4, 0.1).homogeneous,
                               h(0.3, 0.2, 0.4, 0.1), atol=1e-15)


def test_rx130l_joint3_alone_merges_the_locked_links():
    r = load_robot(ROBOTS / "rx130l.toml")
    assert r.moving == ("j3",) and r.numbers == (3,)
    assert dict(r.locked) == {"j1": 0.0, "j2": -math.pi / 2, "j4": 0.0, "j5": 0.0, "j6": 0.0}
    red = r.reduced()
    assert red.nv == 1 and red.names[1] == "j3"
    # merged mass = links 3..6; the torque of the reduced model = the full chain's joint 3
    assert red.inertias[1].mass == pytest.approx(5.0 + 18.0 + 6.0 + 2.5)
    rng = np.random.default_rng(3)
    full, dfull, dred = r.model, r.model.createData(), red.createData()
    for _ in range(5):
        q3, dq3, ddq3 = rng.uniform(-2, 2, 3)
        qf = r.q_full([q3])
        v = np.zeros(6)
        a = np.zeros(6)
        v[2], a[2] = dq3, ddq3
        tau_full = pin.rnea(full, dfull, qf, v, a)[2]
        tau_red = pin.rnea(red, dred, np.array([q3]), np.array([dq3]), np.array([ddq3]))[0]
        assert tau_red == pytest.approx(tau_full, rel=1e-12, abs=1e-9)


def test_with_motion_and_from_pinocchio():
    r = load_robot(ROBOTS / "arm3.toml").with_motion(moving=["j2", "j3"], locked={"j1": 0.5})
    assert r.moving == ("j2", "j3") and r.numbers == (2, 3) and r.reduced().nv == 2
    np.testing.assert_allclose(r.q_full([1.0, 2.0]), [0.5, 1.0, 2.0])
    m = pin.buildSampleModelManipulator()
    rb = Robot.from_pinocchio(m, name="sample", locked={m.names[1]: 0.1},
                              drives={m.names[2]: JointDrive(gear_ratio=50.0)},
                              gravity=[0.0, 0.0, -9.81])
    assert rb.moving == tuple(m.names[2:]) and rb.drives[m.names[2]].gear_ratio == 50.0
    assert rb.reduced().nv == m.nv - 1
    with pytest.raises(RobotError, match="unknown joint"):
        Robot.from_pinocchio(m, drives={"nope": JointDrive()})


# --------------------------------------------------------------------------- URDF
def test_ur10_from_example_robot_data_with_drive_data():
    r = load_robot(ROBOTS / "ur10.toml")
    assert r.joint_names[0] == "shoulder_pan_joint" and len(r.moving) == 6
    assert r.drives["elbow_joint"].gear_ratio == 101.0
    assert r.drives["elbow_joint"].drive_gain == 1.0
    lim = r.limits["shoulder_lift_joint"]  # the file's limits over the URDF's
    assert (lim.q_min, lim.q_max, lim.dq_max, lim.tau_max) == (-2.6, -0.5, 2.16, 330.0)
    direct = load_robot("example-robot-data:ur10")
    assert direct.joint_names == r.joint_names and direct.drives["elbow_joint"] == JointDrive()
    assert direct.name == "ur10" and direct.source == "example-robot-data:ur10"
    assert direct.model.inertias[3].mass == pytest.approx(r.model.inertias[3].mass)


def test_a_plain_urdf_moves_every_joint(tmp_path):
    urdf = """<?xml version="1.0"?>
<robot name="two">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.1 0 0"/><mass value="2.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0 0 0.2"/><mass value="1.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.005"/></inertial></link>
  <joint name="q1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="50" velocity="3"/></joint>
  <joint name="q2" type="prismatic"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.3 0 0"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.5" effort="100" velocity="1"/></joint>
</robot>
"""
    r = load_robot(_write(tmp_path, urdf, "two.urdf"))
    assert r.joint_names == ("q1", "q2") and r.moving == ("q1", "q2")
    assert r.types == ("revolute", "prismatic")
    assert r.limits["q2"].q_max == 0.5 and r.limits["q1"].tau_max == 50.0
    assert r.source.endswith("two.urdf")


# --------------------------------------------------------------------------- errors
_MDH = """
[robot]
name = "x"
[[joints]]
name = "j1"
alpha = 0.0
d = 0.0
theta = 0.0
r = 0.0
[[joints]]
name = "j2"
alpha = 1.5707963267948966
d = 0.0
theta = 0.0
r = 0.0
"""


@pytest.mark.parametrize("text, match", [
    (_MDH + "[joints.drive]\ngear_ratio = -3.0\n", r"joints\[j2\]\.drive\.gear_ratio: expected "
                                                   r"a number > 0"),
    (_MDH + "[joints.drive]\nrotor_inertia = \"big\"\n", r"joints\[j2\]\.drive\.rotor_inertia"),
    (_MDH + "[joints.drive]\nspeed = 3\n", r"joints\[j2\]\.drive\.speed: expected one of"),
    (_MDH + "[motion]\nmoving = [\"j2\"]\n", r"motion\.locked\.j1: expected a locked value"),
    (_MDH + "[motion]\nlocked = { j9 = 0.0 }\n", r"motion\.locked\.j9: expected a joint"),
    (_MDH + "[motion]\nmoving = [\"j1\", \"j7\"]\nlocked = { j2 = 0.0 }\n",
     r"motion\.moving: expected joints of the robot"),
    (_MDH.replace('r = 0.0\n[[joints]]', 'r = 0.0\ntype = "helical"\n[[joints]]'),
     r"joints\[j1\]\.type: expected 'revolute' or 'prismatic'"),
    (_MDH.replace("d = 0.0\ntheta = 0.0\nr = 0.0\n[[joints]]",
                  "d = \"far\"\ntheta = 0.0\nr = 0.0\n[[joints]]"),
     r"joints\[j1\]\.d: expected a finite number"),
    (_MDH + "limits = { q_min = 1.0, q_max = -1.0 }\n", r"joints\[j2\]\.limits\.q_max"),
    (_MDH.replace('name = "x"', 'name = "x"\nurdf = "example-robot-data:ur10"'),
     r"robot\.urdf: expected either a URDF or an MDH table"),
    ("[robot]\nname = \"x\"\n", r"robot: expected either robot\.urdf or an MDH table"),
    ("[robot]\nurdf = \"example-robot-data:ur10\"\n[[joints]]\nname = \"elbow\"\n",
     r"joints\[elbow\]\.name: expected a joint of the URDF"),
    ("[robot]\nurdf = \"example-robot-data:ur10\"\n[[joints]]\nname = \"elbow_joint\"\n"
     "drive = { gear_ratio = 0 }\n", r"joints\[elbow_joint\]\.drive\.gear_ratio"),
    ("[robot]\nurdf = \"example-robot-data:nao9\"\n", r"robot\.urdf: example robot 'nao9'"),
    ("[robot]\nurdf = \"missing.urdf\"\n", r"URDF .*missing\.urdf.* does not parse"),
    ("[robot]\nurdf = \"garbage.urdf\"\n", r"URDF .*garbage\.urdf.* does not parse"),
    ("[robot\nname=", r"not valid TOML"),
    ("[robot]\nname = \"x\"\ncolour = 3\n", r"robot\.colour: expected one of the known keys"),
])
def test_bad_robot_files_fail_in_one_line_naming_file_and_element(tmp_path, text, match):
    (tmp_path / "garbage.urdf").write_text("<robot name='g'><link", encoding="utf-8")
    path = _write(tmp_path, text, "bad.toml")
    with pytest.raises(RobotError, match=match) as e:
        load_robot(path)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(str(path))
    assert isinstance(e.value, TrajectoryError) and isinstance(e.value, ValueError)


def test_a_missing_robot_file_is_a_robot_error(tmp_path):
    with pytest.raises(RobotError, match="cannot read the robot file"):
        load_robot(tmp_path / "nope.toml")


# --------------------------------------------------------------------------- simulator
def test_arm_params_from_a_loaded_robot():
    """sim_drivers' ArmParams.from_robot consumes reduced(), joint_names, moving and drives."""
    r = load_robot(ROBOTS / "rx130l.toml")
    p = ArmParams.from_robot(r)
    assert p.joint_numbers == (3,) and p.name == "rx130l"
    tr = p.truth()
    assert tr["Ia3"] == pytest.approx(100.0**2 * 1.15e-3)
    assert tr["M3"] == pytest.approx(31.5) and "ZZ1" not in tr
    p3 = ArmParams.from_robot(load_robot(ROBOTS / "arm3.toml"))
    assert p3.joint_numbers == (1, 2, 3)
    assert p3.drive.gear_ratio.tolist() == [100.0, 100.0, 80.0]


def test_the_simulator_truth_is_the_regressors_standard_parameters():
    """What ident.robot recovers is what sim_drivers simulates: ArmParams.truth() names and
    values are the regressor's standard parameters, and the simulator's output torque with a
    payload on the flange (frame of the last moving joint) is W chi + the payload torque."""
    robot = load_robot(ROBOTS / "arm3.toml")
    params = ArmParams.from_robot(robot)
    reg = RobotRegressor(robot)
    truth = params.truth()
    np.testing.assert_allclose([truth[n] for n in reg.standard_names], reg.standard_values(),
                               rtol=1e-12, atol=1e-12)
    rng = np.random.default_rng(0)
    q = rng.uniform(-2, 2, (20, 3))
    dq, ddq = rng.normal(size=(20, 3)), rng.normal(size=(20, 3))
    pay = RobotPayloadData(5.0, [0.01, 0.02, 0.08], [0.015, 0.0, 0.001, 0.015, 0.0, 0.01])
    sim = np.array([output_arm_torque(params, q[t], dq[t], ddq[t],
                                      Payload(pay.mass, pay.com, pay.inertia))
                    for t in range(20)])
    ours = reg.rigid(q, dq, ddq) @ reg.standard_values() + reg.payload_torque(q, dq, ddq, pay)
    np.testing.assert_allclose(ours, sim, rtol=1e-10, atol=1e-8)


def test_urdf_inertia_that_is_not_a_number_is_one_line(tmp_path):
    """An inertia entry that is not a number (here in any of the six places) is refused in
    one line naming the link; a non-number off the diagonal ended in an UnboundLocalError."""
    from trajectories import RobotError

    for key in ("ixx", "ixy", "izz"):
        bad = {"ixx": "0.01", "ixy": "0", "izz": "0.02", key: "np.float64(0.23)"}
        urdf = f"""<?xml version="1.0"?>
<robot name="one">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.1 0 0"/><mass value="2.0"/>
    <inertia ixx="{bad['ixx']}" ixy="{bad['ixy']}" ixz="0" iyy="0.02" iyz="0"
             izz="{bad['izz']}"/></inertial></link>
  <joint name="q1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="50" velocity="3"/></joint>
</robot>
"""
        with pytest.raises(RobotError, match=r"link 'l1': inertia: expected finite numbers") as e:
            load_robot(_write(tmp_path, urdf, f"bad_{key}.urdf"))
        assert "\n" not in str(e.value)
