"""The run folder (``jointid run --out DIR``): one run at a time, logs never silently replaced.

- **One run per folder.** :class:`FolderLock` takes an exclusive ``fcntl.flock`` on
  ``DIR/.jointid-run.lock`` for the whole campaign (the file holds the pid of the run that
  holds it and is left in place: removing a lock file races with the next run). A second
  run into the same folder is refused before anything moves, in one line naming the folder.
  The lock is released by the kernel when the process dies, however it dies.
- **Logs are created, never replaced.** ``<stem>_payload<k>.mcap`` is created with
  ``O_EXCL`` (:func:`create_log_file`). A log left by an earlier run makes a new run refuse
  (:func:`check_logs`) unless ``--resume`` (a completed payload is skipped; the log of a
  payload that did not complete, a killed or stopped run, is moved aside by
  :func:`keep_partial` to ``DIR/partial/<stem>_payload<k>.partial-<n>.mcap``, n = 1, 2, ...)
  or ``--overwrite`` (the log is replaced). The ``partial/`` folder keeps them out of
  ``DIR/*.mcap``, which is what ``jointid fit`` is usually given.
- **The state file only grows.** ``<stem>.state.json`` lists the completed payloads; a run
  starts from what it lists (with or without ``--resume``) and adds to it, written
  atomically (temporary file + ``os.replace``). The one exception: ``--overwrite`` removes
  a payload from it when that payload's log is replaced (its completed log is gone). An
  unreadable state file is refused, not taken as empty, and so is one whose key does not
  hold what :func:`write_state` writes (one line naming the file and the key). It records
  its campaign as the logs do (``campaign``, ``definition``, ``plant``: :class:`RunState`),
  so that a state of another campaign is refused like its logs
  (:func:`daq.runtime.campaign_id.check_state`), each completed payload's log (``logs``:
  name and size), which ``--resume`` checks before it skips that payload
  (:func:`check_completed_logs`), and what no log holds (kept from run to run): the EMCYs
  received while no log was open after the last payload's (``emcy_outside_logs``), the
  warnings of the run's wind-down (``warnings_outside_logs``: the bus lost, a drive no
  longer answering).
- **Room for the log.** :func:`check_free_space` refuses a payload when the file system
  has less free space than the log's expected size: :func:`expected_log_bytes`, the
  uncompressed size of its records (an upper bound: the chunks are zstd-compressed).
"""

from __future__ import annotations

import contextlib
import datetime
import errno
import fcntl
import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from daq import ConfigError

from .mcaplog import chunk_size_for

LOCK_NAME = ".jointid-run.lock"
PARTIAL_DIR = "partial"


class FolderLock:
    """Exclusive lock on a run folder (``fcntl.flock`` on ``DIR/.jointid-run.lock``).

    Parameters
    ----------
    folder : Path
        The run folder (created if missing).

    Raises
    ------
    daq.ConfigError
        Another process holds the lock: ``"runs: another jointid run (pid 4242) is writing
        to this folder; wait for it to end or give another --out"``.
    """

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.path = self.folder / LOCK_NAME
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            holder = ""
            with contextlib.suppress(OSError, ValueError):
                holder = f" (pid {int(os.pread(fd, 32, 0).split()[0])})"
            os.close(fd)
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise ConfigError(f"{self.folder}: another jointid run{holder} is writing to "
                                  f"this folder; wait for it to end or give another --out"
                                  ) from None
            raise ConfigError(f"{self.path}: cannot lock the run folder: "
                              f"{exc.strerror or exc}") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd: int | None = fd

    def release(self) -> None:
        """Unlock (idempotent); the lock file stays."""
        fd, self._fd = self._fd, None
        if fd is not None:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
            os.close(fd)  # closing the last descriptor releases the flock

    def __enter__(self) -> FolderLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def missing_folders(folder: Path) -> list[Path]:
    """The folders of ``folder``'s path that do not exist yet (``folder`` itself included),
    outermost first: what a run into ``folder`` creates, for :func:`remove_unused_folders`."""
    out: list[Path] = []
    f = Path(folder).absolute()
    while not f.exists() and f != f.parent:
        out.insert(0, f)
        f = f.parent
    return out


