"""Export the raw CAN frames of a jointid run log to the usual CAN trace formats.

The ``/can/raw`` channel of a run log (``docs/log-format.md``) holds every frame the master
sent (SYNC, RPDOs) or received (TPDOs, heartbeats, EMCY, SDO) during the cycles of the run,
with python-can timestamps (Unix epoch [s]). :func:`export_can` writes them with
python-can's own writers, chosen by the output's extension, so that python-can's readers,
``python -m can.player`` (replay on any interface), ``python -m can.logconvert``, Vector
CANalyzer/CANoe (``.asc``, ``.blf``), PEAK PCAN-View (``.trc``) and ``canplayer``/``candump``
(``.log``) read them:

=========  ==========================  ============================================
extension  writer                      timestamp resolution of the format
=========  ==========================  ============================================
``.blf``   ``can.BLFWriter``           1 ns from the first frame; the file's start
                                       time is a SYSTEMTIME (1 ms)
``.asc``   ``can.ASCWriter``           1 µs from the first frame; start date to 1 ms
``.log``   ``can.CanutilsLogWriter``   1 µs, absolute (candump ``-l`` format)
``.csv``   ``can.CSVWriter``           full float, absolute
``.trc``   ``can.TRCWriter``           1 µs from the first frame (PCAN v2.1);
                                       start time as a day fraction (≈ 1 ms)
=========  ==========================  ============================================

A ``.gz`` suffix after a text format (``out.asc.gz``, ``out.log.gz``) compresses the file,
as python-can's logger and player do.

Frames are written in time order (stable sort on the timestamp: within a cycle the log keeps
arrival order, which is already time order up to the send/receive stamping of the master).
Direction: the master's own cyclic frames (SYNC 0x80 and each drive's RPDO1 0x200 + node id,
node ids from the log's ``drive<k>`` metadata) are marked transmitted (``is_rx = False``),
every other frame received. All frames are classic CAN, 11-bit identifiers.

Channels: one per bus of the run, in the order of the drives (``drive<k>.channel`` of the
log's metadata; a single-bus run has one). A frame goes to the bus of the node its COB-ID
names (node ids are unique over all buses: ``daq.runtime.buses``); SYNC, TIME, NMT to node 0
and COB-IDs of no logged node went out on every bus (``MultiBus``), so they are written once
per bus. How each format numbers them:

- ``.asc``, ``.blf``, ``.trc``: channel numbers from 1 (Vector, PEAK), bus k (0-based) is
  ``channel + k``; python-can's writers add 1 to ``Message.channel`` (interface numbering
  from 0), so the messages carry ``channel + k - 1``. The ASC file names the buses in
  comment lines after its header (``// jointid channel 1 = can0``). python-can's ASC and BLF
  readers give back the 0-based number, its TRC reader the 1-based one.
- ``.log`` (candump): the bus name itself as the interface column (whitespace replaced by
  ``_``).
- ``.csv``: python-can's CSV has no channel column: a run on one bus only (a multi-bus run is
  refused: it would merge the buses).

:attr:`ExportResult.channels` (and ``jointid export``'s output line) gives the mapping.

A log cut short by a killed process (no summary) is exported up to its last complete chunk;
the reader warns (``RuntimeWarning``).
"""

from __future__ import annotations

import gzip
import struct
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import can
import numpy as np

from daq import DaqError
from daq.protocol.logformat import EXPORT_FORMATS, FRAME_DTYPE
from daq.protocol.reader import LogReadError, read_topics

__all__ = ["EXPORT_FORMATS", "ExportError", "ExportResult", "export_can"]


class _ASCWriter(can.ASCWriter):
    """python-can's ASC writer with the milliseconds of the start date zero-padded.

    python-can 4.x writes ``msec`` with ``str.format`` unpadded, so 22 ms becomes ".22" and
    its own reader (and CANoe) read 220 ms back; seen as a 0.2 s offset in
    ``tests/test_export.py``.
    """

    def _format_header_datetime(self, dt):  # type: ignore[override]
        return dt.strftime(self.FORMAT_DATE.format(f"{dt.microsecond // 1000 % 1000:03d}"))

    def comment(self, text: str) -> None:
        """A ``// text`` line; before the first frame it lands in the header, where CANoe
        writes its own (``// version ...``) and python-can's reader skips them."""
        self.file.write(f"// {text}\n")


