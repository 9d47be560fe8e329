"""Deliberate wiring faults of the virtual lab, for testing ``labkit check`` (and a person's eye).

A real bench goes wrong in a few usual ways: two scope inputs cabled the
other way round, the generator's SYNC cable not plugged into the scope's EXT
TRIG, the amplifier's gain switch not where the config says (that one is the
lab's ``amplifier_gain_db``), the vibrometer decoder left on a range that the
controller will not change (front panel in local mode). :class:`Miswiring`
names them; the lab applies them where the cables would.
"""
from __future__ import annotations

from dataclasses import dataclass

#: the names ``labkit lab serve --miswire`` accepts
MISWIRES = ("swapped-channels", "no-sync", "vibrometer-range-locked")


@dataclass(frozen=True)
class Miswiring:
    """What is cabled wrong (the default: nothing).

    Parameters
    ----------
    swapped_channels:
        Two scope inputs whose cables are exchanged (``(1, 2)``: the drive on 2, the vibrometer on 1).
    sync_disconnected:
        The generator's SYNC output reaches no scope input: an EXT trigger never comes.
    vibrometer_range_mm_s_per_v:
        The decoder stays at this range whatever the controller is told.
    """

    swapped_channels: tuple[int, int] | None = None
    sync_disconnected: bool = False
    vibrometer_range_mm_s_per_v: float | None = None

    @classmethod
    def from_names(cls, names: list[str] | tuple[str, ...], locked_range: float = 1000.0) -> Miswiring:
        """From ``lab serve --miswire`` names (:data:`MISWIRES`)."""
        bad = [n for n in names if n not in MISWIRES]
        if bad:
            raise ValueError(f"unknown miswiring {bad[0]!r} (one of {', '.join(MISWIRES)})")
        return cls(swapped_channels=(1, 2) if "swapped-channels" in names else None,
                   sync_disconnected="no-sync" in names,
                   vibrometer_range_mm_s_per_v=locked_range if "vibrometer-range-locked" in names else None)

    def source(self, channel: int) -> int:
        """The signal a scope input really carries (its own, unless swapped)."""
        if self.swapped_channels is None:
            return channel
        a, b = self.swapped_channels
        return b if channel == a else a if channel == b else channel

    def names(self) -> list[str]:
        return ([MISWIRES[0]] if self.swapped_channels else []) + ([MISWIRES[1]] if self.sync_disconnected else []) \
            + ([MISWIRES[2]] if self.vibrometer_range_mm_s_per_v is not None else [])
