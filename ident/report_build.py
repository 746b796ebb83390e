"""Build the campaign/identification report from the files a run leaves in its folder.

Inputs (all in ``DIR``):

- ``fit.json`` — written by ``jointid fit --json`` (format: ``docs/fit-json.md``);
- ``demo.json`` — optional: campaign summary, the plant's true parameters (only the demo
  knows them), run summary, and the list of figures with captions;
- ``*.png`` — figures named in ``demo.json`` or found by their conventional names.

The folder's files are data, not markup: every text from ``fit.json``/``demo.json`` is
HTML-escaped, and only PNG files inside ``DIR`` are embedded (a figure named outside it --
absolute, ``..`` or a link pointing out -- is refused in one line naming it).

``jointid report DIR`` calls :func:`build_report`; the demo calls it at its end.
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any

from . import IdentError
from .report import Section, fmt, load_json, write_html
from .vocab import upgrade_record

PAPER = (
    "Hamon, Gautier & Garrec, dynamic identification with a load- and velocity-dependent "
    "dry friction model"
)

# Paper Table II ordering of the paper model's parameters (eq. 43).
_ORDER = [
    "J", "MX", "MY", "Ma_ratio", "F_C",
    "a_m_J", "b_m_J", "a_m_MX", "b_m_MX", "a_m_MY", "b_m_MY", "a_m", "b_m",
    "a_g_J", "b_g_J", "a_g_MX", "b_g_MX", "a_g_MY", "b_g_MY", "a_g", "b_g",
    "c_m", "d_m", "c_g", "d_g", "F_V", "tau_off",
]


def _ordered(params: dict) -> list[str]:
    known = [p for p in _ORDER if p in params]
    return known + sorted(p for p in params if p not in _ORDER)


def truth_check(value: float | None, std2: float | None,
                true: float | None) -> tuple[float | None, str]:
    """``(|error| / sigma, row class)`` of an estimate against the truth: ``"good"`` within
    3 sigma (``std2`` is 2 sigma) or 1 % of the truth, ``"bad"`` otherwise, ``""`` when
    either is unknown."""
    if value is None or true is None or not std2:
        return None, ""
    err = abs(value - true)
    good = err <= 1.5 * std2 or err <= 0.01 * abs(true)
    return err / (std2 / 2), "good" if good else "bad"


def parameter_section(name: str, model: dict, truth: dict | None, table_no: str) -> Section:
    """Paper Tables I-II: identified values, 2 sigma, relative deviation (+ truth if known)."""
    s = Section(f"{table_no}: identified values with the {name} model")
    params = model.get("parameters", {})
    header = ["Parameter", "Identified value", "Standard deviation × 2", "Relative deviation [%]"]
    rows, classes = [], []
    for p in _ordered(params):
        v = params[p]
        row = [p, v.get("value"), v.get("std2"), v.get("rel_std_pct")]
        cls = ""
        if truth is not None:
            ratio, cls = truth_check(v.get("value"), v.get("std2"), truth.get(p))
            row += [truth.get(p), ratio]
        rows.append(row)
        classes.append(cls)
    if truth is not None:
        header += ["Plant truth", "|error| / σ"]
    s.table(header, rows, classes)
    removed = model.get("removed") or model.get("eliminated")
    if removed:
        s.para("Eliminated as not significant or not identifiable: " + _describe_removed(removed),
               "muted")
    if truth is not None:
        s.para("Green rows: within 3σ of the plant's truth (or 1 %); red rows: outside. The demo "
               "knows the truth because it simulated the joint; real data have no such column.",
               "muted")
    return s


def _describe_removed(removed: Any) -> str:
    if isinstance(removed, dict):
        return "; ".join(f"{k} ({v})" for k, v in removed.items())
    if isinstance(removed, list):
        parts = []
        for r in removed:
            if isinstance(r, dict):
                parts.append(f"{r.get('name', '?')} ({r.get('reason', '')})")
            else:
                parts.append(str(r))
        return "; ".join(parts)
    return str(removed)


def errors_section(fit: dict) -> Section:
    """Paper Table III (and Table IV when present)."""
    models = fit.get("models", {})
    names = [n for n in ("usual", "paper") if n in models] + [
        n for n in models if n not in ("usual", "paper")
    ]
    s = Section("Table III: relative norm of errors ‖ρ‖/‖Y‖")
    rows = [
        ["All samples (all velocities)"] + [models[n].get("rel_error") for n in names],
        ["Samples with low velocities (0-10 % of max)"]
        + [models[n].get("rel_error_low_velocity") for n in names],
        ["Samples with high velocities (35-100 % of max)"]
        + [models[n].get("rel_error_high_velocity") for n in names],
    ]
    if any(models[n].get("validation_rel_error") is not None for n in names):
        rows.append(["Validation files"] + [models[n].get("validation_rel_error") for n in names])
    s.table(["Measurements used"] + [f"{n} model" for n in names], rows)
    t4 = fit.get("table_iv")
    if t4:
        s.heading("Table IV: identification with and without payload variations")
        rows4 = []
        for label, key in (("With payload variations", "with_payloads"),
                           ("Without payload", "without_payload")):
            if key in t4:
                rows4.append([label] + [t4[key].get(n) for n in names])
        s.table(["Identification carried out"] + [f"{n} model" for n in names], rows4)
    if "usual" in models and "paper" in models:
        u, n = models["usual"], models["paper"]
        try:
            s.para(
                f"The paper model lowers the error on all samples by "
                f"{100 * (1 - n['rel_error'] / u['rel_error']):.0f} % and at low velocities by "
                f"{100 * (1 - n['rel_error_low_velocity'] / u['rel_error_low_velocity']):.0f} % "
                f"(the paper: 34 % and 46 %)."
            )
        except (KeyError, TypeError, ZeroDivisionError):
            pass
    return s


def refinement_section(ref: dict) -> Section:
    s = Section("Closing the loop: residual diagnosis and refinement")
    steps = ref.get("steps", [])
    if not steps:
        s.para("The residual showed no dependence on any candidate variable beyond noise: "
               "refinement added nothing.")
    rows, notes = [], []
    for i, st in enumerate(steps, 1):
        if st.get("sigma_note"):
            notes.append(f"Step {i}: {st['sigma_note']}.")
        ratio = (st.get("floor_ratio") or {}).get("fit_after")
        rng = st.get("physical_range") or {}
        rows.append([
            i, st.get("variable"), st.get("named_effect") or st.get("effect"),
            st.get("rel_error_before"), st.get("rel_error_after"),
            st.get("heldout_rel_error_after"),
            None if ratio is None else f"{ratio:.2f}" + (" (leak?)" if ratio < 1 else ""),
            st.get("validation_rel_error_before"), st.get("validation_rel_error_after"),
            "inside" if rng.get("inside", True) else f"outside: {rng.get('reason')}",
        ])
    if rows:
        s.table(["Step", "Residual depends on", "Effect added", "Error before", "Error after",
                 f"{ref.get('heldout_kind', 'held-out')} after", "Error / noise floor",
                 "Validation before", "Validation after", "Physical range"], rows)
    for text in notes:
        s.para(text)
    if ref.get("noise_floor") is not None:
        s.para(f"Estimated noise floor (what no model can explain): {fmt(ref['noise_floor'])}"
               + (f"; {ref['leak_warning'].strip(' []')}" if ref.get("leak_warning") else "")
               + ".")
    for i, st in enumerate(steps, 1):
        params = st.get("parameters", {})
        if params:
            s.heading(f"Step {i}: {st.get('effect')} ({st.get('variable')})")
            if st.get("description"):
                s.para(str(st["description"]))
            prow = []
            for p, v in params.items():
                if isinstance(v, dict):
                    prow.append([p, v.get("value"), v.get("std2")])
                else:
                    prow.append([p, v, None])
            s.table(["Parameter", "Identified value", "Standard deviation × 2"], prow)
    if ref.get("rel_error_final") is not None:
        s.para(f"Relative error after refinement: {fmt(ref['rel_error_final'])}.")
    return s


def truth_effects_section(demo: dict, ref: dict | None) -> Section | None:
    effects = demo.get("truth_effects")
    if not effects:
        return None
    s = Section("What the plant really had (undeclared effects)")
    s.para("The simulated joint includes effects that no identification model declares. "
           "The refinement did not see this table; compare it with what it found.")
    rows = []
    for name, params in effects.items():
        if isinstance(params, dict):
            rows.append([name, ", ".join(f"{k} = {fmt(v)}" for k, v in params.items())])
        else:
            rows.append([name, fmt(params)])
    s.table(["Effect", "True parameters"], rows)
    return s


def _match_effect_parameter(truth_key: str, params: dict) -> str | None:
    """The refinement parameter that estimates a true effect parameter (by its stem).

    ``amplitude_Nm`` matches ``ripple_amplitude``; ``period_rad`` matches ``ripple_period``.
    """
    stem = truth_key.split("_")[0].lower()
    hits = [n for n in params if stem in n.lower().split("_")]
    return hits[0] if len(hits) == 1 else None


def truth_comparison_section(ref: dict, truth: dict, demo: dict) -> Section | None:
    """Side by side: the refined model's parameters against the plant's truth."""
    final = ref.get("final_parameters")
    if not final or not truth:
        return None
    s = Section("Identified after refinement against the plant's truth")
    s.para("The refined model (the paper model plus the effects the residual pointed to) is "
           "the one to compare with the simulated joint: it is the only model whose structure "
           "contains everything the plant does. Green: within 3σ of the truth (or 1 %).")
    rows, classes = [], []

    def add(label: str, est: dict | None, true: float | None) -> None:
        v = est.get("value") if est else None
        std2 = est.get("std2") if est else None
        ratio, cls = truth_check(v, std2, true)
        rows.append([label, v, std2, true, ratio])
        classes.append(cls)

    for p in _ordered(truth):
        add(p, final.get(p), truth[p])
    steps = ref.get("steps", [])
    for effect, tparams in (demo.get("truth_effects") or {}).items():
        step = next((st for st in steps if st.get("effect") == effect), None)
        found = step.get("parameters", {}) if step else {}
        for k, tv in tparams.items():
            name = _match_effect_parameter(k, found)
            if name is None and not found:
                add(f"{effect}.{k} (not found)", None, tv)
            elif name is not None:
                add(f"{effect}.{k} ({name})", found[name], tv)
    s.table(["Parameter", "Identified value", "Standard deviation × 2", "Plant truth",
             "|error| / σ"], rows, classes)
    return s


_CAPTIONS = {
    "campaign_plan.png": ("campaign", "Planned excitation: position, velocity and "
                                      "acceleration (one payload run; repeated per payload)"),
    "direct_validation_usual.png": ("usual", "Direct validation with the usual model (Fig. 4)"),
    "cross_validation_usual.png": ("usual", "Cross validation on the validation files"),
    "direct_validation_paper.png": ("paper", "Direct validation with the paper model (Fig. 5)"),
    "cross_validation_paper.png": ("paper", "Cross validation on the validation files"),
    "error_vs_velocity.png": ("paper", "Residual against velocity for the fitted models"),
}


def _refinement_caption(stem: str) -> str:
    """Caption of ``refine_step<k>_<kind>`` / ``refine_final_<kind>`` (ident.refine_plots)."""
    _, step, kind = stem.split("_", 2)
    what = ("residual against the leading candidate variables" if kind == "residual"
            else "periodogram of the residual against position and time")
    when = ("after the last step" if step == "final"
            else f"before step {step[len('step'):]} (what led to it)")
    return f"Diagnosis {when}: {what}"


def discover_figures(d: Path, only: list[Path] | None = None) -> dict[str, list[dict[str, str]]]:
    """Figures with the conventional names of :mod:`ident.plots`, :mod:`ident.refine_plots`
    and the campaign plot, grouped by report section with their captions.

    ``only`` restricts them to the files just written (a folder may hold older figures)."""
    out: dict[str, list[dict[str, str]]] = {"campaign": [], "usual": [], "paper": [],
                                            "refinement": []}
    names = None if only is None else {Path(f).name for f in only}
    order = list(_CAPTIONS)

    def rank(f: Path) -> tuple[int, str]:  # known figures first, refinement steps before final
        return (order.index(f.name) if f.name in order else len(order),
                f.name.replace("final", "~"))

    pngs = sorted((f for f in d.glob("*.png") if names is None or f.name in names), key=rank)
    for f in pngs:
        if f.name in _CAPTIONS:
            key, cap = _CAPTIONS[f.name]
        elif f.name.startswith("refine_") and f.stem.count("_") >= 2:
            key, cap = "refinement", _refinement_caption(f.stem)
        else:
            continue
        out[key].append({"file": f.name, "caption": cap})
    return out


def _figures(d: Path, demo: dict, key: str) -> list[tuple[Path, str]]:
    """The figures of one report section as (path, caption), every path inside ``d``.

    ``demo.json`` names them; a name that leaves the folder (absolute, ``..``, a symbolic
    link pointing out) is refused: the report embeds files, and must embed only the run's own.

    Raises
    ------
    IdentError
        A figure entry that is not ``{"file": NAME, "caption": TEXT}`` or leaves ``d``.
    """
    figs = demo.get("figures", {})
    entries = figs.get(key, []) if isinstance(figs, dict) else None
    if not isinstance(entries, list):
        raise IdentError(f"{d / 'demo.json'}: figures: expected a table of lists of "
                         "{file, caption}")
    root = d.resolve()
    out = []
    for fig in entries:
        if not isinstance(fig, dict) or not isinstance(fig.get("file"), str):
            raise IdentError(f"{d / 'demo.json'}: figures.{key}: expected entries "
                             f"{{file, caption}}, got {fig!r}")
        path = (d / fig["file"]).resolve()
        if not path.is_relative_to(root):
            raise IdentError(f"{d / 'demo.json'}: figure {fig['file']!r} is outside the report "
                             f"folder {str(d)!r}; only figures inside it are embedded")
        out.append((d / fig["file"], str(fig.get("caption", ""))))
    return out


def build_report(directory: Path | str, *, title: str = "jointid report") -> Path:
    """(Re)write ``DIR/report.html`` from ``fit.json``, ``demo.json`` and the PNG figures.

    Raises
    ------
    IdentError
        When ``DIR`` or ``DIR/fit.json`` is missing or unreadable.
    """
    d = Path(directory)
    if not d.is_dir():
        raise IdentError(f"{d}: not a directory (expected the output folder of jointid demo/fit)")
    fit = upgrade_record(load_json(d / "fit.json"))  # older records: "new", "qs", "ols"
    demo = upgrade_record(load_json(d / "demo.json")) if (d / "demo.json").exists() else {}
    for name, rec in (("fit.json", fit), ("demo.json", demo)):
        if not isinstance(rec, dict):
            raise IdentError(f"{d / name}: expected a JSON object (the record jointid "
                             f"writes), got a {type(rec).__name__}")
    if not isinstance(fit.get("models"), dict) or not fit["models"]:
        raise IdentError(f"{d / 'fit.json'}: no fitted model ('models' missing or empty): "
                         "expected the record of jointid fit --json or jointid demo")
    if "figures" not in demo:
        demo["figures"] = discover_figures(d)
    truth = demo.get("truth")
    sections: list[Section] = []

    intro = Section("Campaign" if demo.get("campaign_summary") else "Inputs")
    if fit.get("inputs") and not demo.get("campaign_summary"):
        rows = [["identification", f] for f in fit["inputs"]]
        rows += [["validation", f] for f in fit.get("validation_inputs", [])]
        intro.table(["Use", "File"], rows)
        pre = fit.get("preprocessing") or {}
        if pre:
            intro.para("Joint: " + str(fit.get("joint", "?")) + "; preprocessing: "
                       + ", ".join(f"{k} = {fmt(v)}" for k, v in pre.items()), "muted")
    for note in fit.get("notes", []):
        intro.para("Note: " + str(note), "muted")
    if demo.get("description"):
        intro.para(demo["description"])
    if demo.get("campaign_summary"):
        intro.raw(f"<pre>{html.escape(str(demo['campaign_summary']))}</pre>")
    if demo.get("run_summary"):
        intro.raw(f"<pre>{html.escape(str(demo['run_summary']))}</pre>")
    for path, caption in _figures(d, demo, "campaign"):
        intro.figure(path, caption)
    sections.append(intro)

    sections.append(errors_section(fit))
    models = fit.get("models", {})
    for name, table_no in (("usual", "Table I"), ("paper", "Table II")):
        if name in models:
            sec = parameter_section(name, models[name], truth if name == "paper" else None,
                                    table_no)
            for path, caption in _figures(d, demo, name):
                sec.figure(path, caption)
            sections.append(sec)
    if "usual" in models and truth:
        sections[-1 if "paper" not in models else -2].para(
            "The usual model has no exact counterpart in the plant (its friction is the paper's "
            "load- and velocity-dependent one), so no truth column is shown for it.", "muted")

    ref = fit.get("refinement")
    if ref is not None:
        rsec = refinement_section(ref)
        for path, caption in _figures(d, demo, "refinement"):
            rsec.figure(path, caption)
        sections.append(rsec)
    te = truth_effects_section(demo, ref)
    if te is not None:
        sections.append(te)
    if ref is not None and truth:
        tc = truth_comparison_section(ref, truth, demo)
        if tc is not None:
            sections.append(tc)

    subtitle = demo.get("subtitle") or f"Models after {PAPER}."
    out = write_html(d / "report.html", title, subtitle, sections)
    return out

