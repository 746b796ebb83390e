"""How much of a joint's data sits within the closed loop's load jitter of the quadrant
boundary: the paper model's truth-free warning of quadrants blended by the low-pass
(docs/robot-identification.md, "Known limit: quadrants blended by the low-pass").

The paper model decides each row's quadrant from the predicted load tau_out_hat_j, computed on
the low-passed states (eq. 27-28, 44). The load the joint's friction really follows also has
the closed loop's high-frequency part (the drive reacting to encoder steps, the current loop),
which the filter removes. Where |tau_out_hat_j| is smaller than that part, the true quadrant
flips within one filter window and the filtered friction is a mix of both quadrants (with the
rectified jitter adding to the apparent Coulomb friction), while the model gives the row one:
the dry-friction terms come out biased beyond their standard deviation, and no resampling of
the rows (the jackknife) sees it.

The jitter is measured without the truth as the RMS of the measured torque above the chain's
cut-off, tau - lowpass(tau) (an upper bound of the load's part: it also holds the torque
measurement's own noise). It is a scalar per joint and run read for a warning only: no column
of any model is computed from it (the developers' rule: never fit the output with itself).

Measured (2026-11-28, ``jointid fit --robot``'s defaults; share of the kept rows with
|tau_out_hat_j| below the joint's jitter; ``benchmarks/load_jitter_share.py``): the simulated
arm3's gravity-free base yaw 18-39 % at 1 kHz, 500 and 250 Hz (seeds 1 and 2; its c_g1 23-41
sigma off at 1 kHz), the shoulder and elbow at most 1.2 %; the real KUKA recording A's base
axis A1 11.7 %, A2-A6 at most 6 %.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..chain import FullRate, decimation_index
from .signals import RobotSignals

#: A joint whose kept rows have |tau_out_hat| below the torque's jitter above the cut-off on
#: more than this share gets the warning (half :data:`trajectories.excitation.
#: ZERO_LOAD_SHARE`, the share of rows at zero load that the planner names).
JITTER_SHARE = 0.10


def jitter_share(
    signals: RobotSignals,
    loads: Sequence[tuple[FullRate, np.ndarray]],
    decimation: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Per joint, the share of its kept rows whose predicted load is within the torque's
    jitter above the cut-off, and that jitter.

    Parameters
    ----------
    signals : RobotSignals
        :func:`ident.robot.design.design_runs`'s output (its ``columns.keep``: after the sign
        check when it ran).
    loads : sequence of (FullRate, ndarray (n_f, k))
        Per run, :func:`ident.robot.design.full_rate_loads`: the chain's full-rate signals
        (raw torque ``tau`` and low-passed ``tau_f``) [N m] and tau_out_hat [N m].
    decimation : int
        The chain's decimation factor (which full-rate samples are rows).

    Returns
    -------
    share : ndarray, shape (k,)
        Kept rows with |tau_out_hat_j| < jitter_j (of their run) / kept rows.
    jitter : ndarray, shape (k,)
        RMS of tau - lowpass(tau) over the runs' full-rate samples [N m].
    """
    cols = signals.columns
    k = signals.q.shape[1]
    small = np.zeros(k)
    kept = np.zeros(k)
    power = np.zeros(k)
    count = 0
    for i, (f, tau_out) in enumerate(loads):
        high = f.tau - f.tau_f
        rms = np.sqrt(np.mean(high * high, axis=0))
        power += np.sum(high * high, axis=0)
        count += f.n
        rows = np.flatnonzero(signals.experiment == i)
        keep = cols.keep[rows] if cols is not None else np.ones((rows.size, k), dtype=bool)
        at = decimation_index(f.n, decimation)
        small += np.count_nonzero((np.abs(tau_out[at]) < rms) & keep, axis=0)
        kept += np.count_nonzero(keep, axis=0)
    return small / np.maximum(kept, 1), np.sqrt(power / max(count, 1))


def jitter_note(joint: str | None, share: float, jitter: float) -> str:
    """The fit's one-line warning for a joint above :data:`JITTER_SHARE` (``joint`` None:
    the single-joint fit's)."""
    who = "paper model" if joint is None else f"paper model, {joint}"
    return (f"{who}: {100 * share:.0f} % of the rows have a predicted load "
            f"within the torque's jitter above the cut-off (RMS {jitter:.3g}): there the "
            "true quadrant flips within the filter window and the filtered friction mixes "
            "both; its dry-friction terms may be biased beyond their sigma "
            "(docs/robot-identification.md, 'quadrants blended by the low-pass')")
