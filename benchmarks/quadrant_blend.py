"""The paper model's quadrant decision near zero load, on the CLI's chain (findings of
docs/robot-identification.md, "Known limit: quadrants blended by the low-pass").

    python benchmarks/quadrant_blend.py ur10 LOGDIR      # jointid run of the UR10 demo campaign
    python benchmarks/quadrant_blend.py ur10 LOGDIR --robot examples/robots/arm3.toml
    python benchmarks/quadrant_blend.py kuka             # ../shared KUKA recording A

``ur10``: LOGDIR holds the two payload logs of ``examples/campaign_ur10_demo.toml`` run on
the simulator (``jointid run examples/campaign_ur10_demo.toml --simulate --out LOGDIR``, or the
``model_logs`` of ``benchmarks/bench_monitor.py``). The paper model (WLS, no pruning, as
``jointid fit --robot ... --no-prune``) is fitted with

* the default quadrant band (3 % of each joint's RMS predicted load),
* bands of 0, 10 % and 30 % of it,
* the quadrants decided by the simulator's true theta (``quadrant_theta``),
* a band of 3 x the torque's RMS above the chain's cut-off per joint ("jitter"),
* without the sign check (``fit_files(sign_check=False)``),

and each fit's parameters are compared with the simulator's truth (in the model's gauge):
how many of the 100 lie outside 3 sigma, and the shoulder pan's friction terms. A check that
needs no truth is printed too: how far each parameter moves when the band widens from 3 % to
30 % of the RMS load, in sigmas of the wider fit (|theta_30 - theta_3| / sigma_30, a bound on
Hausman's statistic, which divides by sqrt(sigma_30^2 - sigma_3^2)): where the narrow band's
rows are blended it moves.
``kuka``: the torque above the cut-off per axis against the default band, and whether the
jitter band leaves the fit identifiable (it does not).
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import numpy as np  # noqa: E402
from sigma_cases import gauged_truth  # noqa: E402

from ident import IdentError  # noqa: E402
from ident.api_robot import RobotFit  # noqa: E402
from ident.chain import lowpass  # noqa: E402
from ident.cli_robot import load_runs  # noqa: E402
from ident.robot.estimate import RobotModel  # noqa: E402
from sim_drivers.arm import ArmParams  # noqa: E402
from trajectories.robot import load_robot  # noqa: E402

KUKA_DIR = ROOT.parent / "shared" / "data" / "kuka_kr300_weigand2021"
KUKA_MAP = "t=rec.time_cont,q=rec.act_pos_mot_deg,tau=rec.act_torque_abs_nm,q_ref=rec.ref_pos_deg"
PAN_TERMS = ("b_m1", "b_g1", "c_m1", "d_m1", "c_g1", "d_g1")


def jitter(fit: RobotFit, runs: list) -> np.ndarray:
    """RMS of raw minus low-passed torque per joint [N m], at the fit's cut-off."""
    fc = float(fit.settings_["cutoff_hz"])
    ss, n = 0.0, 0
    for r in runs:
        tau = np.asarray(r.tau, dtype=float)
        fs = 1.0 / float(np.median(np.diff(r.t)))
        lp = np.stack([lowpass(tau[:, j], fc, fs) for j in range(tau.shape[1])], axis=1)
        d = tau - lp
        ss = ss + np.nansum(d**2, axis=0)
        n += tau.shape[0]
    return np.sqrt(ss / n)


def jitter_model(base: RobotModel, jit: np.ndarray, times: float = 3.0) -> RobotModel:
    """``base``'s hyper-parameters, its band the larger of 3 % RMS load and times x jit."""

    class _Jitter(RobotModel):
        def _rms_load(self, moms, theta):
            return np.maximum(super()._rms_load(moms, theta),
                              times * jit / float(self.quadrant_band))

    return _Jitter(**base.get_params())


def report(tag: str, m: RobotModel, params) -> None:
    tv = gauged_truth(m, params)
    z = (m.coef_ - tv) / m.std_
    names = list(m.names_)
    pan = "  ".join(f"{n} {m.coef_[names.index(n)]:.2f}+-{m.std_[names.index(n)]:.2f} "
                    f"(truth {tv[names.index(n)]:.2f}, z {z[names.index(n)]:+.1f})"
                    for n in PAN_TERMS)
    print(f"{tag:<22} |z| > 3: {int(np.sum(np.abs(z) > 3)):>2} of {len(z)}; rows per joint "
          f"{m.n_samples_.tolist()}\n    {pan}", flush=True)


