"""A refusal is its one line, and a warning is said once (``jointid fit``, with and without
``--robot``, through :func:`daq.app.cli.main` on a real run log of the simulated 3-dof arm,
cut as a killed writer leaves it).

Before the fix: ``fit --robot`` of a truncated log said "truncated run log" twice (each axis
is one scan of the file); ``fit --trim 2000 run.csv`` said "cut-off 50 Hz is the lower bound"
before its error; a log cut at 2 kB said "truncated run log" (three times with ``--robot``)
before "no cycle logged (the log is cut short)".
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from robot_campaigns import arm3_log

from daq.app.cli import main
from daq.protocol.reader import read_metadata
from ident import DataError
from ident.loaders import read_file

ROOT = Path(__file__).resolve().parents[1]
ARM3 = str(ROOT / "examples" / "robots" / "arm3.toml")
TRUNCATED = "truncated run log"


@pytest.fixture(scope="module")
def arm_log(tmp_path_factory) -> Path:
    """A real run log of the simulated 3-dof arm (one multi-sine period, one payload)."""
    return arm3_log(tmp_path_factory.mktemp("arm_log"), seed=1)


def _cut(src: Path, dst: Path, size: int) -> Path:
    """``src``'s first ``size`` bytes: a writer killed there."""
    dst.write_bytes(src.read_bytes()[:size])
    return dst


def _csv(path: Path, axes: int) -> Path:
    t = np.arange(3000) * 1e-3
    q = [0.5 * np.sin(2 * np.pi * (j + 1) * t) + 0.3 * np.sin(7 * t) for j in range(axes)]
    tau = [10 * np.cos(2 * np.pi * (j + 1) * t) + 3 for j in range(axes)]
    names = ["q", "tau"] if axes == 1 else [*(f"q{j + 1}" for j in range(axes)),
                                            *(f"tau{j + 1}" for j in range(axes))]
    np.savetxt(path, np.column_stack([t, *q, *tau]), delimiter=",", fmt="%.10g",
               header=",".join(["t", *names]), comments="")
    return path


def _stderr(capfd, argv: list[str], code: int) -> list[str]:
    got = main(argv)
    out, err = capfd.readouterr()
    assert got == code, (got, err[-2000:])
    assert "Traceback" not in err, err
    return [ln for ln in err.splitlines() if ln.strip()]


@pytest.mark.parametrize("robot", [False, True])
def test_truncated_log_warned_once(tmp_path, capfd, arm_log, robot):
    """A log cut at 70 % of its bytes fits (rc 0) with one "truncated run log" line, shown
    after the fit (held while it runs) as before."""
    cut = _cut(arm_log, tmp_path / "cut.mcap", int(0.7 * arm_log.stat().st_size))
    args = ["--robot", ARM3, "--no-consistency"] if robot else []
    lines = _stderr(capfd, ["fit", *args, str(cut), "--model", "usual"], 0)
    said = [ln for ln in lines if TRUNCATED in ln]
    assert len(said) == 1, lines
    assert said[0].startswith(f"jointid fit: warning: {cut}: {TRUNCATED}"), said


@pytest.mark.parametrize("robot", [False, True])
def test_log_cut_at_2kb_is_one_line(tmp_path, capfd, arm_log, robot):
    cut = _cut(arm_log, tmp_path / "cut2k.mcap", 2000)
    args = ["--robot", ARM3] if robot else []
    lines = _stderr(capfd, ["fit", *args, str(cut)], 2)
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"jointid fit: error: {cut}: no cycle logged"), lines
    assert "cut short" in lines[0]


@pytest.mark.parametrize("robot", [False, True])
def test_trim_beyond_the_data_is_one_line(tmp_path, capfd, robot):
    """The data's cut-off at its bound (a warning on a successful fit) is not said before
    the refusal of --trim 2000 on 3000 samples."""
    data = _csv(tmp_path / "run.csv", 3 if robot else 1)
    args = ["--robot", ARM3] if robot else []
    lines = _stderr(capfd, ["fit", *args, str(data), "--trim", "2000"], 2)
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"jointid fit: error: {data}: 3000 samples, too few after "
                               "trimming 2000"), lines
    ok = _stderr(capfd, ["fit", *args, str(data), "--model", "usual", "--no-consistency"]
                 if robot else ["fit", str(data), "--model", "usual"], 0)
    assert any("warning" in ln and "cut-off" in ln for ln in ok), ok  # shown when it fits


def test_robot_loader_says_a_truncation_once(tmp_path, arm_log):
    """The robot's reading of a truncated log (every axis, ``ident.loaders.read_file``, no
    CLI around it): "truncated run log" once; a refusal of the same log (a drive's logged
    joint is not the robot's) is said alone, without it."""
    cut = _cut(arm_log, tmp_path / "cut.mcap", int(0.7 * arm_log.stat().st_size))
    joints = tuple(read_metadata(arm_log)[f"drive{i}"]["joint"] for i in range(3))
    with warnings.catch_warnings(record=True) as log:
        warnings.simplefilter("always")
        run = read_file(cut, joints)
    assert run.q.shape[1] == 3
    said = [str(w.message) for w in log if TRUNCATED in str(w.message)]
    assert len(said) == 1, said
    with warnings.catch_warnings(record=True) as log:
        warnings.simplefilter("always")
        with pytest.raises(DataError, match=r"metadata drive1\.joint"):
            read_file(cut, (joints[0], "elsewhere", joints[2]))
    assert [str(w.message) for w in log] == []
