"""Self-contained HTML report: tables and figures of a campaign, its fits and refinement.

The report is one HTML file with every figure embedded (base64 PNG), so it opens anywhere
without the folder around it; the same figures are also written as PNG files beside it.
It is built from plain data — ``fit.json`` (see ``docs/fit-json.md``), an optional
``demo.json`` (campaign summary, plant truth) and the PNG files — so ``jointid report DIR``
can regenerate it from what a run left behind.
"""

from __future__ import annotations

import base64
import html
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import IdentError

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2em auto;
max-width:1100px;color:#1d2430;line-height:1.45;padding:0 1em}
h1{font-size:1.7em;margin-bottom:.2em}
h2{border-bottom:2px solid #dde3ea;padding-bottom:.2em;margin-top:2em}
h3{margin-top:1.4em}
table{border-collapse:collapse;margin:.8em 0;font-size:.92em}
th,td{border:1px solid #d5dbe3;padding:.25em .6em;text-align:right}
th{background:#f1f4f8} td:first-child,th:first-child{text-align:left}
tr.bad td{background:#fdecea} tr.good td{background:#eaf7ee}
figure{margin:1em 0} figure img{max-width:100%;border:1px solid #e3e7ee}
figcaption{font-size:.9em;color:#5a6676}
.note{background:#f6f8fb;border-left:4px solid #7a9cc6;padding:.5em 1em;margin:1em 0}
.muted{color:#6b7686;font-size:.9em} code{background:#f1f4f8;padding:0 .2em}
"""


@dataclass
class Section:
    """One section of the report: a heading, HTML paragraphs/tables, and figures (PNG paths)."""

    title: str
    body: list[str] = field(default_factory=list)
    figures: list[tuple[Path, str]] = field(default_factory=list)

    def para(self, text: str, cls: str = "") -> Section:
        c = f' class="{cls}"' if cls else ""
        self.body.append(f"<p{c}>{html.escape(str(text))}</p>")
        return self

    def raw(self, fragment: str) -> Section:
        """Append trusted HTML (our own markup only: never text read from a file)."""
        self.body.append(fragment)
        return self

    def heading(self, text: str) -> Section:
        """Append a sub-heading; ``text`` is escaped (it may come from ``fit.json``)."""
        self.body.append(f"<h3>{html.escape(text)}</h3>")
        return self

    def table(self, header: Sequence[str], rows: Iterable[Sequence[Any]],
              row_classes: Sequence[str] | None = None, caption: str = "") -> Section:
        self.body.append(html_table(header, rows, row_classes, caption))
        return self

    def figure(self, path: Path | str, caption: str) -> Section:
        self.figures.append((Path(path), caption))
        return self


def fmt(value: Any, digits: int = 4) -> str:
    """Format a number for a table cell (``—`` for missing values)."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return "—"
        if value != 0 and (abs(value) >= 1e5 or abs(value) < 1e-3):
            return f"{value:.{digits - 1}e}"
        return f"{value:.{digits}g}" if abs(value) >= 1 else f"{value:.{digits}f}".rstrip("0")
    return str(value)


def html_table(header: Sequence[str], rows: Iterable[Sequence[Any]],
               row_classes: Sequence[str] | None = None, caption: str = "") -> str:
    out = ["<table>"]
    if caption:
        out.append(f"<caption>{html.escape(caption)}</caption>")
    out.append("<tr>" + "".join(f"<th>{html.escape(str(h))}</th>" for h in header) + "</tr>")
    for i, row in enumerate(rows):
        cls = row_classes[i] if row_classes and i < len(row_classes) and row_classes[i] else ""
        attr = f' class="{cls}"' if cls else ""
        cells = "".join(f"<td>{html.escape(fmt(c))}</td>" for c in row)
        out.append(f"<tr{attr}>{cells}</tr>")
    out.append("</table>")
    return "\n".join(out)


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _embed(path: Path) -> str:
    raw = path.read_bytes()
    if not raw.startswith(_PNG_SIGNATURE):
        raise IdentError(f"{path}: not a PNG file, refused as a report figure")
    data = base64.b64encode(raw).decode("ascii")
    return f"data:image/png;base64,{data}"


def render(title: str, subtitle: str, sections: Sequence[Section]) -> str:
    """Render sections to one self-contained HTML document (figures embedded)."""
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html.escape(title)}</title><style>{CSS}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        f'<p class="muted">{html.escape(subtitle)}</p>',
    ]
    toc = "".join(
        f'<li><a href="#s{i}">{html.escape(s.title)}</a></li>' for i, s in enumerate(sections)
    )
    parts.append(f"<ol>{toc}</ol>")
    for i, s in enumerate(sections):
        parts.append(f'<h2 id="s{i}">{html.escape(s.title)}</h2>')
        parts.extend(s.body)
        for path, caption in s.figures:
            if not path.exists():
                parts.append(f'<p class="note">Figure missing: {html.escape(path.name)}</p>')
                continue
            parts.append(
                f'<figure><img alt="{html.escape(caption)}" src="{_embed(path)}">'
                f"<figcaption>{html.escape(caption)} ({html.escape(path.name)})"
                "</figcaption></figure>"
            )
    parts.append("</body></html>")
    return "\n".join(parts)


def write_html(path: Path, title: str, subtitle: str, sections: Sequence[Section]) -> Path:
    """Write the report atomically (temporary file, then rename): no half-written report."""
    text = render(title, subtitle, sections)
    tmp = path.with_suffix(".html.part")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)
    return path


def load_json(path: Path) -> dict:
    """Read a JSON file, with a one-line error naming it when it is missing or broken."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise IdentError(f"{path}: not found (expected a JSON file written by jointid)") from None
    except json.JSONDecodeError as exc:
        raise IdentError(f"{path}: invalid JSON at line {exc.lineno}: {exc.msg}") from None


def write_json(path: Path, data: Mapping[str, Any]) -> Path:
    tmp = Path(path).with_suffix(".json.part")
    tmp.write_text(json.dumps(data, indent=2, sort_keys=False, default=_json_default) + "\n",
                   encoding="utf-8")
    tmp.replace(path)
    return Path(path)


def _json_default(o: Any) -> Any:
    try:
        import numpy as np

        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
    except ImportError:  # pragma: no cover
        pass
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
