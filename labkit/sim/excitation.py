"""The two ways the robot is driven (model.md section 7): a shaker, or its own PZTs.

Both are small frozen dataclasses (picklable, so sweeps can ship them to
worker processes); :func:`dataclasses.replace` changes a field.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from labkit.errors import InputError

#: Legs driven in phase by the PZT square wave (tripod gait, model.md section 7).
#: Leg numbering (1-based): odd legs on the +x side, even legs on -x; legs 1-2 at
#: y = +pitch (front), 3-4 at y = 0, 5-6 at y = -pitch. So {1, 4, 5} is a tripod.
TRIPOD_A = (1, 4, 5)
TRIPOD_B = (2, 3, 6)


def _positive(name: str, value: float, unit: str, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"not a number: {value!r}", key=name, expected=f"a number in {unit}") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise InputError(f"out of range: {v!r}", key=name,
                         expected=f"a number in {unit}, {'>=' if allow_zero else '>'} 0")
    return v


@dataclass(frozen=True)
class Shaker:
    """Passive walking: the ground moves as ``z_g(t) = amp_um * sin(2 pi freq_hz t)``.

    ``amp_um`` is the displacement amplitude (zero-to-peak), as in the paper's
    "240 Hz, 25 um".
    """

    freq_hz: float = 240.0
    amp_um: float = 25.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "freq_hz", _positive("freq_hz", self.freq_hz, "Hz"))
        object.__setattr__(self, "amp_um", _positive("amp_um", self.amp_um, "um", allow_zero=True))

    @property
    def kind(self) -> str:
        return "shaker"

    def with_value(self, name: str, value: float) -> Shaker:
        """This drive with one field (``freq_hz``, ``amp_um``) set to ``value`` (checked)."""
        return dataclasses.replace(self, **{name: float(value)})

    def to_dict(self) -> dict[str, float | str]:
        return {"kind": "shaker", "freq_hz": self.freq_hz, "amp_um": self.amp_um}


@dataclass(frozen=True)
class PZT:
    """Autonomous walking on still ground: the on-board PZTs get a square wave.

    ``F_act,i = G_i * voltage_v * sign(sin(2 pi freq_hz t))`` on legs
    :data:`TRIPOD_A`, and the opposite sign on :data:`TRIPOD_B`.
    ``G_i`` follows from :attr:`RobotParams.act_um_per_v` (static modal
    deflection per volt). ``mass_mg`` is the robot's total mass with payload
    (``None``: the robot's own ``mass_mg``); the payload rides on the body.
    """

    freq_hz: float = 1800.0
    voltage_v: float = 20.0
    mass_mg: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "freq_hz", _positive("freq_hz", self.freq_hz, "Hz"))
        object.__setattr__(self, "voltage_v", _positive("voltage_v", self.voltage_v, "V", allow_zero=True))
        if self.mass_mg is not None:
            object.__setattr__(self, "mass_mg", _positive("mass_mg", self.mass_mg, "mg"))

    @property
    def kind(self) -> str:
        return "pzt"

    def with_value(self, name: str, value: float) -> PZT:
        """This drive with one field (``freq_hz``, ``voltage_v``, ``mass_mg``) set to ``value`` (checked)."""
        return dataclasses.replace(self, **{name: float(value)})

    def to_dict(self) -> dict[str, float | str]:
        d: dict[str, float | str] = {"kind": "pzt", "freq_hz": self.freq_hz, "voltage_v": self.voltage_v}
        if self.mass_mg is not None:
            d["mass_mg"] = self.mass_mg
        return d
