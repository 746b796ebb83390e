"""A random-walk host clock on the real EMPS data (``../shared``; skipped without it): every
period of the stamps errs by s (1 % or 3 %, normal, seeds 1 and 2) on its own, so the stamps
drift off a uniform grid by more than half a period and the loader reads the values at their
stamps. Its warning gives the measured spread of the steps (the injected s within 5 %: the
sample std of 24840 steps has a relative sd of 0.45 %), says the errors accumulate, and that
the values taken as uniformly sampled are quieter above f_s/4. That advice is checked: the
copy with a uniform time column fits as the original file does, the stamped copy several
times worse (19.5 % against 4.0 % at 3 %, seed 1)."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
import scipy.io as sio

from ident.api import JointModel, load
from ident.loaders import ResamplingWarning
from tests.conftest import shared_path

KW = dict(mapping={"q": "qm", "tau": "vir"}, gain="gtau", joint="prismatic")
# the reference script's preprocessing (tests/test_ident_emps.py)
FIT = dict(model="usual", cutoff=100, decimation=10, dq_min=0, sign_check=False)


def _copy(tmp_path, s: float, seed: int, uniform: bool = False):
    """DATA_EMPS.mat with t_k = t_0 + sum of dt (1 + s e_i), e normal (``uniform``: the
    least-squares line through those stamps instead)."""
    m = sio.loadmat(shared_path("data", "emps") / "DATA_EMPS.mat")
    t = m["t"].ravel()
    dt = float(np.median(np.diff(t)))
    e = np.random.default_rng(seed).standard_normal(t.size - 1)
    ts = np.r_[t[0], t[0] + np.cumsum(dt * (1 + s * e))]
    if uniform:
        k = np.arange(ts.size)
        ts = np.polyval(np.polyfit(k, ts, 1), k)
    out = {k: v for k, v in m.items() if not k.startswith("__")}
    out["t"] = ts[:, None]
    path = tmp_path / f"emps_rw_{s}_{seed}{'_uniform' if uniform else ''}.mat"
    sio.savemat(path, out)
    return path


@pytest.mark.parametrize("s", [0.01, 0.03])
@pytest.mark.parametrize("seed", [1, 2])
def test_random_walk_clock_warning_gives_the_ratio(tmp_path, s, seed):
    path = _copy(tmp_path, s, seed)
    with pytest.warns(ResamplingWarning) as rec:
        load(path, **KW)
    (msg,) = [str(w.message) for w in rec if issubclass(w.category, ResamplingWarning)]
    m = re.search(r"the steps vary ([0-9.]+) % of the period \(std\)", msg)
    assert m, msg
    assert float(m.group(1)) == pytest.approx(100 * s, rel=0.05), msg
    assert "values taken at their stamps" in msg, msg
    assert "accumulating" in msg and "give a uniform time column" in msg, msg
    lower = float(re.search(r"would be ([0-9.e+]+)x lower", msg).group(1))
    assert lower > 10, msg


def test_the_advice_holds(tmp_path):
    """A uniform time column (the stamps' least-squares line) fits as the original file; the
    stamps read as instants at least twice as badly."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = JointModel(**FIT).fit(load(shared_path("data", "emps") / "DATA_EMPS.mat", **KW))
        stamped = JointModel(**FIT).fit(load(_copy(tmp_path, 0.03, 1), **KW))
        uniform = JointModel(**FIT).fit(load(_copy(tmp_path, 0.03, 1, uniform=True), **KW))
    assert uniform.rel_error_ == pytest.approx(ref.rel_error_, rel=0.01)
    assert stamped.rel_error_ > 2 * ref.rel_error_, (stamped.rel_error_, ref.rel_error_)
