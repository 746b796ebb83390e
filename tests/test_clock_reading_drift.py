"""Which reading of irregular stamps :func:`ident.loaders.uniform_grid` takes when the stamps
drift off a uniform grid by more than half a period with one step per period (a random-walk
clock: steps dt (1 + s e), e normal). The uniform reading (the values as sampled, on the
stamps' least-squares line) is then a candidate too, and the positions' noise above f_s/4 in
each reading, neither resampled, chooses:

* the real EMPS run (``../shared``; skipped without it) under a random-walk host clock
  (s = 1 % and 3 %, seeds 1-3) is read as uniformly sampled and fits as the original file
  (within 1.1x of its 4.035 %; read at the stamps it gave 7.7-20.1 %);
* the simulated joint's values taken at random-walk instants (stamps true) keep the stamp
  reading, chosen by the noise (not by the band), and fit as the clean file; the same drive's
  uniformly sampled values under random-walk stamps are read as uniform and fit as the clean
  file too (read at their stamps, s = 1 %: 1.5 % for 0.355 %).

An added sample (no candidate: the stamp reading stays) is in
tests/test_mends_clock_drift.py; lost samples, counted into their slots, in
tests/test_clock_counted_slots.py."""

from __future__ import annotations

import re
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.io as sio

from daq.protocol.control import ControllerGains
from ident.api import JointModel, load
from ident.loaders import ResamplingWarning
from sim_drivers.offline import simulate
from sim_drivers.plant_config import load_plant
from tests.conftest import shared_path
from trajectories.plan import plan_campaign
from trajectories.robot_campaign import RobotCampaign

ROOT = Path(__file__).resolve().parents[1]
KW = dict(mapping={"q": "qm", "tau": "vir"}, gain="gtau", joint="prismatic")
# the reference script's preprocessing (tests/test_ident_emps.py)
FIT = dict(model="usual", cutoff=100, decimation=10, dq_min=0, sign_check=False)
DRIFT = "taken as a drifting clock's stamps of uniformly sampled values"


def random_walk(n: int, s: float, seed: int, dt: float) -> np.ndarray:
    """n stamps from 0 [s], each step dt (1 + s e), e standard normal."""
    e = np.random.default_rng(seed).standard_normal(n - 1)
    return np.r_[0.0, np.cumsum(dt * (1 + s * e))]


def _fit(data) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return JointModel(**FIT).fit(data).rel_error_


def emps_data() -> tuple:
    """DATA_EMPS.mat (scipy.io) and the usual model's error on it as read (``FIT``)."""
    path = shared_path("data", "emps") / "DATA_EMPS.mat"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return sio.loadmat(path), _fit(load(path, **KW))


@pytest.fixture(scope="module")
def emps():
    return emps_data()


@pytest.mark.parametrize("s", [0.01, 0.03])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_walk_clock_on_emps_is_read_as_uniform_and_fits_as_the_original(
        emps, tmp_path, s, seed):
    m, ref = emps
    t = m["t"].ravel()
    ts = t[0] + random_walk(t.size, s, seed, float(np.median(np.diff(t))))
    path = tmp_path / "rw.mat"
    sio.savemat(path, {**{k: v for k, v in m.items() if not k.startswith("__")},
                       "t": ts[:, None]})
    with pytest.warns(ResamplingWarning) as rec:
        (e,) = load(path, **KW)
    (msg,) = [str(w.message) for w in rec if issubclass(w.category, ResamplingWarning)]
    err = _fit([e])
    assert err <= 1.1 * ref, (err, ref, msg)
    np.testing.assert_array_equal(e.q, m["qm"].ravel())  # the values as sampled
    assert DRIFT in msg, msg
    off = float(re.search(r"up to ([0-9.]+) periods off", msg).group(1))
    assert off > 0.5, msg  # beyond the half-period band: the case the band alone refused


# -- a drive whose values were taken at the stamps (the simulated joint) ----------------------


