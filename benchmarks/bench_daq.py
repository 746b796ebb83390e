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
import struct
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
             clock: str = "lockstep", drive_tables: list | None = None,
             **daq: object) -> Campaign:
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
                "drives": drive_tables or [{"node_id": n} for n in range(1, drives + 1)],
                "heartbeat_timeout_s": 2.0, "tpdo_timeout_cycles": 1000,
                "max_following_error": 1.0, **daq},
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


def _paced_stats(run, status: str) -> dict[str, float]:
    lat = run.lateness_s * 1e6
    busy = _busy_us(run.path)
    return {"cycles": run.cycles, "missed": run.missed, "p50": float(np.percentile(lat, 50)),
            "p99": float(np.percentile(lat, 99)), "max": float(lat.max()),
            "busy_p99": float(np.percentile(busy, 99)) if busy.size else float("nan"),
            "status": status}


def _busy_us(path: Path) -> np.ndarray:
    """``busy_s`` of every cycle from the log's ``/timing`` channel [us]."""
    from mcap.reader import make_reader

    out = []
    with open(path, "rb") as f:
        for _, _, m in make_reader(f).iter_messages(topics=["/timing"]):
            out.append(struct.unpack_from("<qddd", m.data, 4)[3])
    return np.array(out) * 1e6


def paced(seconds: float, out: Path, **daq: object) -> dict[str, float]:
    """One simulated 1 kHz paced payload run (drive, plant and master in this process)."""
    c = campaign(seconds, 0.001, 1, clock="paced", **daq)
    r = run_campaign(c, out_dir=out, simulate=default_plant(), yes=True)
    return _paced_stats(r.runs[0], r.status)


def _fifo(priority: int):
    """preexec_fn: SCHED_FIFO ``priority`` for a child (0: leave the policy)."""
    def apply() -> None:
        if priority:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    return apply


def c_loop_start(cycles: int, tmp: Path, priority: int = 0) -> subprocess.Popen | None:
    """Compile and start the C reference loop (it runs beside the Python paced run, so
    both see the same host stalls), under SCHED_FIFO ``priority`` when the Python run
    uses it."""
    gcc = shutil.which("gcc") or shutil.which("cc")
    if gcc is None:
        return None
    exe = tmp / "c_paced_loop"
    if not exe.exists():
        subprocess.run([gcc, "-O2", "-o", str(exe), str(HERE / "c_paced_loop.c")], check=True)
    return subprocess.Popen([str(exe), "1000", str(cycles)], stdout=subprocess.PIPE, text=True,
                            preexec_fn=_fifo(priority))


def fifo_allowed() -> bool:
    """Whether this process may use SCHED_FIFO (CAP_SYS_NICE or root)."""
    try:
        old = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        os.sched_setscheduler(0, old[0], old[1])
        return True
    except (PermissionError, OSError, AttributeError):
        return False


def miss_ratio(p: dict[str, float], c: dict[str, float]) -> float:
    """Python/C miss rate, +1 each (runs of slightly different lengths: compare rates)."""
    return ((p["missed"] + 1) / p["cycles"]) / ((c["missed"] + 1) / c["cycles"])


def paced_rows(seconds: float, tmp: Path, variants: list[tuple[str, dict]]
               ) -> list[tuple[str, str, str, str]]:
    """Each variant: a Python paced run and the C loop beside it (same scheduling policy),
    so the ratio compares the two under the same host load."""
    rows = []
    for k, (label, daq) in enumerate(variants):
        prio = int(daq.get("realtime_priority", 0))
        proc = c_loop_start(int(seconds * 1000), tmp, prio)
        p = paced(seconds, tmp / f"paced{k}", **daq)
        rows.append((f"paced 1 kHz, Python [{label}]", f"missed {p['missed']}/{p['cycles']}",
                     f"lateness p50 {p['p50']:.0f} / p99 {p['p99']:.0f} / max "
                     f"{p['max']:.0f} us", f"busy p99 {p['busy_p99']:.0f} us, run {p['status']}"))
        if proc is None:
            rows.append(("  C clock_nanosleep", "gcc not found", "", ""))
            continue
        cref = c_loop_result(proc)
        rows.append((f"  C clock_nanosleep [{label}]", f"missed {cref['missed']}/"
                     f"{cref['cycles']}", f"lateness p50 {cref['p50']:.0f} / p99 "
                     f"{cref['p99']:.0f} / max {cref['max']:.0f} us",
                     f"miss rate Python/C = {miss_ratio(p, cref):.2f} (+1 each)"))
    return rows


