"""Which campaign a run log belongs to, so that a run folder never mixes two campaigns.

Every log records its campaign (:func:`daq.runtime.runner` metadata): ``campaign.name``,
``campaign.definition`` (:func:`campaign_definition`: the campaign as loaded, canonical
JSON) and, for a simulated run, the ``plant`` record. :func:`check_folder` reads that
metadata from every ``DIR/*.mcap`` (:func:`daq.protocol.reader.read_metadata`, no chunk
is read) and refuses, in one line naming the log and what differs, a folder holding a log of
another campaign: another name, the same name with another definition (an edited campaign
file: another payload mass, segment, limit, robot file...), or another plant (a simulated
run's log in a hardware run's folder, another simulated plant). ``jointid run`` calls it
before anything moves, with and without ``--resume``; ``--overwrite`` (replace what is in the
way) does not.

What the definition leaves out, so that a resume may change it: the ``[daq]`` table and the
joints' ``drive`` (node ids, buses: how the drives are reached, recorded per log in its
``drive<k>`` records), and the campaign file's path. The robot file counts by its content
(SHA-256), not its path. Logs written before ``campaign.definition`` existed are compared by
name and plant only.

The resume state ``<stem>.state.json`` records the same identity (``campaign``,
``definition``, ``plant``): campaigns whose names differ only in characters a file name
cannot hold share its file name, and a folder may hold a state file without logs (moved
away). :func:`check_state` compares it as :func:`difference` compares a log; ``jointid
run`` refuses a state of another campaign, with and without ``--resume``, naming the state
file and what differs; ``--overwrite`` replaces it (the run starts from no completed
payload).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import re
from pathlib import Path
from typing import Any

from daq import ConfigError
from daq.protocol.reader import LogReadError, read_metadata
from trajectories.robot_campaign import RobotCampaign
from trajectories.robot_model import robot_file_path

__all__ = ["campaign_definition", "check_folder", "check_state", "difference",
           "plant_record"]


def campaign_definition(campaign: RobotCampaign) -> str:
    """The campaign as loaded, as canonical JSON (sorted keys): what makes two runs' logs
    belong to one campaign.

    Parameters
    ----------
    campaign : trajectories.robot_campaign.RobotCampaign
        As :func:`trajectories.campaign_file.load_campaign` read it (after ``quick()`` for a
        ``--quick`` run), before the planner optimises any multi-sine (its coefficients'
        last bits may differ from one CPU to another; the file's do not).

    Returns
    -------
    str
        JSON of every field but ``daq``, ``source`` and each joint's ``drive``; the robot
        file as ``"sha256:<hex>"`` of its content (a packaged robot's name as it is).
    """
    d = dataclasses.asdict(campaign)
    for key in ("daq", "source"):
        d.pop(key, None)
    for joint in d.get("joints", []):
        joint.pop("drive", None)
    robot = d.pop("robot_file", "")
    if robot:
        path = Path(robot_file_path(campaign))
        robot = (f"sha256:{hashlib.sha256(path.read_bytes()).hexdigest()}"
                 if path.is_file() else robot)
    d["robot"] = robot
    return json.dumps(d, sort_keys=True, default=repr)


def plant_record(plant_params: Any) -> dict[str, str]:
    """The ``plant`` metadata record of a simulated run (``name``, ``source``,
    ``simulated``, ``truth``: JSON of the plant's truth); empty for hardware."""
    if plant_params is None:
        return {}
    rec = {"name": str(getattr(plant_params, "name", "")),
           "source": str(getattr(plant_params, "source", "")),
           "simulated": "true"}
    try:
        rec["truth"] = json.dumps(plant_params.truth())
    except Exception:  # a plant without a truth() of plain numbers: the name alone
        pass
    return rec


def _plant_text(rec: dict[str, str]) -> str:
    if not rec.get("simulated"):
        return "hardware"
    return f"simulated plant {rec.get('name', '')!r}"


def _short(value: Any) -> str:
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _first_difference(a: Any, b: Any, where: str = "") -> tuple[str, Any, Any] | None:
    """The first key path at which ``a`` and ``b`` (JSON values) differ, with both values."""
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            if a.get(key, None) != b.get(key, None) or (key in a) != (key in b):
                sub = f"{where}.{key}" if where else key
                if key not in a or key not in b:
                    return sub, a.get(key, "(none)"), b.get(key, "(none)")
                return _first_difference(a[key], b[key], sub)
        return None
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return f"{where} (length)", len(a), len(b)
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            if x != y:
                return _first_difference(x, y, f"{where}[{i}]")
        return None
    return (where, a, b) if a != b else None


def difference(log_md: dict[str, dict[str, str]], name: str, definition: str,
               plant: dict[str, str], source: str, *, what: str = "log") -> str:
    """What makes a log's campaign differ from this run's, in a few words; "" when it is
    the same campaign.

    Parameters
    ----------
    log_md : dict
        The log's metadata records (:func:`daq.protocol.reader.read_metadata`).
    name, definition, plant :
        This run's campaign name, :func:`campaign_definition` and :func:`plant_record`.
    source : str
        This run's campaign file (named in the message).
    what : {"log", "state"}
        What ``log_md`` was read from: a run log, or the resume state
        (:func:`check_state`), as the message names it.
    """
    a = "a log" if what == "log" else "the resume state"
    in_it = "in the log" if what == "log" else "in the state file"
    camp = log_md.get("campaign")
    if camp is None or "name" not in camp:
        return "not a jointid run log (no campaign metadata)"
    if camp["name"] != name:
        return f"{a} of another campaign, {camp['name']!r} (this run's: {name!r})"
    theirs = camp.get("definition")
    if theirs is not None and theirs != definition:
        try:
            diff = _first_difference(json.loads(theirs), json.loads(definition))
        except ValueError:
            diff = None
        if diff is None:
            return f"{a} of campaign {name!r} as it was before {source} changed"
        key, old, new = diff
        key = key or "definition"  # not a JSON object at all (a hand-edited file)
        if key == "robot":
            return (f"{a} of campaign {name!r} with another robot file (content {old} "
                    f"{in_it}, {new} now)")
        return (f"{a} of campaign {name!r} as it was before {source} changed: {key} is "
                f"{_short(old)} {in_it}, {_short(new)} now")
    log_plant = log_md.get("plant", {})
    if _plant_text(log_plant) != _plant_text(plant):
        return (f"{a} of campaign {name!r} run on {_plant_text(log_plant)}, this run is on "
                f"{_plant_text(plant)}")
    if plant and log_plant.get("truth", "") != plant.get("truth", ""):
        return (f"{a} of campaign {name!r} run on a {_plant_text(log_plant)} with other "
                f"parameters than this run's")
    return ""


def check_state(campaign: str | None, recorded_definition: Any,
                recorded_plant: dict[str, str] | None, name: str, definition: str,
                plant: dict[str, str], source: str) -> str:
    """What makes the resume state's campaign differ from this run's (:func:`difference`,
    worded for the state file); "" when it is the same campaign.

    The state file's stem is the campaign name made safe for file names
    (:func:`daq.runtime.runner.file_stem`: ``"rig a"`` and ``"rig_a"`` share
    ``rig_a.state.json``), so it records its campaign as the logs do
    (:class:`daq.runtime.runfolder.RunState`). What it does not record is not compared: a
    state file written before ``definition`` and ``plant`` were recorded is compared by
    name, one that records no name (the first format) not at all.

    Parameters
    ----------
    campaign, recorded_definition, recorded_plant :
        What the state file records (``RunState.campaign``, ``.definition``: the parsed
        definition, ``.plant``); None where it records nothing.
    name, definition, plant, source :
        This run's, as for :func:`difference`.
    """
    if campaign is None:
        return ""
    rec: dict[str, Any] = {"name": campaign}
    if recorded_definition is not None:  # canonical again: sorted keys, the same floats
        rec["definition"] = json.dumps(recorded_definition, sort_keys=True)
    md = {"campaign": rec, "plant": plant if recorded_plant is None else recorded_plant}
    return difference(md, name, definition, plant, source, what="state")


def check_folder(folder: Path, stem: str, name: str, definition: str,
                 plant: dict[str, str], source: str) -> None:
    """Refuse a run folder holding a log of another campaign (:func:`difference`).

    Every ``folder/*.mcap`` is read (metadata only). A file of this campaign's own log
    names (``<stem>_payload<k>.mcap``) whose metadata cannot be read (a run killed before
    its header was written) is left to ``--resume`` (kept aside as partial); any other
    unreadable file is refused too: nothing tells which campaign it belongs to.

    Raises
    ------
    daq.ConfigError
        ``"runs/y_payload0.mcap: a log of another campaign, 'y' (this run's: 'x'); a folder
        holds the logs of one campaign: give another --out"``.
    """
    own = re.compile(rf"{re.escape(stem)}_payload\d+\.mcap")
    for path in sorted(Path(folder).glob("*.mcap")):
        try:
            md = read_metadata(path)
        except LogReadError as exc:
            if own.fullmatch(path.name):
                continue
            why = str(exc).split(": ", 1)[-1]
            raise ConfigError(f"{path}: cannot tell which campaign it belongs to ({why}); "
                              f"a folder holds the logs of one campaign: give another --out"
                              ) from None
        why = difference(md, name, definition, plant, source)
        if why:
            raise ConfigError(f"{path}: {why}; a folder holds the logs of one campaign: "
                              f"give another --out")
