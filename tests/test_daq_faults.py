"""Faults: the runner stops motion within a bounded number of cycles, keeps a readable log
and names the cause (simulated drive's fault injector, limits, SIGINT, SIGKILL)."""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from daq_campaigns import joint_campaign

from daq.protocol.cia402 import State, state_from_statusword
from daq.protocol.reader import read_run
from daq.runtime.runner import run_campaign
from sim_drivers.faults import FaultInjector
from sim_drivers.plant_config import default_plant

ROOT = Path(__file__).resolve().parents[1]
_chan = itertools.count()
QS = 2  # daq.quick_stop_cycles used below


def campaign(daq=None, periods=2):
    return joint_campaign(
        "faulty", cycle_s=0.001, payload_masses=(0.0, 3.0),
        sine={"amplitude": 0.3, "frequency_hz": 0.5, "periods": periods},
        daq={"channel": f"test_faults_{next(_chan)}", "quick_stop_cycles": QS, **(daq or {})})


def check_stopped(result, reason_part):
    """One stopped run, its log readable up to the stop, and the drive's own record shows
    quick stop within 2 cycles of the detection and SWITCH ON DISABLED within QS + 2."""
    assert result.status == "stopped"
    assert reason_part in result.reason
    assert len(result.runs) == 1  # the campaign does not go on to the next payload
    run = result.runs[0]
    a = read_run(run.path)
    assert not a.truncated and a.metadata["result"]["status"] == "stopped"
    assert reason_part in a.metadata["result"]["reason"]
    assert np.array_equal(a.cycle, np.arange(len(a)))
    assert any(reason_part in e["message"] for e in a.events)
    f = run.fault_cycle
    assert 0 < f < len(a)
    rec = result.sim_records[0]
    c0 = int(a.metadata["result"]["sync_offset"])
    states = [state_from_statusword(int(s)) for s in rec["statusword"]]
    cyc = rec["cycle"]
    after = [s for c, s in zip(cyc, states, strict=True) if c >= c0 + f + 2]
    assert after and State.OPERATION_ENABLED not in after
    off = (State.SWITCH_ON_DISABLED, State.FAULT)
    first_off = next(c for c, s in zip(cyc, states, strict=True) if c >= c0 + f and s in off)
    assert first_off <= c0 + f + QS + 2
    assert all(s in off for c, s in zip(cyc, states, strict=True) if c >= first_off)
    assert run.stop_cycle != -1 and run.stop_cycle - f <= QS + 1 + 5
    return a, run


def test_emcy_mid_segment(tmp_path):
    inj = FaultInjector(fault_at_cycle=1500)
    r = run_campaign(campaign(), out_dir=tmp_path, simulate=default_plant(), yes=True,
                     fault_injectors={1: inj})
    a, run = check_stopped(r, "EMCY 0xFF01")
    assert r.reason.startswith("node 1: EMCY 0xFF01")
    assert abs(run.fault_cycle - 1500) <= 1


def test_heartbeat_loss(tmp_path):
    inj = FaultInjector(stop_heartbeat_at_cycle=300)
    r = run_campaign(campaign({"heartbeat_timeout_s": 0.3}, periods=6), out_dir=tmp_path,
                     simulate=default_plant(), yes=True, fault_injectors={1: inj})
    check_stopped(r, "heartbeat lost")


def test_tpdos_dropped_for_k_cycles(tmp_path):
    inj = FaultInjector(drop_tpdo_from_cycle=800, drop_tpdo_cycles=6)
    r = run_campaign(campaign({"tpdo_timeout_cycles": 3, "lockstep_wait_s": 0.02}),
                     out_dir=tmp_path, simulate=default_plant(), yes=True,
                     fault_injectors={1: inj})
    a, run = check_stopped(r, "TPDO missing for 3 cycles")
    assert run.fault_cycle == 800 + 2  # the third consecutive cycle without TPDO
    assert np.all(a.flags[800:803] & 1)  # logged, flagged as missing


def test_limit_violation(tmp_path):
    r = run_campaign(campaign({"limits": {"max_velocity": 0.5}}), out_dir=tmp_path,
                     simulate=default_plant(), yes=True)
    a, run = check_stopped(r, "velocity limit")
    assert np.max(np.abs(a.dq[: run.fault_cycle])) <= 0.5  # the first violation is the stop


@pytest.mark.slow  # a jointid subprocess
def test_limit_violation_cli_exit_code(tmp_path):
    toml = _write_campaign(tmp_path, periods=2, extra="[daq.limits]\nmax_velocity = 0.5\n")
    p = subprocess.run(_cli(toml, tmp_path / "out"), capture_output=True, text=True,
                       timeout=120, env=_env())
    assert p.returncode == 3, p.stderr
    assert "stopped: node 1: velocity limit" in p.stderr


