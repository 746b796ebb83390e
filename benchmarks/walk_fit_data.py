"""The walk of a fit's data through the project's files: stays and returns.

Runs ``jointid fit`` (through ``daq.app.cli.main``) on simulated data, once for a single joint
and once for a 3-dof robot (``--robot``), with a profiler hook that follows which project
file the running code is in (function calls and returns; library code counts as the project
file that called it). Consecutive time in one file is a *stay*; a stay in a file visited
before is a *return*. Issue 24 measures the two chains with these counts: many returns mean
the samples bounce between modules (e.g. ``robot/design.py`` <-> ``preprocess.py``).

Only the fit itself is walked (loading, preprocessing, design, estimation, tables), not the
data generation, and not the imports: every project module is imported before the hook is
set (:func:`import_project`; until 2026-11-28 the modules a fit imports lazily counted as
files visited: 101-102 files then).

Printed: stays, returns, files, and the ten most frequent file-to-file hops of each fit.

Usage::

    python benchmarks/walk_fit_data.py [--keep DIR]
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import io
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("ident", "daq", "trajectories", "sim_drivers")


def _project_file(filename: str) -> str | None:
    try:
        rel = Path(filename).resolve().relative_to(ROOT)
    except ValueError:
        return None
    return str(rel) if rel.parts and rel.parts[0] in PACKAGES else None


MIN_SAMPLES = 1000


def _holds_samples(frame) -> bool:  # noqa: ANN001 - a frame
    code = frame.f_code
    names = code.co_varnames[: code.co_argcount + code.co_kwonlyargcount]
    for n in names:
        v = frame.f_locals.get(n)
        if isinstance(v, np.ndarray) and v.size >= MIN_SAMPLES:
            return True
        if isinstance(v, (list, tuple)) and v and isinstance(v[0], np.ndarray) and \
                v[0].size >= MIN_SAMPLES:
            return True
    return False


class Walk:
    """A ``sys.setprofile`` hook recording the sequence of project files the code is in."""

    def __init__(self, samples_only: bool = True) -> None:
        self.seq: list[str] = []
        #: follow only the functions handed the samples (an array argument of at least
        #: MIN_SAMPLES values), i.e. the walk of the data rather than of every helper call
        self.samples_only = samples_only

    def _enter(self, f: str | None) -> None:
        if f is not None and (not self.seq or self.seq[-1] != f):
            self.seq.append(f)

    def hook(self, frame, event, arg) -> None:  # noqa: ANN001 - sys.setprofile signature
        if event == "call":
            f = _project_file(frame.f_code.co_filename)
            if f is not None and self.samples_only and not _holds_samples(frame):
                return
            self._enter(f)
        elif event == "return":
            back = frame.f_back
            while back is not None:  # library frames count as their project caller
                f = _project_file(back.f_code.co_filename)
                if f is not None:
                    self._enter(f)
                    break
                back = back.f_back

    def summary(self, skip: tuple[str, ...] = ("daq/app/cli.py",)) -> dict:
        seq = [f for f in self.seq if f not in skip]
        stays = [f for i, f in enumerate(seq) if i == 0 or seq[i - 1] != f]
        seen: set[str] = set()
        returns = 0
        for f in stays:
            returns += f in seen
            seen.add(f)
        hops = collections.Counter(zip(stays, stays[1:], strict=False))
        return {"stays": len(stays), "returns": returns, "files": len(seen),
                "hops": hops.most_common(10)}


def _single_joint_csvs(d: Path) -> list[Path]:
    import tomllib

    from daq.protocol.control import ControllerGains
    from sim_drivers.offline import simulate
    from sim_drivers.plant_config import load_plant
    from trajectories.plan import plan_campaign
    from trajectories.robot_campaign import RobotCampaign

    with open(ROOT / "examples" / "campaign.toml", "rb") as f:
        campaign = RobotCampaign.from_dict(tomllib.load(f), "campaign.toml").quick()
    plan = plan_campaign(campaign)
    plant = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml")
    gains = ControllerGains(**campaign.gains_kwargs())
    files = []
    for i, p in enumerate(plan.payloads):
        r = simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                     payload_arm=p.arm_m, seed=40 + i)
        path = d / f"joint{i}.csv"
        np.savetxt(path, np.column_stack([r.t, r.q, r.tau_ref, np.full(len(r), p.mass_kg),
                                          np.full(len(r), p.arm_m)]),
                   delimiter=",", fmt="%.10g", header="t,q,tau,payload_kg,payload_arm_m",
                   comments="")
        files.append(path)
    return files


def _robot_csvs(d: Path) -> list[Path]:
    from sim_drivers.arm import ArmGains, ArmParams, model_reference, simulate_arm
    from trajectories.robot import load_robot

    robot = load_robot(ROOT / "examples" / "robots" / "arm3.toml")
    params = ArmParams.from_robot(robot)
    gains = ArmGains.for_params(params)
    files = []
    for seed in (1, 2):
        run = simulate_arm(params, model_reference(params.model, duration_s=8.0, seed=seed),
                           gains, seed=seed)
        cols = run.columns()
        path = d / f"arm{seed}.csv"
        np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",",
                   header=",".join(cols), comments="", fmt="%.17g")
        files.append(path)
    return files


def import_project() -> int:
    """Import every module of the project's packages before the walk: a module imported
    lazily during the fit runs its top level (decorators, dataclasses, constants) under the
    hook, which would count it as a file the data visit (a robot fit imports 94 of them).
    Returns the number of project modules loaded."""
    import importlib
    import pkgutil

    for name in PACKAGES:
        pkg = importlib.import_module(name)
        for info in pkgutil.walk_packages(pkg.__path__, name + "."):
            if info.name.endswith("__main__"):
                continue
            with contextlib.suppress(ImportError):
                importlib.import_module(info.name)
    return sum(m.split(".")[0] in PACKAGES for m in sys.modules)


def walk(argv: list[str]) -> dict:
    from daq.app.cli import main

    import_project()
    w = Walk()
    out = io.StringIO()
    sys.setprofile(w.hook)
    try:
        with contextlib.redirect_stdout(out):
            code = main(argv)
    finally:
        sys.setprofile(None)
    if code != 0:
        raise SystemExit(f"jointid {' '.join(argv)} exited {code}:\n{out.getvalue()[-2000:]}")
    return w.summary()


def _walk_in_child(argv: list[str], out: Path) -> dict:
    """:func:`walk` in a fresh interpreter (each fit starts from the same imports; the
    summary comes back through ``out`` as JSON)."""
    here, where = str(Path(__file__).parent), str(out)
    code = (f"import json, sys; sys.path.insert(0, {here!r}); import walk_fit_data as w; "
            f"s = w.walk({argv!r}); s['hops'] = [[a, b, k] for (a, b), k in s['hops']]; "
            f"open({where!r}, 'w').write(json.dumps(s))")
    subprocess.run([sys.executable, "-c", code], check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return json.loads(out.read_text())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--keep", type=Path, help="write the simulated files here (kept)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        d = args.keep or Path(tmp)
        d.mkdir(parents=True, exist_ok=True)
        joint = _single_joint_csvs(d)
        arm = _robot_csvs(d)
        robot = ROOT / "examples" / "robots" / "arm3.toml"
        cases = {
            "single joint (jointid fit)": ["fit", *map(str, joint), "--json", str(d / "j.json")],
            "3-dof robot (jointid fit --robot)": ["fit", "--robot", str(robot),
                                                  *map(str, arm), "--json", str(d / "r.json")],
        }
        for k, (name, argv) in enumerate(cases.items()):
            s = _walk_in_child(argv, d / f"walk{k}.json")
            print(f"{name}: {s['stays']} stays in {s['files']} files, {s['returns']} returns",
                  flush=True)
            for a, b, n in s["hops"]:
                print(f"    {n:4d}  {a} -> {b}", flush=True)


if __name__ == "__main__":
    main()
