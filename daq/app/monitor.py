"""``jointid monitor``: run a robot campaign with torque monitoring (docs/monitoring.md).

(Past 600 lines: the command's checks, run, calibration and report read one summary; split,
each part would re-derive the options' meaning.)

MODEL (an ``export-model`` folder, or a fit record whose consistent estimate is taken) gives
the predicted torque (:mod:`ident.monitor`); the campaign runs on its buses (``--simulate``:
the simulated arm) with :class:`daq.runtime.monitor.TorqueMonitor` checking every cycle.
``--residual`` chooses the residual: ``filtered`` (default: measured torque minus the model's,
both low-passed) or ``observer`` (the generalized-momentum observer, gain
``--observer-gain`` [1/s]); a thresholds file holds the residual it was calibrated with and
is refused for the other.

* ``--calibrate``: a validation run without collision; the residual's mean and standard
  deviation per joint, and per bin of the joint's moving time (its regime: time since its
  last reversal, start or rest), give ``OUT/thresholds.json`` (band ``mean +- k sigma``,
  at least the peak times a margin, per bin; a bin with few samples takes the constant
  band).
* otherwise ``--thresholds FILE``: crossings are ``collision`` events in the run log, and
  with ``--stop`` they stop the run (quick stop, disable). ``--push`` stages pushes on the
  simulated arm; the detection delay of each and the crossings outside every push (false
  alarms) are measured.

``OUT`` receives ``logs/*.mcap``, ``monitor.json`` (figures), ``residual_<run>_<joint>.png``
and ``report.html``. Everything is checked before the bus is opened: a bad input is one line
naming the file, option or key.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import html
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

from daq import ConfigError, __version__
from daq.protocol.logformat import MONITOR_EDGES_S as DEFAULT_EDGES_S
from daq.protocol.logformat import MONITOR_OBSERVER_GAIN as DEFAULT_OBSERVER_GAIN
from daq.protocol.logformat import MONITOR_RESIDUALS as RESIDUALS

if TYPE_CHECKING:
    from daq.runtime.monitor import PushSpec, TorqueMonitor
    from ident.report import Section
    from trajectories.robot_campaign import RobotCampaign

# the monitor's modules (scipy, matplotlib, pinocchio, canopen...) are imported by the
# functions that use them: `jointid --help` must not wait seconds for them

__all__ = ["analyse", "load_campaign", "parse_edges", "parse_push", "per_joint", "register",
           "independent_rate", "run_monitor", "stuck_edges"]

#: default --rest-velocity: this many times each joint's Stribeck velocity q_s (E < 5 %)
REST_QS = 3.0
#: defaults of --k-sigma and --peak-margin
DEFAULT_K_SIGMA, DEFAULT_PEAK_MARGIN = 6.0, 1.5
#: a crossing up to this long [s] after a push ended still counts as its detection
AFTER_PUSH_S = 0.5
#: defaults of --persist-cycles (consecutive cycles outside the band for a crossing) and
#: --horizon-s (the monitored duration [s] the validation's peaks are extrapolated to:
#: issue 25's 10 min) of a new calibration
DEFAULT_PERSIST_CYCLES, DEFAULT_HORIZON_S = 2, 600.0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``monitor`` subcommand to the ``jointid`` parser."""
    p = sub.add_parser(
        "monitor", help="run a robot campaign with torque monitoring (collision detection)",
        description="Run a robot campaign and compare every cycle's measured torque with the "
        "identified model's (filtered residual, or a generalized-momentum observer with "
        "--residual observer); thresholds from a validation run "
        "(--calibrate); crossings are collision events in the log, a stop with --stop. "
        "docs/monitoring.md.")
    p.add_argument("model", type=Path, metavar="MODEL",
                   help="folder written by jointid export-model, or a fit record "
                   "(jointid fit --robot --json)")
    p.add_argument("campaign", type=Path, help="robot campaign file (TOML)")
    p.add_argument("-o", "--out", type=Path, required=True, metavar="OUT",
                   help="output folder (logs/, monitor.json, report.html)")
    p.add_argument("--simulate", action="store_true",
                   help="run on the simulated arm of the campaign's robot file")
    p.add_argument("--model", dest="model_name", choices=("usual", "paper"),
                   help="model of a fit record (default: paper when identified)")
    p.add_argument("--payload", type=int, action="append", metavar="K",
                   help="run only payload K (0-based; repeatable)")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--calibrate", action="store_true",
                   help="validation run without collision: write OUT/thresholds.json")
    g.add_argument("--thresholds", type=Path, metavar="FILE",
                   help="thresholds of a --calibrate run")
    p.add_argument("--k-sigma", type=float, default=None,
                   help="band half-width in standard deviations of the validation residual "
                   "(default 6; with --thresholds: the file's)")
    p.add_argument("--peak-margin", type=float, default=None,
                   help="the band is at least this times the validation residual's largest "
                   "deviation (default 1.5, 0: k-sigma alone; with --thresholds: the file's)")
    p.add_argument("--regime-edges", default=None, metavar="S1,S2,...",
                   help="--calibrate: edges [s] of the regime bins on each joint's moving "
                   "time (time since its last reversal, start or rest); default "
                   f"{','.join(f'{e:g}' for e in DEFAULT_EDGES_S)}; 'none': one constant "
                   "band")
    p.add_argument("--constant-band", action="store_true",
                   help="with --thresholds: the file's constant band, not its regime bins "
                   "(the format /1 behaviour)")
    p.add_argument("--cutoff-hz", type=float, default=20.0,
                   help="cut-off of the residual filter [Hz] (default 20; filtered residual)")
    p.add_argument("--residual", choices=RESIDUALS, default="filtered",
                   help="filtered: measured minus predicted torque, both low-passed "
                   "(default); observer: the generalized-momentum observer (no acceleration "
                   "needed). A thresholds file must be of the same residual")
    p.add_argument("--observer-gain", type=float, default=None, metavar="K_O",
                   help="--residual observer: the observer's gain [1/s] (time constant "
                   f"1/K_O; default {DEFAULT_OBSERVER_GAIN:g}; with --thresholds: the file's)")
    p.add_argument("--rest-velocity", type=float, default=None,
                   help="below this |dq| [rad/s] the friction is the static band "
                   f"(default: {REST_QS:g} q_s of each joint, the Stribeck region)")
    p.add_argument("--stuck-velocity", type=float, default=None, metavar="V",
                   help="--calibrate: a regime bin of its own for a joint whose measured |dq| "
                   "is at most V [rad/s] (held by its static friction; 0: the drive reads "
                   "zero); recorded in the thresholds file. Default: no such bin")
    p.add_argument("--persist-cycles", type=int, default=None, metavar="N",
                   help="--calibrate: a crossing counts when the residual has been outside "
                   f"its band for N consecutive cycles (default {DEFAULT_PERSIST_CYCLES}); "
                   "the peaks are of that statistic; recorded in the thresholds file")
    p.add_argument("--horizon-s", type=float, default=None, metavar="S",
                   help="--calibrate: extrapolate the validation's peaks to S seconds of "
                   f"monitoring (default {DEFAULT_HORIZON_S:g}; 0: not extrapolated); "
                   "recorded in the thresholds file")
    p.add_argument("--push", action="append", default=[], metavar="JOINT:FORCE:T0[:DT]",
                   help="simulated arm: push the link of JOINT with FORCE [N] from T0 [s] "
                   "after the run starts for DT [s] (default 0.2); repeatable")
    p.add_argument("--stop", action="store_true",
                   help="a crossing stops the run (quick stop, disable)")
    p.add_argument("--paced", action="store_true",
                   help="real-time clock (daq.clock = 'paced'): cycles on the wall clock")
    p.set_defaults(func=_run)


