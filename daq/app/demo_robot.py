"""``jointid demo --robot``: a whole robot campaign end to end on a simulated arm.

plan (optimised multi-sine, predicted condition number) -> run on the simulated CANopen buses
(one simulated CiA 402 drive per joint in front of one simulated arm, the production master
and MCAP logging) -> the logged condition number -> n-dof fit of the usual and the paper
model (:mod:`ident.robot`) -> Table III per joint -> each model refined joint by joint and
the found terms refitted inside its n-dof model -> ``report.html``.

The refinement is ``jointid fit --robot --refine``'s (:func:`ident.cli_robot.refine_robot`),
run on each fitted model (usual and paper): joint j's design is the fit's own rows of that
model (:meth:`ident.robot.estimate.RobotModel.fitted_rows`), its torque as Y and the n-dof
prediction as the declared model (times a gain ~1, taken as the load tau_out) plus the usual
friction (F_C, F_V, tau_off, ~0), so its residual is the n-dof residual and sign(P), the load
are not read from the residual itself (:func:`ident.robot.refine_joint.refine_joint`); the
refinement then looks for effects left in it (quadrant and load-dependent friction, Stribeck,
position ripple, torque lag, generic bases, ...). The other joints' positions and velocities
are given to it as ``q<m>``, ``dq<m>`` (m: 1-based index in the moving chain), so that an
effect of another joint's state (a cable, a coupled bearing load) is found and named by that
variable. Then every term found is refitted inside the n-dof model with every parameter
together (:func:`ident.robot.refit.refit_robot`): before/after per joint and for the robot.
Relative errors are ||rho_j|| / ||tau_j||. ``fit.json`` holds the refinement of the model
``jointid fit --robot --refine`` refines (:func:`ident.vocab.refined_model`), ``demo.json``
both.
"""

from __future__ import annotations

import html
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import matplotlib
import numpy as np
import scipy.signal

from daq import DaqError, __version__, examples
from daq.protocol.reader import read_run
from daq.runtime.progress import Heartbeat
from daq.runtime.robot_rig import arm_truth
from ident.cli_robot import fit_robot, format_report, refine_robot
from ident.report import Section, html_table, write_html, write_json
from ident.robot.loaders import (
    RobotPreprocessing,
    load_robot_runs,
    preprocess_runs,
    resolved_settings,
)
from ident.robot.plots import joint_validation
from ident.robot.tables import format_table_iii, table_iii
from ident.vocab import refined_model
from trajectories.campaign_file import load_campaign
from trajectories.cli import plot_robot_plan
from trajectories.excitation import Quality, assess_robot_campaign, condition_number
from trajectories.robot_campaign import RobotCampaign
from trajectories.robot_model import RobotDynamics, prepare_robot_campaign, robot_for_campaign

from .demo import PLAN_PNG, ROBOT_DEMOS, DemoFolder, demo_folder
from .running import run_with_bar, stop_if_interrupted

__all__ = ["ROBOT_DEMOS", "RobotDemoResult", "logged_condition_number", "run_robot_demo"]


@dataclass(frozen=True)
class RobotDemoResult:
    """What :func:`run_robot_demo` produced."""

    out_dir: Path
    report: Path
    logs: tuple[Path, ...]
    summary: str
    figures: dict


def _example(name: str) -> Path:
    """A shipped example: the installed ``daq.examples`` file, else the source checkout's
    ``examples/`` (an editable install of another checkout maps ``daq.examples`` there)."""
    p = examples.path(name)
    if p.is_file():
        return p
    return Path(__file__).resolve().parents[2] / "examples" / name


def _say(stream: TextIO, text: str) -> None:
    stream.write(text + "\n")
    stream.flush()


