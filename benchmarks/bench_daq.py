"""DAQ benchmarks: lockstep rate (1 and 3 drives), paced 1 kHz jitter vs a C loop, MCAP writes.

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_daq.py [--paced-seconds 60] [--repeat 3]

Prints one table. Everything runs through the full stack: campaign -> plan -> runner ->
canopen master -> python-can virtual bus -> simulated CiA 402 drive + plant -> MCAP.

- lockstep cycles/s: wall-clock rate of a whole payload run (median over ``--repeat``), its
  ratio to real time at 1 kHz, and the process CPU time per cycle (drive + plant + master +
  log, all threads): the CPU figure is the stable one on a shared machine, the wall rate
  depends on how much of a core the scheduler gives us.
- paced: a 1 kHz payload run of ``--paced-seconds``; lateness of every SYNC against its
  deadline (p50/p99/max) and missed cycles (SYNC more than half a period late); the C
  reference loop (``c_paced_loop.c``, compiled here with gcc) runs at the same time for as
  many cycles, so both see the same host stalls; same criterion.
- MCAP: messages/s written by :class:`daq.runtime.mcaplog.RunLog` with the
  runner's per-cycle mix
  (one state, one setpoint, one CAN batch of 4 frames), and the logging time per cycle as a
  share of the lockstep all-in CPU time per cycle.
- master loss (``--safety-repeat``): a simulated drive in CST OPERATION ENABLED watching the
  master's heartbeat (:class:`daq.runtime.master.MasterHeartbeat`, 100 ms, consumer 400 ms) or SYNC
  (0x1006 = 1000 us); the master stops both; time from the last heartbeat / SYNC the drive
  received to its FAULT, against the configured time, in ms and in 1 kHz cycles (the drive
  applies its last torque during that time, and runs no cycle since no SYNC comes).
"""

from __future__ import annotations

import argparse
import itertools
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from daq.protocol.logformat import FRAME  # noqa: E402
from daq.runtime.mcaplog import RunLog  # noqa: E402
from daq.runtime.runner import run_campaign  # noqa: E402
from sim_drivers.plant_config import default_plant  # noqa: E402
from trajectories.campaign import Campaign  # noqa: E402

HERE = Path(__file__).resolve().parent
_chan = itertools.count()


def campaign(seconds: float, cycle_s: float = 0.001, drives: int = 1,
             clock: str = "lockstep") -> Campaign:
    periods = max(1, int(round(seconds * 0.25)))
    raw = {
        "name": "bench",
        "joint": {"kind": "revolute", "limits": {
            "position": [-1.0, 1.0], "max_velocity": 1.0, "max_acceleration": 4.0,
            "max_jerk": 40.0, "max_torque": 700.0}},
        "control": {"cycle_s": cycle_s, "kp": 6000.0, "kd": 200.0,
                    "feedforward": {"J": 30.0, "MX": 21.0}},
        "payloads": [{"mass_kg": 0.0, "arm_m": 1.0}],
        "segments": [{"kind": "sine", "amplitude": 0.3, "frequency_hz": 0.25, "center": 0.0,
                      "periods": periods}],
        "daq": {"channel": f"bench_{next(_chan)}", "clock": clock,
                "drives": [{"node_id": n} for n in range(1, drives + 1)],
                "heartbeat_timeout_s": 2.0, "tpdo_timeout_cycles": 1000,
                "max_following_error": 1.0},
    }
    return Campaign.from_dict(raw, "bench.toml")


def lockstep(drives: int, seconds: float, repeat: int, out: Path) -> tuple[float, float, int]:
    """Median wall cycles/s, median CPU µs/cycle, cycles per run."""
    cycle_s = 0.001 if drives == 1 else 0.002  # 3 drives at 1 kHz exceed 1 Mbit/s
    c = campaign(seconds * (1 if drives == 1 else 0.5) / cycle_s * 0.001, cycle_s, drives)
    rates, cpus, n = [], [], 0
    for _ in range(repeat):
        c0 = time.process_time()
        r = run_campaign(c, out_dir=out, simulate=default_plant(), yes=True)
        cpu = time.process_time() - c0
        assert r.ok, r.reason
        run = r.runs[0]
        n = run.cycles
        rates.append(run.cycles_per_s)
        cpus.append(cpu / n * 1e6)
    return statistics.median(rates), statistics.median(cpus), n


