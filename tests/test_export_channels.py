"""CAN export channels (issue 23 item 2): the channel numbers each format defines (1-based in
ASC, BLF and TRC; the bus name in candump logs), one channel per bus of a robot run, the bus
names kept. Every frame read back with python-can's readers and compared -- channel, id,
data, time -- with what the log holds, routed to its bus independently of the exporter: by
the node id of its COB-ID and the campaign's drive table (SYNC on every bus)."""

from __future__ import annotations

import can
import numpy as np
import pytest
from robot_campaigns import arm3_campaign
from test_daq_run import small_campaign

from daq.app.cli import main
from daq.protocol.export import ExportError, export_can, read_log
from daq.protocol.reader import read_frames
from daq.runtime.runner import run_campaign
from sim_drivers.plant_config import default_plant
from sim_drivers.testing import unique_channel

# extension, time tolerance [s] relative to the first frame (the formats' resolutions)
FORMATS = [(".asc", 1.01e-6), (".blf", 1e-6), (".trc", 1.01e-6), (".log", 1.01e-6)]


@pytest.fixture(scope="module")
def single_bus_log(tmp_path_factory):
    out = tmp_path_factory.mktemp("single")
    c = small_campaign(n_payloads=1, periods=1, freq=1.0, amplitude=0.1)
    r = run_campaign(c, out_dir=out, simulate=default_plant(), yes=True)
    assert r.ok, r.reason
    return r.runs[0].path, {1: 0}


@pytest.fixture(scope="module")
def three_bus_log(tmp_path_factory):
    """A 3-dof arm with one joint per bus (node ids 1, 2, 3)."""
    out = tmp_path_factory.mktemp("three")
    buses = (unique_channel("bus_a"), unique_channel("bus_b"), unique_channel("bus_c"))
    segments = [{"kind": "multisine", "period_s": 1.0, "periods": 1, "harmonics": 2,
                 "fill": 0.5, "seed": 3}]
    c = arm3_campaign(buses=buses, segments=segments, payloads=[{"mass_kg": 0.0}])
    r = run_campaign(c, out_dir=out, simulate=True, yes=True)
    assert r.ok, r.reason
    return r.runs[0].path, {1: 0, 2: 1, 3: 2}, list(buses)


def _expected(path, node_bus: dict[int, int], n_buses: int):
    """(timestamp, id, data, bus index) of every frame of the log as it was on the wires."""
    fr = read_frames(path)
    fr = fr[np.argsort(fr["timestamp"], kind="stable")]
    out = []
    for f in fr:
        cid = int(f["id"])
        bus = node_bus.get(cid & 0x7F)
        for b in range(n_buses) if bus is None else (bus,):
            out.append((float(f["timestamp"]), cid, bytes(f["data"][: f["dlc"]]), b))
    return out


def _check(res, path, node_bus, names, ext, tol):
    want = _expected(path, node_bus, len(names))
    back = list(can.LogReader(res.path))
    assert res.frames == len(want) == len(back)
    # the channel each reader gives back for bus b, by the format's definition
    if ext in (".asc", ".blf"):
        chan = list(range(len(names)))          # file 1..n, python-can's readers: 0-based
    elif ext == ".trc":
        chan = list(range(1, len(names) + 1))   # file 1..n, read back as written
    else:
        chan = [n for n in names]               # candump: the interface (bus) name
    # within one timestamp the order of the buses is the exporter's: compare as multisets
    key = lambda x: (round(x[0], 5), x[1], x[2], str(x[3]))  # noqa: E731
    got = [(m.timestamp, m.arbitration_id, bytes(m.data), m.channel) for m in back]
    exp = [(t, i, d, chan[b]) for t, i, d, b in want]
    t_got = np.array([g[0] for g in got])
    t_exp = np.array([e[0] for e in exp])
    assert np.max(np.abs((t_got - t_got[0]) - (t_exp - t_exp[0]))) <= tol
    got = [(e[0], g[1], g[2], g[3]) for g, e in zip(got, exp, strict=True)]  # time checked
    assert sorted(got, key=key) == sorted(exp, key=key)
    assert [c for c, _ in res.channels] == (
        list(range(1, len(names) + 1)) if ext != ".log" else chan)
    assert [b for _, b in res.channels] == names


@pytest.mark.parametrize(("ext", "tol"), FORMATS)
def test_single_bus_run_on_channel_one(single_bus_log, tmp_path, ext, tol):
    path, node_bus = single_bus_log
    res = export_can(path, tmp_path / f"t{ext}")
    names = [read_log(path)[1]["drive0"]["channel"]]
    _check(res, path, node_bus, names, ext, tol)
    if ext == ".asc":  # the file itself says channel 1 (python-can's writer added 1 to it)
        rows = [ln.split() for ln in res.path.read_text().splitlines()]
        frames = [r for r in rows if len(r) > 3 and r[3] in ("Rx", "Tx")]
        assert len(frames) == res.frames and {f[1] for f in frames} == {"1"}


@pytest.mark.parametrize(("ext", "tol"), FORMATS)
def test_three_bus_robot_run_one_channel_per_bus(three_bus_log, tmp_path, ext, tol):
    path, node_bus, names = three_bus_log
    res = export_can(path, tmp_path / f"t{ext}")
    _check(res, path, node_bus, names, ext, tol)
    if ext == ".asc":  # bus names kept in the header comments
        text = res.path.read_text()
        for k, name in enumerate(names, 1):
            assert f"// jointid channel {k} = {name}" in text


def test_three_bus_run_refused_as_csv_and_mapping_printed(three_bus_log, tmp_path, capsys):
    path, _, names = three_bus_log
    with pytest.raises(ExportError, match="no channel column.*3 buses"):
        export_can(path, tmp_path / "t.csv")
    assert not list(tmp_path.iterdir())
    assert main(["export", str(path), "--can", str(tmp_path / "t.blf")]) == 0
    line = capsys.readouterr().out.strip()
    assert f"on channels 1 = {names[0]}, 2 = {names[1]}, 3 = {names[2]} ->" in line
