"""The bus or a drive gone while the runner winds down (left by the last session): the
runner watched the bus during a payload's run only. A bus that failed *between* payloads or
as the run wound down (an adapter unplugged, a bridge process gone) ended ``jointid run`` in a
python-can traceback (``CanOperationError`` out of the NMT start of the next payload, or of
the SDO that clears the drives' heartbeat consumer), leaving an empty
``<name>_payload<k>.mcap``; a drive that vanished after the last payload showed only as "no
SDO answer", nowhere kept. Now: a bus lost before a payload's run stops the campaign with
"bus lost before the run of payload K: ..." (nothing moved, no empty log left); a bus or
drive lost after the last log closed is a warning of the summary, recorded in the state
file's ``warnings_outside_logs`` (no log is open to hold it), saying that nothing the drives
sent since was seen. What the runner already did is proved here too: a bus lost or a drive
gone *during* a run stops it with its reason, the drives sent the stop sequence, the log
closed properly.

The drives are real simulated CiA 402 nodes on their own :class:`SimNetwork` (the campaign
runs as on hardware: no ``--simulate``), on simulated time (inline dispatch, clocked by the
master's SYNCs): every hook below runs in the master's own thread at a fixed frame, so
nothing depends on the machine's speed. "The bus gone" is the master's python-can bus shut
down under it (what an unplugged adapter does to a socketcan bus); "the drive gone" is the
simulated node stopped (heartbeat, PDOs, SDO server detached: a drive switched off)."""

from __future__ import annotations

import itertools
import json

import can
from daq_campaigns import joint_campaign

from daq.protocol.cia402 import State, state_from_statusword
from daq.protocol.reader import read_frames, read_run
from daq.runtime.runner import run_campaign
from sim_drivers.drive import SimulatedDrive
from sim_drivers.plant import JointPlant
from sim_drivers.plant_config import default_plant
from sim_drivers.simbus import SimNetwork

_chan = itertools.count()
CYCLE_S = 0.002
CLOSED = "CanOperationError: Cannot operate on a closed bus"


class Rig:
    """Simulated drives (node ids 5, 6, ...) on a virtual channel of their own and the
    campaign that drives them, two sine periods (2 s) per payload."""

    def __init__(self, name: str, *, n_drives: int = 1, masses: tuple[float, ...] = (0.0,)
                 ) -> None:
        self.channel = f"daqleft4_{name}_{next(_chan)}"
        scaling = {"rated_torque_Nm": 5.0, "gear_ratio": 100.0, "encoder_counts_per_rev": 4096}
        self.campaign = joint_campaign(
            name, cycle_s=CYCLE_S, payload_masses=masses,
            sine={"amplitude": 0.1, "frequency_hz": 1.0, "periods": 2},
            daq={"channel": self.channel, "tpdo_timeout_cycles": 3, "lockstep_wait_s": 0.05,
                 "drives": [{"node_id": 5 + k, "mode": "cst", "scaling": scaling}
                            for k in range(n_drives)]})
        self.sim = SimNetwork(self.channel, dispatch="inline", sync_cycle_s=CYCLE_S)
        self.drives = []
        for k in range(n_drives):
            plant = JointPlant(default_plant(), CYCLE_S, seed=k)
            plant.reset(0.0)
            self.drives.append(self.sim.add(SimulatedDrive(self.sim.network, 5 + k, plant,
                                                           cycle_s=CYCLE_S, clock="sync")))

    def unplug(self) -> None:
        """Shut the master's bus down under it (its end of the channel: the one peer that is
        not the drives' bus)."""
        for peer in list(self.sim.bus._peers):
            if peer is not self.sim.bus:
                peer.shutdown()

    def on_frame(self, hook) -> None:
        """Call ``hook(msg)`` on every frame the master sends (in the master's thread)."""

        class _Hook(can.Listener):
            def on_message_received(self, msg: can.Message) -> None:
                hook(msg)

        self.sim.bus.add_listener(_Hook())

    def run(self, out, **kwargs):
        try:
            return run_campaign(self.campaign, out_dir=out, prompt=lambda *a: True, **kwargs)
        finally:
            self.sim.close()

    def final_states(self) -> list[State]:
        """Each simulated drive's own CiA 402 state at its last cycle."""
        return [state_from_statusword(int(d.record["statusword"][-1])) for d in self.drives]