def stuck_edges(edges: tuple[float, ...], residual: str, cutoff_hz: float,
                gain: float) -> tuple[float, ...]:
    """The regime edges [s] with the stuck bins in front (``--stuck-velocity``): ``(-T, 0,
    *edges)``, T [s] the residual's settling time after the joint stops (the filters' 4 /
    (zeta omega_n), 45 ms at 20 Hz; the observer's 4 / K_O): bin 0 holds a joint stuck for
    longer than T (its own statistics: the static band's), bin 1 the first T of each hold
    (the transient of the stop)."""
    settle = 4.0 / gain if residual == "observer" else 4.0 / (2 ** -0.5 * 2 * math.pi
                                                                * cutoff_hz)
    return (-round(settle, 4), 0.0, *edges)


def independent_rate(residual: str, cutoff_hz: float, gain: float) -> float:
    """About how many independent values per second [1/s] the residual has: twice its
    bandwidth, 2 f_c for the filtered residual, K_O / pi for the observer's first-order
    low-pass (bandwidth K_O / (2 pi)); the horizon's extrapolation counts them
    (``ident.monitor.horizon_factor``)."""
    return gain / math.pi if residual == "observer" else 2.0 * cutoff_hz


def parse_edges(text: str) -> tuple[float, ...]:
    """``--regime-edges``: increasing seconds > 0 separated by commas, or ``none`` (no
    bins: the constant band alone).

    Raises
    ------
    ConfigError
        Not of that form.
    """
    if text.strip().lower() == "none":
        return ()
    try:
        edges = tuple(float(x) for x in text.split(","))
    except ValueError:
        edges = ()
    if not edges or any(not e > 0 for e in edges) or list(edges) != sorted(set(edges)):
        raise ConfigError(f"--regime-edges {text!r}: expected increasing seconds > 0 "
                          "separated by commas, or 'none'")
    return edges


