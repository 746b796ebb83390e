"""`jointid plan`: prints the summary, draws the plot, rejects bad files in one line."""

from __future__ import annotations

import subprocess
import sys

import matplotlib.image
import numpy as np
import pytest
from daq.examples import path as example_path

from daq.app.cli import main

EXAMPLE = example_path("campaign.toml")
TEXT = EXAMPLE.read_text()


def test_plan_prints_the_summary_of_the_example(capsys):
    assert main(["plan", str(EXAMPLE)]) == 0
    out = capsys.readouterr().out
    assert "campaign 'rx130l-joint3': 3 payload run(s)" in out
    rows = {line.split("%")[0].strip(): line for line in out.splitlines() if "% of vmax" in line}
    low = next(line for line in out.splitlines() if line.startswith("0-10 % of vmax"))
    share, coverage = (float(x.rstrip("%")) for x in low.split()[-2:])
    assert share >= 15.0 and coverage >= 80.0
    assert len(rows) == 3
    for line in out.splitlines():
        if "% of vmax" in line:
            assert float(line.split()[-1].rstrip("%")) >= 80.0  # coverage of every band
    for name in ("segments[0] (trapezoid)", "segments[3] (sine)", "return", "|jerk|"):
        assert name in out


def test_plan_plot_draws_a_png(tmp_path, capsys):
    png = tmp_path / "plan.png"
    assert main(["plan", str(EXAMPLE), "--quick", "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert f"plot: {png}" in out and "(quick)" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    img = matplotlib.image.imread(png)
    assert img.shape[0] > 500 and img.shape[1] > 1000
    assert np.std(img[..., :3]) > 0.05  # not blank


BAD = {
    "unknown key": ("[joint.limits]", "[joint.limits]\nmax_speed = 3", "joint.limits.max_speed"),
    "wrong type": ("max_acceleration = 4.0 ", 'max_acceleration = "4" ',
                   "joint.limits.max_acceleration"),
    "missing field": ("kd = 1000.0 ", "", "control.kd"),
    "zero limit": ("max_velocity = 1.2 ", "max_velocity = 0.0 ", "joint.limits.max_velocity"),
    "segment outside range": ("center = 0.7", "center = 1.0", "segments[3].amplitude"),
    "limit exceeded by a sine": ("frequency_hz = 0.1", "frequency_hz = 0.2",
                                 "segments[3] (sine): peak velocity"),
    "TOML syntax": ("cycles = 1\n", "cycles = = 1\n", "invalid TOML"),
}


@pytest.mark.parametrize("mistake", list(BAD))
def test_bad_campaign_exits_nonzero_with_one_line(tmp_path, capsys, mistake):
    old, new, key = BAD[mistake]
    assert old in TEXT
    f = tmp_path / "bad.toml"
    f.write_text(TEXT.replace(old, new, 1))
    assert main(["plan", str(f)]) == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jointid plan: error: ")
    assert key in lines[0] and "Traceback" not in cap.err


def test_console_entry_point_no_traceback(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text(TEXT.replace("max_jerk = 40.0 ", "max_jerk = -1 ", 1))
    run = subprocess.run([sys.executable, "-m", "daq.app.cli", "plan", str(f)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert run.stderr.strip() == (
        f"jointid plan: error: {f}: joint.limits.max_jerk: expected a number > 0 <= 1e+08 "
        "[rad/s^3 or m/s^3], got -1")
    missing = subprocess.run([sys.executable, "-m", "daq.app.cli", "plan",
                              str(tmp_path / "no.toml")],
                             capture_output=True, text=True, timeout=120)
    assert missing.returncode == 2 and "no.toml" in missing.stderr
    assert "Traceback" not in missing.stderr