def cross_process(seconds: float, tmp: Path, sync_source: str, **daq: object
                  ) -> dict[str, float]:
    """A paced 1 kHz run with the drive in another process (``sim_drivers.serve`` behind a
    loopback python-can-remote bridge) and a third process recording the SYNC train
    (``sync_listener.py``); the C loop runs beside it."""
    from daq.runtime.simrig import plant_scaling
    from sim_drivers.remote import ServeProcess

    sc = plant_scaling(default_plant())
    prio = int(daq.get("realtime_priority", 0))
    with ServeProcess((1,), channel="bench_xproc", realtime_priority=prio) as served:
        npy = tmp / f"sync_{sync_source}.npy"
        lis = subprocess.Popen([sys.executable, str(HERE / "sync_listener.py"), served.url,
                                str(npy)], stdout=subprocess.PIPE, text=True,
                               preexec_fn=_fifo(prio))
        try:
            assert lis.stdout is not None and "listening" in lis.stdout.readline()
            c = campaign(seconds, 0.001, 1, clock="paced", interface="remote",
                         channel=served.url, sync_source=sync_source,
                         tpdo_timeout_cycles=1000, **daq,
                         drive_tables=[{"node_id": 1, "scaling": {
                             "rated_torque_Nm": sc.rated_torque_Nm,
                             "gear_ratio": sc.gear_ratio,
                             "encoder_counts_per_rev": sc.encoder_counts_per_rev}}])
            proc = c_loop_start(int(seconds * 1000), tmp, prio)
            r = run_campaign(c, out_dir=tmp / f"xproc_{sync_source}", prompt=lambda *a: True)
            cref = c_loop_result(proc) if proc is not None else None
            time.sleep(0.2)
        finally:
            lis.terminate()
            lis.wait(10)
    out = _paced_stats(r.runs[0], r.status) if r.runs else {"status": r.status}
    out["reason"] = r.reason
    ts = np.load(npy)
    period = np.diff(ts[:, 0]) * 1e6 if ts.shape[0] > 1 else np.zeros(1)
    arrival = np.diff(ts[:, 1]) * 1e6 if ts.shape[0] > 1 else np.zeros(1)
    out.update({
        "syncs": int(ts.shape[0]),
        "period_p50": float(np.percentile(period, 50)),
        "period_p1": float(np.percentile(period, 1)),
        "period_p99": float(np.percentile(period, 99)),
        "period_max": float(period.max()),
        "period_std": float(np.std(period[period < 5000])),
        "late_periods": int(np.sum(period > 1500)),
        "arrival_p99": float(np.percentile(arrival, 99)),
        "c": cref,
    })
    return out


