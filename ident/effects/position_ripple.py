"""Position ripple A sin(2π q/P + φ) (cogging, gear mesh, screw pitch).

Offered when the residual's periodogram against position has a significant peak; the
period P is refined around the peak (:func:`scan_period`: a grid on a subsample brackets it,
a bounded search on every row chooses it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..signals import Signals
from ._base import Candidate, Context, Effect, amplitude_phase, register, unique_tag
from ._jackknife import hyper_jackknife
from ._scan import Columns, refine_1d

if TYPE_CHECKING:  # pragma: no cover
    from ..preprocess import Design


class PositionRipple(Effect):
    """Position-periodic torque A sin(2π q / P + φ) (cogging, gear mesh, screw pitch).

    Parameters
    ----------
    period : float
        Period P in position [rad or m]; a hyper-parameter refined on the residual.
    """

    effect = "position_ripple"
    variable = "position"
    hyper_names = ("period",)

    def __init__(self, period: float, tag: str = "") -> None:
        super().__init__(tag)
        if not period > 0:
            raise ValueError(f"PositionRipple: period must be > 0, got {period}")
        self.period = float(period)

    def with_hyper(self, **values: float) -> PositionRipple:
        return PositionRipple(values.get("period", self.period), self.tag)

    def names(self) -> tuple[str, ...]:
        return (self._n("ripple_sin"), self._n("ripple_cos"))

    def columns(self, s: Signals) -> np.ndarray:
        th = (2 * np.pi / self.period) * s.q
        return np.column_stack((np.sin(th), np.cos(th)))

    def parameters(self, coef, cov):
        # A sin(th + phi) = A cos(phi) sin(th) + A sin(phi) cos(th)
        amp, amp2, phase, phase2 = amplitude_phase(coef, cov)
        out = {
            self._n("ripple_amplitude"): (amp, amp2),
            self._n("ripple_phase"): (phase, phase2),
        }
        sdp = math.sqrt(max(float(cov[2, 2]), 0.0)) if len(coef) > 2 else 0.0
        out[self._n("ripple_period")] = (self.period, 2 * sdp)
        return out

    def jackknife(self, design: Design, names: Sequence[str]) -> dict[str, float] | None:
        """2σ of amplitude, period and phase by the block jackknife, the period scanned again
        in every replicate as the refinement scans it (:func:`scan_period` around the fitted
        period, on the replicate's rows): the linearised 2σ of the period assumes white
        residuals, while the filtered, decimated residual is autocorrelated and an IDIM-IV
        fit's spread is not eq. 15's (docs/refinement.md, "The ripple's 2σ")."""
        q = design.signals.q
        span = float(q.max() - q.min())
        if not span > 0:
            return None
        ref: list[float] = []

        def physical(coef: np.ndarray, e: Effect) -> np.ndarray:
            a, b = float(coef[0]), float(coef[1])
            phi = math.atan2(b, a)
            if not ref:
                ref.append(phi)
            # the phase near the first replicate's (no jump of 2π between replicates)
            phi = ref[0] + math.remainder(phi - ref[0], 2 * math.pi)
            return np.array([math.hypot(a, b), e.hyper["period"], phi])

        sd = hyper_jackknife(self, design, names,
                             lambda cols: scan_period(cols, self.period, span, self.tag)[0],
                             physical)
        if sd is None:
            return None
        keys = ("ripple_amplitude", "ripple_period", "ripple_phase")
        return {self._n(k): 2 * float(v) for k, v in zip(keys, sd, strict=True)}

    def describe(self) -> str:
        return f"position ripple A sin(2π q/{self.period:.6g} + φ)"


def scan_period(cols: Columns, p0: float, span: float, tag: str) -> tuple[Effect, float]:
    """Ripple period: grid over ±1.5 frequency bins (1/span) around the periodogram peak
    p0 on :attr:`Columns.fast` (at most ~8000 rows), then a bounded search between the
    grid neighbours of its best point on every row of ``cols`` (frequency resolution
    ~1e-7 f0); the returned gain is on every row. The subsample only brackets the peak: a
    period chosen on it too was less accurate (docs/refinement.md, "The ripple's 2σ")."""
    f0, df = 1 / p0, 1.5 / span
    lo, hi = max(f0 - df, 0.5 * f0), f0 + df
    fgrid = np.linspace(lo, hi, 31)
    gains = np.array([cols.fast.gain(PositionRipple(1 / f, tag)) for f in fgrid])
    i = int(np.argmax(gains))
    a, b = fgrid[max(i - 1, 0)], fgrid[min(i + 1, len(fgrid) - 1)]

    def make(f: float) -> Effect:
        return PositionRipple(1 / f, tag)

    g0 = float(gains[i]) if cols.fast is cols else cols.gain(make(fgrid[i]))
    return refine_1d(cols, make, a, b, fgrid[i], g0, 1e-7 * f0)


@register("position_ripple", order=10)
def propose(ctx: Context) -> list[Candidate]:
    """A ripple at the position periodogram's peak, when it is significant."""
    pp = ctx.diag.position_periodogram
    if ctx.span > 0 and math.isfinite(pp.peak_period) and pp.false_alarm < ctx.alpha:
        tag = unique_tag(("ripple_sin", "ripple_cos"), ctx.names)
        e, g = scan_period(ctx.cols, pp.peak_period, ctx.span, tag)
        return [Candidate(e, g, 1)]
    return []
