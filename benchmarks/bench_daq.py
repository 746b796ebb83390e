"""DAQ benchmarks: lockstep rate (1, 3, 6 drives), paced 1 kHz jitter vs a C loop, MCAP writes.

(Past 600 lines: one table whose row groups share the campaign builder, the rigs and the
printing; ratios are only meaningful within one run of one script.)

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_daq.py [--paced-seconds 60] [--repeat 3]

Prints one table. Everything runs through the full stack: campaign -> plan -> runner ->
canopen master -> python-can virtual bus -> simulated CiA 402 drive + plant -> MCAP.

- lockstep cycles/s for 1, 3 and 6 simulated drives (``--drives``): wall-clock rate of a
  whole payload run (median over ``--repeat``), its ratio to real time at 1 kHz, the rate
  relative to 1 drive (linear scaling: n drives at >= 1/n of the 1-drive rate), and one
  cycle's wall time in units of the raw python-can virtual-bus round trip measured in the
  same run (``raw_bus.py``: one frame out, one back, two threads, pinned like the runner).
  One bus carries at most one drive at 1 kHz within ``max_bus_load`` 0.6 (``daq.runtime.busload``):
  the n-drive rows on one bus run a plan of ``n`` ms cycles (the lockstep rate does not
  depend on the simulated cycle), and the "6 buses" row is the 6-axis arm at 1 kHz, one
  drive per bus. CPU per cycle is the process time of the whole campaign (start-up
  included) per cycle: the stable figure on a shared machine; ``1e6 / CPU`` is the rate
  one free core would give (the lockstep run is one thread: the simulated drives run inline in
  the master's ``send``).
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
import contextlib
import itertools
import math
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

import can  # noqa: E402
import numpy as np  # noqa: E402

from daq.protocol.logformat import FRAME  # noqa: E402
from daq.runtime.mcaplog import RunLog  # noqa: E402
from daq.runtime.runner import run_campaign  # noqa: E402
from sim_drivers.plant_config import default_plant  # noqa: E402
from trajectories.robot_campaign import RobotCampaign  # noqa: E402

HERE = Path(__file__).resolve().parent
_chan = itertools.count()


def campaign(seconds: float, cycle_s: float = 0.001, drives: int = 1,
             clock: str = "lockstep", buses: int = 1, drive_tables: list | None = None,
             **daq: object) -> RobotCampaign:
    periods = max(1, int(round(seconds * 0.25)))
    chan = f"bench_{next(_chan)}"
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
        "daq": {"channel": chan, "clock": clock,
                "drives": drive_tables or [
                    {"node_id": n, "channel": chan if buses == 1
                     else f"{chan}_{(n - 1) % buses}"} for n in range(1, drives + 1)],
                "heartbeat_timeout_s": 2.0, "tpdo_timeout_cycles": 1000,
                "max_following_error": 1.0, **daq},
    }
    return RobotCampaign.from_dict(raw, "bench.toml")


def lockstep(drives: int, cycles: int, repeat: int, out: Path, buses: int = 1
             ) -> tuple[float, float, int]:
    """Median wall cycles/s, median CPU µs/cycle, cycles per run: ``drives`` simulated drives
    spread over ``buses`` buses, a plan of about ``cycles`` cycles whose cycle time fits the
    bus budget (1 ms per drive on the busiest bus)."""
    cycle_s = 0.001 * -(-drives // buses)
    c = campaign(cycles * cycle_s, cycle_s, drives, buses=buses)
    rates, cpus, n = [], [], 0
    for _ in range(repeat):
        c0 = time.process_time()
        r = run_campaign(c, out_dir=out, simulate=default_plant(), yes=True, overwrite=True)
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
    r = run_campaign(c, out_dir=out, simulate=default_plant(), yes=True, overwrite=True)
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
            r = run_campaign(c, out_dir=tmp / f"xproc_{sync_source}", prompt=lambda *a: True,
                             overwrite=True)
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
    ap.add_argument("--lockstep-cycles", type=int, default=10000,
                    help="cycles of plan per lockstep run")
    ap.add_argument("--drives", default="1,3,6", help="drive counts of the lockstep rows")
    ap.add_argument("--arm-cycles", type=int, default=3000,
                    help="cycles of the 6-axis arm-on-the-bus rows (0: skip)")
    ap.add_argument("--before", action="store_true",
                    help="add the lockstep rows of the rig before issue 12 (same run)")
    ap.add_argument("--only-lockstep", action="store_true",
                    help="only the lockstep rows (and their raw round-trip reference)")
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
        if args.only_lockstep:
            rows = lockstep_rows(args, tmp)
        elif args.only_paced:
            rows.extend(paced_rows(args.paced_seconds, tmp, variants))
        elif not args.cross_process or args.only_safety:
            rows = safety_rows(args.safety_repeat) if args.safety_repeat else []
            if not args.only_safety:
                rows.extend(speed_rows(args, tmp))
        if args.cross_process and not args.only_lockstep:
            rows.extend(cross_process_rows(args.paced_seconds, tmp, variants))
        w = [max(len(r[i]) for r in rows) for i in range(4)]
        print(f"bench_daq  (python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load "
              f"{os.getloadavg()[0]:.1f})")
        for r in rows:
            print("  ".join(x.ljust(w[i]) for i, x in enumerate(r)).rstrip())
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


@contextlib.contextmanager
def before_rig():
    """The ``--simulate`` rig as it was before issue 12 (for the "before" rows, same run):
    one python-can VirtualBus and canopen network per simulated drive, the master on its own
    VirtualBus; every frame deep-copied to every other bus object and waking its thread."""
    import can

    from daq.runtime import runner
    from sim_drivers.drive import TORQUE_DELAY_CYCLES, SimulatedDrive
    from sim_drivers.plant import JointPlant

    class Rig:
        torque_delay_cycles = TORQUE_DELAY_CYCLES

        def __init__(self) -> None:
            self.drives: list = []
            self.buses: list = []

        def set_payload(self, payload) -> None:
            for d in self.drives:
                d.set_payload(payload.mass_kg, payload.arm_m)

        def close(self) -> None:
            for d in self.drives:
                d.stop()
            for b in self.buses:
                b.shutdown()

    def start_sim(cfg, plant_params, campaign, fault_injectors):
        rig = Rig()
        for k, dcfg in enumerate(cfg.drives):
            bus = can.Bus(interface="virtual", channel=cfg.channel)
            rig.buses.append(bus)
            plant = JointPlant(plant_params, campaign.cycle_s,
                               seed=int(plant_params.drive.seed) + k)
            plant.reset(campaign.start[0])
            drive = SimulatedDrive(bus, dcfg.node_id, plant, dcfg.eds, cycle_s=campaign.cycle_s)
            drive.start()
            rig.drives.append(drive)
        return rig

    saved = runner.start_sim, runner.open_buses
    runner.start_sim = start_sim
    runner.open_buses = lambda cfg, simulated=False: can.Bus(interface="virtual",
                                                             channel=cfg.channel)
    try:
        yield
    finally:
        runner.start_sim, runner.open_buses = saved


def arm_rate(k: int, cycles: int, substeps: int) -> tuple[float, float]:
    """Lockstep cycles/s of a k-dof UR10 on the bus (``sim_drivers.arm_bus.ArmOnBus``: one
    ArmPlant behind k simulated drives) under a minimal struct-packing master on a queued
    SimBus (the runner plans one joint only; a PD loop swings every joint by 0.2 rad at
    0.5 Hz), and the share of the wall time spent in ``ArmPlant.step``."""
    import struct

    import canopen

    from sim_drivers.arm import ArmParams
    from sim_drivers.arm_bus import ArmOnBus
    from sim_drivers.robots import ur10
    from sim_drivers.simbus import SimBus

    params = ArmParams.from_model(ur10(k))
    ch = f"bench_arm_{next(_chan)}"
    nodes = list(range(1, k + 1))
    q0 = [0.1] * k
    arm = ArmOnBus(params, ch, nodes, cycle_s=0.001, q0=q0, substeps=substeps)
    bus = SimBus(ch, dispatch="thread")
    plant_s = [0.0]
    step = arm.plant.step

    def timed_step(tau):
        t0 = time.perf_counter()
        step(tau)
        plant_s[0] += time.perf_counter() - t0

    arm.plant.step = timed_step
    try:
        master = canopen.Network(bus)  # start-up over SDO/NMT, then the raw loop
        master.connect()
        for d in arm.drives:
            node = master.add_node(d.node_id, str(d.dod.path))
            node.sdo[0x6060].raw = 10
            for cw in (6, 7, 15):
                node.sdo[0x6040].raw = cw
        master.nmt.state = "OPERATIONAL"
        node.sdo[0x1000].raw  # noqa: B018 - barrier: NMT start processed
        master.notifier.stop(1.0)
        while bus.recv(0.0) is not None:  # heartbeats and the like: not this loop's business
            pass
        cpr = params.drive.counts_per_rad.tolist()
        tpu = params.drive.torque_per_permille.tolist()
        rx, tx = struct.Struct("<Hh"), struct.Struct("<Hi")  # generic EDS defaults
        slot = {0x180 + n: i for i, n in enumerate(nodes)}
        counts = [round(q * c) for q, c in zip(q0, cpr, strict=True)]
        prev = list(q0)
        # PD at 10 Hz on each joint's inertia, within the drives' torque limit 0x6072
        m_jj = [float(arm.drives[i].plant.params.J) for i in range(k)]
        w = 2 * np.pi * 10.0
        kp, kd = [m * w * w for m in m_jj], [2 * m * w for m in m_jj]
        xmax = [d.max_torque for d in arm.drives]
        sync = can.Message(arbitration_id=0x80, data=b"", is_extended_id=False)
        msgs = [can.Message(arbitration_id=0x200 + n, data=bytes(4), is_extended_id=False)
                for n in nodes]
        t0 = time.perf_counter()
        for c in range(cycles):
            ref = 0.2 * math.sin(math.pi * c * 0.001)  # every joint swings, 0.5 Hz [rad]
            for i in range(k):
                q = counts[i] / cpr[i]
                tau = kp[i] * (q0[i] + ref - q) - kd[i] * (q - prev[i]) / 0.001  # PD [N m]
                prev[i] = q
                x = max(-xmax[i], min(xmax[i], round(tau / tpu[i])))
                msgs[i].data = rx.pack(15, x)
                bus.send(msgs[i])
            bus.send(sync)
            got = 0
            while got < 2 * k:
                m = bus.recv(1.0)
                if m is None:
                    raise TimeoutError("arm on the bus: TPDO missing")
                if m.arbitration_id & 0x780 in (0x180, 0x280):
                    got += 1
                    i = slot.get(m.arbitration_id)
                    if i is not None:
                        counts[i] = tx.unpack_from(m.data)[1]
        wall = time.perf_counter() - t0
    finally:
        bus.shutdown()
        arm.close()
    return cycles / wall, plant_s[0] / wall


def lockstep_rows(args: argparse.Namespace, tmp: Path
                  ) -> list[tuple[str, str, str, str]]:
    """The raw round trip, then one row per drive count (and the 6-axis arm on 6 buses)."""
    from raw_bus import round_trip_us

    rtt = round_trip_us(20000, pin=True)
    rows = [("raw python-can virtual round trip", f"{rtt:.1f} us",
             f"{1e6 / rtt:,.0f} round trips/s", "2 threads, pinned to one CPU like the runner")]
    counts = [int(x) for x in args.drives.split(",")]
    cases = [(n, 1, False) for n in counts] + ([(6, 6, False)] if 6 in counts else [])
    if args.before:
        cases += [(n, 1, True) for n in counts]
    r1 = {}
    for n, buses, before in cases:
        if before:
            with before_rig():
                rate, cpu, cycles = lockstep(n, args.lockstep_cycles, args.repeat,
                                             tmp / f"b{n}", buses)
        else:
            rate, cpu, cycles = lockstep(n, args.lockstep_cycles, args.repeat,
                                         tmp / f"l{n}_{buses}", buses)
        if n == 1:
            r1[before] = rate
        ref = r1.get(before)
        rel = f"{rate / ref:.3f}x the 1-drive rate (1/{n} = {1 / n:.3f})" if ref and n > 1 else ""
        where = (f"{buses} buses, 1 ms plan" if buses > 1
                 else f"1 bus, {-(-n // buses)} ms plan")
        label = "BEFORE (a virtual bus per drive)" if before else "lockstep"
        rows.append((f"{label}, {n} drive{'s' if n > 1 else ''} ({where})",
                     f"{rate:,.0f} cycles/s", f"{rate / 1000:.2f}x real time at 1 kHz",
                     f"cycle = {1e6 / rate / rtt:.2f} raw round trips; {rel}"
                     f"{'; ' if rel else ''}CPU {cpu:.0f} us/cycle (= {1000 / cpu:.1f}x "
                     f"real time on a free core), {cycles} cycles"))
    if args.arm_cycles:
        for sub in (10, 1):
            rate, share = arm_rate(6, args.arm_cycles, sub)
            rows.append((f"6-axis UR10 arm on the bus (ArmOnBus, {sub} substeps)",
                         f"{rate:,.0f} cycles/s", f"{rate / 1000:.2f}x real time at 1 kHz",
                         f"ArmPlant.step {100 * share:.0f} % of the wall time; minimal "
                         f"struct master (the runner plans one joint)"))
    return rows


def speed_rows(args: argparse.Namespace, tmp: Path) -> list[tuple[str, str, str, str]]:
    rows = lockstep_rows(args, tmp)
    cpu1 = float(rows[1][3].split("CPU ")[1].split(" ")[0])
    msg_s, log_us = mcap_rate(100_000, tmp)
    rows.append(("MCAP write (state+setpoint+CAN)", f"{msg_s:,.0f} msg/s",
                 f"{log_us:.1f} us/cycle",
                 f"{100 * log_us / cpu1:.0f} % of the 1-drive all-in CPU cycle"))
    # the plan of a paced run: ~args.paced_seconds of cycles + enable/approach/settle
    rows.extend(paced_rows(args.paced_seconds, tmp, [("default", {})]))
    return rows


if __name__ == "__main__":
    sys.exit(main())
