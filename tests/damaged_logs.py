"""Damaging a real run log for the tests: one chunk's compressed data zeroed in place."""

from __future__ import annotations

from pathlib import Path

from mcap.reader import make_reader


def damage_chunk(src: Path, dst: Path, *, at: float = 0.5, min_chunks: int = 3) -> Path:
    """Copy ``src`` to ``dst`` with 32 bytes in the middle of one chunk's data zeroed: the
    chunk at ``at`` (0..1) of the file's chunks, in file order. The chunk's record length
    stays intact, so readers can skip it and go on with the next one."""
    with open(src, "rb") as f:
        chunks = sorted(make_reader(f).get_summary().chunk_indexes,
                        key=lambda c: c.chunk_start_offset)
    assert len(chunks) >= min_chunks, f"{src}: {len(chunks)} chunks"
    chunk = chunks[int(at * len(chunks))]
    data = bytearray(src.read_bytes())
    k = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[k : k + 32] = bytes(32)
    dst.write_bytes(bytes(data))
    return dst
