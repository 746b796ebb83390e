"""Run logs against the reference MCAP readers; damaged chunks; not-MCAP files; recover.

A real log is written by the runner on a simulated drive (lockstep, virtual bus) and read
back by the ``mcap`` library's indexed (seeking) reader and, where ``node`` and ``npm``
exist, by ``@mcap/core``'s ``McapIndexedReader.readMessages`` (the reader of Foxglove and
Lichtblick), installed with npm into ``~/.cache/jointid-mcap-node`` (the test skips, with the
reason, when node/npm or the install is unavailable).
"""

from __future__ import annotations

import fcntl
import io
import json
import os
import shutil
import struct
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest
import zstandard
from daq_campaigns import sine_campaign
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk, MessageIndex, Opcode
from mcap.writer import CompressionType, Writer

from daq.app.cli import main
from daq.protocol.logformat import FRAME
from daq.protocol.reader import LogReadError, read_frames, read_run
from daq.runtime.mcaplog import RunLog
from daq.runtime.mcaprecover import recover_log
from daq.runtime.runner import run_campaign
from sim_drivers.plant_config import default_plant

NODE_DIR = Path.home() / ".cache" / "jointid-mcap-node"
NODE_PACKAGES = ("@mcap/core@2", "@mcap/support@1")

# reads every message of argv[2] with McapIndexedReader.readMessages; prints counts as JSON
NODE_READER = r"""
const { McapIndexedReader } = require("@mcap/core");
const { loadDecompressHandlers } = require("@mcap/support");
const fs = require("fs/promises");
(async () => {
  const fh = await fs.open(process.argv[2], "r");
  const size = (await fh.stat()).size;
  const readable = {
    size: async () => BigInt(size),
    read: async (offset, length) => {
      const buf = new Uint8Array(Number(length));
      await fh.read(buf, 0, Number(length), Number(offset));
      return buf;
    },
  };
  const reader = await McapIndexedReader.Initialize({
    readable, decompressHandlers: await loadDecompressHandlers() });
  const topics = new Map([...reader.channelsById].map(([id, ch]) => [id, ch.topic]));
  const counts = {};
  let n = 0, last = -1n, ordered = true;
  for await (const msg of reader.readMessages({ validateCrcs: true })) {
    const t = topics.get(msg.channelId);
    counts[t] = (counts[t] ?? 0) + 1;
    if (msg.logTime < last) ordered = false;
    last = msg.logTime;
    n += 1;
  }
  console.log(JSON.stringify({ messages: n, ordered, counts,
    statistics: Number(reader.statistics.messageCount) }));
  await fh.close();
})().catch((e) => { console.error(String(e)); process.exit(1); });
"""


@pytest.fixture(scope="module")
def real_log(tmp_path_factory) -> Path:
    """One payload run of the runner on a simulated drive (lockstep, ~1.4 s of campaign at
    2 ms, 50 ms chunks)."""
    c = sine_campaign("compat", chunk_seconds=0.05)
    out = tmp_path_factory.mktemp("compat")
    r = run_campaign(c, out_dir=out, simulate=default_plant(), yes=True)
    assert r.status == "done", r.reason
    return Path(r.runs[0].path)


def _indexed_read(path: Path) -> tuple[int, dict[str, int], object]:
    """Every message through the mcap library's seeking reader (CRCs checked)."""
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        counts: dict[str, int] = {}
        last = -1
        for _, ch, msg in reader.iter_messages():
            counts[ch.topic] = counts.get(ch.topic, 0) + 1
            assert msg.log_time >= last  # log-time order across chunks
            last = msg.log_time
    return sum(counts.values()), counts, summary


def _index_at(data: bytes, off: int) -> MessageIndex:
    opcode, length = struct.unpack_from("<BQ", data, off)
    assert opcode == Opcode.MESSAGE_INDEX
    return MessageIndex.read(ReadDataStream(io.BytesIO(data[off + 9 : off + 9 + length])))


