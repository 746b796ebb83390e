"""Small robot campaigns (examples/robots/arm3.toml) for the robot run, plan and demo tests."""

from __future__ import annotations

import copy
import dataclasses
import json
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from ident.robot.regressor import RobotRegressor
from ident.robot.signals import RobotPayloadData, RobotSignals
from sim_drivers.arm import ArmGains, ArmParams, Payload, model_reference, simulate_arm
from sim_drivers.testing import unique_channel
from trajectories.robot import load_robot
from trajectories.robot_campaign import RobotCampaign

ROOT = Path(__file__).resolve().parents[1]
ARM3 = ROOT / "examples" / "robots" / "arm3.toml"

_LIMITS = {
    "j1": {"position": [-2.8, 2.8], "max_velocity": 1.5, "max_acceleration": 5.0,
           "max_jerk": 50.0, "max_torque": 250.0},
    "j2": {"position": [-2.4, -0.3], "max_velocity": 1.2, "max_acceleration": 4.0,
           "max_jerk": 40.0, "max_torque": 400.0},
    "j3": {"position": [0.2, 2.6], "max_velocity": 1.5, "max_acceleration": 5.0,
           "max_jerk": 50.0, "max_torque": 200.0},
}


def arm3_raw(*, buses: tuple[str, str, str] | None = None, cycle_s: float = 0.002,
             segments: list[dict[str, Any]] | None = None,
             payloads: list[dict[str, Any]] | None = None, name: str = "arm3-test",
             daq: dict[str, Any] | None = None) -> dict[str, Any]:
    """A 3-dof arm campaign as a TOML mapping: j1 and j2 on one bus, j3 on another (unique
    virtual channels) at 2 ms, a short multi-sine and a trapezoid of j2 under an elbow sweep,
    payloads 0 kg and 5 kg."""
    if buses is None:
        a, b = unique_channel("robot_a"), unique_channel("robot_b")
        buses = (a, a, b)
    segments = segments if segments is not None else [
        {"kind": "multisine", "period_s": 3.0, "periods": 1, "harmonics": 4, "fill": 0.6,
         "seed": 1},
        {"kind": "trapezoid", "joint": "j2", "speeds": [0.5], "range": [-1.6, -0.8],
         "sweep": {"j3": [0.8, 1.6]}, "dwell_s": 0.1},
    ]
    return {
        "name": name,
        "robot": {
            "file": str(ARM3), "moving": ["j1", "j2", "j3"], "start": [0.0, -1.2, 1.2],
            "joints": {n: {"drive": {"node_id": i + 1, "bus": buses[i]},
                           "limits": copy.deepcopy(_LIMITS[n])}
                       for i, n in enumerate(("j1", "j2", "j3"))},
        },
        "control": {"cycle_s": cycle_s, "gains": {
            "j1": {"kp": 8000.0, "kd": 300.0}, "j2": {"kp": 15000.0, "kd": 600.0},
            "j3": {"kp": 6000.0, "kd": 200.0}}},
        "payloads": payloads if payloads is not None else [
            {"mass_kg": 0.0},
            {"mass_kg": 5.0, "com": [0.1, 0.0, 0.0],
             "inertia": [0.015, 0.0, 0.0, 0.015, 0.0, 0.01]}],
        "segments": segments,
        "daq": daq or {},
    }


def arm3_campaign(**kw: Any) -> RobotCampaign:
    return RobotCampaign.from_dict(arm3_raw(**kw), "arm3-test.toml")


def arm3_log(out: Path, seed: int) -> Path:
    """A real run log of the simulated 3-dof arm on the bus (one 3 s multi-sine period of
    ``seed``, one payload run without payload), written in ``out``."""
    from daq.runtime.runner import run_campaign

    c = arm3_campaign(segments=[{"kind": "multisine", "period_s": 3.0, "periods": 1,
                                 "harmonics": 4, "fill": 0.6, "seed": seed}],
                      payloads=[{"mass_kg": 0.0}])
    r = run_campaign(c, out_dir=out, simulate=True, yes=True)
    assert r.ok, r.reason
    return r.runs[0].path


