"""A newcomer's first hour, "nothing lost when something fails", through the real ``jointid``
entry point (real simulated runs, real MCAP logs, a real SIGINT to a real process). Each case
failed on the code before its fix:

- ``jointid demo --out DIR`` interrupted while it wrote its report left DIR with some of the
  report's figures and no fit.json/report.html (a half-written folder), and the line
  "jointid: interrupted (SIGINT)" said nothing of the logs. The rule now
  (:func:`daq.app.demo.demo_folder`): the plan's figure and ``DIR/logs`` are written as the
  demo goes (the logs kept, closed, whatever stops the demo); the report is staged
  (:func:`ident.report.staged_folder`) and moved in at the end: logs kept, report absent.
- ``jointid demo --out DIR`` whose ``DIR/fit.json`` is a folder ran the whole campaign, then
  failed on it with the new figures written; now refused before anything runs.
- a failed ``jointid run --out a/b/c`` (no drive answering) left ``a/b`` behind;
- a CSV named ``.mat``: "not a readable MAT file (Unknown mat file type, version 48, 48)"
  without saying what the file looks like;
- a robot or plant file given to ``jointid plan`` as the campaign (or a campaign given as
  ``--robot``): "joints: expected one of the known keys ..., not this unknown key" without
  naming the likely mix-up.
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
from test_bad_inputs_sweep import _csv, _files, _refused

from daq.protocol.reader import read_run

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
#: seconds the quick demo may take to reach its report (2 shared cores, CI beside)
PATIENCE_S = 600.0


def _sigint_default() -> None:
    """In the child before exec: SIGINT to its default (a suite run with SIGINT ignored, a
    background job, would leave it ignored in the child: test_demo_first_line)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _report_started(out: Path) -> bool:
    """The demo is writing its report: a figure other than the plan in ``out`` (the old
    code's way) or in the staged folder inside it."""
    if not out.is_dir():
        return False
    pngs = {p.name for p in out.glob("*.png")} - {"campaign_plan.png"}
    return bool(pngs) or any(any(d.glob("*.png")) for d in out.glob(f".{out.name}.part-*"))


@pytest.mark.slow
def test_demo_interrupted_while_writing_its_report_keeps_the_logs_and_no_report(tmp_path):
    out = tmp_path / "a" / "demo"
    err_path = tmp_path / "stderr.txt"
    with err_path.open("w") as err, open(os.devnull, "w") as sink:
        proc = subprocess.Popen(
            [sys.executable, "-m", "daq.app.cli", "demo", "--quick", "--out", str(out)],
            cwd=tmp_path, stdout=sink, stderr=err, preexec_fn=_sigint_default,
            env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
        try:
            t_end = time.monotonic() + PATIENCE_S
            while not _report_started(out):
                assert proc.poll() is None, (proc.returncode, err_path.read_text()[-3000:])
                assert time.monotonic() < t_end, "the demo wrote no report figure in time"
                time.sleep(0.005)
            proc.send_signal(signal.SIGINT)
            code = proc.wait(timeout=120)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    text = err_path.read_text()
    assert code == 130, (code, text[-3000:])
    assert "Traceback" not in text, text[-3000:]
    # logs kept, report absent: nothing of it, no staged folder
    assert sorted(p.name for p in out.iterdir()) == ["campaign_plan.png", "logs"]
    assert text.strip().splitlines()[-1] == (
        f"jointid: interrupted (SIGINT): the demo's logs are complete in {out / 'logs'}; "
        f"its report was not written")
    logs = sorted((out / "logs").glob("*.mcap"))
    assert [p.name for p in logs] == [f"rx130l-joint3_quick_payload{k}.mcap" for k in range(3)]
    for log in logs:  # every payload's log whole, its run done
        run = read_run(log)
        assert not run.truncated and run.metadata["result"]["status"] == "done", log
    state = json.loads((out / "logs" / "rx130l-joint3_quick.state.json").read_text())
    assert state["completed"] == [0, 1, 2]


def test_demo_into_a_folder_whose_report_name_is_a_folder_refused_first(tmp_path, capfd):
    """An earlier demo's folder whose fit.json is a folder: refused in one line before the
    campaign runs (the old code ran it, wrote the new figures, then failed on fit.json)."""
    out = tmp_path / "demo"
    out.mkdir()
    (out / "campaign_plan.png").write_bytes(b"\x89PNG\r\n\x1a\n")  # an earlier demo's mark
    (out / "fit.json").mkdir()
    before = _files(tmp_path)
    _refused(capfd, ["demo", "--quick", "--out", str(out)], "--out", str(out / "fit.json"),
             "is a folder")
    assert _files(tmp_path) == before and sorted(p.name for p in out.iterdir()) == [
        "campaign_plan.png", "fit.json"]


def test_failed_run_removes_the_folders_it_created(tmp_path, capfd):
    """No drive answers (no hardware, no --simulate): ``run --out a/b/c`` fails and removes
    c, b and a, which it created; a folder holding something else is kept."""
    argv = ["run", str(EXAMPLES / "campaign.toml"), "--yes", "--out"]
    _refused(capfd, [*argv, str(tmp_path / "a" / "b" / "c")], "no answer")
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "notes.txt").write_text("mine\n")
    _refused(capfd, [*argv, str(tmp_path / "a" / "b" / "c")], "no answer")
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == [
        "a", "a/notes.txt"]