def _open_writer(path: Path, comments: Sequence[str] = ()) -> can.io.generic.MessageWriter:
    """python-can's writer for the suffix of ``path``, with the ASC date fixed; ``comments``
    go into the header of an ASC file (the other formats have no place for them)."""
    name = path.name.lower()
    if name.endswith(".asc") or name.endswith(".asc.gz"):
        w = _ASCWriter(path if name.endswith(".asc")
                       else gzip.open(path, "wt", encoding="utf-8"))
        for c in comments:
            w.comment(c)
        return w
    return can.Logger(path)

SYNC_ID = 0x80
RPDO1_BASE = 0x200
NMT_ID = 0x000
_CYCLE_N = struct.Struct("<qI")  # CanFrames message after its 4-byte CDR header


class ExportError(DaqError):
    """The export cannot be done as asked; the message names the file and the reason."""


@dataclass(frozen=True)
class ExportResult:
    """What :func:`export_can` wrote.

    Attributes
    ----------
    path : Path
        The file written.
    frames : int
        Frames written.
    first_s, last_s : float
        Timestamps of the first and last frame [s] (Unix epoch; NaN when no frame).
    transmitted : int
        Frames marked as sent by the master (SYNC, RPDO1).
    channels : tuple of (int or str, str)
        (channel in the trace, bus name) per bus of the run: the number of ``.asc``,
        ``.blf``, ``.trc`` (from 1), the interface name of ``.log``, None for ``.csv``.
    """

    path: Path
    frames: int
    first_s: float
    last_s: float
    transmitted: int
    channels: tuple[tuple[int | str | None, str], ...] = ()


def _format_of(out: Path) -> str:
    suffixes = [s.lower() for s in out.suffixes]
    if suffixes and suffixes[-1] == ".gz":
        suffixes = suffixes[:-1]
        if suffixes and suffixes[-1] == ".blf":
            raise ExportError(f"{out}: expected one of {', '.join(EXPORT_FORMATS)} "
                              f"(.gz only after a text format), got .blf.gz")
    fmt = suffixes[-1] if suffixes else ""
    if fmt not in EXPORT_FORMATS:
        raise ExportError(f"{out}: expected an output file ending in "
                          f"{', '.join(EXPORT_FORMATS)} (optionally + .gz for text), "
                          f"got {fmt or 'no extension'!r}")
    return fmt


def read_log(path: Path) -> tuple[np.ndarray, dict[str, dict[str, str]], bool]:
    """The ``/can/raw`` frames and the metadata of a run log.

    Read with the run-log reader (:mod:`daq.protocol.reader`): a closed log through its chunk
    index, a log cut short by a killed process record by record. A damaged chunk is skipped
    with a warning naming the cycles it held, and the frames of every other chunk (before
    and after it) are kept.

    Returns
    -------
    (ndarray, dict, bool)
        Frames (structured: ``timestamp`` [s], ``id``, ``dlc``, ``data`` uint8 x 8), in log
        order; metadata name -> map; True when the file ended in a truncated tail or held
        damaged chunks.

    Raises
    ------
    LogReadError
        The file cannot be opened or is not an MCAP file.
    """
    log = read_topics(path, {"/can/raw"})
    parts = [np.frombuffer(msg, FRAME_DTYPE, count=_CYCLE_N.unpack_from(msg, 4)[1], offset=20)
             for msg in log.raw.get("/can/raw", [])]
    frames = np.concatenate(parts) if parts else np.zeros(0, FRAME_DTYPE)
    return frames, log.metadata, log.damaged


def master_ids(metadata: dict[str, dict[str, str]]) -> frozenset[int]:
    """COB-IDs the master sends every cycle: SYNC and each drive's RPDO1."""
    ids = {SYNC_ID}
    for name, rec in metadata.items():
        if name.startswith("drive") and name[5:].isdigit():
            try:
                ids.add(RPDO1_BASE + int(rec.get("node_id", "")))
            except ValueError:
                continue
    return frozenset(ids)


def buses_of(metadata: dict[str, dict[str, str]]) -> tuple[list[str], dict[int, int]]:
    """The run's bus names (in the order of the drives) and node id -> index of its bus.

    From ``drive<k>.channel`` and ``.node_id``; a log without them has one bus, named by
    ``campaign.channel`` (or ``can0``)."""
    default = metadata.get("campaign", {}).get("channel") or "can0"
    drives = sorted((int(n[5:]), rec) for n, rec in metadata.items()
                    if n.startswith("drive") and n[5:].isdigit())
    buses: list[str] = []
    node_bus: dict[int, int] = {}
    for _, rec in drives:
        name = rec.get("channel") or default
        if name not in buses:
            buses.append(name)
        try:
            node_bus[int(rec.get("node_id", ""))] = buses.index(name)
        except ValueError:
            continue
    return buses or [default], node_bus


