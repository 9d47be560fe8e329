"""A simulated sweep read back as the simulator's own result (:class:`labkit.sim.SweepResult`).

:func:`labkit.open` reads a ``sim_sweep`` file as a :class:`~labkit.files.kinds.SimSweep` (its
arrays by name); :func:`sweep_result` turns that into the :class:`~labkit.sim.SweepResult` that
:func:`labkit.sim.sweep` returned, so that the file's one reader serves both.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from labkit.errors import InputError
from labkit.files.base import Json
from labkit.files.kinds import SimSweep

if TYPE_CHECKING:  # pragma: no cover
    from labkit.sim.sweep import SweepResult


def _table(value: Json) -> dict[str, Json]:
    """A decoded ``*_json`` attribute that should be a table (``{}`` when absent or not one)."""
    return value if isinstance(value, dict) else {}


def sweep_result(f: SimSweep) -> SweepResult:
    """The :class:`~labkit.sim.SweepResult` a ``sim_sweep`` file holds (InputError naming a missing dataset)."""
    from labkit.sim.sweep import SweepResult

    c = f.columns

    def need(name: str) -> np.ndarray:
        if name not in c:
            raise InputError("missing dataset", file=f.path, key=name, expected="a sweep written by labkit")
        return c[name]

    def text(name: str) -> np.ndarray | None:
        return c[name].astype(str) if name in c else None

    return SweepResult(quantity=f.quantity, values=f.values, speeds_mm_s=need("speeds_mm_s"),
                       contact_fraction=need("contact_fraction"), patterns=need("patterns").astype(str),
                       impacts=need("impacts"), scenario=_table(f.attrs.get("scenario")),
                       params_toml=f.params_toml, meta=_table(f.attrs.get("meta")), flags=text("flags"),
                       convergence=text("convergence"), step_error_mm_s=c.get("step_error_mm_s"),
                       dt_s=c.get("dt_s"))


def read_sweep_result(path: str | os.PathLike[str]) -> SweepResult:
    """Read a file written by :meth:`labkit.sim.SweepResult.to_h5` (``labkit simulate sweep --out``)
    through :func:`labkit.open`; InputError naming the file when it holds another kind."""
    from labkit.files import open_file

    f = open_file(path)
    if not isinstance(f, SimSweep) or f.kind != "sim_sweep":
        raise InputError(f"not a simulated sweep: kind {f.kind!r}", file=Path(path), key="kind",
                         expected="sim_sweep (labkit simulate sweep --out)")
    return sweep_result(f)