def logged_condition_number(paths: list[Path], dyn: RobotDynamics, predicted: Quality,
                            cycle_s: float, cutoff_hz: float = 20.0) -> list[float]:
    """Condition number of ``dyn``'s regressor on the LOGGED data of each run, on the base
    columns and with the sample stride of the prediction: q from the encoders, dq from the
    drives (0x606C) zero-phase low-passed at ``cutoff_hz``, ddq its central difference; the
    samples of the plan (segment >= 0) where every drive was enabled."""
    b, a = scipy.signal.butter(4, 2.0 * cutoff_hz * cycle_s)
    out = []
    for path in paths:
        axes = [read_run(path, axis=j) for j in range(dyn.k)]
        sel = axes[0].segment >= 0
        for x in axes:
            sel &= x.valid
        q = np.stack([x.q for x in axes], axis=1)
        dq = scipy.signal.filtfilt(b, a, np.stack([x.dq for x in axes], axis=1), axis=0)
        ddq = np.gradient(dq, cycle_s, axis=0)
        idx = np.flatnonzero(sel)[::predicted.stride]
        out.append(condition_number(dyn.regressor(q[idx], dq[idx], ddq[idx]),
                                    predicted.base_columns))
    return out


def run_robot_demo(out_dir: str | Path, *, robot: str = "3", max_steps: int = 2,
                   stream: TextIO | None = None, campaign_path: Path | None = None
                   ) -> RobotDemoResult:
    """Run a robot campaign end to end on the simulated arm and write ``out_dir/report.html``.

    Parameters
    ----------
    out_dir : path-like
        ``logs/*.mcap``, ``fit.json``, ``demo.json``, figures, ``report.html`` (the report
        written whole or not at all, the logs kept: :func:`.demo.demo_folder`).
    robot : {"3", "6"}
        The shipped 3-dof arm (``examples/campaign_robot3_demo.toml``) or the UR10
        (``examples/campaign_ur10_demo.toml``).
    max_steps : int
        Refinement steps per joint at most.
    campaign_path : path, optional
        Another robot campaign instead.

    Raises
    ------
    DaqError
        The campaign stopped before its end, or the file is not a robot campaign.
    daq.runtime.safety.RunInterrupted
        A stop signal (Ctrl-C...) ended the campaign's run (:func:`.running.stop_if_interrupted`).
    """
    with Heartbeat(stream if stream is not None else sys.stderr) as hb:
        return _run_robot_demo(hb, out_dir, robot=robot, max_steps=max_steps,
                               campaign_path=campaign_path)


def _run_robot_demo(hb: Heartbeat, out_dir: str | Path, *, robot: str, max_steps: int,
                    campaign_path: Path | None) -> RobotDemoResult:
    """:func:`run_robot_demo`'s body; ``hb.stream`` is the progress stream, ``hb.status``
    names the step running (a line at least every few seconds on a silent step)."""
    out = Path(out_dir)
    with demo_folder(out) as folder:  # the logs kept, the report whole or absent
        res = _robot_demo_steps(hb, folder, robot=robot, max_steps=max_steps,
                                campaign_path=campaign_path)
    # moved into out: the report's files by their names
    return RobotDemoResult(out, out / res.report.name, res.logs, res.summary, res.figures)


