"""Data a joint never moved in (or moved too little to leave rows after the stiction area)
are one line naming the file, through the command line: ``jointid fit`` built the robot
model's system with no row or no column left and ended in an IndexError traceback from the
normal-equation solve (the single-joint design's own row check runs after the robot fit).
And an output path that cannot be written (``--report`` naming a file, ``--json`` a
directory) is refused in one line naming the flag before the fit, not after it by a bare
OSError ("clean0.csv: File exists")."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest


def _jointid(*args: str, cwd: Path) -> tuple[int, str]:
    r = subprocess.run([sys.executable, "-m", "daq.app.cli", *args], cwd=cwd,
                       capture_output=True, text=True, timeout=300)  # fmt: skip
    return r.returncode, r.stderr


def _write(path: Path, q: np.ndarray, ref: bool) -> None:
    n = q.size
    t = np.arange(n) * 1e-3
    tau = 150.0 + np.random.default_rng(0).normal(0.0, 3.0, n)  # [N m] gravity + noise
    cols = [t, q, tau] + ([np.full(n, 0.5)] if ref else [])
    head = "t,q,tau" + (",q_ref" if ref else "")
    rows = np.column_stack(cols)
    path.write_text(head + "\n" + "\n".join(",".join(f"{v:.10g}" for v in r) for r in rows)
                    + "\n")


@pytest.mark.parametrize("model", ["usual", "paper"])
@pytest.mark.parametrize("ref", [False, True])
def test_joint_at_rest_is_one_line(tmp_path, model, ref):
    _write(tmp_path / "still.csv", np.full(6000, 0.5), ref)
    rc, err = _jointid("fit", "still.csv", "--model", model, cwd=tmp_path)
    lines = err.strip().splitlines()
    assert rc == 2, err
    assert len(lines) == 1, err
    assert "still.csv" in lines[0] and "does not move" in lines[0], lines[0]


def test_no_row_left_before_the_first_usual_fit_is_one_line(tmp_path):
    # two 10 um steps a second: the velocity is nonzero on a few samples only, all in the
    # guard of the stiction area (the paper model's sign check fits the usual model first)
    k = np.arange(6000)
    _write(tmp_path / "steps.csv", 0.5 + np.where(k % 1000 < 500, 0.0, 1e-5), True)
    rc, err = _jointid("fit", "steps.csv", "--model", "paper", "--cutoff", "400", cwd=tmp_path)
    lines = err.strip().splitlines()
    assert rc == 2, err
    assert lines and "Traceback" not in err, err
    assert "samples left after selection" in lines[-1], lines[-1]
    assert all("warning" in x for x in lines[:-1]), err


@pytest.mark.parametrize("flag, target, needle", [
    ("--report", "out.csv", "is a file"),
    ("--json", "adir", "is a directory"),
    ("--json", "out.csv/fit.json", "out.csv is a file"),
    ("--report", "out.csv/sub/dir", "out.csv is a file"),
])  # fmt: skip
def test_unwritable_output_refused_before_the_fit(tmp_path, flag, target, needle):
    # a moving joint: the fit itself would succeed; the output is refused first (nothing
    # printed, no fit run for minutes before an OSError naming the path alone)
    t = np.arange(6000) * 1e-3
    _write(tmp_path / "run.csv", 0.5 + 0.8 * np.sin(2 * np.pi * 0.5 * t), False)
    (tmp_path / "out.csv").write_text("x\n")
    (tmp_path / "adir").mkdir()
    r = subprocess.run([sys.executable, "-m", "daq.app.cli", "fit", "run.csv", "--model",
                        "usual", flag, target], cwd=tmp_path, capture_output=True,
                       text=True, timeout=300)  # fmt: skip
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1, r.stderr
    assert flag in lines[0] and target in lines[0] and needle in lines[0], lines[0]
    assert r.stdout == "", r.stdout
