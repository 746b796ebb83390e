"""Undeclared effects of the n-dof simulator, per joint, vectorised over joints (and samples).

The formulas are those of the plant-effect registry (:mod:`sim_drivers.effects`, one module
each; :mod:`sim_drivers.plant`'s docstring writes them for one joint), one set of
coefficients per joint; a coefficient of 0 (or ``asymmetric`` False) switches the effect off
for that joint:

* position ripple    ``A sin(2 pi q / period + phase)``
* spring             ``k (q - q0)``
* warm-up            dry terms (c, d) of eq. 30 scaled by ``1 + w exp(-t / T_w)``
* asymmetric viscous F_V replaced by ``F_V_pos`` (dq > 0) / ``F_V_neg`` (dq < 0)
* quadratic viscous  ``F_VV dq |dq|``
* torque lag         ``d tau_applied / dt = (tau_cmd - tau_applied) / T_lag`` (dynamic)

and one cross-joint effect, per ordered joint pair (j, m), the only effect of the arm that
depends on another joint's state (n-dof only, no single-joint plant table):

* dry coupling       dry terms (c, d) of joint j scaled by
  ``max(0, 1 + sum_m [c_jm sin(2 pi q_m / P_jm + phi_jm) + a_jm (q_m - q0_jm)])``: a cable
  or hose dragged through joint j whose tension, or a bearing whose preload, follows the
  position of joint m (sinusoidal and linear forms; the factor is clipped at 0 so the dry
  friction never changes sign). It multiplies the warm-up factor.

The effects are those of the plant-effect registry shared with the single joint
(:mod:`sim_drivers.effects`, one module per effect, docs/refinement.md "Adding an effect"):
the tables and keys of :meth:`ArmEffects.make` and :meth:`ArmEffects.from_plant_effects` are
the registry's (a native table's keys are checked against its registered schema at import).
The six above are native: their parameters are per-joint arrays here and their inverse-model
torque is the registry's formula (the effect module's ``torque``) evaluated with those arrays
(:meth:`ArmEffects.position_torque`, :meth:`ArmEffects.viscous_torque`,
:meth:`ArmEffects.warm_up_torque`); their forward-dynamics form is the scalar per-joint code
of :meth:`sim_drivers.dynamics.ChainDynamics.accel` (shared by the arm and the single
joint). Any other registered effect (a new module in ``sim_drivers/effects/``) is carried per
joint as its registered parameters (:attr:`ArmEffects.registered`, values validated by its
schema) and applied through its registration: its ``torque`` in the inverse model
(:meth:`ArmEffects.registered_torque`) and its forward-dynamics ``extra`` knob (a static torque
f(q_j, dq_j, t)) in :class:`~sim_drivers.dynamics.ChainDynamics`, per joint. Such an effect
sees joint j alone: ``Inputs.q, dq, t, tau_out`` of the joint and ``Inputs.params`` with the
joint's ``friction`` (the eq. 30 coefficients as scalars) and ``joint.q_s``. So a new
friction effect is one plant file for both simulators.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from types import SimpleNamespace
from typing import Any

import numpy as np

from trajectories import SchemaError

from . import SimError
from .effects import Inputs, Knobs, PlantEffect, registry

_TWO_PI = 2.0 * math.pi

#: Plant-file table name -> {key in that table: ArmEffects field}.
_TABLES: dict[str, dict[str, str]] = {
    "position_ripple": {"amplitude_Nm": "ripple_amplitude_Nm", "period_rad": "ripple_period_rad",
                        "phase_rad": "ripple_phase_rad"},
    "spring": {"stiffness_Nm_per_rad": "spring_stiffness_Nm_per_rad",
               "rest_position_rad": "spring_rest_rad"},
    "warm_up": {"fraction": "warm_up_fraction", "time_constant_s": "warm_up_time_constant_s"},
    "asymmetric_viscous": {"F_V_pos": "F_V_pos", "F_V_neg": "F_V_neg"},
    "quadratic_viscous": {"F_VV": "F_VV"},
    "torque_lag": {"time_constant_s": "lag_time_constant_s"},
}


def _check_native() -> None:
    """The native tables are registered plant effects with exactly these keys."""
    specs = {e.name: e for e in registry()}
    for table, keys in _TABLES.items():
        if table not in specs or set(specs[table].schema) != set(keys):
            raise SimError(f"ArmEffects: native table {table!r} does not match the plant-effect "
                           f"registry ({sorted(keys)} against "
                           f"{sorted(specs[table].schema) if table in specs else 'absent'})")


_check_native()
#: The registered effects by name (the native ones' formulas are theirs).
_SPECS = {e.name: e for e in registry()}
#: Field of :class:`ArmEffects` holding the registered (non-native) effects, per joint.
_REGISTERED = "registered"
_DEFAULTS = {"ripple_period_rad": _TWO_PI / 16.0, "warm_up_time_constant_s": 60.0,
             "coupling_period_rad": _TWO_PI}
#: ``make(dry_coupling={(j, m): {...}})`` key -> ArmEffects field (shape (k, k), row j, col m).
_COUPLING = {"amplitude": "coupling_amplitude", "period_rad": "coupling_period_rad",
             "phase_rad": "coupling_phase_rad", "slope_per_rad": "coupling_slope_per_rad",
             "rest_position_rad": "coupling_rest_rad"}


@dataclass(frozen=True, eq=False)
class ArmEffects:
    """Undeclared effects per joint; every attribute is an array of shape (k,).

    Attributes
    ----------
    ripple_amplitude_Nm, ripple_period_rad, ripple_phase_rad
        Position ripple A [N m], period [rad], phase [rad].
    spring_stiffness_Nm_per_rad, spring_rest_rad
        Spring k [N m/rad] and rest position q0 [rad].
    warm_up_fraction, warm_up_time_constant_s
        Warm-up excess w [-] and time constant T_w [s].
    asymmetric : ndarray of bool
        Whether the asymmetric viscous friction replaces F_V on that joint.
    F_V_pos, F_V_neg
        Viscous coefficients for dq > 0 and dq < 0 [N m s/rad] (used where ``asymmetric``).
    F_VV
        Quadratic viscous coefficient [N m s^2/rad^2].
    lag_time_constant_s
        Torque lag T_lag [s] (0: no lag).
    coupling_amplitude, coupling_period_rad, coupling_phase_rad : ndarray, shape (k, k)
        Dry coupling, sinusoidal form: row j (the joint whose dry friction changes), column m
        (the joint whose position drives it): c_jm [-], P_jm [rad], phi_jm [rad].
    coupling_slope_per_rad, coupling_rest_rad : ndarray, shape (k, k)
        Dry coupling, linear form: a_jm [1/rad] and q0_jm [rad].
    registered : tuple of dict
        Per joint, the other registered plant effects on it: effect name -> its parameters
        (the registry's dataclass, ``enabled`` True); module docstring.
    """

    ripple_amplitude_Nm: np.ndarray
    ripple_period_rad: np.ndarray
    ripple_phase_rad: np.ndarray
    spring_stiffness_Nm_per_rad: np.ndarray
    spring_rest_rad: np.ndarray
    warm_up_fraction: np.ndarray
    warm_up_time_constant_s: np.ndarray
    asymmetric: np.ndarray
    F_V_pos: np.ndarray
    F_V_neg: np.ndarray
    F_VV: np.ndarray
    lag_time_constant_s: np.ndarray
    coupling_amplitude: np.ndarray | None = None
    coupling_period_rad: np.ndarray | None = None
    coupling_phase_rad: np.ndarray | None = None
    coupling_slope_per_rad: np.ndarray | None = None
    coupling_rest_rad: np.ndarray | None = None
    registered: tuple[dict[str, Any], ...] | None = None

    def __post_init__(self) -> None:
        k = int(np.size(self.lag_time_constant_s))
        reg = tuple({} for _ in range(k)) if self.registered is None else tuple(
            dict(d) for d in self.registered)
        if len(reg) != k:
            raise SimError(f"ArmEffects.registered: expected {k} joints, got {len(reg)}")
        object.__setattr__(self, _REGISTERED, reg)
        for f in fields(self):
            if f.name == _REGISTERED:
                continue
            dtype = bool if f.name == "asymmetric" else float
            pair = f.name.startswith("coupling_")
            v = getattr(self, f.name)
            if v is None:  # a coupling left out: off (default period)
                v = np.full((k, k), _DEFAULTS.get(f.name, 0.0))
            a = np.array(v, dtype=dtype)
            if not pair:
                a = a.reshape(-1)
            if a.shape != ((k, k) if pair else (k,)):
                shape = f"({k}, {k})" if pair else f"({k},)"
                raise SimError(f"ArmEffects.{f.name}: expected shape {shape}, got {a.shape}")
            if dtype is float and not np.all(np.isfinite(a)):
                raise SimError(f"ArmEffects.{f.name}: expected finite values, got {a}")
            a.setflags(write=False)
            object.__setattr__(self, f.name, a)
        for name in ("ripple_period_rad", "warm_up_time_constant_s", "coupling_period_rad"):
            if np.any(getattr(self, name) <= 0):
                raise SimError(f"ArmEffects.{name}: expected values > 0")
        if np.any(self.lag_time_constant_s < 0) or np.any(self.warm_up_fraction < 0):
            raise SimError("ArmEffects: expected lag_time_constant_s >= 0 and "
                           "warm_up_fraction >= 0")

    # ------------------------------------------------------------------ constructors
    @classmethod
    def none(cls, k: int) -> ArmEffects:
        """No effect on any of ``k`` joints."""
        kw: dict[str, Any] = {f.name: np.full(k, _DEFAULTS.get(f.name, 0.0))
                              for f in fields(cls)
                              if not f.name.startswith("coupling_") and f.name != _REGISTERED}
        kw["asymmetric"] = np.zeros(k, dtype=bool)
        return cls(**kw)

    @classmethod
    def make(cls, k: int, **tables: dict[int, dict[str, float]]) -> ArmEffects:
        """Effects from plant-file-like tables, per joint (0-based index in the moving chain).

        Example: ``ArmEffects.make(3, spring={1: {"stiffness_Nm_per_rad": 50.0}},
        position_ripple={0: {"amplitude_Nm": 2.0, "period_rad": 0.3}})``. Table and key names
        are those of the plant file (``sim_drivers.plant_config``); ``enabled`` is accepted
        and ignored (a listed joint has the effect enabled). The cross-joint table is keyed by
        joint pairs (j, m), 0-based: ``dry_coupling={(0, 1): {"amplitude": 0.3,
        "period_rad": 2.0, "phase_rad": 0.5}}`` (joint 0's dry friction follows q of joint 1;
        keys of :data:`_COUPLING`).
        """
        arrays: dict[str, Any] = {f.name: np.array(getattr(cls.none(k), f.name))
                                  for f in fields(cls) if f.name != _REGISTERED}
        registered: list[dict[str, Any]] = [{} for _ in range(k)]
        specs = {e.name: e for e in registry()}
        for (j, m), values in tables.pop("dry_coupling", {}).items():
            if not (0 <= int(j) < k and 0 <= int(m) < k) or int(j) == int(m):
                raise SimError(f"ArmEffects.dry_coupling: joint pair {(j, m)!r}: expected two "
                               f"different indices in 0..{k - 1}")
            for key, v in values.items():
                if key not in _COUPLING:
                    raise SimError(f"ArmEffects.dry_coupling.{key}: unknown key; expected one "
                                   f"of {sorted(_COUPLING)}")
                arrays[_COUPLING[key]][int(j), int(m)] = float(v)
        for table, per_joint in tables.items():
            if table not in _TABLES and table in specs:
                for j, values in per_joint.items():
                    if not 0 <= int(j) < k:
                        raise SimError(f"ArmEffects.{table}: joint index {j!r} not in "
                                       f"0..{k - 1}")
                    registered[int(j)][table] = _registered_params(specs[table], values)
                continue
            if table not in _TABLES:
                raise SimError(f"ArmEffects: unknown effect {table!r}; expected one of "
                               f"{sorted([*specs, 'dry_coupling'])}")
            for j, values in per_joint.items():
                if not 0 <= int(j) < k:
                    raise SimError(f"ArmEffects.{table}: joint index {j!r} not in 0..{k - 1}")
                if table == "asymmetric_viscous":
                    arrays["asymmetric"][j] = True
                for key, v in values.items():
                    if key == "enabled":
                        continue
                    if key not in _TABLES[table]:
                        raise SimError(f"ArmEffects.{table}.{key}: unknown key; expected one "
                                       f"of {sorted(_TABLES[table])}")
                    arrays[_TABLES[table][key]][j] = float(v)
        return cls(**arrays, registered=tuple(registered))

    @classmethod
    def from_plant_effects(cls, per_joint: Any) -> ArmEffects:
        """Effects from one ``sim_drivers.plant_config.Effects``-like object per joint (or
        None): objects with attributes ``position_ripple``, ``spring``, ... each with
        ``enabled`` and the plant-file keys."""
        per_joint = list(per_joint)
        tables: dict[str, dict[int, dict[str, float]]] = {}
        for j, eff in enumerate(per_joint):
            if eff is None:
                continue
            for spec in registry():
                e = getattr(eff, spec.name, None)
                if e is not None and getattr(e, "enabled", False):
                    tables.setdefault(spec.name, {})[j] = {key: getattr(e, key)
                                                           for key in spec.schema}
        return cls.make(len(per_joint), **tables)

    def replace(self, **changes: Any) -> ArmEffects:
        return replace(self, **changes)

    # ------------------------------------------------------------------ queries
    @property
    def k(self) -> int:
        return int(self.F_VV.shape[0])

    def enabled(self) -> dict[str, np.ndarray]:
        """Effect name -> boolean mask (k,) of the joints where it is on (the registered
        effects of :attr:`registered` after the native ones)."""
        extra = {}
        for j, d in enumerate(self.registered):
            for name in d:
                extra.setdefault(name, np.zeros(self.k, dtype=bool))[j] = True
        return {
            "position_ripple": self.ripple_amplitude_Nm != 0,
            "spring": self.spring_stiffness_Nm_per_rad != 0,
            "warm_up": self.warm_up_fraction != 0,
            "asymmetric_viscous": self.asymmetric.copy(),
            "quadratic_viscous": self.F_VV != 0,
            "torque_lag": self.lag_time_constant_s > 0,
            "dry_coupling": self.coupled(),
            **extra,
        }

    def coupled(self) -> np.ndarray:
        """Boolean mask (k,) of the joints whose dry friction follows another joint."""
        return (np.any(self.coupling_amplitude != 0, axis=1)
                | np.any(self.coupling_slope_per_rad != 0, axis=1))

    @property
    def any_position(self) -> bool:
        """Whether a position-dependent torque (ripple or spring) is on for some joint."""
        return bool(np.any(self.ripple_amplitude_Nm) or np.any(self.spring_stiffness_Nm_per_rad))

    # ------------------------------------------------------------------ formulas
    def _native(self, name: str, friction: Any, q: Any, dq: Any, t: Any = 0.0,
                tau_out: Any = 0.0) -> np.ndarray:
        """Torque of native effect ``name`` on every joint [N m], shape (..., k): the
        registered formula (``sim_drivers/effects/<name>.py``, its ``torque``) evaluated with
        one parameter per joint (arrays (k,)); off joints give 0. t [s]: scalar or (...,)."""
        spec = _SPECS[name]
        values = {key: getattr(self, attr) for key, attr in _TABLES[name].items()}
        if name == "asymmetric_viscous":  # off: F_V itself, no excess
            pos, neg = self.viscous_coefficients(friction.F_V)
            values = {"F_V_pos": pos, "F_V_neg": neg}
        p = spec.params(True, **values)
        t = np.asarray(t, dtype=float)
        x = Inputs(SimpleNamespace(friction=friction, joint=SimpleNamespace(q_s=friction.q_s)),
                   np.asarray(q, dtype=float), np.asarray(dq, dtype=float), 0.0, 0.0, 0.0,
                   t[..., None] if t.ndim else t, lambda *_a: np.asarray(tau_out, dtype=float))
        return spec.torque(p, x)

    def position_torque(self, q: Any, friction: Any = None) -> np.ndarray:
        """Ripple + spring torque [N m], shape of ``q`` (..., k) (registered formulas)."""
        return (self._native("position_ripple", friction, q, 0.0)
                + self._native("spring", friction, q, 0.0))

    def viscous_coefficients(self, F_V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Viscous coefficients for dq > 0 and dq < 0 [N m s/rad], shape (k,) each."""
        pos = np.where(self.asymmetric, self.F_V_pos, F_V)
        neg = np.where(self.asymmetric, self.F_V_neg, F_V)
        return pos, neg

    def viscous_torque(self, friction: Any, dq: Any) -> np.ndarray:
        """Viscous torque of the effects beyond eq. 30's F_V dq [N m]: asymmetric and
        quadratic viscous (registered formulas), shape of ``dq`` (..., k)."""
        return (self._native("asymmetric_viscous", friction, 0.0, dq)
                + self._native("quadratic_viscous", friction, 0.0, dq))

    def warm_up_torque(self, friction: Any, dq: Any, t: Any, tau_out: Any) -> np.ndarray:
        """Warm-up torque (registered formula: the dry terms times ``w exp(-t/T_w)``) [N m],
        shape (..., k); t [s] since the run start, scalar or (...,)."""
        return self._native("warm_up", friction, 0.0, dq, t, tau_out)

    def coupling_scale(self, q: Any) -> np.ndarray:
        """Dry-coupling factor of every joint (module docstring), 1 where off; q [rad] of all
        joints, shape (..., k) -> (..., k)."""
        q = np.asarray(q, dtype=float)[..., None, :]  # (..., 1, k): column m
        f = 1.0 + np.sum(
            self.coupling_amplitude
            * np.sin(_TWO_PI * q / self.coupling_period_rad + self.coupling_phase_rad)
            + self.coupling_slope_per_rad * (q - self.coupling_rest_rad), axis=-1)
        return np.maximum(f, 0.0)

    def lag_keep(self, h: float) -> np.ndarray:
        """Per-step retention ``exp(-h / T_lag)`` of the torque lag over a step h [s]; 0 where
        there is no lag (the applied torque is the command)."""
        tl = self.lag_time_constant_s
        with np.errstate(divide="ignore"):
            return np.where(tl > 0, np.exp(-h / np.where(tl > 0, tl, 1.0)), 0.0)

    # ------------------------------------------------------------------ registered effects
    def registered_torque(self, friction: Any, q: Any, dq: Any, t: Any,
                          tau_out: Any) -> np.ndarray:
        """Sum of the registered effects' torques (their ``PlantEffect.torque``) [N m], joint
        by joint, shape of ``q`` (..., k); t [s] since the run start, shape (...,) or scalar;
        ``friction``: the arm's :class:`~sim_drivers.arm_params.ArmFriction`."""
        q = np.asarray(q, dtype=float)
        dq = np.asarray(dq, dtype=float)
        tau_out = np.asarray(tau_out, dtype=float)
        out = np.zeros(np.broadcast_shapes(q.shape, dq.shape))
        specs = {e.name: e for e in registry()}
        for j, d in enumerate(self.registered):
            for name, p in d.items():
                spec = specs[name]
                if spec.torque is None:
                    continue
                tj = tau_out[..., j]
                x = Inputs(_joint_params(friction, j), q[..., j], dq[..., j], 0.0, 0.0, 0.0, t,
                           lambda *_a, tj=tj: tj)
                out[..., j] += np.asarray(spec.torque(p, x), dtype=float)
        return out

    def forward_extra(self, friction: Any) -> list[tuple]:
        """Per joint, the registered effects' static torques ``f(q_j, dq_j, t)`` [N m] of the
        forward dynamics (their ``extra`` knob; t since the run start)."""
        specs = {e.name: e for e in registry()}
        out = []
        for j, d in enumerate(self.registered):
            fs: list = []
            for name, p in d.items():
                kn = Knobs()
                if specs[name].configure is not None:
                    specs[name].configure(p, kn, _joint_params(friction, j))
                fs += kn.extra
            out.append(tuple(fs))
        return out


def _registered_params(spec: PlantEffect, values: dict[str, Any]) -> Any:
    """The registered effect's parameters from a plant-file-like table, validated by its
    schema (one-line :class:`SimError`)."""
    kw: dict[str, Any] = {}
    for key, v in values.items():
        if key == "enabled":
            continue
        if key not in spec.schema:
            raise SimError(f"ArmEffects.{spec.name}.{key}: unknown key; expected one of "
                           f"{sorted(spec.schema)}")
        try:
            kw[key] = spec.schema[key].validate(v, f"{spec.name}.{key}", "ArmEffects")
        except SchemaError as exc:
            raise SimError(str(exc)) from None
    return spec.params(enabled=True, **kw)


def _joint_params(friction: Any, j: int) -> SimpleNamespace:
    """What a registered effect may read of joint j: ``friction`` (eq. 30 coefficients,
    scalars) and ``joint.q_s``, as the single-joint ``PlantParams``."""
    f = {fl.name: float(np.asarray(getattr(friction, fl.name))[j]) for fl in fields(friction)}
    return SimpleNamespace(friction=SimpleNamespace(**f),
                           joint=SimpleNamespace(q_s=f.get("q_s", 0.0)))
