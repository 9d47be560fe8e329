"""Polytec laser Doppler vibrometer controllers over RS-232: OFV-3001 and OFV-5000.

The controller's analog output is a voltage; velocity = volts x the decoder's
scale factor (mm/s per V), so the driver's job is the range: read it, set it
(verified by reading it back, because the OFV-3001 silently ignores invalid
settings), and report over-range.

Facts marked (unverified) in ``docs/instruments.md`` are settings with
defaults that can be overridden per unit: the OFV-3001's baud rate, and the
OFV-5000's over-range and identity commands.
"""
from __future__ import annotations

import re
from typing import Any, ClassVar

from labkit.drivers.base import Instrument, check_range
from labkit.errors import ConfigError, InstrumentError, LimitError

#: OFV-3001 range number by scale factor (mm/s per V), per velocity decoder.
OFV3001_RANGES: dict[str, dict[float, int]] = {
    "OVD-01": {1.0: 5, 5.0: 1, 25.0: 2, 125.0: 3, 1000.0: 4},
    "OVD-02": {5.0: 6, 25.0: 7, 125.0: 8, 1000.0: 9},
}

_TRUE = {"1", "ON", "TRUE", "YES", "+1"}
_FALSE = {"0", "OFF", "FALSE", "NO", "+0"}


def _fmt_scale(x: float) -> str:
    return format(float(x), "g")


class Vibrometer(Instrument):
    """Common part: the scale factor, the velocity from volts, over-range."""

    link = "serial"
    _scale: float | None = None
    #: Velocity decoder scale factor (each controller provides it, as a property).
    scale_mm_s_per_v: float

    def to_velocity_mm_s(self, volts):
        """Velocity in mm/s from the analog output's volts (uses the cached scale factor)."""
        scale = self._scale if self._scale is not None else self.scale_mm_s_per_v
        return volts * scale

    def snapshot(self) -> dict[str, Any]:
        snap = super().snapshot()
        snap["state"]["scale_mm_s_per_v"] = self.scale_mm_s_per_v
        return snap


class OFV3001(Vibrometer):
    """Polytec OFV-3001 controller: ``REN``, ``VELO?``, ``VELOn``, ``OVR``.

    Parameters
    ----------
    decoder:
        ``"OVD-01"`` or ``"OVD-02"`` (selects the range-number table).
    ranges:
        Override the table ``{scale_mm_s_per_v: range_number}`` for this unit.
    serial_number:
        Recorded in the identity (the OFV-3001 has no identity query we trust).

    Notes
    -----
    The baud rate (9600 in a public setup) is (unverified): pass
    ``baud_rate=...`` to :meth:`open`. ``REN`` (remote) is sent before the
    first command of a session.
    """

    model = "OFV-3001"
    transport_defaults: ClassVar[dict[str, Any]] = {"baud_rate": 9600}

    def __init__(self, transport, *, name: str | None = None, decoder: str = "OVD-01",
                 ranges: dict[float, int] | None = None, serial_number: str = "",
                 signal_delay_s: float = 0.0, **settings: Any) -> None:
        super().__init__(transport, name=name, **settings)
        #: the decoder's signal delay (declared: the OFV-3001 has no query for it; (unverified))
        self.signal_delay_s = check_range("signal_delay_s", signal_delay_s, 0.0, 1e-3, "s")
        if ranges is None:
            if decoder not in OFV3001_RANGES:
                raise ConfigError(f"unknown OFV-3001 decoder {decoder!r}", key="decoder",
                                  expected=f"one of {sorted(OFV3001_RANGES)} or explicit ranges")
            ranges = OFV3001_RANGES[decoder]
        self.decoder = decoder
        self.ranges = {float(k): int(v) for k, v in ranges.items()}
        self._by_number = {v: k for k, v in self.ranges.items()}
        self.serial_number = serial_number
        self._remote = False
        self._scale: float | None = None

    def settings(self) -> dict[str, Any]:
        return {**super().settings(), "decoder": self.decoder,
                "ranges": {_fmt_scale(k): v for k, v in sorted(self.ranges.items())},
                "serial_number": self.serial_number, "signal_delay_s": self.signal_delay_s}

    @property
    def identity(self) -> str:
        return f"Polytec,OFV-3001,{self.serial_number or 'unknown'},{self.decoder}"

    def remote(self) -> None:
        """Put the controller under remote control (``REN``)."""
        self.write("REN")
        self._remote = True

    def _ensure_remote(self) -> None:
        if not self._remote:
            self.remote()

    @property
    def range_number(self) -> int:
        """The decoder's range number (``VELO?``)."""
        self._ensure_remote()
        return self.query_int("VELO?")

    @property
    def scale_mm_s_per_v(self) -> float:
        """Scale factor in mm/s per V, from ``VELO?`` (set: one of the table's values)."""
        n = self.range_number
        if n not in self._by_number:
            raise InstrumentError(f"range number {n} is not in the {self.decoder} table "
                                  f"{self.ranges}", instrument=self.name, command="VELO?")
        self._scale = self._by_number[n]
        return self._scale

    @scale_mm_s_per_v.setter
    def scale_mm_s_per_v(self, value: float) -> None:
        v = float(value)
        if v not in self.ranges:
            raise LimitError(f"velocity range: {v:g} mm/s/V is not a range of the "
                             f"{self.decoder} decoder "
                             f"(one of {sorted(self.ranges)}); nothing was sent",
                             limit="velocity range")
        self._ensure_remote()
        n = self.ranges[v]
        self.write(f"VELO{n}")
        back = self.query_int("VELO?")       # invalid settings are silently ignored: verify
        if back != n:
            raise InstrumentError(f"range not accepted: asked {n} ({v:g} mm/s/V), "
                                  f"reads back {back}",
                                  instrument=self.name, command=f"VELO{n}")
        self._scale = v
        self.state["scale_mm_s_per_v"] = v

    def over_range(self) -> bool:
        """True while the decoder is over range (``OVR`` -> 1)."""
        self._ensure_remote()
        return _parse_bool(self, self.query("OVR"), "OVR")

    def snapshot(self) -> dict[str, Any]:
        snap = Instrument.snapshot(self)
        snap["state"]["scale_mm_s_per_v"] = self.scale_mm_s_per_v
        snap["state"]["range_number"] = self.ranges[snap["state"]["scale_mm_s_per_v"]]
        return snap


