"""The robot path's position notes (validation rows outside the fit's positions,
``ident.cli_robot._position_extrapolation`` through ``ident.results.position_split_notes``)
give each joint's range in its own unit: [rad] with degrees for a revolute joint, [m] with
millimetres for a prismatic one (the robot file's joint type); one line per joint, the long
explanation once per report.

Data: the 3-axis cylindrical robot of tests/test_robot_confounded.py (revolute base, two
prismatic axes), usual friction, simulated (``sim_drivers.arm``) about two poses: the fit's
run about one, the validation run about another, their position ranges disjoint on every
joint, so that every joint's validation rows lie outside the fit's positions (checked on the
simulated positions themselves)."""

from __future__ import annotations

import re

import numpy as np
import pytest
from robot_campaigns import write_arm_csv

from ident.cli_robot import fit_files
from ident.results import POSITION_OUTSIDE_SHARE, position_split_notes
from sim_drivers.arm import ArmGains, model_reference, simulate_arm
from tests.test_robot_confounded import cylindrical_arm
from trajectories.robot import load_robot

#: Centres of the fit's and the validation's runs [rad, m, m]: with ``fraction`` 0.5 of the
#: distance to the nearer limit (j1 +-2.5 rad, j2 0.1..0.7 m, j3 0..0.5 m), each run within
#: -1.75..-0.25 / 0.25..1.75 rad, 0.175..0.325 / 0.4..0.6 m, 0.075..0.225 / 0.275..0.425 m
#: (measured: the fit's rows over -1.16..-0.744 rad, 0.177..0.295 m, 0.106..0.203 m).
FIT_CENTRE = (-1.0, 0.25, 0.15)
VAL_CENTRE = (1.0, 0.5, 0.35)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    d = tmp_path_factory.mktemp("cyl3_notes")
    path, params = cylindrical_arm(d)
    robot = load_robot(path)
    runs = []
    for i, centre in enumerate((FIT_CENTRE, VAL_CENTRE)):
        ref = model_reference(params.model, center=centre, fraction=0.5, duration_s=8.0,
                              seed=1 + i)
        runs.append(simulate_arm(params, ref, ArmGains.for_params(params), seed=i))
    files = [write_arm_csv(r, d / f"run{i}.csv") for i, r in enumerate(runs)]
    out = fit_files(robot, [files[0]], [files[1]], model="usual", feasibility=False)
    return robot, runs, files, out


def test_prismatic_range_in_metres_and_the_explanation_once(fitted):
    robot, (fit_run, val_run), files, out = fitted
    splits = out["models"]["usual"]["validation_position_split"]
    notes = [n for n in out["notes"] if n.startswith("validation, ")]
    kinds = dict(zip(robot.joint_names, robot.types, strict=True))
    assert {kinds[j] for j in robot.moving} == {"revolute", "prismatic"}
    for j, joint in enumerate(robot.moving):
        sp = splits[joint]
        lo, hi = sp["q_fit_range"]
        # the fitted rows' range lies within the simulated fit run's positions, and the
        # validation run's lie outside it (disjoint ranges by construction)
        assert fit_run.q[:, j].min() - 1e-9 <= lo < hi <= fit_run.q[:, j].max() + 1e-9
        raw = float(np.mean((val_run.q[:, j] < lo) | (val_run.q[:, j] > hi)))
        assert raw > POSITION_OUTSIDE_SHARE and abs(sp["share_outside"] - raw) < 0.05, (sp, raw)
        (note,) = [n for n in notes if n.startswith(f"validation, {joint} (usual model): ")]
        if kinds[joint] == "prismatic":
            want = f"q = {lo:.3g}..{hi:.3g} m ({1e3 * lo:.3g}..{1e3 * hi:.3g} mm)"
            assert " rad" not in note and " deg" not in note, note
        else:
            want = (f"q = {lo:.3g}..{hi:.3g} rad ({np.degrees(lo):.3g}..{np.degrees(hi):.3g} "
                    "deg)")
        assert want in note, (want, note)
        assert "\n" not in note
    # each reason explained in full once, in the first note giving it; the files named once
    full = {"the gravity columns can be nearly collinear", "the positions alone do not explain"}
    for text in full:
        assert sum(text in n for n in notes) <= 1, notes
    reasons = [re.search(r"\((position extrapolation|inside the range|about as large)", n)
               for n in notes]
    assert all(reasons), notes
    seen: set[str] = set()
    for n, r in zip(notes, reasons, strict=True):
        key = "in" if r.group(1) != "position extrapolation" else "ex"
        assert any(t in n for t in full) == (key not in seen), (n, seen)
        seen.add(key)
    names = files[1].name
    assert sum(n.count(names) for n in notes) == 1 and names in notes[0], notes
    # the builder's text on the recorded splits, given the joint kinds
    assert notes == position_split_notes(
        [(f"{joint} (usual model)", splits[joint]) for joint in robot.moving], [files[1]],
        [kinds[joint] == "revolute" for joint in robot.moving]), notes
