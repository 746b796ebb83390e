"""Torque monitoring on the simulated 3-dof arm at 1 kHz (docs/monitoring.md, issue 25).

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_monitor.py --work DIR STAGE [STAGE ...]

Stages (each a ``jointid monitor`` run through the whole stack: campaign -> runner ->
canopen master -> virtual buses -> simulated CiA 402 drives + simulated arm -> MCAP; lockstep
clock unless said, i.e. simulated time):

``model``
    The identified model: ``jointid run`` of examples/campaign_robot3_demo.toml on the
    simulated arm (2 payloads, 174 s), ``jointid fit --robot`` (both models, consistent
    estimate), ``jointid export-model`` (paper model) -> DIR/model.
``calibrate``
    The validation run: the demo campaign again with the monitor in calibration mode ->
    DIR/calibrate/thresholds.json (k = 6 sigma, at least 1.5 x the validation peak).
``false``
    About 10 min of excitation without pushes: the demo campaign with another multi-sine
    (seed 7, 33 periods of 8 s), both payloads; the monitor logs its residual, and the
    crossings of the calibration's thresholds are counted on it (the thresholds do not change
    the residual, so counting them on the log is what the live check would count).
``detect``
    Pushes of 20 N and 40 N on each link (default point and direction of
    ``sim_drivers.arm_push.staged_push``) for 0.2 s, every 1.5 s (3 per link and force),
    during a multi-sine of all joints (seed 5, 4 periods of 8 s; the pushes fall at whatever
    speed the joints have then), with the calibration's thresholds: detection and delay
    per pushed link (from the cycle the push is staged to the first crossing on any joint),
    crossings outside the push windows.
``paced``
    ``--paced-seconds`` of the demo's multi-sine on the real-time clock (daq.clock = paced,
    1 kHz) with the monitor checking every cycle, then the same run without the monitor,
    ``--paced-repeat`` pairs interleaved (``--realtime P``: daq.realtime_priority = P, pinned
    to the last CPU): missed cycles (SYNC more than half a period late), the lateness
    percentiles and busy times from each log's ``/timing``, how many misses followed a
    cycle longer than the period (the loop's own work; else the loop woke late: the host),
    the 1-min load average of each run and the time the hypervisor stole from each CPU
    during it (/proc/stat), the monitor's time per cycle.
``report``
    Prints the figures of the stages run so far (also written to DIR/bench_monitor.json).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from daq.app.monitor import load_campaign, run_monitor
from daq.app.running import run_with_bar
from daq.protocol.reader import read_topics
from daq.runtime.monitor import read_monitor
from ident.monitor import Thresholds

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "examples" / "campaign_robot3_demo.toml"
JOINTS = ("j1", "j2", "j3")


def _campaign(work: Path, name: str, *, seed: int, periods: int, multisine_only: bool,
              payloads: int = 2, daq: str = "") -> Path:
    """A variant of the demo campaign (its robot, drives, gains, limits)."""
    text = DEMO.read_text()
    text = text.replace('file = "robots/arm3.toml"',
                        f'file = "{(ROOT / "examples" / "robots" / "arm3.toml").as_posix()}"')
    text = text.replace('name = "arm3-demo"', f'name = "{name}"')
    text = re.sub(r"\nseed = 1\b", f"\nseed = {seed}", text)
    text = re.sub(r"\nperiods = 1\b", f"\nperiods = {periods}", text)
    head, _, rest = text.partition("[[segments]]")
    segs = ["[[segments]]" + s for s in rest.split("[[segments]]")]
    if multisine_only:
        segs = [s for s in segs if 'kind = "multisine"' in s]
    if payloads == 1:
        head = head.split("[[payloads]]")[0] + "[[payloads]]\nmass_kg = 0.0\n\n"
    p = work / f"{name}.toml"
    if daq:  # e.g. the paced run's SCHED_FIFO priority and CPU (docs/campaign-robot.md)
        head = head.replace("\n[daq]\n", "\n[daq]\n" + daq + "\n") if "\n[daq]\n" in head \
            else head + "\n[daq]\n" + daq + "\n\n"
    p.write_text(head + "".join(segs))
    return p


def stage_model(work: Path) -> None:
    logs, fit, model = work / "model_logs", work / "fit.json", work / "model"
    jid = [sys.executable, "-m", "daq.app.cli"]
    subprocess.run([*jid, "run", str(DEMO), "--simulate", "--out", str(logs), "--yes",
                    "--overwrite"], check=True)
    subprocess.run([*jid, "fit", "--robot", str(ROOT / "examples/robots/arm3.toml"),
                    *map(str, sorted(logs.glob("*.mcap"))), "--model", "both", "--json",
                    str(fit), "--no-consistency", "--consistent"], check=True,
                   stdout=subprocess.DEVNULL)
    subprocess.run([*jid, "export-model", str(fit), "--model", "paper", "-o", str(model)],
                   check=True)


def stage_calibrate(work: Path) -> dict:
    s = run_monitor(work / "model", DEMO, work / "calibrate", simulate=True, calibrate=True)
    return {"thresholds": s["thresholds"], "wall_s": s["wall_s"],
            "missed": s["missed_cycles"]}


def crossings(path: Path, th: Thresholds) -> tuple[list, float, list]:
    """Rising edges out of the thresholds' band on the armed samples of a log, per joint;
    armed seconds; the largest |r - mean| / half-width per joint."""
    ml = read_monitor(path)
    r = ml.residual[ml.armed]
    lo, hi = np.array(th.lower), np.array(th.upper)
    out = (r < lo) | (r > hi)
    edges = ((out[1:] & ~out[:-1]).sum(axis=0) + out[0]).astype(int).tolist()
    cycle_s = float(np.median(np.diff(ml.t)))
    worst = (np.abs(r - np.array(th.mean)) / np.array(th.half_width)).max(axis=0)
    return edges, r.shape[0] * cycle_s, worst.tolist()


def stage_false(work: Path) -> dict:
    camp = _campaign(work, "arm3-false", seed=7, periods=33, multisine_only=False)
    s = run_monitor(work / "model", camp, work / "false", simulate=True, calibrate=True)
    return {"logs": s["logs"], "wall_s": s["wall_s"], "missed": s["missed_cycles"]}


def stage_detect(work: Path) -> dict:
    camp = _campaign(work, "arm3-detect", seed=5, periods=4, multisine_only=True, payloads=1)
    pushes = []
    t = 1.0
    for force in (20, 40):
        for _ in range(3):
            for j in JOINTS:
                pushes.append(f"{j}:{force}:{t:g}:0.2")
                t += 1.5
    s = run_monitor(work / "model", camp, work / "detect", simulate=True,
                    thresholds=work / "calibrate" / "thresholds.json", pushes=pushes)
    return {"runs": s["runs"], "wall_s": s["wall_s"], "missed": s["missed_cycles"]}


def _paced_timing(path: Path) -> dict:
    """Lateness of every SYNC and the cycle's busy time from a paced log's ``/timing``
    channel (engine.TIMING_SCHEMA): percentiles [us], missed cycles (> half a period late)
    and how many of them followed a cycle that was itself longer than the period (the
    loop's own work) rather than a late wake-up from its sleep (the host)."""
    raw = read_topics(path, {"/timing"}).raw.get("/timing", [])
    rows = np.array([struct.unpack_from("<qddd", m, 4) for m in raw])
    rows = rows[np.argsort(rows[:, 0])]
    late, busy = rows[:, 2], rows[:, 3]
    cycle_s = 1e-3
    miss = np.flatnonzero(late > 0.5 * cycle_s)
    after_long = int(np.sum(busy[miss[miss > 0] - 1] > cycle_s))
    pct = {f"lateness_{k}_us": float(np.percentile(late, q) * 1e6)
           for k, q in (("p50", 50), ("p99", 99), ("p999", 99.9))}
    return {"cycles_timed": int(len(rows)), "missed_timed": int(len(miss)), **pct,
            "lateness_max_us": float(late.max() * 1e6),
            "busy_p50_us": float(np.percentile(busy, 50) * 1e6),
            "busy_p99_us": float(np.percentile(busy, 99) * 1e6),
            "busy_max_us": float(busy.max() * 1e6),
            "missed_after_long_cycle": after_long,
            "missed_late_us": (late[miss] * 1e6).round().astype(int).tolist()}


def _steal_ms() -> list[float]:
    """Time stolen from each CPU by the hypervisor so far [ms] (/proc/stat; [] elsewhere):
    on a VM a loop's wake-up is late while its vCPU is not running."""
    try:
        lines = Path("/proc/stat").read_text().splitlines()
    except OSError:
        return []
    tck = os.sysconf("SC_CLK_TCK")
    return [1000.0 * int(ln.split()[8]) / tck for ln in lines
            if ln.startswith("cpu") and ln[3:4].isdigit()]


def stage_paced(work: Path, seconds: float, realtime: int = 0, repeat: int = 1) -> dict:
    """``repeat`` pairs of runs, interleaved (the host's load changes by the minute): with
    the monitor, then the same campaign without it; each with its load average [1 min]."""
    periods = max(1, int(round(seconds / 8.0)))
    daq = f"realtime_priority = {realtime}\ncpu = -1" if realtime else ""
    camp = _campaign(work, "arm3-paced", seed=1, periods=periods, multisine_only=True,
                     payloads=1, daq=daq)
    out: dict = {"monitor": {"runs": []}, "none": {"runs": []}, "realtime_priority": realtime}
    for _ in range(repeat):
        for tag, th in (("monitor", work / "calibrate" / "thresholds.json"), ("none", None)):
            load0 = os.getloadavg()[0]
            steal0 = _steal_ms()
            if th is None:  # the same run without the monitor: run_campaign alone
                c = load_campaign(camp, True)
                res, wall = run_with_bar(c, work / "paced_none", True, sys.stderr)
                r = res.runs[0]
                run = {"status": res.status, "reason": res.reason, "missed": r.missed,
                       "cycles": r.cycles, "wall_s": wall, **_paced_timing(r.path)}
            else:
                s = run_monitor(work / "model", camp, work / "paced_monitor", simulate=True,
                                thresholds=th, paced=True)
                m = s["runs"][0]
                run = {"status": s["status"], "reason": s["reason"],
                       "missed": s["missed_cycles"][0], "cycles": m["cycles"],
                       "wall_s": s["wall_s"], "false_alarms": len(m["false_alarms"]),
                       "check_us_mean": m["step_us_mean"], "check_us_max": m["step_us_max"],
                       **_paced_timing(work / "paced_monitor" / s["logs"][0])}
            run["load_1min"] = [load0, os.getloadavg()[0]]
            run["steal_ms_per_cpu"] = [b - a for a, b in zip(steal0, _steal_ms(), strict=False)]
            out[tag]["runs"].append(run)
    for tag in ("monitor", "none"):
        runs = out[tag]["runs"]
        out[tag]["missed"] = [r["missed"] for r in runs]
        out[tag]["cycles"] = [r["cycles"] for r in runs]
    return out


def report(work: Path, res: dict) -> None:
    th_path = work / "calibrate" / "thresholds.json"
    if th_path.is_file():
        th = Thresholds.read(th_path)
        print("thresholds (validation: the demo campaign, 2 payloads):")
        for j, s, lo, hi, pk in zip(th.joints, th.sigma, th.lower, th.upper,
                                       th.peak, strict=True):
            print(f"  {j}: sigma {s:.4f} N m, band [{lo:+.3f}, {hi:+.3f}] N m, "
                  f"validation peak {pk:.1f} sigma")
        if (work / "false" / "monitor.json").is_file():
            logs = json.loads((work / "false" / "monitor.json").read_text())["logs"]
            total, secs, worst = np.zeros(3, int), 0.0, np.zeros(3)
            for lg in logs:
                n, sec, w = crossings(work / "false" / lg, th)
                total += n
                secs += sec
                worst = np.maximum(worst, w)
            res["false_alarms"] = {"per_joint": total.tolist(), "monitored_s": secs,
                                   "worst_fraction_of_band": worst.tolist()}
            print(f"false alarms: {int(total.sum())} ("
                  + ", ".join(f"{j} {n}" for j, n in zip(JOINTS, total, strict=True))
                  + f") in {secs / 60:.1f} min of monitored excitation without pushes; "
                  "largest |r - mean| / half-width per joint: "
                  + ", ".join(f"{j} {w:.2f}" for j, w in zip(JOINTS, worst, strict=True)))
    det = res.get("detect")
    if det:
        for run in det["runs"]:
            by: dict = {}
            for p in run["pushes"]:
                by.setdefault((p["joint"], p["force_N"]), []).append(p)
            print("detection (pushes during the multi-sine, 0.2 s each):")
            for (j, f), ps in sorted(by.items()):
                d = [1000 * p["delay_s"] for p in ps if p["detected"]]
                print(f"  link of {j}, {f:g} N: {len(d)}/{len(ps)} detected, delay "
                      + (f"{min(d):.0f}..{max(d):.0f} ms (median "
                         f"{statistics.median(d):.0f})" if d else "-")
                      + "; joints crossed: "
                      + ", ".join(sorted({x for p in ps for x in p["joints_crossed"]})))
            print(f"  crossings outside the push windows: {len(run['false_alarms'])}")
    pc = res.get("paced")
    if pc and "runs" in pc.get("monitor", {}):
        print(f"paced 1 kHz (realtime_priority {pc.get('realtime_priority', 0)}), in run "
              "order:")
        for k in range(len(pc["monitor"]["runs"])):
            for tag in ("monitor", "none"):
                r = pc[tag]["runs"][k]
                check = (f", check {r['check_us_mean']:.0f} us mean / {r['check_us_max']:.0f}"
                         " max" if "check_us_mean" in r else "")
                print(f"  {tag:7s} {r['missed']} missed of {r['cycles']} ({r['status']}"
                      f"{': ' + r['reason'] if r['reason'] else ''}), lateness p50 "
                      f"{r['lateness_p50_us']:.1f} / p99 {r['lateness_p99_us']:.1f} / p99.9 "
                      f"{r['lateness_p999_us']:.0f} / max {r['lateness_max_us']:.0f} us, "
                      f"busy p50 {r['busy_p50_us']:.0f} / p99 {r['busy_p99_us']:.0f} us, "
                      f"{r['missed_after_long_cycle']} after a cycle > 1 ms{check}; load "
                      f"{r['load_1min'][0]:.1f}; stolen by the hypervisor "
                      f"{r.get('steal_ms_per_cpu', [])} ms per CPU")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--paced-seconds", type=float, default=30.0)
    ap.add_argument("--realtime", type=int, default=0,
                    help="paced stage: SCHED_FIFO priority of the cycle loop (daq."
                         "realtime_priority, pinned to the last CPU; needs CAP_SYS_NICE)")
    ap.add_argument("--paced-repeat", type=int, default=1,
                    help="paced stage: pairs of runs (with, without the monitor), interleaved")
    ap.add_argument("stages", nargs="+", choices=("model", "calibrate", "false", "detect",
                                                  "paced", "report"))
    a = ap.parse_args()
    a.work.mkdir(parents=True, exist_ok=True)
    store = a.work / "bench_monitor.json"
    res = json.loads(store.read_text()) if store.is_file() else {}
    for st in a.stages:
        t0 = time.perf_counter()
        if st == "model":
            stage_model(a.work)
        elif st == "calibrate":
            res["calibrate"] = stage_calibrate(a.work)
        elif st == "false":
            res["false"] = stage_false(a.work)
        elif st == "detect":
            res["detect"] = stage_detect(a.work)
        elif st == "paced":
            res["paced"] = stage_paced(a.work, a.paced_seconds, a.realtime, a.paced_repeat)
        if st != "report":
            res.setdefault("stage_wall_s", {})[st] = time.perf_counter() - t0
            store.write_text(json.dumps(res, indent=1, default=str))
    report(a.work, res)
    store.write_text(json.dumps(res, indent=1, default=str))


if __name__ == "__main__":
    main()
