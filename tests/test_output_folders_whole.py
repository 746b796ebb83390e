"""Output folders are written whole or not at all (ident.report.staged_folder): a Ctrl-C
(a real SIGINT to a real ``jointid`` process) or an error while ``jointid fit --report DIR``,
``fit --robot --report DIR``, ``export-model -o DIR`` or ``jointid report DIR`` writes leaves
no half-written folder, and an existing DIR as it was.

Before the fix, ``fit --report DIR`` interrupted after its first figure left DIR with one PNG
and no fit.json; an existing report folder had its figures replaced by the new fit's and kept
the old fit.json; ``report DIR`` whose report.html could not be replaced left
``report.html.part`` behind; ``export-model -o DIR`` wrote the URDF, then failed on the
friction file.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from robot_campaigns import arm_csvs
from test_bad_inputs_sweep import _csv

from daq.app.cli import main
from ident.report import WRITTEN_LIST
from sim_drivers.arm import Payload

ROOT = Path(__file__).resolve().parents[1]
ARM3 = ROOT / "examples" / "robots" / "arm3.toml"
#: seconds a jointid process may take to fit before it writes (2 shared cores, CI beside)
PATIENCE_S = 180.0


def _arm_csv(path: Path) -> Path:
    """A 3-axis CSV (t, q1..q3, tau1..tau3) for ``fit --robot arm3.toml``."""
    t = np.arange(3000) * 1e-3
    cols = [t, *(0.3 * np.sin((j + 1) * t) for j in (1, 2, 3)),
            *(5 * np.cos((j + 1) * t) for j in (1, 2, 3))]
    np.savetxt(path, np.column_stack(cols), delimiter=",", fmt="%.10g",
               header="t,q1,q2,q3,tau1,tau2,tau3", comments="")
    return path


def _snapshot(folder: Path) -> dict[str, bytes]:
    """Every entry under ``folder`` (files with their bytes, folders as b"<dir>")."""
    return {p.relative_to(folder).as_posix(): (b"<dir>" if p.is_dir() else p.read_bytes())
            for p in sorted(folder.rglob("*"))}


def _pngs(folder: Path) -> dict[str, int]:
    return {f.name: f.stat().st_mtime_ns for f in folder.glob("*.png")}


def _written(out: Path, before: dict[str, int]) -> bool:
    """Writing has started: a new PNG in ``out`` (the old code's way; ``before``: its PNGs
    then) or a PNG in the staged folder (beside ``out``, or in it when it exists)."""
    if out.is_dir() and _pngs(out) != before:
        return True
    staged = [*out.parent.glob(f".{out.name}.part-*"),
              *(out.glob(f".{out.name}.part-*") if out.is_dir() else ())]
    return any(any(d.glob("*.png")) for d in staged)


def _interrupt_while_writing(argv: list[str], out: Path, cwd: Path) -> tuple[int, str]:
    """Run ``jointid ARGV`` in a process of its own, send it SIGINT as soon as its first
    figure of ``out`` is on disk, and return (exit code, stderr)."""
    before = _pngs(out) if out.is_dir() else {}
    with (cwd / "stdout.txt").open("w") as so, (cwd / "stderr.txt").open("w") as se:
        proc = subprocess.Popen([sys.executable, "-m", "daq.app.cli", *argv], cwd=cwd,
                                stdout=so, stderr=se, env={**os.environ,
                                                           "OPENBLAS_NUM_THREADS": "1"})
        try:
            t_end = time.monotonic() + PATIENCE_S
            while not _written(out, before):
                assert proc.poll() is None, (proc.returncode, (cwd / "stderr.txt").read_text())
                assert time.monotonic() < t_end, "no figure written in time"
                time.sleep(0.002)
            proc.send_signal(signal.SIGINT)
            code = proc.wait(timeout=PATIENCE_S)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    return code, (cwd / "stderr.txt").read_text()


def _interrupted(code: int, err: str) -> None:
    """The process stopped on the interrupt (not done before it): 130, one line."""
    assert code == 130, (code, err[-2000:])
    assert "Traceback" not in err, err
    assert err.strip().splitlines()[-1].startswith("jointid: interrupted (SIGINT)"), err


@pytest.mark.parametrize("robot", [False, True])
def test_fit_report_interrupted_leaves_nothing(tmp_path, robot):
    """``fit [--robot] --report out/rep`` (out/ absent too): SIGINT after the first figure
    leaves neither out/rep nor out/ nor a staged folder."""
    data = _arm_csv(tmp_path / "arm.csv") if robot else _csv(tmp_path / "run.csv")
    args = ["--robot", str(ARM3), "--model", "usual", "--no-consistency"] if robot else []
    rep = tmp_path / "out" / "rep"
    before = _snapshot(tmp_path)
    code, err = _interrupt_while_writing(["fit", *args, str(data), "--report", str(rep)],
                                         rep, tmp_path)
    _interrupted(code, err)
    after = _snapshot(tmp_path)
    for k in ("stdout.txt", "stderr.txt"):
        after.pop(k)
    assert after == before, sorted(set(after) - set(before))


def test_fit_report_interrupted_keeps_the_existing_folder(tmp_path, capfd):
    """An existing report folder (an earlier fit's, plus a note of the user's) interrupted
    while the new report is written: every file as it was, no staged folder."""
    data = _csv(tmp_path / "run.csv")
    rep = tmp_path / "rep"
    assert main(["fit", str(data), "--model", "usual", "--report", str(rep)]) == 0
    capfd.readouterr()
    (rep / "notes.txt").write_text("mine\n")
    before = _snapshot(tmp_path)
    code, err = _interrupt_while_writing(["fit", str(data), "--report", str(rep)], rep,
                                         tmp_path)
    _interrupted(code, err)
    after = _snapshot(tmp_path)
    for k in ("stdout.txt", "stderr.txt"):
        after.pop(k)
    assert after == before, sorted(set(after) ^ set(before))


def test_fit_report_completed_over_an_existing_folder(tmp_path, capfd):
    """Not interrupted: the new files replace their namesakes, the user's other files stay,
    the record names the figures in DIR (not in the staged folder), no staged folder."""
    data = _csv(tmp_path / "run.csv")
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "notes.txt").write_text("mine\n")
    (rep / "fit.json").write_text("{}\n")
    assert main(["fit", str(data), "--model", "usual", "--report", str(rep)]) == 0
    out = capfd.readouterr().out
    assert f"report: {rep / 'report.html'}" in out
    rec = json.loads((rep / "fit.json").read_text())
    assert rec["figures"] and all(Path(f).parent == rep and Path(f).is_file()
                                  for f in rec["figures"])
    assert (rep / "notes.txt").read_text() == "mine\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rep", "run.csv"]
    assert oct(rep.stat().st_mode & 0o777) == oct(0o777 & ~_umask())


def test_fit_report_into_the_working_folder(tmp_path, capfd, monkeypatch):
    """``--report .``: staged inside the folder (its parent may be read-only), the new files
    beside the data, no staged folder left."""
    monkeypatch.chdir(tmp_path)
    _csv(tmp_path / "run.csv")
    assert main(["fit", "run.csv", "--model", "usual", "--report", "."]) == 0
    capfd.readouterr()
    names = sorted(p.name for p in tmp_path.iterdir())
    assert {"run.csv", "fit.json", "report.html", "tables.txt"} <= set(names), names
    assert not [n for n in names if ".part" in n], names
    assert not [p for p in tmp_path.parent.iterdir() if ".part-" in p.name]


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


def _refused_on_a_folder(tmp_path: Path, capfd, name: str, argv: list[str]) -> None:
    """A report folder of a fit whose file ``name`` is replaced by a folder: ``jointid ARGV``
    exits 2 with one line naming that file and leaves the tree as it was."""
    data = _csv(tmp_path / "run.csv")
    rep = tmp_path / "rep"
    assert main(["fit", str(data), "--model", "usual", "--report", str(rep)]) == 0
    (rep / name).unlink()
    (rep / name).mkdir()
    capfd.readouterr()
    before = _snapshot(tmp_path)
    assert main([a.format(data=data, rep=rep) for a in argv]) == 2
    err = capfd.readouterr().err.splitlines()
    bad = [ln for ln in err if ln.startswith("jointid") and "warning" not in ln]
    assert len(bad) == 1 and str(rep / name) in bad[0] and "Traceback" not in err, err
    assert _snapshot(tmp_path) == before


def test_fit_report_error_while_moving_in_leaves_the_folder(tmp_path, capfd):
    """DIR/direct_validation_usual.png is a folder (known only once the figures are drawn):
    the old code failed there with tables.txt replaced by the new fit's."""
    _refused_on_a_folder(tmp_path, capfd, "direct_validation_usual.png",
                         ["fit", "{data}", "--model", "both", "--report", "{rep}"])


