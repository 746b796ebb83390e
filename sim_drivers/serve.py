"""Serve simulated CiA 402 drives on any python-can interface until interrupted.

``python -m sim_drivers.serve --interface socketcan --channel vcan0 --node-id 1 2``
puts one simulated joint per node ID on the bus (generic EDS and default plant unless
``--eds`` / ``--plant`` are given), so a master in another process (``jointid``, a real PLC,
``candump``) can talk to them. Each drive opens its own bus object.

Without a kernel CAN device (no vcan), ``--bridge-port`` makes the bus reachable from other
processes: ``python -m sim_drivers.serve --interface virtual --channel sim --bridge-port 0``
serves the drives on an in-process virtual bus and a python-can-remote bridge (WebSocket over
TCP, bound to 127.0.0.1 only, :mod:`sim_drivers.bridge`) on it; it prints
``bridge ws://127.0.0.1:<port>/<token>`` once listening, ``token`` random for each start, and
a master opens ``can.Bus(interface="remote", channel="ws://127.0.0.1:<port>/<token>")``
(campaign: ``[daq] interface = "remote"``, ``channel = "ws://127.0.0.1:<port>/<token>"``).
Without the token, from a browser page (``Origin`` header) or as plain HTTP, a connection is
refused. Each client gets its own bus object on the channel, so clients see each other's
frames and the drives'. The drives' warnings (heartbeat lost, SYNC lost, faults) go to stderr.
"""

from __future__ import annotations

import argparse
import logging
import signal
import threading
import types
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import can

from sim_drivers.bridge import Bridge
from sim_drivers.drive import TORQUE_DELAY_CYCLES, SimulatedDrive
from sim_drivers.plant import JointPlant
from sim_drivers.plant_config import load_plant

DEFAULT_PLANT = Path(__file__).with_name("data") / "plant_default.toml"


class Served:
    """Drives started by :func:`start_drives`; :meth:`close` stops them and shuts their buses."""

    def __init__(self, drives: list[SimulatedDrive], buses: list[can.BusABC]) -> None:
        self.drives = drives
        self.buses = buses

    def close(self) -> None:
        for drive in self.drives:
            drive.stop()
        for bus in self.buses:
            bus.shutdown()

    def __enter__(self) -> Served:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def local_periodic(bus: can.BusABC) -> None:
    """Send ``bus``'s periodic frames from a thread of this process (python-can's own
    thread-based task) instead of python-can-remote's server-side task.

    python-can-remote 0.3.0 runs ``send_periodic`` in the bridge process, and its
    ``modify_data`` is broken (``super(self)``): canopen's heartbeat producer modifies its
    task on every NMT state change, the bridge then gets a stop for a task it no longer has
    and drops the connection. A drive's heartbeat must also die with the drive's process,
    which a thread here does and a task in the bridge does not.
    """
    bus._send_periodic_internal = types.MethodType(  # type: ignore[method-assign]
        can.BusABC._send_periodic_internal, bus)


