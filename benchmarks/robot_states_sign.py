"""The states chain's Coulomb column: sign(dq) of the decimated velocity against sign(dq)
formed at full rate and decimated with the torque (``RobotSignals.sign``, what the states
chain carries; docs/robot-data.md, ``--chain states``).

Usage: ``python benchmarks/robot_states_sign.py``

The simulated 3-dof arm with the usual friction model (tests/test_robot_states_chain.py's
data: three payload runs of 12 s, payloads known, 1 % torque noise, noise seeds 0 and 1),
the usual model fitted by LS. Printed per seed and chain -- ``columns`` (the default chain),
``states`` (``preprocess_runs``, ``--chain states``), ``columns-states`` (the states path on
the columns chain's decimated states, ``replace(signals, columns=None)``) -- the rows and the
z-scores of FC1-3 and FV2 against the truth, with the decimated sign column (``sign``) and
with the sign of the decimated dq (``sign=None``, the states path before the column).
"""

from __future__ import annotations

import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_robot_fit import _z  # noqa: E402
from test_robot_states_chain import _fit, arm3_chains  # noqa: E402


def main() -> None:
    warnings.simplefilter("ignore", UserWarning)
    reg, base, truth, out = arm3_chains.__wrapped__()
    names = ("FC1", "FC2", "FC3", "FV2")
    for seed, (columns, states) in enumerate(out):
        for chain, sig in (("columns", columns), ("states", states),
                           ("columns-states", replace(columns, columns=None))):
            for tag, s in (("sign", sig), ("sign=None", replace(sig, sign=None))):
                if chain == "columns" and tag != "sign":
                    continue
                m = _fit(reg, base, s)
                z, _ = _z(m, truth)
                zs = " ".join(f"{n} {z[m.names_.index(n)]:+6.2f}" for n in names)
                i = int(np.nanargmax(np.abs(z)))
                print(f"seed {seed} {chain:14s} {tag:9s} n={s.n:5d}  {zs}  "
                      f"max |z| {abs(z[i]):.2f} ({m.names_[i]})", flush=True)


if __name__ == "__main__":
    main()
