"""Issue 22 item 4, acceptance: the honest sigma covers the friction parameters of the paper
model on the simulated 6-axis arm with friction-dominated wrists and errors in variables
(tests/sigma_cases.py: 0.5 N m drive noise on the wrists acting before the friction's quadrant
decision, one 5 kg payload run), over 20 noise seeds: at least 80 % of the 2-sigma intervals
contain the truth (in the model's gauge), and never fewer than with eq. 15 alone. Both shares
are printed (benchmarks/sigma_coverage.py prints the table with the wrists apart).

Item 6: with the wrists' true Stribeck terms zero, the ones the fit finds are pruned and the
held-out error does not get worse (the issue: Stribeck terms with sigma of 63-161 % that
extrapolate wrongly at low speed).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
from sigma_cases import coverage, wrist_arm, wrist_signals

from ident.robot.estimate import RobotModel
from ident.robot.uncertainty import assess

SEEDS = range(100, 120)
#: Low-speed rows [rad/s] (the issue: the Stribeck terms extrapolate at 0.005-0.05 rad/s).
LOW_SPEED = 0.05


@pytest.mark.slow
def test_honest_sigma_covers_the_friction_parameters():
    out = coverage(SEEDS)
    print(f"\n2-sigma coverage over {len(SEEDS)} seeds: analytic {out['analytic']:.1%} "
          f"(wrists {out['wrist_analytic']:.1%}), honest {out['honest']:.1%} "
          f"(wrists {out['wrist_honest']:.1%})")
    assert out["honest"] >= 0.8, out
    assert out["honest"] >= out["analytic"], out
    # the joints flagged for errors in variables are wrists, the noisy joints
    flagged = {j for row in out["rows"] for j in row[7]}
    assert flagged and all(j.startswith("wrist") for j in flagged), flagged


def _low_speed_error(model, sig, vmax: float = LOW_SPEED) -> dict[str, float]:
    """||rho_j|| / ||tau_j|| on the rows with |dq_j| < vmax [rad/s] (finite torque)."""
    rho = sig.tau - model.predict(sig)
    out = {}
    for j, joint in enumerate(sig.joints):
        ok = np.isfinite(rho[:, j]) & (np.abs(sig.dq[:, j]) < vmax)
        out[joint] = float(np.linalg.norm(rho[ok, j]) / np.linalg.norm(sig.tau[ok, j]))
    return out


@pytest.mark.slow
def test_pruned_stribeck_terms_do_not_extrapolate():
    """The wrists without Stribeck terms (b = d = 0 there), the issue's noise: the paper model
    fits b, d on the wrists with relative sigma far above 30 %; they are pruned (held at 0,
    the model refitted), and on a held-out run (another noise draw) the error of the wrists
    whose dry friction is identified is not worse, neither on all rows nor at low speed
    (|dq| < 0.05 rad/s, where the Stribeck terms act)."""
    params, reg, base = wrist_arm(stribeck=False)
    sig, held = wrist_signals(params, reg, 300), wrist_signals(params, reg, 301)
    m = RobotModel(reg, "paper", "wls", base=base).fit(sig)
    full = copy.copy(m)  # (pruning refits in place: new coef_ arrays, the copy keeps the old)
    u = assess(m, sig)
    wrist_terms = [n for n in u.pruned if n[-1] in "456"
                   and n.rstrip("0123456789") in ("b_m", "b_g", "d_m", "d_g")]
    print(f"\npruned {u.pruned}\nunidentified {u.unidentified}")
    assert wrist_terms, u.pruned
    for n in u.pruned:
        assert m.params_[n] == 0.0
    e_full, e_pruned = full.rel_error(held), m.rel_error(held)
    l_full, l_pruned = _low_speed_error(full, held), _low_speed_error(m, held)
    print(f"held-out all rows: {e_full}\n pruned: {e_pruned}\nlow speed: {l_full}\n "
          f"pruned: {l_pruned}")
    # on every wrist whose dry friction itself is identified (a_m, a_g, c_m, c_g within the
    # threshold; on a wrist where the noise exceeds what its data can resolve nothing is
    # claimed); the shoulder and elbow keep their true Stribeck terms, pruned when weak: a
    # cost at low speed the docs report
    judged = [j for j, num in zip(reg.joints[3:], m.numbers_[3:], strict=True)
              if not any(f"{p}{num}" in u.unidentified for p in ("a_m", "a_g", "c_m", "c_g"))]
    assert judged
    for j in judged:
        assert e_pruned[j] <= 1.01 * e_full[j], (j, e_pruned[j], e_full[j])
        assert l_pruned[j] <= 1.01 * l_full[j], (j, l_pruned[j], l_full[j])
