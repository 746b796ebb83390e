"""Bad inputs met by a stranger with the README in hand (the sweep of 2026-11-29 over every
``jointid`` subcommand): each case below failed the rule "one line naming the file, key or
option and what was expected; non-zero exit; no partial state" before its fix, through the
real entry point (:func:`daq.app.cli.main`, real simulated runs, real MCAP logs):

- a usage error (``--axis j9``, ``demo --robot 4``) printed argparse's usage first (6 lines
  for ``jointid fit``);
- ``plan --plot p.txt`` planned the campaign, then died in matplotlib with a traceback;
- ``fit --gain 0`` fitted all-zero torques (rc 0, a numpy warning);
- ``fit --max-steps 3`` without ``--refine`` was ignored in silence;
- ``export --can OUT`` replaced an existing OUT without a word;
- ``demo --max-steps -1`` ran the whole campaign, then failed (11 lines, logs left behind);
- ``demo --out DIR`` on a folder of something else (a fit report) replaced its fit.json and
  report.html; on a file: a progress line, then "f: File exists";
- ``fit`` of a log cut inside its first chunk said "no cycle with the drive in OPERATION
  ENABLED" (a drive-state matter) for a log that holds no cycle at all;
- ``monitor --thresholds cal/thresholds.json -o cal`` replaced the calibration run's logs and
  monitor.json by the monitored run's;
- ``run --payload 0 --payload 0`` ran payload 0 twice, its second log replacing the first;
- ``fit logs/`` (a folder for ``logs/*.mcap``) said "unknown file type ''";
- a robot campaign's payload inertia with a negative moment: pinocchio's traceback
  ("The 3d inertia should be positive"), after the file was read;
  the same in a robot file (MDH TOML) link's inertia;
- ``fit run.csv --json run.csv`` replaced the data by the JSON record (rc 0);
- ``export-model FIT.json -o FILE`` refitted the record's inputs first (seconds), then failed
  on whatever came first, without naming ``-o``.

The second sweep (same day, ``fit``/``report``/``export-model``/``plan``/``run``: wrong
suffixes, empty files, a missing column, non-UTF-8, folders without permission):

- ``fit a.csv a.csv`` fitted the file twice, ``fit a.csv --validate a.csv`` validated on the
  fitted data (rc 0 both);
- a CSV header naming a column twice: the second replaced the first in silence;
- ``--report``/``--json`` under a folder without permission: "Permission denied" without the
  flag; ``export-model -o`` in a read-only folder refitted first; ``report`` of a read-only
  folder named ``report.html.part``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_daq_run import small_campaign
from test_monitor import _campaign, _model_dir, arm3  # noqa: F401 - arm3: a fixture

from daq.app.cli import main
from daq.runtime.runner import run_campaign
from sim_drivers.plant_config import default_plant

ROOT = Path(__file__).resolve().parents[1]
CAMPAIGN = ROOT / "examples" / "campaign.toml"


def _refused(capfd, argv: list[str], *needles: str) -> str:
    """``jointid ARGV`` exits 2 with one line on stderr holding every needle; returns it."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's usage errors
        code = exc.code
    out, err = capfd.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, (code, out[-2000:], err[-2000:])
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