def to_toml(raw: dict) -> str:
    """Minimal TOML writer for the campaign mappings above (tables, arrays, numbers)."""
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(val(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + " }"
        return repr(v)

    lines = [f"name = {val(raw['name'])}", "[robot]"]
    r = raw["robot"]
    for k in ("file", "moving", "start"):
        lines.append(f"{k} = {val(r[k])}")
    for n, j in r["joints"].items():
        lines += [f"[robot.joints.{n}]", f"drive = {val(j['drive'])}",
                  f"limits = {val(j['limits'])}"]
    lines += ["[control]", f"cycle_s = {raw['control']['cycle_s']!r}", "[control.gains]"]
    lines += [f"{n} = {val(g)}" for n, g in raw["control"]["gains"].items()]
    for p in raw["payloads"]:
        lines.append("[[payloads]]")
        lines += [f"{k} = {val(v)}" for k, v in p.items()]
    for s in raw["segments"]:
        lines.append("[[segments]]")
        lines += [f"{k} = {val(v)}" for k, v in s.items()]
    text = "\n".join(lines) + "\n"
    assert tomllib.loads(text)["name"] == raw["name"]
    return text


def arm_csvs(d: Path, payloads: tuple[Payload | None, ...]) -> list[Path]:
    """The simulated 3-dof arm's default parameters on one 6 s model multi-sine (seed 1,
    about ``[0, -1.9, 0.6]``), one robot CSV per payload (``p<i>.csv`` in ``d``, noise seed
    10 + i): the quick CLI and API fits' files."""
    params = ArmParams.from_robot(load_robot(ARM3))
    ref = model_reference(params.model, center=[0.0, -1.9, 0.6], fraction=0.9,
                          duration_s=6.0, seed=1)
    return [write_arm_csv(simulate_arm(params, ref, ArmGains.for_params(params, payload=p),
                                       payload=p, seed=10 + i), d / f"p{i}.csv")
            for i, p in enumerate(payloads)]


def write_arm_csv(run: Any, path: Path) -> Path:
    """A simulated arm run (``sim_drivers.arm_offline.ArmRun``) as a robot CSV
    (:meth:`~sim_drivers.arm_offline.ArmRun.to_csv`: its columns and, with a payload, the
    payload columns)."""
    run.to_csv(path)
    return path


#: The simulated-arm cases of the cross-joint refinement tests (test_refine_crossjoint.py,
#: test_robot_refit.py): three payload runs, the arm about a pose where the gravity loads
#: change sign, the usual friction on every joint.
ARM3_PAYLOADS = (None, Payload(5.0, [0.0, 0.0, 0.05]),
                 Payload(10.0, [0.02, 0.0, 0.1], [0.02, 0.0, 0.0, 0.02, 0.0, 0.03]))
ARM3_CENTRE = [0.0, -1.9, 0.6]  # as tests/test_robot_fit.py


def arm3_true_state_signals(effects: Any, seed: int, duration_s: float, *,
                            noise: float = 0.01, stride: int = 5) -> tuple[Any, Any, Any]:
    """The 3-dof arm with the usual friction (and ``effects``: an ``ArmEffects`` or None)
    simulated on a model multi-sine for each of :data:`ARM3_PAYLOADS`; its true states every
    ``stride``-th cycle with the applied torque plus white noise of ``noise`` times each
    joint's load. Returns (regressor, signals, arm parameters)."""
    robot = load_robot(ARM3)
    c = ArmParams.from_robot(robot).friction.c_m
    usual = dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0, d_m=0.0, d_g=0.0, c_g=c)
    params = ArmParams.from_robot(robot, usual)
    if effects is not None:
        params = dataclasses.replace(params, effects=effects)
    pays = ARM3_PAYLOADS
    ref = model_reference(params.model, center=ARM3_CENTRE, fraction=0.9,
                          duration_s=duration_s, seed=seed)
    runs = [simulate_arm(params, ref, ArmGains.for_params(params, payload=p), payload=p,
                         seed=10 * seed + i) for i, p in enumerate(pays)]
    reg = RobotRegressor(robot)
    rng = np.random.default_rng(seed)
    sd = noise * params.drive.torque_noise_std_Nm / 0.01  # noise of `noise` x the load L_j
    parts: dict[str, list] = {k: [] for k in ("t", "q", "dq", "ddq", "tau", "experiment")}
    for i, r in enumerate(runs):
        tau = r.tau_applied + rng.standard_normal(r.tau_applied.shape) * sd
        sl = slice(None, None, stride)
        for k, v in (("t", r.t), ("q", r.q_true), ("dq", r.dq_true), ("ddq", r.ddq_true),
                     ("tau", tau), ("experiment", np.full(r.t.size, i))):
            parts[k].append(v[sl])
    payloads = tuple(RobotPayloadData() if p is None else
                     RobotPayloadData(p.mass, p.com, p.inertia) for p in pays)
    sig = RobotSignals(**{k: np.concatenate(v) for k, v in parts.items()}, joints=reg.joints,
                       payloads=payloads, source=f"arm3 seed {seed}")
    return reg, sig, params
