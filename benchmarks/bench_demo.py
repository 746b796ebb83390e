"""Wall time of the demos, as a stranger runs them: ``jointid demo --quick`` and
``jointid demo --robot`` (the 3-dof arm), each in its own subprocess, timed end to end.

For each demo it prints the wall time, the CPU time of the subprocess (user + sys: what the
demo costs, whatever else the machine runs), the time of each stage the demo reports (its
``[k/n] ... (x s)`` lines), the load average before and after (``os.getloadavg``; 2 idle
cores: below 1), and the key figures: Table III and the refinement result (quick demo), the
per-joint Table III and refinements (robot demo). The README quotes this output.

Usage: ``python benchmarks/bench_demo.py [--only quick|robot|robot6|full] [--keep DIR]
[--before DIR]`` (default: quick and robot; ``robot6`` is the UR10 demo, ``full`` the full
single-joint demo). ``--before DIR``: DIR holds an older tree of the code (e.g.
``git archive d4a25f9 | tar -x -C DIR``); each demo is also run with ``PYTHONPATH=DIR``, the
old run just before the new one, and a last table gives both and the ratios old / new of the
wall time, the CPU time and the refinement stage's time (the ``[4/4] refinement`` or
``[5/5] refined`` line: its wall time as printed, and the CPU time the process spent between
the previous stage line and it, read from ``/proc``), from the same run.
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

#: this tree
ROOT = Path(__file__).resolve().parents[1]
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


#: the stage line with the refinement's time: [4/4] refinement ... (x s) / [5/5] refined ...
REFINE_STAGE = re.compile(r"^\[(?:4/4\] refinement|5/5\] refined).*\((\d+(?:\.\d+)?) s\)$")


def run_demo(args: list[str], out: Path, pythonpath: Path | None = None) -> dict:
    """Run ``jointid <args> --out out`` in a subprocess (with ``PYTHONPATH=pythonpath``: an
    older tree of the code); wall and CPU time, output, silences."""
    cmd = [sys.executable, "-c", "import sys; from daq.app.cli import main; sys.exit(main())",
           *args, "--out", str(out)]
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)
    # python -c puts the working directory first on sys.path: run in the tree being timed
    cwd = pythonpath if pythonpath is not None else ROOT
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, cwd=cwd)
    err_lines: list[str] = []
    last = t0
    longest = 0.0
    cpu_at = 0.0
    stage_cpu: dict[str, float] = {}
    assert proc.stderr is not None
    for line in proc.stderr:  # stderr is line-buffered progress: time the gaps
        now = time.perf_counter()
        longest = max(longest, now - last)
        last = now
        err_lines.append(line.rstrip("\n"))
        if STAGE.match(err_lines[-1]):  # the CPU the process spent since the previous stage
            c = _proc_cpu_s(proc.pid)
            stage_cpu[err_lines[-1]] = c - cpu_at
            cpu_at = c
    stdout = proc.stdout.read() if proc.stdout is not None else ""
    rc = proc.wait()
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"rc": rc, "wall_s": wall, "cpu_s": cpu, "stdout": stdout, "stderr": err_lines,
            "stage_cpu_s": stage_cpu,
            "load_before": load0, "load_after": os.getloadavg(), "longest_silence_s": longest}


def _proc_cpu_s(pid: int) -> float:
    """User + system CPU time [s] of a running process so far (Linux /proc; NaN elsewhere)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=tuple(DEMOS), action="append",
                    help="run only this demo (repeatable; default: quick and robot)")
    ap.add_argument("--keep", type=Path, default=None,
                    help="write the demos' output folders here (default: a temporary folder)")
    ap.add_argument("--before", type=Path, default=None,
                    help="an older tree of the code: each demo is also run on it, just before")
    a = ap.parse_args(argv)
    names = a.only or ["quick", "robot"]
    if a.before is not None and not (a.before / "daq" / "app" / "cli.py").is_file():
        print(f"bench_demo: --before {a.before}: no daq/app/cli.py there (expected a tree of "
              "the code)", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        root = a.keep or Path(tmp)
        print(f"bench_demo: {os.cpu_count()} CPUs, {time.strftime('%Y-%m-%d %H:%M %Z')}")
        failed = 0
        pairs: list[tuple[str, dict, dict]] = []
        runs = [(n, v) for n in names for v in (("before", "now") if a.before else ("now",))]
        done: dict[str, dict] = {}
        for name, version in runs:
            old = version == "before"
            r = run_demo(DEMOS[name], root / (f"{name}_before" if old else name),
                         a.before if old else None)
            if old:
                done[name] = r
            elif name in done:
                pairs.append((name, done[name], r))
            print(f"\n--- {'before: ' + str(a.before) if old else 'this tree'}")
            la = " ".join(f"{x:.2f}" for x in r["load_before"])
            lb = " ".join(f"{x:.2f}" for x in r["load_after"])
            print(f"\n=== jointid {' '.join(DEMOS[name])}: {r['wall_s']:.1f} s wall, "
                  f"{r['cpu_s']:.1f} s CPU (exit {r['rc']}); load average before {la}, "
                  f"after {lb}; longest silence on stderr {r['longest_silence_s']:.1f} s "
                  f"({'ok' if r['longest_silence_s'] <= MAX_SILENCE_S else 'TOO LONG'})")
            for line in r["stderr"]:
                m = STAGE.match(line)
                if m:
                    print(f"  {line}  [{r['stage_cpu_s'].get(line, float('nan')):.1f} s CPU]")
            if r["rc"] != 0:
                failed += 1
                print("\n".join(r["stderr"][-20:]))
                continue
            print(r["stdout"].rstrip())
        if pairs:
            print(f"\nbefore ({a.before}) / now, each pair run one after the other")
            print(f"{'demo':<8} {'wall before':>11} {'now':>7} {'ratio':>6}   {'CPU before':>10} "
                  f"{'now':>7} {'ratio':>6}   {'refinement before':>17} {'now':>7} {'ratio':>6}"
                  f"   {'its CPU before':>14} {'now':>7} {'ratio':>6}")
            for name, b, n in pairs:
                (rb, cb), (rn, cn) = _refine_s(b), _refine_s(n)
                print(f"{name:<8} {b['wall_s']:>10.1f}s {n['wall_s']:>6.1f}s "
                      f"{b['wall_s'] / n['wall_s']:>6.2f}   {b['cpu_s']:>9.1f}s "
                      f"{n['cpu_s']:>6.1f}s "
                      f"{b['cpu_s'] / n['cpu_s']:>6.2f}   {rb:>16.1f}s {rn:>6.1f}s "
                      f"{rb / rn if rn > 0 else float('nan'):>6.2f}   {cb:>13.1f}s {cn:>6.1f}s "
                      f"{cb / cn if cn > 0 else float('nan'):>6.2f}")
    return 1 if failed else 0


def _refine_s(r: dict) -> tuple[float, float]:
    """The refinement stage's wall time [s] the demo printed and the CPU time [s] the
    process spent on it (NaN if none)."""
    for line in r["stderr"]:
        m = REFINE_STAGE.match(line)
        if m:
            return float(m.group(1)), r["stage_cpu_s"].get(line, float("nan"))
    return float("nan"), float("nan")


if __name__ == "__main__":
    sys.exit(main())
