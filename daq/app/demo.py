"""The demo pipeline: plan → run on the simulated drive → fit both models → refine → report.

Everything goes through the production code: the campaign is run by
:func:`daq.runtime.runner.run_campaign` over python-can's virtual bus against
:class:`sim_drivers.drive.SimulatedDrive`, the logs are the MCAP files a hardware run would
write, and the fit reads them back with :mod:`ident.loaders`.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from daq import DaqError, __version__, examples
from daq.runtime.progress import Heartbeat

# the pipeline's modules (scipy, matplotlib, pinocchio, canopen...) are imported by the
# functions that run it: `jointid --help` and `jointid demo --help` must not wait for them

#: ``--robot`` choices -> shipped campaign (:func:`daq.app.demo_robot.run_robot_demo`)
ROBOT_DEMOS = {"3": "campaign_robot3_demo.toml", "6": "campaign_ur10_demo.toml"}

TITLE = "jointid demo: simulated Stäubli RX130L joint 3"


@dataclass(frozen=True)
class DemoResult:
    """What :func:`run_demo` produced."""

    out_dir: Path
    report: Path
    fit_json: Path
    logs: tuple[Path, ...]
    summary: str
    fit: dict


def _say(stream: TextIO, text: str) -> None:
    stream.write(text + "\n")
    stream.flush()


#: the files of a demo's report that describe its logs: an earlier demo's are removed when
#: a new demo starts replacing its logs (:meth:`DemoFolder.replacing_logs`)
REPORT_RECORDS = ("report.html", "fit.json", "demo.json", "summary.txt")
#: the plan's figure, written into DIR before the run (a rerun recognises DIR by it)
PLAN_PNG = "campaign_plan.png"


@dataclass
class DemoFolder:
    """A demo's ``--out`` folder while the demo runs (:func:`demo_folder`).

    Attributes
    ----------
    out : Path
        The folder the user named.
    staged : Path
        Where the report is written: fit.json, demo.json, the figures, report.html (moved
        into ``out`` when the demo ends; :func:`ident.report.staged_folder`).
    logs_done : bool
        The campaign's run completed: its logs in ``out/logs`` are whole.
    """

    out: Path
    staged: Path
    logs_done: bool = False

    @property
    def logs(self) -> Path:
        """``out/logs``: the campaign's run folder."""
        return self.out / "logs"

    def replacing_logs(self) -> None:
        """The run is about to replace an earlier demo's logs: its report goes with them --
        its records (:data:`REPORT_RECORDS`) and the figures its report wrote
        (:func:`ident.report.remove_written`), not the new plan's figure --, so that a demo
        stopped from here on leaves its own logs and no report, not the earlier demo's report
        or figures beside logs they do not describe."""
        from ident.report import WRITTEN_LIST, remove_written

        for name in REPORT_RECORDS:
            (self.out / name).unlink(missing_ok=True)
        remove_written(self.out, keep=(PLAN_PNG,))
        (self.out / WRITTEN_LIST).unlink(missing_ok=True)


@contextmanager
def demo_folder(out: Path) -> Iterator[DemoFolder]:
    """The rule of what a demo leaves in ``out``, whatever stops it.

    As the demo goes, ``out`` gets the plan's figure (campaign_plan.png) and the run's
    folder ``out/logs`` (each payload's MCAP log closed as its run ends, kept when a stop
    or Ctrl-C ends the run: :mod:`daq.runtime.runfolder`). The report (fit.json, demo.json,
    the figures, report.html, summary.txt) is written into a staged folder and moved into
    ``out`` at the end, one rename per file (:func:`ident.report.staged_folder`). So an
    error or an interrupt (Ctrl-C, SIGTERM) leaves the logs and no report: none of its
    files, and not an earlier demo's (:meth:`DemoFolder.replacing_logs`). A demo stopped
    before its first log leaves nothing: ``out`` and the parent folders it created are
    removed. An interrupt after the run completed says where its logs are kept.

    Yields
    ------
    DemoFolder
        ``out`` created, the staged folder empty.
    """
    from daq.runtime.runfolder import missing_folders, remove_unused_folders
    from ident.report import staged_folder

    created = missing_folders(out)
    folder = None
    try:
        out.mkdir(parents=True, exist_ok=True)
        with staged_folder(out) as tmp:
            folder = DemoFolder(out, tmp)
            yield folder
    except BaseException as exc:
        logs = out / "logs"
        if not any(logs.glob("*.mcap")):  # before its first log: nothing of it is kept
            remove_unused_folders([logs])
            if created and {p.name for p in out.iterdir()} <= {PLAN_PNG}:
                (out / PLAN_PNG).unlink(missing_ok=True)
            remove_unused_folders(created)
        elif (isinstance(exc, KeyboardInterrupt) and folder is not None and folder.logs_done
              and not getattr(exc, "detail", "")):
            exc.detail = (f"the demo's logs are complete in {logs}; "  # type: ignore[attr-defined]
                          f"its report was not written")
        raise


