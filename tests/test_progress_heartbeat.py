"""The heartbeat: a silent long step still prints a line every interval (issue 23: the UR10
demo printed nothing for 22 minutes during refinement)."""

from __future__ import annotations

import io
import time

from daq.runtime.progress import Heartbeat, ProgressLine


def _wait_for(pred, timeout_s: float = 20.0) -> bool:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if pred():
            return True
        time.sleep(0.02)
    return pred()


def test_a_silent_step_gets_lines_naming_it_with_its_time():
    out = io.StringIO()
    with Heartbeat(out, interval_s=0.2) as hb:
        hb.status("refining joint j2")
        assert _wait_for(lambda: out.getvalue().count("refining joint j2") >= 2)
    lines = out.getvalue().splitlines()
    assert all(ln.startswith("      ... refining joint j2 (") and ln.endswith(" s)")
               for ln in lines)


def test_output_through_its_stream_resets_the_clock_and_none_is_silent():
    out = io.StringIO()
    with Heartbeat(out, interval_s=0.5) as hb:
        hb.status(None)  # e.g. while the campaign's own progress bar runs
        time.sleep(1.2)
        assert out.getvalue() == ""
        hb.interval = 3.0
        hb.status("fitting")
        # a line written by the step itself counts as a sign of life: written every 0.05 s,
        # no heartbeat line comes between them (unless the machine stalled this thread for
        # the whole interval)
        gaps, last = [], time.monotonic()
        for _ in range(12):
            hb.stream.write("step line\n")
            time.sleep(0.05)
            now = time.monotonic()
            gaps.append(now - last)
            last = now
        if max(gaps) < 2.5:
            assert "fitting" not in out.getvalue()
    assert out.getvalue().count("step line") == 12


def test_a_progress_bar_on_its_stream_works_and_a_beat_starts_on_a_new_line():
    out = io.StringIO()
    out.isatty = lambda: True  # the bar redraws one line with \r
    with Heartbeat(out, interval_s=0.2) as hb:
        bar = ProgressLine(hb.stream, width=4)
        bar.update(0.5, "half", force=True)
        hb.status("still here")
        assert _wait_for(lambda: "still here" in out.getvalue())
        bar.close()
    text = out.getvalue()
    assert text.startswith("\r[##..]  50.0% half\n      ... still here (")
