"""The README's KUKA KR300 figures, rerun through the command line's entry point.

README.md ("Whole robots") gives one command on the real recordings of Weigand et al.
(``../shared/data/kuka_kr300_weigand2021``, not in the repository; the test is skipped
without them): fit on recording A, cross-validate on B and C, ``--model both``. It quotes,
for the paper model: a fit of 1.0 % against the usual model's 1.4 % on the same rows, a
cross-validation on B and C of 11.4 % against the usual model's 18.2 % on the same rows, a
fit that converges (Gauss-Newton below its iteration limit, the quadrant passes settled:
theta moving < THETA_TOL sigma), and 20 friction parameters pruned (docs/robot-data.md).
This test runs that command in process (``daq.app.cli.main``, what the ``jointid`` script
calls) and checks those figures.

Until 2026-11-29 the quadrant passes stopped on quadrant flips alone, after two
re-decisions with rows still crossing the band: 11.4 % (11.37) against 18.2 %, 23 pruned,
which this test asserted then. Counting the band's crossings too (2026-11-29, morning) the
passes cycled rows at the band's edge up to their cap: 19.8 %, 19 pruned, not converged. With
the band's hysteresis (``BAND_LEAVE``, 2026-11-29) they settle: 11.43 %, 20 pruned; A4's
quadrants still change on 36 % of its rows with the final values (its parameters are not
identified: they move by less than THETA_TOL of their large sigma), which the record's
``quadrant_drift`` and a note say.

What breaks it (measured before 2026-11-29's stopping rule, docs/robot-identification.md
"Pruning"): the greedy pruning reads
the relative sigma, so any change of that sigma changes which parameters go, and with them
the cross-validation. With the trim of 61 samples the default gave until 2026-11-28 (below),
the pruning reading the honest sigma's HC3 side pruned 19 other parameters and moved the
cross-validation 7.7 -> 12.5 % (A4 79 -> 176 %), the honest sigma before 2026-11-28
(max(eq. 15, jackknife)) gave 9.3 %, no pruning at all (``--no-prune``) 23.9 % (12.7 % at
trim 60). So does a change of which decimated rows are kept: the default trim is
ceil(3 f_s / cut-off) samples;
the files store their period as 0.0039999999 s, which made it ceil(60.0000015) = 61 until
the ceil ignored a sub-ppm excess (``ident.chain.TRIM_RTOL``); it is 60 now, as with an
exact 4 ms. At trims 60, 61, 67, 68 and 73 the paper model cross-validates at 11.4, 15.6,
3340, 25.1 and 64.8 % (docs/robot-data.md): the README's figure is that of this command,
not a property of the recordings, and this test says when it moves.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from daq.app.cli import main

ROOT = Path(__file__).resolve().parents[1]
KUKA = ROOT / "examples" / "robots" / "kuka_kr300_r2500.toml"
SHARED = Path(os.environ.get("JOINTID_SHARED", ROOT.parent / "shared"))  # as conftest.py
DATA = SHARED / "data" / "kuka_kr300_weigand2021"
MAP = "t=rec.time_cont,q=rec.act_pos_mot_deg,tau=rec.act_torque_abs_nm,q_ref=rec.ref_pos_deg"

# The README's figure is 11.4 % (11.43 % printed on 2026-11-29 with the trim of 60 and the
# band's hysteresis). The band is that figure +- 10 % of it: far beyond the rounding of the
# quoted digits (+-0.05) and any floating-point noise of this deterministic fit, and
# excluding the neighbouring trim's 15.6 % and the cycling passes' 19.8 % (it does not tell
# the flips-only rule's 11.37 % apart). Outside it the README's "11.4 %" is no longer what the
# code gives and must be measured again (or the change found).
DOCUMENTED_CV_PCT = 11.4
CV_BAND_PCT = 0.10 * DOCUMENTED_CV_PCT
# README: the usual model on the same rows, 18.2 % (18.23): the usual fit is linear, one pass,
# unaffected by the quadrant passes; to its printed digit.
DOCUMENTED_CV_USUAL_PCT = 18.2
# docs/robot-data.md: 20 parameters pruned. The count, not the names: +-2 of
# the 60 prunable parameters: one removal more or less, undone or not by the chi-square
# test, is a change of the order worth re-reading the docs for, not of the claim.
DOCUMENTED_PRUNED = 20
PRUNED_TOL = 2

pytestmark = pytest.mark.skipif(
    not DATA.is_dir(), reason=f"real KUKA recordings absent: {DATA} (../shared not mounted)")


def _fit(tmp_path: Path, capfd, model: str) -> dict:
    """The README's command with ``--model MODEL``; its JSON record."""
    out = tmp_path / f"kuka_{model}.json"
    files = [DATA / f"recorded_2020-10-21_FF_{x}_08ms.mat" for x in "ABC"]
    code = main(["fit", "--robot", str(KUKA), str(files[0]),
                 "--validate", str(files[1]), str(files[2]),
                 "--q-unit", "deg", "--map", MAP, "--model", model, "--json", str(out)])
    _, err = capfd.readouterr()
    assert code == 0, err
    return json.loads(out.read_text())


def test_readme_kuka_paper_model_cross_validation_and_pruning(tmp_path, capfd):
    """The paper model cross-validates on B and C at the documented figure, below the usual
    model on the same rows; its fit converges (the README says on what), with the documented
    number of pruned parameters."""
    both = _fit(tmp_path, capfd, "both")["models"]
    paper, usual = both["paper"], both["usual"]
    assert "error" not in paper, paper
    cv = 100 * paper["validation_rel_error"]["all"]
    cv_usual = 100 * usual["validation_rel_error"]["all"]
    print(f"\nCV on B and C, all axes: paper {cv:.2f} %, usual (same rows) {cv_usual:.2f} %; "
          f"pruned {len(paper['uncertainty']['pruned'])}; "
          f"fit: paper {100 * paper['rel_error']['all']:.2f} %, "
          f"usual {100 * usual['rel_error']['all']:.2f} %; converged {paper['converged']}: "
          f"{paper.get('convergence')}")
    assert abs(cv - DOCUMENTED_CV_PCT) <= CV_BAND_PCT, (
        f"paper model's cross-validation on B and C {cv:.2f} % outside "
        f"{DOCUMENTED_CV_PCT} +- {CV_BAND_PCT:.2f} % (README)")
    assert abs(cv_usual - DOCUMENTED_CV_USUAL_PCT) <= 0.05 + 1e-9, cv_usual
    assert cv < cv_usual, (cv, cv_usual)  # README: below the usual model
    # README: converged (Gauss-Newton below its limit, the passes settled), with A4's
    # quadrants drifting (its parameters unidentified), which the record says
    assert paper["converged"] is True and "convergence" not in paper, paper.get("convergence")
    assert paper["quadrant_drift"]["A4"] > 0.1, paper["quadrant_drift"]
    pruned = paper["uncertainty"]["pruned"]
    assert abs(len(pruned) - DOCUMENTED_PRUNED) <= PRUNED_TOL, pruned
    assert all(paper["parameters"][p]["pruned"] for p in pruned)
    # the README's fit figures: the paper model below the usual one on the same rows
    assert paper["rel_error"]["all"] < usual["rel_error"]["all"]
