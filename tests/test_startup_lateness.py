"""The start-up lateness check: before the plan moves, the drives enabled and holding, the
master counts per drive the cycles whose answer was missing at the deadline or came with an
older one, and refuses to start (drives disabled, log closed) above ``[daq] lateness_stop``,
warns above ``lateness_warn``.

The bus tests run the real master in lockstep (``lateness_check_s`` given: left out, lockstep
has no check) against a simulated drive whose fault injector makes its answers late or lost
on drawn cycles, so that what the check must measure is known: a late answer is one cycle
without an answer and one with two (``FaultInjector.late_tpdo_*``), a lost one a cycle without.
"""

from __future__ import annotations

import itertools
import os
import re

import numpy as np
import pytest
from daq_campaigns import joint_campaign

from daq.protocol.reader import read_run
from daq.runtime.config import parse_daq
from daq.runtime.runner import run_campaign
from daq.runtime.safety import lateness_verdict
from sim_drivers.faults import FaultInjector
from sim_drivers.plant_config import default_plant

_chan = itertools.count()
CHECK_S = 0.3  # [s] the hold: 300 cycles at 1 ms


def _run(out_root, inj: FaultInjector | None, **daq):
    """A lockstep run (1 ms, 2 kg at 1 m, a 0.1 rad 1 Hz sine) with the start-up check of
    CHECK_S and the drive's fault injector ``inj``: (result, its log)."""
    c = joint_campaign(
        "chk", cycle_s=0.001, sine={"amplitude": 0.1, "frequency_hz": 1.0, "periods": 1},
        payload_masses=(2.0,),
        daq={"channel": f"chk_{os.getpid()}_{next(_chan)}", "lockstep_wait_s": 0.02,
             "lateness_check_s": CHECK_S, **daq})
    r = run_campaign(c, out_dir=out_root / f"run{next(_chan)}", simulate=default_plant(),
                     yes=True, fault_injectors={1: inj} if inj else None)
    return r, read_run(r.runs[0].path)


def _check_event(a) -> tuple[int, float]:
    """(cycle of the check's info event, the share it names for node 1)."""
    ev = [e for e in a.events if e["message"].startswith("start-up lateness check: late")]
    assert len(ev) == 1, a.events
    return ev[0]["cycle"], float(re.search(r"node 1 ([\d.]+)%", ev[0]["message"])[1]) / 100


def test_an_idle_bus_starts_without_a_warning(tmp_path):
    """No late answer: 0 % measured, no warning, the plan runs after the hold."""
    r, a = _run(tmp_path, None)
    assert r.status == "done", r.reason
    cyc, share = _check_event(a)
    assert share == 0.0
    assert not any(e["kind"] == "warning" for e in a.events)
    assert not any("lateness" in n for n in r.notes)
    seg = np.asarray(a.segment)
    assert np.flatnonzero(seg >= 0)[0] >= cyc  # the plan moved after the check


def test_lost_answers_within_the_soft_limit_warn(tmp_path):
    """One answer in 8 lost: the check measures exactly that share (every cycle of the hold
    counted once) and the run goes on with a warning naming the bus, in the log and in the
    summary."""
    inj = FaultInjector(drop_tpdo_from_cycle=0, drop_tpdo_cycles=1, drop_tpdo_period=8)
    r, a = _run(tmp_path, inj)
    assert r.status == "done", r.reason
    cyc, share = _check_event(a)
    n = round(CHECK_S / 0.001)
    start = cyc - n  # the hold's first cycle (drive cycle = master cycle + offset)
    off = int(a.metadata["result"]["sync_offset"])
    expect = sum(inj.drop_tpdo(k + off) for k in range(start, cyc)) / n
    assert share == pytest.approx(expect, abs=0.0006)
    warn = [e["message"] for e in a.events if e["kind"] == "warning"]
    assert len(warn) == 1 and "above daq.lateness_warn" in warn[0], warn
    assert re.search(r"bus chk_\d+_\d+: 12\.\d% of the drives' answers", warn[0]), warn[0]
    assert any("start-up lateness check" in n for n in r.notes), r.notes


@pytest.mark.parametrize("seed", [1, 2])
def test_late_answers_beyond_the_limit_refuse_to_start(tmp_path, seed):
    """30 % of the answers late (runs of one): each is a cycle without an answer and one
    with two, about 60 % measured, as the drawn cycles say: the run is refused in one line
    naming the bus and the share, the plan never moved, the drives were disabled and the
    log is closed and readable."""
    inj = FaultInjector(late_tpdo_from_cycle=0, late_tpdo_cycles=100000, late_tpdo_share=0.3,
                        late_tpdo_run=1, late_tpdo_seed=seed)
    r, a = _run(tmp_path, inj)
    assert r.status == "stopped"
    assert "\n" not in r.reason
    assert r.reason.startswith("start-up lateness check: bus chk_"), r.reason
    assert "above daq.lateness_stop (30%)" in r.reason
    cyc, share = _check_event(a)
    n = cyc - int(re.search(r"over the (\d+) cycles", r.reason)[1])
    off = int(a.metadata["result"]["sync_offset"])
    late = inj.late_cycles
    expect = sum((k + off in late) + (k + off - 1 in late) for k in range(n, cyc)) / (cyc - n)
    assert share == pytest.approx(expect, abs=0.0006)
    assert f"{100 * share:.1f}%" in r.reason
    assert not (np.asarray(a.segment) >= 0).any()  # the plan never moved
    assert r.runs[0].stop_cycle >= 0  # the drives confirmed the stop (disabled)
    assert a.metadata["result"]["status"] == "stopped"


def test_verdict_takes_the_worst_bus_and_measures_longer_near_the_limit():
    cfg = parse_daq({"lateness_warn": 0.02, "lateness_stop": 0.1})  # not the defaults
    names = ["node 1", "node 2", "node 3"]
    buses = ["can0", "can0", "can1"]
    assert lateness_verdict([0, 1, 2], 500, buses, names, cfg, 0.001)[0] == ""
    level, why, unsure = lateness_verdict([0, 0, 30], 500, buses, names, cfg, 0.001)
    assert level == "warning" and "bus can1: 6.0%" in why and not unsure
    level, why, unsure = lateness_verdict([200, 100, 0], 500, buses, names, cfg, 0.001)
    assert level == "stop" and "bus can0: 30.0%" in why and "node 1 40%" in why
    assert lateness_verdict([50, 50, 0], 500, buses, names, cfg, 0.001)[2]  # 10 %: unsure


@pytest.mark.parametrize("raw,msg", [
    ({"lateness_check_s": -1.0}, "daq.lateness_check_s: expected"),
    ({"lateness_stop": 1.5}, "daq.lateness_stop: expected"),
    ({"lateness_warn": 0.2, "lateness_stop": 0.1},
     "daq.lateness_warn: expected at most daq.lateness_stop (0.1), got 0.2"),
])
def test_bad_lateness_keys_are_one_line(raw, msg):
    from daq import ConfigError

    with pytest.raises(ConfigError) as e:
        parse_daq(raw, "c.toml")
    assert "\n" not in str(e.value) and str(e.value).startswith("c.toml: " + msg), str(e.value)


def test_the_check_follows_the_clock_unless_given():
    assert parse_daq({}).lateness_check_s == 0.0  # lockstep: no check, no hold
    assert parse_daq({"clock": "paced"}).lateness_check_s == 0.5
    assert parse_daq({"clock": "paced", "lateness_check_s": 0}).lateness_check_s == 0.0