def parse_push(text: str, joints: list[str]) -> PushSpec:
    """``JOINT:FORCE:T0[:DT]`` -> :class:`PushSpec` (JOINT a moving joint's name).

    Raises
    ------
    ConfigError
        Not of that form, an unknown joint, a force or duration not > 0, T0 < 0.
    """
    from daq.runtime.monitor import PushSpec

    parts = text.split(":")
    try:
        if len(parts) not in (3, 4):
            raise ValueError
        force, t0 = float(parts[1]), float(parts[2])
        dt = float(parts[3]) if len(parts) == 4 else 0.2
    except ValueError:
        raise ConfigError(f"--push {text!r}: expected JOINT:FORCE_N:T0_S[:DURATION_S]"
                          ) from None
    if parts[0] not in joints:
        raise ConfigError(f"--push {text!r}: joint {parts[0]!r}: expected one of "
                          f"{', '.join(joints)}")
    if not (force > 0 and dt > 0 and t0 >= 0):
        raise ConfigError(f"--push {text!r}: expected FORCE > 0, T0 >= 0, DURATION > 0")
    return PushSpec(joints.index(parts[0]), force, t0, dt)


def analyse(monitor: TorqueMonitor, cycle_s: float) -> list[dict[str, Any]]:
    """Per run: each push's detection (first crossing from its staging to
    :data:`AFTER_PUSH_S` after its end: delay [s], joint) and the crossings outside every
    push window (false alarms)."""
    out = []
    for rec in monitor.records:
        windows = [(c, c + int(round((s.duration_s + AFTER_PUSH_S) / cycle_s)), s)
                   for c, s in rec.staged]
        pushes, used = [], set()
        for c0, c1, spec in windows:
            hits = [(c, j, r) for c, j, r in rec.detections if c0 <= c <= c1]
            first = min(hits, default=None)
            used.update(hits)
            pushes.append({
                "joint": monitor.joints[spec.joint], "force_N": spec.force_N,
                "t0_s": spec.t0_s, "duration_s": spec.duration_s, "cycle": c0,
                "detected": first is not None,
                "delay_s": None if first is None else (first[0] - c0) * cycle_s,
                "by_joint": None if first is None else monitor.joints[first[1]],
                "joints_crossed": sorted({monitor.joints[j] for _, j, _ in hits})})
        false = [{"cycle": c, "joint": monitor.joints[j], "residual": r}
                 for c, j, r in rec.detections if (c, j, r) not in used]
        out.append({"payload": rec.index, "cycles": rec.cycles,
                    "armed_s": rec.armed_cycles * cycle_s, "pushes": pushes,
                    "false_alarms": false, "step_us_mean": 1e6 * rec.step_s_total
                    / max(rec.cycles, 1), "step_us_max": 1e6 * rec.step_s_max})
    return out


