"""The robot path's default fit (WLS) against the simulated arm's truth, at 1 kHz, 500 Hz and
250 Hz, at the default cut-off and given ones (docs/robot-identification.md, "The default
cut-off on logs slower than 1 kHz").

Usage: ``python benchmarks/bench_robot_cutoff_band.py [--seed 1] [--friction paper|usual]
[--duration 20] [--held] [--suffix csv|mcap] [--torque-delay default|hold] [--default-cutoff]``

The simulated 3-dof arm (``examples/robots/arm3.toml``, ``sim_drivers.arm.simulate_arm`` at
1 kHz) tracks the sum-of-sines excitation of tests/test_robot_fit.py (centre where the shoulder
and elbow loads change sign; three payload runs, 0, 5 and 10 kg; noise seeds 10 seed + i) with
the paper friction on every joint (``--friction paper``, the paper model judged) or the usual
one (``--friction usual``: a = 1, b = d = 0, c_g = c_m; the usual model judged, FC = c_m). The
log is what the simulated drives report: measured position (encoder counts), torque actual
(command + ripple noise, the torque acting on the arm, whole per-mille of rated torque), the
reference. Each command is held over the cycle after its sample: the logged torque of sample k
is the mean of the two held around its instant, so that the files, named ``.csv`` (torque delay
0, as a stranger's file), are timed right at every rate (with the held torque, delay 0 misses
half a 1 kHz cycle at every rate and biases the usual model's F_V 6-9 sigma at 1 kHz, ``--held``;
the ``.mcap`` rule, half a sample, is right at 1 kHz only: F_V2 +5 sigma at 250 Hz, ``--held
--suffix mcap``; ``--held --torque-delay hold`` gives the hold's own delay, half a 1 kHz
cycle, 0.5 / n samples when every n-th sample is kept). The runs are subsampled (every 2nd,
every 4th sample) and fitted by ``jointid fit --robot``'s chain with its
defaults (:func:`ident.cli_robot.fit_files`: columns chain, sign check, WLS, honest sigma,
pruning; ``feasibility=False``, which changes no parameter). Printed per case: f_s [Hz], the
cut-off [Hz] ("*": the default, :func:`ident.chain.choose_cutoff`'s floor 0.05 f_s), the
decimation, the torque delay [samples] ("g": given), the sum of z^2 = ((estimate - truth) /
sigma)^2 over the judged model's parameters that are not pruned (about their number, printed
after the slash, when the sigmas hold), the three largest |z| and the number of pruned
parameters.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_robot_cutoff_band import logged, simulated, z_scores  # noqa: E402

from ident.cli_robot import fit_files  # noqa: E402

#: (every n-th sample, given cut-offs [Hz]; None: the default).
CASES = ((1, (None, 12.5, 25.0, 75.0, 125.0)), (2, (None, 50.0, 75.0, 125.0)),
         (4, (None, 25.0, 50.0, 75.0, 100.0)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--friction", choices=("paper", "usual"), default="paper")
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per run")
    ap.add_argument("--held", action="store_true",
                    help="log the torque held over the cycle after its sample (not centred)")
    ap.add_argument("--suffix", choices=("csv", "mcap"), default="csv",
                    help="the files' suffix (mcap: torque delay half a sample)")
    ap.add_argument("--torque-delay", choices=("default", "hold"), default="default",
                    help="default: the files' rule (csv 0, mcap half a sample); hold: given, "
                    "half a 1 kHz cycle (0.5 / n samples with every n-th sample kept)")
    ap.add_argument("--default-cutoff", action="store_true",
                    help="only the default cut-off at each rate")
    a = ap.parse_args()
    params, reg, runs, truth = simulated(a.friction, a.seed, a.duration)
    print(f"arm3, {a.friction} friction, seed {a.seed}, {a.duration:g} s x 3 runs; "
          f"{a.friction} model: f_s [Hz], cut-off [Hz], decimation, sum z^2 / parameters, "
          "largest |z|, pruned")
    for every, cuts in CASES:
        exps = logged(params, runs, every, a.held, a.suffix)
        delay = 0.5 / every if a.torque_delay == "hold" else None  # [samples]
        for cut in cuts[:1] if a.default_cutoff else cuts:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out = fit_files(reg.robot, exps, model="both", cutoff=cut, feasibility=False,
                                torque_delay=delay)
            z, pruned = z_scores(out, a.friction, truth)
            top = sorted(z, key=lambda n: -abs(z[n]))[:3]
            s = out["preprocessing"]
            print(f"{1000 / every:5.0f} {s['cutoff_hz']:7.2f}{'*' if cut is None else ' '} "
                  f"{s['decimation']:3d} {s['torque_delay']:.3f}"
                  f"{'g' if s['torque_delay_given'] else ' '} "
                  f"{sum(v * v for v in z.values()):8.0f} / {len(z)}  "
                  + "  ".join(f"{n} {z[n]:+.1f}" for n in top) + f"  pruned {pruned}",
                  flush=True)


if __name__ == "__main__":
    main()
