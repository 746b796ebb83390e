"""The two fixes of the paper model's overconfident sigma on the simulated arm together: the
soft quadrant weight in the estimator (``RobotModel(quadrants="soft")``) with the chain's
compact-support FIR anti-alias (``ChainSettings.antialias = "fir"``)
(docs/robot-identification.md, after "The soft quadrant weight in the estimator").

Usage: ``python benchmarks/robot_soft_fir.py [--seeds 1 2] [--more 3] [--no-usual]``

arm3, paper friction, three payload runs of 20 s, the drives' log at 1 kHz
(tests/test_robot_cutoff_band.py's ``simulated`` and ``logged``), fitted with
``jointid fit --robot``'s defaults (tests/test_robot_cutoff_band.py's ``fit_default``) except
``quadrants="soft"`` (no pruning in soft mode: every parameter counted), paper model only,
with three anti-alias filters: ``cheby`` (the default), ``fir`` (guard its half-length, 188
samples for r = 20) and ``fir 30 dB`` (benchmarks/robot_paper_fir.py's ``--atten 30``: guard
77). The filter goes in by benchmarks/robot_paper_fir.py's ``_Antialias`` (nothing else
changes). Printed per seed and filter: per joint the sum of z^2 (number of parameters), the
largest |z| and its parameter; the whole arm's sum against the 0.999 quantile of chi^2; the
soft sigma_j; the rows kept per joint (of the decimated rows); the sign check's notes; and
whether tests/test_robot_paper_sigma.py's criterion holds (sum of z^2 under the quantile,
every |z| < 4).

A filter whose criterion holds on every seed of ``--seeds`` is run on the ``--more`` seeds
too and (unless ``--no-usual``) against tests/test_robot_cutoff_band.py's criterion of the
usual model (usual friction simulated, logs at 500 and 250 Hz, default cut-off) with that
filter.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import os
import sys
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import scipy.stats  # noqa: E402
from robot_paper_fir import _Antialias, _kaiser  # noqa: E402
from robot_paper_fir import fit as fit_filtered  # noqa: E402
from robot_soft_quadrant import _sigmas  # noqa: E402
from test_robot_cutoff_band import logged, simulated, z_scores  # noqa: E402

import ident.chain as chain  # noqa: E402
from ident import DataError  # noqa: E402
from ident.cli_robot import fit_files  # noqa: E402
from ident.robot import RobotIdentError  # noqa: E402
from ident.robot.paper import PAPER_BLOCK  # noqa: E402

#: (label, filter, the FIR's attenuation [dB] or None for the chain's own design)
VARIANTS = (("cheby", "cheby", None), ("fir", "fir", None), ("fir 30 dB", "fir", 30.0))


@contextlib.contextmanager
def _filter(name: str, atten: float | None) -> Iterator[None]:
    """The chain's anti-alias ``name`` within the block; ``atten``: the shorter Kaiser FIR
    (benchmarks/robot_paper_fir.py's ``--atten``)."""
    own = chain.fir_antialias
    if atten is not None:
        chain.fir_antialias = functools.lru_cache(maxsize=8)(
            functools.partial(_kaiser, atten=atten))
    try:
        with _Antialias(name):
            yield
    finally:
        chain.fir_antialias = own


def soft_fit(reg, exps, name: str, atten: float | None) -> tuple[dict | str, float]:
    """``fit_default`` with ``quadrants="soft"``, paper model only, the filter; seconds. The
    one-line error instead when it refuses."""
    t0 = time.perf_counter()
    with warnings.catch_warnings(), _filter(name, atten):
        warnings.simplefilter("ignore")
        try:
            out = fit_files(reg.robot, exps, model="paper", feasibility=False,
                            quadrants="soft")
        except (DataError, RobotIdentError) as exc:
            return str(exc), time.perf_counter() - t0
    return out, time.perf_counter() - t0


def holds(z: dict[str, float]) -> bool:
    """tests/test_robot_paper_sigma.py's (and test_robot_cutoff_band.py's) criterion."""
    chi2 = sum(v * v for v in z.values())
    return chi2 < scipy.stats.chi2.ppf(0.999, len(z)) and max(map(abs, z.values())) < 4.0


def paper(seed: int, variants=VARIANTS) -> dict[str, bool]:
    """The soft paper fit with each filter on ``seed``: printed; whether the criterion held."""
    params, reg, sim, truth = simulated("paper", seed)
    exps = logged(params, sim, 1)
    print(f"arm3, paper friction, 1 kHz, seed {seed}, quadrants soft "
          "(chi^2 0.999 quantile: 29.6 for 10)", flush=True)
    ok = {}
    for label, name, atten in variants:
        out, dt = soft_fit(reg, exps, name, atten)
        if isinstance(out, str):
            print(f"  {label}: refused: {out}", flush=True)
            ok[label] = False
            continue
        z, pruned = z_scores(out, "paper", truth)
        assert pruned == 0, pruned  # soft mode does not prune
        rec = out["models"]["paper"]
        if "error" in rec:
            print(f"  {label}: refused: {rec['error']}", flush=True)
            ok[label] = False
            continue
        n = out["_identification"].n
        chi2 = sum(v * v for v in z.values())
        top = max(z, key=lambda k: abs(z[k]))
        ok[label] = holds(z)
        print(f"  {label}: guard {out['preprocessing'].get('guard')} samples, "
              f"{dt:.1f} s; whole arm sum z^2 {chi2:.1f} ({len(z)}; quantile "
              f"{scipy.stats.chi2.ppf(0.999, len(z)):.1f}), largest |z| {top} {z[top]:+.1f}; "
              f"criterion holds: {ok[label]}", flush=True)
        for j in reg.numbers:
            zz = {k: v for k, v in z.items() if k in {f"{p}{j}" for p in PAPER_BLOCK}}
            tj = max(zz, key=lambda k: abs(zz[k]))
            print(f"    joint {j}: {sum(v * v for v in zz.values()):7.1f} ({len(zz)}), "
                  f"largest {tj} {zz[tj]:+.1f}; rows kept "
                  f"{rec['samples'][reg.joints[reg.numbers.index(j)]]} of {n}")
        print(f"    sigma_j [N m]: {_sigmas(out['_estimators']['paper'], reg.joints)}")
        for note in out["notes"]:
            if note.startswith("sign check"):
                print(f"    {note}")
    return ok


def usual(seed: int, name: str, atten: float | None) -> None:
    """tests/test_robot_cutoff_band.py's criterion of the usual model with the filter."""
    params, reg, sim, truth = simulated("usual", seed)
    for every in (2, 4):
        with _filter(name, atten):
            out, dt = fit_filtered(reg, logged(params, sim, every), name)
        if isinstance(out, str):
            print(f"  usual model, seed {seed}, {1000 // every} Hz: refused: {out}")
            continue
        z, pruned = z_scores(out, "usual", truth)
        top = max(z, key=lambda k: abs(z[k]))
        print(f"  usual model, seed {seed}, {1000 // every} Hz, guard "
              f"{out['preprocessing'].get('guard')}: sum z^2 "
              f"{sum(v * v for v in z.values()):.1f} ({len(z)}, pruned {pruned}; quantile "
              f"{scipy.stats.chi2.ppf(0.999, len(z)):.1f}), largest |z| {top} {z[top]:+.1f}; "
              f"criterion holds: {holds(z) and pruned == 0}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="*", default=[1, 2])
    ap.add_argument("--more", type=int, nargs="*", default=[3])
    ap.add_argument("--no-usual", action="store_true")
    a = ap.parse_args()
    held = {label: True for label, _, _ in VARIANTS}
    for s in a.seeds:
        for label, ok in paper(s).items():
            held[label] &= ok
    good = [v for v in VARIANTS if held[v[0]]]
    print("criterion held on seeds " + " ".join(map(str, a.seeds)) + ": "
          + (", ".join(v[0] for v in good) or "none"), flush=True)
    for s in a.more if good else ():
        paper(s, good)
    if good and not a.no_usual:
        print("usual friction simulated, usual model (tests/test_robot_cutoff_band.py)")
        for label, name, atten in good:
            print(f" {label}:")
            for s in (1, 2):
                usual(s, name, atten)


if __name__ == "__main__":
    main()
