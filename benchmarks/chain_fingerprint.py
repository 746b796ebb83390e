"""Fingerprints of the preprocessing chain's output, to compare two versions bit for bit.

Builds a few designs on simulated data -- single joint (``ident.preprocess.build_design``:
the usual and paper columns, a ``reference`` for the IDIM-IV instruments, ``dq_min_rel``,
``tau_min``, a ``load_model``, ``Design.with_term`` and ``Design.select``), a 3-dof arm
(``ident.robot.design.design_runs`` with instruments, ``sign_checked``; ``products_columns``
with a first usual fit's load, with and without the kept full-rate signals, LS and IDIM-IV,
at two q_s with one cache, and the products form's estimate) and the states chain
(``ident.robot.loaders.preprocess_runs``) -- and prints one SHA-256 per array (the bytes of
the float64 values) and the settings. Run it before and after a refactoring of the chain and
``diff`` the two outputs: any changed float shows as a changed line.

Usage::

    python benchmarks/chain_fingerprint.py > before.txt
"""

from __future__ import annotations

import hashlib
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from example_campaign import simulate_example_campaign  # noqa: E402

from ident.fitting import _library  # noqa: E402
from ident.loaders import concat, make_experiment  # noqa: E402
from ident.preprocess import TORQUE_DELAY, build_design  # noqa: E402
from ident.robot import RobotIdentError  # noqa: E402
from ident.robot.design import (  # noqa: E402
    design_runs,
    products_columns,
    resolve_design,
    sign_checked,
)
from ident.robot.estimate import RobotModel  # noqa: E402
from ident.robot.loaders import RawRobotRun, preprocess_runs  # noqa: E402
from ident.robot.regressor import RobotRegressor  # noqa: E402
from ident.robot.signals import RobotPayloadData  # noqa: E402
from ident.terms import Library  # noqa: E402
from sim_drivers.arm import ArmGains, ArmParams, Payload, model_reference, simulate_arm  # noqa: E402,E501
from trajectories.robot import load_robot  # noqa: E402


def _h(x) -> str:  # noqa: ANN001 - any array or None
    if x is None:
        return "None"
    a = np.ascontiguousarray(np.asarray(x, dtype=float))
    return f"{a.shape} {hashlib.sha256(a.tobytes()).hexdigest()[:16]}"


def _design(tag: str, d) -> None:  # noqa: ANN001 - a Design
    print(f"{tag}: settings {d.settings()}")
    print(f"{tag}: names {d.names}")
    for name in ("Y", "W", "Z"):
        print(f"{tag}: {name} {_h(getattr(d, name))}")
    for name in ("t", "q", "dq", "ddq", "tau"):
        print(f"{tag}: signals.{name} {_h(getattr(d.signals, name))}")


def _robot(tag: str, sig) -> None:  # noqa: ANN001 - RobotSignals
    for name in ("t", "q", "dq", "ddq", "tau", "q_ref", "experiment"):
        print(f"{tag}: {name} {_h(getattr(sig, name))}")
    c = sig.columns
    if c is not None:
        for name in ("W", "p", "sign", "keep", "Wz", "pz"):
            print(f"{tag}: columns.{name} {_h(getattr(c, name))}")


def single_joint() -> None:
    _, plan, sims = simulate_example_campaign(11)
    exps = [make_experiment(f"payload{i}.csv", r.t, r.q, r.tau_ref, payload_mass=p.mass_kg,
                            payload_arm=p.arm_m)
            for i, (p, r) in enumerate(zip(plan.payloads, sims, strict=True))]
    sig = concat(exps)
    ref = np.concatenate([r.q_true for r in sims])  # a smooth stand-in reference
    usual = _library("usual", 0.01, True, True)
    paper = _library("paper", 0.01, True, True)
    terms, seen = [], set()
    for t in [*usual.terms(), *paper.terms()]:
        if not set(t.names()) & seen:
            terms.append(t)
            seen |= set(t.names())
    both = Library(*terms)
    d0 = build_design(usual, sig)
    _design("sj default", d0)
    d1 = build_design(both, sig, dq_min_rel=0.01, torque_delay=TORQUE_DELAY, reference=ref)
    _design("sj iv", d1)
    chi = np.linalg.lstsq(d0.W, d0.Y, rcond=None)[0]
    d2 = build_design(usual, sig, cutoff_hz=40.0, decimation=7, trim=100, guard=15,
                      dq_min=0.02, tau_min=0.05, load_model=(usual, chi))
    _design("sj load", d2)
    extra = paper.terms()[-1]
    d3 = d1.without(extra.names()).with_term(extra, states_only=True)
    _design("sj with_term", d3)
    _design("sj select", d1.select(dq_min=0.05, tau_min=0.1))


