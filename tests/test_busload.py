"""Bus budget: the highest rate that fits, drives per bus, the one-line refusal."""

from __future__ import annotations

import re

import pytest

from daq import ConfigError
from daq.runtime.busload import (
    bus_loads,
    check_load,
    check_loads,
    cycle_load,
    drives_per_bus,
    frame_bits,
    max_rate_hz,
    refusal,
)

CST = (4, 8, 5)  # RPDO1, TPDO1, TPDO2 data lengths of one CST drive [byte]
CSP = (6, 8, 5)


@pytest.mark.parametrize("n, cycle_s, share", [(1, 0.001, 0.6), (3, 0.001, 0.6),
                                               (6, 0.001, 0.6), (6, 0.002, 0.3),
                                               (2, 0.0005, 0.9)])
def test_max_rate_and_drives_per_bus_are_the_boundaries(n, cycle_s, share):
    load = cycle_load([CST] * n, cycle_s, 1_000_000)
    rate = max_rate_hz(load, share)
    assert cycle_load([CST] * n, 1 / rate, 1_000_000).share == pytest.approx(share)
    assert cycle_load([CST] * n, 1.001 / rate, 1_000_000).share <= share
    assert cycle_load([CST] * n, 0.999 / rate, 1_000_000).share > share
    k = drives_per_bus(load, share)
    if k:
        assert cycle_load([CST] * k, cycle_s, 1_000_000).share <= share
    assert cycle_load([CST] * (k + 1), cycle_s, 1_000_000).share > share


def test_refusal_is_one_line_with_the_figures_and_both_ways_out():
    # 6 CST drives at 1 kHz on 1 Mbit/s: 1 SYNC + 6 x 3 PDOs, worst-case stuffing
    load = cycle_load([CST] * 6, 0.001, 1_000_000, channel="can0")
    bits = frame_bits(0) + 6 * sum(frame_bits(n) for n in CST)
    assert load.bits_per_cycle == bits == 2065 and load.frames_per_cycle == 19
    with pytest.raises(ConfigError) as exc:
        check_load(load, 0.6, "arm.toml")
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith("arm.toml: daq.max_bus_load: cyclic traffic needs 19 frames/cycle, "
                          "2065 bit/cycle, 206.5 % of 1000 kbit/s at 1 ms (bus 'can0', 6 drives)"
                          " > allowed 60 %")
    rate = float(re.search(r"lower the rate to <= ([\d.]+) Hz", msg).group(1))
    assert rate == 290.0 and rate <= 0.6 * 1e6 / bits < rate + 1
    cycle = float(re.search(r"control.cycle_s >= ([\d.]+) s", msg).group(1))
    assert cycle_load([CST] * 6, cycle, 1_000_000).share <= 0.6
    # 335 bit per drive + 55 bit SYNC within 600 bit per ms: one drive per bus
    assert msg.endswith("or spread the drives over 6 buses (1 drive per bus fit at 1000 Hz)")


def test_refusal_of_a_single_drive_proposes_only_the_rate():
    load = cycle_load([CSP], 0.0002, 500_000)
    msg = refusal(load, 0.5, "c.toml")
    assert "buses" not in msg and "one drive alone is over budget" in msg
    rate = float(re.search(r"<= ([\d.]+) Hz", msg).group(1))
    assert cycle_load([CSP], 1 / rate, 500_000).share <= 0.5


def test_two_buses_each_within_budget_pass_and_the_worst_is_named():
    loads = bus_loads({"can0": [CST, CST], "can1": [CST]}, 0.002, 1_000_000)
    assert loads["can0"].frames_per_cycle == 7 and loads["can1"].frames_per_cycle == 4
    assert check_loads(loads, 0.6, "c.toml") is loads["can0"]
    loads = bus_loads({"can0": [CST], "can1": [CST, CST, CST, CST]}, 0.002, 1_000_000)
    with pytest.raises(ConfigError, match=r"^c.toml: daq.max_bus_load: .*\(bus 'can1', 4 drives"
                                          r"\) > allowed 60 %; .* over 2 buses \(3 drives per"):
        check_loads(loads, 0.6, "c.toml")
