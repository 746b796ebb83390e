"""Bad inputs through the command line, as a user meets them (issue 21 item 5): every case
exits non-zero with ONE line on stderr naming the file (or option, link, key) and the culprit
-- no traceback, no warning lines, no misleading message. Plus the one good case among them:
a CSV with a UTF-8 byte-order mark loads like the same file without it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ident.loaders import load_experiment
from trajectories import RobotError
from trajectories.robot import example_robot_urdf, load_robot

ROOT = Path(__file__).resolve().parents[1]
ARM3 = ROOT / "examples" / "robots" / "arm3.toml"


def _jointid(*args: str, cwd: Path) -> tuple[int, str]:
    """Run ``jointid ARGS`` in a fresh interpreter (warnings as a user sees them)."""
    r = subprocess.run([sys.executable, "-m", "daq.app.cli", *args], cwd=cwd,
                       capture_output=True, text=True, timeout=300)  # fmt: skip
    return r.returncode, r.stderr


def _one_line(rc: int, err: str, *needles: str) -> str:
    lines = err.strip().splitlines()
    assert rc == 2, err
    assert len(lines) == 1, err
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


def _signals(n: int = 2000, dt: float = 1e-3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(n) * dt
    q = 0.5 * np.sin(2 * np.pi * t) + 0.3 * np.sin(7 * t)
    tau = 10 * np.cos(2 * np.pi * t) + 3 + np.sign(np.cos(2 * np.pi * t))
    return t, q, tau


def _csv_text(header: str, cols: list[np.ndarray]) -> str:
    rows = np.column_stack(cols)
    return header + "\n" + "\n".join(",".join(f"{v:.10g}" for v in r) for r in rows) + "\n"


def test_utf8_bom_is_accepted(tmp_path):
    t, q, tau = _signals()
    text = _csv_text("t,q,tau", [t, q, tau])
    plain, bom = tmp_path / "plain.csv", tmp_path / "bom.csv"
    plain.write_bytes(text.encode())
    bom.write_bytes(b"\xef\xbb\xbf" + text.encode())
    a, b = load_experiment(plain), load_experiment(bom)
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.tau, b.tau)


@pytest.mark.parametrize(
    "name, encoding, needles",
    [("latin.csv", "latin-1", ("latin.csv", "not UTF-8", "0xe9")),
     ("utf16.csv", "utf-16", ("utf16.csv", "not UTF-8", "UTF-16"))],
)  # fmt: skip
def test_other_encodings_refused_in_one_line(tmp_path, name, encoding, needles):
    t, q, tau = _signals()
    (tmp_path / name).write_bytes(_csv_text("t,q,tau_\u00e9", [t, q, tau]).encode(encoding))
    rc, err = _jointid("fit", name, cwd=tmp_path)
    _one_line(rc, err, *needles)


def test_header_only_csv(tmp_path):
    (tmp_path / "empty.csv").write_text("t,q,tau\n")
    rc, err = _jointid("fit", "empty.csv", cwd=tmp_path)
    _one_line(rc, err, "empty.csv", "no data rows")


@pytest.mark.parametrize("value", ["0", "-5", "nan", "inf"])
def test_cutoff_must_be_positive_and_finite(tmp_path, value):
    t, q, tau = _signals()
    (tmp_path / "run.csv").write_text(_csv_text("t,q,tau", [t, q, tau]))
    rc, err = _jointid("fit", "run.csv", f"--cutoff={value}", cwd=tmp_path)
    _one_line(rc, err, "--cutoff", "> 0")


def test_absurd_values_refused_naming_file_and_column(tmp_path):
    t, q, tau = _signals()
    (tmp_path / "huge.csv").write_text(_csv_text("t,q,current", [t, q, tau * 1e299]))
    rc, err = _jointid("fit", "huge.csv", "--map", "tau=current", cwd=tmp_path)
    _one_line(rc, err, "huge.csv", "'current'", "beyond")


def test_negative_payload_mass_refused_naming_the_file(tmp_path):
    t, q, tau = _signals()
    (tmp_path / "neg.csv").write_text(_csv_text("t,q,tau,payload_kg,payload_arm_m",
                                                [t, q, tau, -2.0 + 0 * t, 1.0 + 0 * t]))
    rc, err = _jointid("fit", "neg.csv", cwd=tmp_path)
    _one_line(rc, err, "neg.csv", "payload_kg -2.0", "expected a mass >= 0 [kg]")


def test_time_gap_refused_with_its_time(tmp_path):
    t, q, tau = _signals()
    t = np.where(t > 1.0, t + 0.5, t)  # 0.5 s lost after t = 1 s
    (tmp_path / "gap.csv").write_text(_csv_text("t,q,tau", [t, q, tau]))
    rc, err = _jointid("fit", "gap.csv", cwd=tmp_path)
    line = _one_line(rc, err, "gap.csv", "gap")
    assert "t=1 s" in line and "0.501 s" in line


def _robot_csv(path: Path, edit=None) -> None:
    n = 3000
    cols = {"t": np.arange(n) * 1e-3}
    for j in (1, 2, 3):
        cols[f"q{j}"] = 0.3 * np.sin((j + 1) * cols["t"])
    for j in (1, 2, 3):
        cols[f"tau{j}"] = 5 * np.cos((j + 1) * cols["t"])
    if edit:
        edit(cols)
    path.write_text(_csv_text(",".join(cols), list(cols.values())))


def test_robot_nan_names_joint_column_and_row(tmp_path):
    def nan(cols):
        cols["q2"][1234] = np.nan

    _robot_csv(tmp_path / "r.csv", nan)
    rc, err = _jointid("fit", "--robot", str(ARM3), "r.csv", cwd=tmp_path)
    line = _one_line(rc, err, "r.csv", "NaN", "'q2'", "'j2'", "sample 1234")
    # the line of the file holding it (header on line 1)
    lineno = int(line.split("line ")[1].split(" ")[0])
    assert "nan" in (tmp_path / "r.csv").read_text().splitlines()[lineno - 1]


def test_robot_absurd_value_and_gap(tmp_path):
    def big(cols):
        cols["tau3"][100] = 1e300

    def gap(cols):
        cols["t"][2000:] += 0.5

    _robot_csv(tmp_path / "big.csv", big)
    _robot_csv(tmp_path / "gap.csv", gap)
    rc, err = _jointid("fit", "--robot", str(ARM3), "big.csv", cwd=tmp_path)
    _one_line(rc, err, "big.csv", "'tau3'", "'j3'", "beyond")
    rc, err = _jointid("fit", "--robot", str(ARM3), "gap.csv", cwd=tmp_path)
    _one_line(rc, err, "gap.csv", "gap", "t=1.999 s")


def _negative_mass_urdf(path: Path) -> None:
    src = example_robot_urdf("ur10").read_text()
    i = src.index('<link name="forearm_link">')
    j = src.index('<mass value="', i) + len('<mass value="')
    path.write_text(src[:j] + "-2.0" + src[src.index('"', j):])


def test_urdf_negative_mass_refused(tmp_path):
    urdf = tmp_path / "neg.urdf"
    _negative_mass_urdf(urdf)
    with pytest.raises(RobotError, match=r"link 'forearm_link': mass '-2.0'"):
        load_robot(urdf)


def test_urdf_negative_mass_refused_by_run_simulate(tmp_path):
    """``jointid run --simulate`` of a robot campaign builds the simulated arm from the robot
    file: refused before anything starts."""
    (tmp_path / "robots").mkdir()
    _negative_mass_urdf(tmp_path / "robots" / "neg.urdf")
    robot = (ROOT / "examples" / "robots" / "ur10.toml").read_text()
    (tmp_path / "robots" / "ur10.toml").write_text(
        robot.replace('urdf = "example-robot-data:ur10"', 'urdf = "neg.urdf"'))
    camp = (ROOT / "examples" / "campaign_ur10_demo.toml").read_text()
    (tmp_path / "c.toml").write_text(camp)
    rc, err = _jointid("run", "c.toml", "--simulate", "--out", "out", cwd=tmp_path)
    _one_line(rc, err, "neg.urdf", "forearm_link", "mass")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("key", ["max_jerk", "max_acceleration"])
def test_absurd_campaign_limit_refused_naming_key(tmp_path, key):
    text = (ROOT / "examples" / "campaign.toml").read_text()
    lines = [f"{key} = 1e300" if ln.startswith(f"{key} =") else ln for ln in text.splitlines()]
    (tmp_path / "c.toml").write_text("\n".join(lines) + "\n")
    rc, err = _jointid("plan", "c.toml", cwd=tmp_path)
    _one_line(rc, err, "c.toml", f"joint.limits.{key}")