_RANGE_TEXT = re.compile(r"^\s*([0-9.]+(?:[eE][-+]?\d+)?)\s*(mm|m|um|µm)/s/V\s*$")
_UNIT = {"mm": 1.0, "m": 1000.0, "um": 1e-3, "µm": 1e-3}


def _number_with_unit(pattern: re.Pattern[str], units: dict[str, float], text: str, what: str) -> float:
    m = pattern.match(text)
    if not m:
        raise ValueError(f"not a {what}: {text!r}")
    return float(m.group(1)) * units[m.group(2)]


def parse_range_text(text: str) -> float:
    """``"125mm/s/V"`` -> 125.0 (mm/s per V); ``"1m/s/V"`` -> 1000.0. ValueError otherwise."""
    return _number_with_unit(_RANGE_TEXT, _UNIT, text, "velocity range")


_DELAY_TEXT = re.compile(r"^\s*([0-9.]+(?:[eE][-+]?\d+)?)\s*(s|ms|us|µs|ns)\s*$")
_DELAY_UNIT = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}


def parse_delay_text(text: str) -> float:
    """``"7.6us"`` -> 7.6e-06 s. ValueError otherwise."""
    return _number_with_unit(_DELAY_TEXT, _DELAY_UNIT, text, "delay")


def _parse_bool(inst: Instrument, reply: str, command: str) -> bool:
    r = reply.strip().upper()
    if r in _TRUE:
        return True
    if r in _FALSE:
        return False
    raise InstrumentError(f"garbled reply {reply[:40]!r} (expected 0/1)", instrument=inst.name,
                          command=command)


