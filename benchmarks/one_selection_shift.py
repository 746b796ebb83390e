"""The sign-check shift on single joints (:mod:`ident.robot.selection_shift` through
:func:`ident.fitting.fit_models`): the figures of docs/robot-identification.md, "The
sign-check shift", on one joint.

Usage: ``python benchmarks/one_selection_shift.py [--demo DIR]``

Per case, ``fit_models``' defaults unless said: the share of rows the sign check left out (or
that it was skipped), the number of paper-model parameters compared, the largest |z| and the
parameters beyond ``SHIFT_Z`` (the note), the reported fit's chi^2 against the simulator's
truth (where there is one) and the extra fit's CPU time against the whole fit's (one BLAS
thread). Cases: the example campaign (seeds 11 and 12; LS on CSV-named runs, IDIM-IV on
MCAP-named runs with their references, as tests/example_campaign.py and
benchmarks/fit_fingerprint.py), the same LS runs at q_s = 0.05 (the truth's is 0.03), the quick
example campaign with IDIM-IV (seeds 3 and 4, every parameter kept and with the elimination:
tests/test_one_selection_shift.py), the friction-dominated joint of
tests/test_friction_dominated.py (seeds 1 and 21) and the real EMPS (../shared, when present).
``--demo DIR``: also the shift recorded in a ``jointid demo --out DIR`` (its ``fit.json``,
against the truth in its ``demo.json``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import ident.fitting as fitting  # noqa: E402
from ident.robot.selection_shift import SHIFT_Z  # noqa: E402

_SHIFT = fitting._sign_check_shift
_CPU = [0.0]


def _timed(*args, **kwargs):
    t0 = time.process_time()
    try:
        return _SHIFT(*args, **kwargs)
    finally:
        _CPU[0] += time.process_time() - t0


def _row(label: str, exps: list, truth: dict | None = None, **kwargs) -> None:
    _CPU[0] = 0.0
    t0 = time.process_time()
    rep = fitting.fit_models(exps, **kwargs)
    cpu = time.process_time() - t0
    z = rep.sign_check_shift
    check = next((n for n in rep.notes if n.startswith("sign check")), "no sign check")
    check = (check.split(" of the samples")[0].removeprefix("sign check: ") + " left out"
             if check.startswith("sign check: ") else "skipped" if "skipped" in check
             else check)
    if z is None:
        print(f"{label:44s} check {check:16s} no shift recorded", flush=True)
        return
    big = sorted(z, key=lambda n: -abs(z[n]))
    beyond = [f"{n} {z[n]:+.1f}" for n in big if abs(z[n]) > SHIFT_Z]
    m = rep.models["paper"]
    fit = ""
    if truth is not None:
        fit = " truth " + _against(truth, {n: (m.coef_[n], m.std_[n]) for n in m.names_})
    if m.removed_:
        fit += (f" eliminated {', '.join(n for n, _ in m.removed_)}; not compared "
                f"{', '.join(n for n in m.names_ if n not in z) or 'none'};")
    print(f"{label:44s} check {check:16s} {len(z):2d} compared, max |z| {abs(z[big[0]]):.2f} "
          f"({big[0]}), beyond: {', '.join(beyond) or 'none'};{fit} extra fit "
          f"{_CPU[0]:.3f} s of {cpu:.2f} s CPU", flush=True)


def _against(truth: dict, fit: dict) -> str:
    """chi^2 of ``fit`` (name -> (value, std)) against ``truth``, and its largest z's."""
    z = {n: (v - truth[n]) / sd for n, (v, sd) in fit.items()}
    big = sorted(z, key=lambda n: -abs(z[n]))[:2]
    return (f"chi2 {sum(v * v for v in z.values()):.1f}/{len(z)} "
            f"({', '.join(f'{n} {z[n]:+.1f}' for n in big)});")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--demo", type=Path, help="a jointid demo --out directory")
    args = p.parse_args()
    warnings.simplefilter("ignore")
    fitting._sign_check_shift = _timed
    from example_campaign import payload_experiments
    from fit_fingerprint import campaign_runs
    from test_friction_dominated import friction_dominated
    from test_one_selection_shift import _quick_campaign

    from ident.loaders import load_experiment
    from sim_drivers.plant_config import load_plant

    truth = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml").truth()
    for seed in (11, 12):
        ls, iv = campaign_runs(seed)
        _row(f"example campaign seed {seed}, LS", ls, truth)
        _row(f"example campaign seed {seed}, IDIM-IV", iv, truth)
        if seed == 11:
            _row("example campaign seed 11, LS, q_s = 0.05", ls, q_s=0.05)
    for seed in (3, 4):
        exps, _ = _quick_campaign(seed)
        _row(f"quick campaign seed {seed}, IDIM-IV, all kept", exps, truth, eliminate=False,
             table_iv=False)
        _row(f"quick campaign seed {seed}, IDIM-IV", exps, truth, table_iv=False)
    txt = (ROOT / "sim_drivers" / "data" / "plant_default.toml").read_text()
    with tempfile.TemporaryDirectory() as d:
        fplant, fplan, fgains = friction_dominated(txt, Path(d) / "plant.toml", "fd")
    for seed in (1, 21):
        exps = payload_experiments(fplant, fplan, fgains, seed, name="f{i}.csv")
        _row(f"friction-dominated joint seed {seed}", exps, models=("paper",), table_iv=False)
    emps = ROOT.parent / "shared" / "data" / "emps" / "DATA_EMPS.mat"
    if emps.is_file():
        e = load_experiment(emps, mapping={"q": "qm", "tau": "vir"}, gain="gtau",
                            joint="prismatic")
        _row("EMPS (real), defaults", [e])
    if args.demo is not None:
        fit = json.loads((args.demo / "fit.json").read_text())
        demo_truth = json.loads((args.demo / "demo.json").read_text())["truth"]
        rec = fit["models"]["paper"]
        z = rec.get("sign_check_shift") or {}
        big = sorted(z, key=lambda n: -abs(z[n]))
        pars = {n: (v["value"], v["std"]) for n, v in rec["parameters"].items()}
        check = next((n.split(" of the samples")[0].removeprefix("sign check: ")
                      for n in fit["notes"] if n.startswith("sign check: ")), "none")
        print(f"{'jointid demo (fit.json)':44s} check {check + ' left out':16s} "
              f"{len(z):2d} compared, beyond: "
              f"{', '.join(f'{n} {z[n]:+.1f}' for n in big if abs(z[n]) > SHIFT_Z) or 'none'}; "
              f"truth {_against(demo_truth, pars)}", flush=True)


if __name__ == "__main__":
    main()
