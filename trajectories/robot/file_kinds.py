"""Which of jointid's TOML files a parsed mapping looks like (campaign, robot, plant), and the
likely mix-up to name in a one-line error when a file of one kind is given as another: the one
rule, at the robot model's floor so that its robot-file reader uses it too
(:mod:`trajectories.schema` re-exports it)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["TOML_FILE_KINDS", "mixup_hint", "toml_file_kind"]


#: jointid's TOML files, told apart by their top-level keys (:func:`toml_file_kind`): what
#: each looks like and where it goes, for the hint of :func:`mixup_hint` (the robot file
#: reader uses it too: trajectories.robot.formats.mdh_toml)
TOML_FILE_KINDS = {
    "campaign": ("a campaign file ([[segments]], [[payloads]])",
                 "give it to jointid plan or jointid run"),
    "robot": ("a robot file ([[joints]] of MDH parameters)",
              "a campaign names it in [robot] file = ..., jointid fit takes it as --robot"),
    "plant": ("a simulated joint's plant file ([body], [friction])",
              "give it to jointid run CAMPAIGN --simulate"),
}


def toml_file_kind(raw: Any) -> str | None:
    """Which of jointid's TOML files a parsed mapping looks like, by its top-level keys:
    ``"campaign"`` (``segments`` or ``payloads``), ``"robot"`` (``joints`` or ``motion``),
    ``"plant"`` (``body`` or ``friction``); None when none of them."""
    keys = set(raw) if isinstance(raw, Mapping) else set()
    if keys & {"segments", "payloads"}:
        return "campaign"
    if keys & {"joints", "motion"}:
        return "robot"
    if keys & {"body", "friction"}:
        return "plant"
    return None


def mixup_hint(raw: Any, expected: str) -> str:
    """The likely mix-up when a file read as ``expected`` (a key of :data:`TOML_FILE_KINDS`)
    looks like another kind, as the tail of its one-line error, e.g. ``"it looks like a
    robot file ([[joints]] of MDH parameters), not a campaign file: a campaign names it in
    [robot] file = ..., jointid fit takes it as --robot"``; "" when it does not."""
    kind = toml_file_kind(raw)
    if kind is None or kind == expected:
        return ""
    looks, where = TOML_FILE_KINDS[kind]
    return f"it looks like {looks}, not {TOML_FILE_KINDS[expected][0].split(' (')[0]}: {where}"
