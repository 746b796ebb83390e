"""Every Python block of docs/*.md runs as written (issue 23: docs that run).

docs/api.md has its own test (tests/test_docs_api.py). The blocks of every other page run
in order, one namespace per page (a block may use the names of the ones before it), in a
folder holding what the pages name: ``runs/`` (the logs of ``jointid run
examples/campaign.toml --simulate examples/plant_rx130l.toml --quick --out runs``), ``a.mcap``
... ``d.mcap`` (those logs again) and ``examples/`` (the repository's). A block that cannot run
as a script says why in an HTML comment on the line before it::

    <!-- docs-test: skip: REASON -->

and a block that reads ../shared is skipped when that material is absent.
"""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib
import pytest
from conftest import SHARED

from daq.app.cli import main

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
#: pages tested elsewhere
OWN_TEST = {"api.md": "tests/test_docs_api.py"}
SKIP = re.compile(r"<!--\s*docs-test:\s*skip:\s*(.*?)\s*-->\s*$")
BLOCK = re.compile(r"^```python\n(.*?)^```", re.M | re.S)


def blocks(page: Path) -> list[tuple[str, str | None]]:
    """(code, skip reason or None) of every Python block of ``page``."""
    text = page.read_text(encoding="utf-8")
    out = []
    for m in BLOCK.finditer(text):
        before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        skip = SKIP.match(before)
        out.append((m.group(1), skip.group(1) if skip else None))
    return out


PAGES = sorted(p for p in DOCS.glob("*.md") if p.name not in OWN_TEST and blocks(p))


def test_the_pages_with_python_blocks_are_found_and_skips_say_why():
    names = {p.name for p in PAGES}
    assert {"refinement.md", "log-format.md", "robot-format.md"} <= names
    for page in PAGES:
        for k, (code, why) in enumerate(blocks(page), 1):
            assert code.strip(), f"{page.name} block {k} is empty"
            if why is not None:
                assert len(why) > 20, f"{page.name} block {k}: a skip needs its reason"
    for page, test in OWN_TEST.items():
        assert (ROOT / test).is_file() and (DOCS / page).is_file()


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """The files the pages name (module docstring)."""
    d = tmp_path_factory.mktemp("docs")
    # the example campaign without the master's heartbeat: on a busy machine the in-process
    # heartbeat thread can starve past the drive's consumer time (0.4 s) and the drive then
    # faults by design (EMCY 0x8130, tested in test_safety_drive.py); these logs only feed the
    # pages' examples
    campaign = d / "campaign.toml"
    campaign.write_text((ROOT / "examples" / "campaign.toml").read_text(encoding="utf-8")
                        + "\n[daq]\nmaster_heartbeat_ms = 0\n", encoding="utf-8")
    args = ["run", str(campaign), "--simulate",
            str(ROOT / "examples" / "plant_rx130l.toml"), "--quick", "--out", str(d / "runs"),
            "--yes"]
    assert main(args) == 0
    logs = sorted((d / "runs").glob("*.mcap"))
    assert len(logs) == 3
    for name, log in zip(("a", "b", "c", "d"), [*logs, logs[0]], strict=True):
        (d / f"{name}.mcap").symlink_to(log)
    (d / "examples").symlink_to(ROOT / "examples")
    return d


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_python_block_runs(page, folder, monkeypatch, capsys):
    monkeypatch.chdir(folder)
    namespace: dict = {"__name__": f"docs_{page.stem}"}
    ran = skipped = 0
    for k, (code, why) in enumerate(blocks(page), 1):
        if why is not None or ("../shared" in code and not SHARED.exists()):
            skipped += 1
            continue
        exec(compile(code, f"{page.name} block {k}", "exec"), namespace)
        ran += 1
    capsys.readouterr()
    if not ran:
        pytest.skip(f"{page.name}: every block is marked skipped ({skipped})")