def _files(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _csv(path: Path) -> Path:
    t = np.arange(3000) * 1e-3
    q = 0.5 * np.sin(2 * np.pi * t) + 0.3 * np.sin(7 * t)
    tau = 10 * np.cos(2 * np.pi * t) + 3 + np.sign(np.cos(2 * np.pi * t))
    np.savetxt(path, np.column_stack([t, q, tau]), delimiter=",", fmt="%.10g",
               header="t,q,tau", comments="")
    return path


@pytest.fixture(scope="module")
def run_log(tmp_path_factory) -> Path:
    """A real run log of the simulated drive (one short payload)."""
    out = tmp_path_factory.mktemp("sweep_log")
    r = run_campaign(small_campaign(n_payloads=1, periods=1, freq=1.0, amplitude=0.1),
                     out_dir=out, simulate=default_plant(), yes=True)
    assert r.ok, r.reason
    return r.runs[0].path


@pytest.mark.parametrize(("argv", "needles"), [
    (["fit", "run.csv", "--axis", "j9"], ("jointid fit: error:", "--axis", "'j9'",
                                          "(jointid fit --help)")),
    (["demo", "--robot", "4"], ("jointid demo: error:", "--robot", "'4'", "'3', '6'")),
    (["plan"], ("jointid plan: error:", "campaign")),
])  # fmt: skip
def test_usage_errors_are_one_line(tmp_path, capfd, monkeypatch, argv, needles):
    monkeypatch.chdir(tmp_path)
    _refused(capfd, argv, *needles)


@pytest.mark.parametrize(("plot", "needles"), [
    ("p.txt", ("--plot p.txt", ".png", "'.txt'")),
    ("nodir/p.png", ("--plot nodir/p.png", "nodir", "does not exist")),
    (".", ("--plot .", "no extension")),
])  # fmt: skip
def test_plan_plot_name_refused_before_planning(tmp_path, capfd, monkeypatch, plot, needles):
    monkeypatch.chdir(tmp_path)
    _refused(capfd, ["plan", str(CAMPAIGN), "--quick", "--plot", plot], *needles)
    assert not list(tmp_path.rglob("*.*"))


@pytest.mark.parametrize("gain", ["0", "0*2.5", "nan", "inf"])
def test_fit_gain_must_be_finite_and_non_zero(tmp_path, capfd, gain):
    f = _csv(tmp_path / "run.csv")
    js = tmp_path / "fit.json"
    _refused(capfd, ["fit", str(f), "--model", "usual", f"--gain={gain}", "--json", str(js)],
             "run.csv", f"gain '{gain}'", "expected a finite, non-zero drive gain")
    assert not js.exists()


def test_fit_max_steps_without_refine_is_refused(tmp_path, capfd):
    f = _csv(tmp_path / "run.csv")
    _refused(capfd, ["fit", str(f), "--max-steps", "3"], "--max-steps 3", "--refine")
    _refused(capfd, ["fit", "--robot", str(ROOT / "examples" / "robots" / "arm3.toml"),
                     str(f), "--max-steps", "1"], "--max-steps 1", "--refine")


def test_export_never_replaces_an_existing_trace(tmp_path, capfd, run_log):
    out = tmp_path / "trace.asc"
    out.write_text("an earlier trace\n")
    _refused(capfd, ["export", str(run_log), "--can", str(out)], "trace.asc",
             "already exists")
    assert out.read_text() == "an earlier trace\n"
    assert not list(tmp_path.glob(".part-*"))
    # a new name is written as before
    assert main(["export", str(run_log), "--can", str(tmp_path / "new.asc")]) == 0


def test_fit_of_a_log_cut_in_its_first_chunk_says_no_cycle(tmp_path, capfd, run_log):
    """The reader's warning (read 0 complete chunks) may precede it; the error names the file
    and what is missing, not the drive's state."""
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(run_log.read_bytes()[:2000])
    code = main(["fit", str(cut)])
    err = capfd.readouterr().err
    assert code == 2 and "Traceback" not in err
    errors = [ln for ln in err.splitlines() if ": error: " in ln]
    assert len(errors) == 1 and "cut.mcap: no cycle logged (the log is cut short)" in errors[0]


@pytest.mark.slow
def test_demo_bad_max_steps_refused_before_the_run(tmp_path, capfd):
    out = tmp_path / "demo"
    _refused(capfd, ["demo", "--quick", "--out", str(out), "--max-steps", "-1"],
             "--max-steps -1", ">= 0")
    assert not out.exists()


@pytest.mark.slow
def test_demo_out_of_something_else_is_left_alone(tmp_path, capfd):
    """A fit report folder (fit.json, report.html) is not an earlier demo's: refused, nothing
    in it changed; a file as --out is one line too."""
    rep = tmp_path / "fitreport"
    rep.mkdir()
    (rep / "fit.json").write_text('{"models": {}}\n')
    (rep / "report.html").write_text("<html>my fit</html>\n")
    before = _files(rep)
    _refused(capfd, ["demo", "--quick", "--out", str(rep)], "--out", "fitreport",
             "fit.json", "new or empty folder")
    assert _files(rep) == before
    f = tmp_path / "f"
    f.write_text("x")
    _refused(capfd, ["demo", "--quick", "--out", str(f)], "--out", "is a file")
    assert f.read_text() == "x"


@pytest.mark.slow
def test_monitor_into_its_calibration_folder_is_refused(tmp_path, arm3, capfd):  # noqa: F811
    """``--thresholds cal/thresholds.json -o cal``: the monitored run would replace the
    calibration run's logs and monitor.json; refused, the folder unchanged."""
    model = _model_dir(tmp_path, arm3)
    camp = _campaign(tmp_path, "sweep")
    cal = tmp_path / "cal"
    assert main(["monitor", str(model), str(camp), "--simulate", "--calibrate",
                 "-o", str(cal)]) == 0
    capfd.readouterr()
    before = _files(cal)
    assert any(k.startswith("logs/") for k in before) and "monitor.json" in before
    _refused(capfd, ["monitor", str(model), str(camp), "--simulate", "--thresholds",
                     str(cal / "thresholds.json"), "-o", str(cal)],
             f"-o {cal}", "calibration run", "another folder")
    assert _files(cal) == before


def test_run_refuses_a_payload_given_twice(tmp_path, capfd):
    """``--payload 0 --payload 0`` ran payload 0 twice, the second log replacing the first
    (rc 0); refused before anything is created."""
    out = tmp_path / "out"
    _refused(capfd, ["run", str(CAMPAIGN), "--simulate", str(ROOT / "examples" /
                                                            "plant_rx130l.toml"),
                     "--out", str(out), "--yes", "--quick", "--payload", "0", "--payload", "0"],
             "payload index 0", "given twice")
    assert not out.exists()


@pytest.mark.parametrize("robot", [False, True])
def test_fit_of_a_folder_names_it_and_the_fix(tmp_path, capfd, robot):
    logs = tmp_path / "logs"
    logs.mkdir()
    args = ["--robot", str(ROOT / "examples" / "robots" / "arm3.toml")] if robot else []
    _refused(capfd, ["fit", *args, str(logs)], "logs: a folder, expected a file",
             f"{logs / '*.mcap'}")


def test_export_model_output_that_is_a_file(tmp_path, capfd):
    """Checked before the record's inputs are read and refitted."""
    t = np.arange(3000) * 1e-3
    cols = [t, *(0.3 * np.sin((j + 1) * t) for j in (1, 2, 3)),
            *(5 * np.cos((j + 1) * t) for j in (1, 2, 3))]
    data = tmp_path / "arm.csv"
    np.savetxt(data, np.column_stack(cols), delimiter=",", fmt="%.10g",
               header="t,q1,q2,q3,tau1,tau2,tau3", comments="")
    rec = tmp_path / "fit.json"
    assert main(["fit", "--robot", str(ROOT / "examples" / "robots" / "arm3.toml"), str(data),
                 "--model", "usual", "--no-consistency", "--json", str(rec)]) == 0
    capfd.readouterr()
    f = tmp_path / "model"
    f.write_text("not a folder\n")
    _refused(capfd, ["export-model", str(rec), "-o", str(f)], f"-o {f}", "is a file")
    assert f.read_text() == "not a folder\n"


@pytest.mark.parametrize("inertia", [
    "[-0.015, 0.0, 0.0, 0.015, 0.0, 0.01]",  # a negative moment
    "[0.01, 0.0, 0.0, 0.01, 0.0, 0.05]",  # ZZ beyond XX + YY: no body has it
])  # fmt: skip
def test_robot_campaign_payload_inertia_must_be_physical(tmp_path, capfd, inertia):
    src = ROOT / "examples" / "campaign_robot3.toml"
    text = src.read_text()
    old = "inertia = [0.015, 0.0, 0.0, 0.015, 0.0, 0.01]"
    assert old in text
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "arm3.toml").write_text((ROOT / "examples" / "robots" /
                                                    "arm3.toml").read_text())
    (tmp_path / "c.toml").write_text(text.replace(old, f"inertia = {inertia}"))
    _refused(capfd, ["plan", str(tmp_path / "c.toml")], "c.toml: payloads[1].inertia",
             "physically valid inertia")