def _write_campaign(tmp_path, periods, extra=""):
    text = f"""
name = "long"
[joint]
kind = "revolute"
[joint.limits]
position = [-1.0, 1.0]
max_velocity = 1.0
max_acceleration = 4.0
max_jerk = 40.0
max_torque = 700.0
[control]
cycle_s = 0.001
kp = 6000.0
kd = 200.0
[control.feedforward]
J = 30.0
MX = 21.0
[[payloads]]
mass_kg = 0.0
arm_m = 1.0
[[payloads]]
mass_kg = 3.0
arm_m = 1.0
[[segments]]
kind = "sine"
amplitude = 0.3
frequency_hz = 0.5
center = 0.0
periods = {periods}
[daq]
chunk_seconds = 0.1
{extra}"""
    path = tmp_path / "long.toml"
    path.write_text(text)
    return path


def _cli(toml, out):
    plant = ROOT / "sim_drivers" / "data" / "plant_default.toml"
    return [sys.executable, "-c", "import sys; from daq.app.cli import main; sys.exit(main())",
            "run", str(toml), "--simulate", str(plant), "--out", str(out), "--yes"]


def _env():
    env = dict(os.environ)
    env["OPENBLAS_NUM_THREADS"] = "1"
    env["PYTHONPATH"] = str(ROOT)
    return env


def _start_and_wait_for_log(tmp_path, min_bytes):
    toml = _write_campaign(tmp_path, periods=40)
    out = tmp_path / "out"
    proc = subprocess.Popen(_cli(toml, out), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=_env())
    log = out / "long_payload0.mcap"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if log.exists() and log.stat().st_size > min_bytes:
            return proc, log, out
        if proc.poll() is not None:
            break
        time.sleep(0.02)
    proc.kill()
    pytest.fail(f"runner did not write {min_bytes} bytes: {proc.communicate()[1][-2000:]}")


@pytest.mark.slow  # a jointid subprocess
def test_sigint_stops_and_keeps_a_complete_log(tmp_path):
    proc, log, out = _start_and_wait_for_log(tmp_path, 100_000)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "interrupted" in err
    a = read_run(log)
    assert not a.truncated and a.metadata["result"]["status"] == "interrupted"
    assert np.array_equal(a.cycle, np.arange(len(a)))
    assert any(e["message"] == "drives disabled" for e in a.events)
    assert state_from_statusword(int(a.statusword[-1])) is State.SWITCH_ON_DISABLED
    assert not (out / "long_payload1.mcap").exists()
    # the identification says so (a stranger's interrupted log was fitted in silence)
    from ident.api import load

    with pytest.warns(UserWarning, match=r"long_payload0\.mcap: the run did not finish "
                      r"\(interrupted"):
        load([log])


@pytest.mark.slow  # a jointid subprocess
def test_sigkill_leaves_a_readable_log_up_to_the_last_chunk(tmp_path):
    proc, log, out = _start_and_wait_for_log(tmp_path, 300_000)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    size = log.stat().st_size
    with pytest.warns(RuntimeWarning, match="truncated run log"):
        a = read_run(log)
    assert a.truncated
    # every complete chunk is read: chunks of ~0.1 s of data (100 cycles) of ~15-40 kB
    assert len(a) >= 100 * (size // 60_000) - 100
    assert np.array_equal(a.cycle, np.arange(len(a)))
    assert a.payload_mass_kg == 0.0
    assert not (out / "long.state.json").exists()  # payload 0 never completed


@pytest.mark.parametrize("k", [1, 2, 3, 4])
def test_tpdo_missing_while_enabling_does_not_undo_the_enable(tmp_path, k):
    """A TPDO lost during the enable sequence (cycle k): the master repeats the command the
    drive already has instead of stepping from a stale state (0x06 "shutdown" to a drive
    that just reached OPERATION ENABLED would send it back to READY TO SWITCH ON)."""
    inj = FaultInjector(drop_tpdo_from_cycle=k, drop_tpdo_cycles=1)
    r = run_campaign(campaign({"tpdo_timeout_cycles": 3, "lockstep_wait_s": 0.02}),
                     out_dir=tmp_path, simulate=default_plant(), yes=True,
                     fault_injectors={1: inj})
    assert r.ok, r.reason
    rec = r.sim_records[0]
    states = [state_from_statusword(int(s)) for s in rec["statusword"]]
    first_oe = states.index(State.OPERATION_ENABLED)
    # once enabled, the drive stays enabled until the normal shutdown at the end of payload 0
    left = next(i for i in range(first_oe, len(states))
                if states[i] is not State.OPERATION_ENABLED)
    assert left >= r.runs[0].cycles - 4, (first_oe, left, states[first_oe:left + 3])
