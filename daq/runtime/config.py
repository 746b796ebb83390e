"""The ``[daq]`` table of a campaign: bus, drives, scaling, watchdog (validated, frozen).

Format (every key optional; absent: python-can's virtual bus, one drive, node 1, on the
project's generic EDS, cyclic synchronous torque)::

    [daq]
    interface = "socketcan"       # any python-can interface: virtual, socketcan, pcan, kvaser...
                                  # or "config": python-can's own configuration (~/.canrc,
                                  # CAN_INTERFACE / CAN_CHANNEL / CAN_BITRATE environment)
    channel = "can0"
    bitrate = 1000000             # [bit/s]
    max_bus_load = 0.6            # refuse cyclic traffic above this share of the bit rate
    clock = "paced"               # "lockstep" (virtual bus + simulated drives) or "paced"
    sync_source = "runner"        # paced: "runner" (the runner's own timed loop sends SYNC)
                                  # or "periodic" (python-can send_periodic: the kernel's
                                  # broadcast manager on socketcan, a thread elsewhere)
    realtime_priority = 0         # paced: SCHED_FIFO priority 1-99 (needs CAP_SYS_NICE); 0 off
    tpdo_timeout_cycles = 3       # watchdog: TPDOs missing for k consecutive cycles -> stop
    heartbeat_timeout_s = 0.5     # watchdog: no heartbeat for this long [s] -> stop
    max_following_error = 0.2     # watchdog: |q_ref - q| above this [rad] or [m] -> stop
    quick_stop_cycles = 2         # cycles of quick stop before disable voltage
    lockstep_wait_s = 0.5         # lockstep: wall time to wait for the TPDOs of one cycle [s]
    chunk_seconds = 1.0           # MCAP chunk length [s of data] (lost at most on SIGKILL)
    cpu = -1                      # pin the process to this CPU (-1: the last allowed one;
                                  # -2: do not pin)
    master_node_id = 127          # node id of the master's own heartbeat (0x700 + id)
    master_heartbeat_ms = 100     # master heartbeat period [ms] (0: none, drives not told);
                                  # each drive with 0x1016 watches it with a consumer time
                                  # of 3 x period + 100 ms and stops (fault) when it is lost
    [daq.limits]                  # optional, tighter than the campaign's joint.limits
    position = [-1.0, 1.0]
    max_velocity = 1.0
    max_torque = 500.0
    [[daq.drives]]
    node_id = 1
    eds = "drives/epos4.eds"      # relative to the campaign file; default: generic EDS
    mode = "cst"                  # or "csp"
    heartbeat_ms = 100            # heartbeat producer time written to 0x1017 [ms]
    [daq.drives.scaling]          # where the EDS/drive lacks it (ignored with --simulate)
    rated_torque_Nm = 5.0         # motor rated torque [N m] (0x6076 is in mN m)
    rated_current_A = 10.0
    gear_ratio = 100.0
    encoder_counts_per_rev = 4096 # per motor revolution
    drive_gain = 0.5              # joint-side torque per per-mille of 0x6071 [N m/permille]:
                                  # g_f of the paper's eq. 4 per unit of target torque;
                                  # overrides gear_ratio * rated_torque_Nm / 1000 for torque
                                  # (then rated_torque_Nm may be left out)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from daq import ConfigError
from daq.protocol.cia402 import Mode
from trajectories import SchemaError
from trajectories.schema import ArrayOfTables, Field, Table

MODES = {"cst": Mode.CYCLIC_SYNC_TORQUE, "csp": Mode.CYCLIC_SYNC_POSITION}


@dataclass(frozen=True)
class Scaling:
    """Drive chain scaling between bus units and joint-side SI units.

    Attributes
    ----------
    rated_torque_Nm : float
        Motor rated torque [N m] (0x6076 / 1000); 0x6071/0x6077 are per mille of it.
    gear_ratio : float
        N (motor turns per joint turn).
    encoder_counts_per_rev : int
        Encoder counts per motor revolution.
    rated_current_A : float
        Motor rated current [A] (0x6075 / 1000), informative.
    drive_gain : float or None
        Joint-side torque per per-mille unit of 0x6071/0x6077 [N m/permille], i.e. the drive
        gain g_f of the paper (eq. 4, tau = g_f v_f) for v_f in units of 0x6071. When set it
        replaces ``gear_ratio * rated_torque_Nm / 1000`` (:attr:`torque_per_unit`); the
        position scaling still uses ``gear_ratio`` and ``encoder_counts_per_rev``.
    """

    rated_torque_Nm: float
    gear_ratio: float
    encoder_counts_per_rev: int
    rated_current_A: float = float("nan")
    drive_gain: float | None = None

    @property
    def torque_per_unit(self) -> float:
        """Joint-side torque of one per-mille unit of 0x6071/0x6077 [N m]: ``drive_gain``
        when given, else ``gear_ratio * rated_torque_Nm / 1000``."""
        if self.drive_gain is not None:
            return self.drive_gain
        return self.gear_ratio * self.rated_torque_Nm / 1000.0

    @property
    def rad_per_count(self) -> float:
        """Joint position per encoder count [rad/count]: 2 pi / (counts_per_rev N)."""
        return 2.0 * math.pi / (self.encoder_counts_per_rev * self.gear_ratio)

    def as_dict(self) -> dict[str, str]:
        return {
            "rated_torque_Nm": repr(self.rated_torque_Nm),
            "gear_ratio": repr(self.gear_ratio),
            "encoder_counts_per_rev": str(self.encoder_counts_per_rev),
            "rated_current_A": repr(self.rated_current_A),
            "drive_gain_Nm_per_permille": ("" if self.drive_gain is None
                                           else repr(self.drive_gain)),
            "torque_per_unit_Nm": repr(self.torque_per_unit),
            "torque_source": "drive_gain" if self.drive_gain is not None else "rated_torque",
        }


@dataclass(frozen=True)
class DriveConfig:
    """One drive on the bus.

    Attributes
    ----------
    node_id : int
        CANopen node id 1..127.
    eds : Path
        EDS/DCF describing the drive.
    mode : Mode
        ``CYCLIC_SYNC_TORQUE`` (default) or ``CYCLIC_SYNC_POSITION``.
    heartbeat_ms : int
        Heartbeat producer time written to 0x1017 [ms] (0: leave the drive's setting).
    scaling : Scaling or None
        From the campaign, the plant (``--simulate``) or, when None, read from the drive.
    """

    node_id: int
    eds: Path
    mode: Mode
    heartbeat_ms: int
    scaling: Scaling | None

    @property
    def mode_name(self) -> str:
        return "cst" if self.mode is Mode.CYCLIC_SYNC_TORQUE else "csp"


@dataclass(frozen=True)
class DaqConfig:
    """The validated ``[daq]`` table (see the module docstring for meanings and units)."""

    interface: str
    channel: str
    bitrate: int
    max_bus_load: float
    clock: str
    sync_source: str
    realtime_priority: int
    drives: tuple[DriveConfig, ...]
    tpdo_timeout_cycles: int
    heartbeat_timeout_s: float
    max_following_error: float
    quick_stop_cycles: int
    lockstep_wait_s: float
    chunk_seconds: float
    cpu: int
    position_limits: tuple[float, float] | None
    max_velocity: float | None
    max_torque: float | None
    source: str = ""
    master_node_id: int = 127
    master_heartbeat_ms: int = 100

    @property
    def heartbeat_consumer_ms(self) -> int:
        """Consumer time written to the drives' 0x1016 [ms]: 3 producer periods + 100 ms
        (0 when the master sends no heartbeat)."""
        if not self.master_heartbeat_ms:
            return 0
        return min(0xFFFF, 3 * self.master_heartbeat_ms + 100)

    @property
    def virtual(self) -> bool:
        return self.interface == "virtual"


_SCALING = Table(
    {
        "rated_torque_Nm": Field(float, gt=0, required=False, default=float("nan"),
                                 unit="N m"),
        "gear_ratio": Field(float, gt=0, required=False, default=1.0),
        "encoder_counts_per_rev": Field(int, gt=0, unit="counts"),
        "rated_current_A": Field(float, gt=0, required=False, default=float("nan"), unit="A"),
        "drive_gain": Field(float, gt=0, required=False, default=None, unit="N m/permille"),
    },
    required=False,
)

_DRIVE = Table(
    {
        "node_id": Field(int, ge=1, le=127),
        "eds": Field(str, required=False, default=""),
        "mode": Field(str, required=False, default="cst", choices=tuple(MODES)),
        "heartbeat_ms": Field(int, required=False, default=100, ge=0, le=65535, unit="ms"),
        "scaling": _SCALING,
    }
)

_LIMITS = Table(
    {
        "position": Field(float, list_of=True, min_len=2, required=False, unit="rad"),
        "max_velocity": Field(float, gt=0, required=False, unit="rad/s"),
        "max_torque": Field(float, gt=0, required=False, unit="N m"),
    },
    required=False,
)

_DAQ = Table(
    {
        "interface": Field(str, required=False, default="virtual"),
        "channel": Field(str, required=False, default="jointid"),
        "bitrate": Field(int, required=False, default=1_000_000, gt=0, le=1_000_000,
                         unit="bit/s"),
        "max_bus_load": Field(float, required=False, default=0.6, gt=0, le=1),
        "clock": Field(str, required=False, default="", choices=("lockstep", "paced", "")),
        "sync_source": Field(str, required=False, default="runner",
                             choices=("runner", "periodic")),
        "realtime_priority": Field(int, required=False, default=0, ge=0, le=99),
        "drives": ArrayOfTables(_DRIVE, required=False),
        "tpdo_timeout_cycles": Field(int, required=False, default=3, ge=1, unit="cycles"),
        "heartbeat_timeout_s": Field(float, required=False, default=0.5, gt=0, unit="s"),
        "max_following_error": Field(float, required=False, default=0.2, gt=0, unit="rad"),
        "quick_stop_cycles": Field(int, required=False, default=2, ge=1, le=1000),
        "lockstep_wait_s": Field(float, required=False, default=0.5, gt=0, unit="s"),
        "chunk_seconds": Field(float, required=False, default=1.0, gt=0, unit="s"),
        "cpu": Field(int, required=False, default=-1, ge=-2),
        "master_node_id": Field(int, required=False, default=127, ge=1, le=127),
        "master_heartbeat_ms": Field(int, required=False, default=100, ge=0, le=20000,
                                     unit="ms"),
        "limits": _LIMITS,
    }
)


def generic_eds() -> Path:
    """The project's generic EDS of the simulated drive."""
    from importlib import resources

    return Path(str(resources.files("sim_drivers.data").joinpath("jointid_cia402.eds")))


def parse_daq(raw: Mapping[str, Any] | None, source: str = "") -> DaqConfig:
    """Validate a raw ``[daq]`` table.

    Parameters
    ----------
    raw : mapping or None
        ``Campaign.daq`` (``{}`` or None when the campaign has no ``[daq]``).
    source : str
        The campaign file name: used in messages and to resolve relative EDS paths.

    Raises
    ------
    daq.ConfigError
        One line naming the file, the dotted key and what was expected.
    """
    try:
        d = _DAQ.validate(dict(raw or {}), "daq", source)
    except SchemaError as exc:
        raise ConfigError(str(exc)) from None
    base = Path(source).parent if source else Path.cwd()
    drives_raw = d["drives"] or ({"node_id": 1, "eds": "", "mode": "cst", "heartbeat_ms": 100,
                                  "scaling": None},)
    drives = []
    seen: set[int] = set()
    for i, dr in enumerate(drives_raw):
        key = f"daq.drives[{i}]"
        if dr["node_id"] in seen:
            raise ConfigError(f"{source}: {key}.node_id: expected a unique node id, got "
                              f"{dr['node_id']} twice")
        seen.add(dr["node_id"])
        eds = Path(dr["eds"]) if dr["eds"] else generic_eds()
        if dr["eds"] and not eds.is_absolute():
            eds = base / eds
        if not eds.is_file():
            raise ConfigError(f"{source}: {key}.eds: expected an EDS/DCF file, {eds} not found")
        if dr["node_id"] == d["master_node_id"] and d["master_heartbeat_ms"]:
            raise ConfigError(f"{source}: {key}.node_id: expected a node id other than "
                              f"daq.master_node_id ({d['master_node_id']}), got "
                              f"{dr['node_id']}")
        sc = dr.get("scaling")
        if sc and sc.get("drive_gain") is None and not sc["rated_torque_Nm"] > 0:
            raise ConfigError(f"{source}: {key}.scaling: expected rated_torque_Nm [N m] or "
                              f"drive_gain [N m/permille], got neither")
        scaling = Scaling(**sc) if sc else None
        drives.append(DriveConfig(dr["node_id"], eds, MODES[dr["mode"]], dr["heartbeat_ms"],
                                  scaling))
    lim = d["limits"] or {}
    pos = lim.get("position")
    if pos is not None and (len(pos) != 2 or not pos[0] < pos[1]):
        raise ConfigError(f"{source}: daq.limits.position: expected [min, max] with min < max, "
                          f"got {list(pos)}")
    clock = d["clock"] or ("lockstep" if d["interface"] == "virtual" else "paced")
    if clock == "lockstep" and d["interface"] not in ("virtual", "config"):
        raise ConfigError(f"{source}: daq.clock: expected 'paced' on a real interface "
                          f"({d['interface']!r}), got 'lockstep'")
    return DaqConfig(
        interface=d["interface"],
        channel=d["channel"],
        bitrate=d["bitrate"],
        max_bus_load=d["max_bus_load"],
        clock=clock,
        sync_source=d["sync_source"],
        realtime_priority=d["realtime_priority"],
        drives=tuple(drives),
        tpdo_timeout_cycles=d["tpdo_timeout_cycles"],
        heartbeat_timeout_s=d["heartbeat_timeout_s"],
        max_following_error=d["max_following_error"],
        quick_stop_cycles=d["quick_stop_cycles"],
        lockstep_wait_s=d["lockstep_wait_s"],
        chunk_seconds=d["chunk_seconds"],
        cpu=d["cpu"],
        position_limits=tuple(pos) if pos is not None else None,
        max_velocity=lim.get("max_velocity"),
        max_torque=lim.get("max_torque"),
        source=source,
        master_node_id=d["master_node_id"],
        master_heartbeat_ms=d["master_heartbeat_ms"],
    )


def with_scaling(cfg: DaqConfig, scaling: Scaling) -> DaqConfig:
    """The same configuration with every drive's scaling replaced (``--simulate``)."""
    return replace(cfg, drives=tuple(replace(d, scaling=scaling) for d in cfg.drives))
