"""The arm's offline closed loop gives, bit for bit (to the last bits of libm, ``RTOL``), the
numbers it gave before the single-joint and n-joint loops became one
(``sim_drivers.closed_loop``).

``tests/data/arm_offline_fingerprint.json`` holds exact fingerprints (the sum of each record
array and a few samples, as ``float.hex``) of three ``simulate_arm`` / ``simulate_arm_payloads``
runs recorded with the code of main 71a3d7b, before the loops were merged. Regenerate only when
a change of the numbers is intended and explained: ``python tests/test_arm_offline_fingerprint.py
--write``.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from sim_drivers.arm import (
    ArmEffects,
    ArmGains,
    ArmParams,
    Payload,
    model_reference,
    simulate_arm,
    simulate_arm_payloads,
)
from sim_drivers.robots import ur10

DATA = Path(__file__).resolve().parent / "data" / "arm_offline_fingerprint.json"
FIELDS = ("counts", "q", "x", "tau_ref", "tau_applied", "tau_noise", "q_true", "dq_true",
          "ddq_true", "regime")
PAYLOAD = Payload(3.0, [0.0, 0.05, 0.12], [0.01, 0.0, 0.0, 0.01, 0.0, 0.02])


def _runs(case: str) -> list:
    params = ArmParams.from_model(ur10(3))
    ref = model_reference(params.model, duration_s=2.5, seed=2)
    if case == "rnea_payload_seed5":
        gains = ArmGains.for_params(params, payload=PAYLOAD)
        return [simulate_arm(params, ref, gains, payload=PAYLOAD, seed=5)]
    if case == "no_ff_effect_seed7":
        params = dataclasses.replace(params, effects=ArmEffects.make(3, dry_coupling={
            (0, 1): {"amplitude": 0.4, "period_rad": 1.7, "phase_rad": 0.3}}))
        gains = ArmGains.for_params(params, friction_ff=False, velocity_cutoff_hz=50.0)
        return [simulate_arm(params, ref, gains, seed=7, feedforward=None, substeps=4)]
    if case == "payloads_seed3":
        gains = ArmGains.for_params(params)
        return simulate_arm_payloads(params, ref, gains, [None, Payload(8.0, [0.0, 0.0, 0.1])],
                                     seed=3)
    raise KeyError(case)


CASES = ("rnea_payload_seed5", "no_ff_effect_seed7", "payloads_seed3")


def _fingerprint(runs: list) -> list[dict]:
    out = []
    for run in runs:
        fp: dict = {"n": len(run), "cycle_s": float(run.cycle_s).hex()}
        for name in FIELDS:
            a = np.asarray(getattr(run, name))
            idx = [0, 1, a.shape[0] // 3, a.shape[0] // 2, a.shape[0] - 1]
            fp[name] = {
                "dtype": str(a.dtype), "shape": list(a.shape),
                "sum": float(np.sum(a, dtype=float)).hex(),
                "abs_sum": float(np.sum(np.abs(a), dtype=float)).hex(),
                "samples": [float(v).hex() for v in a[idx].ravel()],
            }
        out.append(fp)
    return out


#: Relative tolerance on the float fingerprints: the last bits of libm/BLAS differ between
#: CPUs (1 ULP, 1.7e-16 relative, on one ddq_true sample of ``payloads_seed3`` on an AMD EPYC
#: against the recording machine); the integer encoder counts, shapes and dtypes are exact,
#: and a change of the loop would move the sums far more.
RTOL = 1e-12


def _close(got: dict, want: dict, where: str) -> None:
    assert got["dtype"] == want["dtype"] and got["shape"] == want["shape"], where
    scale = float.fromhex(want["abs_sum"]) / max(int(np.prod(want["shape"])), 1)
    exact = want["dtype"].startswith(("int", "uint", "bool"))
    for key in ("sum", "abs_sum"):
        a, b = float.fromhex(got[key]), float.fromhex(want[key])
        assert a == b if exact else abs(a - b) <= RTOL * float.fromhex(want["abs_sum"]), (
            where, key, a, b)
    for i, (x, y) in enumerate(zip(got["samples"], want["samples"], strict=True)):
        a, b = float.fromhex(x), float.fromhex(y)
        assert a == b if exact else abs(a - b) <= RTOL * max(abs(b), scale), (where, i, a, b)


@pytest.mark.parametrize("case", CASES)
def test_simulate_arm_is_bit_identical_to_the_recorded_runs(case):
    expected = json.loads(DATA.read_text())[case]
    got = _fingerprint(_runs(case))
    assert len(got) == len(expected)
    for r, (g, w) in enumerate(zip(got, expected, strict=True)):
        assert g["n"] == w["n"] and g["cycle_s"] == w["cycle_s"], (case, r)
        for name in FIELDS:
            _close(g[name], w[name], f"{case} run {r} {name}")


if __name__ == "__main__" and "--write" in sys.argv:
    fps = {c: _fingerprint(_runs(c)) for c in CASES}
    DATA.write_text(json.dumps(fps, separators=(",", ":")) + "\n")
