"""The single-joint fit's notes name the axis of a multi-drive MCAP log, not of a one-drive
log (``ident.cli._axis_label``; a one-axis log read as ``axis 0`` was named in every note)."""

from __future__ import annotations

import pytest

from daq.runtime.mcaplog import RunLog
from ident.cli import _axis_label


def _log(path, n_axes: int, drive_meta: bool = True):
    meta = {"campaign": {"name": "t"}}
    if drive_meta:
        meta.update({f"drive{i}": {"node_id": str(i + 1)} for i in range(n_axes)})
    with RunLog(path, n_axes=n_axes, cycle_s=0.001, metadata=meta):
        pass
    return path


@pytest.mark.parametrize("n_axes, drive_meta, want", [
    (1, True, None), (2, True, "axis 1"), (1, False, "axis 1")])
def test_axis_named_only_for_multi_drive_logs(tmp_path, n_axes, drive_meta, want):
    p = _log(tmp_path / "run.mcap", n_axes, drive_meta)
    assert _axis_label([p], {}, 1) == want


def test_mapped_row_is_named_and_plain_files_are_not(tmp_path):
    assert _axis_label([tmp_path / "a.mat"], {"q": "rec.q[3]"}, 0) == "axis rec.q[3]"
    assert _axis_label([tmp_path / "a.csv"], {"q": "q"}, 0) is None
