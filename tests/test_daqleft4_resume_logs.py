"""``--resume`` and the state file (left by the last session).

1. ``jointid run --resume`` skipped every payload the state file listed as completed, even
   when that payload's log had been moved away or deleted: exit 0, "skipped (already
   completed)", and a campaign without that log, without a word. The state file now records
   each completed payload's log (``logs``: file name and size), and ``--resume`` refuses, in
   one line naming the log, when a completed payload's log is missing or is not the size the
   state records (exit 2, nothing written); putting the log back resumes, ``--payload K
   --overwrite`` (without ``--resume``) runs payload K again. A state file written before the
   sizes were recorded is checked for the logs' presence.
2. A hand-edited state file whose ``definition`` was not a JSON object was compared as if it
   were the campaign, and the refusal named an empty key ("...changed:  is "edited" in the
   state file..."); each recorded key is now checked for what the runner writes there, in
   one line naming the state file, the key and what was expected.

Through the real CLI (``daq.app.cli.main``) on a simulated drive (``--simulate``, a real
canopen node on a python-can virtual bus)."""

from __future__ import annotations

import json
import shutil

import pytest
from daq_campaigns import sine_toml

from daq.app.cli import main
from daq.runtime.campaign_id import difference

PLANT = "examples/plant_rx130l.toml"


def _campaign(tmp_path, name: str) -> object:
    src = tmp_path / f"{name}.toml"
    src.write_text(sine_toml(name, f"test_daqleft4_{name}", masses=(0.0, 2.0)))
    return src


def _run(src, out, *extra: str) -> int:
    return main(["run", str(src), "--simulate", PLANT, "--yes", "--out", str(out), *extra])


def _listing(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*")
            if p.is_file() and p.name != ".jointid-run.lock"}


def _refused_unchanged(src, out, capsys, err: str) -> None:
    """``--resume`` exits 2 with exactly ``err`` on stderr and leaves the folder as it was."""
    before = _listing(out)
    assert _run(src, out, "--resume") == 2
    assert capsys.readouterr().err == err
    assert _listing(out) == before