def run_demo(out_dir: str | Path, *, quick: bool = False, max_steps: int = 3,
             stream: TextIO | None = None, campaign_path: Path | None = None,
             plant_path: Path | None = None) -> DemoResult:
    """Run the whole product on the embedded default and write ``out_dir/report.html``.

    Parameters
    ----------
    out_dir : path-like
        Output folder: ``logs/*.mcap``, ``fit.json``, ``demo.json``, PNG figures, ``report.html``
        (the report written whole or not at all, the logs kept: :func:`demo_folder`).
    quick : bool
        Use :meth:`trajectories.robot_campaign.RobotCampaign.quick` (a shortened campaign).
    max_steps : int
        Refinement steps at most.
    stream : text stream
        Progress and stage messages (default stderr).
    campaign_path, plant_path : path, optional
        Override the shipped ``examples/campaign.toml`` / ``examples/plant_rx130l.toml``.

    Raises
    ------
    DaqError
        When the campaign stops before its end (the message names the cause).
    daq.runtime.safety.RunInterrupted
        A stop signal (Ctrl-C...) ended the campaign's run: the drive was stopped and the
        logs closed; ``jointid`` exits 128 + the signal (:func:`.running.stop_if_interrupted`).
    """
    with Heartbeat(stream if stream is not None else sys.stderr) as hb:
        return _run_demo(hb, out_dir, quick=quick, max_steps=max_steps,
                         campaign_path=campaign_path, plant_path=plant_path)


def _run_demo(hb: Heartbeat, out_dir: str | Path, *, quick: bool, max_steps: int,
              campaign_path: Path | None, plant_path: Path | None) -> DemoResult:
    """:func:`run_demo`'s body; ``hb.stream`` is the progress stream, ``hb.status`` names the
    step running (a line at least every few seconds on a silent step)."""
    # the demo's first line at once: the imports take seconds on a loaded machine (about
    # 4.5 s on 2 cores at load average 2, the robot demo's 6 s)
    hb.status("loading the pipeline's modules", say=True)
    out = Path(out_dir)
    with demo_folder(out) as folder:  # the logs kept, the report whole or absent
        res = _demo_steps(hb, folder, quick=quick, max_steps=max_steps,
                          campaign_path=campaign_path, plant_path=plant_path)
    # moved into out: the report's files by their names
    return DemoResult(out, out / res.report.name, out / res.fit_json.name, res.logs,
                      res.summary, res.fit)


