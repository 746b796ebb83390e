"""The ``jointid`` console script starts without the heavy libraries: importing its dispatch
(:mod:`daq.app.cli`, every subcommand's ``register``) loads none of scipy, matplotlib,
pinocchio, canopen or mcap, so ``jointid --help``, a mistyped option or the demo's first
line come at once; each subcommand imports what it drives when it runs. Checked in a fresh
interpreter (the test process has loaded them all)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from ident.estimators import ESTIMATORS
from ident.vocab import METHOD_NAMES

ROOT = Path(__file__).resolve().parents[1]

#: libraries that take seconds to import on a small machine (scipy alone about 1 s)
HEAVY = ("scipy", "matplotlib", "pinocchio", "canopen", "mcap")

_PROBE = ("import sys; import daq.app.cli; "
          f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")


def test_importing_the_cli_loads_no_heavy_library():
    run = subprocess.run([sys.executable, "-c", _PROBE], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert ast.literal_eval(run.stdout.strip()) == [], run.stdout


def test_fit_method_choices_are_the_registered_estimators():
    """``jointid fit --method`` takes its choices from :data:`ident.vocab.METHOD_NAMES`
    (light) instead of the estimator table: both must name the same estimators, in order."""
    assert tuple(ESTIMATORS) == METHOD_NAMES
