"""``daq.export.export_can``: the raw CAN frames of a real run log, written with python-can's
writers and read back with python-can's readers frame for frame; replayed by
``python -m can.player`` in another process."""

from __future__ import annotations

import gzip
import subprocess
import sys
import time

import can
import numpy as np
import pytest
from damaged_logs import damage_chunk
from test_daq_run import small_campaign

from daq.protocol.export import ExportError, export_can
from daq.protocol.reader import read_frames
from daq.runtime.runner import run_campaign
from sim_drivers.bridge import Bridge
from sim_drivers.plant_config import default_plant

# (extension, relative-time tolerance [s], absolute-time tolerance [s]) — the formats'
# resolutions (daq/export.py): 1 ns BLF, 1 us ASC/TRC/candump, full float CSV; ASC, BLF and TRC
# store the start time to about 1 ms.
FORMATS = [(".blf", 1e-6, 1e-3), (".asc", 1.01e-6, None), (".log", 1.01e-6, 1.01e-6),
           (".csv", 1e-9, 1e-9), (".trc", 1.01e-6, 1e-3), (".log.gz", 1.01e-6, 1.01e-6)]


@pytest.fixture(scope="module")
def run_log(tmp_path_factory):
    out = tmp_path_factory.mktemp("export")
    c = small_campaign(n_payloads=1, periods=1, freq=1.0, amplitude=0.1)
    r = run_campaign(c, out_dir=out, simulate=default_plant(), yes=True)
    assert r.ok, r.reason
    return r.runs[0].path


@pytest.mark.parametrize(("ext", "rel_tol", "abs_tol"), FORMATS)
def test_round_trip_frame_for_frame(run_log, tmp_path, ext, rel_tol, abs_tol):
    frames = read_frames(run_log)
    assert frames.shape[0] > 4 * 2000  # SYNC + RPDO + 2 TPDOs per cycle, heartbeats
    res = export_can(run_log, tmp_path / f"trace{ext}")
    assert res.path.is_file() and res.frames == frames.shape[0]
    assert not list(tmp_path.glob(".part-*"))
    back = list(can.LogReader(res.path))
    assert len(back) == frames.shape[0]
    order = np.argsort(frames["timestamp"], kind="stable")
    want = frames[order]
    assert [m.arbitration_id for m in back] == want["id"].tolist()
    assert [m.dlc for m in back] == want["dlc"].tolist()
    assert all(bytes(m.data) == bytes(want["data"][k][:want["dlc"][k]])
               for k, m in enumerate(back))
    assert not any(m.is_extended_id or m.is_remote_frame or m.is_error_frame for m in back)
    t = np.array([m.timestamp for m in back])
    t0 = want["timestamp"]
    assert np.max(np.abs((t - t[0]) - (t0 - t0[0]))) <= rel_tol
    if abs_tol is not None:
        assert np.max(np.abs(t - t0)) <= abs_tol
    assert np.all(np.diff(t) >= 0)  # time order
    if ext in (".blf", ".asc", ".trc"):  # formats that keep the direction
        tx = {m.arbitration_id for m in back if not m.is_rx}
        assert tx == {0x80, 0x201}
        assert res.transmitted == int(np.isin(want["id"], [0x80, 0x201]).sum())
    if ext.endswith(".gz"):
        with gzip.open(res.path, "rt") as f:
            assert f.readline().startswith("(")  # candump -l line, compressed


def test_asc_absolute_start_within_a_millisecond(run_log, tmp_path):
    res = export_can(run_log, tmp_path / "trace.asc")
    with can.ASCReader(res.path, relative_timestamp=False) as r:
        first = next(iter(r))
    assert abs(first.timestamp - res.first_s) < 1e-3


def test_player_replays_the_export_in_another_process(run_log, tmp_path):
    """``python -m can.player`` (a subprocess) replays the BLF export through a
    python-can-remote bridge on 127.0.0.1 into a virtual bus of this process."""
    res = export_can(run_log, tmp_path / "trace.blf")
    want = [m for m in can.LogReader(res.path)]
    channel = "export_replay"
    server = Bridge(0, channel=channel, interface="virtual").start()
    bus = can.Bus(interface="virtual", channel=channel)
    got: list[can.Message] = []
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", "can.player", "-i", "remote", "-c", server.url,
             str(res.path)],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            end = time.monotonic() + 60.0
            while len(got) < len(want) and time.monotonic() < end:
                m = bus.recv(0.5)
                if m is not None:
                    got.append(m)
            _, err = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(5)
    finally:
        bus.shutdown()
        server.close()
    assert proc.returncode == 0, err
    assert [(m.arbitration_id, bytes(m.data)) for m in got] == [
        (m.arbitration_id, bytes(m.data)) for m in want]
    # (a lockstep log runs faster than real time, so its pace says little: not checked)