def _first_preop_unplugs(rig: Rig) -> None:
    """The bus goes away as the master sets the first drive pre-operational after a run."""
    started = []

    def hook(msg: can.Message) -> None:
        if msg.arbitration_id != 0x000:
            return
        if msg.data[0] == 0x01:
            started.append(True)
        elif msg.data[0] == 0x80 and started:
            started.clear()
            rig.unplug()

    rig.on_frame(hook)


def _state(out, name):
    return json.loads((out / f"{name}.state.json").read_text())


def _off(states: list[State]) -> bool:
    return all(s not in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE) for s in states)


def test_bus_gone_between_payloads_stops_the_campaign_in_one_line(tmp_path):
    """The operator mounts payload 1 and the adapter is unplugged meanwhile: before, the NMT
    start of payload 1 raised CanOperationError out of run_campaign (a traceback) and left an
    empty bg_payload1.mcap; now the campaign stops, naming the payload, nothing moved."""
    rig = Rig("bg", masses=(0.0, 2.0))

    def prompt(i, payload, n) -> bool:
        if i == 1:
            rig.unplug()
        return True

    try:
        r = run_campaign(rig.campaign, out_dir=tmp_path, prompt=prompt)
    finally:
        rig.sim.close()
    assert r.status == "stopped"
    assert r.reason == f"bus lost before the run of payload 1: {CLOSED}"
    assert [x.index for x in r.runs] == [0] and r.runs[0].status == "done"
    assert sorted(p.name for p in tmp_path.glob("*.mcap")) == ["bg_payload0.mcap"]
    assert read_run(tmp_path / "bg_payload0.mcap").metadata["result"]["status"] == "done"
    state = _state(tmp_path, "bg")
    assert state["completed"] == [0]
    assert state["logs"]["0"] == {"name": "bg_payload0.mcap",
                                  "bytes": (tmp_path / "bg_payload0.mcap").stat().st_size}
    assert f"campaign bg: stopped (bus lost before the run of payload 1: {CLOSED})" == \
        r.summary().splitlines()[0]
    assert _off(rig.final_states())  # payload 0's shutdown left the drive disabled


def test_bus_gone_as_the_run_winds_down_is_a_warning_kept_in_the_state(tmp_path):
    """Two drives: the bus goes away as the master sets the first one pre-operational after
    payload 0 (its log closed, both drives disabled); the second's NMT command fails. The
    payload completed; the campaign stops before payload 1 with a one-line reason, and the
    summary and the state file say that nothing the drives sent since was seen."""
    rig = Rig("wd", n_drives=2, masses=(0.0, 2.0))
    _first_preop_unplugs(rig)
    r = rig.run(tmp_path)
    lost = (f"bus lost after the run of payload 0 (its log closed, the drives disabled): "
            f"{CLOSED}")
    assert r.status == "stopped", r.reason
    assert r.reason == f"{lost}; payloads [1] not run"
    warning = f"{lost}; nothing the drives sent since was seen (an EMCY, a lost heartbeat)"
    assert f"  warning: {warning} (in no log: recorded in wd.state.json)" in \
        r.summary().splitlines()
    state = _state(tmp_path, "wd")
    assert state["completed"] == [0]
    (rec,) = state["warnings_outside_logs"]
    assert rec["text"] == warning and rec["after_payload"] == 0
    assert rec["utc"].endswith("+00:00")
    a = read_run(tmp_path / "wd_payload0.mcap")
    assert not a.truncated and a.metadata["result"]["status"] == "done"
    assert a.events[-1]["message"] == "drives disabled"
    assert _off(rig.final_states())
    assert not (tmp_path / "wd_payload1.mcap").exists()


def test_bus_gone_after_the_last_payload_is_a_warning_the_campaign_done(tmp_path):
    """One drive, one payload: the bus goes away with the NMT pre-operational after the last
    run; the SDO that clears the drive's heartbeat consumer cannot be sent. Before: a
    CanOperationError traceback (the summary never printed). Now the campaign is done (its
    log complete), with the warning in the summary and the state file."""
    rig = Rig("ld")
    _first_preop_unplugs(rig)
    r = rig.run(tmp_path)
    assert r.ok, r.reason
    warning = (f"node 5: heartbeat consumer 0x1016.1 not cleared after the run (bus lost: "
               f"{CLOSED}): nothing the drives sent since was seen")
    assert f"  warning: {warning} (in no log: recorded in ld.state.json)" in \
        r.summary().splitlines()
    state = _state(tmp_path, "ld")
    assert state["completed"] == [0]
    assert [(w["text"], w["after_payload"]) for w in state["warnings_outside_logs"]] == \
        [(warning, 0)]
    assert read_run(tmp_path / "ld_payload0.mcap").metadata["result"]["status"] == "done"
    assert _off(rig.final_states())


