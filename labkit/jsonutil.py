"""Plain JSON from what labkit holds: numpy scalars and arrays, dataclasses, paths.

One converter for instrument snapshots, run-file attributes and the CLI's
``--json`` line, so the three agree on how a value is written.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, TypeAlias

import numpy as np

#: a JSON value, as :func:`json.loads` returns it (a snapshot, a decoded ``*_json`` attribute, a record)
Json: TypeAlias = "None | bool | int | float | str | list[Json] | dict[str, Json]"


def to_jsonable(obj: Any, *, finite: bool = False) -> Any:
    """Convert ``obj`` recursively into dicts, lists, str, int, float, bool and None.

    Parameters
    ----------
    obj:
        Any nesting of dicts, lists/tuples, numpy arrays and scalars,
        dataclass instances and paths; other objects become ``str(obj)``.
    finite:
        Turn NaN and infinities into ``None`` (strict JSON has no NaN).
    """
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        obj = dataclasses.asdict(obj)
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v, finite=finite) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v, finite=finite) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist(), finite=finite)
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float):
        return None if finite and not math.isfinite(obj) else obj
    if isinstance(obj, (str, int, bool)) or obj is None:
        return obj
    if isinstance(obj, complex):
        return [obj.real, obj.imag]
    if isinstance(obj, Path):
        return str(obj)
    return str(obj)
