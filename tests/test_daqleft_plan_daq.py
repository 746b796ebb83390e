"""``jointid plan`` makes the ``[daq]`` checks of ``jointid run`` (left by the acquisition
sweep): a campaign whose ``[daq]`` had a mistake (a misspelt clock, two CST drives at 1 kHz on
one 1 Mbit/s bus) planned with exit 0, and ``jointid run`` then refused it. Both commands now
refuse it with the same line (one function, ``daq.runtime.runner.check_daq``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from daq.app.cli import main

EXAMPLE = Path("examples/campaign.toml")
PLANT = "examples/plant_rx130l.toml"

BAD_DAQ = {
    "clock": ('[daq]\nclock = "pacd"\n',
              "daq.clock: expected one of 'lockstep', 'paced', '', got 'pacd'"),
    "bus load": ("[daq]\n[[daq.drives]]\nnode_id = 1\n[[daq.drives]]\nnode_id = 2\n",
                 "daq.max_bus_load: cyclic traffic needs 7 frames/cycle"),
    "eds": ('[daq]\n[[daq.drives]]\nnode_id = 1\neds = "nowhere.eds"\n',
            "daq.drives[0].eds: expected an EDS/DCF file"),
}


@pytest.mark.parametrize("case", sorted(BAD_DAQ))
def test_plan_refuses_what_run_refuses(tmp_path, capsys, case):
    text, expected = BAD_DAQ[case]
    src = tmp_path / "c.toml"
    src.write_text(EXAMPLE.read_text() + "\n" + text)
    assert main(["plan", str(src)]) == 2
    plan_err = capsys.readouterr().err.strip()
    assert plan_err.startswith(f"jointid plan: error: {src}: {expected}"), plan_err
    assert len(plan_err.splitlines()) == 1
    out = tmp_path / "runs"
    assert main(["run", str(src), "--simulate", PLANT, "--quick", "--yes", "--out",
                 str(out)]) == 2
    run_err = capsys.readouterr().err.strip()
    assert run_err == plan_err.replace("jointid plan:", "jointid run:", 1)
    assert not out.exists() or not list(out.glob("*.mcap"))


def test_a_good_daq_table_still_plans(tmp_path, capsys):
    src = tmp_path / "c.toml"
    src.write_text(EXAMPLE.read_text() + '\n[daq]\nclock = "lockstep"\n')
    assert main(["plan", str(src), "--quick"]) == 0
    assert "Q1" in capsys.readouterr().out