@pytest.fixture(scope="module")
def quick_runs():
    """The quick example campaign on the default plant: three payload runs (closed loop,
    encoder-quantised q, the logged torque reference) at 1 kHz."""
    with open(ROOT / "examples" / "campaign.toml", "rb") as f:
        campaign = RobotCampaign.from_dict(tomllib.load(f), "campaign.toml").quick()
    plan = plan_campaign(campaign)
    plant = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml")
    gains = ControllerGains(**campaign.gains_kwargs())
    runs = [(simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                      payload_arm=p.arm_m, seed=70 + i), p)
            for i, p in enumerate(plan.payloads)]
    return runs, plant.drive.counts_per_joint_rad


def _files(d: Path, runs, cpr: float, kind: str, s: float, seed: int) -> list[Path]:
    """CSV files of the runs: ``clean``; ``instants``: the values taken at random-walk
    instants (the true position interpolated there and quantised by the encoder, the torque
    reference interpolated; stamps exact); ``stamps``: the drive's values under random-walk
    stamps (a host clock stamping its cycles)."""
    out = []
    for i, (r, p) in enumerate(runs):
        t, q, tau = r.t, r.q, r.tau_ref
        if kind != "clean":
            ts = r.t[0] + random_walk(r.t.size, s, 100 * seed + i, float(np.median(np.diff(r.t))))
            t = ts[ts <= r.t[-1]]
            if kind == "instants":
                q = np.round(np.interp(t, r.t, r.q_true) * cpr) / cpr
                tau = np.interp(t, r.t, r.tau_ref)
            else:
                q, tau = q[:t.size], tau[:t.size]
        path = d / f"{kind}_{i}.csv"
        np.savetxt(path, np.column_stack([t, q, tau, np.full(t.size, p.mass_kg),
                                          np.full(t.size, p.arm_m)]),
                   delimiter=",", fmt="%.10g", header="t,q,tau,payload_kg,payload_arm_m",
                   comments="")
        out.append(path)
    return out


def _sim_fit(files: list[Path]) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return JointModel(model="paper").fit(load(files)).rel_error_


@pytest.fixture(scope="module")
def clean_error(quick_runs, tmp_path_factory):
    runs, cpr = quick_runs
    return _sim_fit(_files(tmp_path_factory.mktemp("clean"), runs, cpr, "clean", 0, 0))


@pytest.mark.parametrize("s", [0.01, 0.03])
@pytest.mark.parametrize("seed", [1, 2])
def test_values_at_random_walk_instants_keep_the_stamp_reading(quick_runs, clean_error,
                                                               tmp_path, s, seed):
    """Stamps true: the uniform reading is a candidate (one step per period) and loses on the
    noise, so the values are interpolated at their stamps and fit as the clean file."""
    runs, cpr = quick_runs
    files = _files(tmp_path, runs, cpr, "instants", s, seed)
    with pytest.warns(ResamplingWarning) as rec:
        load(files[0])
    (msg,) = [str(w.message) for w in rec if issubclass(w.category, ResamplingWarning)]
    assert "values taken at their stamps: their noise above f_s/4 is" in msg, msg
    err = _sim_fit(files)
    assert err <= 1.1 * clean_error, (err, clean_error)


@pytest.mark.parametrize("s", [0.01, 0.03])
@pytest.mark.parametrize("seed", [1, 2])
def test_drive_values_under_random_walk_stamps_are_read_as_uniform(quick_runs, clean_error,
                                                                   tmp_path, s, seed):
    """The same drive's uniformly sampled values under a random-walk host clock: read as
    uniform (judged without resampling either reading: interpolated, the stamp reading's
    quantisation noise was averaged and won at s = 1 %), and fit as the clean file."""
    runs, cpr = quick_runs
    files = _files(tmp_path, runs, cpr, "stamps", s, seed)
    err = _sim_fit(files)
    assert err <= 1.1 * clean_error, (err, clean_error)
    with pytest.warns(ResamplingWarning, match=re.escape(DRIFT)):
        (e,) = load(files[0])
    np.testing.assert_allclose(e.q, runs[0][0].q[:e.q.size], rtol=0, atol=1e-9)
