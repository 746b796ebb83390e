"""Bad input files through ``jointid fit``: one line naming the file, exit code 2, no traceback.

Found rerunning the README's commands as a stranger would (2026-11-28): a ``.mat`` file
shorter than a MAT header (empty, a few bytes of text, a CSV given the wrong extension)
made scipy raise ``MatReadError``, which is not a ``ValueError``, and the command printed a
traceback on the single-joint path and with ``--robot`` alike. Longer garbage already gave
the one line ("not a readable MAT file (Unknown mat file type ...)"): checked here too.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from daq.app.cli import main
from ident.cli_robot import load_runs
from trajectories.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
ARM3 = ROOT / "examples" / "robots" / "arm3.toml"

BAD_MAT = {
    "empty.mat": b"",
    "text.mat": b"hello\n",
    "csv.mat": b"t,q,tau\n0,1,2\n",
    "random.mat": np.random.default_rng(0).bytes(1000),  # past the header: another path
}


def _one_line_error(capfd, argv: list[str], name: str) -> str:
    code = main(argv)
    out, err = capfd.readouterr()
    assert code == 2, (code, out, err)
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert name in lines[0] and "not a readable MAT file" in lines[0], lines[0]
    return lines[0]


@pytest.mark.parametrize("name", sorted(BAD_MAT))
def test_unreadable_mat_is_one_line_single_joint(tmp_path, capfd, name):
    path = tmp_path / name
    path.write_bytes(BAD_MAT[name])
    _one_line_error(capfd, ["fit", str(path)], name)


@pytest.mark.parametrize("name", sorted(BAD_MAT))
def test_unreadable_mat_is_one_line_robot(tmp_path, capfd, name):
    path = tmp_path / name
    path.write_bytes(BAD_MAT[name])
    _one_line_error(capfd, ["fit", "--robot", str(ARM3), str(path)], name)


def test_unreadable_validation_mat_is_one_line(tmp_path, capfd):
    """A bad ``--validate`` file is named as an identification file is (the first file is
    read and checked before it, so it must be good: a CSV of the arm's three axes)."""
    good = _arm3_csv(tmp_path / "good.csv")
    bad = tmp_path / "val.mat"
    bad.write_bytes(b"")
    _one_line_error(capfd, ["fit", "--robot", str(ARM3), str(good), "--validate", str(bad)],
                    "val.mat")


def _arm3_csv(path: Path, scale: float = 1.0) -> Path:
    """A short CSV of the arm's three axes (numbered columns), positions times ``scale``."""
    t = np.arange(400) * 1e-3
    cols = {"t": t}
    for j in (1, 2, 3):
        cols[f"q{j}"] = scale * 0.5 * np.sin(2 * np.pi * 0.7 * j * t)
    for j in (1, 2, 3):
        cols[f"tau{j}"] = np.cos(2 * np.pi * 0.7 * j * t)
    path.write_text(",".join(cols) + "\n" + "\n".join(
        ",".join(f"{cols[c][i]:.9g}" for c in cols) for i in range(t.size)) + "\n")
    return path


@pytest.mark.parametrize("unit", ["mm", "m"])
def test_length_unit_on_a_revolute_robot_is_one_line(tmp_path, capfd, unit):
    """``--q-unit mm`` on a revolute arm read the angles as millimetres and fitted on
    without a word (found on the KUKA recording A: degrees / 1000 as radians, and a fit of
    1.48 % over all axes, as plausible as the right one's); the single-joint loader already
    refuses it, the robot path now too."""
    f = _arm3_csv(tmp_path / "arm.csv")
    code = main(["fit", "--robot", str(ARM3), str(f), "--model", "usual", "--q-unit", unit])
    out, err = capfd.readouterr()
    assert code == 2, (out, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert f"--q-unit {unit}" in lines[0] and "j1, j2, j3" in lines[0] and "revolute" in lines[0]
    assert not out.strip()


def test_angle_unit_on_a_revolute_robot_still_reads(tmp_path):
    """The check refuses the wrong kind only: degrees on the revolute arm read as before
    (the same run in radians, converted)."""
    robot = load_robot(ARM3)
    rad = load_runs(robot, [_arm3_csv(tmp_path / "rad.csv")])
    deg = load_runs(robot, [_arm3_csv(tmp_path / "deg.csv", 180 / np.pi)], q_unit="deg")
    np.testing.assert_allclose(deg[0].q, rad[0].q, rtol=1e-8, atol=1e-12)