def _demo_steps(hb: Heartbeat, folder: DemoFolder, *, quick: bool, max_steps: int,
                campaign_path: Path | None, plant_path: Path | None) -> DemoResult:
    """The demo's steps under ``hb`` (its status "loading the pipeline's modules" until
    they are): the plan's figure and the logs into ``folder.out``, the report into
    ``folder.staged`` (:func:`demo_folder`)."""
    import matplotlib

    from daq.runtime.progress import ProgressLine
    from ident.fitting import fit_models
    from ident.loaders import load_experiments
    from ident.plots import write_plots
    from ident.refine import refine
    from ident.refine_plots import plot_refinement
    from ident.report import write_json
    from ident.report_build import build_report, discover_figures
    from sim_drivers.plant_config import load_plant
    from trajectories.campaign_file import load_campaign
    from trajectories.cli import plot_plan
    from trajectories.multi import plan_robot_campaign

    from .running import run_with_bar, stop_if_interrupted

    hb.status(None)
    matplotlib.use("Agg")
    stream = hb.stream
    out, staged = folder.out, folder.staged
    t_start = time.perf_counter()
    cpath = campaign_path or examples.path("campaign.toml")
    ppath = plant_path or examples.path("plant_rx130l.toml")
    campaign = load_campaign(cpath)
    if campaign.plant != "joint":  # the demo's plant is a plant file's joint
        raise DaqError(f"{cpath}: expected a single-joint campaign ([joint] table), got a "
                       f"robot campaign (jointid demo --robot)")
    if quick:
        campaign = campaign.quick()
    plant = load_plant(ppath)

    # 1. plan (checked against the limits before anything moves)
    hb.status("planning the campaign")
    plan = plan_robot_campaign(campaign)
    summary = plan.summary()
    plot_plan(plan, out / PLAN_PNG)  # in out at once: a rerun knows the folder by it
    _say(stream, f"[1/4] planned {campaign.name}: {len(campaign.payloads)} payloads x "
                 f"{plan.run_duration_s:.1f} s at {1 / campaign.cycle_s:.0f} Hz")

    # 2. run on the simulated drive over the virtual CAN bus (its own progress bar)
    hb.status(None)
    folder.replacing_logs()
    result, run_wall = run_with_bar(campaign, folder.logs, plant, stream)
    stop_if_interrupted(result, folder.logs)  # Ctrl-C: exit 130, not a failure
    if result.status != "done":
        raise DaqError(f"demo campaign {result.status}: {result.reason} "
                       f"(logs kept in {folder.logs})")
    folder.logs_done = True
    logs = tuple(r.path for r in result.runs)
    sim_s = sum(r.cycles for r in result.runs) * campaign.cycle_s
    _say(stream, f"[2/4] ran {sum(r.cycles for r in result.runs)} cycles over the virtual CAN "
                 f"bus in {run_wall:.1f} s ({sim_s / run_wall:.1f}x real time); "
                 f"{len(logs)} MCAP logs in {out / 'logs'}")

    # 3. fit both models on all payloads (one global system, eq. 36 and 40). As in the
    # paper (section III.D), q_s is first chosen a priori — the stiction-to-sliding transition
    # takes about 3 q_s, about 10 % of the nominal velocity — and adjusted once the model
    # is complete (after refinement), to the value that minimises the residual.
    t0 = time.perf_counter()
    hb.status("loading the logs and fitting the usual and the paper model")
    (joint,) = campaign.joints
    exps = load_experiments(list(logs), joint=joint.kind)
    qs0 = round(joint.limits.max_velocity / 30.0, 6)
    report = fit_models(exps, ("usual", "paper"), q_s=qs0)
    est = report.models["paper"].estimator_.upper()
    _say(stream, f"[3/4] fitted the usual and the paper model on {len(exps)} runs "
                 f"({est}, q_s = {qs0:g} rad/s a priori; {time.perf_counter() - t0:.1f} s)")
    for note in report.notes:  # what the fit warns of (also in fit.json and the report)
        _say(stream, "      note: " + note)

    # 4. close the loop: refine the paper model from its residual, then adjust q_s
    t0 = time.perf_counter()

    def step_line(m: str) -> None:
        hb.status(f"refining the paper model, {m}", restart=False)
        _say(stream, "      " + m)

    def refine_new(rep: Any) -> Any:
        hb.status("refining the paper model, step 1: scoring the candidate effects")
        ref = refine(rep.designs["paper"], rep.models["paper"], max_steps=max_steps,
                     vmax=rep.vmax, progress=step_line)
        # the found terms refitted inside the joint's robot model (issue 24's closed loop)
        ref.refit = rep.refit_found_terms("paper", ref.terms, ref.final_design)
        return ref

    ref = refine_new(report)
    bar = ProgressLine(stream)

    def scan_progress(done: int, expected: int, q: float, err: float) -> None:
        hb.status(f"adjusting q_s with the refined model: fit {done + 1}", restart=False)
        bar.update(done / max(done, expected),
                   f"adjusting q_s with the refined model: fit {done}, q_s = {q:.4g} rad/s, "
                   f"error {100 * err:.3f} %")

    hb.status("adjusting q_s with the refined model: fit 1")
    try:
        # each q_s: the found terms refitted inside the joint's robot model (as ref.refit)
        rs = report.rescan_found_terms("paper", ref.terms, ref.final_design,
                                       progress=scan_progress)
    finally:
        bar.close()
    if abs(rs.q_s - qs0) > 0.01 * qs0:
        _say(stream, f"      q_s adjusted with the refined model: {qs0:g} -> {rs.q_s:.4g} rad/s")
        hb.status(f"fitting both models again with q_s = {rs.q_s:.4g} rad/s")
        said = set(report.notes)
        report = fit_models(exps, ("usual", "paper"), q_s=rs.q_s, like=report)
        for note in report.notes:  # the refit's own warnings (fit.json keeps these)
            if note not in said:
                _say(stream, "      note: " + note)
        ref = refine_new(report)
    fit = report.to_json()
    fit["q_s_a_priori"] = qs0
    fit["q_s_rescan"] = [{"q_s": q, "rel_error": e} for q, e in rs.scan]
    fit["refinement"] = ref.to_json()
    fit["refinement"]["model"] = "paper"
    _say(stream, f"[4/4] refinement: {len(ref.steps)} step(s), relative error "
                 f"{ref.rel_error_initial:.4f} -> {ref.rel_error_final:.4f}, q_s = "
                 f"{report.q_s:.4g} rad/s ({time.perf_counter() - t0:.1f} s)")
    rf = ref.refit or {"error": "not made"}
    _say(stream, "      the found terms refitted inside the joint's robot model, every parameter "
                 + (f"together: {rf['rel_error']['before']['all']:.4f} -> "
                    f"{rf['rel_error']['after']['all']:.4f}" if "error" not in rf
                    else f"together: not made ({rf['error']})"))

    # figures (captions and grouping: report_build.discover_figures)
    hb.status("drawing the figures and writing the report")
    shutil.copy2(out / PLAN_PNG, staged / PLAN_PNG)  # the report's folder holds its figures
    written = [staged / PLAN_PNG, *write_plots(report, staged), *plot_refinement(ref, staged)]
    figures = discover_figures(staged, only=written)

    truth = plant.truth()
    demo = {
        "description": (
            f"The example campaign ({campaign.name}) was run on jointid's simulated CiA 402 "
            f"drive over python-can's virtual CAN bus, through the same CANopen master and MCAP "
            f"logging a hardware run uses. The simulated joint follows the paper's load- and "
            f"velocity-dependent friction (eq. 30) and has undeclared effect(s) switched on: "
            f"{', '.join(plant.effects.enabled()) or 'none'}. "
            "The demo knows the plant's true parameters and shows them beside the identified "
            "ones; with real data that column does not exist."
        ),
        "subtitle": f"jointid {__version__} — {'quick' if quick else 'full'} demo, "
                    f"{len(logs)} payload runs, {sim_s:.0f} s of simulated motion",
        "campaign_summary": summary.format_table(),
        "run_summary": result.summary(),
        "truth": truth,
        "truth_effects": plant.truth_effects(),
        "figures": figures,
        "logs": [str(p.relative_to(out)) for p in logs],
    }
    write_json(staged / "demo.json", demo)
    fit_path = write_json(staged / "fit.json", fit)
    html = build_report(staged, title=TITLE)
    text = _summary(fit, ref, time.perf_counter() - t_start)
    return DemoResult(out, html, fit_path, logs, text, fit)