def remove_unused_folders(created: list[Path]) -> None:
    """Remove the folders a run created (:func:`missing_folders`) when it failed before
    writing anything but its lock file (no drive answering, a refused option...): the
    innermost when it holds nothing else, then each parent while it is empty. A folder
    holding anything else (a log, the resume state, a file written meanwhile) is kept, and
    so are its parents."""
    for k, d in enumerate(reversed(created)):
        try:
            if k == 0 and {p.name for p in d.iterdir()} <= {LOCK_NAME}:
                (d / LOCK_NAME).unlink(missing_ok=True)
            d.rmdir()
        except OSError:  # not empty, gone, or written meanwhile: left, with its parents
            return


# ------------------------------------------------------------------------------ state file
@dataclass
class RunState:
    """The resume state ``<stem>.state.json`` of a run folder.

    Attributes
    ----------
    completed : set of int
        Indices of the payloads whose run completed.
    campaign : str or None
        The campaign's name (None: a state file that records none, the first format).
    definition : object or None
        The campaign as loaded, parsed
        (:func:`daq.runtime.campaign_id.campaign_definition`; None: a state file written
        before it was recorded).
    plant : dict or None
        :func:`daq.runtime.campaign_id.plant_record` of the run that wrote it (``{}``:
        hardware; None: not recorded).
    emcy_outside_logs : list of dict
        The EMCYs received while no payload's log was open and none was opened after them
        (after the last payload's run, or before any payload ran): ``text`` (the ``emcy``
        event's words and when), ``node_id``, ``code``, ``error_register`` (hex text),
        ``after_payload`` (index, or None) and ``utc`` (when the run that received it
        recorded it, at its end, ISO 8601). Kept from run to run.
    warnings_outside_logs : list of dict
        What went wrong as a run wound down, after the last payload's log closed (so no
        log holds it): the bus lost, a drive that no longer answered (its heartbeat
        consumer 0x1016 not cleared). ``text`` (the summary's warning), ``after_payload``
        (index, or None) and ``utc``, as for ``emcy_outside_logs``. Kept from run to run.
    logs : dict of int -> dict
        Per completed payload, the log its run closed: ``name`` (the file name in the
        folder) and ``bytes`` (its size), recorded when the payload completed, so that
        ``--resume`` can tell that log is still there (:func:`check_completed_logs`).
        Empty in a state file written before it was recorded (then only the file's
        presence is checked).
    """

    completed: set[int] = field(default_factory=set)
    campaign: str | None = None
    definition: Any = None
    plant: dict[str, str] | None = None
    emcy_outside_logs: list[dict[str, Any]] = field(default_factory=list)
    warnings_outside_logs: list[dict[str, Any]] = field(default_factory=list)
    logs: dict[int, dict[str, Any]] = field(default_factory=dict)


