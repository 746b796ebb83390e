"""docs/api.md runs as written: every Python block, in order and in one namespace (a block
may use the names of the ones before it), in a folder holding the files the page names --
recorded by the command its first block quotes. A block that reads ../shared is skipped
when that material is absent."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib
from conftest import SHARED

from daq.app.cli import main

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "api.md"


def _blocks() -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", DOC.read_text(encoding="utf-8"), re.M | re.S)


def test_the_page_has_python_blocks_and_names_its_recording_command():
    blocks = _blocks()
    assert len(blocks) >= 2
    assert "jointid run examples/campaign.toml" in blocks[0]


def test_every_python_block_runs(tmp_path, monkeypatch, capsys):
    # the logs the first block names, recorded by the command it quotes (from the repo root,
    # so its relative paths hold, into tmp_path)
    cmd = re.search(r"#\s*logs of:\s*jointid (.+)$", _blocks()[0], re.M)
    assert cmd, "the first block names the command that records its logs"
    args = cmd.group(1).split()
    args = [str(ROOT / a) if a.startswith("examples/") else a for a in args]
    monkeypatch.chdir(tmp_path)
    assert main([*args, "--yes"]) == 0
    capsys.readouterr()
    namespace: dict = {"__name__": "docs_api"}
    ran = 0
    for k, code in enumerate(_blocks()):
        if "../shared" in code and not SHARED.exists():
            continue  # needs the shared data, absent here
        exec(compile(code, f"{DOC.name} block {k + 1}", "exec"), namespace)
        ran += 1
    assert ran == len(_blocks())
    # what the first block promised
    est = namespace["est"]
    assert len(est.coef_) == len(est.coef_names_) and "F_V" in est.params_
    assert 0 < est.score(namespace["other_runs"]) <= 1
