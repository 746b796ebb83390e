"""No stale file of an earlier output: a report (``jointid fit --report``, a demo's, an
``export-model -o``) moved into a folder that holds an earlier one removes the earlier one's
files it does not rewrite (:data:`ident.report.WRITTEN_LIST`), never the user's other files;
a SIGKILL during the move leaves a mix that the next output clears.

Before: ``fit --model both --report DIR`` then ``fit --model usual --report DIR`` left the
paper model's figures of the first fit in DIR, which ``jointid report DIR`` then showed
beside the new fit; a demo's interrupted rerun left the earlier demo's figures beside its new
logs.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_bad_inputs_sweep import _csv

from daq.app.cli import main
from daq.app.demo import PLAN_PNG, DemoFolder
from ident.report import WRITTEN_LIST, staged_folder, written_files

ROOT = Path(__file__).resolve().parents[1]


def _output(final: Path, names: list[str], text: str = "x") -> None:
    """An output of ``names`` (files holding ``text``) written through a staged folder."""
    with staged_folder(final) as tmp:
        for n in names:
            (tmp / n).write_text(text)


def _names(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()}


def test_the_earlier_outputs_files_not_rewritten_go(tmp_path):
    rep = tmp_path / "rep"
    _output(rep, ["fit.json", "a_usual.png", "a_paper.png", "report.html"], "old")
    assert _names(rep) == {"fit.json", "a_usual.png", "a_paper.png", "report.html",
                           WRITTEN_LIST}
    (rep / "notes.txt").write_text("mine\n")  # the user's
    (rep / "plots").mkdir()  # the user's folder
    _output(rep, ["fit.json", "a_usual.png", "report.html"], "new")
    assert _names(rep) == {"fit.json", "a_usual.png", "report.html", "notes.txt", "plots",
                           WRITTEN_LIST}
    assert all((rep / n).read_text() == "new" for n in ("fit.json", "a_usual.png"))
    assert (rep / "notes.txt").read_text() == "mine\n"
    assert sorted(written_files(rep)) == ["a_usual.png", "fit.json", "report.html"]


def test_only_plain_files_of_the_folder_are_removed(tmp_path):
    """A list naming paths outside the folder, itself, or a name now a folder: none of those
    touched."""
    rep = tmp_path / "rep"
    outside = tmp_path / "outside.png"
    outside.write_text("keep")
    _output(rep, ["fig.png"])
    (rep / "was_ours").mkdir()
    (rep / WRITTEN_LIST).write_text(json.dumps({"files": [
        "../outside.png", str(outside), "fig.png", "was_ours", "..", ".", "", 3,
        WRITTEN_LIST]}))
    _output(rep, ["other.png"])
    assert outside.read_text() == "keep"
    assert _names(rep) == {"other.png", "was_ours", WRITTEN_LIST}


def test_a_folder_without_the_list_keeps_its_files(tmp_path):
    """A folder written before the list existed (or by anything else): nothing removed."""
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "old_paper.png").write_text("old")
    _output(rep, ["new.png"])
    assert _names(rep) == {"old_paper.png", "new.png", WRITTEN_LIST}


def test_a_refused_output_changes_nothing(tmp_path):
    rep = tmp_path / "rep"
    _output(rep, ["fig.png", "gone.png"])
    (rep / "fit.json").mkdir()  # a name of the output taken by a folder: refused
    before = {p.name: (p.read_bytes() if p.is_file() else b"<dir>") for p in rep.iterdir()}
    with pytest.raises(Exception, match="is a folder"):
        _output(rep, ["fig.png", "fit.json"])
    assert {p.name: (p.read_bytes() if p.is_file() else b"<dir>")
            for p in rep.iterdir()} == before


def test_fit_report_leaves_no_figure_of_the_earlier_fit(tmp_path, capfd):
    """``fit --model both --report DIR``, then ``--model usual`` into the same DIR: DIR's
    figures are the second fit's (its record's list), the user's note stays."""
    data = _csv(tmp_path / "run.csv")
    rep = tmp_path / "rep"
    assert main(["fit", str(data), "--model", "both", "--report", str(rep)]) == 0
    first = {p.name for p in rep.glob("*.png")}
    assert any("paper" in n for n in first), first
    (rep / "notes.txt").write_text("mine\n")
    assert main(["fit", str(data), "--model", "usual", "--report", str(rep)]) == 0
    capfd.readouterr()
    figures = {Path(f).name for f in json.loads((rep / "fit.json").read_text())["figures"]}
    assert {p.name for p in rep.glob("*.png")} == figures
    assert not any("paper" in n for n in figures), figures
    assert (rep / "notes.txt").read_text() == "mine\n"
    assert main(["report", str(rep)]) == 0  # regenerated from what is there: no paper figure
    capfd.readouterr()
    assert "_paper.png" not in (rep / "report.html").read_text()


