"""A simulated Polytec OFV-5000 controller (velocity decoder VD-09) on a pseudo-terminal.

Protocol (RS-232, ``\\n``): ``Get,<Dev>,<i>,<Prop>`` answers one line;
``Set,<Dev>,<i>,<Prop>,<value>`` answers nothing (as the controller);
``GetDevInfo,<Dev>,<i>,<Prop>`` answers the allowed values, comma-separated.
Unknown devices, properties or values get no answer at all (a driver times
out), except ``GetDevInfo`` of an unknown device which answers
``Not Available``. The velocity decoder is ``VeloDec,1``; its analog output
lags the velocity by ``SignalDelay`` (7.6 us here), which the lab simulates.

The analog output is velocity / scale factor, at most +-10 V;
``Get,VeloDec,1,OverRange`` is ``1`` while the velocity at the laser spot
exceeds the range, or while the last acquisition clipped the output (a lab
choice: the OFV-5000's over-range indicator has no documented remote query
here; the drivers make the query a setting).
"""
from __future__ import annotations

import threading
from collections.abc import Callable

RANGES_MM_S_PER_V = (1.0, 5.0, 25.0, 125.0, 1000.0)
FULL_SCALE_V = 10.0


def range_text(scale: float) -> str:
    return f"{scale:g}mm/s/V"


class _Controller:
    """What both controllers share: the lab's velocity at the spot, the range, over-range."""

    name = "vibrometer"
    scale_mm_s_per_v: float
    #: the decoder's signal delay: the analog output is the velocity this long ago
    signal_delay_s = 0.0

    def __init__(self, peak_velocity_mm_s: Callable[[], float] = lambda: 0.0) -> None:
        self.peak_velocity_mm_s = peak_velocity_mm_s
        self.lock = threading.RLock()
        self.clipped = False   # the last acquisition saw the analog output at its +-10 V limit
        self.range_locked = False   # a miswiring: the decoder ignores range settings

    def lock_range(self, scale_mm_s_per_v: float) -> None:
        """Put the decoder on this range and keep it there (the lab's miswiring option)."""
        self._force_range(float(scale_mm_s_per_v))
        self.range_locked = True

    def _force_range(self, scale: float) -> None:
        raise NotImplementedError

    @property
    def full_scale_mm_s(self) -> float:
        return self.scale_mm_s_per_v * FULL_SCALE_V

    def over_range(self) -> bool:
        """The steady-state velocity at the spot exceeds the range, or the last record clipped."""
        return self.clipped or self.peak_velocity_mm_s() > self.full_scale_mm_s


