"""The package graph of docs/architecture.md holds: import-linter's contracts (pyproject.toml)
are kept, and no module hides a dependency on our packages inside a function body."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
OURS = ("trajectories", "daq", "sim_drivers", "ident")

# Function-level imports of our own packages still present, by (file, imported module as
# written). Each needs a reason; none may be added to dodge a cycle.
ALLOWED: dict[tuple[str, str], str] = {}

# The `jointid` subcommand modules import the packages they drive inside their run functions,
# so that `jointid --help`, a mistyped option or the demo's first line do not wait seconds
# for scipy, matplotlib, pinocchio, canopen... (tests/test_cli_import_cost.py). Nothing is
# hidden: import-linter reads function bodies too, so these imports are held to the
# contracts above like any other.
LAZY_FOR_START_UP = frozenset({
    "daq/app/demo.py", "daq/app/monitor.py", "daq/protocol/cli_export.py",
    "daq/runtime/cli.py", "daq/runtime/cli_plan.py", "daq/runtime/cli_recover.py",
    "ident/cli.py", "ident/cli_export_model.py", "ident/cli_report.py", "trajectories/cli.py",
})


def _our_module(node: ast.Import | ast.ImportFrom) -> list[str]:
    """The modules of ours an import statement names ("." prefixed when relative)."""
    if isinstance(node, ast.ImportFrom):
        if node.level:
            return ["." * node.level + (node.module or "")]
        names = [node.module or ""]
    else:
        names = [a.name for a in node.names]
    return [n for n in names if n.split(".")[0] in OURS]


def _function_level_imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    found: list[tuple[int, str]] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inside = in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef
                                                      | ast.Lambda)
            if in_function and isinstance(child, ast.Import | ast.ImportFrom):
                found.extend((child.lineno, m) for m in _our_module(child))
            visit(child, inside)

    visit(tree, False)
    return found


def test_import_linter_contracts_are_kept():
    exe = shutil.which("lint-imports", path=str(Path(sys.executable).parent))
    if exe is None:
        pytest.fail("lint-imports not installed: pip install -e '.[test]' (import-linter)")
    run = subprocess.run([exe, "--config", str(ROOT / "pyproject.toml"), "--no-cache"],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, f"import-linter contracts broken:\n{run.stdout}\n{run.stderr}"
    assert "0 broken" in run.stdout, run.stdout


def test_no_function_level_imports_of_our_packages():
    bad = []
    used = set()
    for pkg in OURS:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            for line, mod in _function_level_imports(path):
                if rel in LAZY_FOR_START_UP:
                    used.add(rel)
                elif (rel, mod) in ALLOWED:
                    used.add((rel, mod))
                else:
                    bad.append(f"{rel}:{line}: import of {mod} inside a function")
    assert not bad, ("imports of our own packages belong at module level (docs/architecture.md)"
                     ":\n" + "\n".join(bad))
    stale = sorted(str(k) for k in (set(ALLOWED) | LAZY_FOR_START_UP) - used)
    assert not stale, f"allow-list entries no longer needed, remove them: {stale}"


def test_daq_root_holds_only_version_and_exceptions():
    tree = ast.parse((ROOT / "daq" / "__init__.py").read_text(encoding="utf-8"))
    ours = [m for n in ast.walk(tree) if isinstance(n, ast.Import | ast.ImportFrom)
            for m in _our_module(n)]
    assert ours == [], f"daq/__init__.py must import nothing of ours, imports {ours}"
