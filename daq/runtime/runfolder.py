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
  unreadable state file is refused, not taken as empty.
- **Room for the log.** :func:`check_free_space` refuses a payload when the file system
  has less free space than the log's expected size: :func:`expected_log_bytes`, the
  uncompressed size of its records (an upper bound: the chunks are zstd-compressed).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import shutil
from pathlib import Path

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
def read_state(path: Path) -> set[int]:
    """The completed payload indices of ``<stem>.state.json`` (empty when there is none).

    Raises
    ------
    daq.ConfigError
        The file exists but is not a state file (it is never taken as empty: that would
        shrink it).
    """
    try:
        text = path.read_text()
    except FileNotFoundError:
        return set()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the resume state: {exc.strerror}") from None
    try:
        raw = json.loads(text)
        return {int(i) for i in raw["completed"]}
    except (ValueError, TypeError, KeyError):
        raise ConfigError(f"{path}: expected a resume state ({{\"completed\": [0, 1]}}), "
                          f"the file is damaged; fix or remove it") from None


def write_state(path: Path, name: str, completed: set[int]) -> None:
    """Write the completed payload indices atomically (temporary file + ``os.replace``)."""
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps({"campaign": name, "completed": sorted(completed)}))
    os.replace(tmp, path)


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
