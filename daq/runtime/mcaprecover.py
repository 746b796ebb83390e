"""Recovery of a run log: its intact records rewritten with message indexes and a summary.

``jointid recover`` (:mod:`daq.runtime.cli_recover`) for a log whose writer was killed (no
summary, a partial last chunk) or written before the writer added message indexes; see
``docs/log-format.md``.
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.data_stream import ReadDataStream
from mcap.records import Attachment, Channel, Header, Message, Metadata, Opcode, Schema

from daq import DaqError, __version__
from daq.protocol.reader import MAGIC, LogReadError, RecordWalk, chunk_records

from .mcaplog import FastWriter, message_offsets


@dataclass(frozen=True)
class Recovered:
    """What :func:`recover_log` wrote.

    Attributes
    ----------
    path : Path
        The file written.
    chunks, messages : int
        Chunks and messages copied.
    damaged : int
        Chunks skipped because their data was damaged (sizes, decompression or CRC).
    dropped_bytes : int
        Bytes at the end of the source that held no complete record (the chunk being
        written when the writer was killed).
    had_summary : bool
        The source was closed properly (had reached its data end).
    """

    path: Path
    chunks: int
    messages: int
    damaged: int
    dropped_bytes: int
    had_summary: bool


def recover_log(src: str | Path, dst: str | Path) -> Recovered:
    """Rewrite the intact records of a run log with message indexes and a summary.

    For a log whose writer was killed (no summary, a partial last chunk): every complete
    record is copied in order (header, schemas, channels, metadata, attachments, chunks
    whose data checks out), each chunk followed by its message indexes, and the summary
    and footer are written, so that indexed readers (``mcap`` library, ``@mcap/core``,
    Foxglove) open the result. A metadata record ``recovered`` (``source``, ``chunks``,
    ``damaged_chunks``, ``dropped_bytes``) is added. The output is written to a temporary
    file next to ``dst`` and renamed on success: nothing is left behind on error.

    Raises
    ------
    DaqError
        ``src`` cannot be read, is not an MCAP file, or ``dst`` is ``src``.
    """
    src, dst = Path(src), Path(dst)
    if dst.exists() and src.exists() and dst.resolve() == src.resolve():
        raise DaqError(f"{dst}: the recovered log must be written to another file")
    try:
        f = open(src, "rb")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise LogReadError(f"{src}: cannot open the run log: {exc.strerror}") from exc
    tmp = dst.with_name(dst.name + ".part")
    try:
        with f, open(tmp, "wb") as out:
            result = _recover(f, src, out, dst)
        tmp.replace(dst)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return result


def _recover(f: Any, src: Path, out: Any, dst: Path) -> Recovered:
    size = os.fstat(f.fileno()).st_size
    if f.read(len(MAGIC)) != MAGIC:
        what = "an empty file" if size == 0 else "no MCAP magic at its start"
        raise LogReadError(f"{src}: not an MCAP file ({what})")
    w = FastWriter(out, chunk_size=1 << 62)  # loose messages (other writers) in one chunk
    started = False
    schemas: set[int] = set()
    channels: set[int] = set()
    chunks = damaged = messages = 0
    walk = RecordWalk(f, size)
    reached_end = False
    for _, opcode, length in walk:
        if opcode == Opcode.DATA_END:
            reached_end = True
            break
        body = f.read(length)
        if opcode == Opcode.HEADER and not started:
            try:
                head = Header.read(ReadDataStream(io.BytesIO(body)))
            except Exception:  # damaged header: ours instead
                head = Header(profile="", library=f"jointid {__version__}")
            w.start(profile=head.profile, library=head.library)
            started = True
            continue
        if not started:
            w.start(library=f"jointid {__version__}")
            started = True
        try:
            if opcode == Opcode.CHUNK:
                raw, _, _ = chunk_records(src, body)
                offsets = message_offsets(raw)
                for inner in _schemas_and_channels(raw):
                    _register(w, inner, schemas, channels)
                w.write_chunk(raw, offsets)
                chunks += 1
                messages += len(offsets)
                continue
            rec = _RECOVERED[opcode].read(ReadDataStream(io.BytesIO(body))) \
                if opcode in _RECOVERED else None
        except LogReadError:
            raise
        except Exception:
            damaged += opcode == Opcode.CHUNK
            continue
        if isinstance(rec, (Schema, Channel)):
            _register(w, rec, schemas, channels)
        elif isinstance(rec, Metadata):
            w.add_metadata(rec.name, dict(rec.metadata))
        elif isinstance(rec, Attachment):
            w.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
        elif isinstance(rec, Message):
            w.add_message(rec.channel_id, rec.log_time, rec.data, rec.publish_time,
                          rec.sequence)
            messages += 1
    if not started:
        w.start(library=f"jointid {__version__}")
    dropped = 0 if walk.complete or reached_end else size - walk.end
    w.add_metadata("recovered", {"source": src.name, "chunks": str(chunks),
                                 "damaged_chunks": str(damaged), "dropped_bytes": str(dropped)})
    w.finish()
    return Recovered(path=dst, chunks=chunks, messages=messages, damaged=damaged,
                     dropped_bytes=dropped, had_summary=reached_end)


_RECOVERED: dict[int, Any] = {Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel,
                              Opcode.METADATA: Metadata, Opcode.ATTACHMENT: Attachment,
                              Opcode.MESSAGE: Message}


def _register(w: FastWriter, rec: Schema | Channel, schemas: set[int],
              channels: set[int]) -> None:
    """Write a schema or channel record once per id (the summary lists it)."""
    if isinstance(rec, Schema) and rec.id not in schemas:
        schemas.add(rec.id)
        w.register_schema(rec.name, rec.encoding, rec.data, fixed_id=rec.id)
    elif isinstance(rec, Channel) and rec.id not in channels:
        channels.add(rec.id)
        w.register_channel(rec.topic, rec.message_encoding, rec.schema_id, fixed_id=rec.id,
                           metadata=rec.metadata)


def _schemas_and_channels(raw: bytes) -> list[Schema | Channel]:
    """The schema and channel records inside a chunk (other writers put them there)."""
    out: list[Schema | Channel] = []
    pos = 0
    while pos + 9 <= len(raw):
        opcode = raw[pos]
        length = int.from_bytes(raw[pos + 1 : pos + 9], "little")
        if opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            cls = Schema if opcode == Opcode.SCHEMA else Channel
            out.append(cls.read(ReadDataStream(io.BytesIO(raw[pos + 9 : pos + 9 + length]))))
        pos += 9 + length
    return out
