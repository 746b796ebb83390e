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
  unreadable state file is refused, not taken as empty. It records its campaign as the
  logs do (``campaign``, ``definition``, ``plant``: :class:`RunState`), so that a state of
  another campaign is refused like its logs (:func:`daq.runtime.campaign_id.check_state`),
  and the EMCYs received while no log was open after the last payload's
  (``emcy_outside_logs``, kept from run to run).
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
    """

    completed: set[int] = field(default_factory=set)
    campaign: str | None = None
    definition: Any = None
    plant: dict[str, str] | None = None
    emcy_outside_logs: list[dict[str, Any]] = field(default_factory=list)


def read_state(path: Path) -> RunState:
    """``<stem>.state.json`` as a :class:`RunState` (empty when there is none).

    Raises
    ------
    daq.ConfigError
        The file exists but is not a state file (it is never taken as empty: that would
        shrink it).
    """
    try:
        text = path.read_text()
    except FileNotFoundError:
        return RunState()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the resume state: {exc.strerror}") from None
    try:
        raw = json.loads(text)
        completed = {int(i) for i in raw["completed"]}
        name = raw.get("campaign")
        plant = raw.get("plant")
        emcy = list(raw.get("emcy_outside_logs", []))
        if not ((name is None or isinstance(name, str))
                and (plant is None or isinstance(plant, dict))
                and all(isinstance(e, dict) for e in emcy)):
            raise TypeError
    except (ValueError, TypeError, KeyError, AttributeError):
        raise ConfigError(f"{path}: expected a resume state ({{\"completed\": [0, 1]}}), "
                          f"the file is damaged; fix or remove it") from None
    return RunState(completed, name, raw.get("definition"), plant, emcy)


def write_state(path: Path, state: RunState) -> None:
    """Write ``state`` atomically (temporary file + ``os.replace``)."""
    tmp = path.with_suffix(".tmp")
    rec: dict[str, Any] = {"campaign": state.campaign, "completed": sorted(state.completed)}
    if state.emcy_outside_logs:
        rec["emcy_outside_logs"] = state.emcy_outside_logs
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
    try:
        write_state(path, state)
        kept = f"in no log: recorded in {path.name}"
    except OSError as exc:
        kept = f"in no log, and not recorded: {path}: {exc.strerror or exc}"
    return [f"{text} {where} ({kept})" for text, *_ in emcy]


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
