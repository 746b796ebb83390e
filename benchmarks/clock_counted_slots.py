"""The time base's readings of irregular stamps (:func:`ident.timebase.uniform_grid`) on real
data: the figures of docs/robot-data.md and docs/fit-json.md ("Irregular time stamps").

Usage: ``python benchmarks/clock_counted_slots.py [--demo-logs DIR]``

The real EMPS run (``../shared/data/emps/DATA_EMPS.mat``) under host clocks: clean; a random
walk (steps dt (1 + s e), e normal; s = 3 %, seeds 1 and 2; s = 1 %, seed 1) alone, with 1
sample lost (index 12000), 5 spread (4000, 8000, ... 20000), a burst of 10 (every other sample
over 12000-12019) and 10 in a row (12000-12009); white jitter without drift (stamps k dt + dt
u, u uniform in +-0.1; seeds 1 and 2; seed 1 also with sample 12000 lost). Each is fitted with
the reference script's preprocessing (usual model, 100 Hz, decimation 10; the usual model's
relative error [%]) and printed with the reading the loader took (its warning, cut). Then the
KUKA recordings (``../shared``, axis A3 of A, B, C, as the README's single-joint command,
usual model) and, with ``--demo-logs``, the MCAP logs of ``jointid demo --quick --out DIR``
(paper model): their ResamplingWarnings (expected none) and their fit.
"""

from __future__ import annotations

import argparse
import tempfile
import warnings
from pathlib import Path

import numpy as np
import scipy.io as sio

from ident import DataError
from ident.api import JointModel, load
from ident.loaders import ResamplingWarning

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
KW = dict(mapping={"q": "qm", "tau": "vir"}, gain="gtau", joint="prismatic")
FIT = dict(model="usual", cutoff=100, decimation=10, dq_min=0, sign_check=False)
SPREAD = (4000, 8000, 12000, 16000, 20000)


def _stamps(t: np.ndarray, kind: str, s: float, seed: int) -> np.ndarray:
    """The time column [s] of ``kind`` (clean, rw: random walk, jitter: white, no drift)."""
    dt = float(np.median(np.diff(t)))
    rng = np.random.default_rng(seed)
    if kind == "rw":
        return np.r_[t[0], t[0] + np.cumsum(dt * (1 + s * rng.standard_normal(t.size - 1)))]
    if kind == "jitter":
        return t + dt * s * rng.uniform(-1, 1, t.size)
    return t.copy()


def _fit(paths: list[Path], kwargs: dict, fit: dict) -> tuple[float | None, list[str]]:
    """The fit's relative error [%] (None: refused) and the ResamplingWarnings (or the
    refusal)."""
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        try:
            exps = load(paths, **kwargs)
        except DataError as exc:
            return None, [f"refused: {exc}"]
    msgs = [str(w.message) for w in rec if issubclass(w.category, ResamplingWarning)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return 100 * JointModel(**fit).fit(exps).rel_error_, msgs


def emps(tmp: Path) -> None:
    m = sio.loadmat(DATA / "emps" / "DATA_EMPS.mat")
    t0 = m["t"].ravel()
    cases: list[tuple[str, str, float, int, tuple[int, ...]]] = [("clean", "clean", 0, 0, ())]
    for s, seed in ((0.03, 1), (0.03, 2), (0.01, 1)):
        tag = f"random walk {100 * s:g} %, seed {seed}"
        cases += [(tag, "rw", s, seed, ()),
                  (tag + ", 1 lost", "rw", s, seed, (12000,)),
                  (tag + ", 5 lost spread", "rw", s, seed, SPREAD),
                  (tag + ", burst of 10 lost", "rw", s, seed, tuple(range(12000, 12020, 2))),
                  (tag + ", 10 lost in a row", "rw", s, seed, tuple(range(12000, 12010)))]
    cases += [("jitter +-10 %, seed 1", "jitter", 0.1, 1, ()),
              ("jitter +-10 %, seed 1, 1 lost", "jitter", 0.1, 1, (12000,)),
              ("jitter +-10 %, seed 2", "jitter", 0.1, 2, ())]
    for i, (name, kind, s, seed, lost) in enumerate(cases):
        cols = {k: v for k, v in m.items() if not k.startswith("__")}
        cols["t"] = _stamps(t0, kind, s, seed)[:, None]
        for k in ("t", "qm", "qg", "vir"):
            cols[k] = np.delete(cols[k], list(lost), axis=0)
        path = tmp / f"emps_{i}.mat"
        sio.savemat(path, cols)
        err, msgs = _fit([path], KW, FIT)
        how = msgs[0].split(": ", 1)[1][:260] if msgs else "regular: no warning"
        print(f"EMPS {name:45s} {'-' if err is None else f'{err:.3f} %':>9s}  {how}", flush=True)


def regular(demo_logs: Path | None) -> None:
    data = DATA / "kuka_kr300_weigand2021"
    files = [data / f"recorded_2020-10-21_FF_{x}_08ms.mat" for x in "ABC"]
    kw = dict(mapping={"t": "rec.time_cont", "q": "rec.act_pos_mot_deg[2]",
                       "q_ref": "rec.ref_pos_deg[2]", "tau": "rec.act_torque_abs_nm[2]"},
              gain="para.u[2]", q_unit="deg")
    runs = [("KUKA A3 (A, B, C), usual, 5 Hz, decimation 4", files, kw,
             dict(model="usual", cutoff=5, decimation=4))]
    if demo_logs is not None:
        runs.append(("demo logs, paper", sorted(demo_logs.glob("*.mcap")), {},
                     dict(model="paper")))
    for name, paths, kwargs, fit in runs:
        err, msgs = _fit(paths, kwargs, fit)
        print(f"{name:50s} {'-' if err is None else f'{err:.4f} %':>10s}  "
              f"ResamplingWarnings: {len(msgs)}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--demo-logs", type=Path, default=None,
                    help="the logs folder of `jointid demo --quick --out DIR` (DIR/logs)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        emps(Path(tmp))
    regular(args.demo_logs)


if __name__ == "__main__":
    main()