def _json_kind(value: Any) -> str:
    """The JSON kind of a parsed value, as a message names it ("a string", "null"...)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"{str(value).lower()}"
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, str):
        return "a string"
    return f"the number {value!r}" if isinstance(value, int | float) else type(value).__name__


def _index(value: Any) -> bool:
    """A payload index as the state file writes it: an integer >= 0 (not true/false)."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _check_state_keys(path: Path, raw: Any) -> None:
    """Refuse a state file whose keys do not hold what :func:`write_state` writes, in one
    line naming the file, the key and what was expected (a hand-edited or damaged file)."""

    def bad(key: str, expected: str, got: Any) -> ConfigError:
        return ConfigError(f"{path}: \"{key}\": expected {expected}, got {_json_kind(got)}; "
                           f"the resume state is damaged: fix or remove it")

    if not isinstance(raw, dict):
        raise bad("(top level)", "a JSON object ({\"completed\": [0, 1], ...})", raw)
    if "completed" not in raw:
        raise ConfigError(f"{path}: \"completed\": missing (expected the completed payloads, "
                          f"e.g. [0, 1]); the resume state is damaged: fix or remove it")
    completed = raw["completed"]
    if not isinstance(completed, list):
        raise bad("completed", "an array of payload indices (integers >= 0)", completed)
    for k, i in enumerate(completed):
        if not _index(i):
            raise bad(f"completed[{k}]", "a payload index (an integer >= 0)", i)
    for key, what in (("campaign", "a string (the campaign's name) or null"),):
        if key in raw and not (raw[key] is None or isinstance(raw[key], str)):
            raise bad(key, what, raw[key])
    for key, what in (("definition", "a JSON object (the campaign as recorded) or null"),
                      ("plant", "a JSON object (the simulated plant's record) or null"),
                      ("logs", "a JSON object (payload index -> its completed log)")):
        if key in raw and not (raw[key] is None or isinstance(raw[key], dict)):
            raise bad(key, what, raw[key])
    for key in ("emcy_outside_logs", "warnings_outside_logs"):
        entries = raw.get(key, [])
        if not isinstance(entries, list):
            raise bad(key, "an array of objects", entries)
        for k, e in enumerate(entries):
            if not isinstance(e, dict):
                raise bad(f"{key}[{k}]", "a JSON object", e)
    for key, rec in (raw.get("logs") or {}).items():
        where = f"logs.{key}"
        if not (key.isdigit() and int(key) in completed):
            raise ConfigError(f"{path}: \"{where}\": expected the index of a completed "
                              f"payload (one of {completed}); the resume state is damaged: "
                              f"fix or remove it")
        if not isinstance(rec, dict):
            raise bad(where, "a JSON object ({\"name\": ..., \"bytes\": ...})", rec)
        if not isinstance(rec.get("name"), str):
            raise bad(f"{where}.name", "a string (the log's file name)", rec.get("name"))
        if not _index(rec.get("bytes")):
            raise bad(f"{where}.bytes", "the log's size (an integer >= 0)", rec.get("bytes"))


def read_state(path: Path) -> RunState:
    """``<stem>.state.json`` as a :class:`RunState` (empty when there is none).

    Raises
    ------
    daq.ConfigError
        The file exists but is not a state file (it is never taken as empty: that would
        shrink it), or one of its keys does not hold what :func:`write_state` writes (a
        hand-edited file): one line naming the file, the key and what was expected, e.g.
        ``runs/x.state.json: "definition": expected a JSON object (the campaign as
        recorded) or null, got a string; the resume state is damaged: fix or remove it``.
    """
    try:
        text = path.read_text()
    except FileNotFoundError:
        return RunState()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the resume state: {exc.strerror}") from None
    try:
        raw = json.loads(text)
    except ValueError:
        raise ConfigError(f"{path}: expected a resume state ({{\"completed\": [0, 1]}}), "
                          f"the file is damaged; fix or remove it") from None
    _check_state_keys(path, raw)
    logs = {int(k): dict(v) for k, v in (raw.get("logs") or {}).items()}
    return RunState(set(raw["completed"]), raw.get("campaign"), raw.get("definition"),
                    raw.get("plant"), list(raw.get("emcy_outside_logs", [])),
                    list(raw.get("warnings_outside_logs", [])), logs)


def write_state(path: Path, state: RunState) -> None:
    """Write ``state`` atomically (temporary file + ``os.replace``)."""
    tmp = path.with_suffix(".tmp")
    rec: dict[str, Any] = {"campaign": state.campaign, "completed": sorted(state.completed)}
    if state.logs:
        rec["logs"] = {str(i): state.logs[i] for i in sorted(state.logs)}
    if state.emcy_outside_logs:
        rec["emcy_outside_logs"] = state.emcy_outside_logs
    if state.warnings_outside_logs:
        rec["warnings_outside_logs"] = state.warnings_outside_logs
    if state.plant is not None:
        rec["plant"] = state.plant
    if state.definition is not None:
        rec["definition"] = state.definition
    # one line per key: the completed payloads and the EMCYs first, the definition last
    tmp.write_text("{\n" + ",\n".join(f" {json.dumps(k)}: {json.dumps(v)}"
                                        for k, v in rec.items()) + "\n}\n")
    os.replace(tmp, path)


