"""Lockstep SYNC cycles per second of the simulated drive + plant (no logging, no controller).

Masters compared, each on python-can's virtual bus with the drive on its own bus object:

- ``step``      : ``SimulatedDrive.step()`` called directly (plant + drive logic + TPDO
                  packing/sending with nobody listening): the drive's own cost per cycle.
                  The canopen master that configured the drive leaves the bus first (also
                  for ``raw``), so no other receiver copies frames.
- ``raw``       : raw python-can master: send RPDO + SYNC, ``bus.recv()`` the two TPDOs.
- ``canopen``   : canopen ``Network`` master, struct-packed PDOs, TPDOs through a
                  callback-fed queue (``sim_drivers.testing.LockstepMaster``, as ``daq`` does).
- ``remotenode``: canopen ``RemoteNode`` PDO objects (per-variable encode/decode,
                  ``PdoMap.transmit``, ``network.sync.transmit``), TPDO callback -> queue.

Each configuration runs in a fresh subprocess, unpinned and pinned to one core with
``os.sched_setaffinity(0, {cpu})`` before any thread starts. Medians over repetitions;
"x RT" is the ratio to real time at 1 kHz (cycles/s / 1000).

Usage: ``python benchmarks/bench_drive.py [--cycles 5000] [--reps 5]``
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import statistics
import struct
import subprocess
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

NODE = 1
MODES = ("step", "raw", "canopen", "remotenode")


def _child(mode: str, pin: bool, cycles: int, reps: int) -> list[float]:
    if pin:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    import can
    import numpy as np

    from sim_drivers.testing import LockstepMaster, make_rig

    rates = []
    for _ in range(reps):
        rig = make_rig(node_id=NODE)
        node = rig.node
        node.sdo[0x6060].raw = 10
        for cw in (6, 7, 15):
            node.sdo[0x6040].raw = cw
        node.nmt.state = "OPERATIONAL"
        node.sdo[0x1000].raw  # noqa: B018 - barrier
        x = (420 + 300 * np.sin(np.arange(cycles) / 200.0)).astype(np.int64)
        if mode in ("step", "raw"):
            rig.network.disconnect()  # configured: the SDO master leaves the bus
        if mode == "step":
            drive = rig.drive
            t0 = time.perf_counter()
            for v in x.tolist():
                drive.target_torque = v
                drive.step()
            dt = time.perf_counter() - t0
        elif mode == "raw":
            bus = can.Bus(interface="virtual", channel=rig.channel)
            rpdo = struct.Struct("<Hh")
            sync = can.Message(arbitration_id=0x80, data=b"", is_extended_id=False)
            t0 = time.perf_counter()
            for v in x.tolist():
                bus.send(
                    can.Message(arbitration_id=0x200 + NODE, data=rpdo.pack(15, v),
                                is_extended_id=False)
                )
                bus.send(sync)
                got = 0
                while got < 2:
                    msg = bus.recv(2.0)
                    if msg is None:
                        raise TimeoutError("TPDO lost")
                    if msg.arbitration_id in (0x180 + NODE, 0x280 + NODE):
                        got += 1
            dt = time.perf_counter() - t0
            bus.shutdown()
        elif mode == "canopen":
            master = LockstepMaster(
                rig.network, 0x200 + NODE, "<Hh",
                {0x180 + NODE: ("<Hi", ("6041", "6064")), 0x280 + NODE: ("<hi", ("6077", "606C"))},
            )
            t0 = time.perf_counter()
            master.run(15, x)
            dt = time.perf_counter() - t0 - 0.05  # run() ends with a 50 ms duplicate check
            master.close()
        else:
            node.rpdo.read()
            node.tpdo.read()
            q: queue.SimpleQueue = queue.SimpleQueue()
            values = {}

            def on_tpdo(m, q=q, values=values):
                for var in m:
                    values[var.index] = var.raw
                q.put(m.cob_id)

            node.tpdo[1].add_callback(on_tpdo)
            node.tpdo[2].add_callback(on_tpdo)
            rp = node.rpdo[1]
            cw, tt = rp["Controlword"], rp["Target torque"]
            cw.raw = 15
            t0 = time.perf_counter()
            for v in x.tolist():
                tt.raw = v
                rp.transmit()
                rig.network.sync.transmit()
                q.get(timeout=2)
                q.get(timeout=2)
            dt = time.perf_counter() - t0
        assert rig.drive.cycle == cycles, (mode, rig.drive.cycle)
        rig.close()
        rates.append(cycles / dt)
    return rates


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=5000)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--child", nargs=2, metavar=("MODE", "PIN"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        rates = _child(args.child[0], args.child[1] == "1", args.cycles, args.reps)
        print(json.dumps(rates))
        return
    print(f"lockstep SYNC cycles, drive + plant (generic EDS, CST), {args.cycles} cycles x "
          f"{args.reps} reps, medians; host: {os.cpu_count()} CPUs")
    print(f"{'master':<11} {'pinned':<7} {'cycles/s':>10} {'us/cycle':>9} {'x RT@1kHz':>10} "
          f"{'min..max cycles/s':>20}")
    results = {}
    for mode in MODES:
        for pin in (False, True):
            out = subprocess.run(
                [sys.executable, __file__, "--cycles", str(args.cycles), "--reps",
                 str(args.reps), "--child", mode, "1" if pin else "0"],
                check=True, capture_output=True, text=True,
            )
            rates = json.loads(out.stdout.strip().splitlines()[-1])
            med = statistics.median(rates)
            results[(mode, pin)] = med
            print(f"{mode:<11} {'yes' if pin else 'no':<7} {med:>10.0f} {1e6 / med:>9.1f} "
                  f"{med / 1000:>10.1f} {min(rates):>9.0f}..{max(rates):<9.0f}")
    print("ratios (pinned / unpinned): " + ", ".join(
        f"{m} {results[(m, True)] / results[(m, False)]:.2f}" for m in MODES))
    print("ratios vs step (pinned): " + ", ".join(
        f"{m} {results[(m, True)] / results[('step', True)]:.2f}" for m in MODES[1:]))


if __name__ == "__main__":
    main()
