"""BLAS threads of the ``jointid`` command (issue 23 item 3): limited to one when the command
starts -- numpy's BLAS is loaded by then, so the limit must reach the loaded library, which
an environment variable set in ``main`` does not -- and a count the user chose is kept.
Checked in a fresh interpreter with threadpoolctl's own view of the loaded BLAS."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

#: the variables by which a user chooses the count (the probe runs without them)
BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")

_PROBE = """
import json, threadpoolctl
from daq.app.cli import main

def blas():
    return [p["num_threads"] for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas"]

before = blas()
try:
    main(["--version"])
except SystemExit:
    pass
print(json.dumps({"before": before, "after": blas()}))
"""


def _probe(**env: str) -> dict:
    clean = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARS}
    r = subprocess.run([sys.executable, "-c", _PROBE], env={**clean, **env},
                       capture_output=True, text=True, timeout=120, check=True)  # fmt: skip
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_cli_start_limits_blas_to_one_thread():
    got = _probe()
    assert got["after"], "no BLAS library found by threadpoolctl"
    if max(got["before"]) <= 1:
        pytest.skip("the BLAS starts with one thread here (one core): nothing to limit")
    assert got["after"] == [1] * len(got["after"])


def test_a_thread_count_the_user_chose_is_kept():
    got = _probe(OPENBLAS_NUM_THREADS="2", OMP_NUM_THREADS="2")
    assert got["after"] == got["before"] == [2] * len(got["before"])