def test_robot_file_link_inertia_must_be_physical(tmp_path, capfd):
    src = ROOT / "examples" / "robots" / "arm3.toml"
    old = "inertia = [0.50, 0.0, 0.0, 0.50, 0.0, 0.12]"
    text = src.read_text()
    assert old in text
    bad = tmp_path / "arm3.toml"
    bad.write_text(text.replace(old, "inertia = [-0.50, 0.0, 0.0, 0.50, 0.0, 0.12]", 1))
    data = tmp_path / "r.csv"
    data.write_text("t,q1,q2,q3,tau1,tau2,tau3\n0,0,0,0,0,0,0\n")
    _refused(capfd, ["fit", "--robot", str(bad), str(data)],
             "arm3.toml: joints[j1].inertia", "positive", "got [-0.5, 0.0, 0.0, 0.5, 0.0, 0.12]")


@pytest.mark.parametrize("robot", [False, True])
def test_fit_json_onto_an_input_is_refused(tmp_path, capfd, robot):
    f = _csv(tmp_path / "run.csv")
    data = f.read_bytes()
    args = ["--robot", str(ROOT / "examples" / "robots" / "rx130l.toml")] if robot else []
    _refused(capfd, ["fit", *args, str(f), "--model", "usual", "--json", str(f)],
             f"--json {f}", "input file")
    assert f.read_bytes() == data
    v = _csv(tmp_path / "val.csv")
    _refused(capfd, ["fit", *args, str(f), "--validate", str(v), "--model", "usual",
                     "--json", str(tmp_path / "." / "val.csv")], "val.csv", "input file")