def per_joint(monitor: TorqueMonitor, logs: list[Path], runs: list[dict[str, Any]],
              cycle_s: float) -> list[dict[str, Any]]:
    """Per joint, over the runs (:func:`analyse`'s ``runs``, their logs): the band
    half-widths the check used [N m] (smallest, largest), the pushes on its link (detected,
    delays [s]), its false alarms, and its largest ``|r - centre| / half-width`` over the
    armed cycles outside every push window (1: on the threshold)."""
    from daq.runtime.monitor import read_monitor

    k = monitor.k
    worst, hw_min, hw_max = [0.0] * k, [np.inf] * k, [0.0] * k
    for rec, path in zip(monitor.records, logs, strict=False):
        ml = read_monitor(path)
        inside = np.zeros(len(ml.cycle), bool)
        for c0, spec in rec.staged:
            c1 = c0 + int(round((spec.duration_s + AFTER_PUSH_S) / cycle_s))
            inside |= (ml.cycle >= c0) & (ml.cycle <= c1)
        sel = ml.armed & ~inside
        half = (ml.upper - ml.lower) / 2
        if not sel.any() or not np.isfinite(half[sel]).all():
            continue
        mid = (ml.upper + ml.lower) / 2
        x = (np.abs(ml.residual[sel] - mid[sel]) / half[sel]).max(axis=0)
        for j in range(k):
            worst[j] = max(worst[j], float(x[j]))
            hw_min[j] = min(hw_min[j], float(half[ml.armed, j].min()))
            hw_max[j] = max(hw_max[j], float(half[ml.armed, j].max()))
    out = []
    for j, name in enumerate(monitor.joints):
        ps = [p for run in runs for p in run["pushes"] if p["joint"] == name]
        out.append({
            "joint": name,
            "half_width_Nm": [hw_min[j], hw_max[j]] if np.isfinite(hw_min[j]) else None,
            "pushes": len(ps), "detected": sum(p["detected"] for p in ps),
            "delays_s": [p["delay_s"] for p in ps if p["detected"]],
            "false_alarms": sum(f["joint"] == name for run in runs
                                for f in run["false_alarms"]),
            "worst_fraction_of_band": worst[j]})
    return out


def load_campaign(path: Path, paced: bool = False) -> RobotCampaign:
    """The robot campaign of ``path``; ``paced``: on the real-time clock."""
    from trajectories.campaign_file import load_any_campaign

    campaign = load_any_campaign(path)
    if campaign.plant != "arm":
        raise ConfigError(f"{path}: expected a robot campaign ([robot] table with a robot "
                          "file), got a single-joint [joint] campaign")
    if paced:
        campaign = dataclasses.replace(campaign, daq={**dict(campaign.daq), "clock": "paced"})
    return campaign


