"""Documented, validated option fields for frozen dataclasses (private; the bottom layer).

An option class declares its fields with :func:`option` (default, documentation, unit and the
rule a value must satisfy) and calls :func:`validate` in ``__post_init__``; the case-file reader
(:mod:`porefsi.case.config`) checks a file's values against the same rules with
:func:`check_value` (naming the key and the file), and the docs render the rules as tables. So a
default, a bound or a choice is written once, next to the option it belongs to. Bounds of
physical quantities come from the physics classes (:attr:`porefsi.flow.fluids.Fluids.LIMITS`,
:attr:`porefsi.solid.materials.Material.LIMITS`) as :class:`Limits`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple

from porefsi.errors import ConfigError

__all__ = ["Limits", "option", "check_value", "validate", "describe_allowed", "field_default"]


class Limits(NamedTuple):
    """An interval of allowed values: ``lo`` / ``hi`` (None: unbounded), each open or closed."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False

    def contains(self, x: float) -> bool:
        """Whether ``x`` lies in the interval."""
        if self.lo is not None and (x < self.lo or (self.lo_open and x == self.lo)):
            return False
        return not (self.hi is not None and (x > self.hi or (self.hi_open and x == self.hi)))

    def describe(self) -> str:
        """E.g. ``"> 0"``, ``">= 0, < 90"``."""
        parts = []
        if self.lo is not None:
            parts.append(f"{'>' if self.lo_open else '>='} {self.lo}")
        if self.hi is not None:
            parts.append(f"{'<' if self.hi_open else '<='} {self.hi}")
        return ", ".join(parts)


def option(default, doc: str, *, choices=None, limits: Limits | None = None, unit: str = "", optional: bool = False,
           items: str | None = None):
    """A dataclass field with its documentation and validation rule.

    ``items`` validates the elements of a list field: ``"number"`` (finite numbers within
    ``limits``, stored as floats), ``"crop"`` (empty, or three ``[start, stop]`` pairs of
    integers with ``0 <= start < stop``) or ``"keys"`` (strings, option names ``section.key``).
    """
    meta = {"doc": doc, "choices": choices, "limits": limits or Limits(), "unit": unit, "optional": optional,
            "items": items}
    if isinstance(default, list):
        return dataclasses.field(default_factory=lambda: list(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def field_default(field: dataclasses.Field):
    """The default value of a dataclass field."""
    return field.default if field.default is not dataclasses.MISSING else field.default_factory()


def _unit(meta) -> str:
    return f" {meta['unit']}" if meta["unit"] else ""


def _bound_error(key: str, meta: dict, value, where: str) -> ConfigError:
    return ConfigError(f"{where}: {key} must be {meta['limits'].describe()}{_unit(meta)}, got {value!r}")


def check_value(section: str, field: dataclasses.Field, value: Any, where: str) -> Any:
    """``value`` of option ``section.field``, checked against its rule and normalised.

    Ints given for float fields become floats.

    Raises
    ------
    ConfigError
        Wrong type, not one of the choices, out of bounds; the message names ``where`` and the key.
    """
    key = f"{section}.{field.name}"
    m = field.metadata
    default = field_default(field)
    if value is None:
        if m["optional"]:
            return None
        raise ConfigError(f"{where}: {key} must be set (default {default!r})")
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: {key} must be true or false, got {value!r}")
        return value
    if isinstance(default, int) and not isinstance(default, bool):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: {key} must be an integer, got {value!r}")
    elif isinstance(default, float) or (default is None and str(field.type).startswith("float")):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: {key} must be a number{_unit(m)}, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError(f"{where}: {key} must be finite, got {value!r}")
    elif isinstance(default, str):
        if not isinstance(value, str):
            raise ConfigError(f"{where}: {key} must be a string, got {value!r}")
    elif isinstance(default, list):
        if not isinstance(value, list):
            raise ConfigError(f"{where}: {key} must be a list, got {value!r}")
        return _check_items(key, m, value, where)
    if m["choices"] is not None and value not in m["choices"]:
        raise ConfigError(f"{where}: {key} = {value!r} is not one of {list(m['choices'])}")
    if not m["limits"].contains(value):
        raise _bound_error(key, m, value, where)
    return value


def _check_items(key: str, m: dict, value: list, where: str) -> list:
    """Validate the elements of list field ``key`` by its ``items`` rule; return the list."""
    if m["items"] == "number":
        out = []
        for i, x in enumerate(value):
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                raise ConfigError(f"{where}: {key}[{i}] must be a finite number{_unit(m)}, got {x!r}")
            if not m["limits"].contains(x):
                raise _bound_error(f"{key}[{i}]", m, x, where)
            out.append(float(x))
        return out
    if m["items"] == "crop" and value:
        form = "[[x0, x1], [y0, y1], [z0, z1]] (voxel indices, integers, 0 <= start < stop)"
        if len(value) != 3 or any(not isinstance(c, list) or len(c) != 2 for c in value):
            raise ConfigError(f"{where}: {key} must be {form}, got {value!r}")
        for ax, (a, b) in zip("xyz", value, strict=True):
            if any(isinstance(v, bool) or not isinstance(v, int) for v in (a, b)):
                raise ConfigError(f"{where}: {key} bounds must be integers (voxel indices), got [{a!r}, {b!r}] "
                                  f"on {ax}; write e.g. [[0, 60], [0, 60], [0, 60]]")
            if not 0 <= a < b:
                raise ConfigError(f"{where}: {key} on {ax} must satisfy 0 <= start < stop, got [{a}, {b}]")
        return [list(c) for c in value]
    if m["items"] == "keys":
        for i, x in enumerate(value):
            if not isinstance(x, str):
                raise ConfigError(f"{where}: {key}[{i}] must be a key name such as \"solid.coarsen\", got {x!r}")
        return list(value)
    return value


def validate(obj, section: str | None = None) -> None:
    """Check every :func:`option` field of the frozen dataclass ``obj`` (call from ``__post_init__``).

    Values are normalised in place (e.g. an int given for a float option becomes a float).

    Raises
    ------
    ConfigError
        A field's value breaks its rule; the message names ``ClassName.field``.
    """
    name = section or type(obj).__name__
    for f in dataclasses.fields(obj):
        if "doc" not in f.metadata:
            continue
        v = getattr(obj, f.name)
        new = check_value(name, f, list(v) if isinstance(v, tuple) and isinstance(field_default(f), list) else v,
                          "option")
        if new is not v:
            object.__setattr__(obj, f.name, new)


def describe_allowed(field: dataclasses.Field) -> str:
    """The allowed values of an option field as table text (choices, or its bounds)."""
    m = field.metadata
    if m["choices"] is not None:
        return ", ".join(f"`{c}`" for c in m["choices"])
    return m["limits"].describe()
