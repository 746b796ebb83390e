"""A small declarative validator for configuration mappings (parsed TOML).

Pure: it validates dictionaries, it never reads files. Every failure raises
:class:`trajectories.SchemaError` with a one-line message that names the source, the
full dotted key and what was expected, e.g.::

    campaign.toml: joint.limits.max_velocity: expected a number > 0 [rad/s], got -1

Usage::

    JOINT = Table({
        "kind": Field(str, choices=("revolute", "prismatic")),
        "max_velocity": Field(float, gt=0, unit="rad/s"),
        "note": Field(str, required=False, default=""),
    })
    joint = JOINT.validate(raw["joint"], "joint", source="campaign.toml")

Integers are accepted where floats are expected; booleans never count as numbers.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from . import SchemaError
from .robot.file_kinds import TOML_FILE_KINDS, mixup_hint, toml_file_kind  # noqa: F401

_MISSING = object()


def _type_name(t: type) -> str:
    return {float: "a number", int: "an integer", str: "a string", bool: "a boolean"}.get(
        t, t.__name__
    )


def fail(source: str, key: str, expected: str, got: Any = _MISSING) -> SchemaError:
    """Build the one-line error ``"<source>: <key>: expected <expected>, got <got>"``."""
    where = f"{source}: " if source else ""
    tail = "" if got is _MISSING else f", got {got!r}"
    return SchemaError(f"{where}{key}: expected {expected}{tail}")


def unknown(source: str, key: str, allowed: str) -> SchemaError:
    """Build the one-line error for a key the schema does not know."""
    where = f"{source}: " if source else ""
    return SchemaError(
        f"{where}{key}: expected one of the known keys ({allowed}), not this unknown key"
    )


@dataclass(frozen=True)
class Field:
    """A scalar (or list of scalars) field.

    Parameters
    ----------
    type : type
        ``float``, ``int``, ``str`` or ``bool``.
    required : bool
        Missing required fields are an error; missing optional ones take ``default``.
    gt, ge, lt, le : float, optional
        Bounds on numbers.
    choices : tuple, optional
        Allowed values.
    unit : str
        Unit shown in error messages, e.g. ``"rad/s"``.
    list_of : bool
        The value is a list of ``type``; bounds apply to each element.
    min_len : int
        Minimum list length when ``list_of``.
    check : callable, optional
        Extra check ``value -> str | None`` returning an expectation text on failure.
    """

    type: type
    required: bool = True
    default: Any = None
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    choices: tuple | None = None
    unit: str = ""
    list_of: bool = False
    min_len: int = 1
    check: Callable[[Any], str | None] | None = None

    def _expect(self) -> str:
        parts = [_type_name(self.type)]
        for op, v in (("> ", self.gt), (">= ", self.ge), ("< ", self.lt), ("<= ", self.le)):
            if v is not None:
                parts.append(f"{op}{v:g}")
        text = " ".join(parts)
        if self.choices is not None:
            text = "one of " + ", ".join(repr(c) for c in self.choices)
        if self.unit:
            text += f" [{self.unit}]"
        return text

    def _scalar(self, value: Any, key: str, source: str) -> Any:
        t = self.type
        if isinstance(value, bool) and t is not bool:
            raise fail(source, key, self._expect(), value)
        original = value
        if t is float and isinstance(value, int):
            value = float(value)
        if not isinstance(value, t):
            raise fail(source, key, self._expect(), original)
        if t is float and not math.isfinite(value):
            raise fail(source, key, "a finite number", original)
        if self.choices is not None and value not in self.choices:
            raise fail(source, key, self._expect(), original)
        if t in (float, int):
            if (
                (self.gt is not None and not value > self.gt)
                or (self.ge is not None and not value >= self.ge)
                or (self.lt is not None and not value < self.lt)
                or (self.le is not None and not value <= self.le)
            ):
                raise fail(source, key, self._expect(), original)
        if self.check is not None:
            problem = self.check(value)
            if problem:
                raise fail(source, key, problem, original)
        return value

    def validate(self, value: Any, key: str, source: str = "") -> Any:
        if self.list_of:
            if not isinstance(value, list) or len(value) < self.min_len:
                raise fail(
                    source, key, f"a list of at least {self.min_len} x {self._expect()}", value
                )
            return tuple(self._scalar(v, f"{key}[{i}]", source) for i, v in enumerate(value))
        return self._scalar(value, key, source)


@dataclass(frozen=True)
class Table:
    """A table (mapping) with known keys; unknown keys are an error.

    ``fields`` maps key -> :class:`Field`, :class:`Table` or :class:`ArrayOfTables`.
    """

    fields: Mapping[str, Any]
    required: bool = True
    doc: str = ""
    extra: Callable[[dict, str, str], None] | None = field(default=None)

    def validate(self, value: Any, key: str, source: str = "") -> dict:
        if not isinstance(value, Mapping):
            raise fail(source, key or "<top level>", "a table", value)
        extra = sorted(set(value) - set(self.fields))
        if extra:
            where = f"{key}." if key else ""
            allowed = ", ".join(sorted(self.fields))
            raise unknown(source, f"{where}{extra[0]}", allowed)
        out: dict = {}
        for name, spec in self.fields.items():
            sub = f"{key}.{name}" if key else name
            if name not in value:
                if getattr(spec, "required", True):
                    raise fail(source, sub, f"a value ({spec_expect(spec)}), it is missing")
                out[name] = _default(spec)
                continue
            out[name] = spec.validate(value[name], sub, source)
        if self.extra is not None:
            self.extra(out, key, source)
        return out


@dataclass(frozen=True)
class TaggedTable:
    """A table whose ``kind`` key selects its schema among ``kinds`` (the segments of a
    campaign); a missing or unknown ``kind`` is an error naming the choices."""

    kinds: Mapping[str, Table]
    required: bool = True

    def validate(self, value: Any, key: str, source: str = "") -> dict:
        if not isinstance(value, Mapping):
            raise fail(source, key, "a table", value)
        names = [repr(k) for k in self.kinds]
        if "kind" not in value:
            listed = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"
            raise fail(source, f"{key}.kind", f"a value ({listed}), it is missing")
        kind = value["kind"]
        if kind not in self.kinds:
            raise fail(source, f"{key}.kind", f"one of {', '.join(names)}", kind)
        return self.kinds[kind].validate(value, key, source)


@dataclass(frozen=True)
class ArrayOfTables:
    """A TOML array of tables (``[[segments]]``), each validated by ``item``."""

    item: Table
    required: bool = True
    min_len: int = 1

    def validate(self, value: Any, key: str, source: str = "") -> tuple[dict, ...]:
        if not isinstance(value, list) or len(value) < self.min_len:
            raise fail(source, key, f"an array of at least {self.min_len} table(s)", value)
        return tuple(self.item.validate(v, f"{key}[{i}]", source) for i, v in enumerate(value))


def spec_expect(spec: Any) -> str:
    if isinstance(spec, Field):
        if spec.list_of:
            return f"a list of {spec._expect()}"
        return spec._expect()
    if isinstance(spec, ArrayOfTables):
        return "an array of tables"
    return "a table"


def _default(spec: Any) -> Any:
    if isinstance(spec, Field):
        return spec.default
    if isinstance(spec, Table):
        return spec.validate({}, "", "") if all(
            not getattr(s, "required", True) for s in spec.fields.values()
        ) else None
    return ()