def keep_emcy_outside_logs(path: Path, state: RunState, after: int | None,
                           emcy: list[tuple[str, int, int, int]]) -> list[str]:
    """Record the EMCYs received after the last payload's log closed (or before any payload
    ran) in the state file's ``emcy_outside_logs``: no log is left to hold them as ``emcy``
    events, as the next payload's log holds those between payloads.

    Parameters
    ----------
    path : Path
        The state file, written with ``state`` (atomically; an OSError is reported, not
        raised: this runs as the run ends).
    state : RunState
        The run's state; the entries are appended to ``state.emcy_outside_logs``.
    after : int or None
        The payload whose run came last (None: none ran).
    emcy : list of (text, node_id, code, error register)
        ``text``: :func:`daq.runtime.engine.emcy_text`.

    Returns
    -------
    list of str
        One warning per EMCY for the run's summary, e.g. ``"node 1: EMCY 0x3210 (error
        register 0x05) after the run of payload 0 (its log closed) (in no log: recorded in
        x.state.json)"``.
    """
    where = (f"after the run of payload {after} (its log closed)" if after is not None
             else "before any payload ran")
    utc = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    for text, node_id, code, reg in emcy:
        state.emcy_outside_logs.append({
            "text": f"{text} {where}", "node_id": node_id, "code": f"0x{code:04X}",
            "error_register": f"0x{reg:02X}", "after_payload": after, "utc": utc})
    kept = _kept_outside_logs(path, state)
    return [f"{text} {where} ({kept})" for text, *_ in emcy]


def _kept_outside_logs(path: Path, state: RunState) -> str:
    """Write ``state`` to ``path`` as a run ends (an OSError reported, not raised) and say
    where what no log holds is kept, for the summary's warnings."""
    try:
        write_state(path, state)
        return f"in no log: recorded in {path.name}"
    except OSError as exc:
        return f"in no log, and not recorded: {path}: {exc.strerror or exc}"


def keep_warnings_outside_logs(path: Path, state: RunState, after: int | None,
                               texts: list[str]) -> list[str]:
    """Record the warnings of a run's wind-down (after the last payload's log closed: the
    bus lost, a drive that no longer answered) in the state file's
    ``warnings_outside_logs``, as :func:`keep_emcy_outside_logs` records the EMCYs of that
    time; returns the summary's warnings, each with where it is kept."""
    utc = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    for text in texts:
        state.warnings_outside_logs.append({"text": text, "after_payload": after, "utc": utc})
    kept = _kept_outside_logs(path, state)
    return [f"{text} ({kept})" for text in texts]


# ------------------------------------------------------------------------------ logs
def log_path(folder: Path, stem: str, index: int) -> Path:
    """``DIR/<stem>_payload<index>.mcap``."""
    return folder / f"{stem}_payload{index}.mcap"


def check_logs(folder: Path, stem: str, todo: list[int], done: set[int], *, resume: bool,
               overwrite: bool) -> None:
    """Refuse to run a payload whose log exists, unless ``resume`` (kept aside when it
    starts) or ``overwrite``.

    Raises
    ------
    daq.ConfigError
        ``"runs/x_payload0.mcap: exists (an earlier run); --resume keeps it and continues
        the campaign, --overwrite replaces it"``.
    """
    if overwrite:
        return
    for i in todo:
        p = log_path(folder, stem, i)
        if p.exists() and not (resume and i not in done):
            state = " (completed)" if i in done else ""
            raise ConfigError(f"{p}: exists (an earlier run{state}); --resume keeps it and "
                              f"continues the campaign, --overwrite replaces it")


def log_record(path: Path) -> dict[str, Any]:
    """What the state file records of a completed payload's log (:attr:`RunState.logs`):
    its file ``name`` and size ``bytes``."""
    return {"name": path.name, "bytes": path.stat().st_size}


