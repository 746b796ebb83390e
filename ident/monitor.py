"""The identified model as a torque predictor for monitoring, and the thresholds' statistics.

(Past 600 lines: the predictor's band and its observer quantities share the friction's
per-joint coefficients and formula, and the thresholds file is read and written next to the
statistics that fill it; splitting would spread one monitor model over two modules.)

:class:`TorquePredictor` evaluates an exported model (docs/model-export.md: a URDF with the
consistent inertials, ``friction.json``) one sample at a time, fast enough for a 1 kHz loop:
pinocchio's RNEA on the URDF (gravity of the friction file, the run's payload attached to the
last moving link, scaled by ``payload_ratio`` when given), then eq. 30 (paper) or
``FC sign + FV dq + OFF`` (usual) per joint -- :func:`ident.robot.export_model.exported_torque`
on one row, written with scalars. For the generalized-momentum observer
(``daq.runtime.monitor.MomentumObserver``) it also gives M (with the rotor inertias), C^T dq
and g of one sample, and the load torque the measured drive torque gives through the
friction's inverse per quadrant (:meth:`TorquePredictor.observer_terms`). It is built from
an ``export-model`` folder
(:func:`load_exported`) or from a fit record (:func:`exported_from_fit`: its consistent
estimate, as ``jointid export-model`` computes it, kept in memory).

:class:`Thresholds` holds, per joint, the mean and standard deviation of a residual recorded
without collision (a validation run) and the band ``mean +- k_sigma sigma`` a monitored
residual must stay in, widened to ``peak_margin`` times the largest deviation of the
validation residual when that is larger (docs/monitoring.md).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from daq.protocol.logformat import MONITOR_EDGES_S, MONITOR_RESIDUALS
from trajectories.robot import Robot

from . import DataError
from .cli_export_model import consistent_from_record, read_fit_record
from .robot.export_model import FRICTION_FORMAT, friction_record, urdf_text
from .vocab import upgrade_record

__all__ = ["DEFAULT_EDGES_S", "DEFAULT_MIN_EPISODES", "DEFAULT_MIN_SAMPLES",
           "RESIDUAL_KINDS", "THIN_BINS", "THRESHOLDS_FORMAT", "Thresholds", "TorquePredictor",
           "exported_from_fit", "horizon_factor", "load_exported", "load_model", "persistent",
           "thresholds_from_residual"]

THRESHOLDS_FORMAT = "jointid-monitor-thresholds/2"
#: the residuals a thresholds file can be calibrated on (its ``residual`` key; a /2 file
#: without it, and every /1 file: ``filtered``)
RESIDUAL_KINDS = MONITOR_RESIDUALS  # the log format's (daq.protocol.logformat)
#: the format before the regime bins (read too: a constant band)
THRESHOLDS_FORMAT_1 = "jointid-monitor-thresholds/1"



def _read_json(path: Path, missing: str) -> Any:
    """The JSON content of ``path``; one-line :class:`DataError` naming the file when it is
    missing (``missing`` says why) or not JSON."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(f"{path}: {missing}") from None
    except json.JSONDecodeError as e:
        raise DataError(f"{path}: not JSON ({e.msg}, line {e.lineno})") from None

