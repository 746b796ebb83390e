"""The ``[daq]`` table of a campaign: bus, drives, scaling, watchdog (validated, frozen).

Format (every key optional; absent: python-can's virtual bus, one drive, node 1, on the
project's generic EDS, cyclic synchronous torque)::

    [daq]
    interface = "socketcan"       # any python-can interface: virtual, socketcan, pcan, kvaser,
                                  # remote (python-can-remote: the URL serve prints, token included)
                                  # or "config": python-can's own configuration opens the bus
    channel = "can0"
    bitrate = 1000000             # [bit/s]
    # interface, channel, bitrate left out: taken from python-can's configuration
    # (can.util.load_config: CAN_INTERFACE / CAN_CHANNEL / CAN_BITRATE / CAN_CONFIG
    # environment, ~/can.conf, /etc/can.conf, ~/.can, ~/.canrc) when it names an
    # interface; else python-can's virtual bus "jointid" at 1 Mbit/s (see can_config_fallback)
    max_bus_load = 0.6            # refuse cyclic traffic above this share of the bit rate
    clock = "paced"               # "lockstep" (virtual bus + simulated drives) or "paced"
    sync_source = "runner"        # paced: "runner" (the runner's own timed loop sends SYNC)
                                  # or "periodic" (python-can send_periodic: the kernel's
                                  # broadcast manager on socketcan, a thread elsewhere)
    realtime_priority = 0         # paced: SCHED_FIFO priority 1-99 (needs CAP_SYS_NICE); 0 off
    switch_interval_s = 0.0002    # paced: Python's GIL switch interval during a payload run
                                  # [s] (sys.setswitchinterval; restored after it); 0: keep
                                  # Python's (5 ms). The loop waking from its sleep waits at
                                  # most about this long for the GIL held by another thread
                                  # (the simulated drives, the log's chunk writer)
    tpdo_timeout_cycles = 3       # watchdog: TPDOs missing for k consecutive cycles -> stop
    rpdo_margin_ms = 100          # paced: the drives' RPDO deadline (0x1400.5) is 3 cycles +
                                  # this [ms]; a master stalled longer stops the run (and a
                                  # drive faults by itself). Longer tolerates a loaded host's
                                  # stalls; the drives then fault later if the master dies
    heartbeat_timeout_s = 0.5     # watchdog: no heartbeat for this long [s] -> stop
    max_following_error = 0.2     # watchdog: |q_ref - q| above this [rad] or [m] -> stop
    quick_stop_cycles = 2         # cycles of quick stop before disable voltage
    lockstep_wait_s = 0.5         # lockstep: wall time to wait for the TPDOs of one cycle [s]
    chunk_seconds = 0.1           # MCAP chunk length [s of data] (lost at most on SIGKILL);
                                  # lockstep: each chunk is compressed inside the cycle loop
                                  # (1 s chunks cost ~1.5 ms once a second, bench_daq.py);
                                  # paced: by a worker thread, outside the cycle
    gc_freeze = true              # paced and lockstep: gc.collect() + gc.freeze() before each
                                  # payload run, no automatic collection during it (a full
                                  # collection stalls 10-50 ms); collections resume after it
    cpu = -1                      # pin the process to this CPU (-1: the last allowed one;
                                  # -2: do not pin)
    master_node_id = 127          # node id of the master's own heartbeat (0x700 + id)
    master_heartbeat_ms = 100     # master heartbeat period [ms] (0: none, drives not told);
                                  # each drive with 0x1016 watches it with a consumer time
                                  # of 3 x period + 100 ms and stops (fault) when it is lost
    allow_beyond_drive_limits = false  # true: accept a velocity watchdog above the drive's
                                  # max motor speed 0x6080 (refused by default: it could
                                  # never fire)
    velocity_source = "drive"     # torque mode: the velocity the master's position loop
                                  # filters (daq.protocol.control.PDLaw): "drive" (the drive's
                                  # own 0x606C: a late answer, to an earlier SYNC taken as this
                                  # one's, does not make it spike) or "difference" (the
                                  # backward difference of 0x6064). Left out: "drive" on the
                                  # paced clock, "difference" in lockstep (every answer is
                                  # that SYNC's; the logs of lockstep runs stay as they were)
    lateness_check_s = 0.5        # before the plan moves (drives enabled, holding the start
                                  # position): hold this long [s] measuring, per bus, the
                                  # share of the drives' answers missing at the cycle's
                                  # deadline or come with an older one (an answer to an
                                  # earlier SYNC); a share within 2 sigmas of lateness_stop is
                                  # measured again, at most 3 x this long in all. Left out:
                                  # 0.5 on the paced clock, 0 (no check, no hold) in lockstep
    lateness_warn = 0.1           # a share above this: the run goes on, with a warning (log
                                  # event, summary)
    lateness_stop = 0.3           # a share above this: the run is refused (drives disabled,
                                  # log closed), one line naming the bus and what was measured
    torque_delay_cycles = 1.5     # timing written in each log for identification [cycles]:
                                  # from the SYNC whose position the master reads to the
                                  # middle of the cycle the torque it sends acts over. 1.5 on
                                  # drives whose synchronous RPDO is actuated at the next
                                  # SYNC (CiA 301) and whose TPDO samples at SYNC; with
                                  # --simulate the simulated drives' own timing is written
    [daq.limits]                  # optional, tighter than the campaign's joint.limits;
                                  # refused beyond the sanity bounds of joint limits
                                  # (trajectories.campaign.SANE_LIMITS: 1e3 rad/s...)
    position = [-1.0, 1.0]
    max_velocity = 1.0
    max_torque = 500.0
    [[daq.drives]]
    node_id = 1                   # unique over all buses
    eds = "drives/epos4.eds"      # relative to the campaign file; default: generic EDS
    mode = "cst"                  # or "csp"
    heartbeat_ms = 100            # heartbeat producer time written to 0x1017 [ms]
    channel = "can1"              # the bus of this drive (default: daq.channel); drives on
                                  # several channels of the same interface and bit rate, each
                                  # bus with its own SYNC and its own load budget
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
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import can
import can.util

from daq import ConfigError
from daq.protocol.cia402 import Mode
from trajectories import SchemaError
from trajectories.campaign import SANE_LIMITS
from trajectories.schema import ArrayOfTables, Field, Table

MODES = {"cst": Mode.CYCLIC_SYNC_TORQUE, "csp": Mode.CYCLIC_SYNC_POSITION}
#: the velocity the torque loop filters: the drive's 0x606C or the position's difference
VELOCITY_SOURCES = ("drive", "difference")
#: [s] the start-up lateness check's hold on the paced clock when ``lateness_check_s`` is
#: left out (lockstep: 0, no check)
LATENESS_CHECK_S = 0.5
#: the start-up lateness check's limits: share of the drives' answers late or missing
#: during the hold (calibration: :mod:`daq.runtime.safety`)
LATENESS_WARN = 0.1
LATENESS_STOP = 0.3


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
    channel : str
        The bus the drive is on (``daq.channel`` unless the drive names another one).
    """

    node_id: int
    eds: Path
    mode: Mode
    heartbeat_ms: int
    scaling: Scaling | None
    channel: str = ""

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
    rpdo_margin_ms: int
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
    from_can_config: tuple[str, ...] = ()  # keys taken from python-can's configuration
    gc_freeze: bool = True  # no automatic garbage collection during a payload run
    switch_interval_s: float = 0.0002  # [s] GIL switch interval of a paced run (0: Python's)
    allow_beyond_drive_limits: bool = False  # supervision limits above the drive's own
    torque_delay_cycles: float = 1.5  # [cycles] the logs' torque timing (module docstring)
    velocity_source: str = "difference"  # "drive" (0x606C) or "difference" (resolved)
    lateness_check_s: float = 0.0  # [s] the start-up lateness check's hold (resolved; 0: none)
    lateness_warn: float = LATENESS_WARN  # share of late/missing answers: warning above
    lateness_stop: float = LATENESS_STOP  # share of late/missing answers: refused above

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

    @property
    def channels(self) -> tuple[str, ...]:
        """The buses, in the order of their first drive (``daq.channel`` alone by default)."""
        return tuple(dict.fromkeys(d.channel or self.channel for d in self.drives)) or (
            self.channel,)

    def drives_on(self, channel: str) -> tuple[DriveConfig, ...]:
        """The drives on bus ``channel``."""
        return tuple(d for d in self.drives if (d.channel or self.channel) == channel)


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
        "channel": Field(str, required=False, default=""),
        "scaling": _SCALING,
    }
)

