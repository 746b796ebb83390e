"""MCAP run log writer/reader, bus-load arithmetic, [daq] validation, paced clock."""

from __future__ import annotations

import io
import struct
import warnings

import numpy as np
import pytest
from daq_campaigns import sine_campaign
from mcap.reader import make_reader

from daq import ConfigError
from daq.protocol.logformat import FRAME, STATE_SIZE
from daq.protocol.reader import LogReadError, list_runs, read_frames, read_run
from daq.runtime.busload import check_load, cycle_load, frame_bits
from daq.runtime.config import parse_daq
from daq.runtime.mcaplog import RunLog
from daq.runtime.progress import ProgressLine


# ----------------------------------------------------------------------------- bus load
def test_frame_bits_worst_case_stuffing():
    assert frame_bits(0) == 55  # SYNC
    assert frame_bits(8) == 135  # 111 unstuffed + 24 stuff bits
    assert [frame_bits(n) for n in range(9)] == [
        47 + 8 * n + (34 + 8 * n - 1) // 4 for n in range(9)]
    with pytest.raises(ValueError):
        frame_bits(9)


def test_cycle_load_and_refusal():
    # one CST drive: SYNC + RPDO(4) + TPDO(8) + TPDO(5)
    load = cycle_load([(4, 8, 5)], 0.001, 1_000_000)
    assert load.frames_per_cycle == 4
    assert load.bits_per_cycle == 55 + 95 + 135 + 105
    assert load.share == pytest.approx(0.390)
    check_load(load, 0.6)
    with pytest.raises(ConfigError, match=r"c.toml: daq.max_bus_load: .*39.0 % .*> allowed 30 %"):
        check_load(load, 0.3, "c.toml")


# ------------------------------------------------------------------------------- config
def test_daq_defaults_and_errors(tmp_path):
    cfg = parse_daq({})
    assert cfg.interface == "virtual" and cfg.clock == "lockstep"
    assert len(cfg.drives) == 1 and cfg.drives[0].node_id == 1
    assert cfg.torque_delay_cycles == 1.5  # synchronous RPDO actuated at the next SYNC
    with pytest.raises(ConfigError, match=r"c.toml: daq.torque_delay_cycles: expected"):
        parse_daq({"torque_delay_cycles": -1.0}, "c.toml")
    assert cfg.drives[0].eds.name == "jointid_cia402.eds" and cfg.drives[0].mode_name == "cst"
    with pytest.raises(ConfigError, match=r"c.toml: daq.drives\[0\].mode: expected one of"):
        parse_daq({"drives": [{"node_id": 1, "mode": "csv"}]}, "c.toml")
    with pytest.raises(ConfigError, match=r"c.toml: daq.drives\[1\].node_id: expected a unique"):
        parse_daq({"drives": [{"node_id": 1}, {"node_id": 1}]}, "c.toml")
    with pytest.raises(ConfigError, match=r"daq.drives\[0\].eds: expected an EDS/DCF file"):
        parse_daq({"drives": [{"node_id": 1, "eds": "nope.eds"}]}, str(tmp_path / "c.toml"))
    with pytest.raises(ConfigError, match="daq.clock: expected 'paced' on a real interface"):
        parse_daq({"interface": "socketcan", "clock": "lockstep"}, "c.toml")
    assert parse_daq({"interface": "socketcan", "channel": "can0"}).clock == "paced"
    cfg = parse_daq({"drives": [{"node_id": 3, "scaling": {
        "rated_torque_Nm": 5.0, "gear_ratio": 100.0, "encoder_counts_per_rev": 4096}}]})
    sc = cfg.drives[0].scaling
    assert sc.torque_per_unit == pytest.approx(0.5)
    assert sc.rad_per_count == pytest.approx(2 * np.pi / 409600)


# ---------------------------------------------------------------------------------- MCAP
def _write(path, n, chunk_seconds=0.05, close=True):
    log = RunLog(path, n_axes=2, cycle_s=0.001, chunk_seconds=chunk_seconds,
                 metadata={"payload": {"mass_kg": "3.5", "arm_m": "1.2"},
                           "campaign": {"joint_kind": "revolute"}},
                 attachments=[("c.toml", "application/toml", b"name = 'x'\n")])
    fr = FRAME.pack(1.5, 0x80, 0, b"") + FRAME.pack(1.5, 0x201, 4, b"\x0f\x00\x10\x00")
    for c in range(n):
        for ax in range(2):
            log.state(ax, c, c * 1e-3, 0.001 * c + ax, -0.5 * c, 2.0 * c, 3.0, c * 7 + ax,
                      -c, c % 1000, -(c % 1000), 0x1237, c & 1)
        log.setpoint(c, c * 1e-3, 0.002 * c, 0.1, 0.2, c // 100, 0)
        log.frames(c, fr, 2)
    log.event(10, 0.01, "fault", "node 1: EMCY 0xFF01", 0)
    if close:
        log.close({"status": "done"})
    return log


def test_state_record_round_trip(tmp_path):
    p = tmp_path / "r_payload0.mcap"
    _write(p, 1000)
    for ax in range(2):
        a = read_run(p, axis=ax)
        c = np.arange(1000)
        assert np.array_equal(a.cycle, c) and a.cycle.dtype == np.int64
        assert np.array_equal(a.q, 0.001 * c + ax)
        assert np.array_equal(a.dq, -0.5 * c)
        assert np.array_equal(a.tau_ref, 2.0 * c)
        assert np.array_equal(a.counts, c * 7 + ax)
        assert np.array_equal(a.statusword, np.full(1000, 0x1237))
        assert np.array_equal(a.flags, c & 1)
        assert np.array_equal(a.q_ref, 0.002 * c) and np.array_equal(a.segment, c // 100)
        assert a.payload_mass_kg == 3.5 and a.payload_arm_m == 1.2 and a.revolute
        assert a.events == [{"t": 0.01, "cycle": 10, "kind": "fault", "axis": 0,
                             "message": "node 1: EMCY 0xFF01"}]
        assert a.metadata["result"]["status"] == "done" and not a.truncated
    with pytest.raises(LogReadError, match=r"no channel /joint/2/state"):
        read_run(p, axis=2)


def test_log_is_standard_mcap_with_viewer_schemas(tmp_path):
    """The mcap library reads every message; schemas are ros2msg/cdr and jsonschema/json."""
    p = tmp_path / "r.mcap"
    _write(p, 300)
    with open(p, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        topics = {ch.topic: (ch.message_encoding, summary.schemas[ch.schema_id])
                  for ch in summary.channels.values()}
        assert topics["/joint/0/state"][0] == "cdr"
        assert topics["/joint/0/state"][1].encoding == "ros2msg"
        assert topics["/events"][0] == "json"
        assert topics["/events"][1].encoding == "jsonschema"
        assert summary.statistics.message_count == 300 * 4 + 1
        assert summary.statistics.chunk_count > 1  # chunked (~50 ms of data per chunk)
        states = [m for _, ch, m in reader.iter_messages(topics=["/joint/1/state"])]
        assert len(states) == 300 and all(len(m.data) == STATE_SIZE for m in states)
        # CDR little endian header, then float64 t, int64 cycle, float64 q
        hdr, t, cyc, q = struct.unpack_from("<4sdqd", states[5].data)
        assert hdr == b"\x00\x01\x00\x00" and cyc == 5 and q == pytest.approx(1.005)
        assert states[5].log_time - states[4].log_time == 1_000_000  # integer ns per cycle
        names = {a.name for a in reader.iter_attachments()}
        assert names == {"c.toml"}
        md = {m.name: m.metadata for m in reader.iter_metadata()}
        assert md["payload"]["mass_kg"] == "3.5"
    frames = read_frames(p)
    assert len(frames) == 600 and frames["id"][1] == 0x201
    assert frames["data"][1].tolist() == [0x0F, 0, 0x10, 0, 0, 0, 0, 0]


def test_truncated_log_reads_complete_chunks_and_warns(tmp_path):
    p = tmp_path / "r.mcap"
    _write(p, 2000)
    data = p.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.warns(RuntimeWarning, match="truncated run log"):
        a = read_run(cut)
    assert a.truncated and 0 < len(a) < 2000
    assert np.array_equal(a.cycle, np.arange(len(a)))
    assert np.array_equal(a.q, 0.001 * np.arange(len(a)))


def test_unclosed_writer_file_is_readable_up_to_the_last_chunk(tmp_path):
    """What a killed process leaves: chunks flushed as they fill, no summary."""
    p = tmp_path / "open.mcap"
    log = _write(p, 1000, close=False)
    log._file.flush()
    raw = p.read_bytes()
    log.close()
    cut = tmp_path / "killed.mcap"
    cut.write_bytes(raw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        a = read_run(cut)
    assert a.truncated
    assert 1000 - 100 <= len(a) < 1000  # at most one chunk (~50 cycles here) lost


def test_not_mcap_and_list_runs(tmp_path):
    bad = tmp_path / "x_payload0.mcap"
    bad.write_bytes(b"hello world, not mcap at all")
    with pytest.raises(LogReadError, match=r"x_payload0.mcap: not an MCAP file"), \
            warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # said once, not as a truncated log
        read_run(bad)
    for k in (10, 2):
        (tmp_path / f"x_payload{k}.mcap").write_bytes(b"")
    assert [p.name for p in list_runs(tmp_path)] == [
        "x_payload0.mcap", "x_payload2.mcap", "x_payload10.mcap"]


def test_progress_line():
    out = io.StringIO()
    bar = ProgressLine(out, width=10, quiet_interval_s=0.0)
    bar.update(0.5, "payload 1/3")
    bar.close()
    assert out.getvalue() == "[#####.....]  50.0% payload 1/3\n"


# ---------------------------------------------------------------------------- paced clock

@pytest.mark.parametrize("source", ["runner", "periodic"])
def test_paced_clock_records_timing_of_every_cycle(tmp_path, source):
    from daq.runtime.runner import run_campaign
    from sim_drivers.plant_config import default_plant

    c = sine_campaign("paced", clock="paced", sync_source=source)
    r = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True)
    assert r.status == "done", r.reason
    run = r.runs[0]
    assert run.lateness_s.shape == (run.cycles,)
    if source == "runner":
        assert np.all(run.lateness_s >= 0)  # the runner never sends a SYNC early
    a = read_run(run.path)
    assert np.array_equal(a.cycle, np.arange(run.cycles))
    assert a.metadata["campaign"]["clock"] == "paced"
    # the simulated single-joint drive's own timing, not the [daq] default for hardware
    assert float(a.metadata["campaign"]["torque_delay_cycles"]) == 0.5
    with open(run.path, "rb") as f:
        timing = [m for _, _, m in make_reader(f).iter_messages(topics=["/timing"])]
    assert len(timing) == run.cycles
    lat = [struct.unpack_from("<qdd", m.data, 4)[2] for m in timing]
    assert np.allclose(lat, run.lateness_s)


def test_campaign_names_become_safe_file_stems():
    from daq.runtime.runner import file_stem

    assert file_stem("rx130l-joint3 (quick)") == "rx130l-joint3_quick"
    assert file_stem("a/b\\c") == "a_b_c"
    assert file_stem("???") == "campaign"
