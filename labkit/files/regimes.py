"""The reader of a simulated regime map (kind ``sim_regime_map``, from ``labkit simulate regime-map --out``)."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from labkit.errors import InputError
from labkit.files.base import FileSummary, Json, LabFile, column, require_xarray, root_attrs, text, units_of

if TYPE_CHECKING:  # pragma: no cover
    import xarray

#: the grid's level axis per drive (``kind_of_drive``): tray amplitude or PZT voltage
LEVEL_NAMES = {"shaker": "amp_um", "pzt": "voltage_v"}


class RegimeMapSummary(FileSummary):
    """:meth:`SimRegimeMap.summary`: the drive, the grid's axes and how many points fell in each regime."""

    drive: str
    freq_hz: list[float]
    level_name: str
    level: list[float]
    counts: dict[str, int]


@dataclass
class SimRegimeMap(LabFile):
    """Gait regimes over a drive grid (kind ``sim_regime_map``): ``regimes[i, j]`` (``still``, ``firm``,
    ``partial``, ``jumping``), ``speeds_mm_s[i, j]`` and ``flags[i, j]`` at ``freq_hz[i]`` and
    ``level[j]`` (``level_name``: ``amp_um`` for a shaker, ``voltage_v`` for the PZT)."""

    drive: str = "?"
    level_name: str = "?"
    freq_hz: np.ndarray = field(default_factory=lambda: np.array([]))
    level: np.ndarray = field(default_factory=lambda: np.array([]))
    regimes: np.ndarray = field(default_factory=lambda: np.array([]), repr=False)
    speeds_mm_s: np.ndarray = field(default_factory=lambda: np.array([]), repr=False)
    flags: np.ndarray = field(default_factory=lambda: np.array([]), repr=False)
    params_toml: str = field(default="", repr=False)

    @property
    def meta(self) -> dict[str, Json]:
        """The map's duration, seed, parameter source and classifier thresholds."""
        meta = self.attrs.get("meta")
        return meta if isinstance(meta, dict) else {}

    def counts(self) -> dict[str, int]:
        """How many grid points fell in each regime (every regime of :data:`labkit.sim.regime.REGIMES`)."""
        from labkit.sim.regime import REGIMES

        return {r: int(np.count_nonzero(self.regimes == r)) for r in REGIMES}

    def summary(self) -> RegimeMapSummary:
        return {**super().summary(), "drive": self.drive, "freq_hz": [float(f) for f in self.freq_hz],
                "level_name": self.level_name, "level": [float(v) for v in self.level], "counts": self.counts()}

    def to_xarray(self) -> xarray.Dataset:
        """``regime``, ``speed_mm_s`` and ``flags`` over ``freq_hz`` x the level (``amp_um`` or ``voltage_v``)."""
        xr = require_xarray()
        dims = ("freq_hz", self.level_name)
        ds = xr.Dataset({"regime": (dims, self.regimes, {"units": "label"}),
                         "speed_mm_s": (dims, self.speeds_mm_s, {"units": self.units.get("speed_mm_s", "")}),
                         "flags": (dims, self.flags, {"units": "label"})},
                        coords={"freq_hz": ("freq_hz", self.freq_hz, {"units": "Hz"}),
                                self.level_name: (self.level_name, self.level,
                                                  {"units": self.units.get(self.level_name, "")})})
        ds.attrs.update(kind=self.kind, file=str(self.path), drive=self.drive)
        return ds


def read_sim_regime_map(path: Path, f: Any) -> SimRegimeMap:
    """A map written by :meth:`labkit.sim.regime.RegimeMap.to_h5` (InputError naming a missing dataset,
    or a grid whose arrays do not match its axes)."""
    drive = text(f.attrs.get("kind_of_drive", ""))
    if drive not in LEVEL_NAMES:
        raise InputError(f"unknown drive {drive!r}", file=path, key="kind_of_drive", expected=" or ".join(LEVEL_NAMES))
    level_name = LEVEL_NAMES[drive]
    names = ("freq_hz", level_name, "regime", "speed_mm_s", "flags")
    for name in names:
        if name not in f:
            raise InputError("missing dataset", file=path, key=name, expected="a regime map written by labkit")
    freq, level, regimes, speeds, flags = (column(f[n]) for n in names)
    shape = (freq.size, level.size)
    for name, arr in (("regime", regimes), ("speed_mm_s", speeds), ("flags", flags)):
        if arr.shape != shape:
            raise InputError(f"shape {arr.shape} does not match the grid", file=path, key=name,
                             expected=f"{shape} (freq_hz x {level_name})")
    return SimRegimeMap(path, "sim_regime_map", int(f.attrs.get("schema_version", 0)), root_attrs(f),
                        {n: units_of(f[n]) for n in names}, drive, level_name, freq, level,
                        regimes.astype(str), speeds.astype(float), flags.astype(str),
                        text(f.attrs.get("params_toml", "")))
