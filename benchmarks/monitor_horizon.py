"""The monitor's crossing rule before and after persistence + horizon, offline on bench folders.

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/monitor_horizon.py --work DIR \
        [--campaign examples/campaign_ur10_demo.toml] [--false-also DIR2 ...] [--oracle] \
        [--cache FILE.pkl] [--constant-band] [--json OUT.json]

DIR is a ``bench_monitor.py`` work folder whose ``model``, ``calibrate``, ``false`` and
``detect`` stages ran (the filtered residual); each ``--false-also`` folder holds another
``false`` stage of the same campaign (``bench_monitor.py --work DIR2 --false-seed 17
false``, DIR2/model the same model), whose logs count as more false-alarm minutes. Every
log's q, dq and torque actual are replayed through the monitor's residual once
(``monitor_stuck.replay_all``: the identified model of DIR/model, or with ``--oracle`` the
simulator's parameters; ``--cache`` keeps the replay for the next call); then two rules are
evaluated on the same residual, each calibrated on DIR's calibrate logs
(``thresholds_from_residual``: k = 6, peak margin 1.5, the default regime bins, pooled thin
bins):

``before``
    a crossing at the first cycle out of the band; the peaks are the validation's;
``after``
    the default of ``jointid monitor --calibrate`` (``daq.app.monitor``): a crossing after
    ``DEFAULT_PERSIST_CYCLES`` consecutive cycles out of the band, the peaks those of that
    statistic, extrapolated from the validation's duration to ``DEFAULT_HORIZON_S``
    (``ident.monitor.horizon_factor``).

Printed per joint: the bands (half-widths [N m], ``*`` no statistics of its own), the false
alarms (crossings) and largest excursion / band on each false stage (``after``: the smallest
of each ``DEFAULT_PERSIST_CYCLES`` consecutive ones, what the rule compares), and per pushed link
and force the delays [ms] of the detect log's pushes (from the staging cycle to the first
crossing on any joint; ``None`` missed) and the crossings outside the pushes. The live
monitor gives the same figures (its moving time, bands and persistence are these
functions'; the ``before`` figures equal those ``bench_monitor.py`` recorded).
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_monitor as bm  # noqa: E402  (the bench's replay and push windows)
import monitor_stuck as ms  # noqa: E402

from daq.app.monitor import (  # noqa: E402
    AFTER_PUSH_S,
    DEFAULT_K_SIGMA,
    DEFAULT_PEAK_MARGIN,
)
from daq.runtime.monitor import moving_seconds  # noqa: E402
from ident.monitor import DEFAULT_EDGES_S, thresholds_from_residual  # noqa: E402


def replay(work: Path, also: list[Path], oracle: bool, cache: Path | None
           ) -> tuple[dict, list[str], float]:
    """Per (stage, log): the replayed residual and states (``monitor_stuck.replay_all``);
    the other folders' false logs as stage ``false`` too (their names prefixed)."""
    if cache is not None and cache.is_file():  # DIR's own replay, kept by an earlier call
        d = pickle.loads(cache.read_bytes())
        runs, joints, cs = d["runs"], d["joints"], d["cycle_s"]
    else:
        runs, c = ms.replay_all(work, oracle)
        joints, cs = list(c.moving), float(c.cycle_s)
        if cache is not None:
            cache.write_bytes(pickle.dumps({"runs": runs, "joints": joints, "cycle_s": cs}))
    for i, w in enumerate(also):
        more, _ = ms.replay_all(w, oracle)  # its own calibrate/detect: none expected
        runs.update({("false", f"{i}:{w.name}/{n}"): d for (s, n), d in more.items()
                     if s == "false"})
    return runs, joints, cs


