"""Plant files: the shipped ones load, bad ones fail with one line naming file and key."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from sim_drivers import PlantConfigError, SimError
from sim_drivers.plant_config import (
    PlantParams,
    default_plant,
    load_plant,
    plant_from_dict,
)

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "plant_rx130l.toml"

# docs/architecture.md, "Parameter names": the paper model (eq. 42-43)
NEW_MODEL_NAMES = (
    "a_m_J b_m_J a_m_MX b_m_MX a_m_MY b_m_MY a_m b_m "
    "a_g_J b_g_J a_g_MX b_g_MX a_g_MY b_g_MY a_g b_g c_m d_m c_g d_g F_V tau_off"
).split()


def test_example_is_the_default_plant_plus_one_position_ripple():
    ex = load_plant(EXAMPLE)
    de = default_plant()
    assert isinstance(ex, PlantParams) and ex.source == str(EXAMPLE)
    assert ex.effects.enabled() == ("position_ripple",)
    assert de.effects.enabled() == ()
    assert ex.without_effects().as_dict() == de.as_dict()
    r = ex.effects.position_ripple
    assert 2.0 <= r.amplitude_Nm <= 6.0 and r.period_rad == pytest.approx(2 * math.pi / 16)
    assert "UNDECLARED EFFECT SWITCHED ON" in EXAMPLE.read_text()
    te = ex.truth_effects()
    assert set(te) == {"position_ripple"}
    assert te["position_ripple"]["amplitude_Nm"] == r.amplitude_Nm
    assert math.hypot(te["position_ripple"]["sin_Nm"], te["position_ripple"]["cos_Nm"]) \
        == pytest.approx(r.amplitude_Nm)


def test_default_values_in_the_spirit_of_table_ii():
    p = default_plant()
    assert p.revolute and p.joint.q_s == 0.03
    assert 25 < p.body.J < 35 and 190 < p.body.MX * 9.81 < 220
    f = p.friction
    assert f.a_m > 1 > f.a_g and f.c_m > f.c_g > 0 and f.F_V > 0 and f.tau_off > 0


def test_truth_uses_the_architecture_names_and_exact_products():
    p = default_plant()
    t = p.truth()
    assert list(t) == NEW_MODEL_NAMES
    f, b = p.friction, p.body
    assert t["a_m_J"] == f.a_m * b.J and t["b_g_MX"] == f.b_g * b.MX
    assert t["a_g_MY"] == f.a_g * b.MY and t["a_m"] == f.a_m and t["b_g"] == f.b_g
    assert t["tau_off"] == f.tau_off and t["d_g"] == f.d_g


def test_with_effect_and_round_trip():
    p = default_plant()
    q = p.with_effect("spring", stiffness_Nm_per_rad=40.0, rest_position_rad=0.1)
    assert q.effects.enabled() == ("spring",) and q.effects.spring.stiffness_Nm_per_rad == 40.0
    assert q.truth_effects() == {"spring": {"stiffness_Nm_per_rad": 40.0,
                                            "rest_position_rad": 0.1}}
    assert plant_from_dict(q.as_dict()).as_dict() == q.as_dict()
    with pytest.raises(PlantConfigError, match=r"effects\.magic: no such effect"):
        p.with_effect("magic")
    with pytest.raises(PlantConfigError, match=r"effects\.spring\.k: no such key"):
        p.with_effect("spring", k=1.0)
    with pytest.raises(PlantConfigError, match=r"effects\.torque_lag\.time_constant_s"):
        p.with_effect("torque_lag", time_constant_s=-1.0)


def _raw():
    return default_plant().as_dict()


def _mutate(path, value):
    raw = _raw()
    node = raw
    keys = path.split(".")
    for k in keys[:-1]:
        node = node.setdefault(k, {})
    if value is _DELETE:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return raw


_DELETE = object()


@pytest.mark.parametrize(
    "path, value, key, expect",
    [
        ("body.Jz", 1.0, "body.Jz", "unknown key"),
        ("friction.c_m", "21", "friction.c_m", "a number"),
        ("drive.encoder_counts_per_rev", 4096.5, "drive.encoder_counts_per_rev", "an integer"),
        ("drive.seed", True, "drive.seed", "an integer"),
        ("body.J", _DELETE, "body.J", "missing"),
        ("body.J", -3.0, "body.J", "> 0"),
        ("joint.kind", "helical", "joint.kind", "one of"),
        ("joint.q_s", 0.0, "joint.q_s", "> 0"),
        ("friction.F_V", float("nan"), "friction.F_V", "finite"),
        ("friction.b_g", 1.0, "friction.b_g", "a_g - b_g > 0"),
        ("friction.d_m", -30.0, "friction.d_m", "c_m + d_m >= 0"),
        ("drive", 3, "drive", "a table"),
        ("effects.spring", {"enabled": True, "stiffness_Nm_per_rad": 3.0},
         "effects.spring.rest_position_rad", "when enabled = true"),
        ("effects.torque_lag.time_constant_s", 0.0, "effects.torque_lag.time_constant_s", "> 0"),
        ("effects.wobble", {}, "effects.wobble", "unknown key"),
        ("effects.position_ripple.enabled", "yes", "effects.position_ripple.enabled",
         "a boolean"),
    ],
)
def test_bad_values_name_file_and_key(path, value, key, expect):
    with pytest.raises(PlantConfigError) as info:
        plant_from_dict(_mutate(path, value), "my_plant.toml")
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(f"my_plant.toml: {key}:"), msg
    assert expect in msg, msg


def test_prismatic_rejects_first_moments():
    raw = _raw()
    raw["joint"]["kind"] = "prismatic"
    with pytest.raises(PlantConfigError, match=r"^p\.toml: body\.MX: expected 0 or absent"):
        plant_from_dict(raw, "p.toml")


def test_file_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[joint\nkind = 1\n")
    with pytest.raises(PlantConfigError, match=r"bad\.toml: not valid TOML"):
        load_plant(bad)
    with pytest.raises(PlantConfigError, match=r"missing\.toml: cannot read"):
        load_plant(tmp_path / "missing.toml")
    wrong = tmp_path / "wrong.toml"
    wrong.write_text(EXAMPLE.read_text().replace("amplitude_Nm = 2.5", "amplitude_Nm = 'big'"))
    with pytest.raises(PlantConfigError) as info:
        load_plant(wrong)
    assert str(info.value).startswith(f"{wrong}: effects.position_ripple.amplitude_Nm: expected")
    assert issubclass(PlantConfigError, SimError) and issubclass(PlantConfigError, ValueError)
