"""Wall time of the demos, as a stranger runs them: ``jointid demo --quick`` and
``jointid demo --robot`` (the 3-dof arm), each in its own subprocess, timed end to end.

For each demo it prints the wall time, the CPU time of the subprocess (user + sys: what the
demo costs, whatever else the machine runs), the time of each stage the demo reports (its
``[k/n] ... (x s)`` lines), the load average before and after (``os.getloadavg``; 2 idle
cores: below 1), and the key figures: Table III and the refinement result (quick demo), the
per-joint Table III and refinements (robot demo). The README quotes this output.

Usage: ``python benchmarks/bench_demo.py [--only quick|robot|robot6|full] [--keep DIR]``
(default: quick and robot; ``robot6`` is the UR10 demo, ``full`` the full single-joint demo).
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: name -> jointid demo arguments
DEMOS = {
    "quick": ["demo", "--quick"],
    "robot": ["demo", "--robot"],
    "robot6": ["demo", "--robot", "6"],
    "full": ["demo"],
}
#: the stage lines a demo prints on stderr that carry a time
STAGE = re.compile(r"^\[(\d)/(\d)\] (.*)$")
#: longest silence on stderr [s] the progress contract allows
MAX_SILENCE_S = 10.0


def run_demo(args: list[str], out: Path) -> dict:
    """Run ``jointid <args> --out out`` in a subprocess; wall and CPU time, output, silences."""
    cmd = [sys.executable, "-c", "import sys; from daq.app.cli import main; sys.exit(main())",
           *args, "--out", str(out)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    err_lines: list[str] = []
    last = t0
    longest = 0.0
    assert proc.stderr is not None
    for line in proc.stderr:  # stderr is line-buffered progress: time the gaps
        now = time.perf_counter()
        longest = max(longest, now - last)
        last = now
        err_lines.append(line.rstrip("\n"))
    stdout = proc.stdout.read() if proc.stdout is not None else ""
    rc = proc.wait()
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"rc": rc, "wall_s": wall, "cpu_s": cpu, "stdout": stdout, "stderr": err_lines,
            "load_before": load0, "load_after": os.getloadavg(), "longest_silence_s": longest}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=tuple(DEMOS), action="append",
                    help="run only this demo (repeatable; default: quick and robot)")
    ap.add_argument("--keep", type=Path, default=None,
                    help="write the demos' output folders here (default: a temporary folder)")
    a = ap.parse_args(argv)
    names = a.only or ["quick", "robot"]
    with tempfile.TemporaryDirectory() as tmp:
        root = a.keep or Path(tmp)
        print(f"bench_demo: {os.cpu_count()} CPUs, {time.strftime('%Y-%m-%d %H:%M %Z')}")
        failed = 0
        for name in names:
            r = run_demo(DEMOS[name], root / name)
            la = " ".join(f"{x:.2f}" for x in r["load_before"])
            lb = " ".join(f"{x:.2f}" for x in r["load_after"])
            print(f"\n=== jointid {' '.join(DEMOS[name])}: {r['wall_s']:.1f} s wall, "
                  f"{r['cpu_s']:.1f} s CPU (exit {r['rc']}); load average before {la}, "
                  f"after {lb}; longest silence on stderr {r['longest_silence_s']:.1f} s "
                  f"({'ok' if r['longest_silence_s'] <= MAX_SILENCE_S else 'TOO LONG'})")
            for line in r["stderr"]:
                m = STAGE.match(line)
                if m:
                    print(f"  {line}")
            if r["rc"] != 0:
                failed += 1
                print("\n".join(r["stderr"][-20:]))
                continue
            print(r["stdout"].rstrip())
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