class OFV5000(Vibrometer):
    """Polytec OFV-5000 controller: ``Get,VeloDec,<i>,Range`` / ``Set,VeloDec,<i>,Range,<r>``.

    Parameters
    ----------
    decoder_index:
        The velocity decoder's index ``<i>`` (differs per unit; default 1).
    ranges_mm_s_per_v:
        If given, the ranges this unit's decoder offers: a request outside them
        is refused before sending. Otherwise the set is verified by reading back.
    over_range_command:
        Query for the over-range flag (unverified; default
        ``"Get,VeloDec,{i},OverRange"``; ``{i}`` is the decoder index).
    identity_command:
        Query for the controller's identity (unverified; default
        ``"GetDevInfo,Controller,0,Name"``).

    Notes
    -----
    115200 8N1 (override with ``baud_rate=...``). ``Set`` has no reply.
    """

    model = "OFV-5000"
    transport_defaults: ClassVar[dict[str, Any]] = {"baud_rate": 115200, "bytesize": 8,
                                                    "parity": "N", "stopbits": 1}

    def __init__(self, transport, *, name: str | None = None, decoder_index: int = 1,
                 ranges_mm_s_per_v: tuple[float, ...] | None = None,
                 over_range_command: str = "Get,VeloDec,{i},OverRange",
                 identity_command: str = "GetDevInfo,Controller,0,Name",
                 signal_delay_command: str = "Get,VeloDec,{i},SignalDelay",
                 signal_delay_s: float | None = None,
                 **settings: Any) -> None:
        super().__init__(transport, name=name, **settings)
        self.signal_delay_command = signal_delay_command
        self._delay: float | None = None if signal_delay_s is None else check_range(
            "signal_delay_s", signal_delay_s, 0.0, 1e-3, "s")
        self._delay_declared = signal_delay_s is not None
        self.decoder_index = int(decoder_index)
        self.ranges_mm_s_per_v = (None if ranges_mm_s_per_v is None
                                  else tuple(sorted(float(r) for r in ranges_mm_s_per_v)))
        self.over_range_command = over_range_command
        self.identity_command = identity_command
        self._scale: float | None = None

    def settings(self) -> dict[str, Any]:
        return {**super().settings(), "decoder_index": self.decoder_index,
                "ranges_mm_s_per_v": self.ranges_mm_s_per_v,
                "over_range_command": self.over_range_command,
                "identity_command": self.identity_command,
                "signal_delay_command": self.signal_delay_command,
                "signal_delay_s": self._delay if self._delay_declared else None}

    def _get(self, prop: str, dev: str = "VeloDec") -> str:
        return self.query(f"Get,{dev},{self.decoder_index if dev == 'VeloDec' else 0},{prop}")

    @property
    def signal_delay_s(self) -> float:
        """The decoder's signal delay, s: its analog output is the velocity this long ago (asked once
        with ``signal_delay_command``, answered like ``7.6us``; or the declared ``signal_delay_s``)."""
        if self._delay is None:
            self._delay = self._query_parsed(self.signal_delay_command.format(i=self.decoder_index),
                                             parse_delay_text, "7.6us")
        return self._delay

    def _query_parsed(self, cmd: str, parse: Any, example: str) -> float:
        """``parse(reply)`` of ``cmd``; a reply it cannot read is a garbled reply (InstrumentError)."""
        reply = self.query(cmd)
        try:
            return float(parse(reply))
        except ValueError:
            raise InstrumentError(f"garbled reply {reply[:40]!r} (expected e.g. '{example}')",
                                  instrument=self.name, command=cmd) from None

    def set_decoder(self, prop: str, value: str) -> None:
        """``Set,VeloDec,<i>,<prop>,<value>`` (``Filter``, ``Tracking``), read back: the controller
        ignores an invalid value without a word."""
        self.write(f"Set,VeloDec,{self.decoder_index},{prop},{value}")
        back = self._get(prop)
        if back.lower() != str(value).lower():
            raise InstrumentError(f"{prop} not accepted: asked {value!r}, reads back {back[:40]!r}",
                                  instrument=self.name, command=f"Set,VeloDec,{self.decoder_index},{prop}")
        self.state[prop.lower()] = back

    def snapshot(self) -> dict[str, Any]:
        """The base snapshot plus what decides the record's meaning: range, signal delay, filter,
        tracking and the sensor's signal level at the time."""
        snap = super().snapshot()
        st = snap["state"]
        st["signal_delay_s"] = self.signal_delay_s
        for key, prop, dev in (("filter", "Filter", "VeloDec"), ("tracking", "Tracking", "VeloDec"),
                               ("signal_level", "SignalLevel", "SensorHead")):
            st[key] = self._get(prop, dev)
        return snap

    @property
    def identity(self) -> str:
        if self._identity is None:
            self._identity = self.query(self.identity_command.format(i=self.decoder_index))
        return self._identity

    @property
    def scale_mm_s_per_v(self) -> float:
        """Scale factor in mm/s per V (``Get,VeloDec,<i>,Range``); set with a value in mm/s/V."""
        self._scale = self._query_parsed(f"Get,VeloDec,{self.decoder_index},Range", parse_range_text,
                                         "125mm/s/V")
        return self._scale

    @scale_mm_s_per_v.setter
    def scale_mm_s_per_v(self, value: float) -> None:
        v = float(value)
        if not v > 0:
            raise LimitError(f"velocity range: scale factor must be > 0 mm/s/V, got {v:g}",
                             limit="velocity range")
        if self.ranges_mm_s_per_v is not None and v not in self.ranges_mm_s_per_v:
            raise LimitError(f"velocity range: {v:g} mm/s/V is not a range of decoder "
                             f"{self.decoder_index} "
                             f"(one of {list(self.ranges_mm_s_per_v)}); nothing was sent",
                             limit="velocity range")
        cmd = f"Set,VeloDec,{self.decoder_index},Range,{_fmt_scale(v)}mm/s/V"
        self.write(cmd)
        back = self.scale_mm_s_per_v
        if abs(back - v) > 1e-9 * v:
            raise InstrumentError(f"range not accepted: asked {v:g} mm/s/V, reads back {back:g}",
                                  instrument=self.name, command=cmd)
        self.state["scale_mm_s_per_v"] = v

    def over_range(self) -> bool:
        """True while the decoder reports over-range (see ``over_range_command``)."""
        cmd = self.over_range_command.format(i=self.decoder_index)
        return _parse_bool(self, self.query(cmd), cmd)

    def device_info(self, prop: str = "Range") -> str:
        """``GetDevInfo,VeloDec,<i>,<prop>``: the controller's list of allowed values (raw text)."""
        return self.query(f"GetDevInfo,VeloDec,{self.decoder_index},{prop}")
