"""The single-joint fit evaluates the 1-dof regressor once per run at full rate (issue 24).

:class:`ident.one_joint.OneJointProblem` keeps the full-rate regressor the columns chain
evaluated (:class:`ident.robot.design.FullRateColumns`): the load prediction of the sign
check and quadrants and the full-rate products read it instead of evaluating it again, and
the paper model's design at another q_s than the combined design's takes its columns from
the products (:meth:`~ident.one_joint.OneJointProblem.paper_columns`) instead of evaluating
the rigid body and payload terms again. Checked here: the count of full-rate evaluations
per run (the cache's own counter), and that the fits and designs are the same floats as
without the reuse (the cache bounded to 0 bytes: every evaluation made again; the terms
evaluated). The validation files' designs go through the robot chain too
(``ident.fitting._other_designs``): once per validation run, the same floats as
:func:`ident.preprocess.build_design`'s.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from example_campaign import simulate_example_campaign

from ident.fitting import _combined_library, _part, fit_models
from ident.loaders import concat, make_experiment
from ident.models import Payload, RigidBody, usual_model
from ident.one_joint import OneJointProblem
from ident.preprocess import TORQUE_DELAY, build_design
from ident.terms import Library, Term

QS0, QS1 = 0.03, 0.05  # [rad/s]: the design's q_s and another


@pytest.fixture(scope="module")
def campaign():
    """The example campaign simulated offline (seed 11): each run as an experiment with its
    reference position (the planned trajectory at its cycles) [rad]."""
    _, plan, sims = simulate_example_campaign(11)
    refs = [plan.reference.q[np.minimum(r.cycle, plan.reference.q.size - 1)] for r in sims]
    exps = [make_experiment(f"payload{i}.mcap", r.t, r.q, r.tau_ref, q_ref=q,
                            payload_mass=p.mass_kg, payload_arm=p.arm_m)
            for i, (p, r, q) in enumerate(zip(plan.payloads, sims, refs, strict=True))]
    return exps, refs


def _problem(campaign, iv: bool, full_bytes: int | None = None) -> OneJointProblem:
    exps, refs = campaign
    kw = {} if full_bytes is None else {"full_bytes": full_bytes}
    return OneJointProblem(exps, revolute=True, has_payload=True,
                           references=refs if iv else None, paper=True,
                           torque_delay=TORQUE_DELAY, **kw)


def _fits(problem: OneJointProblem) -> list[np.ndarray]:
    """The usual fit and the paper fit at two q_s (the products formed for each)."""
    return [problem.fit("usual").robot.coef_, problem.fit("paper", QS0).robot.coef_,
            problem.fit("paper", QS1).robot.coef_]


@pytest.mark.parametrize("iv", [False, True])
def test_regressor_evaluated_once_per_run(campaign, iv: bool) -> None:
    """The chain's evaluation is the only one (sign check, quadrant load, products at two
    q_s); bounded to 0 bytes, each run is evaluated three times (the chain, the load model,
    the products) and every fit is the same floats."""
    n = len(campaign[0])
    kept = _problem(campaign, iv)
    fits = _fits(kept)
    assert kept.full_columns.evaluations == dict.fromkeys(range(n), 1)
    assert kept.full_columns.nbytes > 0
    again = _problem(campaign, iv, full_bytes=0)
    fits0 = _fits(again)
    assert again.full_columns.nbytes == 0
    assert again.full_columns.evaluations == dict.fromkeys(range(n), 3)
    for a, b in zip(fits, fits0, strict=True):
        assert np.array_equal(a, b)


class _NotEvaluated(Term):
    """A term with the given names whose columns must come from given decimated rows."""

    def __init__(self, names: tuple[str, ...]) -> None:
        self._names = names

    def names(self) -> tuple[str, ...]:
        return self._names

    def columns(self, s):  # noqa: ANN001, ANN201 - Signals
        raise AssertionError(f"{self._names}: evaluated")


@pytest.mark.parametrize("iv", [False, True])
def test_paper_design_at_another_qs_from_products(campaign, iv: bool) -> None:
    """The paper design at another q_s than the combined design's (``ident.fitting._part``,
    a q_s scan's fit) takes its quadrant columns from the robot chain's products at that q_s:
    the same floats as the terms evaluated on the design's full-rate signals, no full-rate
    evaluation of the regressor, and the rigid body and payload terms not evaluated."""
    exps, refs = campaign
    problem = _problem(campaign, iv)
    sig = concat(exps)
    inner = Library(*[t for t in usual_model(True, payload=True).terms()
                      if isinstance(t, RigidBody | Payload)])
    values = problem.load_values()
    load_model = (inner, np.array([values.get(n, 0.0) for n in inner.names()]))
    full = problem.design(_combined_library(["usual", "paper"], QS0, True, True), sig,
                          load_model=load_model,
                          sign_check=not problem.model_quadrant)
    assert (full.Z is not None) == iv
    given = problem.paper_columns(QS1, load_model)
    assert given is not None
    lib, reused = _part(full, "paper", True, QS1, QS0,
                        lambda q: problem.paper_columns(q, load_model))
    _, evaluated = _part(full, "paper", True, QS1, QS0)
    assert reused.names == evaluated.names == tuple(
        n for n in full.names if n in set(lib.names()))
    for what in ("Y", "W", "Z"):
        a, b = getattr(reused, what), getattr(evaluated, what)
        assert (a is None and b is None) or np.array_equal(a, b), what
    assert problem.full_columns.evaluations == dict.fromkeys(range(len(exps)), 1)
    # the given rows only: a term that cannot be evaluated
    quad = [n for n in reused.names if n[:3] in ("a_m", "b_m", "a_g", "b_g", "c_m", "d_m",
                                                 "c_g", "d_g")]
    bare = full.without([n for n in full.names if n in quad])
    out = bare.with_term(_NotEvaluated(tuple(quad)), decimated=given)
    assert np.array_equal(out.W[:, -len(quad):], evaluated.W[:, [evaluated.names.index(n)
                                                                 for n in quad]])


def test_fit_models_evaluates_once_and_releases(campaign) -> None:
    """``fit_models`` with a q_s scan (the paper design at another q_s than the combined
    design's): each run's regressor evaluated once at full rate, and released once the fits
    are made (the report holds no full-rate regressor)."""
    exps, _ = campaign
    rep = fit_models(exps, q_s="scan")
    assert rep.q_s != rep.qs_design
    kept = rep.robot_signals["paper"].columns.full_columns
    assert kept.evaluations == dict.fromkeys(range(len(exps)), 1)
    assert kept.nbytes == 0 and kept.get(0) is None


def test_validation_designs_evaluate_once_per_run(campaign) -> None:
    """``fit_models`` with a validation file and a q_s scan (the paper design at another q_s
    than the combined design's): the validation run's regressor is evaluated once at full
    rate (before: three to four times -- the load model, the rigid body and payload terms,
    the paper model's terms, again at the scan's q_s; ``benchmarks/full_rate_calls.py``),
    released afterwards, and every validation design is the same floats as
    :func:`~ident.preprocess.build_design`'s with the fit's settled settings (the terms
    evaluated); :meth:`~ident.fitting.FitReport.designs_for` gives the same designs."""
    exps, _ = campaign
    val = exps[2:]
    rep = fit_models(exps[:2], validation=val, q_s="scan")
    assert rep.q_s != rep.qs_design and set(rep.validation_designs) == {"usual", "paper"}
    kept = rep.validation_signals.columns.full_columns
    assert kept.evaluations == dict.fromkeys(range(len(val)), 1)
    assert kept.nbytes == 0 and kept.get(0) is None
    assert rep.validation_signals.columns.full is None
    pre = {k: v for k, v in rep.settings.items() if k != "quadrant_load"}
    lib = _combined_library(list(rep.models), rep.qs_design, True, rep.has_payload)
    terms = build_design(lib, concat(val), **pre)
    again = rep.designs_for(val)
    for name, d in rep.validation_designs.items():
        ref = _part(terms, name, rep.has_payload, rep.q_s, rep.qs_design)[1]
        assert d.names == ref.names == again[name].names
        for what in ("Y", "W", "Z"):
            a, b, c = getattr(d, what), getattr(ref, what), getattr(again[name], what)
            assert (a is None and b is None and c is None) or (
                np.array_equal(a, b) and np.array_equal(a, c)), (name, what)


@pytest.mark.slow
def test_designs_for_is_the_validation_design_with_the_band(tmp_path) -> None:
    """The friction-dominated joint (tests/test_friction_dominated.py: the sign check
    skipped, the paper model's quadrant band), two runs fitted and the third as validation:
    ``designs_for`` gives the validation designs, the band's rows left out too (before:
    without the band, 9527 rows against 9055 at seed 1), and the validation run's regressor
    is evaluated once."""
    from test_friction_dominated import friction_dominated

    from sim_drivers.offline import simulate

    root = Path(__file__).resolve().parents[1]
    txt = (root / "sim_drivers" / "data" / "plant_default.toml").read_text()
    plant, plan, gains = friction_dominated(txt, tmp_path / "plant.toml", "fd")
    exps = []
    for i, p in enumerate(plan.payloads):
        r = simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                     payload_arm=p.arm_m, seed=1 + i)
        exps.append(make_experiment(f"p{i}.csv", r.t, r.q, r.tau_ref,
                                    payload_mass=p.mass_kg, payload_arm=p.arm_m))
    rep = fit_models(exps[:2], validation=exps[2:], table_iv=False)
    assert rep.band_nm > 0 and any(n.startswith("sign check skipped") for n in rep.notes)
    again = rep.designs_for(exps[2:])
    assert len(again["paper"]) < len(again["usual"])  # the band's rows left out
    for name, d in rep.validation_designs.items():
        assert d.names == again[name].names
        for what in ("Y", "W"):
            assert np.array_equal(getattr(d, what), getattr(again[name], what)), (name, what)
    kept = rep.validation_signals.columns.full_columns
    assert kept.evaluations == {0: 1}


def test_table_iv_problem_reuses_the_fits_runs(campaign) -> None:
    """Table IV's fit without payload (a problem on the runs without payload, the fit's
    settled settings and first fit) takes those runs' full-rate signals and regressor from
    the fit's problem (:meth:`~ident.one_joint.OneJointProblem.reuse_for`): no evaluation of
    its own, and the same floats as filtering and evaluating them again."""
    exps, _ = campaign
    main = _problem(campaign, False)
    empty = [i for i, e in enumerate(exps) if float(e.payload_mass) == 0]
    assert 0 < len(empty) < len(exps)
    st = main.settings
    kw = dict(revolute=True, has_payload=False, references=None, paper=True,
              torque_delay=TORQUE_DELAY, sign_check=False, first=main.first,
              first_checked=main.sign_checked, model_quadrant=True, cutoff_hz=st.cutoff_hz,
              decimation=st.decimation, dq_min=st.dq_min, trim=st.trim, guard=st.guard)
    sub = [exps[i] for i in empty]
    reused = OneJointProblem(sub, reuse=main.reuse_for(empty), **kw)
    fresh = OneJointProblem(sub, **kw)
    assert reused.full_rate()[0] is main.full_rate()[empty[0]]
    fits, fits0 = _fits(reused), _fits(fresh)
    assert reused.full_columns.evaluations == {}
    assert fresh.full_columns.evaluations == dict.fromkeys(range(len(empty)), 1)
    for a, b in zip(fits, fits0, strict=True):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("payload, method", [("known", "ls"), ("ratio", "ls"),
                                             ("mass", "ls"), ("known", "iv")])
def test_robot_fit_evaluates_once_and_releases(payload: str, method: str) -> None:
    """``jointid fit --robot`` (``fit_robot``, columns chain, both models, sign check): each
    run's regressor evaluated once at full rate -- the chain's, kept
    (``design_runs(keep_full=True)``) for the sign check's load -- and released after it:
    the record's signals hold neither the full-rate signals nor the regressor."""
    import warnings
    from pathlib import Path

    from ident.cli_robot import fit_robot
    from ident.robot.loaders import RawRobotRun, RobotPreprocessing
    from ident.robot.signals import RobotPayloadData
    from sim_drivers.arm import ArmGains, ArmParams, model_reference, simulate_arm
    from sim_drivers.arm import Payload as ArmPayload
    from trajectories.robot import load_robot

    # the 3-dof arm of benchmarks/full_rate_calls.py: two 6 s runs, no payload and 5 kg
    robot = load_robot(Path(__file__).resolve().parents[1] / "examples" / "robots"
                       / "arm3.toml")
    params = ArmParams.from_robot(robot)
    ref = model_reference(params.model, center=[0.0, -1.9, 0.6], fraction=0.9,
                          duration_s=6.0, seed=3)
    runs = []
    for i, mass in enumerate((0.0, 5.0)):
        pay = ArmPayload(mass, [0.0, 0.0, 0.05]) if mass else None
        r = simulate_arm(params, ref, ArmGains.for_params(params, payload=pay), payload=pay,
                         seed=30 + i)
        runs.append(RawRobotRun(f"run{i}.csv", r.t, r.q_true, r.tau_applied, q_ref=r.q_ref,
                                payload=RobotPayloadData(mass, [0.0, 0.0, 0.05]) if mass
                                else RobotPayloadData()))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = fit_robot(robot, runs, models=("usual", "paper"), method=method,
                        payload=payload, preprocessing=RobotPreprocessing(
                            torque_delay=TORQUE_DELAY), feasibility=False, sigma_blocks=0)
    assert "paper" in out["_estimators"]
    for sig in (out["_identification"], out["_signals"][0]):
        cols = sig.columns
        assert cols.full is None
        assert cols.full_columns.evaluations == dict.fromkeys(range(len(runs)), 1)
        assert cols.full_columns.nbytes == 0 and cols.full_columns.get(0) is None