_LIMITS = Table(  # the sanity bounds of the joint limits (trajectories.campaign.SANE_LIMITS)
    {
        "position": Field(float, list_of=True, min_len=2, required=False,
                          ge=-SANE_LIMITS["position"], le=SANE_LIMITS["position"], unit="rad"),
        "max_velocity": Field(float, gt=0, le=SANE_LIMITS["max_velocity"], required=False,
                              unit="rad/s"),
        "max_torque": Field(float, gt=0, le=SANE_LIMITS["max_torque"], required=False,
                            unit="N m"),
    },
    required=False,
)

DEFAULT_INTERFACE = "virtual"
DEFAULT_CHANNEL = "jointid"
DEFAULT_BITRATE = 1_000_000  # [bit/s]
_BUS_KEYS = ("interface", "channel", "bitrate")

_DAQ = Table(
    {
        "interface": Field(str, required=False, default=None),
        "channel": Field(str, required=False, default=None),
        "bitrate": Field(int, required=False, default=None, gt=0, le=1_000_000,
                         unit="bit/s"),
        "max_bus_load": Field(float, required=False, default=0.6, gt=0, le=1),
        "clock": Field(str, required=False, default="", choices=("lockstep", "paced", "")),
        "sync_source": Field(str, required=False, default="runner",
                             choices=("runner", "periodic")),
        "realtime_priority": Field(int, required=False, default=0, ge=0, le=99),
        "drives": ArrayOfTables(_DRIVE, required=False),
        "tpdo_timeout_cycles": Field(int, required=False, default=3, ge=1, unit="cycles"),
        "rpdo_margin_ms": Field(int, required=False, default=100, ge=0, le=60000, unit="ms"),
        "heartbeat_timeout_s": Field(float, required=False, default=0.5, gt=0, unit="s"),
        "max_following_error": Field(float, required=False, default=0.2, gt=0, unit="rad"),
        "quick_stop_cycles": Field(int, required=False, default=2, ge=1, le=1000),
        "lockstep_wait_s": Field(float, required=False, default=0.5, gt=0, unit="s"),
        "chunk_seconds": Field(float, required=False, default=0.1, gt=0, unit="s"),
        "gc_freeze": Field(bool, required=False, default=True),
        "switch_interval_s": Field(float, required=False, default=0.0002, ge=0, le=0.1,
                                   unit="s"),
        "cpu": Field(int, required=False, default=-1, ge=-2),
        "master_node_id": Field(int, required=False, default=127, ge=1, le=127),
        "master_heartbeat_ms": Field(int, required=False, default=100, ge=0, le=20000,
                                     unit="ms"),
        "limits": _LIMITS,
        "allow_beyond_drive_limits": Field(bool, required=False, default=False),
        "torque_delay_cycles": Field(float, required=False, default=1.5, ge=0, le=10,
                                     unit="cycles"),
        "velocity_source": Field(str, required=False, default=None, choices=VELOCITY_SOURCES),
        "lateness_check_s": Field(float, required=False, default=None, ge=0, le=10,
                                  unit="s"),
        "lateness_warn": Field(float, required=False, default=LATENESS_WARN, ge=0, le=1),
        "lateness_stop": Field(float, required=False, default=LATENESS_STOP, ge=0, le=1),
    }
)