class TorquePredictor:
    """Joint torques [N m] the exported model predicts for one sample (module docstring).

    Parameters
    ----------
    urdf : str
        URDF text of the exported model (its moving joints in the robot's order).
    friction : mapping
        The friction file's content (``jointid-friction/2``; ``/1`` read too).
    payload : object, optional
        ``mass_kg`` (or ``mass``) [kg], ``com`` (3,) [m] in the last moving joint's frame,
        ``inertia`` (XX XY XZ YY YZ ZZ about the CoM) [kg m^2]; None or 0 kg: none.
    source : str
        Where the model came from (for messages and the log).
    """

    def __init__(self, urdf: str, friction: Mapping[str, Any], payload: Any = None,
                 source: str = "") -> None:
        if friction.get("format") not in (FRICTION_FORMAT, "jointid-friction/1"):
            raise DataError(f"{source or 'friction'}: format {friction.get('format')!r}: "
                            f"expected {FRICTION_FORMAT!r}")
        friction = upgrade_record(dict(friction))  # jointid-friction/1: "qs" for q_s
        try:
            model = pin.buildModelFromXML(urdf)
        except Exception as exc:  # noqa: BLE001 - pinocchio raises plain exceptions
            raise DataError(f"{source or 'urdf'}: not a URDF pinocchio reads ({exc})"
                            ) from None
        self.k = k = model.njoints - 1
        joints = list(friction.get("joints", []))
        if len(joints) != k:
            raise DataError(f"{source}: friction.joints: expected {k} joints (the URDF's), "
                            f"got {len(joints)}")
        model.gravity = pin.Motion(np.r_[np.asarray(friction["gravity"], float), 0.0, 0.0,
                                        0.0])
        mass = float(getattr(payload, "mass_kg", getattr(payload, "mass", 0.0)) or 0.0)
        if mass > 0:
            ratio = float(friction.get("payload_ratio", 1.0))
            xx, xy, xz, yy, yz, zz = (ratio * float(v) for v in payload.inertia)
            ic = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
            model.inertias[k] = model.inertias[k] + pin.Inertia(
                ratio * mass, np.asarray(payload.com, float), ic)
        self.model, self.data = model, model.createData()
        self.names = [str(j["name"]) for j in joints]
        self.paper = friction["model"] == "paper"
        keys = (("rotor_inertia", "q_s", "a_m", "b_m", "a_g", "b_g", "c_m", "d_m", "c_g",
                 "d_g", "FV", "OFF") if self.paper else ("rotor_inertia", "FC", "FV", "OFF"))
        try:
            self._coef = [tuple(float(j[key]) for key in keys) for j in joints]
        except KeyError as e:
            raise DataError(f"{source}: friction.joints: key {e.args[0]!r} missing") from None
        self.source = source
        #: Stribeck velocity q_s of each joint [rad/s] (the friction file's ``q_s``)
        self.q_s = [float(j.get("q_s", 0.0)) for j in joints]

    def _friction(self, j: int, t_out: float, v: float, s: float, e: float) -> float:
        """Joint j's torque for output torque ``t_out``, velocity ``v``, sign ``s``, Stribeck
        factor ``e`` (the exported model's formula)."""
        c = self._coef[j]
        if not self.paper:
            return t_out + c[1] * s + c[2] * v + c[3]
        _, _, am, bm, ag, bg, cm, dm, cg, dg, fv, off = c
        p = t_out * s
        if p > 0:
            tau = (am + bm * e) * t_out + (cm + dm * e) * s
        elif p < 0:
            tau = (ag - bg * e) * t_out + (cg + dg * e) * s
        else:  # P+ = P- = 1/2 (sign 0), as exported_torque
            tau = 0.5 * ((am + bm * e) * t_out + (cm + dm * e) * s
                         + (ag - bg * e) * t_out + (cg + dg * e) * s)
        return tau + fv * v + off

    def _rigid(self, q: Sequence[float], dq: Sequence[float], ddq: Sequence[float]
               ) -> list[float]:
        """tau_out = RNEA + Ia ddq per joint [N m]."""
        tr = pin.rnea(self.model, self.data, np.asarray(q, float), np.asarray(dq, float),
                      np.asarray(ddq, float)).tolist()
        return [t + c[0] * float(a) for t, c, a in zip(tr, self._coef, ddq, strict=True)]

    def __call__(self, q: Sequence[float], dq: Sequence[float],
                 ddq: Sequence[float]) -> list[float]:
        """Predicted joint torques [N m] at q [rad], dq [rad/s], ddq [rad/s^2] (k each):
        :func:`~ident.robot.export_model.exported_torque` of one sample."""
        out = []
        exp = math.exp
        for j, t_out in enumerate(self._rigid(q, dq, ddq)):
            v = float(dq[j])
            s = 1.0 if v > 0 else -1.0 if v < 0 else 0.0
            e = exp(-abs(v) / self._coef[j][1]) if self.paper else 1.0
            out.append(self._friction(j, t_out, v, s, e))
        return out

    def band(self, q: Sequence[float], dq: Sequence[float], ddq: Sequence[float],
             v_rest: float | Sequence[float] = 0.0) -> tuple[list[float], list[float]]:
        """The torque interval [N m] the model allows: the prediction (both bounds equal)
        where ``|dq_j| >= v_rest`` [rad/s] (one value, or one per joint); below it, where
        sign(dq) is not known, the range of the friction the model gives at any speed below
        ``v_rest``: either sign of dq, Stribeck factor E from ``exp(-v_rest / q_s)`` to 1
        (the friction is linear in E, so the four corners bound it), plus the viscous and
        offset terms. With physical Stribeck terms (b, d >= 0) E = 1 bounds it: the
        stiction band of the paper's section III.B at the joint's load; an identified model
        may have them negative (static friction below the Coulomb level), and then E = 1
        alone would leave out the model's own prediction just below ``v_rest``.
        """
        lo, hi = [], []
        exp = math.exp
        vr = [float(v_rest)] * self.k if np.ndim(v_rest) == 0 else list(v_rest)
        for j, t_out in enumerate(self._rigid(q, dq, ddq)):
            v = float(dq[j])
            if abs(v) >= vr[j] and v != 0.0:
                e = exp(-abs(v) / self._coef[j][1]) if self.paper else 1.0
                x = self._friction(j, t_out, v, 1.0 if v > 0 else -1.0, e)
                lo.append(x)
                hi.append(x)
                continue
            e0 = exp(-vr[j] / self._coef[j][1]) if self.paper else 1.0
            x = [self._friction(j, t_out, v, s, e) for s in (1.0, -1.0) for e in (1.0, e0)]
            lo.append(min(x))
            hi.append(max(x))
        return lo, hi


    # -- the generalized-momentum observer's quantities (daq.runtime.monitor) ------------
    def momentum_terms(self, q: Sequence[float], dq: Sequence[float]
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(M (k, k) [kg m^2] with the rotor inertias Ia on its diagonal, C(q, dq)^T dq (k,)
        [N m], g(q) (k,) [N m]) at q [rad], dq [rad/s]: pinocchio's CRBA, Coriolis matrix
        (the one with dM/dt = C + C^T) and generalized gravity on this predictor's model
        (its payload attached). ``M ddq + C dq + g = tau_out`` is the model's rigid body
        (:meth:`_rigid`), so ``dp/dt = tau_out + C^T dq - g`` for ``p = M dq``."""
        model, data = self.model, self.data
        qa, va = np.asarray(q, float), np.asarray(dq, float)
        m = pin.crba(model, data, qa)
        m = np.triu(m) + np.triu(m, 1).T  # CRBA fills the upper triangle
        m[np.diag_indices(self.k)] += [c[0] for c in self._coef]
        c = pin.computeCoriolisMatrix(model, data, qa, va)
        g = pin.computeGeneralizedGravity(model, data, qa)
        return m, c.T @ va, np.array(g)

    def _load(self, j: int, tau: float, v: float, s: float, e: float) -> list[float]:
        """Output torques tau_out [N m] of joint j whose friction model gives the drive torque
        ``tau`` [N m] at velocity ``v``, sign ``s`` and Stribeck factor ``e``: the inverse of
        :meth:`_friction` per quadrant (motor candidate if ``tau_out s > 0``, generator
        candidate if ``tau_out s < 0``, the simulator's choice); both when both are
        consistent (then any load between them fits), 0 when neither is (``tau`` inside the
        jump of the dry friction at zero load)."""
        c = self._coef[j]
        if not self.paper:
            return [tau - c[1] * s - c[2] * v - c[3]]
        _, _, am, bm, ag, bg, cm, dm, cg, dg, fv, off = c
        x = tau - fv * v - off
        out = []
        km, kg = am + bm * e, ag - bg * e
        if km > 0 and (xm := (x - (cm + dm * e) * s) / km) * s > 0:
            out.append(xm)
        if kg > 0 and (xg := (x - (cg + dg * e) * s) / kg) * s < 0:
            out.append(xg)
        return out or [0.0]

    def load_interval(self, dq: Sequence[float], tau: Sequence[float],
                      v_rest: float | Sequence[float] = 0.0
                      ) -> tuple[list[float], list[float]]:
        """The output (load) torque tau_out [N m] per joint that the measured drive torque
        ``tau`` [N m] gives through the inverse of the friction model (no acceleration
        needed): one value where ``|dq_j| >= v_rest`` [rad/s] (an interval only where both
        quadrants fit), and below it -- where sign(dq) is not known -- the interval over
        either sign and the Stribeck factor from ``exp(-v_rest / q_s)`` to 1, the corners
        of :meth:`band` (each corner's friction is increasing in tau_out, so the corners'
        inverses bound the loads the whole band allows)."""
        lo, hi = [], []
        exp = math.exp
        vr = [float(v_rest)] * self.k if np.ndim(v_rest) == 0 else list(v_rest)
        for j in range(self.k):
            v, x = float(dq[j]), float(tau[j])
            if abs(v) >= vr[j] and v != 0.0:
                e = exp(-abs(v) / self._coef[j][1]) if self.paper else 1.0
                t = self._load(j, x, v, 1.0 if v > 0 else -1.0, e)
            else:
                e0 = exp(-vr[j] / self._coef[j][1]) if self.paper else 1.0
                t = [y for s in (1.0, -1.0) for e in (1.0, e0)
                     for y in self._load(j, x, v, s, e)]
            lo.append(min(t))
            hi.append(max(t))
        return lo, hi

    def observer_terms(self, q: Sequence[float], dq: Sequence[float], tau: Sequence[float],
                       v_rest: float | Sequence[float] = 0.0
                       ) -> tuple[list[float], list[float], list[float]]:
        """What the momentum observer (``daq.runtime.monitor.MomentumObserver``) needs of
        one sample of measured q [rad], dq [rad/s], drive torque tau [N m]: the momentum
        ``p = M dq`` [N m s], its model rate without external torque ``beta = tau_out + C^T
        dq - g`` [N m] with tau_out the centre of :meth:`load_interval`, and the interval's
        half-width [N m] (0 while the joint moves; the static friction's share below
        ``v_rest``)."""
        m, ctdq, g = self.momentum_terms(q, dq)
        lo, hi = self.load_interval(dq, tau, v_rest)
        p = (m @ np.asarray(dq, float)).tolist()
        beta = [0.5 * (a + b) + c - gg for a, b, c, gg in zip(lo, hi, ctdq.tolist(),
                                                            g.tolist(), strict=True)]
        return p, beta, [0.5 * (b - a) for a, b in zip(lo, hi, strict=True)]


@dataclass(frozen=True)
class ExportedModel:
    """An exported model in memory: URDF text and friction record (docs/model-export.md)."""

    urdf: str
    friction: dict[str, Any]
    source: str

    def predictor(self, payload: Any = None) -> TorquePredictor:
        """A :class:`TorquePredictor` for a run with ``payload``."""
        return TorquePredictor(self.urdf, self.friction, payload, self.source)


def load_exported(folder: str | Path) -> ExportedModel:
    """The model ``jointid export-model`` wrote into ``folder`` (one ``*.urdf`` and
    ``friction.json``).

    Raises
    ------
    DataError
        No or several URDF files, no friction.json, not JSON.
    """
    d = Path(folder)
    urdfs = sorted(d.glob("*.urdf"))
    if len(urdfs) != 1:
        raise DataError(f"{d}: expected one .urdf file (jointid export-model), found "
                        f"{len(urdfs)}")
    fpath = d / "friction.json"
    fr = _read_json(fpath, "missing (jointid export-model writes it)")
    if not isinstance(fr, dict):
        raise DataError(f"{fpath}: expected a JSON object")
    return ExportedModel(urdfs[0].read_text(encoding="utf-8"), fr, str(d))


def exported_from_fit(path: str | Path, robot: Robot, model: str | None = None
                      ) -> ExportedModel:
    """The consistent estimate of a fit record (``jointid fit --robot --json``) as an
    exported model, in memory (what ``jointid export-model`` would write).

    Raises
    ------
    DataError
        Not a fit record, the model not identified, its consistent estimate not valid, or
        the record's inputs do not give its parameters again.
    """
    path = Path(path)
    rec = read_fit_record(path)
    fitted = [n for n, r in rec.get("models", {}).items() if "error" not in r]
    name = model or ("paper" if "paper" in fitted else "usual")
    if name not in fitted:
        raise DataError(f"{path}: models.{name}: not identified in this record (it has "
                        f"{fitted or 'none'})")
    if list(robot.moving) != list(rec["robot"]["moving"]):
        raise DataError(f"{path}: moving joints {rec['robot']['moving']}, the robot's are "
                        f"{list(robot.moving)}")
    cons, fixed = consistent_from_record(path, rec, robot, name)
    if not cons.get("valid", False):
        raise DataError(f"{path}: models.{name}.consistent: a link is not physically valid")
    text = urdf_text(robot.reduced(), cons["standard"], robot.numbers, robot.name or "robot")
    fr = friction_record(cons["model"], tuple(robot.moving), robot.numbers,
                         cons["parameters"], cons["standard"], cons["q_s"], robot.gravity,
                         cons.get("known_rotor_inertia"), fixed,
                         cons.get("friction_regrouped"))
    return ExportedModel(text, fr, f"{path} ({name} model, consistent estimate)")


def load_model(path: str | Path, robot: Robot | None, model: str | None = None
               ) -> ExportedModel:
    """An ``export-model`` folder, or a fit record (then ``robot`` is needed)."""
    p = Path(path)
    if p.is_dir():
        return load_exported(p)
    if robot is None:
        raise DataError(f"{p}: a fit record needs the robot (the campaign's)")
    return exported_from_fit(p, robot, model)


#: default regime bins: edges [s] on a joint's moving time (the log format's, where they are
#: explained)
DEFAULT_EDGES_S = MONITOR_EDGES_S
#: a regime bin with fewer validation samples than this takes the joint's constant band
DEFAULT_MIN_SAMPLES = 1000
#: ... or entered fewer times than this (separate motions): the chance that the next motion
#: in the bin goes beyond all N seen is 1 / (N + 1), here < 5 % (before the peak margin)
DEFAULT_MIN_EPISODES = 20
#: what a bin without its own statistics (too few samples or episodes) takes: ``pooled``
#: (default of a new calibration) its samples pooled with the nearest shorter bins until
#: they are enough, that band intersected with the constant band; ``constant`` the joint's
#: constant band (files written before the key: their bands are unchanged)
THIN_BINS = ("pooled", "constant")


def persistent(out: Any, cycles: int) -> np.ndarray:
    """(n, k) bool: the samples where ``out`` (n, k) has been true for ``cycles``
    consecutive samples (this one included): the live check's crossing condition
    (``daq.runtime.monitor.TorqueMonitor`` with ``persist_cycles``)."""
    o = np.asarray(out, dtype=bool)
    res = o.copy()
    for i in range(1, int(cycles)):
        res[i:] &= o[:-i]
        res[:i] = False
    return res


def _persist_dev(dev: np.ndarray, cycles: int) -> np.ndarray:
    """|dev| where ``dev`` (n,) kept its sign for ``cycles`` samples, as the smallest |dev|
    of those samples (0 elsewhere): a band of half-width h is left for ``cycles``
    consecutive samples exactly where this exceeds h."""
    up, dn = np.maximum(dev, 0.0), np.maximum(-dev, 0.0)
    for i in range(1, int(cycles)):
        up[i:] = np.minimum(up[i:], up[:-i])
        dn[i:] = np.minimum(dn[i:], dn[:-i])
        up[:i] = dn[:i] = 0.0
    return np.maximum(up, dn)


def horizon_factor(seconds: float, validation_s: float, horizon_s: float,
                   independent_per_s: float) -> float:
    """How much further [ratio] the largest deviation seen in ``seconds`` [s] of validation
    samples (a regime bin's) is expected to reach over ``horizon_s`` [s] of monitoring,
    the whole validation having lasted ``validation_s`` [s] (the bin then gets H / T times
    as many samples): the largest of n independent Gaussian values grows as sqrt(2 ln n),
    so ``sqrt(ln(n H / T) / ln n)`` with n = ``seconds`` x ``independent_per_s`` (about
    twice the residual's bandwidth: 2 f_c for the filtered residual, K_O / pi for the
    observer), n at least e; 1 when H <= T or no rate is given."""
    if not (horizon_s > validation_s > 0 and independent_per_s > 0 and seconds > 0):
        return 1.0
    n = max(seconds * independent_per_s, math.e)
    return math.sqrt(math.log(n * horizon_s / validation_s) / math.log(n))


def _band(mean: float, sigma: float, peak: float, k_sigma: float, margin: float
          ) -> tuple[float, float]:
    """(lower, upper) [N m] of ``mean +- max(k_sigma, margin peak) sigma``."""
    h = sigma * max(k_sigma, margin * peak)
    return mean - h, mean + h


def _pooled(n: Sequence[int], mean: Sequence[float], sigma: Sequence[float],
            peak: Sequence[float]) -> tuple[float, float, float]:
    """(mean [N m], standard deviation [N m], peak [sigma]) of the samples of several bins
    together, from each bin's count, mean, standard deviation and peak: mean and spread
    exact, the peak bounded by ``max |mean_i - mean| + peak_i sigma_i`` (each bin's
    farthest sample lies at most that far from the pooled mean)."""
    total = sum(n)
    m = sum(k * x for k, x in zip(n, mean, strict=True)) / total
    sd = math.sqrt(sum(k * (s * s + (x - m) ** 2)
                       for k, x, s in zip(n, mean, sigma, strict=True)) / total)
    far = max(abs(x - m) + p * s for k, x, s, p in zip(n, mean, sigma, peak, strict=True)
              if k)
    return m, sd, (far / sd if sd > 0 else 0.0)


@dataclass(frozen=True)
class Thresholds:
    """Per joint: the band ``mean +- max(k_sigma, peak_margin peak) sigma`` of the monitored
    residual [N m], constant (the whole validation run's statistics) or per regime bin (the
    statistics of the validation samples in each bin of the joint's moving time).

    Attributes
    ----------
    joints : tuple of str
    k_sigma : float
    peak_margin : float
        The band is at least ``peak_margin`` times the validation's largest deviation
        (0: k_sigma alone).
    mean, sigma : tuple of float
        Mean and standard deviation of the validation residual [N m] (all its samples off
        the static band: the constant band).
    peak : tuple of float
        Largest ``|r - mean| / sigma`` seen in the validation residual (the margin k_sigma
        leaves: k_sigma / peak).
    samples : int
    source : str
    edges_s : tuple of float
        Edges [s] of the regime bins on the moving time (increasing, > 0; bin b holds
        ``edges_s[b-1] <= moving_s < edges_s[b]``); empty: the constant band only.
    bin_mean, bin_sigma, bin_peak : tuple of tuple of float
        Per joint and bin (``len(edges_s) + 1``): mean [N m], standard deviation [N m] and
        largest deviation [sigma] of the validation samples in the bin (0 for an empty bin).
    bin_samples : tuple of tuple of int
        Per joint and bin: validation samples in it.
    bin_episodes : tuple of tuple of int
        Per joint and bin: times the validation entered it (separate motions).
    min_samples, min_episodes : int
        A bin with fewer samples or episodes (or no spread) has no band of its own.
    stuck_velocity : tuple of float
        Per joint [rad/s], with a stuck bin (``edges_s`` starting at 0): a joint is stuck
        while its measured |dq| is at most this (its moving time is then minus the time it
        has been stuck, bin 0); empty without a stuck bin. Bin 0's statistics are of all its
        samples (the residual is 0 inside the static band), its band at least as wide as the
        narrowest band of the joint's other bins with their own statistics.
    thin_bins : str
        What such a bin takes (:data:`THIN_BINS`): ``pooled``, the band of its samples
        pooled with the nearest shorter bins (moving time below it) until the pool has
        ``min_samples`` samples and ``min_episodes`` entries, intersected with the constant
        band (both hold every validation sample of the bin; the joint's constant band when
        no pool qualifies); ``constant``, the constant band.
    residual : str
        The residual the statistics are of (:data:`RESIDUAL_KINDS`): ``filtered`` or
        ``observer`` (the generalized-momentum observer, docs/monitoring.md).
    persist_cycles : int
        A crossing counts when the residual has been outside the band for this many
        consecutive cycles; the peaks are of that statistic (the smallest deviation of each
        ``persist_cycles`` consecutive samples of one sign, :func:`persistent`).
    horizon_s, validation_s, independent_per_s : float
        The peaks are extrapolated from the validation's ``validation_s`` [s] to
        ``horizon_s`` [s] of monitoring (:func:`horizon_factor`, with
        ``independent_per_s`` [1/s]); 0: not extrapolated (files before the key).
    observer_gain : float
        The observer's gain K_O [1/s] the statistics were taken with (0: the filtered
        residual).
    """

    joints: tuple[str, ...]
    k_sigma: float
    mean: tuple[float, ...]
    sigma: tuple[float, ...]
    peak: tuple[float, ...]
    samples: int
    source: str = ""
    peak_margin: float = 0.0
    edges_s: tuple[float, ...] = ()
    bin_mean: tuple[tuple[float, ...], ...] = ()
    bin_sigma: tuple[tuple[float, ...], ...] = ()
    bin_peak: tuple[tuple[float, ...], ...] = ()
    bin_samples: tuple[tuple[int, ...], ...] = ()
    bin_episodes: tuple[tuple[int, ...], ...] = ()
    min_samples: int = DEFAULT_MIN_SAMPLES
    min_episodes: int = DEFAULT_MIN_EPISODES
    residual: str = "filtered"
    observer_gain: float = 0.0
    thin_bins: str = "pooled"
    stuck_velocity: tuple[float, ...] = ()
    persist_cycles: int = 1
    horizon_s: float = 0.0
    validation_s: float = 0.0
    independent_per_s: float = 0.0

    @property
    def half_width(self) -> list[float]:
        """Half-width of the constant band per joint [N m]: ``max(k_sigma sigma,
        peak_margin peak sigma)``."""
        return [s * max(self.k_sigma, self.peak_margin * p)
                for s, p in zip(self.sigma, self.peak, strict=True)]

    @property
    def lower(self) -> list[float]:
        """Lower bound of the constant band per joint [N m]."""
        return [m - h for m, h in zip(self.mean, self.half_width, strict=True)]

    @property
    def upper(self) -> list[float]:
        """Upper bound of the constant band per joint [N m]."""
        return [m + h for m, h in zip(self.mean, self.half_width, strict=True)]

    @property
    def regime(self) -> bool:
        """True when the bands depend on the regime (bins present)."""
        return bool(self.bin_samples)

    @property
    def bin_used(self) -> list[list[bool]]:
        """Per joint and bin: its own statistics set its band (enough samples and
        episodes, spread > 0); else the constant band."""
        stuck = _has_stuck(self.edges_s)  # its spread may be 0: the floor sets its band
        return [[n >= self.min_samples and e >= self.min_episodes
                 and (s > 0 or (stuck and not i))
                 for i, (n, e, s) in enumerate(zip(ns, es, ss, strict=True))]
                for ns, es, ss in zip(self.bin_samples, self.bin_episodes, self.bin_sigma,
                                      strict=True)]

    def bands(self) -> tuple[list[list[float]], list[list[float]]]:
        """(lower, upper) [N m] per joint and regime bin: the bin's own band where
        :attr:`bin_used`, elsewhere the :attr:`thin_bins` rule (pooled with the nearest
        shorter bins, or the joint's constant band); one bin per joint (the constant band)
        without regime bins."""
        if not self.regime:
            return [[x] for x in self.lower], [[x] for x in self.upper]
        lo: list[list[float]] = []
        hi: list[list[float]] = []
        for j, used in enumerate(self.bin_used):
            b = [_band(self.bin_mean[j][i], self.bin_sigma[j][i], self.bin_peak[j][i],
                       self.k_sigma, self.peak_margin) if u else self._thin_band(j, i)
                 for i, u in enumerate(used)]
            if _has_stuck(self.edges_s) and used[0]:
                # the stuck bin: at least as wide as the narrowest band of the joint's motion
                # with its own statistics (the residual's noise where the model holds best;
                # none: the constant band), about the stuck samples' mean
                h = min([(y - x) / 2 for (x, y), u in zip(b[1:], used[1:], strict=True) if u]
                        or [self.half_width[j]])
                m = self.bin_mean[j][0]
                b[0] = (min(b[0][0], m - h), max(b[0][1], m + h))
            lo.append([x for x, _ in b])
            hi.append([x for _, x in b])
        return lo, hi

    def _thin_band(self, j: int, i: int) -> tuple[float, float]:
        """The band [N m] of joint j's bin i, which has no statistics of its own
        (:attr:`thin_bins`)."""
        c = (self.lower[j], self.upper[j])
        if self.thin_bins != "pooled":
            return c
        first = 1 if _has_stuck(self.edges_s) else 0  # never pooled with the stuck bin
        if i < first:
            return c
        for a in range(i - 1, first - 1, -1):  # the nearest shorter bins first
            n = self.bin_samples[j][a:i + 1]
            # a motion enters bins a..i through bin a (the moving time grows one cycle at a
            # time or restarts at 0): the pool's episodes are bin a's
            if sum(n) < self.min_samples or self.bin_episodes[j][a] < self.min_episodes:
                continue
            m, sd, pk = _pooled(n, self.bin_mean[j][a:i + 1], self.bin_sigma[j][a:i + 1],
                                self.bin_peak[j][a:i + 1])
            if sd > 0:
                p = _band(m, sd, pk, self.k_sigma, self.peak_margin)
                return max(p[0], c[0]), min(p[1], c[1])
        return c

    def constant(self) -> Thresholds:
        """The same statistics without the regime bins: the constant band (format /1)."""
        return dataclasses.replace(self, edges_s=(), bin_mean=(), bin_sigma=(), bin_peak=(),
                                   bin_samples=(), bin_episodes=(), stuck_velocity=())

    def with_k(self, k_sigma: float | None = None, peak_margin: float | None = None
               ) -> Thresholds:
        """The same statistics with another ``k_sigma`` or ``peak_margin``."""
        return dataclasses.replace(
            self, k_sigma=self.k_sigma if k_sigma is None else float(k_sigma),
            peak_margin=self.peak_margin if peak_margin is None else float(peak_margin))

    def to_json(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "format": THRESHOLDS_FORMAT, "joints": list(self.joints),
            "k_sigma": self.k_sigma, "peak_margin": self.peak_margin,
            "mean": list(self.mean), "sigma": list(self.sigma),
            "peak_sigmas": list(self.peak), "lower": self.lower, "upper": self.upper,
            "samples": self.samples, "source": self.source, "residual": self.residual,
            "regime": None}
        if self.residual == "observer":
            d["observer_gain_per_s"] = self.observer_gain
        d["persist_cycles"] = self.persist_cycles
        d["horizon"] = ({"horizon_s": self.horizon_s, "validation_s": self.validation_s,
                         "independent_per_s": self.independent_per_s}
                        if self.horizon_s > 0 else None)
        if self.regime:
            lo, hi = self.bands()
            d["regime"] = {
                "variable": "moving_s", "edges_s": list(self.edges_s),
                "min_samples": self.min_samples, "min_episodes": self.min_episodes,
                "mean": [list(x) for x in self.bin_mean],
                "sigma": [list(x) for x in self.bin_sigma],
                "peak_sigmas": [list(x) for x in self.bin_peak],
                "samples": [list(x) for x in self.bin_samples],
                "episodes": [list(x) for x in self.bin_episodes],
                "own": self.bin_used, "thin_bins": self.thin_bins, "lower": lo,
                "upper": hi, "stuck_velocity": list(self.stuck_velocity) or None}
        return d

    @classmethod
    def read(cls, path: str | Path) -> Thresholds:
        """Read a thresholds file (:meth:`to_json`; format /1, without regime bins, too).

        Raises
        ------
        DataError
            Not JSON, another format, a key missing or of the wrong length.
        """
        p = Path(path)
        d = _read_json(p, "no such thresholds file")
        if not isinstance(d, dict) or d.get("format") not in (THRESHOLDS_FORMAT,
                                                               THRESHOLDS_FORMAT_1):
            raise DataError(f"{p}: format: expected {THRESHOLDS_FORMAT!r} (jointid monitor "
                            "--calibrate)")
        try:
            joints = tuple(str(j) for j in d["joints"])
            vals = [tuple(float(x) for x in d[key]) for key in ("mean", "sigma",
                                                               "peak_sigmas")]
            k = float(d["k_sigma"])
            margin = float(d.get("peak_margin", 0.0))
            n = int(d["samples"])
        except (KeyError, TypeError, ValueError) as e:
            raise DataError(f"{p}: key {e.args[0] if e.args else '?'!r} missing or not a "
                            "number") from None
        for key, v in zip(("mean", "sigma", "peak_sigmas"), vals, strict=True):
            if len(v) != len(joints):
                raise DataError(f"{p}: {key}: expected {len(joints)} values (one per joint)")
        if not all(s > 0 for s in vals[1]) or not k > 0:
            raise DataError(f"{p}: sigma and k_sigma: expected numbers > 0")
        if not margin >= 0:
            raise DataError(f"{p}: peak_margin: expected a number >= 0")
        kind = d.get("residual", "filtered")
        if kind not in RESIDUAL_KINDS:
            raise DataError(f"{p}: residual: expected one of {', '.join(RESIDUAL_KINDS)}, got "
                            f"{kind!r}")
        gain = 0.0
        if kind == "observer":
            gain = d.get("observer_gain_per_s")
            if isinstance(gain, bool) or not isinstance(gain, int | float) or not gain > 0:
                raise DataError(f"{p}: observer_gain_per_s: expected a number > 0 [1/s] (the "
                                "observer residual's gain)")
        persist = d.get("persist_cycles", 1)
        if isinstance(persist, bool) or not isinstance(persist, int) or persist < 1:
            raise DataError(f"{p}: persist_cycles: expected an integer >= 1 (consecutive "
                            "cycles outside the band)")
        hz = d.get("horizon")
        try:
            hor = ((0.0, 0.0, 0.0) if hz is None else
                   tuple(float(hz[x]) for x in ("horizon_s", "validation_s",
                                                "independent_per_s")))
        except (KeyError, TypeError, ValueError):
            hor = (-1.0, 0.0, 0.0)
        if hz is not None and not all(x > 0 for x in hor):
            raise DataError(f"{p}: horizon: expected null or horizon_s, validation_s [s], "
                            "independent_per_s [1/s], numbers > 0")
        th = cls(joints, k, vals[0], vals[1], vals[2], n, str(d.get("source", "")), margin,
                 residual=kind, observer_gain=float(gain), persist_cycles=persist,
                 horizon_s=hor[0], validation_s=hor[1], independent_per_s=hor[2])
        reg = d.get("regime") if d["format"] == THRESHOLDS_FORMAT else None
        return th if reg is None else _read_regime(p, reg, th)


def _increasing(edges: Sequence[float]) -> bool:
    """True when ``edges`` are strictly increasing (or empty) and > 0, or start at 0 or
    below with 0 among them: then bin 0 is the stuck bin (:func:`_has_stuck`)."""
    return (all(edges[i + 1] > edges[i] for i in range(len(edges) - 1))
            and all(e > 0 or 0.0 in edges for e in edges[:1]))


def _has_stuck(edges: Sequence[float]) -> bool:
    """True when bin 0 of ``edges`` [s] is the stuck bin: the first edge is 0 or below, so
    bin 0 holds the samples of moving time below it (minus the time the joint has been held
    by its static friction, ``daq.runtime.monitor``: a first edge -T leaves the first T
    seconds of each hold, the filters' settling, to the bins between -T and 0)."""
    return bool(edges) and edges[0] <= 0.0


def _read_regime(p: Path, reg: Any, th: Thresholds) -> Thresholds:
    """``th`` with the regime bins of a thresholds file's ``regime`` object."""
    if not isinstance(reg, dict):
        raise DataError(f"{p}: regime: expected an object or null")
    if reg.get("variable") != "moving_s":
        raise DataError(f"{p}: regime.variable: expected 'moving_s', got "
                        f"{reg.get('variable')!r}")
    try:
        edges = tuple(float(x) for x in reg["edges_s"])
        mins, mine = int(reg["min_samples"]), int(reg["min_episodes"])
        tabs = [tuple(tuple(float(x) for x in row) for row in reg[key])
                for key in ("mean", "sigma", "peak_sigmas")]
        counts, eps = (tuple(tuple(int(x) for x in row) for row in reg[key])
                       for key in ("samples", "episodes"))
    except (KeyError, TypeError, ValueError) as e:
        raise DataError(f"{p}: regime: key {e.args[0] if e.args else '?'!r} missing or "
                        "not numbers") from None
    if not _increasing(edges):
        raise DataError(f"{p}: regime.edges_s: expected increasing numbers >= 0 [s]")
    if not (mins >= 1 and mine >= 1):
        raise DataError(f"{p}: regime.min_samples, min_episodes: expected integers >= 1")
    shape = (len(th.joints), len(edges) + 1)
    for key, t in zip(("mean", "sigma", "peak_sigmas", "samples", "episodes"),
                      (*tabs, counts, eps), strict=True):
        if len(t) != shape[0] or any(len(row) != shape[1] for row in t):
            raise DataError(f"{p}: regime.{key}: expected {shape[0]} rows (one per joint) "
                            f"of {shape[1]} values (one per bin)")
    if any(x < 0 for t in (tabs[1], counts, eps) for row in t for x in row):
        raise DataError(f"{p}: regime.sigma, samples, episodes: expected numbers >= 0")
    thin = reg.get("thin_bins", "constant")  # before the key: the constant band
    if thin not in THIN_BINS:
        raise DataError(f"{p}: regime.thin_bins: expected one of {', '.join(THIN_BINS)}, "
                        f"got {thin!r}")
    vs = reg.get("stuck_velocity")
    try:
        stuck = () if vs is None else tuple(float(x) for x in vs)
    except (TypeError, ValueError):
        stuck = (-1.0,)
    if _has_stuck(edges) != bool(stuck) or len(stuck) not in (0, shape[0]) or any(
            not x >= 0 for x in stuck):
        raise DataError(f"{p}: regime.stuck_velocity: expected {shape[0]} numbers >= 0 "
                        "[rad/s] when edges_s starts at 0 (the stuck bin), else null")
    return dataclasses.replace(th, edges_s=edges, bin_mean=tabs[0], bin_sigma=tabs[1],
                               stuck_velocity=stuck,
                               bin_peak=tabs[2], bin_samples=counts, bin_episodes=eps,
                               min_samples=mins, min_episodes=mine, thin_bins=thin)


def _stats(x: np.ndarray) -> tuple[float, float, float]:
    """(mean, standard deviation, largest |x - mean| / sd) of ``x``; zeros when it has
    fewer than 2 samples or no spread."""
    if x.size < 2 or not x.std() > 0:
        return (float(x.mean()) if x.size else 0.0), 0.0, 0.0
    m, sd = float(x.mean()), float(x.std())
    return m, sd, float(np.abs(x - m).max() / sd)


def thresholds_from_residual(residual: Any, joints: Sequence[str], k_sigma: float,
                             source: str = "", peak_margin: float = 0.0,
                             moving_s: Any = None,
                             edges_s: Sequence[float] = DEFAULT_EDGES_S,
                             min_samples: int = DEFAULT_MIN_SAMPLES,
                             min_episodes: int = DEFAULT_MIN_EPISODES,
                             kind: str = "filtered", observer_gain: float = 0.0,
                             thin_bins: str = "pooled",
                             stuck_velocity: Sequence[float] | None = None,
                             persist_cycles: int = 1, horizon_s: float = 0.0,
                             cycle_s: float = 0.0, independent_per_s: float = 0.0
                             ) -> Thresholds:
    """Thresholds from a residual (n, k) [N m] recorded without collision: per joint the
    mean, standard deviation and peak of its samples off the static band (residual not
    exactly 0; near rest the model predicts an interval, :meth:`TorquePredictor.band`);
    with ``moving_s`` (n, k) [s] (each sample's moving time, the monitor's; the samples in
    time order), the same per bin of ``edges_s``, and how many times each bin was entered
    (episodes: separate motions). ``kind`` and ``observer_gain`` [1/s] say which
    residual it is (recorded in the file, :class:`Thresholds`); ``thin_bins`` what a bin
    with too few samples or episodes takes (:data:`THIN_BINS`). ``edges_s`` starting at 0:
    bin 0 is the stuck bin (``moving_s`` < 0, the monitor's with ``stuck_velocity`` [rad/s]
    per joint, recorded in the file), its statistics of all its samples.

    The peaks are those of the crossing rule's statistic: with ``persist_cycles`` P the
    smallest deviation from the mean of each P consecutive samples of one sign (P = 1:
    ``|r - mean|``); with ``horizon_s`` > 0 [s] each is extrapolated from the validation's
    duration (samples x ``cycle_s`` [s]) to the horizon (:func:`horizon_factor` on the
    bin's seconds, ``independent_per_s`` [1/s]).

    Raises
    ------
    DataError
        Fewer than 100 samples, a joint whose residual is constant, k_sigma not > 0,
        moving_s not of the residual's shape or not finite, edges not increasing > 0.
    """
    r = np.asarray(residual, dtype=float)
    if r.ndim != 2 or r.shape[1] != len(joints):
        raise DataError(f"{source}: residual: expected (n, {len(joints)}) samples")
    if r.shape[0] < 100:
        raise DataError(f"{source}: {r.shape[0]} residual samples: expected at least 100 "
                        "(a validation run without collision)")
    if not k_sigma > 0:
        raise DataError(f"k_sigma: expected a number > 0, got {k_sigma}")
    edges = tuple(float(e) for e in edges_s)
    if not _increasing(edges):
        raise DataError(f"regime edges: expected increasing numbers >= 0 [s], got {edges}")
    if not (int(min_samples) >= 1 and int(min_episodes) >= 1):
        raise DataError(f"regime min_samples, min_episodes: expected integers >= 1, got "
                        f"{min_samples}, {min_episodes}")
    if thin_bins not in THIN_BINS:
        raise DataError(f"thin_bins: expected one of {', '.join(THIN_BINS)}, got "
                        f"{thin_bins!r}")
    if _has_stuck(edges) and (stuck_velocity is None or len(stuck_velocity) != len(joints)):
        raise DataError(f"regime edges {edges}: a first edge 0 or below (the stuck bin) needs "
                        f"stuck_velocity, {len(joints)} values [rad/s]")
    if isinstance(persist_cycles, bool) or int(persist_cycles) != persist_cycles or not (
            persist_cycles >= 1):
        raise DataError(f"persist_cycles: expected an integer >= 1, got {persist_cycles}")
    if horizon_s and not (horizon_s > 0 and cycle_s > 0 and independent_per_s > 0):
        raise DataError(f"horizon {horizon_s} s: expected a number > 0 with cycle_s and "
                        f"independent_per_s > 0, got {cycle_s}, {independent_per_s}")
    pc = int(persist_cycles)
    val_s = r.shape[0] * cycle_s if horizon_s else 0.0

    def peak(col: np.ndarray, sel: np.ndarray, m: float, sd: float) -> float:
        # the rule's statistic over the time-ordered column, at the selected samples,
        # extrapolated to the horizon (sigmas)
        if not sd > 0 or not sel.any():
            return 0.0
        dev = _persist_dev(np.where(col != 0.0, col - m, 0.0), pc)
        f = horizon_factor(int(sel.sum()) * cycle_s, val_s, horizon_s, independent_per_s)
        return float(dev[sel].max() / sd * f)

    s = None
    if moving_s is not None:
        s = np.asarray(moving_s, dtype=float)
        if s.shape != r.shape or not np.isfinite(s).all():
            raise DataError(f"{source}: moving_s: expected {r.shape} finite values (the "
                            "residual's samples)")
    mean, sigma, peaks = [], [], []
    bins: list[list[tuple[float, float, float]]] = []
    counts: list[tuple[int, ...]] = []
    episodes: list[tuple[int, ...]] = []
    for j, name in enumerate(joints):
        off = r[:, j] != 0.0  # 0 exactly: inside the static band (no prediction)
        x = r[off, j]
        if x.size < 100 or not x.std() > 0:
            raise DataError(f"{source}: residual of {name}: {x.size} samples off its static "
                            "band, expected at least 100 that vary (did the joint move?)")
        m, sd, _ = _stats(x)
        mean.append(m)
        sigma.append(sd)
        peaks.append(peak(r[:, j], off, m, sd))
        if s is not None:
            nb = len(edges) + 1
            ball = np.searchsorted(edges, s[:, j], side="right")  # every sample, in order
            row = []
            for i in range(nb):
                sel = off & (ball == i)
                bm, bsd, _ = _stats(r[sel, j])
                row.append((bm, bsd, peak(r[:, j], sel, bm, bsd)))
            bins.append(row)
            counts.append(tuple(int(n) for n in np.bincount(ball[off], minlength=nb)))
            if _has_stuck(edges):  # the stuck bin: every sample (0 inside the static band)
                held = s[:, j] < edges[0]
                bm, bsd, _ = _stats(r[held, j])
                # inside the static band r is 0 exactly: the deviation from the mean counts
                dev = _persist_dev(r[:, j] - bm, pc)
                f = horizon_factor(int(held.sum()) * cycle_s, val_s, horizon_s,
                                   independent_per_s)
                bins[-1][0] = (bm, bsd, float(dev[held].max() / bsd * f) if bsd > 0
                               else 0.0)
                counts[-1] = (int(held.sum()), *counts[-1][1:])
            enter = ball[np.r_[True, ball[1:] != ball[:-1]]]
            episodes.append(tuple(int(n) for n in np.bincount(enter, minlength=nb)))
    if kind not in RESIDUAL_KINDS or (kind == "observer") != (observer_gain > 0):
        raise DataError(f"residual {kind!r}, gain {observer_gain}: expected one of "
                        f"{', '.join(RESIDUAL_KINDS)} (the observer's with its gain > 0)")
    th = Thresholds(tuple(joints), float(k_sigma), tuple(mean), tuple(sigma), tuple(peaks),
                    int(r.shape[0]), source, float(peak_margin), residual=kind,
                    observer_gain=float(observer_gain), persist_cycles=pc,
                    horizon_s=float(horizon_s) if horizon_s else 0.0, validation_s=val_s,
                    independent_per_s=float(independent_per_s) if horizon_s else 0.0)
    if s is None:
        return th
    return dataclasses.replace(
        th, edges_s=edges, bin_mean=tuple(tuple(v[0] for v in bj) for bj in bins),
        bin_sigma=tuple(tuple(v[1] for v in bj) for bj in bins),
        bin_peak=tuple(tuple(v[2] for v in bj) for bj in bins),
        bin_samples=tuple(counts), bin_episodes=tuple(episodes),
        min_samples=int(min_samples), min_episodes=int(min_episodes), thin_bins=thin_bins,
        stuck_velocity=tuple(float(v) for v in stuck_velocity or ()) if _has_stuck(edges)
        else ())
