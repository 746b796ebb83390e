"""``[daq]`` keys of the torque loop's run safety: ``velocity_source`` (the velocity the
master's position loop filters) and the start-up lateness check's ``lateness_check_s``,
``lateness_warn``, ``lateness_stop``: their defaults (the clock decides where left out) and
one-line errors naming the key, from ``parse_daq`` and from ``jointid plan``."""

from __future__ import annotations

import subprocess
import sys

import pytest
from daq_campaigns import sine_toml

from daq import ConfigError
from daq.runtime.config import parse_daq


def test_velocity_source_follows_the_clock_unless_given():
    """Left out: the drive's 0x606C on the paced clock, the position's difference in
    lockstep (as before the key); given: as given on either clock."""
    assert parse_daq({}).velocity_source == "difference"  # virtual bus: lockstep
    assert parse_daq({"clock": "paced"}).velocity_source == "drive"
    for v in ("drive", "difference"):
        assert parse_daq({"velocity_source": v}).velocity_source == v
        assert parse_daq({"clock": "paced", "velocity_source": v}).velocity_source == v


@pytest.mark.parametrize("bad", ["Drive", "0x606C", "", 3, True])
def test_a_bad_velocity_source_is_one_line(bad):
    with pytest.raises(ConfigError) as e:
        parse_daq({"velocity_source": bad}, "c.toml")
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith("c.toml: daq.velocity_source: expected one of 'drive', "
                          "'difference'"), msg


def test_jointid_plan_refuses_a_bad_velocity_source(tmp_path):
    """The CLI says it in one line on stderr, exit code 2 (before any bus is opened)."""
    f = tmp_path / "c.toml"
    f.write_text(sine_toml("c", "vs_bad") + 'velocity_source = "differance"\n')
    r = subprocess.run([sys.executable, "-m", "daq.app.cli", "plan", str(f)], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and "daq.velocity_source: expected one of" in lines[0], r.stderr
    assert "'differance'" in lines[0]
