"""The robot path's torque delay (``jointid fit --robot --torque-delay``, ``RobotFit(
torque_delay=)``, ``fit_files(torque_delay=)``): the name and unit of the single-joint
``fit_models(torque_delay=)`` [samples of the log's period].

Data: tests/test_robot_cutoff_band.py's simulated arm3 with the usual friction, the drives'
log with each command held over the 1 kHz cycle after its sample (``logged(held=True)``): the
torque is half a 1 kHz cycle, 0.5 ms, after the position sample, 0.5 samples at 1 kHz and
0.125 at 250 Hz (every 4th sample kept). Given that delay, the usual model fitted by
``jointid fit --robot``'s defaults is within its stated sigma (sum of z^2 under the 0.999
quantile of chi^2, every |z| < 4) at 1 kHz and 250 Hz on two seeds; a ``.csv`` file's
default (0) is not at 1 kHz, and a jointid log's (half a sample) is further off at 250 Hz
(docs/robot-identification.md, "The default cut-off on logs slower than 1 kHz";
``benchmarks/bench_robot_cutoff_band.py --held --torque-delay hold``). Then the command line
and the API: the JSON's ``preprocessing`` says the delay used and whether it was given, and a
bad delay is one line naming the flag; the single-joint ``jointid fit`` takes the same flag."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.stats
from robot_campaigns import ARM3
from test_robot_cutoff_band import logged, simulated, z_scores

from daq.app.cli import main
from ident import DataError
from ident.api import RobotFit
from ident.cli_robot import fit_files
from sim_drivers.arm_offline import write_robot_csv

#: Every n-th sample of the 1 kHz log kept: 250 Hz.
EVERY = 4
#: The hold's delay: half a 1 kHz cycle [samples at 250 Hz].
HOLD = 0.5 / EVERY


def _fit(params, reg, runs, every: int, suffix: str, torque_delay: float | None) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the cut-off at its lower bound: warned, expected
        return fit_files(reg.robot, logged(params, runs, every, True, suffix), model="both",
                         torque_delay=torque_delay, feasibility=False)


def _judged(out: dict, truth: dict[str, float], given: float | None) -> tuple[float, float]:
    """(sum of z^2, its chi^2 0.999 quantile) of the usual model, every parameter kept; the
    record says the delay used and whether given."""
    pre = out["preprocessing"]
    assert pre["torque_delay_given"] is (given is not None), pre
    if given is not None:
        assert pre["torque_delay"] == given, pre
    z, pruned = z_scores(out, "usual", truth)
    assert pruned == 0 and len(z) == 25, (pruned, sorted(z))
    chi2 = sum(v * v for v in z.values())
    return chi2, float(scipy.stats.chi2.ppf(0.999, len(z)))


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_held_log_within_sigma_with_the_given_delay(seed):
    params, reg, runs, truth = simulated("usual", seed)
    # 1 kHz, .csv files: the default 0 misses the hold's half cycle (F_V 6-9 sigma low,
    # measured: sum z^2 273 and 199); given, 0.5 sample: within sigma (3 and 3)
    chi2, bound = _judged(_fit(params, reg, runs, 1, "csv", None), truth, None)
    assert chi2 > bound, chi2
    out = _fit(params, reg, runs, 1, "csv", 0.5)
    chi2, bound = _judged(out, truth, 0.5)
    z = z_scores(out, "usual", truth)[0]
    assert chi2 < bound and max(abs(v) for v in z.values()) < 4.0, (chi2, z)
    # 250 Hz: the hold is a quarter of that, 0.125 sample (measured 33 and 10; largest |z|
    # 2.7); a jointid log's default, half a sample, puts the torque 1.5 ms late (64 and 22:
    # beyond the quantile on seed 1 only, so only compared)
    out = _fit(params, reg, runs, EVERY, "mcap", HOLD)
    chi2, bound = _judged(out, truth, HOLD)
    z = z_scores(out, "usual", truth)[0]
    assert chi2 < bound and max(abs(v) for v in z.values()) < 4.0, (chi2, z)
    late, _ = _judged(_fit(params, reg, runs, EVERY, "mcap", None), truth, None)
    assert late > chi2, (late, chi2)


def _write_csv(run, path: Path) -> Path:
    """A RawRobotRun as a robot CSV (docs/robot-data.md: t, q1..qk, tau1..tauk, q_ref1..qk,
    the payload's constant columns)."""
    k = run.q.shape[1]
    cols = {"t": run.t, **{f"q{j + 1}": run.q[:, j] for j in range(k)},
            **{f"tau{j + 1}": run.tau[:, j] for j in range(k)},
            **{f"q_ref{j + 1}": run.q_ref[:, j] for j in range(k)}}
    write_robot_csv(path, cols, run.payload if run.payload.mass > 0 else None)
    return path


def test_cli_and_api_report_the_delay_used_and_whether_given(tmp_path, capfd):
    params, reg, runs, _ = simulated("usual", 1, 8.0)
    files = [_write_csv(r, tmp_path / r.source) for r in logged(params, runs, EVERY, True)]
    options = ["--model", "usual", "--sigma-blocks", "0", "--no-consistency"]
    recs = {}
    for name, extra in (("given", ["--torque-delay", str(HOLD)]), ("default", [])):
        out = tmp_path / f"{name}.json"
        code = main(["fit", "--robot", str(ARM3), *map(str, files), *options, *extra,
                     "--json", str(out)])
        text, err = capfd.readouterr()
        assert code == 0, err
        recs[name] = json.loads(out.read_text())
        pre = recs[name]["preprocessing"]
        want = (HOLD, True) if name == "given" else (0.0, False)  # .csv: delay 0
        assert (pre["torque_delay"], pre["torque_delay_given"]) == want, pre
        assert (f"torque delay {want[0]:g} sample ({'given' if want[1] else 'default'})"
                in text), text
    # the delay reached the chain: other numbers
    a, b = (recs[n]["models"]["usual"]["parameters"] for n in ("given", "default"))
    assert a["FV2"]["value"] != b["FV2"]["value"]
    # the Python API takes it under the same name and gives the command line's numbers
    fit = RobotFit(ARM3, "usual", torque_delay=HOLD, sigma_blocks=0, consistency=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit.fit(files)
    assert fit.settings_["torque_delay"] == HOLD and fit.settings_["torque_delay_given"]
    assert fit.params_["usual"] == {p: v["value"] for p, v in a.items()}
    with pytest.raises(DataError, match=r"torque_delay 1\.5: expected a delay in \[0, 1\) "):
        RobotFit(ARM3, "usual", torque_delay=1.5).fit(files)


@pytest.mark.parametrize("value, shown", [("-0.1", "-0.1"), ("half", "'half'")])
def test_bad_torque_delay_is_one_line(tmp_path, value, shown):
    (tmp_path / "r.csv").write_text("t,q1,q2,q3,tau1,tau2,tau3\n")  # refused before reading
    r = subprocess.run([sys.executable, "-m", "daq.app.cli", "fit", "--robot", str(ARM3),
                        "r.csv", f"--torque-delay={value}"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300)  # fmt: skip
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert f"--torque-delay {shown}: expected a delay in [0, 1) samples" in lines[0], lines


def test_single_joint_takes_the_same_option(tmp_path, capfd):
    """``jointid fit --torque-delay`` without ``--robot``: the same flag, unit and record key
    (``fit_models(torque_delay=)`` of the JointModel ``jointid fit`` runs)."""
    t = np.arange(4000) * 1e-3
    q = 0.5 * np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sin(3.1 * t)
    dq = np.gradient(q, t)
    tau = 0.2 * np.gradient(dq, t) + 3 * np.cos(q) + 0.5 * dq + 0.8 * np.sign(dq)
    np.savetxt(tmp_path / "one.csv", np.column_stack([t, q, tau]), delimiter=",",
               header="t,q,tau", comments="", fmt="%.17g")
    for extra, want in ((["--torque-delay", "0.3"], 0.3), ([], 0.0)):  # .csv default: 0
        out = tmp_path / "one.json"
        code = main(["fit", str(tmp_path / "one.csv"), "--model", "usual", *extra,
                     "--json", str(out)])
        assert code == 0, capfd.readouterr().err
        pre = json.loads(out.read_text())["preprocessing"]
        assert (pre["torque_delay"], pre["torque_delay_given"]) == (want, bool(extra)), pre