def arm_runs() -> tuple:
    """The 3-dof arm: two simulated runs (no payload, 5 kg); also
    ``benchmarks/full_rate_calls.py``'s."""
    robot = load_robot(ROOT / "examples" / "robots" / "arm3.toml")
    params = ArmParams.from_robot(robot)
    ref = model_reference(params.model, center=[0.0, -1.9, 0.6], fraction=0.9, duration_s=6.0,
                          seed=3)
    runs = []
    for i, mass in enumerate((0.0, 5.0)):
        pay = RobotPayloadData(mass, [0.0, 0.0, 0.05]) if mass else RobotPayloadData()
        p = Payload(mass, [0.0, 0.0, 0.05]) if mass else None
        r = simulate_arm(params, ref, ArmGains.for_params(params, payload=p), payload=p,
                         seed=30 + i)
        runs.append(RawRobotRun(f"run{i}.csv", r.t, r.q_true, r.tau_applied, q_ref=r.q_ref,
                                payload=pay))
    return robot, runs


def robot() -> None:
    robot, runs = arm_runs()
    reg = RobotRegressor(robot)
    for iv in (False, True):
        settings = resolve_design(runs, instruments=iv, torque_delay=TORQUE_DELAY)
        print(f"robot iv={iv}: settings {settings.as_dict()}")
        sig, dq_min = design_runs(runs, reg, settings, instruments=iv)
        print(f"robot iv={iv}: dq_min {dq_min!r}")
        _robot(f"robot iv={iv}", sig)
    settings = resolve_design(runs, dq_min=0.02)
    sig, _ = design_runs(runs, reg, settings)

    def load(s):  # noqa: ANN001, ANN202 - RobotSignals
        return 0.5 * s.q + 0.1 * s.ddq

    checked, kept = sign_checked(sig, runs, settings, load, 0.2)
    print(f"robot checked: kept {_h(kept)}")
    _robot("robot checked", checked)
    _robot("robot states", preprocess_runs(runs, robot.moving))
    robot_products(reg, runs)


def robot_products(reg, runs) -> None:  # noqa: ANN001 - RobotRegressor, runs
    """The full-rate products of the 3-dof arm with a first usual fit's load (its
    ``load_torque`` at full rate: the sign check's and the products' quadrants)."""
    for iv in (False, True):
        method = "iv" if iv else "ls"
        settings = resolve_design(runs, instruments=iv, torque_delay=TORQUE_DELAY)
        for keep in (False, True):
            tag = f"robot products iv={iv} keep_full={keep}"
            sig, dq_min = design_runs(runs, reg, settings, instruments=iv, keep_full=keep)
            st = replace(settings, dq_min=dq_min)
            first = RobotModel(reg, "usual", method).fit(sig)
            print(f"{tag}: first {_h(first.coef_)}")
            checked, kept = sign_checked(sig, runs, st, first.load_torque, 0.7)
            print(f"{tag}: kept {_h(kept)}")
            cache: dict = {}
            for q_s in (0.03, 0.01):
                out = products_columns(checked, runs, reg, st, first.load_torque, q_s,
                                       instruments=iv, cache=cache)
                pr = out.columns.products
                for j, a in enumerate(pr.loads):
                    print(f"{tag} q_s={q_s}: loads[{j}] {_h(a)}")
                for j, a in enumerate(pr.loads_z or ()):
                    print(f"{tag} q_s={q_s}: loads_z[{j}] {_h(a)}")
                print(f"{tag} q_s={q_s}: coulomb {_h(pr.coulomb)} pplus {_h(pr.pplus)}")
                try:
                    fit = RobotModel(reg, "paper", method, form="products", q_s=q_s).fit(out)
                    print(f"{tag} q_s={q_s}: paper {_h(fit.coef_)}")
                except RobotIdentError as err:  # arm3's j2: one load sign on these rows
                    print(f"{tag} q_s={q_s}: paper refused: {err}")


if __name__ == "__main__":
    np.set_printoptions(precision=17)
    single_joint()
    robot()