def _check_message_indexes(path: Path, summary) -> int:
    """Every chunk index points to one MessageIndex per channel of its chunk, right after the
    chunk; each entry's offset holds a message of that channel at that log time. Returns the
    number of entries."""
    data = path.read_bytes()
    n = 0
    for ci in summary.chunk_indexes:
        end = ci.chunk_start_offset + ci.chunk_length
        assert ci.message_index_offsets and min(ci.message_index_offsets.values()) == end
        chunk = Chunk.read(ReadDataStream(io.BytesIO(data[ci.chunk_start_offset + 9 : end])))
        raw = zstandard.ZstdDecompressor().decompress(
            chunk.data, max_output_size=chunk.uncompressed_size)
        total = 0
        for cid, off in ci.message_index_offsets.items():
            mi = _index_at(data, off)
            total += 9 + struct.unpack_from("<Q", data, off + 1)[0]
            times = [t for t, _ in mi.records]
            assert mi.channel_id == cid and times and times == sorted(times)
            assert ci.message_start_time <= times[0] and times[-1] <= ci.message_end_time
            for t, o in mi.records:
                op, _, ch, _, lt = struct.unpack_from("<BQHIQ", raw, o)
                assert (op, ch, lt) == (Opcode.MESSAGE, cid, t)
            n += len(mi.records)
        assert total == ci.message_index_length
    return n