def test_fit_report_whose_record_is_a_folder_refused_before_the_fit(tmp_path, capfd):
    """DIR/fit.json is a folder: refused before any file is read (the old code replaced
    DIR's figures, then failed on fit.json)."""
    _refused_on_a_folder(tmp_path, capfd, "fit.json",
                         ["fit", "{data}", "--model", "paper", "--report", "{rep}"])
    assert "warning" not in capfd.readouterr().err


def test_report_that_cannot_be_replaced_leaves_no_part_file(tmp_path, capfd):
    """``jointid report DIR`` whose report.html is a folder: the old code left
    report.html.part behind."""
    _refused_on_a_folder(tmp_path, capfd, "report.html", ["report", "{rep}"])


@pytest.fixture(scope="module")
def arm3_record(tmp_path_factory) -> Path:
    """``jointid fit --robot arm3.toml --consistent --json``: a record export-model writes
    without a refit (simulated payload runs, as tests/test_model_export.py)."""
    d = tmp_path_factory.mktemp("arm3_record")
    files = [str(f) for f in arm_csvs(d, (None, Payload(5.0, [0.0, 0.0, 0.05])))]
    rec = d / "fit.json"
    assert main(["fit", "--robot", str(ARM3), *files, "--model", "usual", "--consistent",
                 "--no-consistency", "--json", str(rec)]) == 0
    return rec


def test_export_model_error_while_writing_leaves_nothing(tmp_path, capfd, arm3_record):
    """-o DIR whose friction.json is a folder: one line naming it, exit 2, DIR as it was (the
    old code wrote DIR/arm3.urdf, then failed); a fresh -o is written whole."""
    out = tmp_path / "model"
    out.mkdir()
    (out / "friction.json").mkdir()
    capfd.readouterr()
    before = _snapshot(tmp_path)
    assert main(["export-model", str(arm3_record), "-o", str(out)]) == 2
    err = [ln for ln in capfd.readouterr().err.splitlines() if "error" in ln]
    assert len(err) == 1 and str(out / "friction.json") in err[0], err
    assert _snapshot(tmp_path) == before
    fresh = tmp_path / "a" / "fresh"
    assert main(["export-model", str(arm3_record), "-o", str(fresh)]) == 0
    text = capfd.readouterr().out
    assert f"wrote {fresh / 'arm3.urdf'}" in text
    assert sorted(p.name for p in fresh.iterdir()) == [WRITTEN_LIST, "arm3.urdf",
                                                       "consistent.json", "friction.json"]
    assert sorted(p.name for p in fresh.parent.iterdir()) == ["fresh"]