def _robot_demo_steps(hb: Heartbeat, folder: DemoFolder, *, robot: str, max_steps: int,
                      campaign_path: Path | None) -> RobotDemoResult:
    """The robot demo's steps: the plan's figure and the logs into ``folder.out``, the
    report into ``folder.staged`` (:func:`.demo.demo_folder`)."""
    matplotlib.use("Agg")
    stream = hb.stream
    out, staged = folder.out, folder.staged
    t_start = time.perf_counter()
    if campaign_path is None:
        if robot not in ROBOT_DEMOS:
            raise DaqError(f"--robot: expected one of {', '.join(ROBOT_DEMOS)}, got {robot!r}")
        campaign_path = _example(ROBOT_DEMOS[robot])
    campaign = load_campaign(campaign_path)
    if campaign.plant != "arm":  # a simulated arm of the campaign's robot file
        raise DaqError(f"{campaign_path}: expected a robot campaign ([robot] table)")
    rob = robot_for_campaign(campaign)
    timing: dict[str, float] = {}

    # 1. plan: optimise the multi-sines, predict the excitation quality
    t0 = time.perf_counter()
    hb.status("planning: optimising the multi-sines")
    played, dyn, opt = prepare_robot_campaign(campaign, robot=rob)
    assessment = assess_robot_campaign(played, regressor=dyn.regressor,
                                       inverse_dynamics=dyn.inverse_dynamics)
    pred = assessment.quality
    plan = assessment.plan
    plot_robot_plan(plan, out / PLAN_PNG)  # in out at once: a rerun knows the folder by it
    timing["plan_s"] = time.perf_counter() - t0
    _say(stream, f"[1/5] planned {campaign.name}: {len(campaign.payloads)} payloads x "
                 f"{plan.duration_s:.1f} s at {1 / campaign.cycle_s:.0f} Hz, {plan.n_joints} "
                 f"joints; predicted condition number {pred.cond:.4g}"
                 + (f" (multi-sine optimised {opt[0].cond_start:.4g} -> {opt[0].cond_end:.4g})"
                    if opt else ""))

    # 2. run on the simulated buses (its own progress bar)
    hb.status(None)
    folder.replacing_logs()
    result, run_wall = run_with_bar(campaign, folder.logs, True, stream)
    timing["run_s"] = run_wall
    stop_if_interrupted(result, folder.logs)  # Ctrl-C: exit 130, not a failure
    if result.status != "done":
        raise DaqError(f"robot demo campaign {result.status}: {result.reason} "
                       f"(logs kept in {folder.logs})")
    folder.logs_done = True
    logs = tuple(r.path for r in result.runs)
    cycles = sum(r.cycles for r in result.runs)
    sim_s = cycles * campaign.cycle_s
    _say(stream, f"[2/5] ran {cycles} cycles of {plan.n_joints} drives over the simulated CAN "
                 f"buses in {run_wall:.1f} s ({sim_s / run_wall:.2f}x real time); "
                 f"{len(logs)} MCAP logs in {out / 'logs'}")

    # 3. condition number of the logged data (issue 12: prediction vs what was logged)
    hb.status("condition number of the logged data")
    logged = logged_condition_number(list(logs), dyn, pred, campaign.cycle_s)
    _say(stream, "[3/5] condition number: predicted " + f"{pred.cond:.4g}, logged "
         + ", ".join(f"{c:.4g}" for c in logged)
         + " (" + ", ".join(f"{100 * (c / pred.cond - 1):+.1f} %" for c in logged) + ")")

    # 4. n-dof fit of both models, Table III per joint
    t0 = time.perf_counter()
    hb.status("loading the logs and fitting the n-dof usual and paper models")
    runs = load_robot_runs(list(logs), rob.moving)
    fit = fit_robot(rob, runs, models=("usual", "paper"))
    text = format_report(fit)
    # the figures read the states chain's samples; the refinement the fit's own rows: the
    # states chain (no torque delay, a 50 Hz band at 1 kHz) showed the closed loop's reaction
    # to the encoder's quantisation as a torque lag of the arm (docs/campaign-robot.md)
    settings = resolved_settings(runs, None)
    pre = RobotPreprocessing(settings["cutoff_hz"], int(settings["decimation"]),
                             int(settings["trim"]))
    sig = preprocess_runs(runs, rob.moving, pre)
    ests = fit["_estimators"]
    vmax = [j.limits.max_velocity for j in campaign.joints]
    # Table III on the samples the fit used (joint j's torque at |dq_j| <= dq_min left out)
    t3 = table_iii(ests, fit["_signals"][0], vmax=vmax)
    timing["fit_s"] = time.perf_counter() - t0
    _say(stream, f"[4/5] fitted {', '.join(ests)} on {fit['preprocessing']['samples']} "
                 f"samples ({fit['method']}; "
                 f"{timing['fit_s']:.1f} s)")

    # 5. each model refined joint by joint on its own rows, the found terms refitted inside
    # its n-dof model (ident.cli_robot.refine_robot: what `jointid fit --robot --refine` does)
    t0 = time.perf_counter()
    refinements: dict[str, dict[str, Any]] = {}
    refits: dict[str, dict[str, Any]] = {}
    records: dict[str, dict[str, Any]] = {}
    for model in ests:
        what = f"refining the {model} model's residual"
        hb.status(what)

        def step(m: str, what: str = what) -> None:
            hb.status(f"{what}: {m}", restart=False)

        t_m = time.perf_counter()
        rec = refine_robot(fit, max_steps=max_steps, model=model, progress=step)
        done = fit.pop("_refinements")
        fit.pop("_refit", None)
        records[model] = fit.pop("refinement")
        refits[model] = rec["refit"]
        per: dict[str, Any] = {}
        for name in rob.moving:
            r = done.get(name, rec["joints"].get(name, {}).get("error", "not refined"))
            per[name] = r
            _say(stream, f"      {model} {name}: " + (
                f"not run ({r})" if isinstance(r, str) else
                ("; ".join(f"{s.effect} ({s.variable})" for s in r.steps) or "nothing left")))
        _say(stream, f"      {model} " + _refit_line(rec["refit"])
             + f" ({time.perf_counter() - t_m:.1f} s)")
        refinements[model] = per
    # fit.json holds the refinement `jointid fit --robot --refine` would write
    fit["refinement"] = records[refined_model(ests)]
    timing["refine_s"] = time.perf_counter() - t0
    _say(stream, f"[5/5] refined each joint's residual of the {' and the '.join(ests)} "
                 f"model(s) ({timing['refine_s']:.1f} s)")

    # figures and report
    hb.status("drawing the figures and writing the report")
    figures: dict[str, list[str]] = {}
    shutil.copy2(out / PLAN_PNG, staged / PLAN_PNG)  # the report's folder holds its figures
    for name, est in ests.items():
        for j, joint in enumerate(rob.moving):
            p = staged / f"direct_validation_{name}_{joint}.png"
            joint_validation(est, sig, None, j, name).savefig(p, dpi=90)
            figures.setdefault(name, []).append(p.name)
    truth_std = arm_truth(played).truth()
    wall = time.perf_counter() - t_start
    timing["wall_s"] = wall
    summary = _summary(campaign, t3, refinements, refits, pred.cond, logged, sim_s, run_wall,
                       wall)
    public = {k: v for k, v in fit.items() if not k.startswith("_")}
    write_json(staged / "fit.json", public)
    demo = {
        "campaign": str(campaign_path), "robot": rob.source, "joints": list(rob.moving),
        "predicted_condition_number": pred.cond, "logged_condition_number": logged,
        "base_columns": pred.base_columns.tolist(),
        "table_iii": t3, "timing": timing, "cycles": cycles, "simulated_s": sim_s,
        "refinement": {m: {n: (r if isinstance(r, str) else r.to_json())
                           for n, r in per.items()} for m, per in refinements.items()},
        "refit": refits,
        "logs": [str(p.relative_to(out)) for p in logs],
    }
    write_json(staged / "demo.json", demo)
    report = _write_report(staged, campaign, rob, assessment, result, fit, text, t3, ests,
                           truth_std, refinements, refits, logged, figures, summary, sim_s)
    return RobotDemoResult(out, report, logs, summary, figures)


