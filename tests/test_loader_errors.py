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
    t = np.arange(400) * 1e-3
    cols = {"t": t}
    for j in (1, 2, 3):
        cols[f"q{j}"] = 0.5 * np.sin(2 * np.pi * 0.7 * j * t)
    for j in (1, 2, 3):
        cols[f"tau{j}"] = np.cos(2 * np.pi * 0.7 * j * t)
    good = tmp_path / "good.csv"
    good.write_text(",".join(cols) + "\n" + "\n".join(
        ",".join(f"{cols[c][i]:.9g}" for c in cols) for i in range(t.size)) + "\n")
    bad = tmp_path / "val.mat"
    bad.write_bytes(b"")
    _one_line_error(capfd, ["fit", "--robot", str(ARM3), str(good), "--validate", str(bad)],
                    "val.mat")