def _node_reader() -> Path | str:
    """The node script with @mcap/core installed beside it, or why it is unavailable.

    Two test sessions may start at once on a fresh machine (CI runs the suite beside another
    copy): the check and the install run under an exclusive lock on the folder, so that one
    session installs and the other waits and reuses it (a second ``npm install`` in the same
    folder rewrites node_modules while the first session's node reads it)."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if not node or not npm:
        return "node/npm not found: @mcap/core reader not run"
    NODE_DIR.mkdir(parents=True, exist_ok=True)
    with open(NODE_DIR / ".install.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file is closed
        ok = all((NODE_DIR / "node_modules" / p.rsplit("@", 1)[0] / "package.json").is_file()
                 for p in NODE_PACKAGES)
        if not ok:
            if not (NODE_DIR / "package.json").is_file():
                (NODE_DIR / "package.json").write_text('{"name": "jointid-mcap-node", '
                                                       '"private": true}\n')
            try:
                proc = subprocess.run([npm, "install", "--no-audit", "--no-fund",
                                       *NODE_PACKAGES], cwd=NODE_DIR, capture_output=True,
                                      text=True, timeout=600)
            except subprocess.TimeoutExpired:
                return "npm install @mcap/core timed out"
            if proc.returncode != 0:
                return f"npm install @mcap/core failed: {proc.stderr.strip()[-300:]}"
        script = NODE_DIR / "read_all.js"
        if not script.is_file() or script.read_text() != NODE_READER:
            tmp = script.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_text(NODE_READER)
            tmp.replace(script)  # atomic: a reader never sees half a script
    return script


def _node_read(path: Path) -> dict:
    """What @mcap/core's readMessages reads from ``path``; skips when it is unavailable."""
    script = _node_reader()
    if isinstance(script, str):
        pytest.skip(script)
    proc = subprocess.run(["node", str(script), str(path)], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def _write(path: Path, n: int, close: bool = True) -> RunLog:
    """A two-axis log of ``n`` cycles at 1 kHz, ~50 cycles per chunk."""
    log = RunLog(path, n_axes=2, cycle_s=0.001, chunk_seconds=0.05,
                 metadata={"payload": {"mass_kg": "3.5", "arm_m": "1.2"},
                           "campaign": {"joint_kind": "revolute", "cycle_s": "0.001"}},
                 attachments=[("c.toml", "application/toml", b"name = 'x'\n")])
    fr = FRAME.pack(1.5, 0x80, 0, b"") + FRAME.pack(1.5, 0x201, 4, b"\x0f\x00\x10\x00")
    for c in range(n):
        for ax in range(2):
            log.state(ax, c, c * 1e-3, 0.001 * c + ax, -0.5 * c, 2.0 * c, 3.0, c * 7 + ax,
                      -c, c % 1000, -(c % 1000), 0x1237, 0)
        log.setpoint(c, c * 1e-3, 0.002 * c, 0.1, 0.2, 0, 0)
        log.frames(c, fr, 2)
    if close:
        log.close({"status": "done"})
    return log


def _chunk_cycles(path: Path, log: RunLog) -> list[tuple[int, int, int, int]]:
    """(offset, length, first cycle, last cycle) of every chunk, from the chunk indexes."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    return [(ci.chunk_start_offset, ci.chunk_length,
             (ci.message_start_time - log.start_ns) // log.cycle_ns,
             (ci.message_end_time - log.start_ns) // log.cycle_ns)
            for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)]


# ------------------------------------------------------------------- reference readers
def test_real_log_read_by_mcap_indexed_reader(real_log):
    n, counts, summary = _indexed_read(real_log)
    stats = summary.statistics
    assert n == stats.message_count > 0
    assert stats.chunk_count == len(summary.chunk_indexes) > 1
    by_topic = {summary.channels[c].topic: k for c, k in stats.channel_message_counts.items()}
    assert counts == by_topic
    run = read_run(real_log)
    assert counts["/joint/0/state"] == counts["/setpoint"] == counts["/can/raw"] == len(run)
    assert {s.name for s in summary.schemas.values()} >= {"jointid_msgs/msg/JointState",
                                                          "jointid_msgs/msg/Setpoint"}
    assert _check_message_indexes(real_log, summary) == n


def test_real_log_read_by_mcap_core_indexed_reader(real_log):
    """@mcap/core (Foxglove, Lichtblick): readMessages returns every message in order."""
    n, counts, _ = _indexed_read(real_log)
    got = _node_read(real_log)
    assert got["messages"] == got["statistics"] == n
    assert got["counts"] == counts and got["ordered"]


# --------------------------------------------------------------------- damaged chunks
@pytest.mark.parametrize("damage", ["data", "record header"])
def test_damaged_chunk_is_skipped_and_the_rest_read(tmp_path, damage):
    p = tmp_path / "r.mcap"
    log = _write(p, 1000)
    chunks = _chunk_cycles(p, log)
    off, length, first, last = chunks[len(chunks) // 2]
    data = bytearray(p.read_bytes())
    if damage == "data":  # inside the compressed data
        data[off + length // 2 : off + length // 2 + 32] = bytes(32)
    else:  # the opcode and length: a stream reader loses its way there
        data[off : off + 9] = b"\xff" * 9
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with pytest.warns(RuntimeWarning) as rec:
        a = read_run(bad, axis=1)
    msgs = [str(w.message) for w in rec]
    assert msgs == [f"{bad}: chunk at offset {off} damaged "
                    f"({msgs[0].split('(', 1)[1].split(')')[0]}): cycles {first}..{last} lost"]
    kept = np.setdiff1d(np.arange(1000), np.arange(first, last + 1))
    assert np.array_equal(a.cycle, kept) and last < 999  # every chunk after it is read
    assert np.array_equal(a.q, 0.001 * kept + 1)
    assert a.lost_cycles == ((first, last),) and not a.truncated
    assert a.metadata["result"]["status"] == "done"
    with pytest.warns(RuntimeWarning, match=f"cycles {first}..{last} lost"):
        frames = read_frames(bad)
    assert np.array_equal(np.unique(frames["cycle"]), kept)


def test_not_mcap_is_said_in_one_line(tmp_path, capsys):
    bad = tmp_path / "noise_payload0.mcap"
    bad.write_bytes(np.random.default_rng(0).integers(0, 256, 5000, np.uint8).tobytes())
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "truncated" warning either
        with pytest.raises(LogReadError) as exc:
            read_run(bad)
    assert str(exc.value) == f"{bad}: not an MCAP file (no MCAP magic at its start)"
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(LogReadError, match=r"empty.mcap: not an MCAP file \(an empty file\)"):
        read_run(empty)
    out = tmp_path / "out.mcap"
    assert main(["recover", str(bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == (f"jointid recover: error: {bad}: not an MCAP file "
                   "(no MCAP magic at its start)\n")
    assert not out.exists() and not (tmp_path / "out.mcap.part").exists()


# ---------------------------------------------------------------------------- recover
def test_recover_log_truncated_mid_chunk(tmp_path, capsys):
    p = tmp_path / "full.mcap"
    log = _write(p, 1000)
    chunks = _chunk_cycles(p, log)
    off, length, first, _ = chunks[-3]
    killed = tmp_path / "killed_payload0.mcap"
    killed.write_bytes(p.read_bytes()[: off + length // 2])  # cut inside a chunk
    with pytest.warns(RuntimeWarning, match="truncated run log"):
        cut = read_run(killed)
    assert np.array_equal(cut.cycle, np.arange(first))
    with open(killed, "rb") as f, pytest.raises(Exception):  # noqa: B017, PT011
        make_reader(f).get_summary()  # what the indexed readers say before recover
    assert main(["recover", str(killed)]) == 0
    line = capsys.readouterr().out
    assert line.startswith(f"recover: {len(chunks) - 3} chunks, {4 * first} messages -> {killed}")
    assert f"original kept as {killed}.orig" in line
    assert (tmp_path / "killed_payload0.mcap.orig").stat().st_size == off + length // 2
    n, counts, summary = _indexed_read(killed)
    assert n == summary.statistics.message_count == 4 * first
    assert counts == {"/joint/0/state": first, "/joint/1/state": first, "/setpoint": first,
                      "/can/raw": first}
    assert _check_message_indexes(killed, summary) == n
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = read_run(killed)
    assert not rec.truncated
    for k in ("cycle", "q", "dq", "tau_ref", "q_ref"):
        assert np.array_equal(getattr(rec, k), getattr(cut, k))
    assert rec.metadata["payload"] == {"mass_kg": "3.5", "arm_m": "1.2"}
    assert rec.metadata["recovered"]["dropped_bytes"] == str(length // 2)
    if isinstance(_node_reader(), Path):  # where node runs, Foxglove's reader too
        got = _node_read(killed)
        assert got["messages"] == n and got["counts"] == counts


def test_recover_refuses_its_own_output_and_keeps_nothing_on_error(tmp_path):
    p = tmp_path / "r.mcap"
    _write(p, 200)
    with pytest.raises(Exception, match="another file"):
        recover_log(p, p)
    assert read_run(p).metadata["result"]["status"] == "done"
    (tmp_path / "r.mcap.orig").write_bytes(b"")
    assert main(["recover", str(p)]) == 2
    assert read_run(p).metadata["result"]["status"] == "done"  # untouched


def test_recover_a_file_of_the_mcap_library_writer_cut_short(tmp_path):
    """Schemas and channels inside chunks (the library's writer puts them there) reach the
    summary of the recovered file."""
    p = tmp_path / "lib.mcap"
    with open(p, "wb") as f:
        w = Writer(f, chunk_size=2000, compression=CompressionType.ZSTD)
        w.start()
        sid = w.register_schema("s", "jsonschema", b"{}")
        cid = w.register_channel("/a", "json", sid)
        for k in range(300):
            w.add_message(cid, 1000 + k, json.dumps({"k": k}).encode(), 1000 + k, k)
        w.finish()
    with open(p, "rb") as f:
        summary = make_reader(f).get_summary()
    last = max(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(p.read_bytes()[: last.chunk_start_offset + 20])
    res = recover_log(cut, tmp_path / "rec.mcap")
    n_kept = 300 - sum(1 for _ in range(last.message_start_time, last.message_end_time + 1))
    assert res.messages == n_kept and res.chunks == len(summary.chunk_indexes) - 1
    n, counts, rec_summary = _indexed_read(res.path)
    assert n == n_kept and counts == {"/a": n_kept}
    assert [c.topic for c in rec_summary.channels.values()] == ["/a"]


@pytest.mark.parametrize("cut", ["closing magic", "summary"])
def test_closed_log_without_usable_summary_is_read_to_its_data_end(tmp_path, cut):
    """A copy that lost its tail after the data end (or a damaged footer) loses nothing."""
    p = tmp_path / "r.mcap"
    _write(p, 600)
    data = p.read_bytes()
    summary_start = struct.unpack_from("<Q", data, len(data) - 8 - 20)[0]  # footer field
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(data[:-8] + bytes(8) if cut == "closing magic" else data[:summary_start + 5])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        a = read_run(bad)
    assert np.array_equal(a.cycle, np.arange(600)) and not a.truncated
    assert a.metadata["result"]["status"] == "done"
