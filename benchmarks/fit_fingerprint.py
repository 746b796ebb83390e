"""Fingerprints of ``fit_models``' output, to compare two versions bit for bit.

    python benchmarks/fit_fingerprint.py > before.txt   # then, on the other version:
    python benchmarks/fit_fingerprint.py > after.txt && diff before.txt after.txt

Nine configurations: the example campaign (seed 11, three payload runs) with LS, IDIM-IV
(MCAP-named runs with references), validation files, ``q_s="scan"``, ``like=`` that scan at
another q_s, no sign check and ``tau_min``; the EMPS data (``../shared/data/emps``, skipped
when absent) with the reference script's settings plus its pulses file as validation, and
with the defaults. Per configuration one SHA-256 of the report's JSON (every float's repr),
one of its printed tables, and one per array of every model's design and validation design
(Y, W, Z, the decimated dq). Any changed float shows as a changed line.
"""

from __future__ import annotations

import hashlib
import json
import sys
import warnings
from pathlib import Path

import numpy as np

from ident.fitting import fit_models
from ident.loaders import load_experiment, make_experiment

ROOT = Path(__file__).resolve().parents[1]


def _h(x) -> str:
    if isinstance(x, str):
        return hashlib.sha256(x.encode()).hexdigest()[:16]
    if x is None:
        return "none"
    return hashlib.sha256(np.ascontiguousarray(x, dtype=float).tobytes()).hexdigest()[:16]


def _print(name: str, rep) -> None:
    print(name, "json", _h(json.dumps(rep.to_json(), sort_keys=True, default=repr)))
    print(name, "tables", _h(rep.format_tables()))
    for kind, designs in (("design", rep.designs), ("validation", rep.validation_designs)):
        for m, d in sorted(designs.items()):
            print(name, kind, m, len(d), " ".join(d.names))
            for what, a in (("Y", d.Y), ("W", d.W), ("Z", d.Z), ("dq", d.signals.dq)):
                print(name, kind, m, what, _h(a))


def campaign_runs(seed: int = 11) -> tuple[list, list]:
    """The example campaign simulated offline (``tests/example_campaign.py``, which must be
    importable): its three payload runs as CSV-named experiments (LS) and as MCAP-named ones
    with their references (IDIM-IV, half-cycle torque delay)."""
    from example_campaign import simulate_example_campaign

    _, plan, sims = simulate_example_campaign(seed)
    refs = [plan.reference.q[np.minimum(r.cycle, plan.reference.q.size - 1)] for r in sims]

    def exps(suffix: str, ref: bool) -> list:
        return [make_experiment(f"payload{i}.{suffix}", r.t, r.q, r.tau_ref,
                                q_ref=q if ref else None, payload_mass=p.mass_kg,
                                payload_arm=p.arm_m)
                for i, (p, r, q) in enumerate(zip(plan.payloads, sims, refs, strict=True))]

    return exps("csv", False), exps("mcap", True)


def main() -> None:
    warnings.simplefilter("ignore")
    ls, iv = campaign_runs()
    _print("ls", fit_models(ls))
    _print("iv", fit_models(iv))
    _print("ls_validation", fit_models(ls[:2], validation=ls[2:]))
    scan = fit_models(ls, q_s="scan")
    _print("scan", scan)
    _print("like", fit_models(ls, like=scan, q_s=0.05))
    _print("no_sign_check", fit_models(ls, sign_check=False))
    _print("tau_min", fit_models(ls, tau_min=2.0))
    emps = (ROOT.parent / "shared").resolve() / "data" / "emps"
    if not emps.is_dir():
        print("emps skipped: ../shared/data/emps absent")
        return

    def load(name: str):
        return load_experiment(emps / name, mapping={"q": "qm", "tau": "vir"}, gain="gtau",
                               joint="prismatic")

    _print("emps_script", fit_models([load("DATA_EMPS.mat")],
                                     validation=[load("DATA_EMPS_PULSES.mat")],
                                     cutoff_hz=100.0, decimation=10))
    _print("emps_defaults", fit_models([load("DATA_EMPS.mat")]))


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT / "tests"))
    main()
