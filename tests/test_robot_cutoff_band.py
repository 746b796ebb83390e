"""The robot path's default cut-off (WLS: ``choose_cutoff``'s, at least 0.05 f_s) on logs
slower than 1 kHz, against the simulated arm's truth: the usual model, fitted by
``jointid fit --robot``'s defaults on the simulated drives' log subsampled to 500 Hz (cut-off
25 Hz) and 250 Hz (12.5 Hz, the real KUKA recordings' rate and cut-off), recovers the truth
within its stated sigma (sum of z^2 under the 0.999 quantile of chi^2, every |z| < 4) on two
seeds. The paper model does not, at any rate (docs/robot-identification.md, "The default
cut-off on logs slower than 1 kHz": its figures, ``benchmarks/bench_robot_cutoff_band.py``,
which takes this module's setup)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.stats
from robot_campaigns import ARM3
from test_robot_fit import PAYLOADS, _simulate

from ident.cli_robot import fit_files
from ident.loaders import RawRobotRun
from ident.robot.signals import RobotPayloadData
from sim_drivers.arm import ArmParams
from trajectories.robot import load_robot

#: The simulated runs' length [s] (each of the three payload runs).
DURATION_S = 20.0


def simulated(friction: str, seed: int, duration_s: float = DURATION_S) -> tuple:
    """(arm parameters, regressor, runs, truth) of the arm3 of tests/test_robot_fit.py at
    1 kHz with the ``"paper"`` friction on every joint or the ``"usual"`` one (a = 1,
    b = d = 0, c_g = c_m; the truth then has FC = c_m, the usual model's Coulomb term)."""
    law = None
    if friction == "usual":
        c = ArmParams.from_robot(load_robot(ARM3)).friction.c_m
        law = dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0, d_m=0.0, d_g=0.0, c_g=c)
    params, reg, _, runs = _simulate("arm3", law, duration_s, seed)
    truth = params.truth(None)
    if friction == "usual":
        truth.update({f"FC{j}": truth[f"c_m{j}"] for j in reg.numbers})
    return params, reg, runs, truth


def logged(params, runs, every: int, held: bool = False,
           suffix: str = "csv") -> list[RawRobotRun]:
    """The runs as the simulated drives log them (measured position, torque actual -- the
    command plus the ripple noise, whole per-mille of rated torque --, the reference), every
    ``every``-th sample. Each command is held over the cycle after its sample: the torque of
    sample k is the mean of the two held around its instant, so that the ``.csv`` files
    (torque delay 0) are timed right at every rate; ``held``: the held torque instead;
    ``suffix`` ``"mcap"``: the half-sample torque delay of jointid's logs."""
    step = params.drive.torque_per_permille  # [N m] per per-mille, (k,)
    k = slice(None, None, every)
    out = []
    for i, (r, p) in enumerate(zip(runs, PAYLOADS, strict=True)):
        pay = RobotPayloadData() if p is None else RobotPayloadData(p.mass, p.com, p.inertia)
        tau = np.round(r.tau_applied / step) * step
        if not held:  # at the sample instant
            tau = np.vstack([tau[:1], 0.5 * (tau[1:] + tau[:-1])])
        out.append(RawRobotRun(f"run{i}.{suffix}", r.t[k], r.q[k], tau[k], q_ref=r.q_ref[k],
                               payload=pay))
    return out


def z_scores(out: dict, model: str, truth: dict[str, float]) -> tuple[dict[str, float], int]:
    """z = (value - truth) / std of the fit record's parameters of ``model`` (``std``: the
    stated, honest sigma), the pruned ones left out; and the number pruned."""
    est = out["_estimators"][model]
    assert not est.fixed_, est.fixed_  # payload runs fix the scale: no gauge
    rec = out["models"][model]["parameters"]
    tv = est.truth_vector(truth)
    z = {n: (rec[n]["value"] - t) / rec[n]["std"]
         for n, t in zip(est.names_, tv, strict=True) if not rec[n]["pruned"]}
    return z, sum(r["pruned"] for r in rec.values())


def fit_default(params, reg, runs, every: int, cutoff_hz: float | None = None) -> dict:
    """``jointid fit --robot``'s defaults (both models, WLS, columns chain, sign check, honest
    sigma, pruning; no feasibility search, which changes no parameter) on the log kept every
    ``every``-th sample."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the cut-off at its lower bound: warned, expected
        return fit_files(reg.robot, logged(params, runs, every), model="both",
                         cutoff=cutoff_hz, feasibility=False)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_usual_model_at_the_default_cutoff_within_sigma_at_500_and_250_hz(seed):
    params, reg, runs, truth = simulated("usual", seed)
    for every, cut in ((2, 25.0), (4, 12.5)):
        out = fit_default(params, reg, runs, every)
        assert out["preprocessing"]["cutoff_hz"] == pytest.approx(cut)  # 0.05 f_s
        z, pruned = z_scores(out, "usual", truth)
        assert pruned == 0 and len(z) == 25, (pruned, sorted(z))
        chi2 = sum(v * v for v in z.values())
        # measured: 6 and 8 at 500 Hz, 23 and 22 at 250 Hz; largest |z| 2.2
        assert chi2 < scipy.stats.chi2.ppf(0.999, len(z)), (every, chi2, z)
        assert max(abs(v) for v in z.values()) < 4.0, (every, z)
