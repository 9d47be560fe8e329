"""Small typed getters over a parsed TOML table whose errors name file, key and what was expected.

They complement :func:`labkit.tomlio.get_number` (numbers with ranges) with
tables, strings from a fixed set, integers, booleans and number lists, and
a check that no unknown key slipped in (a misspelt ``settle_cycle`` must not
silently fall back to a default at the bench).
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from labkit.errors import ConfigError
from labkit.tomlio import MISSING, TomlValue, get_number

__all__ = ["Table", "get_number"]

_MISSING = MISSING


class Table:
    """A view of one TOML table: ``data`` plus where it sits (``file``, dotted ``prefix``)."""

    def __init__(self, data: dict[str, TomlValue], file: str | Path | None, prefix: str = "") -> None:
        self.data = data
        self.file = None if file is None else str(file)
        self.prefix = prefix

    def name(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def error(self, key: str, message: str, expected: str | None = None) -> ConfigError:
        return ConfigError(message, file=self.file, key=self.name(key), expected=expected)

    def __contains__(self, key: str) -> bool:
        return key in self.data

    def table(self, key: str, *, required: bool = True) -> Table:
        """The sub-table ``key`` (an empty one when optional and absent)."""
        if key not in self.data:
            if required:
                raise self.error(key, "missing table", "a TOML table [" + self.name(key) + "]")
            return Table({}, self.file, self.name(key))
        value = self.data[key]
        if not isinstance(value, dict):
            raise self.error(key, f"not a table: {value!r}", "a TOML table [" + self.name(key) + "]")
        return Table(value, self.file, self.name(key))

    def number(self, key: str, *, default: Any = _MISSING, unit: str = "",
               minimum: float | None = None, maximum: float | None = None,
               exclusive_minimum: bool = False) -> float:
        """A finite number within the bounds (inf or nan never pass: a run would fail mid-way)."""
        value = get_number(self.data, key, file=self.file, prefix=self.prefix, unit=unit, default=default,
                           minimum=minimum, maximum=maximum, exclusive_minimum=exclusive_minimum)
        if value is not None and key in self.data and not math.isfinite(value):
            raise self.error(key, f"not finite: {value!r}", "a finite number" + (f" in {unit}" if unit else ""))
        return value

    def integer(self, key: str, *, default: Any = _MISSING, minimum: int | None = None,
                maximum: int | None = None) -> int:
        expected = "an integer" + (f" >= {minimum}" if minimum is not None else "") + (
            f" <= {maximum}" if maximum is not None else "")
        if key not in self.data:
            if default is _MISSING:
                raise self.error(key, "missing", expected)
            return default
        value = self.data[key]
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, f"not an integer: {value!r}", expected)
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            raise self.error(key, f"out of range: {value!r}", expected)
        return int(value)

    def string(self, key: str, *, default: Any = _MISSING, choices: Iterable[str] | None = None,
               lower: bool = False) -> str:
        choices = None if choices is None else tuple(choices)
        expected = ("one of " + ", ".join(repr(c) for c in choices)) if choices else "a string"
        if key not in self.data:
            if default is _MISSING:
                raise self.error(key, "missing", expected)
            return default
        value = self.data[key]
        if not isinstance(value, str) or not value.strip():
            raise self.error(key, f"not a non-empty string: {value!r}", expected)
        if lower:
            value = value.lower()
        if choices is not None and value not in choices:
            raise self.error(key, f"unknown value {value!r}", expected)
        return value

    def boolean(self, key: str, *, default: Any = _MISSING) -> bool:
        if key not in self.data:
            if default is _MISSING:
                raise self.error(key, "missing", "true or false")
            return default
        value = self.data[key]
        if not isinstance(value, bool):
            raise self.error(key, f"not a boolean: {value!r}", "true or false")
        return value

    def numbers(self, key: str, *, unit: str = "", minimum: float | None = None,
                maximum: float | None = None, exclusive_minimum: bool = False,
                default: Any = _MISSING) -> tuple[float, ...]:
        """A non-empty list of numbers, each checked like :meth:`number`."""
        bound = (f" {'>' if exclusive_minimum else '>='} {minimum:g}" if minimum is not None else "") + (
            f" <= {maximum:g}" if maximum is not None else "")
        expected = f"a non-empty list of numbers{' in ' + unit if unit else ''}{bound}"
        value = self._list(key, expected, default)
        if value is default:
            return default
        return tuple(self._item(key, i, item, expected, minimum, maximum, exclusive_minimum)
                     for i, item in enumerate(value))

    def _list(self, key: str, expected: str, default: Any) -> Any:
        """``data[key]`` as a non-empty list, or ``default`` when absent and optional."""
        if key not in self.data:
            if default is _MISSING:
                raise self.error(key, "missing", expected)
            return default
        value = self.data[key]
        if not isinstance(value, list) or not value:
            raise self.error(key, f"not a non-empty list: {value!r}", expected)
        return value

    def _item(self, key: str, i: int, item: Any, expected: str, minimum: float | None,
              maximum: float | None, exclusive_minimum: bool) -> float:
        name = f"{key}[{i}]"
        if isinstance(item, bool) or not isinstance(item, (int, float)):
            raise self.error(name, f"not a number: {item!r}", expected)
        v = float(item)
        low = minimum is not None and (v <= minimum if exclusive_minimum else v < minimum)
        if low or (maximum is not None and v > maximum) or not math.isfinite(v):
            raise self.error(name, f"out of range: {v!r}", expected)
        return v

    def strings(self, key: str, *, choices: Iterable[str] | None = None,
                default: Any = _MISSING, lower: bool = True) -> tuple[str, ...]:
        choices = None if choices is None else tuple(choices)
        expected = "a non-empty list of " + (("names from " + ", ".join(repr(c) for c in choices))
                                             if choices else "strings")
        value = self._list(key, expected, default)
        if value is default:
            return default
        out = []
        for i, item in enumerate(value):
            if not isinstance(item, str):
                raise self.error(f"{key}[{i}]", f"not a string: {item!r}", expected)
            item = item.lower() if lower else item
            if choices is not None and item not in choices:
                raise self.error(f"{key}[{i}]", f"unknown value {item!r}", expected)
            if item in out:
                raise self.error(f"{key}[{i}]", f"repeated value {item!r}", "each name once")
            out.append(item)
        return tuple(out)

    def only(self, allowed: Iterable[str]) -> None:
        """Reject keys outside ``allowed`` (typos must not fall back to defaults silently)."""
        allowed = set(allowed)
        for key in self.data:
            if key not in allowed:
                raise self.error(key, "unknown key", "one of " + ", ".join(sorted(allowed)))
