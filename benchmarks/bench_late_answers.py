"""Late answers: the paced position loop through a loopback bridge on a loaded host.

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_late_answers.py [--cycle 0.001]
        [--runs 3] [--busy 4] [--hops 2] [--periods 5] [--velocity drive|difference]
        [--check-s 0.5]

A python-can-remote bridge on 127.0.0.1, the simulated drive (node 3) in another process
(``--hops 2``: behind the bridge; 1: served by the bridge's own process) and the master
(``run_campaign``, paced, ``--cycle``) in this one, a 0.1 rad 0.5 Hz sine of ``--periods``
periods (the campaign of ``tests/test_cross_process.py``, TPDO watchdog 50 cycles), beside
``--busy`` busy loops (``sh -c 'while :; do :; done'``, started and stopped here by their
pid). ``--velocity difference`` makes the master's law use the backward difference of the
position even though the clock is paced (``[daq] velocity_source = "difference"``: what it
did before ``drive_velocity``).

``--check-s``: the start-up lateness check's hold ``[daq] lateness_check_s`` [s], its limits
set to 1 so that the run goes on whatever it measures (the calibration of ``lateness_warn``
and ``lateness_stop``, :mod:`daq.runtime.safety`).

Per run, from its log: status and reason; the start-up lateness check's share of late or
missing answers (``check``); the start-up (cycles before the plan moves) and
the plan's share of cycles without the drive's answer; the plan's share of cycles whose
newest TPDO1 was received before the cycle's SYNC was sent (``plan_stale``: the loop ran on
the answer to an earlier SYNC; outside the check's hold the master's wait stops at such a
queued set, so one late answer can keep it a cycle behind); the TPDO1 frames' delay after the
SYNC they follow (p50/p90/p99 [ms], and the share later than a cycle); the rms tracking
error [mrad] and the largest |dq| [rad/s] on answered cycles; the torque reference's
cycle-to-cycle change (std and max [N m]) while the plan runs.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT))

from test_cross_process import remote_campaign  # noqa: E402

from daq.protocol.reader import read_frames, read_run  # noqa: E402
from daq.runtime.runner import run_campaign  # noqa: E402
from sim_drivers.remote import ServeProcess  # noqa: E402


def one_run(out: Path, k: int, cycle: float, hops: int, periods: int, velocity: str,
            check_s: float) -> dict:
    """One campaign through the bridge; the figures of its log."""
    if hops == 2:
        bridge = ServeProcess((), channel=f"late{k}")
        drive = ServeProcess((3,), interface="remote", channel=bridge.url, bridge=False,
                             args=("--sync-loss-floor", "0.3", "--cycle", str(cycle)))
        servers, url = (drive, bridge), bridge.url
    else:
        s = ServeProcess((3,), channel=f"late{k}",
                         args=("--sync-loss-floor", "0.5", "--cycle", str(cycle)))
        servers, url = (s,), s.url
    try:
        c = remote_campaign(url, 3, periods=periods, cycle_s=cycle, tpdo_timeout_cycles=50,
                            heartbeat_timeout_s=0.5, velocity_source=velocity,
                            lateness_check_s=check_s, lateness_warn=1.0, lateness_stop=1.0)
        r = run_campaign(c, out_dir=out / f"r{k}", prompt=lambda *a: True)
    finally:
        for s in servers:
            s.close()
    run = r.runs[0]
    a = read_run(run.path)
    fr = read_frames(run.path)
    t, ids = np.asarray(fr["timestamp"], float), np.asarray(fr["id"])
    sync_t = t[ids == 0x80]
    tp = t[ids == 0x183]
    idx = np.searchsorted(sync_t, tp) - 1
    ok = idx >= 0
    lat, idx = tp[ok] - sync_t[idx[ok]], idx[ok]
    seg = np.asarray(a.segment)
    miss = (np.asarray(a.flags) & 1) != 0
    move = int(np.flatnonzero(seg >= 0)[0]) if (seg >= 0).any() else len(seg)
    plan, answered = seg >= 0, (seg >= 0) & ~miss
    run_lat = lat[idx >= move]
    cyc = np.asarray(fr["cycle"])
    sync_c = cyc[ids == 0x80]
    t_sync = dict(zip(sync_c.tolist(), sync_t.tolist(), strict=True))
    newest: dict[int, float] = {}
    for c, x in zip(cyc[ids == 0x183].tolist(), tp.tolist(), strict=True):
        newest[c] = max(x, newest.get(c, x))
    plan_c = np.flatnonzero(seg >= 0)
    stale = [newest[c] < t_sync[c] for c in plan_c.tolist() if c in newest and c in t_sync]
    tau = np.asarray(a.tau_ref)[plan]
    chk = [e["message"].rsplit(": ", 1)[1] for e in a.events
           if e["message"].startswith("start-up lateness check: late")]
    return {
        "status": run.status, "reason": run.reason[:80], "check": chk[0] if chk else "",
        "startup_cycles": move,
        "startup_missing": round(float(miss[:move].mean()), 3),
        "plan_missing": round(float(miss[plan].mean()), 3),
        "plan_stale": round(float(np.mean(stale)), 3) if stale else 0.0,
        "delay_ms_p50_p90_p99": [round(1e3 * x, 2) for x in np.quantile(run_lat, [.5, .9, .99])],
        "later_than_a_cycle": round(float(np.mean(run_lat > cycle)), 3),
        "rms_err_mrad": round(1e3 * float(np.sqrt(np.mean(
            (np.asarray(a.q_ref) - np.asarray(a.q))[answered] ** 2))), 2),
        "max_abs_dq": round(float(np.abs(np.asarray(a.dq)[answered]).max()), 3),
        "dtau_std": round(float(np.std(np.diff(tau))), 2),
        "dtau_max": round(float(np.abs(np.diff(tau)).max()), 1),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycle", type=float, default=0.001)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--busy", type=int, default=4)
    ap.add_argument("--hops", type=int, choices=(1, 2), default=2)
    ap.add_argument("--periods", type=int, default=5)
    ap.add_argument("--velocity", choices=("drive", "difference"), default="drive")
    ap.add_argument("--check-s", type=float, default=0.5)
    args = ap.parse_args()
    busy = [subprocess.Popen(["sh", "-c", "while :; do :; done"]) for _ in range(args.busy)]
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for k in range(args.runs):
                row = one_run(Path(tmp), k, args.cycle, args.hops, args.periods, args.velocity,
                              args.check_s)
                print(json.dumps({"velocity": args.velocity, "busy": args.busy,
                                  "hops": args.hops, **row}), flush=True)
    finally:
        for p in busy:
            p.kill()
            p.wait()


if __name__ == "__main__":
    main()