@pytest.mark.parametrize(("content", "hint"), [
    ("csv", "it looks like a CSV text file: name it .csv"),
    ('{"models": {}}\n', "it looks like a JSON text file (a jointid record?), not a data file"),
    ("", "the file is empty"),
])
def test_a_mat_file_that_is_not_one_says_what_it_looks_like(tmp_path, capfd, content, hint):
    path = tmp_path / "run.mat"
    if content == "csv":
        _csv(tmp_path / "run.csv").rename(path)
    else:
        path.write_text(content)
    line = _refused(capfd, ["fit", str(path)], str(path), "not a readable MAT file")
    assert line.endswith("; " + hint), line


@pytest.mark.parametrize(("argv", "looks", "expected"), [
    (["plan", "{robots}/arm3.toml"], "it looks like a robot file", "not a campaign file"),
    (["plan", "{ex}/plant_rx130l.toml"], "it looks like a simulated joint's plant file",
     "not a campaign file"),
    (["run", "{ex}/robots/arm3.toml", "--simulate", "--out", "{tmp}/runs"],
     "it looks like a robot file", "not a campaign file"),
    (["fit", "--robot", "{ex}/campaign.toml", "{tmp}/run.csv"],
     "it looks like a campaign file", "not a robot file"),
    (["run", "{ex}/campaign.toml", "--simulate", "{ex}/campaign_robot3.toml", "--out",
      "{tmp}/runs"], "it looks like a campaign file", "not a simulated joint's plant file"),
    (["run", "{ex}/campaign.toml", "--simulate", "{robots}/arm3.toml", "--out", "{tmp}/runs"],
     "it looks like a robot file", "not a simulated joint's plant file"),
    (["fit", "--robot", "{ex}/campaign_robot3_demo.toml", "{tmp}/run.csv"],
     "it looks like a campaign file", "not a robot file"),
])
def test_a_file_of_another_kind_names_the_mix_up(tmp_path, capfd, argv, looks, expected):
    _csv(tmp_path / "run.csv")
    args = [a.format(ex=EXAMPLES, robots=EXAMPLES / "robots", tmp=tmp_path) for a in argv]
    named = [a for a in args if a.endswith(".toml")][-1]  # the file of the wrong kind
    line = _refused(capfd, args, named, "not this unknown key", looks, expected)
    assert f"{looks}" in line.split("not this unknown key; ", 1)[1], line
    assert not (tmp_path / "runs").exists()


def test_a_campaign_whose_robot_file_is_a_campaign_names_the_mix_up(tmp_path, capfd):
    """``[robot] file = ...`` naming a campaign: the robot file's error says so."""
    src = (EXAMPLES / "campaign_robot3_demo.toml").read_text()
    bad = tmp_path / "c.toml"
    bad.write_text(src.replace('file = "robots/arm3.toml"',
                               f'file = "{EXAMPLES / "campaign.toml"}"'))
    assert bad.read_text() != src
    _refused(capfd, ["plan", str(bad)], str(EXAMPLES / "campaign.toml"),
             "it looks like a campaign file", "not a robot file")


@pytest.mark.parametrize(("argv", "named", "hint"), [
    # --robot forgotten: the robot file taken for a measurement
    (["fit", "{robots}/arm3.toml", "{tmp}/run.csv"], "{robots}/arm3.toml",
     "it looks like a robot file ([[joints]] of MDH parameters): a campaign names it in "
     "[robot] file = ..., jointid fit takes it as --robot"),
    (["fit", "{ex}/campaign.toml"], "{ex}/campaign.toml",
     "it looks like a campaign file ([[segments]], [[payloads]]): give it to jointid plan or "
     "jointid run"),
    (["fit", "{tmp}/arm.urdf"], "{tmp}/arm.urdf",
     "it looks like a robot file (URDF): jointid fit takes it as --robot"),
    # a log where the campaign is expected
    (["plan", "{tmp}/run.mcap"], "{tmp}/run.mcap",
     "an MCAP log, not a campaign file: give it to jointid fit or jointid export"),
    (["plan", "{tmp}/bin.toml"], "{tmp}/bin.toml", "expected a campaign file (TOML text)"),
])
def test_a_measurement_or_campaign_of_another_kind_says_where_it_goes(tmp_path, capfd, argv,
                                                                        named, hint):
    _csv(tmp_path / "run.csv")
    (tmp_path / "arm.urdf").write_text("<robot name='x'/>\n")
    (tmp_path / "run.mcap").write_bytes(b"\x89MCAP0\r\n" + bytes(range(128, 256)))
    (tmp_path / "bin.toml").write_bytes(bytes(range(128, 256)))
    fmt = dict(ex=EXAMPLES, robots=EXAMPLES / "robots", tmp=tmp_path)
    line = _refused(capfd, [a.format(**fmt) for a in argv], named.format(**fmt))
    assert line.endswith(hint), line
