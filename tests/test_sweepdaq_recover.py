"""``jointid recover LOG -o OUT`` onto an existing file (found by the acquisition sweep): a
mistyped ``-o`` naming another payload's finished log replaced it in silence. It is refused
in one line, exit 2, and both files are left as they were."""

from __future__ import annotations

from pathlib import Path

from daq.app.cli import main
from daq.protocol.logformat import FRAME
from daq.protocol.reader import read_run
from daq.runtime.mcaplog import RunLog


def _log(path: Path, n: int, mass: str) -> None:
    """A closed one-axis run log of ``n`` cycles at 1 kHz carrying payload ``mass``."""
    log = RunLog(path, n_axes=1, cycle_s=0.001, chunk_seconds=0.05,
                 metadata={"payload": {"mass_kg": mass, "arm_m": "1.2"},
                           "campaign": {"joint_kind": "revolute", "cycle_s": "0.001"}})
    fr = FRAME.pack(1.5, 0x80, 0, b"")
    for c in range(n):
        log.state(0, c, c * 1e-3, 0.001 * c, 0.0, 1.0, 1.0, c, 0, 0, 0, 0x1237, 0)
        log.setpoint(c, c * 1e-3, 0.001 * c, 0.0, 0.0, 0, 0)
        log.frames(c, fr, 1)
    log.close({"status": "done"})


def test_recover_refuses_an_existing_output(tmp_path, capsys):
    src = tmp_path / "c_payload0.mcap"
    other = tmp_path / "c_payload1.mcap"
    _log(src, 300, "0.0")
    _log(other, 200, "5.0")
    before = other.read_bytes()
    assert main(["recover", str(src), "-o", str(other)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"jointid recover: error: {other}: already exists")
    assert len(err.strip().splitlines()) == 1
    assert other.read_bytes() == before
    assert read_run(other).metadata["payload"]["mass_kg"] == "5.0"
    assert not (tmp_path / "c_payload1.mcap.part").exists()
    # a new name is still written
    new = tmp_path / "fixed.mcap"
    assert main(["recover", str(src), "-o", str(new)]) == 0
    assert len(read_run(new).cycle) == 300