def _summary(fit: dict, ref: Any, wall_s: float) -> str:
    from ident.refine_result import ONE_TRAJECTORY_NOTE, leak_note

    m = fit["models"]
    rows = [
        ("All samples (all velocities)", "rel_error"),
        ("Low velocities (0-10 % of max)", "rel_error_low_velocity"),
        ("High velocities (35-100 % of max)", "rel_error_high_velocity"),
    ]
    lines = ["", "Table III — relative norm of errors ||rho||/||Y||",
             f"{'Measurements used':<36}{'Usual model':>13}{'Paper model':>13}"]
    for label, key in rows:
        u, n = m["usual"].get(key), m["paper"].get(key)
        lines.append(f"{label:<36}{_f(u):>13}{_f(n):>13}")
    lines.append("")
    leak = leak_note(min(ref.rel_error_final, ref.heldout_rel_error_final), ref.noise_floor)
    lines.append(f"Refinement of the paper model: {_f(ref.rel_error_initial)} -> "
                 f"{_f(ref.rel_error_final)} ({ref.heldout_kind} "
                 f"{_f(ref.heldout_rel_error_initial)} -> {_f(ref.heldout_rel_error_final)}; "
                 f"noise floor {_f(ref.noise_floor)}"
                 f"{leak})")
    for i, s in enumerate(ref.steps, 1):
        params = ", ".join(f"{k} = {v['value']:.4g}" for k, v in s.parameters.items())
        lines.append(f"  step {i}: residual depends on {s.variable} -> added {s.effect} "
                     f"({params}); {_f(s.rel_error_before)} -> {_f(s.rel_error_after)}")
    if not ref.steps:
        lines.append("  nothing significant left in the residual")
    if ref.heldout_one_trajectory and ref.validation_rel_error_initial is None:
        lines.append(f"  {ONE_TRAJECTORY_NOTE}")
    lines.append(f"(whole demo: {wall_s:.0f} s)")
    return "\n".join(lines)