def test_truncated_log_exports_what_was_written(run_log, tmp_path):
    raw = run_log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(raw[: len(raw) * 2 // 3])
    with pytest.warns(RuntimeWarning, match="cut.mcap: log cut short or damaged"):
        res = export_can(cut, tmp_path / "cut.log")
    full = read_frames(run_log)
    assert 0 < res.frames < full.shape[0]
    back = list(can.LogReader(res.path))
    assert len(back) == res.frames
    # the frames of the complete chunks are the first ones of the full log
    want = np.sort(full["timestamp"][: res.frames])
    assert np.allclose([m.timestamp for m in back], want, rtol=0, atol=1.01e-6)


def test_damaged_middle_chunk_exports_every_other_chunk(run_log, tmp_path):
    """A damaged chunk costs its own frames only: the chunks after it are exported too."""
    bad = damage_chunk(run_log, tmp_path / "bad.mcap")
    with pytest.warns(RuntimeWarning, match="damaged"):
        kept = read_frames(bad)
    with pytest.warns(RuntimeWarning, match="bad.mcap: log cut short or damaged"):
        res = export_can(bad, tmp_path / "bad.log")
    full = read_frames(run_log)
    assert res.frames == kept.shape[0] < full.shape[0]
    back = list(can.LogReader(res.path))
    assert len(back) == res.frames
    # frames logged after the damaged chunk are in the export
    assert max(m.timestamp for m in back) >= np.max(full["timestamp"]) - 1.01e-6


@pytest.mark.parametrize(("name", "match"), [
    ("out.mf4", r"out.mf4: expected an output file ending in .blf, .asc, .log, .csv, .trc"),
    ("out", r"out: expected an output file ending in .* got 'no extension'"),
    ("out.blf.gz", r"out.blf.gz: expected one of .* got .blf.gz"),
])
def test_bad_output_name_is_one_line_and_writes_nothing(run_log, tmp_path, name, match):
    with pytest.raises(ExportError, match=match):
        export_can(run_log, tmp_path / name)
    assert list(tmp_path.iterdir()) == []


def test_not_a_run_log(tmp_path):
    with pytest.raises(ExportError, match=r"nope.mcap: expected a jointid run log"):
        export_can(tmp_path / "nope.mcap", tmp_path / "x.blf")
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    with pytest.raises(ExportError, match=r"bad.mcap: expected a jointid run log"):
        export_can(bad, tmp_path / "x.blf")
    assert not (tmp_path / "x.blf").exists()


def test_jointid_export_subcommand(run_log, tmp_path, capsys):
    from daq.app.cli import main

    out = tmp_path / "cli.asc"
    assert main(["export", str(run_log), "--can", str(out)]) == 0
    line = capsys.readouterr().out.strip()
    n = read_frames(run_log).shape[0]
    assert line.startswith(f"export: {n} CAN frames (") and line.endswith(f"-> {out}")
    assert len(list(can.LogReader(out))) == n
    # bad input: one line on stderr naming the file and what was expected, exit 2, no file
    assert main(["export", str(run_log), "--can", str(tmp_path / "x.pcap")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("jointid export: error: ")
    assert "x.pcap: expected an output file ending in .blf" in err[0]
    assert not (tmp_path / "x.pcap").exists()
    assert main(["export", str(tmp_path / "none.mcap"), "--can", str(tmp_path / "y.blf")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "none.mcap: expected a jointid run log" in err[0]


@pytest.mark.parametrize("suffix", [".asc", ".asc.gz"])
@pytest.mark.parametrize("ms", [0.004, 0.022, 0.5])
def test_asc_start_date_keeps_milliseconds_below_100(tmp_path, suffix, ms):
    """python-can writes the start date's milliseconds unpadded (22 ms -> ".22", read back as
    220 ms); the exporter's ASC writer pads them."""
    from daq.protocol.export import _open_writer

    t0 = 1_795_385_585.0 + ms
    path = tmp_path / f"one{suffix}"
    w = _open_writer(path)
    w.on_message_received(can.Message(timestamp=t0, arbitration_id=0x181, is_extended_id=False,
                                      dlc=2, data=b"\x01\x02", channel=1))
    w.stop()
    f = gzip.open(path, "rt") if suffix.endswith(".gz") else path
    with can.ASCReader(f, relative_timestamp=False) as r:
        first = next(iter(r))
    assert abs(first.timestamp - t0) < 1e-3