class SimOFV5000(_Controller):
    """The controller's state and line protocol; ``peak_velocity_mm_s()`` comes from the lab."""

    #: VD-09 decoder: 7.6 us (the lab's value, answered as ``SignalDelay``)
    signal_delay_s = 7.6e-6

    def __init__(self, peak_velocity_mm_s: Callable[[], float] = lambda: 0.0) -> None:
        super().__init__(peak_velocity_mm_s)
        self.scale_mm_s_per_v = 125.0
        self.props: dict[tuple[str, int, str], str] = {
            ("Controller", 0, "Name"): "OFV-5000",
            ("Controller", 0, "Version"): "4.1",
            ("Controller", 0, "Remote"): "Local",
            ("Controller", 0, "PowerUp"): "Last",
            ("Interface", 0, "Name"): "RS-232",
            ("Interface", 0, "BaudRate"): "115200",
            ("Interface", 0, "Echo"): "Off",
            ("SensorHead", 0, "Name"): "OFV-505",
            ("VeloDec", 1, "Name"): "VD-09",
            ("VeloDec", 1, "MaxFreq"): "1.5MHz",
            ("VeloDec", 1, "SignalDelay"): f"{self.signal_delay_s * 1e6:g}us",
            ("SensorHead", 0, "SignalLevel"): "87",
            ("VeloDec", 1, "Filter"): "Off",
            ("VeloDec", 1, "Tracking"): "Off",
        }
        self.allowed: dict[tuple[str, int, str], tuple[str, ...]] = {
            ("VeloDec", 1, "Range"): tuple(range_text(r) for r in RANGES_MM_S_PER_V),
            ("Controller", 0, "Remote"): ("Local", "Remote"),
            ("Interface", 0, "Echo"): ("Off", "On"),
            ("VeloDec", 1, "Filter"): ("Off", "20kHz", "100kHz", "1.5MHz"),
            ("VeloDec", 1, "Tracking"): ("Off", "On"),
        }

    def _force_range(self, scale: float) -> None:
        self.scale_mm_s_per_v = scale

    def handle(self, line: str) -> bytes | None:
        parts = [p.strip() for p in line.strip().split(",")]
        with self.lock:
            reply = self._handle(parts)
        if reply is None:
            return None
        if self.props[("Interface", 0, "Echo")] == "On":
            return (line + "\n" + reply + "\n").encode("ascii", "replace")
        return (reply + "\n").encode("ascii", "replace")

    def _handle(self, parts: list[str]) -> str | None:
        if len(parts) < 4 or not parts[2].isdigit():
            return None
        verb, dev, idx, prop = parts[0], parts[1], int(parts[2]), parts[3]
        key = (dev, idx, prop)
        if verb == "Get" and len(parts) == 4:
            return self._get(key)
        if verb == "GetDevInfo" and len(parts) == 4:
            if key in self.allowed:
                return ",".join(self.allowed[key])
            return self.props.get(key, "Not Available")
        if verb == "Set" and len(parts) == 5:
            self._set(key, parts[4])
        return None

    def _get(self, key: tuple[str, int, str]) -> str | None:
        if key == ("VeloDec", 1, "Range"):
            return range_text(self.scale_mm_s_per_v)
        if key == ("VeloDec", 1, "OverRange"):
            return "1" if self.over_range() else "0"
        return self.props.get(key)

    def _set(self, key: tuple[str, int, str], value: str) -> None:
        """A setting; a locked range, an invalid value and an unknown property are ignored silently."""
        if key == ("VeloDec", 1, "Range"):
            if self.range_locked:
                return
            for r in RANGES_MM_S_PER_V:
                if value.lower() == range_text(r).lower():
                    self.scale_mm_s_per_v = r
                    self.clipped = False
            return
        if key in self.allowed and value not in self.allowed[key]:
            return      # invalid settings are ignored silently
        if key in self.props:
            self.props[key] = value


#: OFV-3001 with an OVD-01 decoder: range number -> scale factor, mm/s per V (docs/instruments.md)
OFV3001_OVD01 = {5: 1.0, 1: 5.0, 2: 25.0, 3: 125.0, 4: 1000.0}


class SimOFV3001(_Controller):
    """A simulated Polytec OFV-3001 controller with an OVD-01 velocity decoder.

    Protocol (RS-232, ``\\n``): ``REN`` puts it under remote control (no
    answer); ``VELO?`` answers the range number; ``VELOn`` sets it (no
    answer); ``OVR`` answers ``0`` or ``1`` (over range). As on the
    controller, invalid settings, and settings before ``REN``, are ignored
    silently; unknown commands get no answer.
    """

    def __init__(self, peak_velocity_mm_s: Callable[[], float] = lambda: 0.0) -> None:
        super().__init__(peak_velocity_mm_s)
        self.range_number = 3
        self.remote = False

    def _force_range(self, scale: float) -> None:
        self.range_number = {v: k for k, v in OFV3001_OVD01.items()}[scale]

    @property   # read-only here: the range number decides it
    def scale_mm_s_per_v(self) -> float:  # type: ignore[override]
        return OFV3001_OVD01[self.range_number]

    def handle(self, line: str) -> bytes | None:
        word = line.strip().upper()
        with self.lock:
            if word == "REN":
                self.remote = True
                return None
            if word == "VELO?":
                return f"{self.range_number}\n".encode("ascii")
            if word == "OVR":
                return b"1\n" if self.over_range() else b"0\n"
            if word.startswith("VELO") and word[4:].isdigit():
                n = int(word[4:])
                if self.remote and n in OFV3001_OVD01 and not self.range_locked:
                    self.range_number = n
                    self.clipped = False
            return None
