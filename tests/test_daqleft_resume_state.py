"""The resume state belongs to one campaign (left by the campaign-folder fix): a folder's
logs were checked against the campaign, but ``<stem>.state.json`` was not, and its name is
the campaign's name made safe for file names (``"rig a"`` and ``"rig_a"`` share
``rig_a.state.json``). In a folder whose logs were moved away (to fit them elsewhere),
``--resume`` of campaign ``rig_a`` skipped payload 0 because campaign ``rig a`` had
completed its payload 0, and the run wrote that into its own state. The state file now
records the campaign as the logs do (name, ``definition``, plant); a state of another
campaign, or of this one before its file changed, is refused with and without ``--resume``
in one line naming the state file and what differs, nothing written."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest
from daq_campaigns import sine_campaign, sine_toml

from daq import ConfigError
from daq.app.cli import main
from daq.runtime.campaign_id import campaign_definition, plant_record
from daq.runtime.runner import run_campaign
from sim_drivers.plant_config import default_plant


def _two_payloads(name: str, masses: tuple[float, float] = (0.0, 2.0)):
    c = sine_campaign(name)
    return replace(c, payloads=tuple(replace(c.payloads[0], mass_kg=m) for m in masses))


def _listing(folder):
    return {p.name: p.read_bytes() for p in folder.rglob("*") if p.is_file()
            and p.name != ".jointid-run.lock"}


def _first_payload_then_logs_moved_away(tmp_path, c):
    out = tmp_path / "runs"
    r = run_campaign(c, out_dir=out, simulate=default_plant(), yes=True, payloads=[0])
    assert r.ok, r.reason
    elsewhere = tmp_path / "fitted"
    elsewhere.mkdir()
    for p in out.glob("*.mcap"):
        p.rename(elsewhere / p.name)
    return out


def _logs_back(tmp_path, out):
    """The moved logs put back (``--resume`` refuses a completed payload whose log is
    missing: tests/test_daqleft4_resume_logs.py)."""
    for p in (tmp_path / "fitted").glob("*.mcap"):
        p.rename(out / p.name)


def test_a_state_of_another_campaign_or_an_edited_one_is_refused(tmp_path):
    plant = default_plant()
    c = _two_payloads("rig a")
    out = _first_payload_then_logs_moved_away(tmp_path, c)
    state_file = out / "rig_a.state.json"
    state = json.loads(state_file.read_text())  # the state records the campaign's identity
    assert state["campaign"] == "rig a" and state["completed"] == [0]
    assert json.dumps(state["definition"], sort_keys=True) == campaign_definition(c)
    assert state["plant"] == plant_record(plant)
    before = _listing(out)

    other = _two_payloads("rig_a", (5.0, 7.0))  # another campaign, the same file stem
    for resume in (True, False):
        with pytest.raises(ConfigError) as e:
            run_campaign(other, out_dir=out, simulate=plant, yes=True, resume=resume)
        assert str(e.value) == (f"{state_file}: the resume state of another campaign, "
                                f"'rig a' (this run's: 'rig_a'); a folder holds the logs of "
                                f"one campaign: give another --out")
    edited = replace(c, payloads=(c.payloads[0], replace(c.payloads[1], mass_kg=3.0)))
    with pytest.raises(ConfigError) as e:
        run_campaign(edited, out_dir=out, simulate=plant, yes=True, resume=True)
    assert str(e.value) == (f"{state_file}: the resume state of campaign 'rig a' as it was "
                            f"before rig a.toml changed: payloads[1].mass_kg is 2.0 in the "
                            f"state file, 3.0 now; a folder holds the logs of one campaign: "
                            f"give another --out")
    other_plant = replace(plant, friction=replace(plant.friction, F_V=60.0))
    with pytest.raises(ConfigError, match="rig_a.state.json: the resume state of campaign "
                                          "'rig a' run on a simulated plant 'rx130l-joint3' "
                                          "with other parameters than this run's"):
        run_campaign(c, out_dir=out, simulate=other_plant, yes=True, resume=True)
    assert _listing(out) == before  # nothing written

    # the same campaign resumes after its completed payload (its log put back)
    _logs_back(tmp_path, out)
    r = run_campaign(c, out_dir=out, simulate=plant, yes=True, resume=True)
    assert r.ok and r.skipped == (0,) and [x.index for x in r.runs] == [1], r.reason
    assert json.loads(state_file.read_text())["completed"] == [0, 1]

    # --overwrite replaces what is in the way: the other campaign starts from nothing done
    r = run_campaign(other, out_dir=out, simulate=plant, yes=True, overwrite=True,
                     payloads=[1])
    assert r.ok and r.skipped == () and [x.index for x in r.runs] == [1], r.reason
    assert f"{state_file}: the resume state of another campaign, 'rig a' (this run's: " \
           f"'rig_a'): replaced (--overwrite)" in r.notes
    state = json.loads(state_file.read_text())
    assert state["campaign"] == "rig_a" and state["completed"] == [1]


def test_an_older_state_file_is_compared_by_what_it_records(tmp_path):
    """A state file written before the definition was recorded: compared by name (another
    campaign's is refused), resumed when the name matches (its definition and plant are
    added); one without a name (the first format) is taken as it is."""
    c = _two_payloads("rig_a")
    out = _first_payload_then_logs_moved_away(tmp_path, c)
    state_file = out / "rig_a.state.json"
    state_file.write_text(json.dumps({"campaign": "rig a", "completed": [0]}))
    with pytest.raises(ConfigError, match="rig_a.state.json: the resume state of another "
                                          "campaign, 'rig a' "):
        run_campaign(c, out_dir=out, simulate=default_plant(), yes=True, resume=True)
    _logs_back(tmp_path, out)
    for old in ({"campaign": "rig_a", "completed": [0]}, {"completed": [0]}):
        state_file.write_text(json.dumps(old))
        r = run_campaign(c, out_dir=out, simulate=default_plant(), yes=True, resume=True)
        assert r.ok and r.skipped == (0,) and [x.index for x in r.runs] == [1], r.reason
        state = json.loads(state_file.read_text())
        assert state["campaign"] == "rig_a" and state["completed"] == [0, 1]
        assert json.dumps(state["definition"], sort_keys=True) == campaign_definition(c)
        (out / "rig_a_payload1.mcap").unlink()  # (moved away too)


def test_cli_resume_with_a_state_of_another_campaign(tmp_path, capsys):
    """``jointid run --resume`` into a folder holding only the state file of campaign
    "rig a" (its logs moved away): exit 2, one line, nothing written, nothing moved."""
    src = tmp_path / "rig_a.toml"
    src.write_text(sine_toml("rig_a", "test_rig_a_cli"))
    out = tmp_path / "runs"
    out.mkdir()
    state_file = out / "rig_a.state.json"
    state_file.write_text(json.dumps({"campaign": "rig a", "completed": [0]}))
    before = _listing(out)
    code = main(["run", str(src), "--simulate", "examples/plant_rx130l.toml", "--yes",
                 "--out", str(out), "--resume"])
    assert code == 2
    assert capsys.readouterr().err == (
        f"jointid run: error: {state_file}: the resume state of another campaign, 'rig a' "
        f"(this run's: 'rig_a'); a folder holds the logs of one campaign: give another "
        f"--out\n")
    assert _listing(out) == before and not list(out.glob("*.mcap"))