def evaluate(runs: dict, joints: list[str], cs: float, after: bool, constant: bool = False
             ) -> dict:
    """Thresholds from the calibrate runs, false alarms per false folder, detection
    (module docstring); ``constant``: the constant band (``--constant-band``)."""
    cal = [d for (s, _), d in runs.items() if s == "calibrate"]

    def regime(d: dict) -> np.ndarray:
        return moving_seconds(d["vel"], d["vr"], cs)

    th = thresholds_from_residual(
        np.concatenate([d["r"][d["armed"]] for d in cal]), joints, DEFAULT_K_SIGMA,
        "offline", DEFAULT_PEAK_MARGIN, np.concatenate([regime(d)[d["armed"]] for d in cal]),
        DEFAULT_EDGES_S, **(bm.rule_kwargs("filtered", 0.0, cs) if after else {}))
    if constant:
        th = th.constant()
    out: dict = {"bands": [[round((h - lo) / 2, 3) for lo, h in zip(a, b, strict=True)]
                           for a, b in zip(*th.bands(), strict=True)],
                 "own": th.bin_used or [[True]] * len(joints),
                 "persist_cycles": th.persist_cycles,
                 "horizon_s": th.horizon_s, "validation_s": th.validation_s}
    false: dict = {}
    pushes, outside = [], 0
    span = int(round((bm.PUSH_S + AFTER_PUSH_S) / cs))
    for (stage, name), d in runs.items():
        if stage == "calibrate":
            continue
        lo, hi = bm.sample_bands(th, regime(d))
        hits = bm._rising(d["r"], d["armed"], lo, hi, th.persist_cycles)
        if stage == "false":
            a = d["armed"]
            f = false.setdefault(name.split("/")[0] if "/" in name else "own", {
                "false_alarms": np.zeros(len(joints), int), "minutes": 0.0,
                "worst": np.zeros(len(joints))})
            f["false_alarms"] += hits.sum(axis=0)
            f["minutes"] += float(a.sum()) * cs / 60.0
            # the excursion the rule sees: the smallest of persist_cycles consecutive ones
            x = np.abs(d["r"] - (lo + hi) / 2) / ((hi - lo) / 2)
            for i in range(1, th.persist_cycles):
                x[i:] = np.minimum(x[i:], x[:-i])
                x[:i] = 0.0
            f["worst"] = np.maximum(f["worst"], x[a].max(axis=0))
            continue
        found, out_n = bm.push_delays(d["cycle"], d["events"], hits, joints, span, cs)
        pushes += found
        outside += out_n
    out["false"] = {k: {"false_alarms": v["false_alarms"].tolist(),
                        "minutes": round(v["minutes"], 2),
                        "worst": v["worst"].round(3).tolist()} for k, v in false.items()}
    out.update(pushes=pushes, outside=outside)
    return out


def show(tag: str, res: dict, joints: list[str]) -> None:
    print(f"== {tag} (persist {res['persist_cycles']} cycles, horizon {res['horizon_s']:g} s "
          f"from {res['validation_s']:.1f} s)")
    for j, name in enumerate(joints):
        bands = " ".join(f"{b:.3f}{'' if u else '*'}"
                         for b, u in zip(res["bands"][j], res["own"][j], strict=True))
        print(f"  {name:22s} bands {bands}")
    for k, f in res["false"].items():
        print(f"  false stage {k}: false alarms {f['false_alarms']} in {f['minutes']:.1f} min, "
              f"largest excursion / band {f['worst']}")
    print(f"  crossings outside the pushes {res['outside']}")
    bm.print_push_delays(res["pushes"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--campaign", type=Path, default=bm.DEMO)
    ap.add_argument("--false-also", type=Path, action="append", default=[])
    ap.add_argument("--oracle", action="store_true")
    ap.add_argument("--cache", type=Path, default=None)
    ap.add_argument("--constant-band", action="store_true",
                    help="evaluate the constant band (jointid monitor --constant-band)")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    bm.SOURCE["campaign"] = a.campaign.resolve()
    runs, joints, cs = replay(a.work, a.false_also, a.oracle, a.cache)
    res = {"before": evaluate(runs, joints, cs, False, a.constant_band),
           "after": evaluate(runs, joints, cs, True, a.constant_band),
           "constant_band": a.constant_band,
           "model": "oracle" if a.oracle else "identified", "work": str(a.work),
           "false_also": [str(p) for p in a.false_also]}
    for tag in ("before", "after"):
        show(f"{res['model']} {tag}{' (constant band)' if a.constant_band else ''}", res[tag],
             joints)
    if a.json:
        a.json.write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
