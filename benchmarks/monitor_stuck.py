"""The monitor's stuck bin against the rule without it, offline on a bench work folder.

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/monitor_stuck.py --work DIR \
        [--campaign examples/campaign_ur10_demo.toml] [--stuck-velocity 0] [--oracle] \
        [--json OUT.json]

DIR is a ``bench_monitor.py`` work folder whose ``model``, ``calibrate``, ``false`` and
``detect`` stages ran (the filtered residual). Every log's q, dq and torque actual are
replayed through the monitor's residual (``bench_monitor.replay``'s path: the identified
model of DIR/model, or with ``--oracle`` the simulator's own parameters) once; then two
threshold rules are evaluated on the same residual, each calibrated on the calibrate logs by
the live rule (``thresholds_from_residual``, k = 6, peak margin 1.5, pooled thin bins):

``before``
    the default regime bins (moving time 0-30 ms, ..., >= 1 s; rest in the first bin);
``after``
    the same plus the stuck bins (``jointid monitor --calibrate --stuck-velocity V``,
    ``daq.app.monitor.stuck_edges``): a joint whose measured |dq| has been at most V
    (default 0: the drive reads zero) for longer than the filter's settling time (45 ms) is
    in bin 0, with the statistics of all its stuck samples and a band at least as wide as
    the joint's narrowest own band; the first 45 ms of each hold in bin 1.

Printed per joint: the bands (half-widths [N m], ``*`` no statistics of its own), the false
alarms (rising crossings) and largest excursion / band on the false logs, and per pushed
link and force the delays [ms] of the detect log's pushes (from the staging cycle to the
first crossing on any joint; ``None`` missed) and the crossings outside the pushes. The
live monitor gives the same figures (its moving time and bands are these functions'; the
``before`` figures equal those ``bench_monitor.py`` recorded).
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_monitor as bm  # noqa: E402  (the bench's replay and push windows)

from daq.app.monitor import (  # noqa: E402
    AFTER_PUSH_S,
    DEFAULT_K_SIGMA,
    DEFAULT_PEAK_MARGIN,
    stuck_edges,
)
from daq.runtime.monitor import moving_seconds, residual_for  # noqa: E402
from ident.monitor import DEFAULT_EDGES_S, load_exported, thresholds_from_residual  # noqa: E402


def replay_all(work: Path, oracle: bool) -> tuple[dict, object]:
    """Per (stage, log name): the filtered residual r (n, k) [N m] of the monitored cycles,
    the filtered and measured velocities (n, k) [rad/s], armed (n,), cycles, events, rest
    velocities; and the campaign."""
    _, c = bm._source()
    model = bm.truth_model(c) if oracle else load_exported(work / "model")
    out = {}
    for stage in ("calibrate", "false", "detect"):
        for log in sorted((work / stage / "logs").glob("*.mcap")):
            ml, q, dq, tau, pred, vr = bm.logged_states(log, c, model)
            k, n = len(c.moving), len(q)
            res = residual_for("filtered", functools.partial(pred.band, v_rest=vr), k,
                               c.cycle_s)
            r, vel = np.zeros((n, k)), np.zeros((n, k))
            for i in range(n):
                r[i], _, _, vel[i] = res.step(q[i], dq[i], tau[i])
            out[(stage, log.name)] = {"r": r, "vel": vel, "dq": np.asarray(dq), "vr": vr,
                                      "armed": ml.armed, "cycle": ml.cycle,
                                      "events": ml.events}
    return out, c


def evaluate(runs: dict, c: object, stuck: float | None) -> dict:
    """Thresholds from the calibrate runs, false alarms, detection (module docstring);
    ``stuck`` None: the rule without the stuck bin."""
    joints, cs = list(c.moving), c.cycle_s
    vs = None if stuck is None else [stuck] * len(joints)
    edges = (DEFAULT_EDGES_S if vs is None
             else stuck_edges(DEFAULT_EDGES_S, "filtered", 20.0, 0.0))

    def regime(d: dict) -> np.ndarray:
        return moving_seconds(d["vel"], d["vr"], cs, d["dq"], vs)

    cal = [d for (s, _), d in runs.items() if s == "calibrate"]
    th = thresholds_from_residual(
        np.concatenate([d["r"][d["armed"]] for d in cal]), joints, DEFAULT_K_SIGMA,
        "offline", DEFAULT_PEAK_MARGIN, np.concatenate([regime(d)[d["armed"]] for d in cal]),
        edges, stuck_velocity=vs)
    out: dict = {"bands": [[round((h - lo) / 2, 3) for lo, h in zip(a, b, strict=True)]
                           for a, b in zip(*th.bands(), strict=True)],
                 "own": th.bin_used, "samples": [list(x) for x in th.bin_samples],
                 "episodes": [list(x) for x in th.bin_episodes]}
    fa, worst, secs = np.zeros(len(joints), int), np.zeros(len(joints)), 0.0
    pushes, outside = [], 0
    span = int(round((bm.PUSH_S + AFTER_PUSH_S) / cs))
    for (stage, _), d in runs.items():
        if stage == "calibrate":
            continue
        lo, hi = bm.sample_bands(th, regime(d))
        hits = bm._rising(d["r"], d["armed"], lo, hi)
        if stage == "false":
            a = d["armed"]
            fa += hits.sum(axis=0)
            secs += float(a.sum()) * cs
            worst = np.maximum(worst, (np.abs(d["r"][a] - (lo[a] + hi[a]) / 2)
                                       / ((hi[a] - lo[a]) / 2)).max(axis=0))
            continue
        found, out_n = bm.push_delays(d["cycle"], d["events"], hits, joints, span, cs)
        pushes += found
        outside += out_n
    out.update(false_alarms=fa.tolist(), false_minutes=secs / 60.0,
               worst=worst.round(3).tolist(), pushes=pushes, outside=outside)
    return out


def show(tag: str, res: dict, joints: list[str]) -> None:
    print(f"== {tag}")
    for j, name in enumerate(joints):
        bands = " ".join(f"{b:.2f}{'' if u else '*'}"
                         for b, u in zip(res["bands"][j], res["own"][j], strict=True))
        print(f"  {name:22s} bands {bands}")
    print(f"  false alarms {res['false_alarms']} in {res['false_minutes']:.1f} min, largest "
          f"excursion / band {res['worst']}; crossings outside the pushes {res['outside']}")
    bm.print_push_delays(res["pushes"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--campaign", type=Path, default=bm.DEMO)
    ap.add_argument("--stuck-velocity", type=float, default=0.0)
    ap.add_argument("--oracle", action="store_true")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    bm.SOURCE["campaign"] = a.campaign.resolve()
    runs, c = replay_all(a.work, a.oracle)
    res = {"before": evaluate(runs, c, None), "after": evaluate(runs, c, a.stuck_velocity),
           "stuck_velocity": a.stuck_velocity, "model": "oracle" if a.oracle else "identified",
           "work": str(a.work)}
    for tag in ("before", "after"):
        show(f"{res['model']} {tag}", res[tag], list(c.moving))
    if a.json:
        a.json.write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