def band_shift(base: RobotModel, wide: RobotModel, params) -> None:
    """Per joint, the largest |theta_wide - theta| / sigma_wide and its parameter; the
    parameters outside 3 sigma of the truth with it."""
    tv = gauged_truth(base, params)
    shift = np.abs(wide.coef_ - base.coef_) / np.where(wide.std_ > 0, wide.std_, np.inf)
    z = (base.coef_ - tv) / base.std_
    names = list(base.names_)
    print("band 3 % -> 30 %: largest shift / sigma_30 per joint (|z| > 3 against the truth):")
    for j, joint in enumerate(base.joints_):
        idx = [i for i, n in enumerate(names) if n[-1:] == str(j + 1) or
               n.endswith(f"{j + 1}R")]
        i = max(idx, key=lambda i: shift[i])
        far = ", ".join(f"{names[i]} {z[i]:+.1f}" for i in idx if abs(z[i]) > 3) or "none"
        print(f"    {joint:<22} {shift[i]:.1f} ({names[i]})   {far}")


def ur10(logdir: Path, robot_file: Path) -> None:
    files = sorted(logdir.glob("*.mcap"))
    if not files:
        sys.exit(f"{logdir}: no .mcap logs")
    fit = RobotFit(robot_file, model="paper", consistency=False, prune=False).fit(files)
    base, sig = fit.models_["paper"], fit.signals_
    truth = ArmParams.from_robot(load_robot(robot_file))
    report("default (3 % RMS load)", base, truth)
    for frac in (0.0, 0.1, 0.3):
        p = base.get_params()
        p.update(quadrant_band=frac)
        report(f"band {frac:.0%} RMS load", RobotModel(**p).fit(sig), truth)
    p = base.get_params()
    p.update(quadrant_theta=gauged_truth(base, truth)[:base.n_theta_])
    report("true-theta quadrants", RobotModel(**p).fit(sig), truth)
    p = base.get_params()
    p.update(quadrant_band=0.3)
    band_shift(base, RobotModel(**p).fit(sig), truth)
    report("no sign check", RobotFit(robot_file, model="paper", consistency=False, prune=False,
                                     sign_check=False).fit(files).models_["paper"], truth)
    runs = load_runs(load_robot(robot_file), files)
    jit = jitter(fit, runs)
    print("torque above the cut-off [N m]:", np.round(jit, 3).tolist())
    m = jitter_model(base, jit).fit(sig)
    print("jitter band [N m]:", np.round(m.band_, 3).tolist())
    report("band 3 x jitter", m, truth)


def kuka() -> None:
    if not KUKA_DIR.is_dir():
        sys.exit(f"{KUKA_DIR}: absent")
    robot_file = ROOT / "examples" / "robots" / "kuka_kr300_r2500.toml"
    files = [KUKA_DIR / "recorded_2020-10-21_FF_A_08ms.mat"]
    fit = RobotFit(robot_file, model="paper", consistency=False, prune=False, q_unit="deg",
                   mapping=KUKA_MAP).fit(files)
    base = fit.models_["paper"]
    from trajectories.robot import load_robot

    runs = load_runs(load_robot(robot_file), files, mapping=fit._mapping(), q_unit="deg")
    jit = jitter(fit, runs)
    print("default band [N m]:", np.round(base.band_, 1).tolist(), "rows",
          base.n_samples_.tolist())
    print("torque above the cut-off [N m]:", np.round(jit, 1).tolist())
    for times in (1.0, 3.0):
        try:
            m = jitter_model(base, jit, times).fit(fit.signals_)
            print(f"band {times:g} x jitter: rows {m.n_samples_.tolist()}")
        except IdentError as e:
            print(f"band {times:g} x jitter: {e}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", choices=("ur10", "kuka"))
    ap.add_argument("logdir", nargs="?", type=Path)
    ap.add_argument("--robot", type=Path, default=ROOT / "examples" / "robots" / "ur10.toml",
                    help="robot file of the simulated logs (the first joint's terms are shown)")
    a = ap.parse_args()
    warnings.simplefilter("ignore")
    if a.case == "ur10":
        if a.logdir is None:
            ap.error("ur10 needs LOGDIR")
        ur10(a.logdir, a.robot)
    else:
        kuka()


if __name__ == "__main__":
    main()