def paced(seconds: float, out: Path) -> dict[str, float]:
    c = campaign(seconds, 0.001, 1, clock="paced")
    r = run_campaign(c, out_dir=out, simulate=default_plant(), yes=True)
    run = r.runs[0]
    lat = run.lateness_s * 1e6
    return {"cycles": run.cycles, "missed": run.missed, "p50": float(np.percentile(lat, 50)),
            "p99": float(np.percentile(lat, 99)), "max": float(lat.max()),
            "status": r.status}


def c_loop_start(cycles: int, tmp: Path) -> subprocess.Popen | None:
    """Compile and start the C reference loop (it runs beside the Python paced run, so
    both see the same host stalls)."""
    gcc = shutil.which("gcc") or shutil.which("cc")
    if gcc is None:
        return None
    exe = tmp / "c_paced_loop"
    subprocess.run([gcc, "-O2", "-o", str(exe), str(HERE / "c_paced_loop.c")], check=True)
    return subprocess.Popen([str(exe), "1000", str(cycles)], stdout=subprocess.PIPE, text=True)


def c_loop_result(proc: subprocess.Popen) -> dict[str, float]:
    out, _ = proc.communicate(timeout=3600)
    fields = dict(kv.split("=") for kv in out.split())
    return {"cycles": int(fields["cycles"]), "missed": int(fields["missed"]),
            "p50": float(fields["p50_us"]), "p99": float(fields["p99_us"]),
            "max": float(fields["max_us"])}


def mcap_rate(cycles: int, tmp: Path) -> tuple[float, float]:
    """Messages/s and µs of logging per cycle (1 axis, 4 frames per cycle), in process CPU
    time like the lockstep CPU figure they are compared with."""
    frames = b"".join(FRAME.pack(1.0, cid, 8, b"\x01" * 8) for cid in (0x80, 0x201, 0x181,
                                                                          0x281))
    best = []
    for _ in range(3):
        log = RunLog(tmp / "bench_write.mcap", n_axes=1, cycle_s=0.001)
        t0 = time.process_time()
        for c in range(cycles):
            log.state(0, c, c * 1e-3, 0.1, 0.2, 3.0, 4.0, 1000, 20, 6, 8, 0x1237, 0)
            log.setpoint(c, c * 1e-3, 0.1, 0.2, 0.3, 0, 0)
            log.frames(c, frames, 4)
        log.close()
        best.append(time.process_time() - t0)
    dt = statistics.median(best)
    return 3 * cycles / dt, dt / cycles * 1e6


def master_loss(repeat: int) -> dict[str, list[float]]:
    """Delays [s] from the last heartbeat / SYNC received to the drive's FAULT, and the
    configured timeouts [s]."""
    from daq.protocol.cia402 import State, path
    from daq.runtime.master import MasterHeartbeat
    from sim_drivers.testing import LockstepMaster, make_rig

    node = 9
    tpdos = {0x180 + node: ("<Hi", ("6041", "6064")), 0x280 + node: ("<hi", ("6077", "606C"))}
    out: dict[str, list[float]] = {"hb": [], "sync": [], "hb_cfg": [], "sync_cfg": []}

    def wait_fault(rig) -> None:
        end = time.monotonic() + 5.0
        while rig.drive.state is not State.FAULT and time.monotonic() < end:
            time.sleep(0.001)

    for kind in ("hb", "sync"):
        for _ in range(repeat):
            rig = make_rig(node_id=node)
            hb = MasterHeartbeat(rig.network.bus, 127, 100)
            try:
                if kind == "hb":
                    rig.node.sdo[0x1016][1].raw = (127 << 16) | 400
                    hb.start()
                else:
                    rig.node.sdo[0x1006].raw = 1000
                rig.node.sdo[0x6060].raw = 10
                for _, cw in path(State.SWITCH_ON_DISABLED, State.OPERATION_ENABLED):
                    rig.node.sdo[0x6040].raw = cw
                rig.node.nmt.state = "OPERATIONAL"
                rig.node.sdo[0x1000].raw  # noqa: B018 - barrier: NMT start processed
                m = LockstepMaster(rig.network, 0x200 + node, "<Hh", tpdos)
                m.run(0x0F, np.full(300, 100))
                if kind == "hb":
                    time.sleep(0.25)  # a few heartbeats
                    hb.stop()
                    c = rig.drive._consumers[1]
                    wait_fault(rig)
                    out["hb"].append(rig.drive.fault_time - c.last)
                    out["hb_cfg"].append(c.time_s)
                else:
                    wait_fault(rig)
                    out["sync"].append(rig.drive.fault_time - rig.drive.last_sync_time)
                    out["sync_cfg"].append(rig.drive.sync_timeout_s)
                m.close()
            finally:
                hb.stop()
                rig.close()
    return out