def check_completed_logs(folder: Path, stem: str, state: RunState, state_file: Path) -> None:
    """Refuse a ``--resume`` whose state file lists a completed payload whose log is not in
    the folder as that payload's run left it: missing (moved away, deleted), or of another
    size than the state file records (replaced, cut, rewritten). The resume would skip that
    payload and leave the campaign without its log, without a word; the safe course is to
    stop and say so. Putting the log back resumes; ``--payload K --overwrite`` runs payload K
    again (its new log is recorded when it completes). A state file written before the logs
    were recorded is checked for their presence, and the logs found are recorded in
    ``state`` (written with it at the run's next write).

    Raises
    ------
    daq.ConfigError
        ``"runs/x_payload0.mcap: missing, but runs/x.state.json lists payload 0 as
        completed (--resume would skip it and leave the campaign without its log); put the
        log back, or run the payload again: --payload 0 --overwrite"``.
    """
    for i in sorted(state.completed):
        p = log_path(folder, stem, i)
        rec = state.logs.get(i, {})
        again = (f"; put the log back, or run the payload again: --payload {i} --overwrite "
                 f"(without --resume)")
        if rec.get("name", p.name) != p.name:
            raise ConfigError(f"{state_file}: \"logs.{i}.name\": expected {p.name!r} (payload "
                              f"{i}'s log), got {rec['name']!r}; the resume state is damaged: "
                              f"fix or remove it")
        try:
            size = p.stat().st_size if p.is_file() else None
        except OSError:
            size = None
        if size is None:
            raise ConfigError(f"{p}: missing, but {state_file} lists payload {i} as completed "
                              f"(--resume would skip it and leave the campaign without its "
                              f"log){again}")
        if "bytes" in rec and size != rec["bytes"]:
            raise ConfigError(f"{p}: {size} bytes, but {state_file} records {rec['bytes']} "
                              f"bytes for payload {i}'s completed log (replaced or changed "
                              f"since){again}")
        if not rec:  # a state file written before the logs were recorded: as found now
            state.logs[i] = {"name": p.name, "bytes": size}


def keep_partial(path: Path) -> Path:
    """Move the log of a payload that did not complete to
    ``partial/<name>.partial-<n>.mcap`` (first free n from 1); returns the new path."""
    dest_dir = path.parent / PARTIAL_DIR
    dest_dir.mkdir(exist_ok=True)
    n = 1
    while (dest := dest_dir / f"{path.stem}.partial-{n}{path.suffix}").exists():
        n += 1
    os.rename(path, dest)  # same file system; the folder lock keeps others out
    return dest


def create_log_file(path: Path, overwrite: bool) -> None:
    """Create ``path`` empty with ``O_EXCL`` (after removing it when ``overwrite``), so that
    a log is never replaced without a word.

    Raises
    ------
    daq.ConfigError
        The file exists (and ``overwrite`` is false), or cannot be created.
    """
    if overwrite:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        raise ConfigError(f"{path}: exists; --resume keeps it and continues the campaign, "
                          f"--overwrite replaces it") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot create the run log: {exc.strerror}") from None
    os.close(fd)


def expected_log_bytes(n_axes: int, cycle_s: float, n_cycles: int,
                       attachments_bytes: int) -> int:
    """Upper bound of a payload log's size [byte]: its records uncompressed (state, setpoint,
    frames: :func:`daq.runtime.mcaplog.chunk_size_for` over ``n_cycles``), attachments, and
    64 KiB for header, metadata and summary."""
    data = chunk_size_for(n_axes, 1 + 3 * n_axes, cycle_s, n_cycles * cycle_s)
    return data + attachments_bytes + 65536


def check_free_space(path: Path, need: int) -> str:
    """"" when the file system of ``path`` (its folder) has ``need`` bytes free, else the
    one-line refusal naming the file, the need and what is free."""
    free = shutil.disk_usage(path.parent).free
    if free >= need:
        return ""
    return (f"{path}: not enough free space for the run log: expected up to "
            f"{need / 1e6:.1f} MB, {free / 1e6:.1f} MB free on {path.parent}")
