"""The HTML report is self-contained, shows the paper's tables, and marks truth mismatches."""

from __future__ import annotations

import base64
import json
import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from ident import IdentError  # noqa: E402
from ident.report_build import build_report  # noqa: E402


def _fit_json():
    p = lambda v, s: {"value": v, "std2": 2 * s, "rel_std_pct": 100 * s / abs(v)}  # noqa: E731
    return {
        "models": {
            "usual": {"rel_error": 0.0733, "rel_error_low_velocity": 0.0737,
                      "rel_error_high_velocity": 0.0863,
                      "parameters": {"J": p(30.9, 0.14), "F_C": p(39.9, 0.04)}},
            "new": {"rel_error": 0.0484, "rel_error_low_velocity": 0.0401,
                    "rel_error_high_velocity": 0.0881,
                    "parameters": {"a_m_J": p(32.4, 0.13), "c_m": p(21.0, 0.07)}},
        },
        "refinement": {"steps": [{"effect": "position_ripple", "variable": "position",
                                  "parameters": {"A": {"value": 5.0, "std2": 0.1}},
                                  "rel_error_before": 0.05, "rel_error_after": 0.03,
                                  "validation_rel_error_before": None,
                                  "validation_rel_error_after": None}],
                       "rel_error_final": 0.03},
    }


def test_report_embeds_figures_and_flags_truth(tmp_path):
    (tmp_path / "fit.json").write_text(json.dumps(_fit_json()))
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    fig.savefig(tmp_path / "validation_new.png")
    plt.close(fig)
    demo = {
        "truth": {"a_m_J": 32.5, "c_m": 25.0},  # c_m is 57 sigma away: must be flagged
        "truth_effects": {"position_ripple": {"amplitude_Nm": 5.0}},
        "figures": {"new": [{"file": "validation_new.png", "caption": "Direct validation"}]},
    }
    (tmp_path / "demo.json").write_text(json.dumps(demo))
    out = build_report(tmp_path, title="t")
    text = out.read_text()
    # the figure is embedded, not linked: the report stands alone
    m = re.search(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)
    assert m and base64.b64decode(m.group(1))[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Table III" in text and "0.0484" in text and "position_ripple" in text
    rows = re.findall(r'<tr class="(good|bad)"><td>([^<]+)</td>', text)
    assert ("good", "a_m_J") in rows and ("bad", "c_m") in rows
    # this record and demo.json are spelled as older ones ("new"): reported as "paper"
    assert "paper model" in text and "new model" not in text


def test_report_refuses_missing_fit(tmp_path):
    with pytest.raises(IdentError, match="fit.json"):
        build_report(tmp_path)


@pytest.mark.parametrize(("fit", "demo", "match"), [
    ("[]", None, r"fit\.json: expected a JSON object .* got a list"),
    ("{}", None, r"fit\.json: no fitted model"),
    (None, "[1, 2]", r"demo\.json: expected a JSON object .* got a list"),
])
def test_report_refuses_a_record_that_is_not_a_fit(tmp_path, capsys, fit, demo, match):
    """A fit.json (or demo.json) that is not jointid's record: one line naming the file, exit
    2, no report written (a list ended in a traceback, an empty object built a report)."""
    from daq.app.cli import main

    (tmp_path / "fit.json").write_text(fit if fit is not None else json.dumps(_fit_json()))
    if demo is not None:
        (tmp_path / "demo.json").write_text(demo)
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and re.search(match, err), err
    assert not (tmp_path / "report.html").exists()


_EVIL = '<script>alert("x")</script>'


def _png(path):
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    fig.savefig(path)
    plt.close(fig)


def test_report_escapes_every_field(tmp_path):
    """Text read from fit.json / demo.json never reaches the page as markup: refinement step
    names and variables, parameter names, notes, summaries, captions, truth effects."""
    fit = _fit_json()
    step = fit["refinement"]["steps"][0]
    step["effect"], step["variable"] = _EVIL, _EVIL + "v"
    step["description"] = _EVIL
    fit["models"]["new"]["parameters"][_EVIL] = {"value": 1.0, "std2": 0.1}
    fit["notes"] = [_EVIL]
    (tmp_path / "fit.json").write_text(json.dumps(fit))
    _png(tmp_path / "a.png")
    demo = {"description": _EVIL, "campaign_summary": _EVIL, "run_summary": _EVIL,
            "subtitle": _EVIL, "truth_effects": {_EVIL: {"k": 1.0}},
            "figures": {"new": [{"file": "a.png", "caption": _EVIL}]}}
    (tmp_path / "demo.json").write_text(json.dumps(demo))
    text = build_report(tmp_path, title=_EVIL).read_text()
    assert "<script" not in text
    assert "&lt;script&gt;" in text
    assert text.count("&lt;script&gt;") >= 10


def test_report_embeds_only_figures_inside_its_folder(tmp_path, capsys):
    from daq.app.cli import main

    d = tmp_path / "rep"
    d.mkdir()
    (d / "fit.json").write_text(json.dumps(_fit_json()))
    outside = tmp_path / "secret.png"
    _png(outside)
    (d / "link.png").symlink_to(outside)
    for name in (str(outside), "../secret.png", "link.png"):
        demo = {"figures": {"new": [{"file": name, "caption": "c"}]}}
        (d / "demo.json").write_text(json.dumps(demo))
        assert main(["report", str(d)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "outside the report folder" in err and name in err
        assert not (d / "report.html").exists()
    # inside the folder: embedded; a file that is not a PNG: refused, naming it
    _png(d / "ok.png")
    (d / "notes.png").write_text("not an image")
    (d / "demo.json").write_text(json.dumps({"figures": {"new": [{"file": "ok.png",
                                                                  "caption": "c"}]}}))
    assert main(["report", str(d)]) == 0
    (d / "demo.json").write_text(json.dumps({"figures": {"new": [{"file": "notes.png",
                                                                  "caption": "c"}]}}))
    assert main(["report", str(d)]) == 2
    assert "notes.png: not a PNG" in capsys.readouterr().err
