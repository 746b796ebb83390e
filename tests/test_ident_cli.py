"""``jointid fit`` end to end on CSV files from the simulated joint: JSON record keys
(docs/fit-json.md), tables on stdout, report plots, validation, errors as one line."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from daq.app.cli import main

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def csv_runs(tmp_path_factory):
    from daq.protocol.control import ControllerGains
    from sim_drivers.offline import simulate
    from sim_drivers.plant_config import load_plant
    from trajectories.plan import plan_campaign
    from trajectories.robot_campaign import RobotCampaign

    with open(ROOT / "examples" / "campaign.toml", "rb") as f:
        campaign = RobotCampaign.from_dict(tomllib.load(f), "campaign.toml").quick()
    plan = plan_campaign(campaign)
    plant = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml")
    gains = ControllerGains(**campaign.gains_kwargs())
    d = tmp_path_factory.mktemp("csv")
    files = []
    for i, p in enumerate([*plan.payloads, plan.payloads[1]]):  # last: validation run
        r = simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                     payload_arm=p.arm_m, seed=40 + i)  # fmt: skip
        path = d / f"run{i}.csv"
        cols = [r.t, r.q, r.tau_ref, np.full(len(r), p.mass_kg), np.full(len(r), p.arm_m)]
        np.savetxt(path, np.column_stack(cols), delimiter=",", fmt="%.10g",
                   header="t,q,tau,payload_kg,payload_arm_m", comments="")  # fmt: skip
        files.append(path)
    return files


def test_fit_json_report_and_tables(csv_runs, tmp_path, capsys):
    js = tmp_path / "fit.json"
    rep = tmp_path / "report"
    args = ["fit", *map(str, csv_runs[:3]), "--validate", str(csv_runs[3]),
            "--json", str(js), "--report", str(rep)]  # fmt: skip
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "Identified values with the usual model" in out and "a_m_MX" in out
    assert "Relative norm of errors for 2 identifications" in out  # Table IV
    fit = json.loads(js.read_text())
    assert fit["format"] == "jointid-fit/2" and fit["joint"] == "revolute"
    for name in ("usual", "paper"):
        m = fit["models"][name]
        for key in ("rel_error", "rel_error_low_velocity", "rel_error_high_velocity",
                    "validation_rel_error"):  # fmt: skip
            assert isinstance(m[key], float) and 0 < m[key] < 0.2, (name, key)
        for p in m["parameters"].values():
            assert set(p) >= {"value", "std2", "rel_std_pct"}
        assert isinstance(m["removed"], list)
    assert fit["models"]["paper"]["rel_error"] < fit["models"]["usual"]["rel_error"]
    assert set(fit["table_iv"]) == {"with_payloads", "without_payload"}
    assert "Ma_ratio" in fit["models"]["usual"]["parameters"]
    assert (rep / "direct_validation_paper.png").stat().st_size > 10_000
    assert (rep / "cross_validation_usual.png").exists()
    # the report folder is complete: fit.json and a self-contained HTML report embedding
    # every figure, which `jointid report DIR` can rebuild
    assert json.loads((rep / "fit.json").read_text())["models"].keys() == {"usual", "paper"}
    html = (rep / "report.html").read_text()
    assert html.count("data:image/png;base64,") == len(list(rep.glob("*.png")))
    assert (rep / "tables.txt").read_text().startswith("Identified values")


def test_single_model_and_qs_scan(csv_runs, tmp_path):
    js = tmp_path / "fit.json"
    assert main(["fit", *map(str, csv_runs[:3]), "--model", "new", "--q-s", "scan",
                 "--json", str(js)]) == 0  # fmt: skip
    fit = json.loads(js.read_text())
    assert list(fit["models"]) == ["paper"]
    scan = fit["q_s_scan"]
    assert len(scan) >= 5
    best = min(scan, key=lambda s: s["rel_error"])
    assert fit["q_s"] == best["q_s"] == fit["models"]["paper"]["q_s"]


def test_missing_column_is_one_line_error(tmp_path, capsys):
    p = tmp_path / "bad.csv"
    p.write_text("t,q,current\n" + "\n".join(f"{k * 1e-3},0,0" for k in range(100)))
    assert main(["fit", str(p)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "bad.csv" in err and "'tau'" in err


def test_refine_flag_writes_refinement(csv_runs, tmp_path):
    pytest.importorskip("ident.refine")
    js = tmp_path / "fit.json"
    assert main(["fit", *map(str, csv_runs[:3]), "--refine", "--max-steps", "1",
                 "--json", str(js)]) == 0  # fmt: skip
    ref = json.loads(js.read_text())["refinement"]
    assert "steps" in ref and "rel_error_final" in ref


def test_method_names_are_the_robot_ones(csv_runs, tmp_path, capsys):
    """--method ls|wls|iv on one joint (issue 24): 'ols' (deprecated) is 'ls', 'wls' of one
    joint is 'ls' (one constant weight), the same numbers; iv without q_ref is one line."""
    recs = {}
    for method in ("ls", "ols", "wls"):
        js = tmp_path / f"{method}.json"
        assert main(["fit", *map(str, csv_runs[:3]), "--model", "usual", "--method", method,
                     "--json", str(js)]) == 0  # fmt: skip
        recs[method] = json.loads(js.read_text())["models"]["usual"]
    assert recs["ls"]["estimator"] == "ls"
    assert recs["ls"] == recs["ols"] == recs["wls"]
    capsys.readouterr()
    assert main(["fit", *map(str, csv_runs[:3]), "--method", "iv"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "q_ref" in err, err
