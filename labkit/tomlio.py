"""Reading and writing TOML with errors that name the file, the key and what was expected."""
from __future__ import annotations

import datetime as dt
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeAlias

import tomli_w

from labkit.errors import ConfigError, InputError

#: a TOML value as :mod:`tomllib` parses it (a table: ``dict[str, TomlValue]``; ``dt.date`` includes datetimes)
TomlValue: TypeAlias = "str | int | float | bool | dt.date | dt.time | list[TomlValue] | dict[str, TomlValue]"

#: "no default given" (a key without one is required); :class:`labkit.experiments.tomlcheck.Table` shares it
MISSING = object()


def load_toml(path: str | Path) -> tuple[dict[str, Any], str]:
    """Parse a TOML file; return ``(table, text)``.

    Raises
    ------
    InputError
        The file is missing or unreadable.
    ConfigError
        The text is not valid TOML (the parser's line and column are kept).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("no such file", file=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read: {exc}", file=path) from None
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"not valid TOML: {exc}", file=path) from None


def dump_toml(table: Mapping[str, object], path: str | Path, header: str = "") -> None:
    """Write ``table`` as TOML, with an optional comment header."""
    text = tomli_w.dumps(table)
    if header:
        text = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines()) + "\n" + text
    Path(path).write_text(text, encoding="utf-8")


def get_number(table: Mapping[str, TomlValue], key: str, *, file: str | Path | None = None,
               prefix: str = "", default: Any = MISSING, unit: str = "",
               minimum: float | None = None, maximum: float | None = None,
               exclusive_minimum: bool = False) -> float:
    """Fetch ``table[key]`` as a float and check its range; errors name file and key.

    ``prefix`` is the dotted path of ``table`` inside the file, for messages.
    """
    name = f"{prefix}.{key}" if prefix else key
    if key not in table:
        if default is MISSING:
            raise ConfigError("missing", file=file, key=name,
                              expected=_expect(unit, minimum, maximum, exclusive_minimum))
        return default
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"not a number: {value!r}", file=file, key=name,
                          expected=_expect(unit, minimum, maximum, exclusive_minimum))
    value = float(value)
    bad = (minimum is not None and (value <= minimum if exclusive_minimum else value < minimum)) or (
        maximum is not None and value > maximum)
    if bad or value != value:
        raise ConfigError(f"out of range: {value!r}", file=file, key=name,
                          expected=_expect(unit, minimum, maximum, exclusive_minimum))
    return value


def _expect(unit: str, minimum: float | None, maximum: float | None, exclusive_minimum: bool) -> str:
    parts = ["a number"]
    if unit:
        parts.append(f"in {unit}")
    if minimum is not None:
        parts.append(f"{'>' if exclusive_minimum else '>='} {minimum:g}")
    if maximum is not None:
        parts.append(f"<= {maximum:g}")
    return " ".join(parts)
