"""A run folder holds the logs of one campaign (left by the acquisition sweep): ``jointid run``
ran a second campaign into a folder holding another's logs, and ``--resume`` continued a
campaign whose file had changed (another payload mass) after its first payloads were logged,
both without a word, so ``jointid fit DIR/*.mcap`` mixed them. Both are refused now, before
anything moves, in one line naming the stranger log and what differs (the logs' ``campaign``
metadata: name, ``definition``; the ``plant`` record)."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import pytest
from daq_campaigns import sine_campaign

from daq import ConfigError
from daq.app.cli import main
from daq.protocol.reader import read_metadata
from daq.runtime.campaign_id import campaign_definition
from daq.runtime.runner import run_campaign
from sim_drivers.plant_config import default_plant


def _two_payloads(name: str = "fold"):
    c = sine_campaign(name)
    return replace(c, payloads=(c.payloads[0], replace(c.payloads[0], mass_kg=2.0)))


def _listing(folder):
    return {p.name: p.read_bytes() for p in folder.rglob("*") if p.is_file()
            and p.name != ".jointid-run.lock"}


def test_another_campaign_and_a_changed_one_are_refused(tmp_path):
    c = _two_payloads()
    plant = default_plant()
    r = run_campaign(c, out_dir=tmp_path, simulate=plant, yes=True, payloads=[0])
    assert r.ok, r.reason
    log0 = tmp_path / "fold_payload0.mcap"
    md = read_metadata(log0)  # the log records the campaign as loaded
    assert md["campaign"]["name"] == "fold"
    assert md["campaign"]["definition"] == campaign_definition(c)
    assert json.loads(md["campaign"]["definition"])["payloads"][1]["mass_kg"] == 2.0
    before = _listing(tmp_path)

    # a fresh run of another campaign into the folder
    with pytest.raises(ConfigError) as e:
        run_campaign(_two_payloads("other"), out_dir=tmp_path, simulate=plant, yes=True)
    assert str(e.value) == (f"{log0}: a log of another campaign, 'fold' (this run's: "
                            f"'other'); a folder holds the logs of one campaign: give "
                            f"another --out")
    # --resume of the same campaign after its file changed payload 1's mass
    changed = replace(c, payloads=(c.payloads[0], replace(c.payloads[1], mass_kg=3.0)))
    with pytest.raises(ConfigError) as e:
        run_campaign(changed, out_dir=tmp_path, simulate=plant, yes=True, resume=True)
    assert str(e.value) == (f"{log0}: a log of campaign 'fold' as it was before fold.toml "
                            f"changed: payloads[1].mass_kg is 2.0 in the log, 3.0 now; a "
                            f"folder holds the logs of one campaign: give another --out")
    # the same on another simulated plant
    other_plant = replace(plant, friction=replace(plant.friction, F_V=60.0))
    with pytest.raises(ConfigError, match="with other parameters than this run's"):
        run_campaign(c, out_dir=tmp_path, simulate=other_plant, yes=True, resume=True)
    assert _listing(tmp_path) == before  # nothing written, nothing moved

    # the same campaign resumes; [daq] (how the drives are reached) may change
    again = replace(c, daq={**c.daq, "channel": c.daq["channel"] + "_b"})
    r = run_campaign(again, out_dir=tmp_path, simulate=plant, yes=True, resume=True)
    assert r.ok and r.skipped == (0,) and [x.index for x in r.runs] == [1], r.reason


def test_a_file_whose_campaign_cannot_be_read_is_refused(tmp_path):
    (tmp_path / "notes.mcap").write_bytes(b"")
    c = sine_campaign("fold")
    with pytest.raises(ConfigError) as e:
        run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True)
    assert str(e.value).startswith(f"{tmp_path / 'notes.mcap'}: cannot tell which campaign "
                                   f"it belongs to (not an MCAP file (an empty file))")
    # --overwrite replaces what is in the way: the check is not made
    r = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True, overwrite=True)
    assert r.ok, r.reason


@pytest.mark.slow
def test_cli_resume_with_an_edited_campaign_file(tmp_path, capsys):
    """The stranger's path: ``jointid run --quick`` then ``--resume`` with a payload mass
    edited in the campaign file: exit 2, one line, the folder untouched."""
    src = tmp_path / "c.toml"
    shutil.copy("examples/campaign.toml", src)
    out = tmp_path / "runs"
    plant = "examples/plant_rx130l.toml"
    args = ["run", str(src), "--simulate", plant, "--quick", "--yes", "--out", str(out)]
    assert main([*args, "--payload", "0"]) == 0
    capsys.readouterr()
    before = _listing(out)
    src.write_text(src.read_text().replace("mass_kg = 6.970", "mass_kg = 5.0"))
    assert main([*args, "--resume"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"jointid run: error: {out / 'rx130l-joint3_quick_payload0.mcap'}: a log "
                   f"of campaign 'rx130l-joint3 (quick)' as it was before {src} changed: "
                   f"payloads[2].mass_kg is 6.97 in the log, 5.0 now; a folder holds the "
                   f"logs of one campaign: give another --out")
    assert _listing(out) == before
