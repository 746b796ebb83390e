"""A module past 600 lines says at its top why (a "(Past 600 lines: ...)" sentence in its
docstring, as ``ident/fitting.py`` does); ``ident/library_search.py``, ``ident/refine.py``,
``ident/robot/consistent_fit.py`` and ``daq/protocol/reader.py`` did not."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("ident", "daq", "sim_drivers", "trajectories")
LIMIT = 600  # lines


def test_modules_past_600_lines_say_why():
    silent = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            text = path.read_text(encoding="utf-8")
            if text.count("\n") <= LIMIT:
                continue
            doc = ast.get_docstring(ast.parse(text)) or ""
            if "past 600 lines" not in doc.lower():
                silent.append(f"{path.relative_to(ROOT)} ({text.count(chr(10))} lines)")
    assert not silent, (f"modules past {LIMIT} lines without a '(Past 600 lines: ...)' "
                        f"sentence: {silent}")
