"""``jointid fit --robot`` on the real KUKA KR300 no longer refuses the paper model where some
of its columns are zero on the data: it drops them (the rank rule of every fit) and goes on.

README.md's KUKA command with ``--trim 67`` (data ``../shared/data/kuka_kr300_weigand2021``,
not in the repository: skipped without them) ended in exit 2, "paper model: parameters not
identifiable on these data: ['a_m4', 'b_m4', 'c_m4', 'd_m4'] have no excitation (their columns
are zero) -- evidence ...: A4: 0 rows motor, 25 generator, ...": A4 has no row in the motor
quadrant at that trim. The single-joint fit drops such columns; the n-dof fit now does too:
held at 0, ``removed`` in the record with the reason and the refusal's evidence (rows per
quadrant, which trajectory would fix it), a note, then pruning, honest sigma and validation
as on any fit. (Figures at trims 60-73: docs/robot-identification.md, "Refused or dropped".)
"""

from __future__ import annotations

import json
import math

from test_kuka_readme import DATA, KUKA, MAP, pytestmark  # noqa: F401  (skip without data)

from daq.app.cli import main
from ident.estimators import ZERO_COLUMN

A4_MOTOR = ("a_m4", "b_m4", "c_m4", "d_m4")


def test_trim_67_fits_and_reports_a4_motor_columns_dropped(tmp_path, capfd):
    out = tmp_path / "kuka_67.json"
    files = [DATA / f"recorded_2020-10-21_FF_{x}_08ms.mat" for x in "ABC"]
    code = main(["fit", "--robot", str(KUKA), str(files[0]),
                 "--validate", str(files[1]), str(files[2]),
                 "--q-unit", "deg", "--map", MAP, "--model", "paper", "--trim", "67",
                 "--json", str(out)])
    printed, err = capfd.readouterr()
    assert code == 0, err
    rec = json.loads(out.read_text())
    paper = rec["models"]["paper"]
    assert "error" not in paper, paper
    # dropped with the rank rule's reason, held at 0, neither pruned nor "unidentified"
    assert [(r["name"], r["reason"]) for r in paper["removed"]] == [
        (n, ZERO_COLUMN) for n in A4_MOTOR]
    for n in A4_MOTOR:
        p = paper["parameters"][n]
        assert p["value"] == 0.0 and p["removed"] == ZERO_COLUMN and not p["pruned"], p
        assert n not in paper["unidentified"]
    # the evidence the refusal gave: A4's rows per quadrant and the trajectory that fixes it
    ev = " ".join(paper["removed_evidence"])
    assert "A4: 0 rows motor" in ev and "Fix: a trajectory on which the load of A4" in ev, ev
    note = [n for n in rec["notes"]
            if n.startswith("paper model: a_m4, b_m4, c_m4, d_m4 removed before the fit")]
    assert len(note) == 1 and "A4: 0 rows motor" in note[0], rec["notes"]
    assert "a_m4, b_m4, c_m4, d_m4 removed before the fit" in printed
    # and the rest of the fit went on: pruning, honest sigma, cross-validation on B and C
    assert paper["uncertainty"]["pruned"], paper["uncertainty"]
    assert not set(paper["uncertainty"]["pruned"]) & set(A4_MOTOR)
    cv = paper["validation_rel_error"]
    assert set(cv) >= {"A1", "A2", "A3", "A4", "A5", "A6", "all"}
    assert all(math.isfinite(v) for v in cv.values()), cv