def test_demo_replacing_its_logs_removes_the_earlier_reports_figures(tmp_path):
    """A demo rerun in an earlier demo's folder, from the moment it replaces the logs: the
    earlier report's records and figures are gone, the new plan's figure kept (a stop from
    here on leaves the new logs and no report)."""
    out = tmp_path / "demo"
    _output(out, [PLAN_PNG, "fit.json", "demo.json", "report.html", "refine_step2.png",
                  "direct_validation_paper.png"], "earlier")
    (out / "logs").mkdir()
    (out / "logs" / "run.mcap").write_text("earlier log")
    (out / PLAN_PNG).write_text("the new plan")  # written by the new demo first
    DemoFolder(out, out / ".staged").replacing_logs()
    assert _names(out) == {PLAN_PNG, "logs"}
    assert (out / PLAN_PNG).read_text() == "the new plan"


# -- a SIGKILL while the output is moved in ---------------------------------------------------

N_NEW = 3000
WRITER = """
import sys
from pathlib import Path
from ident.report import staged_folder
final, n = Path(sys.argv[1]), int(sys.argv[2])
with staged_folder(final) as tmp:
    for i in range(n):
        (tmp / f"new_{i:05d}.png").write_text("new")
    print("staged", flush=True)
"""


def test_sigkill_while_moving_in_leaves_a_mix_the_next_output_clears(tmp_path):
    """What remains: the move into an existing folder is one rename per file (not atomic), so a
    SIGKILL between two renames leaves some new files beside the earlier output's. The list
    then names both outputs' files: the next output removes them all (and the killed
    process's staged folder)."""
    rep = tmp_path / "rep"
    _output(rep, [f"old_{i:05d}.png" for i in range(N_NEW)], "old")
    (rep / "notes.txt").write_text("mine\n")
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(rep), str(N_NEW)], cwd=ROOT,
                            stdout=subprocess.PIPE, text=True)
    first = rep / "new_00000.png"
    try:
        assert proc.stdout.readline().strip() == "staged"
        t_end = time.monotonic() + 60
        while not first.exists():
            assert proc.poll() is None and time.monotonic() < t_end, "no file moved in"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    names = _names(rep)
    new = {n for n in names if n.startswith("new_")}
    old = {n for n in names if n.startswith("old_")}
    assert new and (len(new) < N_NEW or old), "the kill came after the move"  # a mix
    assert new | old <= set(written_files(rep))  # both outputs' files listed as ours
    assert any(".part-" in n for n in names)  # the killed process's staged folder
    _output(rep, ["fit.json", "third.png"])
    assert _names(rep) == {"fit.json", "third.png", "notes.txt", WRITTEN_LIST}
    assert (rep / "notes.txt").read_text() == "mine\n"


def test_a_staged_folder_of_a_live_writer_is_left(tmp_path):
    """Only a dead writer's staged folder goes: another process still writing keeps its."""
    rep = tmp_path / "rep"
    _output(rep, ["fig.png"])
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    try:
        (rep / f".rep.part-{live.pid}-00abcd").mkdir()
        (rep / f".rep.part-{dead.pid}-00abcd").mkdir()
        (rep / f".rep.part-{dead.pid}-notours").mkdir()  # not a name staged_folder gives
        _output(rep, ["fig.png"])
        assert _names(rep) == {"fig.png", WRITTEN_LIST, f".rep.part-{live.pid}-00abcd",
                               f".rep.part-{dead.pid}-notours"}
    finally:
        live.kill()
        live.wait()