# ------------------------------------------------------------------ the sweep of 2026-11-29 (2)
@pytest.mark.parametrize("robot", [False, True])
def test_fit_of_a_file_given_twice_is_refused(tmp_path, capfd, robot):
    """``fit runs/*.csv runs/a.csv`` fitted a's samples twice; ``--validate`` of an input
    cross-validated on the fitted data (rc 0 both)."""
    f = _csv(tmp_path / "run.csv")
    args = ["--robot", str(ROOT / "examples" / "robots" / "rx130l.toml")] if robot else []
    _refused(capfd, ["fit", *args, str(f), str(f)], f"{f}: given twice among the inputs")
    _refused(capfd, ["fit", *args, str(f), "--validate", str(tmp_path / "." / "run.csv")],
             "run.csv: given among the inputs and the --validate files")


def test_fit_json_onto_the_report_folder_is_refused(tmp_path, capfd):
    """``--report x --json x``: the report was written, then "x: Is a directory" (rc 2)."""
    f = _csv(tmp_path / "run.csv")
    out = tmp_path / "x"
    _refused(capfd, ["fit", str(f), "--report", str(out), "--json", str(out)],
             f"--json {out}: is the --report folder")
    assert not out.exists()


def test_run_out_that_is_a_file_and_a_failed_first_run(tmp_path, capfd, monkeypatch):
    """``run --out run.csv`` said "run.csv: File exists"; a run that fails before writing
    anything (no drive on the bus) left its new --out folder with its lock file."""
    monkeypatch.chdir(tmp_path)
    f = _csv(tmp_path / "run.csv")
    _refused(capfd, ["run", str(CAMPAIGN), "--simulate", str(ROOT / "examples" /
                                                              "plant_rx130l.toml"),
                     "--out", str(f), "--yes"], f"--out {f}: is a file, expected a folder")
    _refused(capfd, ["run", str(CAMPAIGN), "--out", "logs", "--yes"], "no answer")
    assert not (tmp_path / "logs").exists()


def test_csv_column_named_twice_is_refused(tmp_path, capfd):
    """``t,q,tau,tau``: the second tau replaced the first in silence (rc 0)."""
    f = _csv(tmp_path / "run.csv")
    lines = f.read_text().splitlines()
    f.write_text("\n".join([lines[0] + ",tau"] + [ln + ",0" for ln in lines[1:]]) + "\n")
    _refused(capfd, ["fit", str(f)], f"{f}: column 'tau' twice in the header (columns 3 and 4)")


def _unprivileged(argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """``jointid ARGV`` in a process that file permissions bind: as root (CI, this machine)
    without the capabilities that override them (setpriv), else as the user it is."""
    cmd = [sys.executable, "-m", "daq.app.cli", *argv]
    if os.geteuid() == 0:
        if shutil.which("setpriv") is None:
            pytest.skip("root without setpriv: permissions cannot bind")
        cmd = ["setpriv", "--bounding-set=-dac_override,-dac_read_search", "--", *cmd]
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})


def _one_line(r: subprocess.CompletedProcess, *needles: str) -> None:
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2 and len(lines) == 1, (r.returncode, r.stderr[-2000:])
    for n in needles:
        assert n in lines[0], (n, lines[0])


def test_folders_without_permission(tmp_path, capfd):
    """A folder without permission on the way of an output: named with its flag in one line,
    before any fit (``--report noperm/rep`` said "noperm/rep: Permission denied" without the
    flag; ``export-model -o ro/m`` refitted the record first, then failed on whatever came
    first; ``report`` of a read-only folder named ``report.html.part``)."""
    f = _csv(tmp_path / "run.csv")
    rep = tmp_path / "rep"
    assert main(["fit", str(f), "--model", "usual", "--report", str(rep)]) == 0
    capfd.readouterr()
    (tmp_path / "noperm").mkdir()
    (tmp_path / "ro").mkdir()
    rec = tmp_path / "rec.json"
    rec.write_text('{"format": "jointid-robot-fit/2"}\n')  # refused on its keys, if read
    try:
        for d, mode in (("noperm", 0o000), ("ro", 0o555), ("rep", 0o555)):
            (tmp_path / d).chmod(mode)
        _one_line(_unprivileged(["fit", "run.csv", "--report", "noperm/rep"], tmp_path),
                  "jointid fit: error: --report noperm/rep: Permission denied")
        _one_line(_unprivileged(["fit", "run.csv", "--json", "noperm/a.json"], tmp_path),
                  "jointid fit: error: --json noperm/a.json: Permission denied")
        _one_line(_unprivileged(["export-model", "rec.json", "-o", "ro/m"], tmp_path),
                  "jointid export-model: error: -o ro/m: ro is not writable")
        _one_line(_unprivileged(["report", "rep"], tmp_path),
                  "jointid report: error: rep/report.html: Permission denied")
    finally:
        for d in ("noperm", "ro", "rep"):
            (tmp_path / d).chmod(0o755)
    assert sorted(p.name for p in (tmp_path / "ro").iterdir()) == []
    assert not any(p.name.endswith(".part") for p in rep.iterdir())
