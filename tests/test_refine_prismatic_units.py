"""A prismatic joint's refinement speaks in its units: the library terms' sentences
(``ident.describe``) were written in a revolute joint's [rad], [rad/s], [N m] whatever the
joint, so the EMPS ball-screw axis (positions in m, forces in N) was told "the torque varies
with position and velocity jointly (interaction): ±28.5 N m over the samples"."""

from __future__ import annotations

import json
import re
import subprocess
import sys

from conftest import shared_path

from ident.describe import prismatic_units


def test_prismatic_units_of_a_sentence():
    s = ("dry friction varies with position, period ≈ 0.0025 rad, amplitude ≈ 1.2 N m; "
         "slope 3 N m/rad, ±2 N m over [0, 0.2] rad, q_s = 0.01 rad/s, 4 rad/s^2")
    assert prismatic_units(s) == (
        "dry friction varies with position, period ≈ 0.0025 m, amplitude ≈ 1.2 N; "
        "slope 3 N/m, ±2 N over [0, 0.2] m, q_s = 0.01 m/s, 4 m/s^2")
    assert prismatic_units("radius 3 rads, N metre") == "radius 3 rads, N metre"


def test_emps_refinement_sentences_in_newtons_and_metres(tmp_path):
    data = shared_path("data", "emps", "DATA_EMPS.mat")
    r = subprocess.run(
        [sys.executable, "-m", "daq.app.cli", "fit", str(data), "--joint", "prismatic",
         "--map", "q=qm,tau=vir", "--gain", "gtau", "--model", "paper", "--cutoff", "100",
         "--decimation", "10", "--dq-min", "0", "--no-sign-check", "--refine",
         "--max-steps", "3", "--json", "emps.json"],
        cwd=tmp_path, capture_output=True, text=True, timeout=600)  # fmt: skip
    assert r.returncode == 0, r.stderr
    # step 3 on these data: a library basis in position x velocity, described in words
    lines = [x for x in r.stdout.splitlines() if "jointly (interaction)" in x]
    assert lines, r.stdout
    assert all(re.search(r"±[0-9.]+ N over", x) for x in lines), lines
    bad = re.compile(r"\bN m\b|\brad\b|\brad/s\b")
    out = json.loads((tmp_path / "emps.json").read_text())
    steps = out["refinement"]["steps"]
    said = [st.get("description") or "" for st in steps] + [r.stdout]
    assert not any(bad.search(x) for x in said), [x for x in said if bad.search(x)]