def safety_rows(repeat: int) -> list[tuple[str, str, str, str]]:
    ml = master_loss(repeat)
    rows = []
    for kind, label in (("hb", "master loss: heartbeat -> FAULT"),
                        ("sync", "master loss: SYNC -> FAULT")):
        d = np.array(ml[kind]) * 1e3
        cfg = statistics.median(ml[kind + "_cfg"]) * 1e3
        over = d - cfg
        rows.append((label, f"median {np.median(d):.1f} ms (cfg {cfg:.0f} ms)",
                     f"= {np.median(d):.0f} cycles at 1 kHz",
                     f"overshoot median {np.median(over):.1f} / max {over.max():.1f} ms, "
                     f"n={len(d)}"))
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paced-seconds", type=float, default=60.0)
    ap.add_argument("--lockstep-seconds", type=float, default=10.0,
                    help="simulated seconds per lockstep run")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--safety-repeat", type=int, default=5,
                    help="master-loss reaction measurements per kind (0: skip)")
    ap.add_argument("--only-safety", action="store_true", help="only the master-loss rows")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_daq_"))
    try:
        rows = safety_rows(args.safety_repeat) if args.safety_repeat else []
        if not args.only_safety:
            rows.extend(speed_rows(args, tmp))
        w = [max(len(r[i]) for r in rows) for i in range(4)]
        print(f"bench_daq  (python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load "
              f"{os.getloadavg()[0]:.1f})")
        for r in rows:
            print("  ".join(x.ljust(w[i]) for i, x in enumerate(r)).rstrip())
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


def speed_rows(args: argparse.Namespace, tmp: Path) -> list[tuple[str, str, str, str]]:
    rows = []
    r1, cpu1, n1 = lockstep(1, args.lockstep_seconds, args.repeat, tmp / "l1")
    rows.append(("lockstep, 1 drive, 1 kHz plan", f"{r1:,.0f} cycles/s",
                 f"{r1 / 1000:.2f}x real time", f"CPU {cpu1:.0f} us/cycle, {n1} cycles"))
    r3, cpu3, n3 = lockstep(3, args.lockstep_seconds, args.repeat, tmp / "l3")
    rows.append(("lockstep, 3 drives", f"{r3:,.0f} cycles/s",
                 f"{r3 / 1000:.2f}x real time at 1 kHz",
                 f"CPU {cpu3:.0f} us/cycle; 3 vs 1 drive: {r3 / r1:.2f}x rate"))
    msg_s, log_us = mcap_rate(100_000, tmp)
    rows.append(("MCAP write (state+setpoint+CAN)", f"{msg_s:,.0f} msg/s",
                 f"{log_us:.1f} us/cycle",
                 f"{100 * log_us / cpu1:.0f} % of the 1-drive all-in CPU cycle"))
    # the plan of a paced run: ~args.paced_seconds of cycles + enable/approach/settle
    proc = c_loop_start(int(args.paced_seconds * 1000), tmp)
    p = paced(args.paced_seconds, tmp / "paced")
    rows.append(("paced 1 kHz, Python runner", f"missed {p['missed']}/{p['cycles']}",
                 f"lateness p50 {p['p50']:.0f} / p99 {p['p99']:.0f} / max "
                 f"{p['max']:.0f} us", f"run {p['status']}"))
    cref = c_loop_result(proc) if proc is not None else None
    if cref is None:
        rows.append(("paced 1 kHz, C clock_nanosleep", "gcc not found", "", ""))
    else:
        # runs of slightly different lengths (enable/approach/settle): compare rates
        ratio = ((p["missed"] + 1) / p["cycles"]) / ((cref["missed"] + 1) / cref["cycles"])
        rows.append(("paced 1 kHz, C clock_nanosleep", f"missed {cref['missed']}/"
                     f"{cref['cycles']}", f"lateness p50 {cref['p50']:.0f} / p99 "
                     f"{cref['p99']:.0f} / max {cref['max']:.0f} us",
                     f"miss rate Python/C = {ratio:.2f} (+1 each)"))
    return rows


if __name__ == "__main__":
    sys.exit(main())
