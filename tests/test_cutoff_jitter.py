"""Issue 22 item 2: ``choose_cutoff`` on a log with jittered time stamps (values taken at the
true, jittered instants): taken as uniform, the differences of q are broadband noise and the
rule reaches its 0.4 f_s ceiling -- which is now warned about with the reason; given the time
stamps, q is resampled first and the choice is the one of the same motion sampled uniformly."""

from __future__ import annotations

import numpy as np
import pytest

from ident.preprocess import choose_cutoff

FS = 1000.0


def _motion(t: np.ndarray) -> np.ndarray:
    """Sum of sines up to 1.5 Hz [rad], quantised like a 4096-count encoder behind N = 100."""
    f = np.array([0.1, 0.37, 0.8, 1.5])
    a = np.array([0.8, 0.3, 0.1, 0.03])
    q = (a * np.sin(2 * np.pi * np.outer(t, f) + np.arange(4))).sum(1)
    step = 2 * np.pi / (4096 * 100)
    return np.round(q / step) * step


@pytest.mark.parametrize("jitter", [0.2, 0.3])
def test_jittered_stamps(jitter):
    rng = np.random.default_rng(7)
    n = 20000
    tu = np.arange(n) / FS
    t = tu + rng.uniform(-jitter, jitter, n) / FS
    t[0] = 0.0
    q = _motion(t)
    dt = float(np.median(np.diff(t)))
    reference = choose_cutoff(_motion(tu), 1 / FS)
    with pytest.warns(UserWarning, match="upper bound 0.4 f_s"):
        naive = choose_cutoff(q, dt, source="log.csv")
    assert naive == pytest.approx(0.4 / dt, rel=1e-3)
    resampled = choose_cutoff(q, dt, t=t)
    assert 0.5 * reference <= resampled <= 2 * reference, (resampled, reference)
    assert resampled < 0.1 / dt
