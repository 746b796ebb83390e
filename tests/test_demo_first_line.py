"""The demo's first line comes before its heavy modules load (left by the demo heartbeat
fix): ``jointid demo --robot`` printed nothing for 6.6 s on a loaded 2-core machine (the
robot demo's modules loaded under a heartbeat that speaks after 5 s of silence, then the
planning under a new one), ``jointid demo --quick`` 4.2 s, although every step prints a
line at least every 5 s. The first line now names the loading step at once. Checked by
order, not by time: with ``python -X importtime`` the interpreter writes a line to stderr
as each import completes, and the demo's first line must come before scipy's."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("scipy", "matplotlib", "pinocchio", "canopen", "mcap")

def sigint_default() -> None:
    """In the child before exec: SIGINT to its default, so that Python installs its
    KeyboardInterrupt handler even where this suite runs with SIGINT ignored (a background
    job of a non-interactive shell, ``nohup``: the child inherits SIG_IGN, jointid then
    rightly leaves Ctrl-C ignored, and the signal this test sends does nothing)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)



@pytest.mark.parametrize(("args", "first"), [
    (["--robot"], "      ... loading the robot demo's modules"),
    (["--quick"], "      ... loading the pipeline's modules"),
])
def test_the_first_line_comes_before_the_heavy_imports(tmp_path, args, first):
    proc = subprocess.Popen(
        [sys.executable, "-X", "importtime", "-c",
         "import sys; from daq.app.cli import main; sys.exit(main())",
         "demo", *args, "--out", str(tmp_path / "demo")],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=sigint_default)
    lines: list[str] = []
    try:
        for line in proc.stderr:  # until the first heavy library finished importing
            lines.append(line.rstrip("\n"))
            if line.startswith("import time:") and \
                    line.rsplit("|", 1)[-1].strip() in HEAVY:
                break
    finally:
        proc.send_signal(signal.SIGINT)  # stop the demo (exit 130)
        proc.communicate(timeout=120)
    ours = [ln for ln in lines if not ln.startswith("import time:")]
    assert ours[:1] == [first], lines[-20:]
    assert lines[-1].rsplit("|", 1)[-1].strip() in HEAVY  # the heavy import came after it