def run_monitor(model: Path, campaign_path: Path, out: Path, *, simulate: bool = False,
                model_name: str | None = None, payloads: list[int] | None = None,
                calibrate: bool = False, thresholds: Path | None = None,
                k_sigma: float | None = None, peak_margin: float | None = None,
                regime_edges: str | None = None, constant_band: bool = False,
                cutoff_hz: float = 20.0, residual: str = "filtered",
                observer_gain: float | None = None,
                rest_velocity: float | None = None, stuck_velocity: float | None = None,
                persist_cycles: int | None = None, horizon_s: float | None = None,
                pushes: list[str] | None = None,
                stop: bool = False, paced: bool = False,
                stream: TextIO | None = None) -> dict[str, Any]:
    """``jointid monitor`` (module docstring); returns the content of ``monitor.json``.

    Raises
    ------
    daq.ConfigError, ident.IdentError, trajectories.TrajectoryError
        Bad input (one line), before the bus is opened.
    """
    from daq.runtime.monitor import TorqueMonitor, read_monitor
    from ident.monitor import (
        DEFAULT_MIN_EPISODES,
        DEFAULT_MIN_SAMPLES,
        Thresholds,
        load_model,
        thresholds_from_residual,
    )
    from ident.report import write_json
    from trajectories.robot_model import robot_for_campaign

    from .running import run_with_bar

    stream = stream if stream is not None else sys.stderr
    if out.exists() and not out.is_dir():
        raise ConfigError(f"-o {out}: is a file, expected a folder")
    if thresholds is not None and thresholds.resolve().parent == out.resolve():
        # the calibration's logs, monitor.json and report would be replaced by this run's
        raise ConfigError(f"-o {out}: holds the calibration run of --thresholds {thresholds}; "
                          f"expected another folder (this run would replace its logs, "
                          f"monitor.json and report.html)")
    campaign = load_campaign(campaign_path, paced)
    joints = list(campaign.moving)
    specs = [parse_push(p, joints) for p in pushes or []]
    if specs and not simulate:
        raise ConfigError("--push: expected --simulate (pushes are staged on the simulated "
                          "arm)")
    if calibrate and (specs or stop):
        raise ConfigError("--calibrate: a validation run takes no --push and no --stop")
    if rest_velocity is not None and not rest_velocity >= 0:
        raise ConfigError(f"--rest-velocity: expected a number >= 0, got {rest_velocity}")
    if stuck_velocity is not None and not (calibrate and stuck_velocity >= 0):
        raise ConfigError(f"--stuck-velocity: expected --calibrate and a number >= 0 [rad/s], "
                          f"got {stuck_velocity} (a thresholds file holds its own)")
    if persist_cycles is not None and not (calibrate and persist_cycles >= 1):
        raise ConfigError(f"--persist-cycles: expected --calibrate and an integer >= 1, got "
                          f"{persist_cycles} (a thresholds file holds its own)")
    if horizon_s is not None and not (calibrate and horizon_s >= 0):
        raise ConfigError(f"--horizon-s: expected --calibrate and a number >= 0 [s], got "
                          f"{horizon_s} (a thresholds file holds its own)")
    if k_sigma is not None and not k_sigma > 0:
        raise ConfigError(f"--k-sigma: expected a number > 0, got {k_sigma}")
    if peak_margin is not None and not peak_margin >= 0:
        raise ConfigError(f"--peak-margin: expected a number >= 0, got {peak_margin}")
    if regime_edges is not None and not calibrate:
        raise ConfigError("--regime-edges: expected --calibrate (the bins are the "
                          "thresholds file's)")
    if constant_band and calibrate:
        raise ConfigError("--constant-band: expected --thresholds")
    if residual not in RESIDUALS:
        raise ConfigError(f"--residual {residual!r}: expected one of {', '.join(RESIDUALS)}")
    if observer_gain is not None and residual != "observer":
        raise ConfigError("--observer-gain: expected --residual observer")
    if observer_gain is not None and not 0 < observer_gain * campaign.cycle_s < 1:
        raise ConfigError(f"--observer-gain: expected 0 < K_O < {1 / campaign.cycle_s:g} "
                          f"[1/s] (1 / the campaign's cycle), got {observer_gain}")
    edges = DEFAULT_EDGES_S if regime_edges is None else parse_edges(regime_edges)
    v_stuck = None if stuck_velocity is None else [stuck_velocity] * len(joints)
    robot = robot_for_campaign(campaign)
    exported = load_model(model, robot, model_name)
    pred0 = exported.predictor(None)
    if pred0.names != joints:
        raise ConfigError(f"{model}: joints {pred0.names}, the campaign's are {joints}")
    v_rest = ([REST_QS * q for q in pred0.q_s] if rest_velocity is None
              else [rest_velocity] * len(joints))
    if not all(v >= 0 for v in v_rest):
        raise ConfigError(f"{model}: friction q_s: expected numbers >= 0")
    th = None
    if thresholds is not None:
        th = Thresholds.read(thresholds)
        if list(th.joints) != joints:
            raise ConfigError(f"{thresholds}: joints {list(th.joints)}, the campaign's are "
                              f"{joints}")
        if th.residual != residual:
            raise ConfigError(f"{thresholds}: calibrated with the {th.residual} residual, "
                              f"expected the {residual} one (--residual {th.residual}, or "
                              f"--calibrate with --residual {residual})")
        if (residual == "observer" and observer_gain is not None
                and observer_gain != th.observer_gain):
            raise ConfigError(f"{thresholds}: observer gain {th.observer_gain:g} 1/s, expected "
                              f"--observer-gain {observer_gain:g} (the thresholds hold only "
                              "for their gain)")
        if residual == "observer":
            observer_gain = th.observer_gain
        th = th.with_k(k_sigma, peak_margin)
        if constant_band:
            th = th.constant()
        v_stuck = list(th.stuck_velocity) or None

    gain = (DEFAULT_OBSERVER_GAIN if observer_gain is None else observer_gain
            ) if residual == "observer" else 0.0
    if calibrate and v_stuck is not None:  # bins 0, 1: the joint held by its static friction
        edges = stuck_edges(edges, residual, cutoff_hz, gain)

    def predictor_for(payload: Any) -> Any:
        pred = exported.predictor(payload)
        if residual == "observer":
            return functools.partial(pred.observer_terms, v_rest=v_rest)
        return functools.partial(pred.band, v_rest=v_rest)

    lower, upper = (None, None) if th is None else th.bands()
    mon = TorqueMonitor(predictor_for, joints, campaign.cycle_s, lower=lower, upper=upper,
                        edges_s=() if th is None else th.edges_s, rest_velocity=v_rest,
                        cutoff_hz=cutoff_hz, stop=stop, pushes=specs, residual=residual,
                        observer_gain=gain or DEFAULT_OBSERVER_GAIN,
                        stuck_velocity=v_stuck,
                        persist_cycles=1 if th is None else th.persist_cycles)
    out.mkdir(parents=True, exist_ok=True)
    result, wall = run_with_bar(campaign, out / "logs", True if simulate else None, stream,
                                payloads=payloads, monitor=mon)
    logs = [r.path for r in result.runs]
    summary: dict[str, Any] = {
        "campaign": str(campaign_path), "model": exported.source, "joints": joints,
        "cycle_s": campaign.cycle_s, "clock": campaign.daq.get("clock", "default"),
        "cutoff_hz": cutoff_hz, "residual": residual, "observer_gain": gain or None,
        "rest_velocity": v_rest, "stuck_velocity": v_stuck, "status": result.status,
        "reason": result.reason,
        "wall_s": wall, "missed_cycles": [r.missed for r in result.runs],
        "logs": [str(p.relative_to(out)) for p in logs]}
    if calibrate and result.status != "done":
        # thresholds from a run cut short (Ctrl-C, a fault, a lost bus) would hold only its
        # first cycles: not written, and an older thresholds.json of the folder goes too
        (out / "thresholds.json").unlink(missing_ok=True)
        summary["thresholds"] = None
        summary["calibration"] = (f"not written: the validation run ended {result.status} "
                                  f"({result.reason}); run --calibrate again")
    elif calibrate:
        res, mov = [], []
        for p in logs:
            ml = read_monitor(p)
            res.append(ml.residual[ml.armed])
            mov.append(ml.moving_s[ml.armed])
        th = thresholds_from_residual(np.concatenate(res), joints,
                                      DEFAULT_K_SIGMA if k_sigma is None else k_sigma,
                                      ", ".join(summary["logs"]),
                                      DEFAULT_PEAK_MARGIN if peak_margin is None
                                      else peak_margin,
                                      np.concatenate(mov) if edges else None, edges,
                                      DEFAULT_MIN_SAMPLES, DEFAULT_MIN_EPISODES,
                                      kind=residual, observer_gain=gain,
                                      stuck_velocity=v_stuck,
                                      persist_cycles=(DEFAULT_PERSIST_CYCLES
                                                      if persist_cycles is None
                                                      else persist_cycles),
                                      horizon_s=(DEFAULT_HORIZON_S if horizon_s is None
                                                 else horizon_s),
                                      cycle_s=campaign.cycle_s,
                                      independent_per_s=independent_rate(residual,
                                                                         cutoff_hz, gain))
        write_json(out / "thresholds.json", th.to_json())
        summary["thresholds"] = th.to_json()
    else:
        summary["thresholds"] = th.to_json() if th is not None else None
        summary["runs"] = analyse(mon, campaign.cycle_s)
        summary["per_joint"] = per_joint(mon, logs, summary["runs"], campaign.cycle_s)
    summary["report"] = str(_report(out, logs, summary, mon).relative_to(out))
    write_json(out / "monitor.json", summary)
    return summary