def cross_process_rows(seconds: float, tmp: Path, variants: list[tuple[str, dict]]
                       ) -> list[tuple[str, str, str, str]]:
    rows = []
    for sync_source in ("runner", "periodic"):
        for label, daq in variants:
            x = cross_process(seconds, tmp, sync_source, **daq)
            tag = f"cross-process, SYNC {sync_source} [{label}]"
            if "cycles" not in x:
                rows.append((tag, f"run {x['status']}", "", ""))
                continue
            ratio = (f"miss rate Python/C = {miss_ratio(x, x['c']):.2f} (C missed "
                     f"{x['c']['missed']}/{x['c']['cycles']})" if x.get("c") else "")
            if x["status"] != "done":
                ratio += f"; run {x['status']}: {x['reason']}"
            rows.append((tag, f"missed {x['missed']}/{x['cycles']}",
                         f"lateness p50 {x['p50']:.0f} / p99 {x['p99']:.0f} / max "
                         f"{x['max']:.0f} us", ratio))
            rows.append(("  SYNC seen by a 3rd process", f"{x['syncs']} SYNCs",
                         f"period p1 {x['period_p1']:.0f} / p50 {x['period_p50']:.0f} / p99 "
                         f"{x['period_p99']:.0f} / max {x['period_max']:.0f} us",
                         f"std {x['period_std']:.0f} us, {x['late_periods']} periods > 1.5 ms,"
                         f" arrival p99 {x['arrival_p99']:.0f} us"))
    return rows


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
    """Delays [s] from the last heartbeat / SYNC / RPDO received to the drive's FAULT, and
    the configured timeouts [s]."""
    from daq.protocol.cia402 import State, path
    from daq.runtime.master import MasterHeartbeat, rpdo_timeout_ms
    from sim_drivers.testing import LockstepMaster, make_rig

    node = 9
    tpdos = {0x180 + node: ("<Hi", ("6041", "6064")), 0x280 + node: ("<hi", ("6077", "606C"))}
    out: dict[str, list[float]] = {"hb": [], "sync": [], "rpdo": [], "hb_cfg": [],
                                   "sync_cfg": [], "rpdo_cfg": []}

    def wait_fault(rig) -> None:
        end = time.monotonic() + 5.0
        while rig.drive.state is not State.FAULT and time.monotonic() < end:
            time.sleep(0.001)

    for kind in ("hb", "sync", "rpdo"):
        for _ in range(repeat):
            rig = make_rig(node_id=node)
            hb = MasterHeartbeat(rig.network.bus, 127, 100)
            try:
                if kind == "hb":
                    rig.node.sdo[0x1016][1].raw = (127 << 16) | 400
                    hb.start()
                elif kind == "sync":
                    rig.node.sdo[0x1006].raw = 1000
                else:  # RPDO1 event timer as the master writes it at 1 kHz paced
                    rig.node.sdo[0x1400][5].raw = rpdo_timeout_ms(0.001, paced=True)
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
                elif kind == "sync":
                    wait_fault(rig)
                    out["sync"].append(rig.drive.fault_time - rig.drive.last_sync_time)
                    out["sync_cfg"].append(rig.drive.sync_timeout_s)
                else:  # hung master, SYNC goes on from a periodic task
                    rig.network.sync.start(0.001)
                    try:
                        timer_s, _ = rig.drive.rpdo_timers[1]
                        wait_fault(rig)
                        last = rig.drive.rpdo_timers[1][1]
                    finally:
                        rig.network.sync.stop()
                    out["rpdo"].append(rig.drive.fault_time - last)
                    out["rpdo_cfg"].append(timer_s)
                m.close()
            finally:
                hb.stop()
                rig.close()
    return out


def safety_rows(repeat: int) -> list[tuple[str, str, str, str]]:
    ml = master_loss(repeat)
    rows = []
    for kind, label in (("hb", "master loss: heartbeat -> FAULT"),
                        ("sync", "master loss: SYNC -> FAULT"),
                        ("rpdo", "hung master, SYNC on: RPDO timer -> FAULT")):
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
    ap.add_argument("--only-paced", action="store_true",
                    help="only the paced rows: Python vs C in the same run, per variant "
                         "(default scheduling, and SCHED_FIFO when allowed)")
    ap.add_argument("--cross-process", action="store_true",
                    help="add paced runs with the drive in another process (loopback bridge) "
                         "and a third process timing the SYNC train")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_daq_"))
    # "before": automatic garbage collection and 1 s MCAP chunks (the defaults until
    # 2026-11); "after": the defaults now (gc frozen during a run, 0.1 s chunks)
    before = {"gc_freeze": False, "chunk_seconds": 1.0}
    variants: list[tuple[str, dict]] = [("before: gc on, 1 s chunks", before),
                                        ("after: gc frozen, 0.1 s chunks", {})]
    if fifo_allowed():
        fifo = {"realtime_priority": 10}
        variants += [("before, SCHED_FIFO 10", {**before, **fifo}),
                     ("after, SCHED_FIFO 10", fifo)]
    try:
        rows = []
        if args.only_paced:
            rows.extend(paced_rows(args.paced_seconds, tmp, variants))
        elif not args.cross_process or args.only_safety:
            rows = safety_rows(args.safety_repeat) if args.safety_repeat else []
            if not args.only_safety:
                rows.extend(speed_rows(args, tmp))
        if args.cross_process:
            rows.extend(cross_process_rows(args.paced_seconds, tmp, variants))
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
    rows.extend(paced_rows(args.paced_seconds, tmp, [("default", {})]))
    return rows


if __name__ == "__main__":
    sys.exit(main())