def _f(x: float | None) -> str:
    return "—" if x is None else f"{x:.4f}"


# ------------------------------------------------------------------ jointid demo
def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="run the whole campaign on the simulated joint and write a report",
        description="Plan the example campaign, run it on the simulated CiA 402 drive over a "
        "virtual CAN bus, log to MCAP, fit the usual and the paper model, refine from the "
        "residual, and write DIR/report.html.",
    )
    p.add_argument("--out", type=Path, default=Path("jointid-demo"),
                   help="output folder (default: ./jointid-demo)")
    p.add_argument("--quick", action="store_true",
                   help="a shortened campaign (under a minute on 2 cores)")
    p.add_argument("--max-steps", type=int, default=None,
                   help="refinement steps (default 3; per joint with --robot: 2)")
    p.add_argument("--robot", nargs="?", const="3", default=None, choices=tuple(ROBOT_DEMOS),
                   help="a whole robot campaign instead: the 3-dof arm (default, "
                   "examples/robots/arm3.toml) or 6 for the UR10; plan, run on simulated "
                   "buses, n-dof fit (usual and paper), Table III and refinement per joint")
    p.set_defaults(func=_demo)


#: files a demo writes first (its plan, then its record): a folder holding one of them is an
#: earlier demo's, which a demo regenerates
DEMO_MARKS = ("demo.json", "campaign_plan.png")


def check_demo_args(out: Path, max_steps: int | None) -> None:
    """Refuse, before anything runs, what the demo would fail on or destroy late.

    Parameters
    ----------
    out : Path
        The ``--out`` folder: absent, empty, or an earlier demo's (it holds one of
        :data:`DEMO_MARKS`), which the demo regenerates. Any other folder with files in it
        (a ``jointid run`` folder, a ``jointid fit --report`` folder...) is refused: the demo
        would replace its ``fit.json`` and ``report.html`` or mix its logs in; so is one
        where a name of the report (:data:`REPORT_RECORDS`) is a folder.
    max_steps : int or None
        ``--max-steps``: >= 0 (None: the default).

    Raises
    ------
    DaqError
        Naming the option and what was expected.
    """
    if max_steps is not None and max_steps < 0:
        raise DaqError(f"--max-steps {max_steps}: expected a number of refinement steps >= 0")
    if out.exists() and not out.is_dir():
        raise DaqError(f"--out {out}: is a file, expected a folder (new, empty, or an "
                       f"earlier demo's)")
    if out.is_dir() and not any((out / m).exists() for m in DEMO_MARKS):
        found = sorted(p.name for p in out.iterdir())
        if found:
            shown = ", ".join(found[:3]) + (", ..." if len(found) > 3 else "")
            raise DaqError(f"--out {out}: holds files that are not an earlier demo's "
                           f"({shown}; no demo.json): expected a new or empty folder, the "
                           f"demo writes logs/, fit.json and report.html there")
    for name in REPORT_RECORDS:  # else known only as the report is moved in, after the run
        if (out / name).is_dir():
            raise DaqError(f"--out {out}: {out / name} is a folder, expected the demo's file "
                           f"name (remove or rename it, or give another --out)")


def _demo(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    check_demo_args(args.out, args.max_steps)
    if args.robot is not None:
        if args.quick:
            raise DaqError("--quick: expected the single-joint demo (the robot demo is "
                           "already short)")
        with Heartbeat(sys.stderr) as hb:  # a line at once, then if this takes seconds
            hb.status("loading the robot demo's modules", say=True)
            from .demo_robot import run_robot_demo

            hb.status(None)  # the robot demo's own heartbeat, counting from the last line
            res = run_robot_demo(args.out, robot=args.robot, stream=hb.stream,
                                 max_steps=2 if args.max_steps is None else args.max_steps)
        print(res.summary)
        print(f"report: {res.report}  ({time.perf_counter() - t0:.0f} s)")
        return 0
    result = run_demo(args.out, quick=args.quick,
                      max_steps=3 if args.max_steps is None else args.max_steps,
                      stream=sys.stderr)
    print(result.summary)
    print(f"report: {result.report}  ({time.perf_counter() - t0:.0f} s)")
    return 0

