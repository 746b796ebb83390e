"""The robot path's paper model against the simulated arm's truth at 1 kHz, with
``jointid fit --robot``'s defaults (WLS, columns chain, sign check, honest sigma, pruning):
what its stated sigma should hold to, as the usual model does in
tests/test_robot_cutoff_band.py (sum of z^2 under the 0.999 quantile of chi^2, every
|z| < 4, two seeds). It does not today: the gravity-free base yaw's load jitters across zero
under the closed loop, so the low-pass blends its friction's quadrants, and c_g1 comes out
+40.7 and +22.6 sigma high (sum of z^2 2150 and 1011; docs/robot-identification.md, "The
default cut-off on logs slower than 1 kHz", ``benchmarks/robot_paper_blend.py``). Strict
xfail: the day a change makes the sigma hold, this fails and the mark goes."""

from __future__ import annotations

import pytest
import scipy.stats
from test_robot_cutoff_band import fit_default, simulated, z_scores


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="known limit: the base yaw's quadrants blended by the "
                   "low-pass (docs/robot-identification.md)")
@pytest.mark.parametrize("seed", [1, 2])
def test_paper_model_at_1khz_within_its_sigma(seed):
    params, reg, runs, truth = simulated("paper", seed)
    out = fit_default(params, reg, runs, 1)
    z, pruned = z_scores(out, "paper", truth)
    chi2 = sum(v * v for v in z.values())
    # measured 2026-11-28: 2150 / 40 and 1011 / 43 (c_g1 +40.7, +22.6)
    assert chi2 < scipy.stats.chi2.ppf(0.999, len(z)), (chi2, len(z), pruned)
    assert max(abs(v) for v in z.values()) < 4.0, z
