"""A plan that exceeds a limit is named with the campaign file (found by the acquisition
sweep): every other mistake of ``jointid plan`` / ``jointid run`` starts with the file
("bad.toml: joint.limits...") but a limit the plan exceeded did not ("jointid plan: error:
segments[3] (sine): peak velocity ..."), so a stranger planning several files could not
tell which one was at fault. The library's LimitError keeps its message (its tests anchor
on it); the command lines add the file."""

from __future__ import annotations

import pytest
from daq.examples import path as example_path

from daq.app.cli import main

EXAMPLE = example_path("campaign.toml")
PLANT = example_path("plant_rx130l.toml")

CASES = {
    "sine too fast": ("frequency_hz = 0.1", "frequency_hz = 1.0",
                      "segments[3] (sine): peak velocity 10.05 rad/s exceeds "
                      "joint.limits.max_velocity 1.2 rad/s"),
    "torque limit": ("max_torque = 700.0", "max_torque = 100.0",
                     "payloads[0] (0 kg at 1.277 m): segments[0] (trapezoid): torque "),
}


@pytest.mark.parametrize("case", list(CASES))
def test_plan_and_run_name_the_file_of_an_exceeded_limit(tmp_path, capsys, case):
    old, new, what = CASES[case]
    text = EXAMPLE.read_text()
    assert old in text
    bad = tmp_path / "mine.toml"
    bad.write_text(text.replace(old, new, 1))
    assert main(["plan", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"jointid plan: error: {bad}: {what}"), err
    out = tmp_path / "out"
    assert main(["run", str(bad), "--simulate", str(PLANT), "--out", str(out), "--yes"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"jointid run: error: {bad}: {what}"), err
    assert not out.exists()  # refused before the folder was made