def generic_eds() -> Path:
    """The project's generic EDS of the simulated drive."""
    from importlib import resources

    return Path(str(resources.files("sim_drivers.data").joinpath("jointid_cia402.eds")))


def python_can_config(source: str = "") -> dict[str, Any]:
    """python-can's own bus configuration (``can.util.load_config()``), or ``{}`` when no
    source (environment, config file, ``can.rc``) names an interface.

    Raises
    ------
    daq.ConfigError
        The configuration names an interface python-can does not know, or is unreadable.
    """
    try:
        return dict(can.util.load_config())
    except can.CanInterfaceNotImplementedError as exc:
        named = any(src.get("interface") or src.get("bustype") for src in (
            can.rc, can.util.load_environment_config(), can.util.load_file_config()))
        if not named:
            return {}
        raise ConfigError(f"{source or 'campaign'}: daq.interface: left out, and python-can's "
                          f"configuration names an unusable interface ({exc})") from None
    except (ValueError, OSError) as exc:  # malformed CAN_CONFIG JSON, unreadable file
        raise ConfigError(f"{source or 'campaign'}: daq.interface: left out, and python-can's "
                          f"configuration cannot be read ({exc})") from None


def can_config_fallback(d: Mapping[str, Any], source: str = "",
                        use_can_config: bool = True) -> tuple[dict[str, Any], tuple[str, ...]]:
    """Fill ``interface``/``channel``/``bitrate`` left out of ``[daq]``.

    From python-can's configuration (:func:`python_can_config`) when it names an interface
    and ``[daq]`` names none or the same one; else the defaults (python-can's virtual bus,
    channel ``"jointid"``, 1 Mbit/s). A ``bitrate`` from python-can's configuration must lie
    in (0, 1 Mbit/s] like the table's own.

    Returns
    -------
    (dict, tuple of str)
        The three values and the keys taken from python-can's configuration.
    """
    out = {k: d.get(k) for k in _BUS_KEYS}
    taken: list[str] = []
    if all(out[k] is not None for k in _BUS_KEYS) or not use_can_config:
        pc: dict[str, Any] = {}
    else:
        pc = python_can_config(source)
    pc_iface = pc.get("interface")
    if pc_iface and out["interface"] in (None, pc_iface):
        for key in _BUS_KEYS:
            if out[key] is None and pc.get(key) not in (None, ""):
                out[key] = pc[key]
                taken.append(key)
    if "bitrate" in taken:
        try:
            rate = int(out["bitrate"])
        except (TypeError, ValueError):
            rate = -1
        if not 0 < rate <= 1_000_000:
            raise ConfigError(f"{source or 'campaign'}: daq.bitrate: left out, and python-can's "
                              f"configuration gives {out['bitrate']!r}: expected an integer "
                              f"in (0, 1000000] [bit/s]")
        out["bitrate"] = rate
    if "channel" in taken:
        out["channel"] = str(out["channel"])
    out["interface"] = out["interface"] or DEFAULT_INTERFACE
    out["channel"] = out["channel"] if out["channel"] is not None else DEFAULT_CHANNEL
    out["bitrate"] = out["bitrate"] or DEFAULT_BITRATE
    return out, tuple(taken)


