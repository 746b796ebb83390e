"""A parameter left out because its column is a linear combination of others is removed with
the single-joint reason naming its partners ("not separable: linear combination of A, B",
:func:`ident.estimate.fit_least_squares`), also on the robot model's path, whose rank rule
reads only the Gram matrix (:func:`ident.estimators.rank_rule`, the one rule of every model), and
by the single-joint
names when a joint is fitted as a 1-dof robot (:func:`ident.fitting.fit_models` through
:class:`ident.one_joint.OneJointProblem`)."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
import scipy.linalg
from example_campaign import ROOT

from daq.protocol.control import ControllerGains
from ident.estimators import RCOND, ZERO_COLUMN, dependent_columns, dependent_reason, rank_rule
from ident.fitting import fit_models
from ident.loaders import make_experiment
from ident.models import IdentModel
from ident.robot.estimate import renamed_reason
from sim_drivers.offline import simulate
from sim_drivers.plant_config import load_plant
from trajectories.plan import plan_campaign
from trajectories.robot_campaign import RobotCampaign

PREFIX = "not separable: linear combination of "
OLD = "not separable: linear combination of the other columns"


def _partners(why: str) -> list[str]:
    assert why.startswith(PREFIX), why
    return why[len(PREFIX):].split(", ")


def qr_rule_reference(W: np.ndarray, names: list[str]) -> dict[str, list[str]]:
    """The rank rule computed independently of :func:`rank_rule`, on the rows: column-pivoted
    QR of the unit-norm columns, kept while |R_kk| > RCOND |R_00|; a dependent column's
    partners are the kept columns whose coefficients (R11 a = R[:rank, k]) exceed 1e-3 of the
    largest, in pivot order (what ``dependent_columns`` computed before it read W^T W)."""
    norms = np.linalg.norm(W, axis=0)
    Ws = W / np.where(norms > 0, norms, 1.0)
    _, R, piv = scipy.linalg.qr(Ws, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > RCOND * d[0]))
    out = {}
    for k in range(rank, W.shape[1]):
        coef = np.abs(scipy.linalg.solve_triangular(R[:rank, :rank], R[:rank, k]))
        big = coef > 1e-3 * max(coef.max(), 1e-300)
        out[names[piv[k]]] = [names[piv[i]] for i in np.flatnonzero(big)]
    return out


def test_rank_rule_partners_are_the_rows_qr_ones():
    """From W^T W alone: the same dependent columns and partners as the column-pivoted QR of
    the rows (:func:`qr_rule_reference`), whatever the column scales; a kept column with a
    coefficient below 1e-3 of the largest (here 1e-6) is not a partner; a zero column has
    none. ``dependent_columns`` (the rows' entry point) gives the same."""
    rng = np.random.default_rng(3)
    W = rng.standard_normal((500, 7)) * [1.0, 1e3, 1e-2, 1.0, 5.0, 1.0, 1.0]
    W[:, 3] = 2.0 * W[:, 0] - 1e-3 * W[:, 1]  # a combination of 0 and 1
    W[:, 5] = 30.0 * W[:, 2] + 1e-6 * 6.0 * W[:, 4]  # of 2, and 4 negligibly
    W[:, 6] = 0.0
    names = [f"c{i}" for i in range(7)]
    dep, partners = rank_rule(W.T @ W)
    ref = qr_rule_reference(W[:, :6], names[:6])
    assert [names[i] for i in dep] == sorted([*ref, "c6"]) and len(ref) == 2
    assert 6 not in partners  # the zero column: ZERO_COLUMN, no partners
    for c, ps in partners.items():
        assert [names[p] for p in ps] == ref[names[c]]
    got = {frozenset({names[c], *(names[p] for p in ps)}) for c, ps in partners.items()}
    assert got == {frozenset({"c0", "c1", "c3"}), frozenset({"c2", "c5"})}  # c4: no partner
    assert dict(dependent_columns(W, names)) == {**ref, "c6": []}


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_rows_and_moments_decide_alike(seed):
    """Random regressors with random column scales (1e-3..1e3) and 1 to 3 exact dependencies:
    the rows' QR (:func:`qr_rule_reference`) and the Gram matrix (``dependent_columns``, the
    rule every model applies) leave out the same number of columns, each with the QR's
    partners (as a set) when the same column is left out; the kept columns have full rank."""
    rng = np.random.default_rng(seed)
    b = int(rng.integers(6, 12))
    W = rng.standard_normal((300, b))
    n_dep = int(rng.integers(1, 4))
    for k in range(n_dep):
        src = rng.choice(b - n_dep, size=2, replace=False)
        W[:, b - 1 - k] = rng.normal() * W[:, src[0]] + rng.normal() * W[:, src[1]]
    W = W * 10.0 ** rng.uniform(-3, 3, size=b)
    names = [f"c{i}" for i in range(b)]
    ref = qr_rule_reference(W, names)
    got = dict(dependent_columns(W, names))
    assert len(got) == len(ref) == n_dep
    for n in set(got) & set(ref):
        assert set(got[n]) == set(ref[n])  # the order: pivots, which rounding may swap
    kept = [i for i, n in enumerate(names) if n not in got]
    assert np.linalg.matrix_rank(W[:, kept] / np.linalg.norm(W[:, kept], axis=0)) == len(kept)


def test_reason_strings():
    """The reason reads as the single-joint one; renaming touches only the partner names."""
    assert dependent_reason(["A", "B"]) == PREFIX + "A, B"
    why = dependent_reason(["a_m_MX1_1", "a_m_ZZ1R_1"])
    assert renamed_reason(why, {"a_m_MX1_1": "a_m_MX", "a_m_ZZ1R_1": "a_m_J"}) == \
        PREFIX + "a_m_MX, a_m_J"
    assert renamed_reason(ZERO_COLUMN, {"zero": "x"}) == ZERO_COLUMN


@pytest.fixture(scope="module")
def loaded_run():
    """The example campaign's first loaded run alone (the default plant): one payload on
    every row, whose torque m r^2 ddq + m g r cos q is exactly a combination of the J and MX
    columns (arm along the link: not of MY)."""
    with open(ROOT / "examples" / "campaign.toml", "rb") as fh:
        campaign = RobotCampaign.from_dict(tomllib.load(fh), "examples/campaign.toml")
    plan = plan_campaign(campaign)
    plant = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml")
    p = next(p for p in plan.payloads if p.mass_kg > 0)
    r = simulate(plant, plan.reference, ControllerGains(**campaign.gains_kwargs()),
                 payload_mass=p.mass_kg, payload_arm=p.arm_m, seed=12)
    return make_experiment("loaded.csv", r.t, r.q, r.tau_ref, payload_mass=p.mass_kg,
                           payload_arm=p.arm_m)


def test_products_form_names_the_partners(loaded_run):
    """The paper model's products form on one joint: the payload torque's products a_m, b_m,
    a_g, b_g are fixed at 0, each naming the same products of J and MX -- by the robot's
    names in ``RobotModel.removed_``, by the single-joint names in fit_models -- and the
    same partners as the single-joint least squares (QR on the columns) names for the
    parameters it removes too."""
    kw = {"models": ["paper"], "payload": True, "sign_check": False}
    report = fit_models([loaded_run], table_iv=False, **kw)
    ours = report.models["paper"]
    robot = {n: set(_partners(why)) for n, why in ours.robot_.removed_}
    assert robot == {f"{p}1": {f"{p}_MX1_1", f"{p}_ZZ1R_1"}
                     for p in ("a_m", "b_m", "a_g", "b_g")}
    for removed in (ours.removed_,):
        assert [n for n, _ in removed] == ["a_m", "b_m", "a_g", "b_g"]
        for n, why in removed:
            assert OLD not in why and "_1" not in why
            assert sorted(_partners(why)) == [f"{n}_J", f"{n}_MX"], why
    # the single-joint least squares on the same design: removes a_m, a_g, b_g too (and
    # b_m_MX instead of b_m: its rank rule pivots on the products, not the load columns)
    name = "paper"
    ref = IdentModel(report.models[name].library, name).fit(report.designs[name])
    single = {n: set(_partners(why)) for n, why in ref.removed_}
    mine = {n: set(_partners(why)) for n, why in ours.removed_}
    both = set(single) & set(mine)
    assert both >= {"a_m", "a_g", "b_g"}
    assert all(single[n] == mine[n] for n in both)


@pytest.mark.parametrize("eliminate", [True, False])
def test_one_payload_in_every_run_is_removed_not_an_error(loaded_run, eliminate):
    """Every run carries the same payload (the default ``payload=None`` sees a mass): its
    ratio's column (eq. 35) is a combination of J and MX. The single-joint least squares
    removed ``Ma_ratio`` with that reason; through the robot model the rank rule now runs
    before the first solve (the sign check's first usual fit included), with or without the
    elimination, so fit_models gives the same fit instead of refusing the data as not
    identifiable: the usual model's values and error equal the single-joint least squares' on
    the same design to 1e-8, the paper model's error too (it removes the payload's products,
    an equivalent choice of the dependent columns)."""
    report = fit_models([loaded_run], table_iv=False, eliminate=eliminate)
    usual = report.models["usual"]
    assert [n for n, _ in usual.removed_][:1] == ["Ma_ratio"]
    assert sorted(_partners(usual.removed_[0][1])) == ["J", "MX"]
    for name, m in report.models.items():
        ref = IdentModel(m.library, name).fit(report.designs[name], eliminate=eliminate)
        assert m.rel_error_ == pytest.approx(ref.rel_error_, rel=1e-8), name
        assert "Ma_ratio" not in m.names_ and "a_m" not in m.names_
        if name == "usual":
            assert m.names_ == ref.names_
            for n in ref.names_:
                assert m.coef_[n] == pytest.approx(ref.coef_[n], rel=1e-8), n
    assert any("not identifiable on these data: Ma_ratio" in n for n in report.notes)