def _plot(ml: Any, joints: list[str], path: Path, j: int, stage: list) -> None:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 3.2))
    ax.plot(ml.t, ml.residual[:, j], lw=0.7, label="residual")
    if np.isfinite(ml.upper[:, j]).any():
        ax.plot(ml.t, ml.upper[:, j], "r--", lw=0.8, label="thresholds")
        ax.plot(ml.t, ml.lower[:, j], "r--", lw=0.8)
    for t0, dt in stage:
        ax.axvspan(t0, t0 + dt, color="orange", alpha=0.3)
    hits = [e["t"] for e in ml.events if e["kind"] == "collision" and e["axis"] == j]
    if hits:
        ax.plot(hits, np.interp(hits, ml.t, ml.residual[:, j]), "kv", label="crossing")
    ax.set_xlabel("campaign time [s]")
    ax.set_ylabel(f"{joints[j]} residual [N m]")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _report(out: Path, logs: list[Path], summary: dict[str, Any], mon: TorqueMonitor
            ) -> Path:
    import matplotlib

    from daq.runtime.monitor import read_monitor
    from ident.report import Section, write_html

    matplotlib.use("Agg")
    joints = summary["joints"]
    what = (f"residual = measured torque minus the model's, both low-passed at "
            f"{summary['cutoff_hz']:g} Hz" if summary["residual"] == "filtered" else
            "residual = minus the generalized-momentum observer's external torque (gain "
            f"{summary['observer_gain']:g} 1/s)")
    intro = Section("What was run").para(
        f"Campaign {summary['campaign']}, model {summary['model']}; {what} "
        f"(static friction band below |dq| = "
        f"{', '.join(f'{v:.3g}' for v in summary['rest_velocity'])} rad/s). Status: "
        f"{summary['status']} {summary['reason']}; missed cycles per run: "
        f"{summary['missed_cycles']}.")
    sections = [intro]
    th = summary.get("thresholds")
    if th:
        sections.append(Section("Thresholds").para(
            f"Constant band: mean +- max({th['k_sigma']:g}, {th['peak_margin']:g} peak) "
            f"sigma of the validation residual. {_rule_text(th)}").table(
            ["joint", "mean [N m]", "sigma [N m]", "k", "lower", "upper", "peak/sigma"],
            [[j, f"{m:.4g}", f"{s:.4g}", f"{th['k_sigma']:g}", f"{lo:.4g}", f"{hi:.4g}",
              f"{pk:.3g}"] for j, m, s, lo, hi, pk in zip(
                joints, th["mean"], th["sigma"], th["lower"], th["upper"],
                th["peak_sigmas"], strict=True)]))
        if th.get("regime"):
            sections.append(_regime_section(th["regime"], joints))
    rows = []
    for run in summary.get("runs", []):
        for p in run["pushes"]:
            rows.append([run["payload"], p["joint"], f"{p['force_N']:g}", f"{p['t0_s']:g}",
                         "yes" if p["detected"] else "NO",
                         "—" if p["delay_s"] is None else f"{1000 * p['delay_s']:.0f}",
                         ", ".join(p["joints_crossed"]) or "—"])
    if rows:
        sections.append(Section("Pushes").para(
            "Delay: from the cycle the push was staged to the first crossing (any joint).")
            .table(["payload", "pushed link", "force [N]", "t0 [s]", "detected",
                    "delay [ms]", "joints crossed"], rows))
    if summary.get("per_joint"):
        sections.append(Section("Per joint").para(
            "Band half-width the check used (smallest..largest over the regimes met), the "
            "pushes on the joint's link (detected of staged, delays), the joint's crossings "
            "outside every push window (false alarms), and its largest |residual - band "
            "centre| / half-width outside the push windows (1 = on the threshold).").table(
            ["joint", "band half-width [N m]", "pushes detected", "delays [ms]",
             "false alarms", "largest excursion / band"],
            [[d["joint"], "—" if d["half_width_Nm"] is None else
              f"{d['half_width_Nm'][0]:.3g}..{d['half_width_Nm'][1]:.3g}",
              f"{d['detected']}/{d['pushes']}",
              ", ".join(f"{1000 * t:.0f}" for t in d["delays_s"]) or "—",
              d["false_alarms"], f"{d['worst_fraction_of_band']:.2f}"]
             for d in summary["per_joint"]]))
    if "runs" in summary:
        fa = [[run["payload"], f"{run['armed_s']:.1f}", len(run["false_alarms"]),
               f"{run['step_us_mean']:.0f}", f"{run['step_us_max']:.0f}"]
              for run in summary["runs"]]
        sections.append(Section("False alarms and cost").table(
            ["payload", "monitored [s]", "false alarms", "check mean [us]",
             "check max [us]"], fa))
    for i, p in enumerate(logs):
        ml = read_monitor(p)
        rec = mon.records[i] if i < len(mon.records) else None
        stage = [(c * summary["cycle_s"], s.duration_s) for c, s in rec.staged] if rec else []
        sec = Section(f"Run {p.name}")
        for j, name in enumerate(joints):
            fig = out / f"residual_{i}_{name}.png"
            _plot(ml, joints, fig, j, stage)
            sec.figure(fig, f"{name}: residual, thresholds, pushes (orange), crossings")
        sections.append(sec)
    sections.append(Section("Summary").raw(
        f"<pre>{html.escape(json.dumps(summary, indent=1, default=str)[:20000])}</pre>"))
    return write_html(out / "report.html", "jointid monitor",
                      f"jointid {__version__} — torque monitoring", sections)