def start_drives(
    interface: str,
    channel: str,
    node_ids: Sequence[int],
    *,
    eds: str | Path | None = None,
    plant: str | Path | None = None,
    cycle_s: float = 0.001,
    q0: float = 0.0,
    bitrate: int | None = None,
    sync_loss_floor_s: float | None = None,
) -> Served:
    """Start one simulated drive per node ID on ``interface``/``channel``.

    Parameters
    ----------
    interface, channel : str
        python-can interface name and channel (``"virtual"``, ``"socketcan"``/``"vcan0"``...).
    node_ids : sequence of int
        CANopen node IDs, 1-127.
    eds, plant : path or None
        EDS/DCF and plant file (defaults: generic EDS, ``sim_drivers/data/plant_default.toml``).
    cycle_s : float
        SYNC period the plants are stepped with [s].
    q0 : float
        Initial joint position [rad] (or [m]).
    bitrate : int or None
        Passed to ``can.Bus`` when given.
    sync_loss_floor_s : float or None
        Shortest SYNC-loss timeout of the drives [s] (default: the drive's own).
    """
    params = load_plant(plant or DEFAULT_PLANT)
    drives: list[SimulatedDrive] = []
    buses: list[can.BusABC] = []
    kwargs = {} if bitrate is None else {"bitrate": bitrate}
    served = Served(drives, buses)
    try:
        for k, node_id in enumerate(node_ids):
            bus = can.Bus(interface=interface, channel=channel, **kwargs)
            buses.append(bus)
            if interface == "remote":
                local_periodic(bus)
            joint = JointPlant(params, cycle_s, seed=int(params.drive.seed) + k)
            joint.reset(q0)
            extra = {} if sync_loss_floor_s is None else {"sync_loss_floor_s": sync_loss_floor_s}
            drive = SimulatedDrive(bus, node_id, joint, eds, cycle_s=cycle_s, **extra)
            drive.start()
            drives.append(drive)
    except Exception:
        served.close()
        raise
    return served


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: serve drives until SIGINT/SIGTERM."""
    ap = argparse.ArgumentParser(prog="python -m sim_drivers.serve", description=__doc__)
    ap.add_argument("--interface", default="socketcan", help="python-can interface")
    ap.add_argument("--channel", default="vcan0", help="python-can channel")
    ap.add_argument("--node-id", type=int, nargs="*", default=[1],
                    help="node IDs 1-127 (none: serve only the --bridge-port bridge)")
    ap.add_argument("--eds", type=Path, help="EDS/DCF (default: generic jointid EDS)")
    ap.add_argument("--plant", type=Path, help="plant TOML (default: plant_default.toml)")
    ap.add_argument("--cycle", type=float, default=0.001, help="SYNC period [s]")
    ap.add_argument("--q0", type=float, default=0.0, help="initial joint position [rad]")
    ap.add_argument("--bitrate", type=int, help="bus bitrate [bit/s]")
    ap.add_argument("--sync-loss-floor", type=float, metavar="S",
                    help="shortest SYNC-loss timeout of the drives [s] (default 0.1)")
    ap.add_argument("--bridge-port", type=int, metavar="PORT",
                    help="also serve the bus to other processes over python-can-remote on "
                         "ws://127.0.0.1:PORT/TOKEN (0: any free port; the URL with its "
                         "random token is printed)")
    args = ap.parse_args(argv)
    if not args.node_id and args.bridge_port is None:
        ap.error("nothing to serve: give --node-id and/or --bridge-port")
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(name)s: %(message)s")
    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    with start_drives(
        args.interface, args.channel, args.node_id, eds=args.eds, plant=args.plant,
        cycle_s=args.cycle, q0=args.q0, bitrate=args.bitrate,
        sync_loss_floor_s=args.sync_loss_floor,
    ) as served:
        ids = ", ".join(str(d.node_id) for d in served.drives) or "none"
        print(f"serving node(s) {ids} on {args.interface}:{args.channel}; Ctrl-C stops",
              flush=True)
        # the master cannot tell simulated drives from real ones: say their log timing
        print(f"torque timing of these drives: {TORQUE_DELAY_CYCLES} cycles (campaign: [daq] "
              f"torque_delay_cycles = {TORQUE_DELAY_CYCLES}, docs/log-format.md)", flush=True)
        bridge = None
        if args.bridge_port is not None:
            bridge = start_bridge(args.interface, args.channel, args.bridge_port,
                                  bitrate=args.bitrate)
            print(f"bridge {bridge.url}", flush=True)
        try:
            done.wait()
        finally:
            if bridge is not None:
                bridge.close()
    return 0


def start_bridge(interface: str, channel: str, port: int, *,
                 bitrate: int | None = None, token: str | None = None) -> Bridge:
    """A python-can-remote bridge on 127.0.0.1:``port`` to ``interface``/``channel``
    (:class:`sim_drivers.bridge.Bridge`: token in the URL, no browser, no files).

    Each WebSocket client gets its own python-can bus on the channel (opened in this
    process), so on the virtual interface the clients and the drives share one bus. Runs
    in a daemon thread; stop it with ``close()``.

    Returns
    -------
    sim_drivers.bridge.Bridge
        ``url`` is what clients open (``ws://127.0.0.1:<port>/<token>``); ``server_port``
        the port listened on (useful with ``port=0``).
    """
    config: dict[str, Any] = {"interface": interface, "channel": channel}
    if bitrate is not None:
        config["bitrate"] = bitrate
    return Bridge(port, token=token, **config).start()


if __name__ == "__main__":
    raise SystemExit(main())