def test_drive_gone_after_the_last_payload_is_a_warning_kept_in_the_state(tmp_path):
    """The drive is switched off as the run winds down (at the NMT pre-operational after its
    last payload): it no longer answers the SDO that clears its heartbeat consumer. The
    summary says so and asks whether it is off or its bus gone; the state file keeps it."""
    rig = Rig("dg")
    started = []

    def hook(msg: can.Message) -> None:
        if msg.arbitration_id == 0x000 and msg.data[0] == 0x01:
            started.append(True)
        elif msg.arbitration_id == 0x000 and msg.data[0] == 0x80 and started:
            started.clear()
            rig.drives[0].stop()

    rig.on_frame(hook)
    r = rig.run(tmp_path)
    assert r.ok, r.reason
    warning = ("node 5: heartbeat consumer 0x1016.1 not cleared after the run (no SDO answer: "
               "is the drive off, or its bus gone?): if the drive still watches the master, "
               "it faults (EMCY 0x8130) when its heartbeat stops")
    assert f"  warning: {warning} (in no log: recorded in dg.state.json)" in \
        r.summary().splitlines()
    state = _state(tmp_path, "dg")
    assert [(w["text"], w["after_payload"]) for w in state["warnings_outside_logs"]] == \
        [(warning, 0)]
    assert _off(rig.final_states())


def test_bus_gone_during_a_run_stops_it_with_its_log_closed(tmp_path):
    """Already handled (proved here): the bus goes away at cycle 500 of the run; the run stops
    as "bus lost", its log closed properly (summary written, status stopped, the fault
    event), nothing recorded as completed."""
    rig = Rig("dr")
    done = []

    def progress(p) -> None:
        if p.phase == "run" and p.cycle >= 500 and not done:
            done.append(p.cycle)
            rig.unplug()

    r = rig.run(tmp_path, progress=progress)
    assert r.status == "stopped" and r.reason == f"bus lost: {CLOSED}"
    (run,) = r.runs
    a = read_run(run.path)
    assert not a.truncated and a.metadata["result"]["status"] == "stopped"
    assert a.metadata["result"]["reason"] == r.reason
    assert a.events[-1]["kind"] == "fault" and a.events[-1]["message"] == r.reason
    assert len(a) == run.cycles == done[0]  # every cycle up to the loss, none after
    assert not (tmp_path / "dr.state.json").exists()  # nothing completed, nothing to add


def test_drive_gone_during_a_run_stops_it_and_sends_the_stop_sequence(tmp_path):
    """Already handled (proved here): the drive is switched off at cycle 500; its TPDOs stop,
    the run stops on "TPDO missing" and sends the stop sequence (quick stop, disable), which
    nobody confirms: the log says so. The heartbeat consumer cannot be cleared: a warning,
    kept in the state file."""
    rig = Rig("dv")
    done = []

    def progress(p) -> None:
        if p.phase == "run" and p.cycle >= 500 and not done:
            done.append(p.cycle)
            rig.drives[0].stop()

    r = rig.run(tmp_path, progress=progress)
    assert r.status == "stopped" and r.reason == "node 5: TPDO missing for 3 cycles (watchdog)"
    (run,) = r.runs
    a = read_run(run.path)
    assert not a.truncated and a.metadata["result"]["status"] == "stopped"
    assert a.events[-1]["kind"] == "stop"
    assert a.events[-1]["message"].startswith("drives did not confirm the stop: node 5 sw=")
    # quick stop (0x0002), then disable voltage (0x0000) were sent after the fault
    rpdo = read_frames(run.path)
    rpdo = rpdo[rpdo["id"] == 0x205]
    controlwords = [int(d[0]) | int(d[1]) << 8 for d in rpdo["data"]]
    assert controlwords[-1] == 0x0000 and 0x0002 in controlwords[-12:]
    state = _state(tmp_path, "dv")
    assert state["completed"] == []
    assert [w["after_payload"] for w in state["warnings_outside_logs"]] == [0]
    assert "no SDO answer" in state["warnings_outside_logs"][0]["text"]