def _refit_line(fit: dict[str, Any]) -> str:
    """One line of the n-dof refit (:func:`ident.robot.refit.refit_robot`): per joint and
    for the robot, the error of the n-dof fit -> the refit with the found terms kept, and
    those the held-out check refused (:mod:`ident.robot.refit_accept`)."""
    if "error" in fit:
        return f"n-dof refit not done: {fit['error']}"
    if "skipped" in fit:
        return f"n-dof refit: none ({fit['skipped']})"
    ba = fit["rel_error"]
    n = len(fit.get("extras", []))
    refused = fit.get("refused") or []
    tail = ("" if not refused else "; refused (they raised the held-out error): " + ", ".join(
        f"{r['joint']} {r['effect']}" for r in refused))
    return (f"n-dof refit with {n} found term(s), every parameter together: " + ", ".join(
        f"{j} {ba['before'][j]:.4f} -> {ba['after'][j]:.4f}" for j in ba["before"]) + tail)


def _summary(campaign: RobotCampaign, t3: dict, refinements: dict, refits: dict, pred: float,
             logged: list[float], sim_s: float, run_wall: float, wall: float) -> str:
    lines = ["", f"Robot demo {campaign.name}: {sim_s:.0f} s of simulated motion in "
             f"{run_wall:.0f} s on the bus ({sim_s / run_wall:.2f}x real time)",
             f"condition number: predicted {pred:.4g}, logged "
             + ", ".join(f"{c:.4g}" for c in logged), "",
             "Table III per joint — relative norm of errors ||rho||/||tau||",
             format_table_iii(t3), ""]
    lines.append("Refinement of each joint's residual (ident.refine; relative error "
                 "||rho_j||/||tau_j||)")
    for model, per in refinements.items():
        for name, r in per.items():
            if isinstance(r, str):
                lines.append(f"  {model:>6} {name}: not run ({r})")
                continue
            steps = "; ".join(f"{s.effect} ({s.variable})" for s in r.steps) or "nothing left"
            lines.append(f"  {model:>6} {name}: {steps}; {r.rel_error_initial:.4f} -> "
                         f"{r.rel_error_final:.4f}")
        lines.append(f"  {model:>6} {_refit_line(refits[model])}")
    lines.append(f"(whole demo: {wall:.0f} s)")
    return "\n".join(lines)


