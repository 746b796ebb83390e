"""``jointid fit --robot`` on runs that all carry the same payload: the default payload ratio
M_ae/M_aw (eq. 35) is not separable from the last link's parameters then, and the fit ended
in "parameters not identifiable on these data (cond 2.9e+300)"; it is now one line saying
why and what to do before anything is fitted, and ``--payload known`` fits."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROBOT = Path(__file__).resolve().parents[1] / "examples" / "robots" / "rx130l.toml"


@pytest.fixture
def logs(tmp_path):
    mcaplog = pytest.importorskip("daq.runtime.mcaplog")
    t = np.arange(4000) * 1e-3
    q = 0.7 + 0.8 * np.sin(2 * np.pi * 0.5 * t) + 0.3 * np.sin(2 * np.pi * 1.3 * t)
    dq = np.gradient(q, t)
    ddq = np.gradient(dq, t)
    out = []
    for k, mass in enumerate((3.4584, 3.4584)):
        tau = 31 * ddq + (21.1 + 1.277 * mass) * 9.81 * np.cos(q) + 40 * dq \
            + 25 * np.sign(dq) + 10 + np.random.default_rng(k).normal(0, 1.0, t.size)
        p = tmp_path / f"run_payload{k}.mcap"
        meta = {"payload": {"mass_kg": f"{mass}", "arm_m": "1.277"},
                "campaign": {"joint_kind": "revolute"}}  # fmt: skip
        with mcaplog.RunLog(p, n_axes=1, cycle_s=1e-3, metadata=meta) as w:
            for i in range(t.size):
                w.state(0, i, t[i], q[i], dq[i], tau[i], tau[i], int(q[i] * 65190), 0, 0, 0,
                        0x27)
        out.append(p)
    return out


def _fit(logs, *extra):
    return subprocess.run([sys.executable, "-m", "daq.app.cli", "fit", "--robot", str(ROBOT),
                           *[p.name for p in logs], "--model", "usual", *extra],
                          cwd=logs[0].parent, capture_output=True, text=True,
                          timeout=300)  # fmt: skip


def test_same_payload_in_every_run_is_one_line(logs):
    r = _fit(logs)
    # one error line (the automatic cut-off's warning may come before it)
    lines = [x for x in r.stderr.strip().splitlines() if ": warning: " not in x]
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert "same payload" in lines[0] and "--payload known" in lines[0], lines[0]
    assert logs[0].name in lines[0] and r.stdout == ""


def test_payload_known_fits_them(logs):
    r = _fit(logs, "--payload", "known")
    assert r.returncode == 0, r.stderr
    assert "payload known" in r.stdout