def _rule_text(th: dict[str, Any]) -> str:
    """The crossing rule of a thresholds record, in a sentence."""
    p = int(th.get("persist_cycles", 1))
    hz = th.get("horizon")
    return ((f"A crossing counts after {p} consecutive cycles out of the band; the peaks are "
             "of that statistic" if p > 1 else "A crossing counts at its first cycle out of "
             "the band")
            + (f", extrapolated from the validation's {hz['validation_s']:.1f} s to "
               f"{hz['horizon_s']:g} s of monitoring." if hz else "."))


def _bin_names(edges: list[float]) -> list[str]:
    """Column titles of the regime bins: moving-time ranges [s]."""
    b = [0.0, *edges]
    return [f"{lo:g}-{hi:g} s" for lo, hi in zip(b[:-1], b[1:], strict=True)] + [
        f">= {b[-1]:g} s"]


def _regime_section(reg: dict[str, Any], joints: list[str]) -> Section:
    """Half-width [N m], samples and episodes of the regime bins per joint ('*': too few,
    pooled with the shorter bins or the constant band)."""
    from ident.report import Section

    rows = []
    for j, name in enumerate(joints):
        rows.append([name] + [
            f"{(hi - lo) / 2:.3g}{'' if own else '*'} ({n}, {e})" for lo, hi, own, n, e in zip(
                reg["lower"][j], reg["upper"][j], reg["own"][j], reg["samples"][j],
                reg["episodes"][j], strict=True)])
    return Section("Thresholds per regime").para(
        "Band half-width [N m] (validation samples, episodes) per bin of the joint's moving "
        "time (time its filtered velocity has kept its sign above the rest velocity: 0 at "
        f"rest, at a reversal, at breakaway). *: fewer than {reg['min_samples']} samples "
        f"or {reg['min_episodes']} episodes, " + (
            "pooled with the nearest shorter bins that make enough, within the constant "
            "band" if reg.get("thin_bins") == "pooled" else "the constant band")
        + ".").table(
            ["joint", *_bin_names(reg["edges_s"])], rows)


