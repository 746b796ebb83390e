"""``[daq.drives.scaling]`` with ``--simulate`` (found by the acquisition sweep): a hardware
campaign's scaling (gear ratio 160, rated torque 0.3 N m) was replaced by the simulated
plant's (100, 5 N m) without a word, so a stranger's smoke run seemed to exercise a scaling
it did not use. The run now says so (a warning of the run's summary and of the log's cycle
0); a scaling equal to the plant's, or none, gets no note."""

from __future__ import annotations

from daq_campaigns import sine_campaign

from daq.protocol.reader import read_run
from daq.runtime.runner import run_campaign
from sim_drivers.plant_config import default_plant

HW = {"rated_torque_Nm": 0.3, "gear_ratio": 160.0, "encoder_counts_per_rev": 4096}


def test_a_scaling_the_simulation_ignores_is_named(tmp_path):
    plant = default_plant()
    c = sine_campaign("simscale", drives=[{"node_id": 1, "scaling": HW}])
    r = run_campaign(c, out_dir=tmp_path / "a", simulate=plant, yes=True)
    assert r.status == "done", r.reason
    notes = [n for n in r.notes if "daq.drives.scaling" in n]
    assert len(notes) == 1, r.notes
    d = plant.drive
    assert notes[0] == (
        "--simulate: node 1: [daq.drives.scaling] (gear ratio 160, rated torque 0.3 N m, "
        "4096 counts/rev) is not used: the simulated drive's chain is (gear ratio "
        f"{d.gear_ratio:g}, rated torque {d.rated_torque_Nm:g} N m, "
        f"{d.encoder_counts_per_rev} counts/rev)")
    assert "warning: --simulate: node 1" in r.summary()
    ev = read_run(r.runs[0].path).events
    assert any(e["kind"] == "warning" and "daq.drives.scaling" in e["message"] for e in ev)
    # the plant's own chain given, or none: nothing to say
    same = {"rated_torque_Nm": d.rated_torque_Nm, "gear_ratio": d.gear_ratio,
            "encoder_counts_per_rev": d.encoder_counts_per_rev}
    for drives in ([{"node_id": 1, "scaling": same}], [{"node_id": 1}]):
        r2 = run_campaign(sine_campaign("simscale", drives=drives), out_dir=tmp_path / "b",
                          simulate=plant, yes=True, overwrite=True)
        assert r2.status == "done" and not any("scaling" in n for n in r2.notes), r2.notes