def _write_report(out: Path, campaign: RobotCampaign, rob: Any, assessment: Any, result: Any,
                  fit: dict, text: str, t3: dict, ests: dict, truth_std: dict,
                  refinements: dict, refits: dict, logged: list[float], figures: dict,
                  summary: str,
                  sim_s: float) -> Path:
    pred = assessment.quality
    intro = Section("What was run").para(
        f"The robot campaign {campaign.name} ({len(campaign.payloads)} payloads) "
        f"was planned for the {len(rob.moving)} moving joints of {rob.source}, "
        "then run through jointid's CANopen master against one simulated CiA 402 drive per "
        "joint (real canopen nodes on simulated CAN buses) in front of one simulated arm "
        "(pinocchio dynamics with the paper's load- and velocity-dependent friction on every "
        "joint, sim_drivers.arm). The logs are the MCAP files a hardware run writes; the fit "
        "reads them back. The simulator's true parameters are shown beside the identified "
        "ones; with real data that column does not exist.")
    intro.raw(f"<pre>{html.escape(str(assessment))}</pre>")
    intro.figure(out / PLAN_PNG, "one payload run of the plan")
    cond = Section("Excitation: predicted vs logged condition number").para(
        f"Condition number of the robot model's regressor (standard parameters, rotor "
        f"inertias, usual friction; {pred.rank} base columns chosen at random states) over "
        f"the plan: {pred.cond:.4g}. Over the logged q, dq (ddq by filtered differentiation) "
        f"of each run, same base columns and stride: "
        + ", ".join(f"{c:.4g}" for c in logged) + ".")
    cond.raw(f"<pre>{html.escape(result.summary())}</pre>")
    t3_rows = []
    for joint, models in t3.items():
        bands = list(next(iter(models.values())))
        for b in bands:
            t3_rows.append([joint, b, *(f"{100 * models[m][b]:.2f}" for m in models)])
    models = list(next(iter(t3.values())))
    tab = Section("Table III per joint").para(
        "Relative norm of the torque error ||rho_j|| / ||tau_j|| [%] of each joint, all "
        "samples and by velocity band (fractions of the joint's max velocity), "
        "identification data.").raw(html_table(["joint", "samples", *models], t3_rows))
    sections = [intro, cond, tab]
    for name, est in ests.items():
        truth = est.truth_vector(truth_std)
        rows = []
        for n, v, s, tv in zip(est.names_, est.coef_, est.std_, truth, strict=True):
            rel = f"{100 * s / abs(v):.2f}" if v else "—"
            rows.append([n, f"{v:.5g}", f"{s:.3g}", rel, "—" if not np.isfinite(tv)
                         else f"{tv:.5g}"])
        sec = Section(f"{name} model: parameters").raw(html_table(
            ["parameter", "estimate", "std", "rel. std [%]", "simulator truth"], rows))
        for fname in figures.get(name, []):
            sec.figure(out / fname, f"{name} model, {fname.split('_')[-1][:-4]}")
        sections.append(sec)
    ref = Section("Refinement of each joint's residual").para(
        "ident's single-joint refinement (ident.refine) on each joint of each n-dof fit "
        "(the samples the fit used): the declared model is the n-dof prediction (times a gain "
        "~1, also the load prediction) plus the usual friction (F_C, F_V, tau_off) refitted "
        "on the joint's measured torque, so the residual is the n-dof residual; an accepted "
        "step names an effect still in it. Relative errors are ||rho_j|| / ||tau_j||. The "
        "other joints' positions and velocities (q<m>, dq<m>, m = joint number in the moving "
        "chain) are searched too: a step in one of them is a cross-joint effect. Then the "
        "terms found on every joint are refitted inside the n-dof model with every parameter "
        "together (ident.robot.refit; last rows: the n-dof fit -> the refit, per joint).")
    rows = []
    for model, per in refinements.items():
        for joint, r in per.items():
            if isinstance(r, str):
                rows.append([model, joint, "not run", r, "", ""])
                continue
            steps = "; ".join(f"{s.effect} ({s.variable})" for s in r.steps) or "none accepted"
            rej = "; ".join(f"{x.effect}: {x.reason}" for x in r.rejected[:3]) or "—"
            rows.append([model, joint, steps, rej,
                         f"{r.rel_error_initial:.4f}", f"{r.rel_error_final:.4f}"])
    for model, fit_ in refits.items():
        if "error" in fit_ or "skipped" in fit_:
            rows.append([model, "n-dof refit", "not done" if "error" in fit_ else "none",
                         fit_.get("error") or fit_["skipped"], "", ""])
            continue
        terms = "; ".join(f"{x['joint']}: {x['effect']}" for x in fit_.get("extras", []))
        for joint, before in fit_["rel_error"]["before"].items():
            rows.append([model, f"n-dof refit, {joint}", terms or "no term", "—",
                         f"{before:.4f}", f"{fit_['rel_error']['after'][joint]:.4f}"])
    ref.raw(html_table(["model", "joint", "accepted", "rejected (first 3)",
                        "rel. error before", "after"], rows))
    sections.append(ref)
    sections.append(Section("Fit tables").raw(f"<pre>{html.escape(text)}</pre>"))
    sections.append(Section("Summary").raw(f"<pre>{html.escape(summary)}</pre>"))
    sub = (f"jointid {__version__} — {len(result.runs)} payload runs, {sim_s:.0f} s of simulated "
           f"motion, {len(rob.moving)} joints")
    path = write_html(out / "report.html", f"jointid demo --robot: {rob.name}", sub, sections)
    (out / "summary.txt").write_text(summary + "\n", encoding="utf-8")
    return path
