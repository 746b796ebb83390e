"""``--map`` and ``--gain`` when every file is a jointid MCAP log are refused in one line
naming the flags and the log: ``jointid fit run.mcap --gain 2`` and ``--map q=foo`` ran the
fit with them silently ignored (the log's own channels and joint-side torque). With a CSV or
MAT file among the inputs or the validation files they still apply to those. And ``--joint``
contradicting a log's own joint kind (its metadata) is refused, not obeyed in silence."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest


@pytest.fixture
def log(tmp_path):
    mcaplog = pytest.importorskip("daq.runtime.mcaplog")
    t = np.arange(3000) * 1e-3
    q = 0.5 * np.sin(2 * np.pi * 0.5 * t) + 0.2 * np.sin(2 * np.pi * 1.3 * t)
    tau = 10 * np.cos(2 * np.pi * 0.5 * t) + 3 + 5 * np.sign(np.cos(2 * np.pi * 0.5 * t))
    p = tmp_path / "run_payload0.mcap"
    meta = {"payload": {"mass_kg": "0", "arm_m": "1.277"},
            "campaign": {"joint_kind": "revolute"}}  # fmt: skip
    with mcaplog.RunLog(p, n_axes=1, cycle_s=1e-3, metadata=meta) as w:
        for k in range(t.size):
            w.state(0, k, t[k], q[k], 0.0, tau[k], tau[k], int(q[k] * 65190), 0, 0, 0, 0x27)
    rows = np.column_stack([t, q, tau / 2.0])
    (tmp_path / "other.csv").write_text(
        "time,pos,cmd\n" + "\n".join(",".join(f"{v:.10g}" for v in r) for r in rows) + "\n")
    return p


def _fit(cwd, *args):
    r = subprocess.run([sys.executable, "-m", "daq.app.cli", "fit", *args, "--model", "usual"],
                       cwd=cwd, capture_output=True, text=True, timeout=300)  # fmt: skip
    return r.returncode, r.stdout, r.stderr


@pytest.mark.parametrize("opts, needle", [
    (["--gain", "2"], "--gain"),
    (["--map", "q=foo"], "--map"),
    (["--map", "q=foo", "--gain", "para.u[2]"], "--map and --gain"),
])  # fmt: skip
def test_foreign_options_on_logs_only_are_one_line(log, opts, needle):
    rc, out, err = _fit(log.parent, log.name, *opts)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1, err
    assert needle in lines[0] and log.name in lines[0] and "CSV and MAT" in lines[0], lines[0]
    assert out == ""


def test_robot_map_on_logs_only_is_one_line(log):
    robot = __import__("pathlib").Path(__file__).resolve().parents[1] / "examples" / "robots"
    rc, _, err = _fit(log.parent, "--robot", str(robot / "rx130l.toml"), log.name,
                      "--map", "q=foo")
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    assert "--map" in err and log.name in err


def test_options_still_apply_to_a_csv_validation_file(log):
    # the log fitted, the CSV (other names, half the torque) validated through the mapping
    rc, out, err = _fit(log.parent, log.name, "--validate", "other.csv",
                        "--map", "t=time,q=pos,tau=cmd", "--gain", "2")
    assert rc == 0, err
    assert "Validation files" in out


def test_joint_kind_contradicting_the_log_is_one_line(log):
    # the log's metadata says revolute: fitted as prismatic it gave a 60 % error in silence
    rc, out, err = _fit(log.parent, log.name, "--joint", "prismatic")
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1, err
    assert log.name in lines[0] and "revolute" in lines[0] and "--joint" in lines[0], lines[0]
    rc, out, err = _fit(log.parent, log.name, "--joint", "revolute")  # agreeing: fitted
    assert rc == 0, err