def parse_daq(raw: Mapping[str, Any] | None, source: str = "", *,
              use_can_config: bool = True) -> DaqConfig:
    """Validate a raw ``[daq]`` table.

    Parameters
    ----------
    raw : mapping or None
        ``RobotCampaign.daq`` (``{}`` or None when the campaign has no ``[daq]``).
    source : str
        The campaign file name: used in messages and to resolve relative EDS paths.
    use_can_config : bool
        Fill ``interface``/``channel``/``bitrate`` left out from python-can's configuration
        (:func:`can_config_fallback`); False: the defaults (simulated runs).

    Raises
    ------
    daq.ConfigError
        One line naming the file, the dotted key and what was expected.
    """
    try:
        d = _DAQ.validate(dict(raw or {}), "daq", source)
    except SchemaError as exc:
        raise ConfigError(str(exc)) from None
    bus, from_pc = can_config_fallback(d, source, use_can_config)
    d.update(bus)
    base = Path(source).parent if source else Path.cwd()
    drives_raw = d["drives"] or ({"node_id": 1, "eds": "", "mode": "cst", "heartbeat_ms": 100,
                                  "channel": "", "scaling": None},)
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
        channel = dr.get("channel") or d["channel"]
        if channel != d["channel"] and d["interface"] == "config":
            raise ConfigError(f"{source}: {key}.channel: expected no channel with interface "
                              f"'config' (python-can's configuration names one bus), got "
                              f"{channel!r}")
        drives.append(DriveConfig(dr["node_id"], eds, MODES[dr["mode"]], dr["heartbeat_ms"],
                                  scaling, channel))
    lim = d["limits"] or {}
    pos = lim.get("position")
    if pos is not None and (len(pos) != 2 or not pos[0] < pos[1]):
        raise ConfigError(f"{source}: daq.limits.position: expected [min, max] with min < max, "
                          f"got {list(pos)}")
    clock = d["clock"] or ("lockstep" if d["interface"] == "virtual" else "paced")
    if clock == "lockstep" and d["interface"] not in ("virtual", "config"):
        raise ConfigError(f"{source}: daq.clock: expected 'paced' on a real interface "
                          f"({d['interface']!r}), got 'lockstep'")
    if d["lateness_warn"] > d["lateness_stop"]:
        raise ConfigError(f"{source}: daq.lateness_warn: expected at most daq.lateness_stop "
                          f"({d['lateness_stop']:g}), got {d['lateness_warn']:g}")
    check_s = d["lateness_check_s"]
    if check_s is None:
        check_s = LATENESS_CHECK_S if clock == "paced" else 0.0
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
        rpdo_margin_ms=d["rpdo_margin_ms"],
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
        from_can_config=from_pc,
        gc_freeze=d["gc_freeze"],
        switch_interval_s=d["switch_interval_s"],
        allow_beyond_drive_limits=d["allow_beyond_drive_limits"],
        torque_delay_cycles=d["torque_delay_cycles"],
        velocity_source=d["velocity_source"] or (
            "drive" if clock == "paced" else "difference"),
        lateness_check_s=check_s,
        lateness_warn=d["lateness_warn"],
        lateness_stop=d["lateness_stop"],
    )


def with_scalings(cfg: DaqConfig, scalings: Sequence[Scaling]) -> DaqConfig:
    """The same configuration with drive k's scaling replaced by ``scalings[k]``
    (``--simulate``: the simulated drives' own chains)."""
    return replace(cfg, drives=tuple(replace(d, scaling=s)
                                     for d, s in zip(cfg.drives, scalings, strict=True)))
