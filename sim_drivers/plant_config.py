"""Plant file: the simulated joint's parameters, read from TOML and validated.

A plant file describes one joint (paper section IV.A, eq. 31/34), its friction following the
load- and velocity-dependent model of Hamon, Gautier & Garrec (eq. 25/30), the drive chain
(eq. 4) and the *undeclared effects*: physical effects that no identification model declares,
each off unless its table says ``enabled = true``. Layout (all keys; units in brackets)::

    name = "rx130l-joint3"                 # optional, free text

    [joint]
    kind = "revolute"                      # or "prismatic"
    q_s = 0.03                             # [rad/s] velocity constant of eq. 29

    [body]                                 # tau_out = J ddq + MX g cos q + MY g sin q (eq. 31)
    J = 31.0                               # [kg m^2] ([kg] prismatic)
    MX = 21.0                              # [kg m]   (revolute only; 0 / absent if prismatic)
    MY = -0.8                              # [kg m]

    [friction]                             # eq. 25/30; m: motor, g: generator quadrants
    a_m = 1.06                             # [-]   (a_m > 0, a_m + b_m > 0)
    b_m = 0.2                              # [-]
    c_m = 21.0                             # [N m] (>= 0; c_m + d_m >= 0)
    d_m = 8.0                              # [N m]
    a_g = 0.93                             # [-]   (a_g > 0, a_g - b_g > 0, a_g - b_g <= a_m + b_m)
    b_g = 0.2                              # [-]
    c_g = 16.0                             # [N m]
    d_g = 6.0                              # [N m]
    F_V = 40.0                             # [N m s/rad]
    tau_off = 10.0                         # [N m]

    [drive]                                # g_f = N G_i K_t (eq. 4)
    gear_ratio = 100.0                     # N [motor rad per joint rad] (per joint m prismatic)
    torque_constant_Nm_per_A = 0.5         # K_t, motor side [N m/A]
    amplifier_gain = 1.0                   # G_i [A per unit of current reference]
    rated_torque_Nm = 5.0                  # motor side [N m] (object 0x6076)
    rated_current_A = 10.0                 # [A] (object 0x6075)
    encoder_counts_per_rev = 4096          # per motor revolution
    torque_noise_std_Nm = 3.0              # applied-torque ripple noise, joint side [N m]
    seed = 1                               # noise seed (runs are reproducible)

    [effects.position_ripple]              # A sin(2 pi q / period + phase)
    enabled = true
    amplitude_Nm = 5.0
    period_rad = 0.39269908169872414
    phase_rad = 0.0

    [effects.spring]                       # k (q - q0)
    [effects.warm_up]                      # dry friction (c, d) x (1 + w exp(-t / T_w))
    [effects.asymmetric_viscous]           # F_V -> F_V_pos (dq > 0), F_V_neg (dq < 0)
    [effects.quadratic_viscous]            # F_VV dq |dq|
    [effects.torque_lag]                   # d tau_applied / dt = (tau_cmd - tau_applied) / T_lag

Each effect is one module of :mod:`sim_drivers.effects` (its table's keys, units and
validation, its formula and its torque), found by a registry: the ``effects`` tables
accepted here are exactly the registered ones. Every invalid file raises
:class:`sim_drivers.PlantConfigError` with a one-line message naming the file and the
dotted key.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import asdict, dataclass, field, fields, make_dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Any

from trajectories import SchemaError
from trajectories.friction import DEFAULT_Q_S
from trajectories.schema import Field, Table, fail, mixup_hint

from . import PlantConfigError
from .effects import (  # noqa: F401 - re-exported: the effects' parameter dataclasses
    AsymmetricViscous,
    PositionRipple,
    QuadraticViscous,
    Spring,
    TorqueLag,
    WarmUp,
)
from .effects import registry as effect_registry

G = 9.81  # [m/s^2] gravity used by the paper (section IV.A)


# --------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class JointSpec:
    """Kind of joint and the a-priori velocity constant of the friction model.

    Attributes
    ----------
    kind : str
        ``"revolute"`` (gravity terms g cos q, g sin q) or ``"prismatic"`` (no gravity).
    q_s : float
        Velocity constant of the exponential E = exp(-|dq| / q_s) (eq. 29) [rad/s] or [m/s].
    """

    kind: str = "revolute"
    q_s: float = DEFAULT_Q_S

    @property
    def revolute(self) -> bool:
        return self.kind == "revolute"


@dataclass(frozen=True)
class BodyParams:
    """Rigid body of the joint's output (eq. 31).

    Attributes
    ----------
    J : float
        Inertia about the joint axis, drive chain included [kg m^2] (moving mass [kg] prismatic).
    MX, MY : float
        First moments of the link [kg m]; revolute joints only (0 for prismatic).
    """

    J: float
    MX: float = 0.0
    MY: float = 0.0


@dataclass(frozen=True)
class FrictionParams:
    """Load- and velocity-dependent friction of eq. 25/30 (the paper's new model).

    With E = exp(-|dq| / q_s) and tau_out the output (load) torque::

        P_out > 0:  tau = (a_m + b_m E) tau_out + (c_m + d_m E) sign(dq) + F_V dq + tau_off
        P_out < 0:  tau = (a_g - b_g E) tau_out + (c_g + d_g E) sign(dq) + F_V dq + tau_off

    Attributes
    ----------
    a_m, b_m, a_g, b_g : float
        Load coefficients [-] (a_m = 1 + alpha_m, a_g = 1 - alpha_g, eq. 24-25).
    c_m, d_m, c_g, d_g : float
        Load-independent dry friction, sliding part c and stiction excess d [N m].
    F_V : float
        Viscous coefficient [N m s/rad].
    tau_off : float
        Offset torque (amplifier offset + asymmetric Coulomb, eq. 6) [N m].
    """

    a_m: float
    b_m: float
    c_m: float
    d_m: float
    a_g: float
    b_g: float
    c_g: float
    d_g: float
    F_V: float
    tau_off: float = 0.0


@dataclass(frozen=True)
class DriveParams:
    """Drive chain: gear, motor, amplifier and encoder.

    The drive receives ``x`` = target torque (0x6071) in per-mille of the rated torque (int16);
    the joint-side commanded torque is ``tau_cmd = N * rated_torque_Nm * x / 1000`` [N m], which
    is what the master logs as tau = g_f v_f (eq. 7); the current loop is ideal, so the applied
    torque equals tau_cmd up to the ripple noise (and the torque lag effect, when enabled).
    Encoder: ``counts = round(q * N * encoder_counts_per_rev / (2 pi))`` (motor-side quantisation).

    Attributes
    ----------
    gear_ratio : float
        N, motor velocity over joint velocity [-] (motor rad per joint m for prismatic joints).
    torque_constant_Nm_per_A : float
        K_t, motor side [N m/A].
    amplifier_gain : float
        G_i, current per unit of current reference [A/unit].
    rated_torque_Nm : float
        Motor rated torque [N m] (0x6076 is this value in mN m).
    rated_current_A : float
        Motor rated current [A].
    encoder_counts_per_rev : int
        Encoder counts per motor revolution.
    torque_noise_std_Nm : float
        Standard deviation of the applied-torque ripple noise, joint side [N m]; one Gaussian
        sample per control cycle, held over the cycle.
    seed : int
        Seed of the noise generator (default seed of :class:`~sim_drivers.plant.JointPlant`).
    """

    gear_ratio: float
    torque_constant_Nm_per_A: float
    amplifier_gain: float
    rated_torque_Nm: float
    rated_current_A: float
    encoder_counts_per_rev: int
    torque_noise_std_Nm: float = 0.0
    seed: int = 0

    @property
    def g_f(self) -> float:
        """Nominal drive gain g_f = N G_i K_t (eq. 4) [N m per unit of current reference]."""
        return self.gear_ratio * self.amplifier_gain * self.torque_constant_Nm_per_A

    @property
    def torque_per_permille(self) -> float:
        """Joint-side torque of one per-mille of rated torque, N * rated / 1000 [N m]."""
        return self.gear_ratio * self.rated_torque_Nm / 1000.0

    @property
    def counts_per_joint_rad(self) -> float:
        """Encoder counts per joint radian (per joint metre, prismatic) [counts/rad]."""
        return self.gear_ratio * self.encoder_counts_per_rev / (2.0 * math.pi)


def _enabled(self) -> tuple[str, ...]:
    """Names of the enabled effects, in declaration order."""
    return tuple(f.name for f in fields(self) if getattr(self, f.name).enabled)


#: Parameter dataclass of each undeclared effect, in plant-file order
#: (:func:`sim_drivers.effects.registry`).
EFFECT_TYPES: dict[str, type] = {e.name: e.params for e in effect_registry()}

#: The undeclared effects, each disabled by default: one field per registered effect
#: (``effects.position_ripple``, ``effects.spring``...), built from the registry.
Effects = make_dataclass(
    "Effects",
    [(name, cls, field(default_factory=cls)) for name, cls in EFFECT_TYPES.items()],
    frozen=True,
    namespace={"enabled": _enabled,
               "__doc__": "The undeclared effects, each disabled by default."},
)
Effects.__module__ = __name__  # (make_dataclass's ``module=`` needs Python 3.12)


_NEW_MODEL_LOAD = ("J", "MX", "MY")


@dataclass(frozen=True)
class PlantParams:
    """Everything the simulated joint needs; build with :func:`load_plant` or
    :func:`plant_from_dict`.

    Attributes
    ----------
    joint : JointSpec
    body : BodyParams
    friction : FrictionParams
    drive : DriveParams
    effects : Effects
    name : str
        Free text naming the plant.
    source : str
        Where the parameters came from (file path or ``"<dict>"``).
    """

    joint: JointSpec
    body: BodyParams
    friction: FrictionParams
    drive: DriveParams
    effects: Effects = field(default_factory=Effects)
    name: str = ""
    source: str = ""

    @property
    def revolute(self) -> bool:
        return self.joint.revolute

    def truth(self) -> dict[str, float]:
        """The exact values of the new model's base parameters (eq. 42-43), named as in
        ``docs/architecture.md``.

        ``a_m_J = a_m J``, ``b_m_J = b_m J``, ``a_m_MX = a_m MX`` ... for the motor (m) and
        generator (g) quadrants; ``a_m``, ``b_m`` (``a_g``, ``b_g``) are the coefficients of the
        payload column M_a L_a (L_a ddq + g cos q) (M_a ddq for prismatic joints); then
        ``c_m, d_m, c_g, d_g, F_V, tau_off``. Prismatic joints have no MX/MY entries.
        """
        f, b = self.friction, self.body
        out: dict[str, float] = {}
        inertial = _NEW_MODEL_LOAD if self.revolute else ("J",)
        for quad in ("m", "g"):
            a = getattr(f, f"a_{quad}")
            bb = getattr(f, f"b_{quad}")
            for p in inertial:
                out[f"a_{quad}_{p}"] = a * getattr(b, p)
                out[f"b_{quad}_{p}"] = bb * getattr(b, p)
            out[f"a_{quad}"] = a
            out[f"b_{quad}"] = bb
        for p in ("c_m", "d_m", "c_g", "d_g", "F_V", "tau_off"):
            out[p] = getattr(f, p)
        return out

    def truth_effects(self) -> dict[str, dict[str, float]]:
        """The enabled undeclared effects with their parameters, e.g.
        ``{"position_ripple": {"amplitude_Nm": 5.0, "period_rad": 0.39, "phase_rad": 0.0}}``.

        Position ripple also lists its linear coefficients ``sin_Nm = A cos(phase)`` and
        ``cos_Nm = A sin(phase)`` (A sin(x + phase) = sin_Nm sin x + cos_Nm cos x).
        """
        out: dict[str, dict[str, float]] = {}
        specs = {e.name: e for e in effect_registry()}
        for name in self.effects.enabled():
            eff = getattr(self.effects, name)
            vals = {k: float(v) for k, v in asdict(eff).items() if k != "enabled"}
            if specs[name].truth is not None:
                vals.update(specs[name].truth(eff))
            out[name] = vals
        return out

    def with_effect(self, name: str, **values: Any) -> PlantParams:
        """A copy with effect ``name`` enabled and the given parameters changed, e.g.
        ``params.with_effect("spring", stiffness_Nm_per_rad=40.0)``.

        Raises
        ------
        PlantConfigError
            Unknown effect or parameter name, or an invalid value.
        """
        if name not in EFFECT_TYPES:
            raise PlantConfigError(
                f"{self.source or '<plant>'}: effects.{name}: no such effect "
                f"(allowed: {', '.join(EFFECT_TYPES)})"
            )
        current = asdict(getattr(self.effects, name))
        unknown = sorted(set(values) - set(current))
        if unknown:
            raise PlantConfigError(
                f"{self.source or '<plant>'}: effects.{name}.{unknown[0]}: no such key "
                f"(allowed: {', '.join(sorted(current))})"
            )
        current.update(values)
        if "enabled" not in values:
            current["enabled"] = True
        raw = self.as_dict()
        raw.setdefault("effects", {})[name] = current
        return plant_from_dict(raw, self.source or "<plant>")

    def without_effects(self) -> PlantParams:
        """A copy with every undeclared effect disabled."""
        return replace(self, effects=Effects())

    def as_dict(self) -> dict[str, Any]:
        """Plain nested dict in the plant-file layout (round-trips through
        :func:`plant_from_dict`); used as run metadata."""
        d = asdict(self)
        d.pop("source")
        if not self.revolute:
            d["body"].pop("MX")
            d["body"].pop("MY")
        return d


# --------------------------------------------------------------------------- schema
def _num(unit: str = "", **kw: Any) -> Field:
    return Field(float, unit=unit, **kw)


def _effect_table(cls: type, specs: dict[str, Field]) -> Table:
    """An optional effects table; parameters become required once ``enabled = true``."""

    def extra(out: dict, key: str, source: str) -> None:
        if out["enabled"]:
            for name, value in out.items():
                if value is None:
                    raise fail(source, f"{key}.{name}", f"a value when enabled = true "
                               f"({specs[name]._expect()}), it is missing")
        defaults = {f.name: f.default for f in fields(cls)}
        for name, value in out.items():
            if value is None:
                out[name] = defaults[name]

    return Table(
        {"enabled": Field(bool, required=False, default=False),
         **{k: replace(v, required=False, default=None) for k, v in specs.items()}},
        required=False,
        extra=extra,
    )


PLANT_SCHEMA = Table(
    {
        "name": Field(str, required=False, default=""),
        "joint": Table({
            "kind": Field(str, choices=("revolute", "prismatic")),
            "q_s": _num("rad/s", gt=0),
        }),
        "body": Table({
            "J": _num("kg m^2", gt=0),
            "MX": _num("kg m", required=False, default=0.0),
            "MY": _num("kg m", required=False, default=0.0),
        }),
        "friction": Table({
            "a_m": _num(gt=0),
            "b_m": _num(),
            "c_m": _num("N m", ge=0),
            "d_m": _num("N m"),
            "a_g": _num(gt=0),
            "b_g": _num(),
            "c_g": _num("N m", ge=0),
            "d_g": _num("N m"),
            "F_V": _num("N m s/rad", ge=0),
            "tau_off": _num("N m", required=False, default=0.0),
        }),
        "drive": Table({
            "gear_ratio": _num(gt=0),
            "torque_constant_Nm_per_A": _num("N m/A", gt=0),
            "amplifier_gain": _num("A/unit", gt=0),
            "rated_torque_Nm": _num("N m", gt=0),
            "rated_current_A": _num("A", gt=0),
            "encoder_counts_per_rev": Field(int, gt=0),
            "torque_noise_std_Nm": _num("N m", ge=0, required=False, default=0.0),
            "seed": Field(int, ge=0, required=False, default=0),
        }),
        "effects": Table(
            {e.name: _effect_table(e.params, dict(e.schema)) for e in effect_registry()},
            required=False,
        ),
    }
)


def _check_physics(v: dict, source: str) -> None:
    """Cross-field checks the schema cannot express (one-line errors naming the key)."""
    f = v["friction"]
    if not f["a_m"] + f["b_m"] > 0:
        raise fail(source, "friction.b_m", "a_m + b_m > 0 (motor load coefficient at rest)",
                   f["b_m"])
    if not f["a_g"] - f["b_g"] > 0:
        raise fail(source, "friction.b_g", "a_g - b_g > 0 (generator load coefficient at rest)",
                   f["b_g"])
    for q in ("m", "g"):
        if not f[f"c_{q}"] + f[f"d_{q}"] >= 0:
            raise fail(source, f"friction.d_{q}", f"c_{q} + d_{q} >= 0 (static friction)",
                       f[f"d_{q}"])
    if not f["a_m"] + f["b_m"] >= f["a_g"] - f["b_g"]:
        raise fail(source, "friction.a_g",
                   "a_g - b_g <= a_m + b_m (the stiction band must widen with the load, eq. 21-23)",
                   f["a_g"])
    if v["joint"]["kind"] == "prismatic":
        for k in ("MX", "MY"):
            if v["body"][k] != 0.0:
                raise fail(source, f"body.{k}", "0 or absent for a prismatic joint (no gravity)",
                           v["body"][k])


def plant_from_dict(raw: Any, source: str = "<dict>") -> PlantParams:
    """Validate a parsed plant file and build :class:`PlantParams`.

    Parameters
    ----------
    raw : mapping
        Parsed TOML (see the module docstring for the layout).
    source : str
        Name used in error messages (the file path).

    Raises
    ------
    PlantConfigError
        One line: ``"<source>: <dotted key>: expected ..., got ..."``.
    """
    try:
        v = PLANT_SCHEMA.validate(raw, "", source)
        _check_physics(v, source)
    except SchemaError as exc:
        raise PlantConfigError(str(exc)) from None
    eff_raw = v.get("effects") or {}
    effects = Effects(**{
        name: cls(**(eff_raw.get(name) or {})) for name, cls in EFFECT_TYPES.items()
    })
    return PlantParams(
        joint=JointSpec(**v["joint"]),
        body=BodyParams(**v["body"]),
        friction=FrictionParams(**v["friction"]),
        drive=DriveParams(**v["drive"]),
        effects=effects,
        name=v["name"],
        source=source,
    )


def load_plant(path: str | Path) -> PlantParams:
    """Read and validate a plant TOML file.

    Raises
    ------
    PlantConfigError
        The file cannot be read, is not TOML, or does not match the schema.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise PlantConfigError(f"{p}: cannot read the plant file ({exc.strerror})") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise PlantConfigError(f"{p}: not valid TOML ({exc})") from None
    try:
        return plant_from_dict(raw, str(p))
    except PlantConfigError as exc:  # a campaign or robot file given as the plant: say so
        hint = mixup_hint(raw, "plant")
        if not hint:
            raise
        raise PlantConfigError(f"{exc}; {hint}") from None


def default_plant() -> PlantParams:
    """The packaged plant (``sim_drivers/data/plant_default.toml``): the RX130L-like joint of
    ``examples/plant_rx130l.toml`` without any undeclared effect."""
    ref = resources.files("sim_drivers.data").joinpath("plant_default.toml")
    raw = tomllib.loads(ref.read_text(encoding="utf-8"))
    return plant_from_dict(raw, "sim_drivers/data/plant_default.toml")
