"""``jointid fit --q-s`` out of range is one line naming the flag, before any file is read
(it was "q_s must be positive [rad/s], got 0.0" after loading, without the flag; the
``--robot`` path already named it)."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize("value", ["0", "-0.03", "nan", "inf"])
def test_qs_out_of_range_names_the_flag_before_reading(tmp_path, value):
    # the input does not exist: the option is refused first
    r = subprocess.run([sys.executable, "-m", "daq.app.cli", "fit", "absent.csv",
                        "--model", "paper", "--q-s", value],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300)  # fmt: skip
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1, r.stderr
    assert f"--q-s '{value}'" in lines[0] and "> 0" in lines[0], lines[0]


@pytest.mark.parametrize("robot", [False, True], ids=["single-joint", "robot"])
@pytest.mark.parametrize("flag,value", [("--q-s", "0.05"), ("--qs", "scan"), ("--q-s", "0")])
def test_qs_with_the_usual_model_is_refused_by_both_clis(tmp_path, robot, flag, value):
    """``--q-s`` with ``--model usual`` (no q_s-dependent term) was accepted and ignored by
    both ``jointid fit`` and ``jointid fit --robot``; now both refuse it in the same line,
    before any file is read (the files named do not exist)."""
    where = ["--robot", "absent.toml"] if robot else []
    r = subprocess.run([sys.executable, "-m", "daq.app.cli", "fit", *where, "absent.csv",
                        "--model", "usual", flag, value],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300)  # fmt: skip
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1, r.stderr
    assert f"--q-s {value}:" in lines[0] and "--model usual" in lines[0], lines[0]
    # with a model that has q_s the option passes that rule (the absent file is the error)
    r = subprocess.run([sys.executable, "-m", "daq.app.cli", "fit", *where, "absent.csv",
                        "--model", "both", flag, "0.05"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300)  # fmt: skip
    assert r.returncode == 2 and "absent" in r.stderr and "--model usual" not in r.stderr, \
        r.stderr
