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
import os
import re
import secrets
import shutil
import signal
import threading
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager, suppress
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


def write_text_atomic(path: Path | str, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through ``PATH.part`` and a rename: an interrupt or
    an error while writing leaves ``path`` as it was (absent, or the previous file) and no
    ``.part`` file behind."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    try:
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
    except BaseException as e:
        with suppress(OSError):
            tmp.unlink(missing_ok=True)
        if isinstance(e, OSError) and e.filename == str(tmp):  # name the file the user asked
            raise type(e)(e.errno, e.strerror, str(path)) from None
        raise
    return path


def write_html(path: Path, title: str, subtitle: str, sections: Sequence[Section]) -> Path:
    """Write the report atomically (temporary file, then rename): no half-written report."""
    return write_text_atomic(path, render(title, subtitle, sections))


#: signals held back while a staged folder is moved in (:func:`staged_folder`)
_HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextmanager
def _signals_held() -> Iterator[None]:
    """Hold :data:`_HELD_SIGNALS` back (main thread only): a Ctrl-C arriving meanwhile is
    delivered when the block ends, after the renames, not between two of them."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


#: the list of the files a staged folder moved into its folder (hidden, in that folder): the
#: next output written there removes those of them it does not rewrite (no stale figure of
#: an earlier report left to look current), and never any other file
WRITTEN_LIST = ".jointid-written.json"


def written_files(folder: Path) -> list[str]:
    """The names of the files the last output staged into ``folder`` wrote
    (:data:`WRITTEN_LIST`; empty when absent or unreadable: a folder of an earlier version,
    or none of ours). Only plain names: nothing outside ``folder`` is ever named."""
    try:
        names = json.loads((folder / WRITTEN_LIST).read_text(encoding="utf-8"))["files"]
    except (OSError, ValueError, KeyError, TypeError):
        return []
    if not isinstance(names, list):
        return []
    return [n for n in names if isinstance(n, str) and n not in ("", ".", "..", WRITTEN_LIST)
            and Path(n).name == n and "\\" not in n]


def _write_list(folder: Path, names: Iterable[str]) -> None:
    write_text_atomic(folder / WRITTEN_LIST, json.dumps(
        {"written_by": "jointid (ident.report.staged_folder)", "files": sorted(set(names))},
        indent=1) + "\n")


def remove_written(folder: Path, keep: Iterable[str] = ()) -> list[str]:
    """Remove the files of ``folder`` that its last staged output wrote
    (:func:`written_files`), but those named in ``keep``; folders and the user's other files
    are left. Returns the names removed."""
    keep = set(keep)
    gone = []
    for name in written_files(folder):
        p = folder / name
        if name not in keep and (p.is_symlink() or p.is_file()):
            p.unlink(missing_ok=True)
            gone.append(name)
    return gone


def _move_in(tmp: Path, final: Path) -> None:
    """The staged folder ``tmp`` becomes ``final``: renamed to it when ``final`` is absent,
    else its files replace their namesakes in ``final`` one rename each and the files of
    the earlier output there that this one does not rewrite are removed (the user's other
    files are kept), signals held over the whole move.

    Not atomic when ``final`` exists: a SIGKILL between two renames leaves ``final`` with
    some new files and some old ones. :data:`WRITTEN_LIST` is first rewritten to name both
    outputs' files, so the next output written there still removes every file of both that
    it does not rewrite (and :func:`staged_folder` the killed process's staged folder). A
    whole-folder switch is not possible here: ``final`` holds the user's files (kept) and a
    demo's logs (written into it as the demo runs), and ``--report .`` is staged inside it."""
    new = sorted(f.name for f in tmp.iterdir() if f.name != WRITTEN_LIST)
    _write_list(tmp, new)
    if final.is_dir():  # a name of ours taken by a folder: refused before any rename
        for f in tmp.iterdir():
            if (final / f.name).is_dir() and not f.is_dir():
                raise IdentError(f"{final / f.name}: is a folder, expected a file name (the "
                                 f"output written into {final}); nothing written")
    with _signals_held():
        if not final.exists():
            try:
                tmp.rename(final)
                return
            except OSError:  # created meanwhile: move the files in as below
                if not final.is_dir():
                    raise
        old = written_files(final)
        _write_list(final, [*old, *new])  # both outputs' files, until the move is done
        for name in new:
            (tmp / name).replace(final / name)
        remove_written(final, keep=new)
        (tmp / WRITTEN_LIST).replace(final / WRITTEN_LIST)
        tmp.rmdir()


def _remove_dead_staging(final: Path) -> None:
    """Remove the staged folders ``.NAME.part-<pid>-<hex>`` of ``final`` (beside it, or in
    it) left by a process killed while writing (SIGKILL: its pid is gone)."""
    full = final.absolute()
    pattern = re.compile(rf"\.{re.escape(full.name or 'out')}\.part-(\d+)-[0-9a-f]{{6}}")
    for where in (full.parent, full):
        try:
            entries = list(where.iterdir()) if where.is_dir() else []
        except OSError:
            continue
        for d in entries:
            m = pattern.fullmatch(d.name)
            if m is None or not d.is_dir() or int(m.group(1)) == os.getpid():
                continue
            try:
                os.kill(int(m.group(1)), 0)
            except ProcessLookupError:  # its writer is gone
                shutil.rmtree(d, ignore_errors=True)
            except OSError:  # alive, another user's
                pass


@contextmanager
def staged_folder(final: Path | str) -> Iterator[Path]:
    """An output folder written whole or not at all: yields a temporary folder
    ``.NAME.part-<pid>-<hex>`` to write into -- beside ``final`` when it is absent, inside it
    when it exists (its parent need not be writable: ``--report .``) --, moved into ``final``
    when the block ends (:func:`_move_in`: a rename when ``final`` is absent, else one rename
    per file, signals held, and the files of the earlier output there that this one does not
    rewrite removed: :data:`WRITTEN_LIST`). On an error or an interrupt (Ctrl-C) inside the
    block, the temporary folder and the parent folders created for it are removed: ``final``
    is left as it was (absent, or its previous files intact), nothing half-written remains.
    A SIGKILL during the move leaves a mix of both outputs (:func:`_move_in`), which the next
    output written there clears.

    Parameters
    ----------
    final : Path or str
        The folder the user named (``jointid fit --report DIR``, ``export-model -o DIR``).

    Yields
    ------
    Path
        The temporary folder, empty.
    """
    final = Path(final)
    full = final.absolute()  # "." -> the working folder, its name
    parent = full if full.is_dir() else full.parent
    created = []  # the missing parent folders, outermost first, to remove on failure
    anc = parent
    while not anc.exists() and anc != anc.parent:
        created.insert(0, anc)
        anc = anc.parent
    tmp = parent / f".{full.name or 'out'}.part-{os.getpid()}-{secrets.token_hex(3)}"
    try:
        parent.mkdir(parents=True, exist_ok=True)
        tmp.mkdir()
        yield tmp
        _move_in(tmp, final)
        _remove_dead_staging(final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        for d in reversed(created):
            try:
                d.rmdir()
            except OSError:  # not empty (something else wrote there) or gone: left
                break
        raise


def load_json(path: Path) -> dict:
    """Read a JSON file, with a one-line error naming it when it is missing or broken."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise IdentError(f"{path}: not found (expected a JSON file written by jointid)") from None
    except json.JSONDecodeError as exc:
        raise IdentError(f"{path}: invalid JSON at line {exc.lineno}: {exc.msg}") from None


def write_json(path: Path, data: Mapping[str, Any]) -> Path:
    """Write ``data`` as indented JSON, atomically (:func:`write_text_atomic`)."""
    return write_text_atomic(path, json.dumps(data, indent=2, sort_keys=False,
                                              default=_json_default) + "\n")


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
