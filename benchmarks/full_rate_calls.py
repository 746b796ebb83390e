"""How often one fit evaluates the regressor at full rate, and how long it takes.

    python benchmarks/full_rate_calls.py [--repeat 3]

Counts, on the current code, the calls of the n-dof regressor (``RobotRegressor.rigid_kpn``,
``RobotRegressor.payload_torque``) and of the single-joint terms ``RigidBody.columns`` and
``Payload.columns`` (:mod:`ident.models`), with the samples each call was given; "passes" is
those samples over the full-rate samples of the fit's runs (one pass: every run evaluated
once at full rate; a call on decimated samples adds 1 / r). Three single-joint fits of the
example campaign (``tests/example_campaign.py``, seed 11: LS; IDIM-IV with its references;
LS with a q_s scan, whose fit is at another q_s than the design's), the validation file of a
single-joint fit (two runs fitted, LS with a q_s scan, the third run as validation: the
passes over the validation run's full-rate samples, the difference of the same fit with and
without it, and the validation chain's own count, ``FitReport.validation_signals``) and
robot fits
(``ident.cli_robot.fit_robot``, columns chain, usual and paper models, on two simulated
runs of ``examples/robots/arm3.toml``: LS with each ``payload`` -- known, ratio, mass -- and
IDIM-IV with the payload known). Then the time of one LS ``fit_models`` and of the
robot fit (process CPU time, best of ``--repeat``), in the same process (the fit_models
ratio between two trees: ``benchmarks/bench_fit_versions.py``, interleaved). The counters
wrap the classes' methods in this script only (a measurement, not a test).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from chain_fingerprint import arm_runs  # noqa: E402
from fit_fingerprint import campaign_runs  # noqa: E402

from ident import models as sj  # noqa: E402
from ident.cli_robot import fit_robot  # noqa: E402
from ident.fitting import fit_models  # noqa: E402
from ident.preprocess import TORQUE_DELAY  # noqa: E402
from ident.robot.loaders import RobotPreprocessing  # noqa: E402
from trajectories.robot import regressor as rr  # noqa: E402

#: label -> [calls, samples]
COUNTS: dict[str, list[int]] = defaultdict(lambda: [0, 0])


def _wrap(cls: type, name: str, label: str, samples: Callable[[tuple], int]) -> None:
    orig = getattr(cls, name)

    def counted(self, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
        c = COUNTS[label]
        c[0] += 1
        c[1] += samples(args)
        return orig(self, *args, **kwargs)

    setattr(cls, name, counted)


def _install() -> None:
    _wrap(rr.RobotRegressor, "rigid_kpn", "rigid_kpn", lambda a: int(np.shape(a[0])[0]))
    _wrap(rr.RobotRegressor, "payload_torque", "payload_torque",
          lambda a: int(np.shape(a[0])[0]))
    _wrap(sj.RigidBody, "columns", "RigidBody.columns", lambda a: int(np.size(a[0].q)))
    _wrap(sj.Payload, "columns", "Payload.columns", lambda a: int(np.size(a[0].q)))


def _report(tag: str, full_samples: int) -> None:
    for label in ("rigid_kpn", "payload_torque", "RigidBody.columns", "Payload.columns"):
        calls, n = COUNTS.get(label, [0, 0])
        print(f"{tag}: {label}: {calls} calls, {n / full_samples:.2f} passes")
    COUNTS.clear()


def _full_samples(full) -> int:  # noqa: ANN001 - tuple of FullRate
    return sum(int(f.n) for f in full)


def _validation(ls: list) -> None:
    """The passes spent on a validation run: the same fit with and without it."""
    fit, val = ls[:2], ls[2:]
    fit_models(fit, q_s="scan")
    alone = {k: v[:] for k, v in COUNTS.items()}
    COUNTS.clear()
    rep = fit_models(fit, validation=val, q_s="scan")
    n = sum(len(e.t) - 2 * int(rep.settings["trim"]) for e in val)
    tag = f"fit_models validation (q_s scan, fit at q_s {rep.q_s:.4g})"
    for label in ("rigid_kpn", "payload_torque", "RigidBody.columns", "Payload.columns"):
        calls, samples = COUNTS.get(label, [0, 0])
        calls0, samples0 = alone.get(label, [0, 0])
        print(f"{tag}: validation run: {label}: {calls - calls0} calls, "
              f"{(samples - samples0) / n:.2f} passes")
    sig = getattr(rep, "validation_signals", None)  # (older trees: none)
    if sig is not None:
        print(f"{tag}: validation chain's count per run: "
              f"{sig.columns.full_columns.evaluations}")
    COUNTS.clear()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    ls, iv = campaign_runs()
    robot, runs = arm_runs()
    pre = RobotPreprocessing(torque_delay=TORQUE_DELAY)

    def robot_fit(payload: str = "known", method: str = "ls") -> dict:
        return fit_robot(robot, runs, models=("usual", "paper"), method=method,
                         payload=payload, preprocessing=pre, feasibility=False,
                         sigma_blocks=0)

    _install()
    for tag, fit in (("fit_models ls", lambda: fit_models(ls)),
                     ("fit_models iv", lambda: fit_models(iv)),
                     ("fit_models q_s scan", lambda: fit_models(ls, q_s="scan"))):
        rep = fit()
        if rep.q_s != rep.qs_design:
            tag += f" (fit at q_s {rep.q_s:.4g}, design at {rep.qs_design:g})"
        _report(tag, _full_samples(rep.robot_signals["usual"].columns.full))
    _validation(ls)
    for payload, method in (("known", "ls"), ("ratio", "ls"), ("mass", "ls"),
                            ("known", "iv")):
        rec = robot_fit(payload, method)
        # the robot fit's full-rate samples: its runs after the chain's trim
        trim = int(rec["preprocessing"]["trim"])
        _report(f"robot fit (payload {payload}, {method})",
                sum(r.t.size - 2 * trim for r in runs))
    for tag, fit in (("fit_models ls", lambda: fit_models(ls)), ("robot fit", robot_fit)):
        best = np.inf
        for _ in range(args.repeat):
            t0 = time.process_time()
            fit()
            best = min(best, time.process_time() - t0)
        print(f"{tag}: {best:.3f} s CPU (best of {args.repeat})")


if __name__ == "__main__":
    main()
