"""Torque monitoring on a simulated robot (docs/monitoring.md, issue 25).

(Past 600 lines: the stages share the campaign derivation, the offline replay and the
band evaluation, and the bench stays one file run as a script.)

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_monitor.py --work DIR \
        [--campaign examples/campaign_ur10_demo.toml] STAGE [STAGE ...]

``--campaign`` is the robot campaign the stages derive theirs from (default the 3-dof demo,
examples/campaign_robot3_demo.toml; e.g. the UR10's, examples/campaign_ur10_demo.toml): its
robot, drives, gains, limits, payloads and segments; the derived campaigns change only the
seeded multi-sine's seed and number of periods (a multi-sine with given coefficients, e.g.
the slow pan of examples/campaign_ur10_lowspeed.toml, is kept as it is, like a trapezoid),
keep the seeded multi-sine alone (detect, paced) and the first payload alone (detect,
paced). Use one DIR per campaign.

Stages (each a ``jointid monitor`` run through the whole stack: campaign -> runner ->
canopen master -> virtual buses -> simulated CiA 402 drives + simulated arm -> MCAP; lockstep
clock unless said, i.e. simulated time):

``model``
    The identified model: ``jointid run`` of the campaign on the simulated arm (all its
    payloads), ``jointid fit --robot`` (its robot file; both models, consistent estimate,
    ``--no-prune``: a monitor wants the best predictor, docs/monitoring.md; ``--prune``: the
    fit's default pruning),
    ``jointid export-model`` (paper model) -> DIR/model.
``calibrate``
    The validation run: the campaign with another multi-sine (seed 3, or the next free one
    when the campaign's is 3: ``_other_seed``; as many periods; the
    campaign itself would repeat the model's logs bit for bit in lockstep) with the monitor
    in calibration mode ->
    DIR/calibrate/thresholds.json (k = 6 sigma, at least 1.5 x the validation peak; per
    regime bin of the moving time, and the constant band).
``false``
    At least ``--false-minutes`` (default 10) of excitation without pushes: the campaign
    with another multi-sine (seed 7, ``--false-seed``) of as many periods as that takes
    over all payloads (``--false-periods`` to set them); the monitor logs its residual, and
    the crossings of the calibration's thresholds are counted on it (the thresholds do not
    change the residual, so counting them on the log, with its moving time, is what the
    live check would count), for the regime bands and for the constant band.
``detect``
    Pushes of 20 N and 40 N on the link of every moving joint (default point and direction
    of ``sim_drivers.arm_push.staged_push``) for 0.2 s, every 1.5 s (3 per link and force,
    links in turn), during a multi-sine of all joints (seed 5, as many periods as the pushes
    take; the pushes fall at whatever speed the joints have then), with the calibration's
    thresholds (regime bands, live): detection and delay per pushed link (from the cycle
    the push is staged to the first crossing on any joint), crossings outside the push
    windows; per push, the joint torques J^T F of the push (at the logged q), the largest
    |r - centre| / half-width per joint in its window and the moving time of each joint
    at the push. The same log evaluated offline with the constant band (the /1 rule) and
    with the regime bands (must equal the live result).
``oracle``
    The logs of calibrate, false and detect re-evaluated offline with the simulator's own
    parameters as the model (the best an identification could give; the replay gives the
    logged residual exactly with the logged model): thresholds, false alarms, detection.
    Separates what the identified model costs from what the monitor itself can do.
``observer``
    Offline, on the logs of calibrate, false and detect (no simulator run): the filtered
    residual and the generalized-momentum observer's (``--observer-gain`` K_O [1/s]) side by
    side, each with the identified model and with the simulator's own parameters (oracle):
    thresholds from the calibrate logs by the live rule, false alarms and the largest
    excursion / band on the false logs, the detect log's pushes (detected, delays, crossings
    outside them). The identified filtered figures are checked against those the stages
    recorded (``check_against_recorded``: the comparison is on equal terms). With
    ``--results FILE`` the figures go to FILE (the work folder is only read);
    ``--thin-bins constant`` calibrates with the rule before the pooled thin bins.
``paced``
    ``--paced-seconds`` of the demo's multi-sine on the real-time clock (daq.clock = paced,
    1 kHz) with the monitor checking every cycle, then the same run without the monitor,
    ``--paced-repeat`` pairs interleaved (``--realtime P``: daq.realtime_priority = P, pinned
    to the last CPU): missed cycles (SYNC more than half a period late), the lateness
    percentiles and busy times from each log's ``/timing``, how many misses followed a
    cycle longer than the period (the loop's own work; else the loop woke late: the host),
    the 1-min load average of each run and the time the hypervisor stole from each CPU
    during it (/proc/stat), the monitor's time per cycle.
``report``
    Prints the figures of the stages run so far (also written to DIR/bench_monitor.json).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import os
import re
import statistics
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from daq.app.monitor import (
    AFTER_PUSH_S,
    DEFAULT_HORIZON_S,
    DEFAULT_K_SIGMA,
    DEFAULT_PEAK_MARGIN,
    DEFAULT_PERSIST_CYCLES,
    REST_QS,
    independent_rate,
    load_campaign,
    run_monitor,
)
from daq.app.running import run_with_bar
from daq.protocol.reader import read_run, read_topics
from daq.runtime.monitor import (
    DEFAULT_OBSERVER_GAIN,
    RESIDUALS,
    moving_seconds,
    read_monitor,
    residual_for,
)
from ident.monitor import (
    THIN_BINS,
    ExportedModel,
    Thresholds,
    load_exported,
    persistent,
    thresholds_from_residual,
)
from ident.robot.export_model import friction_record, urdf_text
from sim_drivers.arm import ArmParams
from sim_drivers.arm_push import push_torque, staged_push
from trajectories.multi import plan_robot_campaign
from trajectories.robot_model import robot_for_campaign

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "examples" / "campaign_robot3_demo.toml"
#: the campaign the stages derive theirs from (``--campaign``; set by :func:`main`)
SOURCE = {"campaign": DEMO}
#: push schedule of the detect stage: first push [s], spacing [s], duration [s], forces [N]
PUSH_T0_S, PUSH_EVERY_S, PUSH_S, PUSH_FORCES_N, PUSHES_PER_FORCE = 1.0, 1.5, 0.2, (20, 40), 3


def _source() -> tuple[Path, object]:
    """The source campaign file and its :class:`RobotCampaign`."""
    path = SOURCE["campaign"]
    return path, load_campaign(path)


def _robot_file(path: Path) -> str:
    """The robot file of campaign ``path`` as written there, made absolute (a relative path
    is relative to the campaign file; ``example-robot-data:...`` kept)."""
    m = re.search(r'^file = "([^"]+)"', path.read_text(), re.M)
    if m is None:
        raise SystemExit(f"{path}: robot.file: not found")
    f = m.group(1)
    if ":" in f and not Path(f).is_absolute() and not Path(f).exists():
        return f  # example-robot-data:NAME
    return (path.parent / f).resolve().as_posix()


def _multisine_periods(segments_s: float, total_s: float) -> int:
    """Periods of the multi-sine(s) (``segments_s`` [s] per period, all of them) for a run
    of at least ``total_s`` [s] besides the rest of the plan."""
    return max(1, math.ceil(total_s / segments_s))


def _multisines() -> list:
    """The source campaign's seeded multi-sine segments (the stages vary their seed and
    periods; a multi-sine with given coefficients ``a``, ``b`` is a fixed part of the plan,
    like a trapezoid)."""
    _, c = _source()
    ms = [s for s in c.segments if type(s).__name__ == "MultisineSegment" and s.a is None]
    if not ms:
        raise SystemExit(f"{SOURCE['campaign']}: no multi-sine segment to derive the "
                         "stages' campaigns from")
    return ms


def _plan_parts() -> tuple[float, float]:
    """(the source campaign's plan duration without its multi-sines [s], one period of all
    its multi-sines [s]); the plan is the one ``jointid run`` plays (no optimisation needed:
    the coefficients change the motion, not the durations)."""
    _, c = _source()
    plan = plan_robot_campaign(c)
    ms = _multisines()
    one = sum(s.period_s for s in ms)
    return plan.duration_s - sum(s.period_s * s.periods for s in ms), one


def _campaign(work: Path, name: str, *, seed: int, periods: int, multisine_only: bool,
              payloads: int = 2, daq: str = "") -> Path:
    """A variant of the source campaign (its robot, drives, gains, limits): every seeded
    multi-sine (not one with given ``a``, ``b``: kept as it is) with ``seed`` and
    ``periods``; ``multisine_only``: no other segment;
    ``payloads`` 1: the first payload only (else all of the campaign's)."""
    src = SOURCE["campaign"]
    text = src.read_text()
    base = load_campaign(src).name
    text = re.sub(r'^file = "[^"]+"', f'file = "{_robot_file(src)}"', text, count=1,
                  flags=re.M)
    text = re.sub(r'^name = "[^"]+"', f'name = "{base}-{name.rsplit("-", 1)[-1]}"', text,
                  count=1, flags=re.M)
    head, _, rest = text.partition("[[segments]]")
    segs = ["[[segments]]" + s for s in rest.split("[[segments]]")]
    ms = [bool(re.search(r'^kind = "multisine"', s, re.M)) and not re.search(r"^a = ", s, re.M)
          for s in segs]
    segs = [re.sub(r"^periods = \d+\b", f"periods = {periods}",
                   re.sub(r"^seed = \d+\b", f"seed = {seed}", s, flags=re.M), flags=re.M)
            if m else s for s, m in zip(segs, ms, strict=True)]
    if multisine_only:
        segs = [s for s, m in zip(segs, ms, strict=True) if m]
    if payloads == 1:
        first = head.split("[[payloads]]")
        head = first[0] + "[[payloads]]" + first[1].rstrip() + "\n\n"
    p = work / f"{name}.toml"
    if daq:  # e.g. the paced run's SCHED_FIFO priority and CPU (docs/campaign-robot.md)
        head = head.replace("\n[daq]\n", "\n[daq]\n" + daq + "\n") if "\n[daq]\n" in head \
            else head + "\n[daq]\n" + daq + "\n\n"
    p.write_text(head + "".join(segs))
    return p


def stage_model(work: Path) -> None:
    logs, fit, model = work / "model_logs", work / "fit.json", work / "model"
    jid = [sys.executable, "-m", "daq.app.cli"]
    src = SOURCE["campaign"]
    subprocess.run([*jid, "run", str(src), "--simulate", "--out", str(logs), "--yes",
                    "--overwrite"], check=True)
    subprocess.run([*jid, "fit", "--robot", _robot_file(src),
                    *map(str, sorted(logs.glob("*.mcap"))), "--model", "both", "--json",
                    str(fit), "--no-consistency", "--consistent",
                    *(() if SOURCE.get("prune") else ("--no-prune",))], check=True,
                   stdout=subprocess.DEVNULL)
    subprocess.run([*jid, "export-model", str(fit), "--model", "paper", "-o", str(model)],
                   check=True)


def stage_calibrate(work: Path) -> dict:
    # the validation run is not the fit's: another multi-sine (seed 3 or the next free one)
    # (with the source campaign itself the lockstep simulation repeats the model's logs bit
    # for bit, and the bands would be the training residual's)
    _, c = _source()
    periods = max(s.periods for s in _multisines())
    camp = _campaign(work, "calibrate", seed=_other_seed(3), periods=periods,
                     multisine_only=False, payloads=len(c.payloads))
    s = run_monitor(work / "model", camp, work / "calibrate", simulate=True, calibrate=True)
    return {"thresholds": s["thresholds"], "wall_s": s["wall_s"],
            "missed": s["missed_cycles"]}


def rule_kwargs(kind: str, gain: float, cycle_s: float) -> dict:
    """The crossing rule of a new ``jointid monitor --calibrate`` (persistence, horizon)
    as keywords of ``thresholds_from_residual``."""
    return {"persist_cycles": DEFAULT_PERSIST_CYCLES, "horizon_s": DEFAULT_HORIZON_S,
            "cycle_s": cycle_s,
            "independent_per_s": independent_rate(kind, 20.0, gain if kind == "observer"
                                                  else 0.0)}


def sample_bands(th: Thresholds, moving_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) (n, k) [N m] of ``th`` at each sample's moving time (n, k) [s]: the
    band the live check uses (the constant band when ``th`` has no regime bins)."""
    lo, hi = (np.array(x) for x in th.bands())
    b = (np.searchsorted(np.array(th.edges_s), moving_s, side="right") if th.edges_s
         else np.zeros(moving_s.shape, int))
    cols = np.arange(moving_s.shape[1])[None, :]
    return lo[cols, b], hi[cols, b]


def crossings(path: Path, th: Thresholds) -> tuple[list, float, list]:
    """Rising edges out of the thresholds' band on the armed samples of a log, per joint;
    armed seconds; the largest |r - centre| / half-width per joint."""
    ml = read_monitor(path)
    r = ml.residual[ml.armed]
    lo, hi = sample_bands(th, ml.moving_s[ml.armed])
    out = persistent((r < lo) | (r > hi), th.persist_cycles)
    edges = ((out[1:] & ~out[:-1]).sum(axis=0) + out[0]).astype(int).tolist()
    cycle_s = float(np.median(np.diff(ml.t)))
    worst = (np.abs(r - (lo + hi) / 2) / ((hi - lo) / 2)).max(axis=0)
    return edges, r.shape[0] * cycle_s, worst.tolist()


def stage_false(work: Path, minutes: float, periods: int | None = None, seed: int = 7
                ) -> dict:
    _, c = _source()
    other_s, period_s = _plan_parts()
    if periods is None:  # at least `minutes` of plan over all payloads
        periods = _multisine_periods(period_s, 60.0 * minutes / len(c.payloads) - other_s)
    camp = _campaign(work, "false", seed=_other_seed(seed), periods=periods,
                     multisine_only=False, payloads=len(c.payloads))
    s = run_monitor(work / "model", camp, work / "false", simulate=True, calibrate=True)
    return {"logs": s["logs"], "wall_s": s["wall_s"], "missed": s["missed_cycles"],
            "periods": periods, "period_s": period_s}


def _other_seed(seed: int) -> int:
    """``seed``, or another one when the source campaign's multi-sine uses it (the stages'
    multi-sines differ from the validation's)."""
    seeds = {s.seed for s in _source()[1].segments if hasattr(s, "seed")}
    while seed in seeds:
        seed += 10
    return seed


def push_schedule(joints: list[str]) -> list[str]:
    """``--push`` arguments of the detect stage: each force, PUSHES_PER_FORCE rounds of
    every link in turn, one push every PUSH_EVERY_S."""
    out, t = [], PUSH_T0_S
    for force in PUSH_FORCES_N:
        for _ in range(PUSHES_PER_FORCE):
            for j in joints:
                out.append(f"{j}:{force}:{t:g}:{PUSH_S:g}")
                t += PUSH_EVERY_S
    return out


def stage_detect(work: Path) -> dict:
    _, c = _source()
    pushes = push_schedule(list(c.moving))
    end_s = float(pushes[-1].split(":")[2]) + PUSH_S + AFTER_PUSH_S + 1.0
    _, period_s = _plan_parts()
    camp = _campaign(work, "detect", seed=_other_seed(5),
                     periods=_multisine_periods(period_s, end_s), multisine_only=True,
                     payloads=1)
    s = run_monitor(work / "model", camp, work / "detect", simulate=True,
                    thresholds=work / "calibrate" / "thresholds.json", pushes=pushes)
    th = Thresholds.read(work / "calibrate" / "thresholds.json")
    offline: dict = {"constant": [], "regime": []}
    for run, log in zip(s["runs"], s["logs"], strict=True):
        _push_figures(work / "detect" / log, run, th, c)
        ml = read_monitor(work / "detect" / log)
        for tag, t in (("constant", th.constant()), ("regime", th)):
            lo, hi = sample_bands(t, ml.moving_s)
            offline[tag].append(detect_offline(ml, ml.residual, lo, hi, list(c.moving),
                                               c.cycle_s, th.persist_cycles))
    return {"runs": s["runs"], "wall_s": s["wall_s"], "missed": s["missed_cycles"],
            "offline": offline}


def _push_figures(log: Path, run: dict, th: Thresholds, campaign: object) -> None:
    """Per push of ``run`` (detect stage): its joint torques J^T F [N m] at the logged q of
    its staging cycle (default point and direction, as staged) and the largest
    |r - mean| / half-width per joint over its window (> 1: crossed)."""
    ml = read_monitor(log)
    axes = [read_run(log, axis=j) for j in range(len(th.joints))]
    model = ArmParams.from_robot(robot_for_campaign(campaign)).model
    data = model.createData()
    cycle_s = float(np.median(np.diff(ml.t)))
    mid, half = (ml.upper + ml.lower) / 2, (ml.upper - ml.lower) / 2
    for p in run["pushes"]:
        j = th.joints.index(p["joint"])
        q = [float(np.interp(p["cycle"], a.cycle, a.q)) for a in axes]
        push = staged_push(model, q, j, p["force_N"], 0.0, p["duration_s"])
        p["joint_torques_Nm"] = push_torque(model, data, q, push).round(3).tolist()
        c1 = p["cycle"] + int(round((p["duration_s"] + AFTER_PUSH_S) / cycle_s))
        sel = (ml.cycle >= p["cycle"]) & (ml.cycle <= c1) & ml.armed
        p["peak_fraction_of_band"] = (
            (np.abs(ml.residual[sel] - mid[sel]) / half[sel]).max(axis=0).round(3).tolist()
            if sel.any() else None)
        i0 = int(np.searchsorted(ml.cycle, p["cycle"]))
        p["moving_s_at_push"] = ml.moving_s[min(i0, len(ml.cycle) - 1)].round(3).tolist()
        p["dq_at_push"] = [round(float(np.interp(p["cycle"], a.cycle, a.dq)), 3)
                           for a in axes]


def truth_model(campaign: object) -> ExportedModel:
    """The simulator's own parameters (``ArmParams.truth``) as an exported paper model: the
    best an identification could give."""
    robot = robot_for_campaign(campaign)
    tr = ArmParams.from_robot(robot).truth()
    fr = friction_record("paper", tuple(robot.moving), robot.numbers, tr, tr,
                         [tr[f"qs{n}"] for n in robot.numbers], robot.gravity)
    return ExportedModel(urdf_text(robot.reduced(), tr, robot.numbers, "truth"), fr,
                         "simulator truth")


def logged_states(log: Path, campaign: object, model: ExportedModel
                  ) -> tuple[object, list, list, list, object, list[float]]:
    """A monitored run log's monitor records and, at their cycles, the logged q [rad],
    dq [rad/s], torque actual [N m] (lists of k values per cycle), with the model's predictor
    for the log's payload (``_payload<i>`` in its name) and each joint's rest velocity
    (3 q_s) [rad/s]: what :func:`replay` and ``bench_predband.py`` feed a residual."""
    ml = read_monitor(log)
    k = len(campaign.moving)
    axes = [read_run(log, axis=j) for j in range(k)]
    idx = np.searchsorted(axes[0].cycle, ml.cycle)
    q, dq, tau = (np.stack([getattr(a, f)[idx] for a in axes], axis=1).tolist()
                  for f in ("q", "dq", "tau_actual"))
    m = re.search(r"_payload(\d+)\.mcap$", log.name)
    payload = campaign.payloads[int(m.group(1))] if m else None
    pred = model.predictor(payload)
    return ml, q, dq, tau, pred, [REST_QS * x for x in pred.q_s]


def replay(log: Path, campaign: object, model: ExportedModel, cutoff_hz: float = 20.0,
           kind: str = "filtered", gain: float = DEFAULT_OBSERVER_GAIN
           ) -> tuple[object, np.ndarray, np.ndarray]:
    """The monitor's residual (n, k) [N m] of a monitored run log recomputed offline with
    another model or another residual (``kind`` filtered or observer, its gain K_O [1/s]):
    the logged q, dq, torque actual of the monitored cycles through the residual
    :class:`daq.runtime.monitor.TorqueMonitor` makes (:func:`residual_for`; rest velocity
    3 q_s) (with the log's own model and residual it gives the logged residual exactly).
    Returns (the log's :class:`MonitorLog`, residual, moving time (n, k) [s] at the model's
    rest velocity)."""
    ml, q, dq, tau, pred, v_rest = logged_states(log, campaign, model)
    k, n = len(campaign.moving), len(q)
    fn = functools.partial(pred.band if kind == "filtered" else pred.observer_terms,
                           v_rest=v_rest)
    res = residual_for(kind, fn, k, campaign.cycle_s, cutoff_hz=cutoff_hz, gain=gain)
    r = np.zeros((n, k))
    vel = np.zeros((n, k))
    for i in range(n):
        r[i], _, _, vel[i] = res.step(q[i], dq[i], tau[i])
    return ml, r, moving_seconds(vel, v_rest, campaign.cycle_s)


def _rising(r: np.ndarray, armed: np.ndarray, lo: np.ndarray, hi: np.ndarray,
            persist: int = 1) -> np.ndarray:
    """(n, k) bool: the armed samples where r has been out of the band [lo, hi] for
    ``persist`` consecutive armed samples (first such sample: the live crossing)."""
    out = persistent(((r < lo) | (r > hi)) & armed[:, None], persist)
    prev = np.vstack([np.zeros((1, r.shape[1]), bool), out[:-1]])
    return out & ~prev


def push_delays(cycle: np.ndarray, events: list[dict], hits: np.ndarray, joints: list[str],
                span: int, cycle_s: float) -> tuple[list[dict], int]:
    """Per push event of a run (``events``' ``push`` entries, cycles ``cycle``): its joint,
    force [N] and the delay of the first crossing (``hits``, (n, k)) within ``span`` cycles
    [ms] (None: missed); and the crossings outside the push windows."""
    used = np.zeros(len(cycle), bool)
    pushes = []
    for e in (e for e in events if e["kind"] == "push"):
        win = (cycle >= e["cycle"]) & (cycle <= e["cycle"] + span)
        used |= win
        rows = np.flatnonzero(win & hits.any(axis=1))
        pushes.append({"joint": joints[e["axis"]],
                       "force_N": float(e["message"].split(":")[1].split("N")[0]),
                       "delay_ms": round(1000 * (cycle[rows[0]] - e["cycle"]) * cycle_s)
                       if rows.size else None})
    return pushes, int(hits[~used].sum())


def print_push_delays(pushes: list[dict]) -> None:
    """One line per pushed joint and force: the delays [ms] of :func:`push_delays`."""
    by: dict = {}
    for p in pushes:
        by.setdefault((p["joint"], p["force_N"]), []).append(p["delay_ms"])
    for (name, force), d in by.items():
        print(f"  push {name} {force:g} N: delays [ms] {d}")


def detect_offline(ml: object, r: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                   joints: list[str], cycle_s: float, persist: int = 1) -> dict:
    """The detect stage's pushes (the log's push events) against residual ``r`` and bands
    ``lo``, ``hi`` (n, k): detection, delay, joints crossed; crossings outside the push
    windows."""
    hits = _rising(r, ml.armed, lo, hi, persist)
    used = np.zeros(len(ml.cycle), bool)
    span = int(round((PUSH_S + AFTER_PUSH_S) / cycle_s))
    pushes = []
    for e in (e for e in ml.events if e["kind"] == "push"):
        force = float(e["message"].split(":")[1].split("N")[0])
        win = (ml.cycle >= e["cycle"]) & (ml.cycle <= e["cycle"] + span)
        used |= win
        rows = np.flatnonzero(win & hits.any(axis=1))
        pushes.append({"joint": joints[e["axis"]], "force_N": force,
                       "detected": bool(rows.size),
                       "delay_s": float((ml.cycle[rows[0]] - e["cycle"]) * cycle_s)
                       if rows.size else None,
                       "joints_crossed": sorted({joints[j] for j in
                                                 np.flatnonzero(hits[win].any(axis=0))})})
    return {"pushes": pushes, "crossings_outside": int(hits[~used].sum())}


def stage_oracle(work: Path) -> dict:
    """The logs of the calibrate, false and detect stages re-evaluated offline with the
    simulator's own parameters as the model (:func:`truth_model`, :func:`replay`):
    thresholds from the calibrate logs (the same rule), crossings on the false logs,
    detection of the detect stage's pushes. What the monitor does with a perfect
    identification: the difference to the stages' figures is the identified model's."""
    _, c = _source()
    model = truth_model(c)
    joints = list(c.moving)
    logs = sorted((work / "calibrate" / "logs").glob("*.mcap"))
    res = [replay(p, c, model) for p in logs]
    th = thresholds_from_residual(np.concatenate([r[ml.armed] for ml, r, _ in res]), joints,
                                  DEFAULT_K_SIGMA, "oracle", DEFAULT_PEAK_MARGIN,
                                  np.concatenate([m[ml.armed] for ml, _, m in res]),
                                  **rule_kwargs("filtered", 0.0, c.cycle_s))
    out: dict = {"thresholds": th.to_json()}
    false_n, secs = np.zeros(len(joints), int), 0.0
    for p in sorted((work / "false" / "logs").glob("*.mcap")):
        ml, r, m = replay(p, c, model)
        false_n += _rising(r, ml.armed, *sample_bands(th, m), th.persist_cycles).sum(axis=0)
        secs += float(ml.armed.sum()) * c.cycle_s
    out["false_alarms"] = {"per_joint": false_n.tolist(), "monitored_s": secs}
    pushes, outside = [], 0
    for p in sorted((work / "detect" / "logs").glob("*.mcap")):
        ml, r, m = replay(p, c, model)
        d = detect_offline(ml, r, *sample_bands(th, m), joints, c.cycle_s, th.persist_cycles)
        pushes += d["pushes"]
        outside += d["crossings_outside"]
    out["detect"] = {"pushes": pushes, "crossings_outside": outside}
    return out


def _evaluate(work: Path, campaign: object, model: ExportedModel, kind: str, gain: float,
              thin_bins: str = "pooled") -> dict:
    """One residual (``kind``, gain K_O [1/s]) with one model, offline on the logs of the
    calibrate, false and detect stages (:func:`replay`): thresholds from the calibrate logs
    (the live rule: :func:`thresholds_from_residual`, k = 6, peak margin 1.5, the default
    regime bins, ``thin_bins`` the rule of the bins with too few samples or episodes), the
    false logs' crossings and largest |r - centre| / half-width per joint (armed samples),
    the detect log's pushes (:func:`detect_offline`); with the regime bands
    (``false_alarms``, ``detect``) and with the constant band (``constant_...``)."""
    joints = list(campaign.moving)
    res = [replay(p, campaign, model, kind=kind, gain=gain)
           for p in sorted((work / "calibrate" / "logs").glob("*.mcap"))]
    th = thresholds_from_residual(np.concatenate([r[ml.armed] for ml, r, _ in res]), joints,
                                  DEFAULT_K_SIGMA, f"{kind} offline", DEFAULT_PEAK_MARGIN,
                                  np.concatenate([m[ml.armed] for ml, _, m in res]),
                                  kind=kind, observer_gain=gain if kind == "observer" else 0.0,
                                  thin_bins=thin_bins,
                                  **rule_kwargs(kind, gain, campaign.cycle_s))
    out: dict = {"thresholds": th.to_json()}
    bands = {"": th, "constant_": th.constant()}  # the regime bands, and the constant band
    false_n = {t: np.zeros(len(joints), int) for t in bands}
    worst = {t: np.zeros(len(joints)) for t in bands}
    secs = 0.0
    for p in sorted((work / "false" / "logs").glob("*.mcap")):
        ml, r, m = replay(p, campaign, model, kind=kind, gain=gain)
        secs += float(ml.armed.sum()) * campaign.cycle_s
        a = ml.armed
        for t, x in bands.items():
            lo, hi = sample_bands(x, m)
            false_n[t] += _rising(r, a, lo, hi, th.persist_cycles).sum(axis=0)
            worst[t] = np.maximum(worst[t], (np.abs(r[a] - (lo[a] + hi[a]) / 2)
                                             / ((hi[a] - lo[a]) / 2)).max(axis=0))
    pushes: dict = {t: [] for t in bands}
    outside = dict.fromkeys(bands, 0)
    for p in sorted((work / "detect" / "logs").glob("*.mcap")):
        ml, r, m = replay(p, campaign, model, kind=kind, gain=gain)
        for t, x in bands.items():
            d = detect_offline(ml, r, *sample_bands(x, m), joints, campaign.cycle_s,
                               th.persist_cycles)
            pushes[t] += d["pushes"]
            outside[t] += d["crossings_outside"]
    for t in bands:
        out[f"{t}false_alarms"] = {"per_joint": false_n[t].tolist(), "monitored_s": secs,
                                   "worst_fraction_of_band": worst[t].tolist()}
        out[f"{t}detect"] = {"pushes": pushes[t], "crossings_outside": outside[t]}
    return out


def _pushes_key(pushes: list) -> list:
    """(joint, force, detected, delay [ms] rounded) per push: what two evaluations must
    share to be the same."""
    return [(p["joint"], p["force_N"], p["detected"],
             None if p["delay_s"] is None else round(1000 * p["delay_s"]))
            for p in pushes]


def stage_observer(work: Path, gain: float, kinds: tuple[str, ...] = RESIDUALS,
                   thin_bins: str = "pooled") -> dict:
    """Offline, on the logs of the calibrate, false and detect stages: the filtered residual
    and the momentum observer's (gain K_O [1/s]) side by side, with the identified model
    (DIR/model) and with the simulator's own parameters (:func:`truth_model`, the oracle);
    :func:`_evaluate` each (``kinds``: the residuals to evaluate; ``thin_bins``: the rule of
    the regime bins with too few samples or episodes, ``ident.monitor.THIN_BINS``). The
    identified filtered figures are checked against the ones the stages recorded in
    DIR/bench_monitor.json (``check_against_recorded``: the thresholds' statistics always;
    the false alarms and detections are the same only with the rule the live calibration
    file has, ``constant`` for files written before the key)."""
    _, c = _source()
    models = {"identified": load_exported(work / "model"), "oracle": truth_model(c)}
    out: dict = {"gain_per_s": gain, "thin_bins": thin_bins, "figures": {}}
    for name, model in models.items():
        for kind in kinds:
            t0 = time.perf_counter()
            out["figures"][f"{name}/{kind}"] = _evaluate(work, c, model, kind, gain,
                                                         thin_bins)
            print(f"  observer stage: {name}/{kind} in {time.perf_counter() - t0:.0f} s",
                  file=sys.stderr)
    out["check_against_recorded"] = chk = {}
    if "filtered" not in kinds:
        return out
    store = work / "bench_monitor.json"
    rec = json.loads(store.read_text()) if store.is_file() else {}
    mine = out["figures"]["identified/filtered"]
    live = dataclasses.replace(Thresholds.read(work / "calibrate" / "thresholds.json"),
                               thin_bins=thin_bins).to_json()["regime"]
    chk["thresholds_max_diff_Nm"] = float(max(
        np.abs(np.array(mine["thresholds"]["regime"][b]) - np.array(live[b])).max()
        for b in ("lower", "upper")))
    fa = rec.get("false_alarms", {}).get("regime")
    if fa:
        chk["false_alarms_equal"] = fa["per_joint"] == mine["false_alarms"]["per_joint"]
        chk["worst_fraction_max_diff"] = float(np.abs(
            np.array(fa["worst_fraction_of_band"])
            - np.array(mine["false_alarms"]["worst_fraction_of_band"])).max())
    det = rec.get("detect", {}).get("offline", {}).get("regime")
    if det:
        chk["detect_equal"] = (_pushes_key([p for d in det for p in d["pushes"]])
                               == _pushes_key(mine["detect"]["pushes"])
                               and sum(d["crossings_outside"] for d in det)
                               == mine["detect"]["crossings_outside"])
    orc, mo = rec.get("oracle"), out["figures"]["oracle/filtered"]
    if orc:
        chk["oracle_false_alarms_equal"] = (orc["false_alarms"]["per_joint"]
                                            == mo["false_alarms"]["per_joint"])
        chk["oracle_detect_equal"] = (_pushes_key(orc["detect"]["pushes"])
                                      == _pushes_key(mo["detect"]["pushes"]))
    return out


def print_observer(res: dict) -> None:
    """The observer stage's tables (regime bands, then the constant band): per pushed link
    and force, detected of 3 and delays [ms]; per joint, false alarms and the largest
    excursion / band; for each model and residual."""
    print(f"observer stage (K_O = {res['gain_per_s']:g} 1/s, thin bins "
          f"{res.get('thin_bins', 'constant')}), offline on the same logs; "
          "check against the recorded filtered figures: " + json.dumps(
              res["check_against_recorded"]))
    for band in ("", "constant_"):
        print(f"-- {'constant band' if band else 'regime bands'}")
        _print_observer({t: {"thresholds": f["thresholds"], "detect": f[f"{band}detect"],
                             "false_alarms": f[f"{band}false_alarms"]}
                         for t, f in res["figures"].items()}, not band)


def _print_observer(figs: dict, bins: bool) -> None:
    """One table of :func:`print_observer` (``bins``: and the regime bands' widths)."""
    tags = list(figs)
    joints = figs[tags[0]]["thresholds"]["joints"]
    print("  " + "link/force".ljust(28) + "".join(t.rjust(26) for t in tags))
    forces = sorted({p["force_N"] for p in figs[tags[0]]["detect"]["pushes"]})
    for f in forces:
        for j in joints:
            cells = []
            for t in tags:
                ps = [p for p in figs[t]["detect"]["pushes"]
                      if p["joint"] == j and p["force_N"] == f]
                d = [f"{1000 * p['delay_s']:.0f}" for p in ps if p["detected"]]
                cells.append(f"{len(d)}/{len(ps)} [{','.join(d) or '-'}]")
            print(f"  {j[:20]:20s} {f:4g} N " + "".join(x.rjust(26) for x in cells))
    print("  " + "crossings outside pushes".ljust(28) + "".join(
        str(figs[t]["detect"]["crossings_outside"]).rjust(26) for t in tags))
    for i, j in enumerate(joints):
        print(f"  false alarms {j[:15]:15s}" + "".join(
            (f"{figs[t]['false_alarms']['per_joint'][i]} "
             f"({figs[t]['false_alarms']['worst_fraction_of_band'][i]:.2f})").rjust(26)
            for t in tags))
    print("  monitored [min]".ljust(30) + "".join(
        f"{figs[t]['false_alarms']['monitored_s'] / 60:.1f}".rjust(26) for t in tags))
    for t in tags if bins else ():
        reg = figs[t]["thresholds"]["regime"]
        print(f"  {t} half-width per moving-time bin {reg['edges_s']} s [N m]: " + "; ".join(
            f"{j} " + " ".join(f"{(b - a) / 2:.3g}" for a, b in zip(lo, hi, strict=True))
            for j, lo, hi in zip(joints, reg["lower"], reg["upper"], strict=True)))


def _paced_timing(path: Path) -> dict:
    """Lateness of every SYNC and the cycle's busy time from a paced log's ``/timing``
    channel (engine.TIMING_SCHEMA): percentiles [us], missed cycles (> half a period late)
    and how many of them followed a cycle that was itself longer than the period (the
    loop's own work) rather than a late wake-up from its sleep (the host)."""
    raw = read_topics(path, {"/timing"}).raw.get("/timing", [])
    rows = np.array([struct.unpack_from("<qddd", m, 4) for m in raw])
    rows = rows[np.argsort(rows[:, 0])]
    late, busy = rows[:, 2], rows[:, 3]
    cycle_s = 1e-3
    miss = np.flatnonzero(late > 0.5 * cycle_s)
    after_long = int(np.sum(busy[miss[miss > 0] - 1] > cycle_s))
    pct = {f"lateness_{k}_us": float(np.percentile(late, q) * 1e6)
           for k, q in (("p50", 50), ("p99", 99), ("p999", 99.9))}
    return {"cycles_timed": int(len(rows)), "missed_timed": int(len(miss)), **pct,
            "lateness_max_us": float(late.max() * 1e6),
            "busy_p50_us": float(np.percentile(busy, 50) * 1e6),
            "busy_p99_us": float(np.percentile(busy, 99) * 1e6),
            "busy_max_us": float(busy.max() * 1e6),
            "missed_after_long_cycle": after_long,
            "missed_late_us": (late[miss] * 1e6).round().astype(int).tolist()}


def _steal_ms() -> list[float]:
    """Time stolen from each CPU by the hypervisor so far [ms] (/proc/stat; [] elsewhere):
    on a VM a loop's wake-up is late while its vCPU is not running."""
    try:
        lines = Path("/proc/stat").read_text().splitlines()
    except OSError:
        return []
    tck = os.sysconf("SC_CLK_TCK")
    return [1000.0 * int(ln.split()[8]) / tck for ln in lines
            if ln.startswith("cpu") and ln[3:4].isdigit()]


def stage_paced(work: Path, seconds: float, realtime: int = 0, repeat: int = 1) -> dict:
    """``repeat`` pairs of runs, interleaved (the host's load changes by the minute): with
    the monitor, then the same campaign without it; each with its load average [1 min]."""
    periods = max(1, int(round(seconds / 8.0)))
    daq = f"realtime_priority = {realtime}\ncpu = -1" if realtime else ""
    camp = _campaign(work, "arm3-paced", seed=1, periods=periods, multisine_only=True,
                     payloads=1, daq=daq)
    out: dict = {"monitor": {"runs": []}, "none": {"runs": []}, "realtime_priority": realtime}
    for _ in range(repeat):
        for tag, th in (("monitor", work / "calibrate" / "thresholds.json"), ("none", None)):
            load0 = os.getloadavg()[0]
            steal0 = _steal_ms()
            if th is None:  # the same run without the monitor: run_campaign alone
                c = load_campaign(camp, True)
                res, wall = run_with_bar(c, work / "paced_none", True, sys.stderr)
                r = res.runs[0]
                run = {"status": res.status, "reason": res.reason, "missed": r.missed,
                       "cycles": r.cycles, "wall_s": wall, **_paced_timing(r.path)}
            else:
                s = run_monitor(work / "model", camp, work / "paced_monitor", simulate=True,
                                thresholds=th, paced=True)
                m = s["runs"][0]
                run = {"status": s["status"], "reason": s["reason"],
                       "missed": s["missed_cycles"][0], "cycles": m["cycles"],
                       "wall_s": s["wall_s"], "false_alarms": len(m["false_alarms"]),
                       "check_us_mean": m["step_us_mean"], "check_us_max": m["step_us_max"],
                       **_paced_timing(work / "paced_monitor" / s["logs"][0])}
            run["load_1min"] = [load0, os.getloadavg()[0]]
            run["steal_ms_per_cpu"] = [b - a for a, b in zip(steal0, _steal_ms(), strict=False)]
            out[tag]["runs"].append(run)
    for tag in ("monitor", "none"):
        runs = out[tag]["runs"]
        out[tag]["missed"] = [r["missed"] for r in runs]
        out[tag]["cycles"] = [r["cycles"] for r in runs]
    return out


def _print_detect(pushes: list, outside: int) -> None:
    """Detected of n, delays and joints crossed per pushed link and force."""
    by: dict = {}
    for p in pushes:
        by.setdefault((p["force_N"], p["joint"]), []).append(p)
    for (f, j), ps in sorted(by.items()):
        d = [1000 * p["delay_s"] for p in ps if p["detected"]]
        print(f"  link of {j}, {f:g} N: {len(d)}/{len(ps)} detected, delay "
              + (f"{min(d):.0f}..{max(d):.0f} ms" if d else "-") + "; joints crossed: "
              + ", ".join(sorted({x for p in ps for x in p["joints_crossed"]})))
    print(f"  crossings outside the push windows: {outside}")


def report(work: Path, res: dict) -> None:
    th_path = work / "calibrate" / "thresholds.json"
    if th_path.is_file():
        th = Thresholds.read(th_path)
        joints, k = list(th.joints), len(th.joints)
        print(f"thresholds (validation: {SOURCE['campaign'].name}, all payloads):")
        for j, s, lo, hi, pk in zip(th.joints, th.sigma, th.lower, th.upper,
                                       th.peak, strict=True):
            print(f"  {j}: sigma {s:.4f} N m, constant band [{lo:+.3f}, {hi:+.3f}] N m, "
                  f"validation peak {pk:.1f} sigma")
        if th.regime:
            blo, bhi = th.bands()
            print(f"  regime bands, half-width [N m] (samples, episodes) per moving-time bin "
                  f"(edges {list(th.edges_s)} s; *: < {th.min_samples} samples or "
                  f"{th.min_episodes} episodes, "
                  + ("pooled with shorter bins, within the constant band):"
                     if th.thin_bins == "pooled" else "constant):"))
            for j, name in enumerate(joints):
                print(f"    {name}: " + "  ".join(
                    f"{(b - a) / 2:.3g}{'' if u else '*'} ({n}, {e})" for a, b, u, n, e in zip(
                        blo[j], bhi[j], th.bin_used[j], th.bin_samples[j],
                        th.bin_episodes[j], strict=True)))
        if (work / "false" / "monitor.json").is_file():
            logs = json.loads((work / "false" / "monitor.json").read_text())["logs"]
            res["false_alarms"] = {}
            for tag, t in (("regime", th), ("constant", th.constant())):
                total, secs, worst = np.zeros(k, int), 0.0, np.zeros(k)
                for lg in logs:
                    n, sec, w = crossings(work / "false" / lg, t)
                    total += n
                    secs += sec
                    worst = np.maximum(worst, w)
                res["false_alarms"][tag] = {"per_joint": total.tolist(), "monitored_s": secs,
                                            "worst_fraction_of_band": worst.tolist()}
                print(f"false alarms, {tag} band: {int(total.sum())} ("
                      + ", ".join(f"{j} {n}" for j, n in zip(joints, total, strict=True))
                      + f") in {secs / 60:.1f} min of monitored excitation without pushes; "
                      "largest |r - centre| / half-width per joint: "
                      + ", ".join(f"{j} {w:.2f}" for j, w in zip(joints, worst,
                                                                 strict=True)))
    det = res.get("detect")
    if det:
        for run in det["runs"]:
            by: dict = {}
            for p in run["pushes"]:
                by.setdefault((p["joint"], p["force_N"]), []).append(p)
            print("detection (pushes during the multi-sine, 0.2 s each):")
            for (j, f), ps in sorted(by.items(), key=lambda x: (x[0][1], x[0][0])):
                d = [1000 * p["delay_s"] for p in ps if p["detected"]]
                print(f"  link of {j}, {f:g} N: {len(d)}/{len(ps)} detected, delay "
                      + (f"{min(d):.0f}..{max(d):.0f} ms (median "
                         f"{statistics.median(d):.0f})" if d else "-")
                      + "; joints crossed: "
                      + ", ".join(sorted({x for p in ps for x in p["joints_crossed"]})))
                for p in ps:
                    if "joint_torques_Nm" in p:
                        print(f"    t0 {p['t0_s']:g} s: J^T F "
                              f"{p['joint_torques_Nm']} N m, peak |r - centre| / half-width "
                              f"{p['peak_fraction_of_band']}, dq {p['dq_at_push']} rad/s, "
                              f"moving {p.get('moving_s_at_push')} s")
            print(f"  crossings outside the push windows: {len(run['false_alarms'])}")
        for tag, runs in det.get("offline", {}).items():
            print(f"offline on the same log, {tag} band:")
            _print_detect([p for d in runs for p in d["pushes"]],
                          sum(d["crossings_outside"] for d in runs))
    orc = res.get("oracle")
    if orc:
        t = orc["thresholds"]
        print("oracle (the simulator's own parameters as the model, same logs): bands +-"
              + ", ".join(f"{j} {(hi - lo) / 2:.3f}" for j, lo, hi in
                          zip(t["joints"], t["lower"], t["upper"], strict=True)) + " N m")
        if t.get("regime"):
            print("  oracle regime bands, half-width per bin: " + "; ".join(
                f"{j} " + " ".join(f"{(b - a) / 2:.3g}" for a, b in zip(lo, hi, strict=True))
                for j, lo, hi in zip(t["joints"], t["regime"]["lower"],
                                     t["regime"]["upper"], strict=True)))
        fa = orc["false_alarms"]
        print(f"  false alarms: {sum(fa['per_joint'])} {fa['per_joint']} in "
              f"{fa['monitored_s'] / 60:.1f} min")
        _print_detect(orc["detect"]["pushes"], orc["detect"]["crossings_outside"])
    pc = res.get("paced")
    if pc and "runs" in pc.get("monitor", {}):
        print(f"paced 1 kHz (realtime_priority {pc.get('realtime_priority', 0)}), in run "
              "order:")
        for k in range(len(pc["monitor"]["runs"])):
            for tag in ("monitor", "none"):
                r = pc[tag]["runs"][k]
                check = (f", check {r['check_us_mean']:.0f} us mean / {r['check_us_max']:.0f}"
                         " max" if "check_us_mean" in r else "")
                print(f"  {tag:7s} {r['missed']} missed of {r['cycles']} ({r['status']}"
                      f"{': ' + r['reason'] if r['reason'] else ''}), lateness p50 "
                      f"{r['lateness_p50_us']:.1f} / p99 {r['lateness_p99_us']:.1f} / p99.9 "
                      f"{r['lateness_p999_us']:.0f} / max {r['lateness_max_us']:.0f} us, "
                      f"busy p50 {r['busy_p50_us']:.0f} / p99 {r['busy_p99_us']:.0f} us, "
                      f"{r['missed_after_long_cycle']} after a cycle > 1 ms{check}; load "
                      f"{r['load_1min'][0]:.1f}; stolen by the hypervisor "
                      f"{r.get('steal_ms_per_cpu', [])} ms per CPU")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--campaign", type=Path, default=DEMO,
                    help="robot campaign the stages derive theirs from (default: "
                    "examples/campaign_robot3_demo.toml)")
    ap.add_argument("--prune", action="store_true",
                    help="model stage: the fit's default pruning (held at 0: the paper "
                         "model's friction terms above 30 %% relative sigma)")
    ap.add_argument("--false-minutes", type=float, default=10.0,
                    help="false stage: at least this long [min] over all payloads")
    ap.add_argument("--false-periods", type=int, default=None,
                    help="false stage: periods of the multi-sine (instead of "
                    "--false-minutes)")
    ap.add_argument("--false-seed", type=int, default=7,
                    help="false stage: the multi-sine's seed (default 7; the next free one "
                    "+10 when the campaign's uses it)")
    ap.add_argument("--paced-seconds", type=float, default=30.0)
    ap.add_argument("--realtime", type=int, default=0,
                    help="paced stage: SCHED_FIFO priority of the cycle loop (daq."
                         "realtime_priority, pinned to the last CPU; needs CAP_SYS_NICE)")
    ap.add_argument("--paced-repeat", type=int, default=1,
                    help="paced stage: pairs of runs (with, without the monitor), interleaved")
    ap.add_argument("--observer-gain", type=float, default=DEFAULT_OBSERVER_GAIN,
                    help="observer stage: the momentum observer's gain K_O [1/s]")
    ap.add_argument("--residuals", default=",".join(RESIDUALS),
                    help="observer stage: the residuals to evaluate, comma-separated "
                    "(default: filtered,observer)")
    ap.add_argument("--thin-bins", choices=THIN_BINS, default=THIN_BINS[0],
                    help="observer stage: what a regime bin with too few samples or episodes "
                    "takes (default pooled; constant: the rule before, to compare with "
                    "figures recorded by it)")
    ap.add_argument("--results", type=Path, default=None,
                    help="where the figures are stored (default DIR/bench_monitor.json)")
    ap.add_argument("stages", nargs="+", choices=("model", "calibrate", "false", "detect",
                                                  "oracle", "observer", "paced", "report"))
    a = ap.parse_args()
    SOURCE["campaign"] = a.campaign.resolve()
    SOURCE["prune"] = a.prune
    a.work.mkdir(parents=True, exist_ok=True)
    store = a.results or a.work / "bench_monitor.json"
    store.parent.mkdir(parents=True, exist_ok=True)
    res = json.loads(store.read_text()) if store.is_file() else {}
    for st in a.stages:
        t0 = time.perf_counter()
        if st == "model":
            stage_model(a.work)
        elif st == "calibrate":
            res["calibrate"] = stage_calibrate(a.work)
        elif st == "false":
            res["false"] = stage_false(a.work, a.false_minutes, a.false_periods,
                                       a.false_seed)
        elif st == "detect":
            res["detect"] = stage_detect(a.work)
        elif st == "oracle":
            res["oracle"] = stage_oracle(a.work)
        elif st == "observer":
            kinds = tuple(a.residuals.split(","))
            if not kinds or not set(kinds) <= set(RESIDUALS):
                raise SystemExit(f"--residuals {a.residuals!r}: expected some of "
                                 f"{','.join(RESIDUALS)}")
            res["observer"] = stage_observer(a.work, a.observer_gain, kinds, a.thin_bins)
        elif st == "paced":
            res["paced"] = stage_paced(a.work, a.paced_seconds, a.realtime, a.paced_repeat)
        if st != "report":
            res.setdefault("stage_wall_s", {})[st] = time.perf_counter() - t0
            store.write_text(json.dumps(res, indent=1, default=str))
    if "report" in a.stages or set(a.stages) != {"observer"}:
        report(a.work, res)
    if "observer" in res:
        print_observer(res["observer"])
    store.write_text(json.dumps(res, indent=1, default=str))


if __name__ == "__main__":
    main()