def _frame_buses(cid: int, data: np.ndarray, dlc: int, node_bus: dict[int, int],
                 n_buses: int) -> range | tuple[int]:
    """Indices of the buses a frame was on: its node's, or all for a broadcast."""
    node = data[1] if cid == NMT_ID and dlc >= 2 else cid & 0x7F
    k = node_bus.get(int(node)) if node else None
    return range(n_buses) if k is None else (k,)


def export_can(mcap_path: str | Path, out_path: str | Path, *, channel: int = 1) -> ExportResult:
    """Write the raw CAN frames of a run log to a CAN trace file chosen by extension.

    Parameters
    ----------
    mcap_path : path-like
        A jointid run log (``<campaign>_payload<k>.mcap``).
    out_path : path-like
        Output file; its extension picks the format (module docstring). Written to a
        temporary name next to it and renamed at the end: no partial file on error.
    channel : int
        Channel number of the run's first bus in ``.asc``/``.blf``/``.trc`` (1-based, as
        those formats count); bus k is ``channel + k``. ``.log`` names the buses instead.

    Returns
    -------
    ExportResult

    Raises
    ------
    ExportError
        Unknown extension, an existing output file (never replaced), unreadable log, log
        without a ``/can/raw`` channel, a multi-bus run to ``.csv`` (no channel column),
        unwritable output.
    """
    src = Path(mcap_path)
    out = Path(out_path)
    _format_of(out)
    if out.exists():  # a trace (or anything) there is never replaced
        raise ExportError(f"{out}: already exists; export writes a new file (remove it first "
                          f"or give another --can)")
    if not src.is_file():
        raise ExportError(f"{src}: expected a jointid run log (.mcap), file not found")
    try:
        frames, meta, damaged = read_log(src)
    except LogReadError as exc:
        why = str(exc).removeprefix(f"{src}: ")
        raise ExportError(f"{src}: expected a jointid run log ({why})") from None
    if not frames.shape[0] and "campaign" not in meta:
        raise ExportError(f"{src}: expected a jointid run log (MCAP with a /can/raw channel "
                          f"and campaign metadata), found neither")
    if damaged:
        warnings.warn(f"{src}: log cut short or damaged: exporting the {frames.shape[0]} "
                      f"frames of its readable chunks", RuntimeWarning, stacklevel=2)
    order = np.argsort(frames["timestamp"], kind="stable")
    frames = frames[order]
    tx_ids = master_ids(meta)
    buses, node_bus = buses_of(meta)
    fmt = _format_of(out)
    if fmt == ".csv" and len(buses) > 1:
        raise ExportError(f"{out}: python-can's CSV has no channel column, the run used "
                          f"{len(buses)} buses ({', '.join(buses)}); export it as .blf, .asc, "
                          ".trc or .log")
    labels: list[int | str | None]
    if fmt == ".log":
        labels = ["_".join(b.split()) or "can0" for b in buses]
        msg_channel: list[int | str | None] = list(labels)
    elif fmt == ".csv":
        labels = msg_channel = [None]
    else:  # the writers write Message.channel + 1
        labels = [channel + k for k in range(len(buses))]
        msg_channel = [c - 1 for c in labels]
    comments = [f"jointid channel {c} = {b}" for c, b in zip(labels, buses, strict=True)]
    # python-can picks the writer by the suffix: the temporary name keeps the extension(s)
    tmp = out.with_name(f".part-{out.name}")
    n_tx = n_written = 0
    try:
        writer = _open_writer(tmp, comments)
        try:
            ts, ids, dlcs, data = (frames["timestamp"].tolist(), frames["id"].tolist(),
                                   frames["dlc"].tolist(), frames["data"])
            n_bus = len(buses)
            for k in range(len(ts)):
                cid = ids[k]
                dlc = dlcs[k]
                rx = cid not in tx_ids
                payload = bytes(data[k][:dlc])
                for b in _frame_buses(cid, data[k], dlc, node_bus, n_bus):
                    n_tx += not rx
                    n_written += 1
                    writer.on_message_received(can.Message(
                        timestamp=ts[k], arbitration_id=cid, is_extended_id=False,
                        dlc=dlc, data=payload, is_rx=rx, channel=msg_channel[b]))
        finally:
            writer.stop()
        tmp.replace(out)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise ExportError(f"{out}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    n = int(frames.shape[0])
    first = float(frames["timestamp"][0]) if n else float("nan")
    last = float(frames["timestamp"][-1]) if n else float("nan")
    return ExportResult(out, n_written, first, last, n_tx,
                        tuple(zip(labels, buses, strict=True)))
