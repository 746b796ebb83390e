"""Campaign orchestration: ``run_campaign`` opens the bus, starts the drives (and the
``--simulate`` rig), runs one payload after the other through :class:`daq.runtime.engine.Engine`
(one MCAP log each), asks the operator between payloads and keeps the resume state file.

(Past 600 lines: the campaign's lifecycle -- bus, drives, payloads, resume state, the
wind-down with its bus-lost and EMCY checks -- stays in one file so that every exit path is
read together and leaves the drives safe; the log metadata helpers (``_metadata``,
``_attachments``) are the part that could move out.)"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import signal
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import can
import canopen
import numpy as np

from daq import ConfigError, DaqError, __version__
from trajectories.multi import plan_robot_campaign
from trajectories.robot_campaign import RobotCampaign
from trajectories.robot_model import prepare_robot_campaign, robot_file_path

from .buses import open_buses, sync_clocked
from .busload import bus_loads, check_loads
from .campaign_id import campaign_definition, check_folder, check_state, plant_record
from .config import DaqConfig, Scaling, with_scalings
from .cycle_io import BUS_ERRORS, CycleIO
from .engine import ENABLE_MAX_CYCLES, SETTLE_CYCLES, Engine, drive_joints, emcy_text
from .master import MasterDrive, MasterHeartbeat, pdo_lengths, rpdo_timeout_ms
from .mcaplog import RunLog
from .results import CampaignResult, PayloadResult, Progress
from .robot_rig import (
    robot_daq_config,
    robot_metadata,
    sim_params,
    sim_scalings,
    start_arm_sim,
)
from .runfolder import (
    FolderLock,
    RunState,
    check_completed_logs,
    check_free_space,
    check_logs,
    create_log_file,
    expected_log_bytes,
    keep_emcy_outside_logs,
    keep_partial,
    keep_warnings_outside_logs,
    log_path,
    log_record,
    read_state,
    write_state,
)
from .safety import StopSignals, interrupt_reason, redact_url_secret
from .simrig import SimRig, start_sim

__all__ = ["CampaignResult", "PayloadResult", "Progress", "check_daq", "file_stem",
           "run_campaign"]


logger = logging.getLogger(__name__)


def _pin_cpu(cpu: int) -> set[int] | None:
    if cpu == -2 or not hasattr(os, "sched_setaffinity"):
        return None
    old = os.sched_getaffinity(0)
    target = max(old) if cpu == -1 else cpu
    if target not in old:
        raise ConfigError(f"daq.cpu: expected one of the allowed CPUs {sorted(old)}, got {cpu}")
    os.sched_setaffinity(0, {target})
    return old


def _set_realtime(cfg: DaqConfig) -> tuple[int, int] | None:
    """SCHED_FIFO at ``cfg.realtime_priority`` for this thread and the threads it starts."""
    if not cfg.realtime_priority:
        return None
    old = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(cfg.realtime_priority))
    except (PermissionError, OSError) as exc:
        raise ConfigError(f"{cfg.source}: daq.realtime_priority: cannot set SCHED_FIFO "
                          f"{cfg.realtime_priority} ({exc.strerror}; needs CAP_SYS_NICE)"
                          ) from None
    return old



# ----------------------------------------------------------------------------- campaign
def file_stem(name: str) -> str:
    """A campaign name made safe for file names (``"rx130l (quick)"`` -> ``"rx130l_quick"``)."""
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_")
    return stem or "campaign"


def _state_path(out_dir: Path, name: str) -> Path:
    return out_dir / f"{file_stem(name)}.state.json"


def _metadata(campaign: RobotCampaign, cfg: DaqConfig, plan: Any, index: int, payload: Any,
              scalings: list[Scaling], plant_params: Any,
              bus_info: str = "", drives: Sequence[MasterDrive] = (),
              torque_delay_cycles: float | None = None, definition: str = "",
              ) -> dict[str, dict[str, str]]:
    joints = campaign.joints
    cut = campaign.control.velocity_cutoff_hz
    if campaign.robot_file:  # per joint, as ident's robot loader reads them
        pos: Any = [list(j.limits.position) for j in joints]
        gains: Any = {j.name: {"kp": j.kp, "kd": j.kd, "velocity_cutoff_hz": cut}
                      for j in joints}
    else:  # no robot file: its one joint, as ident's single-joint loader reads it
        pos = list(joints[0].limits.position)
        gains = joints[0].gains_kwargs(cut)
    pay = {"index": str(index), "mass_kg": repr(float(payload.mass_kg))}
    if payload.arm_m is not None:  # a point mass on a lever arm (a [joint] file)
        pay["arm_m"] = repr(float(payload.arm_m))
    else:
        pay["com_m"] = json.dumps([float(x) for x in payload.com])
        pay["inertia_kgm2"] = json.dumps([float(x) for x in payload.inertia])
    md: dict[str, dict[str, str]] = {
        "campaign": {
            "name": campaign.name, "source": str(campaign.source),
            "joint_kind": joints[0].kind, "cycle_s": repr(campaign.cycle_s),
            "clock": cfg.clock, "interface": cfg.interface, "channel": cfg.channel,
            "bitrate": str(cfg.bitrate), "bus": bus_info,
            "n_payloads": str(len(campaign.payloads)),
            "segments": json.dumps(list(plan.segment_names)),
            "position_limits": json.dumps(pos),
            "gains": json.dumps(gains),
            # [cycles] from a logged position's SYNC to the middle of the cycle the torque
            # computed from it acts over (the simulated drives' or the [daq] setting)
            "torque_delay_cycles": repr(float(cfg.torque_delay_cycles
                                              if torque_delay_cycles is None
                                              else torque_delay_cycles)),
            # the velocity the master's torque loop filtered ([daq] velocity_source)
            "velocity_source": cfg.velocity_source,
            # the campaign as loaded (campaign_id.campaign_definition): a run folder holds
            # the logs of one campaign
            "definition": definition,
        },
        "payload": pay,
        "software": {"jointid": __version__, "python-can": can.__version__,
                     "canopen": getattr(canopen, "__version__", "?"),
                     "python": sys.version.split()[0]},
    }
    if campaign.robot_file:
        md["campaign"]["kind"] = "robot"
        md["robot"] = robot_metadata(campaign)
    cols = drive_joints(campaign, len(cfg.drives))
    for k, (d, s) in enumerate(zip(cfg.drives, scalings, strict=True)):
        md[f"drive{k}"] = {"node_id": str(d.node_id), "eds": d.eds.name, "mode": d.mode_name,
                           "channel": d.channel or cfg.channel, **s.as_dict()}
        if campaign.robot_file:
            md[f"drive{k}"]["joint"] = joints[cols[k]].name
        if k < len(drives):
            v = drives[k].consumer_value
            md[f"drive{k}"]["heartbeat_consumer"] = ("" if v is None else f"0x{v:08X}")
            t = drives[k].rpdo_timer_ms
            md[f"drive{k}"]["rpdo_event_timer_ms"] = "" if t is None else str(t)
    md["safety"] = {
        "master_node_id": str(cfg.master_node_id),
        "master_heartbeat_ms": str(cfg.master_heartbeat_ms),
        "heartbeat_consumer_ms": str(cfg.heartbeat_consumer_ms),
        "sync_period_us": str(_sync_period_us(cfg, campaign.cycle_s)),
        "rpdo_timeout_ms": str(rpdo_timeout_ms(campaign.cycle_s, cfg.clock == "paced",
                                               cfg.rpdo_margin_ms)),
    }
    if plant_params is not None:
        md["plant"] = plant_record(plant_params)
    for rec in md.values():
        for key in ("channel", "bus"):
            if key in rec:
                rec[key] = redact_url_secret(rec[key])
    return md




def _sync_period_us(cfg: DaqConfig, cycle_s: float) -> int:
    """0x1006 for the drives [µs]: the cycle when paced, 0 (SYNC monitoring off) in
    lockstep, where SYNCs may be far apart in wall time on a loaded host."""
    return int(round(cycle_s * 1e6)) if cfg.clock == "paced" else 0


def _attachments(campaign: RobotCampaign, cfg: DaqConfig,
                 plant_params: Any) -> list[tuple[str, str, bytes]]:
    out = []
    src = Path(str(campaign.source)) if campaign.source else None
    if src is not None and src.is_file():
        out.append((src.name, "application/toml", src.read_bytes()))
    seen = set()
    for d in cfg.drives:
        if d.eds not in seen:
            seen.add(d.eds)
            out.append((d.eds.name, "text/plain", d.eds.read_bytes()))
    if plant_params is not None:
        p = Path(str(getattr(plant_params, "source", "")))
        if p.suffix == ".toml" and p.is_file():
            out.append((p.name, "application/toml", p.read_bytes()))
    if campaign.robot_file:
        p = Path(robot_file_path(campaign))
        if p.suffix in (".toml", ".urdf") and p.is_file():
            media = "application/toml" if p.suffix == ".toml" else "application/xml"
            out.append((p.name, media, p.read_bytes()))
    return out


def prompt_payload(index: int, payload: Any, n: int) -> bool | None:
    """Ask the operator to mount a payload; False to abort the campaign, None when the
    standard input is closed (no one to answer: a script, a notebook, CI)."""
    where = (f"at {payload.arm_m:g} m" if getattr(payload, "arm_m", None) is not None else
             f"CoM {', '.join(f'{x:g}' for x in payload.com)} m in the flange frame")
    try:
        answer = input(f"Mount payload {index + 1}/{n}: {payload.mass_kg:g} kg {where}, "
                       f"then press Enter (q to quit): ")
    except EOFError:
        print()  # end the prompt's line
        return None
    return answer.strip().lower() not in ("q", "quit", "n", "no")


def run_campaign(
    campaign: RobotCampaign,
    *,
    out_dir: str | Path,
    simulate: Any = None,
    yes: bool = False,
    progress: Callable[[Progress], None] | None = None,
    payloads: Sequence[int] | None = None,
    resume: bool = False,
    fault_injectors: dict[int, Any] | None = None,
    prompt: Callable[[int, Any, int], bool] | None = None,
    overwrite: bool = False,
    monitor: Any = None,
) -> CampaignResult:
    """Run a campaign: one MCAP file per payload run in ``out_dir``.

    Parameters
    ----------
    campaign : trajectories.robot_campaign.RobotCampaign
        Either file format (:func:`trajectories.campaign_file.load_campaign`); a ``[joint]``
        file is a robot with one moving joint whose drives are those of ``[daq]``.
    out_dir : path-like
        Created if needed; receives ``<name>_payload<k>.mcap`` and ``<name>.state.json``
        (:class:`~daq.runtime.runfolder.RunState`: the completed payloads and their logs'
        names and sizes, the campaign's identity, the EMCYs received after the last
        payload's log closed and the warnings of the run's wind-down -- the bus lost, a
        drive no longer answering --, which no log holds: each also a warning of the
        result's ``notes``).
        Locked for the whole run (one run per folder); an existing log is never replaced
        without ``overwrite`` (:mod:`daq.runtime.runfolder`).
    simulate : sim_drivers.plant_config.PlantParams, sim_drivers.arm.ArmParams, True or None
        Run against simulated drives on python-can's virtual bus, the plant the campaign
        asks for (:attr:`~trajectories.robot_campaign.RobotCampaign.plant`,
        :mod:`daq.runtime.robot_rig`): ``"arm"``, one simulated arm behind its drives --
        ``simulate`` is its :class:`~sim_drivers.arm.ArmParams`, or True for
        ``ArmParams.from_robot`` of the campaign's robot file; ``"joint"`` (no robot file),
        one joint plant per drive -- ``simulate`` is a plant file's
        :class:`~sim_drivers.plant_config.PlantParams` (drive scaling: its ``[drive]``).
    yes : bool
        Do not ask the operator between payloads (unattended).
    progress : callable or None
        Called with a :class:`Progress` every ~250 cycles.
    payloads : sequence of int or None
        Indices of the payloads to run (default: all), each once (a repeated index is
        refused: its second log would replace the first).
    resume : bool
        Skip the payloads the state file lists as completed, once their logs are checked
        (:func:`~daq.runtime.runfolder.check_completed_logs`: a completed payload's log
        missing or changed is refused); the log of a payload that did not complete is moved
        to ``partial/`` before the payload runs again.
    fault_injectors : dict node_id -> sim_drivers.faults.FaultInjector, optional
        For tests with simulated drives.
    prompt : callable or None
        ``(index, payload, n) -> bool`` replacing the interactive prompt.
    overwrite : bool
        Replace the logs of the payloads run (the state file forgets a payload whose
        completed log is replaced, until it completes again).
    monitor : daq.runtime.monitor.TorqueMonitor, optional
        Checks every cycle of the run phase (``jointid monitor``); with a simulated arm it
        gets the arm (``monitor.arm``) to stage its pushes on.

    Returns
    -------
    CampaignResult
        ``status`` "done", "stopped" (a fault, a log write failure, too little free space
        before a later payload, the bus lost during a run or before the next payload's;
        ``reason`` names it), "interrupted" (SIGINT, SIGTERM or
        SIGHUP during a payload or at the prompt) or "aborted" (the operator declined a
        payload).

    Raises
    ------
    daq.ConfigError
        Refusals before any motion: invalid ``[daq]``, bus load over the limit, unknown node,
        EDS or drive without the requested mode, PDO read-back mismatch, the folder locked
        by another run, a log that exists, an unreadable state file or one of another
        campaign (:func:`~daq.runtime.campaign_id.check_state`; ``overwrite`` replaces it),
        with ``resume`` a completed payload whose log is missing or changed, too little
        free space.
    daq.runtime.safety.RunInterrupted
        A stop signal before the first payload started (no drive enabled).
    trajectories.TrajectoryError
        The plan violates a limit.
    """
    cfg, load = check_daq(campaign, simulated=simulate is not None)
    definition = campaign_definition(campaign)  # as loaded: before any optimisation
    # the multi-sines as jointid plan optimised them (deterministic)
    campaign, _dyn, _opt = prepare_robot_campaign(campaign)
    sim_notes: list[str] = []
    if simulate is not None:  # the plant the campaign asks for (campaign.plant)
        simulate = sim_params(campaign, simulate)
        chains = sim_scalings(campaign, simulate, len(cfg.drives))
        sim_notes = [f"--simulate: node {d.node_id}: [daq.drives.scaling] "
                     f"({_scaling_text(d.scaling)}) is not used: the simulated drive's chain "
                     f"is ({_scaling_text(s)})"
                     for d, s in zip(cfg.drives, chains, strict=True)
                     if d.scaling is not None and _chain(d.scaling) != _chain(s)]
        cfg = with_scalings(cfg, chains)
        if cfg.interface != "virtual":
            raise ConfigError(f"{campaign.source}: daq.interface: expected 'virtual' with "
                              f"--simulate, got {cfg.interface!r}")
    # every refusal before anything is created, opened or moved
    plan = plan_robot_campaign(campaign)  # a [joint] campaign: a robot with one moving joint
    n_pay = len(campaign.payloads)
    todo = list(range(n_pay)) if payloads is None else list(payloads)
    for k, i in enumerate(todo):
        if not 0 <= i < n_pay:
            raise ConfigError(f"payload index {i}: expected 0..{n_pay - 1}")
        if i in todo[:k]:  # run twice, its second log would replace the first
            raise ConfigError(f"payload index {i}: given twice, expected each payload once")
    out = Path(out_dir)
    stem = file_stem(campaign.name)
    lock = FolderLock(out)  # one run per folder, from here to the end
    try:
        return _run_locked(campaign, cfg, plan, load, out, stem, todo, simulate, yes,
                           progress, resume, overwrite, fault_injectors, prompt, monitor,
                           sim_notes, definition)
    finally:
        lock.release()


def check_daq(campaign: RobotCampaign, *, simulated: bool = False) -> tuple[DaqConfig, Any]:
    """The checks of a campaign's ``[daq]`` (and its robot file's drives) that
    :func:`run_campaign` makes before anything is opened, and ``jointid plan`` too (so a
    campaign that plans also runs): the table itself
    (:func:`~daq.runtime.robot_rig.robot_daq_config`: keys, values, node ids, EDS files,
    clock) and the cyclic bus load on every bus (:func:`~daq.runtime.busload.check_loads`).

    Parameters
    ----------
    campaign : trajectories.robot_campaign.RobotCampaign
    simulated : bool
        A ``--simulate`` run: on python-can's virtual bus, whose own configuration (naming
        the real bus) must not fill what ``[daq]`` leaves out.

    Returns
    -------
    (DaqConfig, busload.BusLoad)
        The parsed ``[daq]`` and the highest bus load.

    Raises
    ------
    daq.ConfigError
        One line naming the campaign file and the key.
    """
    cfg = robot_daq_config(campaign, use_can_config=not simulated)
    loads = bus_loads({ch: [pdo_lengths(d.mode) for d in cfg.drives_on(ch)]
                       for ch in cfg.channels}, campaign.cycle_s, cfg.bitrate)
    return cfg, check_loads(loads, cfg.max_bus_load, str(campaign.source) or "campaign")


def _bus_lost(exc: BaseException, when: str = "") -> str:
    """The one-line reason of a bus that failed under the runner outside a payload's run
    (worded as the engine's "bus lost: ..." within one): ``when`` (" before the run of
    payload 1") is said before the error."""
    return f"bus lost{when}: {type(exc).__name__}: {exc}".splitlines()[0]


def _chain(sc: Any) -> tuple[float, float, int]:
    """What a scaling does to the logged values: gear ratio, joint torque per unit, counts."""
    return (float(sc.gear_ratio), float(sc.torque_per_unit), int(sc.encoder_counts_per_rev))


def _scaling_text(sc: Any) -> str:
    """A drive scaling in a few words, for the ``--simulate`` note."""
    text = (f"gear ratio {sc.gear_ratio:g}, rated torque {sc.rated_torque_Nm:g} N m, "
            f"{sc.encoder_counts_per_rev} counts/rev")
    gain = getattr(sc, "drive_gain", None)
    return text + (f", drive gain {gain:g} N m/unit" if gain else "")


def _run_locked(campaign: RobotCampaign, cfg: DaqConfig, plan: Any, load: Any, out: Path,
                stem: str, todo: list[int], simulate: Any, yes: bool,
                progress: Callable[[Progress], None] | None, resume: bool, overwrite: bool,
                fault_injectors: dict[int, Any] | None,
                prompt: Callable[[int, Any, int], bool] | None,
                monitor: Any = None, sim_notes: list[str] | None = None,
                definition: str = "") -> CampaignResult:
    """:func:`run_campaign` once the refusals passed and the folder is locked;
    ``sim_notes``: warnings of the ``--simulate`` set-up (a scaling the simulation ignores);
    ``definition``: :func:`~daq.runtime.campaign_id.campaign_definition` of the campaign as
    loaded."""
    n_pay = len(campaign.payloads)
    plant = plant_record(simulate)
    source = str(campaign.source) or "this campaign"
    if not overwrite:  # a folder holds the logs of one campaign (never two mixed)
        check_folder(out, stem, campaign.name, definition, plant, source)
    state_file = _state_path(out, campaign.name)
    state = read_state(state_file)  # merged into, never shrunk (runfolder)
    notes: list[str] = list(sim_notes or ())
    # the state file's name is the campaign's stem: another campaign's may share it
    if why := check_state(state.campaign, state.definition, state.plant, campaign.name,
                          definition, plant, source):
        if not overwrite:
            raise ConfigError(f"{state_file}: {why}; a folder holds the logs of one "
                              f"campaign: give another --out")
        notes.append(f"{state_file}: {why}: replaced (--overwrite)")
        state = RunState()
    state.campaign, state.plant = campaign.name, plant
    state.definition = json.loads(definition) if definition else None
    completed = state.completed
    if resume:  # each completed payload's log as its run left it, or a refusal
        check_completed_logs(out, stem, state, state_file)
    done_before = completed if resume else set()
    skipped = tuple(i for i in todo if i in done_before)
    todo = [i for i in todo if i not in done_before]
    check_logs(out, stem, todo, completed, resume=resume, overwrite=overwrite)
    attachments = _attachments(campaign, cfg, simulate)
    n_ref = len(plan.t)
    log_bytes = expected_log_bytes(len(cfg.drives), campaign.cycle_s,
                                   n_ref + ENABLE_MAX_CYCLES + SETTLE_CYCLES + 100,
                                   sum(len(a[2]) for a in attachments))
    if todo and (why := check_free_space(log_path(out, stem, todo[0]), log_bytes)):
        raise ConfigError(why)

    old_affinity = _pin_cpu(cfg.cpu)
    old_sched = _set_realtime(cfg) if cfg.clock == "paced" else None
    sim: SimRig | None = None
    network: canopen.Network | None = None
    signals = StopSignals()
    engine: Engine | None = None
    runs: list[PayloadResult] = []
    sim_records: tuple[dict[str, np.ndarray], ...] = ()
    heartbeat: MasterHeartbeat | None = None
    drives: list[MasterDrive] = []
    io: CycleIO | None = None
    clean = False
    status, reason = "done", ""
    #: the bus failed outside a payload's run (no NMT, no SDO can be sent any more)
    bus_gone = ""
    #: warnings of the wind-down, after the last log closed: in no log (the state file)
    end_notes: list[str] = []
    try:
        signals.install()  # SIGINT, SIGTERM, SIGHUP: the stop sequence (safety.StopSignals)
        if simulate is not None:  # the plant the campaign asks for (robot_rig.sim_params)
            start = start_arm_sim if campaign.plant == "arm" else start_sim
            sim = start(cfg, simulate, campaign, fault_injectors or {})
        bus = open_buses(cfg, simulated=sim is not None)
        io = CycleIO([d.node_id for d in cfg.drives])
        if cfg.clock == "lockstep" and sync_clocked(bus):  # heartbeats paced by SYNC
            io.use_sync_clock(campaign.cycle_s)
        network = canopen.Network(bus)
        network.NOTIFIER_CYCLE = 0.05
        network.listeners.append(io)
        network.connect()
        drives = [MasterDrive(network, d) for d in cfg.drives]
        if cfg.master_heartbeat_ms:
            heartbeat = MasterHeartbeat(bus, cfg.master_node_id, cfg.master_heartbeat_ms)
            heartbeat.start()
        else:
            notes.append("daq.master_heartbeat_ms = 0: the master sends no heartbeat, the "
                         "drives do not watch it")
        tau_maxes = [cfg.max_torque if cfg.max_torque is not None
                     else campaign.joints[c].limits.max_torque
                     for c in drive_joints(campaign, len(drives))]
        scalings = [d.start_up(campaign.cycle_s, tau_max, master_id=cfg.master_node_id,
                               consumer_ms=cfg.heartbeat_consumer_ms,
                               sync_period_us=_sync_period_us(cfg, campaign.cycle_s),
                               rpdo_timeout_ms=rpdo_timeout_ms(
                                   campaign.cycle_s, cfg.clock == "paced", cfg.rpdo_margin_ms))
                    for d, tau_max in zip(drives, tau_maxes, strict=True)]
        if heartbeat is not None:
            heartbeat.beat()  # the drives watch the master from now on, not a period later
        for d in drives:
            notes.extend(d.notes)
        for note in notes:
            logger.warning("%s", note)
        engine = Engine(campaign, cfg, network, io, drives, scalings, load, progress)
        engine.notes = notes
        if monitor is not None:
            engine.monitor = monitor
            monitor.arm = getattr(sim, "arm", None)
        engine.check_drive_limits()
        ask = prompt or prompt_payload
        for n_done, i in enumerate(todo):
            p = campaign.payloads[i]
            if sim is not None:
                sim.set_payload(p)
            if not yes and (n_done > 0 or sim is None or prompt is not None):
                try:  # a stop signal at the prompt interrupts it at once (RunInterrupted)
                    accepted = ask(i, p, n_pay)
                except KeyboardInterrupt as exc:
                    sig = signal.Signals(getattr(exc, "signum", signal.SIGINT)).name
                    status, reason = "interrupted", interrupt_reason(sig)
                    break
                if accepted is None:
                    status, reason = "aborted", (
                        f"no answer at the prompt of payload {i} (standard input closed); "
                        "run with --yes (-y) to mount the payloads without prompts")
                    break
                if not accepted:
                    status, reason = "aborted", f"operator declined payload {i}"
                    break
            path = log_path(out, stem, i)
            if n_done > 0 and (why := check_free_space(path, log_bytes)):
                status, reason = "stopped", why
                break
            if path.exists() and not overwrite:  # (check_logs: resume) kept, never replaced
                logger.warning("%s: kept as %s (payload %d did not complete)", path,
                               keep_partial(path), i)
            create_log_file(path, overwrite)
            if overwrite and i in completed:  # its completed log is replaced: not done now
                completed.discard(i)
                state.logs.pop(i, None)
                write_state(state_file, state)
            # EMCYs since the start-up or the last payload's end (the drive's own report of a
            # fault while no run watched it): logged in this payload's log and reported
            early, io.emcy = io.emcy, []  # (a swap: the listener appends to io.emcy)
            io.hb_time = [io.clock()] * len(drives)
            try:
                for d in drives:
                    d.nmt_start()
            except BUS_ERRORS as exc:  # the bus went away between payloads: nothing moved
                bus_gone = reason = _bus_lost(exc, f" before the run of payload {i}")
                with contextlib.suppress(OSError):
                    path.unlink()  # the empty file create_log_file made: no log was opened
                io.emcy[:0] = early  # in no log: recorded in the state file below
                status = "stopped"
                break
            drive_cycle0 = sim.drives[0].cycle if sim is not None else -1
            try:
                log = RunLog(path, n_axes=len(drives), cycle_s=campaign.cycle_s,
                             metadata=_metadata(campaign, cfg, plan, i, p, scalings, simulate,
                                                str(getattr(bus, "channel_info", "")),
                                                drives, None if sim is None
                                                else sim.torque_delay_cycles, definition),
                             attachments=attachments, chunk_seconds=cfg.chunk_seconds,
                             frames_per_cycle=1 + 3 * len(drives),
                             axis_setpoints=not engine.shared_reference)
            except OSError as exc:  # writing the header: nothing moved yet
                raise DaqError(f"log write failed: {path}: {exc.strerror or exc}") from None
            for dd, code, reg in early:
                why = f"{emcy_text(drives[dd], code, reg)} before the run of payload {i}"
                log.event(0, 0.0, "emcy", why, dd)
                notes.append(f"{why} (logged at cycle 0 of {path.name})")
                logger.warning("%s", why)
            signals.engine = engine  # a stop signal now ends the run with the stop sequence
            try:
                r = engine.run_payload(i, p, plan, log, drive_cycle0)
            finally:
                signals.engine = None
            runs.append(r)
            for note in engine.lateness_notes:  # the start-up check's warning (in the log)
                notes.append(f"{note} (payload {i}, {path.name})")
            if engine.bus_lost:  # nothing can be sent any more: no NMT, no SDO
                status, reason = r.status, r.reason
                break
            try:
                for d in drives:
                    with contextlib.suppress(DaqError):
                        d.nmt_preop()
            except BUS_ERRORS as exc:  # the bus went away as the run ended (its log closed)
                off = ("the drives disabled" if r.stop_cycle >= 0
                       else "the drives did not confirm the stop")
                bus_gone = _bus_lost(exc, f" after the run of payload {i} (its log closed, "
                                          f"{off})")
                end_notes.append(f"{bus_gone}; nothing the drives sent since was seen (an "
                                 f"EMCY, a lost heartbeat)")
            if r.status != "done":
                status, reason = r.status, r.reason
                break
            completed.add(i)
            state.logs[i] = log_record(path)  # what --resume checks is still there
            write_state(state_file, state)
            if bus_gone:  # the payload completed; nothing can be sent any more
                if rest := todo[n_done + 1:]:
                    status, reason = "stopped", f"{bus_gone}; payloads {rest} not run"
                break
            if engine.interrupted:  # a signal as the run ended: it completed, stop here
                status, reason = "interrupted", interrupt_reason(engine.interrupted)
                break
        clean = (engine is None or not engine.bus_lost) and not bus_gone
    except KeyboardInterrupt:  # a stop signal outside a payload run: no drive enabled
        clean = (engine is None or not engine.bus_lost) and not bus_gone
        raise
    finally:
        signals.closing = True  # a second signal does not cut the clean-up short
        if clean:  # normal end, drives disabled: stop watching the master, then go silent
            for d in drives:
                try:
                    note = d.clear_master_heartbeat()
                except BUS_ERRORS as exc:  # the bus went away now: nothing more to send
                    note = (f"{d.name}: heartbeat consumer 0x1016.1 not cleared after the run "
                            f"({_bus_lost(exc)}): nothing the drives sent since was seen")
                    clean = False
                if note:
                    end_notes.append(note)
        if heartbeat is not None:
            with contextlib.suppress(*BUS_ERRORS):  # (a lost bus: nothing to stop)
                heartbeat.stop()
        if sim is not None:
            sim_records = tuple(d.record for d in sim.drives)
        signals.restore()
        if network is not None:
            try:
                network.disconnect()
            except Exception:
                # a bus whose transport died cannot shut down (python-can-remote raises
                # OSError): mark it shut down, or its __del__ tries again at exit
                with contextlib.suppress(Exception):
                    can.BusABC.shutdown(network.bus)
        if sim is not None:
            sim.close()
        after = runs[-1].index if runs else None
        if io is not None and io.emcy:  # in no log: none is open now, and none will be
            for text in keep_emcy_outside_logs(
                    state_file, state, after,
                    [(emcy_text(f"node {cfg.drives[dd].node_id}", code, reg),
                      cfg.drives[dd].node_id, code, reg) for dd, code, reg in io.emcy]):
                notes.append(text)
                logger.warning("%s", text)
        if end_notes:  # the wind-down's warnings: in no log either
            for text in keep_warnings_outside_logs(state_file, state, after, end_notes):
                notes.append(text)
                logger.warning("%s", text)
        if old_affinity is not None:
            with contextlib.suppress(OSError):
                os.sched_setaffinity(0, old_affinity)
        if old_sched is not None:
            with contextlib.suppress(OSError):
                os.sched_setscheduler(0, old_sched[0], os.sched_param(old_sched[1]))
    return CampaignResult(campaign.name, out, tuple(runs), status, reason, load, skipped,
                          sim_records, tuple(notes))