def test_resume_refuses_a_completed_payload_whose_log_is_gone(tmp_path, capsys):
    src = _campaign(tmp_path, "rl")
    out = tmp_path / "runs"
    assert _run(src, out, "--payload", "0") == 0
    log0 = out / "rl_payload0.mcap"
    state_file = out / "rl.state.json"
    state = json.loads(state_file.read_text())
    assert state["completed"] == [0]
    assert state["logs"] == {"0": {"name": "rl_payload0.mcap", "bytes": log0.stat().st_size}}
    capsys.readouterr()

    # the log moved away (to fit it elsewhere): refused, one line, nothing written
    elsewhere = tmp_path / "fitted"
    elsewhere.mkdir()
    shutil.move(log0, elsewhere / log0.name)
    _refused_unchanged(src, out, capsys, (
        f"jointid run: error: {log0}: missing, but {state_file} lists payload 0 as completed "
        f"(--resume would skip it and leave the campaign without its log); put the log back, "
        f"or run the payload again: --payload 0 --overwrite (without --resume)\n"))

    # another file under its name (here: the log cut short): refused by its size
    data = (elsewhere / log0.name).read_bytes()
    log0.write_bytes(data[: len(data) // 2])
    _refused_unchanged(src, out, capsys, (
        f"jointid run: error: {log0}: {len(data) // 2} bytes, but {state_file} records "
        f"{len(data)} bytes for payload 0's completed log (replaced or changed since); put the "
        f"log back, or run the payload again: --payload 0 --overwrite (without --resume)\n"))

    # a state file written before the sizes were recorded: the log's presence is checked
    log0.unlink()
    state_file.write_text(json.dumps({k: v for k, v in state.items() if k != "logs"}))
    assert _run(src, out, "--resume") == 2
    assert f"{log0}: missing, but {state_file} lists payload 0" in capsys.readouterr().err

    # the log put back: the resume skips payload 0 and runs payload 1
    shutil.move(elsewhere / log0.name, log0)
    assert _run(src, out, "--resume") == 0
    err = capsys.readouterr().err
    assert "skipped (already completed): payloads [0]" in err
    state = json.loads(state_file.read_text())
    assert state["completed"] == [0, 1]
    assert state["logs"] == {str(k): {"name": f"rl_payload{k}.mcap",
                                      "bytes": (out / f"rl_payload{k}.mcap").stat().st_size}
                             for k in (0, 1)}

    # asked explicitly: payload 0 again, its new log recorded
    log0.unlink()
    assert _run(src, out, "--payload", "0", "--overwrite") == 0
    state = json.loads(state_file.read_text())
    assert state["completed"] == [0, 1]
    assert state["logs"]["0"] == {"name": "rl_payload0.mcap", "bytes": log0.stat().st_size}
    assert _run(src, out, "--resume") == 0  # everything there: nothing to run
    assert "skipped (already completed): payloads [0, 1]" in capsys.readouterr().err


BAD_KEYS = [
    ("definition", "edited by hand",
     'expected a JSON object (the campaign as recorded) or null, got a string'),
    ("definition", [1, 2], "expected a JSON object (the campaign as recorded) or null, "
                           "got an array"),
    ("plant", "x", "expected a JSON object (the simulated plant's record) or null, "
                   "got a string"),
    ("campaign", 3, "expected a string (the campaign's name) or null, got the number 3"),
    ("completed", "0", "expected an array of payload indices (integers >= 0), got a string"),
    ("completed[1]", [0, "1"], "expected a payload index (an integer >= 0), got a string"),
    ("completed[0]", [True], "expected a payload index (an integer >= 0), got true"),
    ("emcy_outside_logs", {}, "expected an array of objects, got an object"),
    ("warnings_outside_logs[0]", ["x"], "expected a JSON object, got a string"),
    ("logs", [], "expected a JSON object (payload index -> its completed log), got an array"),
    ("logs.0", 5, 'expected a JSON object ({"name": ..., "bytes": ...}), got the number 5'),
    ("logs.0.bytes", {"name": "sk_payload0.mcap", "bytes": "12"},
     "expected the log's size (an integer >= 0), got a string"),
]


@pytest.mark.parametrize(("key", "value", "expected"), BAD_KEYS,
                         ids=[f"{k}={json.dumps(v)}" for k, v, _ in BAD_KEYS])
def test_a_hand_edited_state_key_is_named_in_one_line(tmp_path, capsys, key, value, expected):
    """Each recorded key holding what the runner never writes there: exit 2, one line naming
    the state file and the key, nothing written (the refusal comes before the drive starts).
    The valid state is the one a run of payload 0 writes."""
    src = _campaign(tmp_path, "sk")
    out = tmp_path / "runs"
    out.mkdir()
    state_file = out / "sk.state.json"
    state = {"campaign": "sk", "completed": [0],
             "logs": {"0": {"name": "sk_payload0.mcap", "bytes": 10}}, "plant": {},
             "definition": {}}
    top = key.split("[")[0].split(".")[0]
    if key.startswith("logs.0"):
        state["logs"]["0"] = value
    else:
        state[top] = value
    state_file.write_text(json.dumps(state))
    before = _listing(out)
    assert _run(src, out, "--resume") == 2
    assert capsys.readouterr().err == (
        f'jointid run: error: {state_file}: "{key}": {expected}; the resume state is '
        f"damaged: fix or remove it\n")
    assert _listing(out) == before


def test_state_keys_that_do_not_fit_together(tmp_path, capsys):
    """``logs`` naming a payload the state does not list as completed, and a log's name that
    is not its payload's, are damage too: one line each, naming the key."""
    src = _campaign(tmp_path, "sn")
    out = tmp_path / "runs"
    out.mkdir()
    state_file = out / "sn.state.json"
    state_file.write_text(json.dumps({"campaign": "sn", "completed": [0],
                                      "logs": {"1": {"name": "sn_payload1.mcap", "bytes": 1}}}))
    assert _run(src, out, "--resume") == 2
    assert capsys.readouterr().err == (
        f'jointid run: error: {state_file}: "logs.1": expected the index of a completed '
        f"payload (one of [0]); the resume state is damaged: fix or remove it\n")
    state_file.write_text(json.dumps({"campaign": "sn", "completed": [0],
                                      "logs": {"0": {"name": "other.mcap", "bytes": 1}}}))
    assert _run(src, out, "--resume") == 2
    assert capsys.readouterr().err == (
        f"jointid run: error: {state_file}: \"logs.0.name\": expected 'sn_payload0.mcap' "
        f"(payload 0's log), got 'other.mcap'; the resume state is damaged: fix or remove "
        f"it\n")
    assert not list(out.glob("*.mcap"))


def test_a_definition_that_is_no_object_is_named(tmp_path):
    """A log (or state) whose recorded definition is JSON but not an object: the refusal
    names "definition", not an empty key."""
    md = {"campaign": {"name": "x", "definition": json.dumps("edited")}}
    why = difference(md, "x", json.dumps({"name": "x"}), {}, "x.toml")
    assert why == ('a log of campaign \'x\' as it was before x.toml changed: definition is '
                   '"edited" in the log, {"name": "x"} now')