def _run(args: argparse.Namespace) -> int:
    s = run_monitor(args.model, args.campaign, args.out, simulate=args.simulate,
                    model_name=args.model_name, payloads=args.payload,
                    calibrate=args.calibrate, thresholds=args.thresholds,
                    k_sigma=args.k_sigma, peak_margin=args.peak_margin,
                    regime_edges=args.regime_edges, constant_band=args.constant_band,
                    cutoff_hz=args.cutoff_hz, residual=args.residual,
                    observer_gain=args.observer_gain,
                    rest_velocity=args.rest_velocity,
                    stuck_velocity=args.stuck_velocity,
                    persist_cycles=args.persist_cycles, horizon_s=args.horizon_s,
                    pushes=args.push, stop=args.stop,
                    paced=args.paced)
    print(format_summary(s))
    if s["status"] == "interrupted":  # Ctrl-C: exit 128 + the signal (130), as jointid run
        from daq.runtime.safety import RunInterrupted, interrupt_signal

        raise RunInterrupted(interrupt_signal(s["reason"]),
                             f"the monitor run stopped; its log is closed in {args.out}")
    return 0 if s["status"] == "done" or args.stop else 1


def format_summary(s: dict[str, Any]) -> str:
    """Lines for the terminal."""
    kind = ("observer residual, K_O " f"{s['observer_gain']:g} 1/s"
            if s.get("residual") == "observer" else "filtered residual")
    lines = [f"monitor ({kind}): {s['status']} {s['reason']}".rstrip() + f"; missed cycles "
             f"{s['missed_cycles']}"]
    if s.get("calibration"):
        lines.append(f"thresholds {s['calibration']}")
    th = s.get("thresholds")
    if th:
        lines.append("thresholds, constant band [N m]: " + ", ".join(
            f"{j} {lo:+.3g}..{hi:+.3g}" for j, lo, hi in zip(
                s["joints"], th["lower"], th["upper"], strict=True)))
        reg = th.get("regime")
        if reg:
            lines.append(f"  per regime (moving time bins {_bin_names(reg['edges_s'])}), "
                         "half-width [N m]: " + "; ".join(
                             f"{j} " + " ".join(f"{(b - a) / 2:.3g}" for a, b in zip(
                                 lo, hi, strict=True))
                             for j, lo, hi in zip(s["joints"], reg["lower"], reg["upper"],
                                                  strict=True)))
    for run in s.get("runs", []):
        for p in run["pushes"]:
            lines.append(f"payload {run['payload']}: push {p['force_N']:g} N on {p['joint']}"
                         f" at {p['t0_s']:g} s: " + (
                             f"detected after {1000 * p['delay_s']:.0f} ms ({p['by_joint']})"
                             if p["detected"] else "NOT detected"))
        lines.append(f"payload {run['payload']}: {len(run['false_alarms'])} false alarm(s) "
                     f"in {run['armed_s']:.1f} s monitored; check {run['step_us_mean']:.0f} "
                     f"us mean, {run['step_us_max']:.0f} us max")
    lines.append(f"report: {s['report']}")
    return "\n".join(lines)
