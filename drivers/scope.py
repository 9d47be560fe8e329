"""Oscilloscopes: Keysight InfiniiVision and Rigol DS1000Z.

They digitise the vibrometer's analog velocity output and the drive signal.
Waveforms come as IEEE 488.2 definite-length blocks, BYTE (``'B'``) or WORD
(``'H'``: big-endian on InfiniiVision after ``:WAV:BYT MSBF``, little-endian
on the Rigol), parsed by pyvisa's ``query_binary_values`` into numpy arrays,
then scaled from the ten-field preamble
``format, type, points, count, xinc, xorig, xref, yinc, yorig, yref``:

============  ===================================  ==========================
model         volts                                seconds
============  ===================================  ==========================
InfiniiVision ``(d - yref) * yinc + yorig``        ``(i - xref) * xinc + xorig``
DS1000Z       ``(d - yorig - yref) * yinc``        ``(i - xref) * xinc + xorig``
============  ===================================  ==========================

The Rigol returns at most 250 000 bytes per ``:WAV:DATA?``, so long records
are read in chunks with ``:WAV:STAR``/``:WAV:STOP`` (1-based, inclusive);
its RAW mode (the whole memory, not the screen) needs ``:STOP`` first.
"""
from __future__ import annotations

import re
import time
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from labkit.drivers.base import ScpiInstrument, check_choice, check_range
from labkit.errors import InstrumentError, LimitError


@dataclass
class Waveform:
    """One channel's record, scaled to SI units."""

    t_s: np.ndarray
    volts: np.ndarray
    xinc_s: float
    channel: int
    preamble: dict[str, float] = field(default_factory=dict)

    @property
    def fs_hz(self) -> float:
        """Sample rate."""
        return 1.0 / self.xinc_s


class AcquisitionTimeout(InstrumentError):
    """The acquisition did not complete in time: in NORMal sweep, no trigger came."""

    #: what callers test (duck-typed: they need not import the driver)
    no_trigger = True


_PRE_FIELDS = ("format", "type", "points", "count", "xinc", "xorig", "xref", "yinc", "yorig",
               "yref")


class Oscilloscope(ScpiInstrument):
    """Common driver; subclasses give the model's commands, formats and scaling.

    Parameters
    ----------
    channels:
        Number of analog inputs (for validating ``ch``). Default: what the
        identity's model word says (``DSOX3024T``: 4, ``DS1202Z-E``: 2); given,
        it must agree with it.
    max_volts_per_div:
        Refuse vertical scales above this (the scope's own range, default 10 V/div).
    """

    model = "scope"
    err_command = ":SYST:ERR?"
    #: horizontal divisions on screen
    divisions: ClassVar[int] = 10
    #: ``:WAV:PRE?`` format code per format name
    format_codes: ClassVar[dict[str, int]] = {"BYTE": 0, "WORD": 1}
    poll_s: ClassVar[float] = 0.02
    #: The query whose reply says the acquisition is complete (each model sets it).
    _done_command: ClassVar[str]

    connect_on_open = True
    #: The model word of ``*IDN?``: group ``ch`` is the number of analog channels.
    model_pattern: ClassVar[re.Pattern[str]]
    #: What :attr:`model_pattern` accepts, in words (for the error).
    model_words: ClassVar[str]

    def __init__(self, transport, *, name: str | None = None, channels: int | None = None,
                 max_volts_per_div: float = 10.0, **settings: Any) -> None:
        super().__init__(transport, name=name, **settings)
        self.declared_channels = None if channels is None else int(
            check_range("channels", channels, 1, 8))
        self.n_channels = 4 if channels is None else int(channels)
        self.max_volts_per_div = float(max_volts_per_div)
        self.state = {"channels": {}}

    def settings(self) -> dict[str, Any]:
        return {**super().settings(), "channels": self.n_channels,
                "max_volts_per_div": self.max_volts_per_div}

    def identify(self, identity: str) -> tuple[str, int]:
        _, word = self._identity_fields(identity)
        m = self.model_pattern.fullmatch(word.strip().upper())
        if m is None:
            raise self._unknown_model(identity, self.model_words)
        return word.strip(), int(m.group("ch"))

    def identified(self, model: str, channels: int) -> None:
        if self.declared_channels is not None and self.declared_channels != channels:
            from labkit.errors import ConfigError
            raise ConfigError(f"{self.name}: channels = {self.declared_channels} declared, but the "
                              f"{model} has {channels}; nothing else was sent", key="channels",
                              expected=f"{channels} or no setting")
        self.n_channels = channels

    def snapshot(self) -> dict[str, Any]:
        snap = super().snapshot()
        snap.setdefault("connect", {})["channels"] = self.n_channels
        return snap

    def _ch(self, ch: int) -> int:
        return int(check_range("scope channel", ch, 1, self.n_channels))

    def setup_channel(self, ch: int, volts_per_div: float, offset_v: float = 0.0,
                      coupling: str = "DC") -> None:
        """Display channel ``ch`` with ``volts_per_div`` and ``coupling`` (DC/AC), the input
        voltage ``offset_v`` at the screen's vertical centre (on every model: the command that
        puts it there is the model's, see :meth:`_offset_command`)."""
        c = self._ch(ch)
        vdiv = check_range("volts_per_div", volts_per_div, 1e-4, self.max_volts_per_div, "V/div")
        off = check_range("offset_v", offset_v, -1e3, 1e3, "V")
        cp = check_choice("coupling", coupling, ("DC", "AC"))
        self._send_all([f":CHAN{c}:DISP 1", f":CHAN{c}:COUP {cp}", f":CHAN{c}:SCAL {vdiv:.6g}",
                        self._offset_command(c, off)])
        self.state["channels"][str(c)] = {"volts_per_div": vdiv, "offset_v": off, "coupling": cp}

    def _offset_command(self, ch: int, centre_v: float) -> str:
        """The command that puts ``centre_v`` at the screen's centre. InfiniiVision:
        ``:CHANnel<n>:OFFSet`` *is* the centre voltage ("the value represented at center
        screen", 3000 X-Series Programmer's Guide, :CHANnel<n>:OFFSet)."""
        return f":CHAN{ch}:OFFS {centre_v:.6g}"

    def _timebase_command(self, scale_s: float) -> str:
        return f":TIM:SCAL {scale_s:.6g}"

    def set_timebase(self, record_s: float) -> None:
        """Show ``record_s`` seconds across the screen (``divisions`` divisions)."""
        rec = check_range("record_s", record_s, 1e-9, 5e4, "s")
        scale = rec / self.divisions
        self._send_all([self._timebase_command(scale)])
        self.state.update(record_s=rec, time_per_div_s=scale)

    @property
    def has_ext_trigger(self) -> bool:
        """Whether the model has an external trigger input (every InfiniiVision has EXT TRIG)."""
        return True

    def trigger_source_for(self, requested: str | None, drive_channel: int) -> str:
        """The trigger source of a run: ``requested``, or by default the generator's sync on EXT
        where the scope has that input, else the drive itself (``CHAN<drive_channel>``).

        Raises
        ------
        ConfigError
            ``requested`` is EXT and the model has no EXT input (nothing is sent).
        """
        if requested is None:
            return "EXT" if self.has_ext_trigger else f"CHAN{int(drive_channel)}"
        src = str(requested).upper()
        if src == "EXT" and not self.has_ext_trigger:
            from labkit.errors import ConfigError
            raise ConfigError(f"trigger_source = 'EXT', but the {self._model_name()} has no external trigger "
                              "input; nothing was set", key="scope.trigger_source",
                              expected=f"CHAN1..CHAN{self.n_channels} (or no setting: the drive channel; "
                                       "the generator's sync can go into a spare channel)")
        if src.startswith("CHAN") and src[4:].isdigit():
            self._ch(int(src[4:]))          # a channel the scope has (CHAN3 on a DS1202Z-E: refused)
        return src

    def _model_name(self) -> str:
        return self.instrument_model or self.model

    def set_trigger(self, source: str = "CHAN1", level_v: float = 0.0, slope: str = "POS") -> None:
        """Edge trigger on ``source`` (CHANn, EXT where the model has it) at ``level_v``, slope POS/NEG."""
        src = self.trigger_source_for(source, 1)
        if not (src == "EXT" or (src.startswith("CHAN") and src[4:].isdigit())):
            check_choice("trigger source", src, ("CHAN1", "CHAN2", "CHAN3", "CHAN4", "EXT"))
        lev = check_range("trigger level_v", level_v, -1e3, 1e3, "V")
        sl = check_choice("trigger slope", slope, ("POS", "NEG"))
        self._send_all([":TRIG:MODE EDGE", f":TRIG:EDGE:SOUR {src}", f":TRIG:EDGE:LEV {lev:.6g}",
                        f":TRIG:EDGE:SLOP {sl}", ":TRIG:SWE NORM"])
        # In AUTO sweep a scope that sees no edge records anyway (untriggered data, a random phase);
        # in NORMal it waits for the trigger, so a missing sync ends in a timeout, never in a record.
        self._read_back({":TRIG:EDGE:SOUR?": src, ":TRIG:EDGE:SLOP?": sl, ":TRIG:SWE?": "NORM"})
        got = self.query_float(":TRIG:EDGE:LEV?")
        if abs(got - lev) > 1e-6 + 1e-3 * abs(lev) + 0.02 * abs(self._level_resolution(src)):
            raise InstrumentError(f"trigger level reads back {got:g} V, {lev:g} V was set", instrument=self.name,
                                  command=":TRIG:EDGE:LEV?")
        self.state["trigger"] = {"source": src, "level_v": lev, "slope": sl, "sweep": "NORM"}

    def _level_resolution(self, source: str) -> float:
        """The trigger level's step on ``source``: a fraction of its V/div (0 for EXT)."""
        ch = self.state["channels"].get(source[4:]) if source.startswith("CHAN") else None
        return float(ch["volts_per_div"]) if ch else 0.0

    def _read_back(self, expected: dict[str, str]) -> None:
        """Query each setting; InstrumentError naming the first whose reply differs (short forms:
        ``CHANnel1`` answers ``CHAN1``, ``POSitive`` ``POS``)."""
        for cmd, want in expected.items():
            reply = self.query(cmd).strip('"').upper()
            if not (reply == want or want.startswith(reply) and len(reply) >= 3
                    or reply.startswith(want)):
                raise InstrumentError(f"{cmd} answers {reply[:40]!r}, {want} was set", instrument=self.name,
                                      command=cmd)

    def set_averaging(self, count: int) -> None:
        """Average ``count`` triggered records (``count`` 1: normal acquisition); read back.

        Averaging needs a stable trigger (the generator's sync): each record is
        aligned on it, so the response adds up and uncorrelated noise falls by
        about ``sqrt(count)``.
        """
        n = int(check_range("averages", count, 1, 65536))
        cmds = [":ACQ:TYPE NORM"] if n == 1 else [":ACQ:TYPE AVER", self._average_command(n)]
        self._send_all(cmds)
        self._read_back({":ACQ:TYPE?": "NORM" if n == 1 else "AVER"})
        if n > 1:
            ask = self._average_command(n).split()[0] + "?"
            got = self.query_int(ask)
            if got != n:
                raise InstrumentError(f"{ask} answers {got}, {n} was set", instrument=self.name, command=ask)
        self.state["acquisition"] = "NORM" if n == 1 else "AVER"
        self.state["averages"] = n

    def _average_command(self, count: int) -> str:
        return f":ACQ:COUN {count}"

    def set_record_points(self, points: int) -> None:
        """Samples per record (the base model records what its screen holds: nothing to send)."""
        self.state["record_points"] = int(check_range("record points", points, 100, 8e6))

    def set_trigger_at_start(self, record_s: float) -> None:
        """Put the trigger at the record's first sample (the base model keeps its default)."""
        self.state["trigger_at_start_s"] = float(check_range("record_s", record_s, 1e-9, 5e4, "s"))

    #: whether :meth:`set_record_delay` is implemented for the model
    record_delay = False

    def set_record_delay(self, record_s: float, delay_s: float) -> None:
        """Record ``record_s`` seconds starting ``delay_s`` after the trigger (e.g. a burst's settled part)."""
        raise NotImplementedError(f"{self.model}: no delayed record")

    def single(self) -> None:
        """Arm one acquisition (``:SING``)."""
        self.write(":SING")

    def run(self) -> None:
        """Free-running acquisition (``:RUN``)."""
        self.write(":RUN")

    def stop(self) -> None:
        """Stop acquiring (``:STOP``)."""
        self.write(":STOP")

    def _done(self) -> bool:
        raise NotImplementedError

    def wait_done(self, timeout_s: float = 10.0) -> None:
        """Poll until the acquisition is complete; InstrumentError after ``timeout_s``."""
        deadline = time.monotonic() + float(timeout_s)
        while True:
            if self._done():
                return
            if time.monotonic() > deadline:
                raise AcquisitionTimeout(f"acquisition not complete within {timeout_s:g} s "
                                         "(no trigger?)",
                                         instrument=self.name, command=self._done_command)
            time.sleep(self.poll_s)

    def preamble(self) -> dict[str, float]:
        """``:WAV:PRE?`` as a dict of the ten fields (garbled -> InstrumentError)."""
        reply = self.query(":WAV:PRE?")
        parts = reply.split(",")
        try:
            if len(parts) != 10:
                raise ValueError(f"{len(parts)} fields")
            vals = [float(p) for p in parts]
        except ValueError as exc:
            raise InstrumentError(f"garbled preamble {reply[:80]!r} ({exc}; expected 10 numbers)",
                                  instrument=self.name, command=":WAV:PRE?") from None
        pre = dict(zip(_PRE_FIELDS, vals))
        for k in ("format", "type", "points", "count"):
            pre[k] = int(pre[k])
        if pre["points"] <= 0 or not pre["xinc"] > 0 or not pre["yinc"] > 0:
            raise InstrumentError(f"implausible preamble {reply[:80]!r} (points, xinc, yinc > 0)",
                                  instrument=self.name, command=":WAV:PRE?")
        return pre

    def _check_format(self, pre: dict[str, float], fmt: str) -> None:
        if pre["format"] != self.format_codes[fmt]:
            raise InstrumentError(f"preamble format {pre['format']} is not {fmt} "
                                  f"({self.format_codes[fmt]})", instrument=self.name,
                                  command=":WAV:PRE?")

    def read_waveform(self, ch: int, fmt: str = "WORD") -> Waveform:
        """Transfer channel ``ch`` (BYTE or WORD) and scale it to volts and seconds."""
        raise NotImplementedError

    @staticmethod
    def _times(pre: dict[str, float], first: int, n: int) -> np.ndarray:
        i = np.arange(first, first + n, dtype=np.float64)
        return (i - pre["xref"]) * pre["xinc"] + pre["xorig"]


class InfiniiVision(Oscilloscope):
    """Keysight InfiniiVision (2000X/3000T/4000X); WORD is big-endian unsigned (``:WAV:BYT MSBF``).

    Parameters
    ----------
    points:
        ``:WAV:POIN`` value: ``"MAX"`` (default) or a number of points.
    """

    model = "InfiniiVision"
    _done_command = ":OPER:COND?"
    #: DSOX3024T, MSOX4154A, DSOX1102G, EDUX1052G, "DSO-X 2024A" (Agilent): series digit,
    #: two bandwidth digits, the channel count, a letter
    model_pattern = re.compile(r"(?:DSO|MSO|EDU)-?X ?\d\d\d(?P<ch>[24])[A-Z]")
    model_words = "an InfiniiVision model: DSOX/MSOX/EDUX + series, bandwidth, channels (DSOX3024T)"

    def __init__(self, transport, *, name: str | None = None, points: int | str = "MAX",
                 **settings: Any) -> None:
        super().__init__(transport, name=name, **settings)
        self.points = points if str(points).upper() == "MAX" else int(
            check_range("points", points, 100, 8e6))

    def settings(self) -> dict[str, Any]:
        return {**super().settings(), "points": self.points}

    def set_record_points(self, points: int) -> None:
        """Samples per record read back (``:WAV:POIN:MODE RAW``, ``:WAV:POIN n``), sent now; the
        mode is read back (the count may be fewer than asked until a record exists: IV
        :WAVeform:POINts)."""
        n = int(check_range("points", points, 100, 8e6))
        self._send_all([":WAV:POIN:MODE RAW", f":WAV:POIN {n}"])
        self._read_back({":WAV:POIN:MODE?": "RAW"})
        self.points = n
        self.state["record_points"] = n

    def set_trigger_at_start(self, record_s: float) -> None:
        """Trigger at the record's first sample: reference LEFT puts it one division (10 %) in,
        a delay of that much moves it to the start (``:TIM:REF LEFT``, ``:TIM:POS``)."""
        rec = check_range("record_s", record_s, 1e-9, 5e4, "s")
        self._send_all([":TIM:REF LEFT", f":TIM:POS {rec / self.divisions:.6g}"])
        self.state["trigger_at_start_s"] = rec

    record_delay = True

    def set_record_delay(self, record_s: float, delay_s: float) -> None:
        """Record ``record_s`` from ``delay_s`` after the trigger: reference LEFT (one division of
        pre-trigger) and a position of one division plus the delay (``:TIM:REF LEFT``, ``:TIM:POS``)."""
        rec = check_range("record_s", record_s, 1e-9, 5e4, "s")
        d = check_range("delay_s", delay_s, 0.0, 400.0, "s")
        self._send_all([":TIM:REF LEFT", f":TIM:POS {rec / self.divisions + d:.9g}"])
        self.state["record_delay_s"] = d

    def _done(self) -> bool:
        # bit 3 (value 8) of the operation status condition register: "Run" (acquiring)
        return not (self.query_int(self._done_command) & 8)

    def read_waveform(self, ch: int, fmt: str = "WORD") -> Waveform:
        c = self._ch(ch)
        f = check_choice("waveform format", fmt, ("BYTE", "WORD"))
        cmds = [f":WAV:SOUR CHAN{c}", f":WAV:FORM {f}"]
        if f == "WORD":
            cmds += [":WAV:BYT MSBF", ":WAV:UNS 1"]
        cmds += [":WAV:POIN:MODE RAW", f":WAV:POIN {self.points}"]
        self._send_all(cmds)
        pre = self.preamble()
        self._check_format(pre, f)
        data = self.query_binary(":WAV:DATA?", "H" if f == "WORD" else "B", big_endian=True)
        if data.size != pre["points"]:
            raise InstrumentError(f"block holds {data.size} points, preamble says {pre['points']}",
                                  instrument=self.name, command=":WAV:DATA?")
        volts = (data.astype(np.float64) - pre["yref"]) * pre["yinc"] + pre["yorig"]
        return Waveform(self._times(pre, 0, data.size), volts, pre["xinc"], c, pre)


#: DS1000Z Programming Guide, :ACQuire:MDEPth: depths per number of channels switched on
MDEP_DEPTHS = {1: (12_000, 120_000, 1_200_000, 12_000_000, 24_000_000),
               2: (6_000, 60_000, 600_000, 6_000_000, 12_000_000),
               4: (3_000, 30_000, 300_000, 3_000_000, 6_000_000)}
#: :ACQuire:AVERages: 2^n, n = 1..10
MDEP_AVERAGES = tuple(2 ** k for k in range(1, 11))


class RigolDS1000Z(Oscilloscope):
    """Rigol DS1000Z (DS1054Z, DS1104Z...): 12 divisions, RAW chunked reads.

    Parameters
    ----------
    max_block_bytes:
        Largest ``:WAV:DATA?`` block the scope sends (250 000).
    """

    model = "DS1000Z"
    divisions = 12
    #: DS1054Z, DS1104Z, MSO1104Z, DS1074Z-S PLUS, DS1202Z-E: bandwidth digits, channel count, Z
    model_pattern = re.compile(r"(?:DS|MSO)1\d\d(?P<ch>[24])Z(?:-E|-S|-S PLUS| PLUS)?")
    model_words = "a DS1000Z model: DS1054Z, DS1074Z, DS1104Z, MSO1104Z, DS1202Z-E ..."
    #: DS1000Z Programming Guide, :WAVeform:PREamble?: <format> 0 (BYTE), 1 (WORD) or 2 (ASC)
    format_codes = {"BYTE": 0, "WORD": 1}
    _done_command = ":TRIG:STAT?"

    def __init__(self, transport, *, name: str | None = None, max_block_bytes: int = 250_000,
                 **settings: Any) -> None:
        super().__init__(transport, name=name, **settings)
        self.max_block_bytes = int(check_range("max_block_bytes", max_block_bytes, 2, 250_000))

    def settings(self) -> dict[str, Any]:
        return {**super().settings(), "max_block_bytes": self.max_block_bytes}

    #: the four-channel DS1000Z models (no EXT TRIG input): a config that names one is refused before
    #: anything is sent when it asks for EXT (:mod:`labkit.experiments.config`)
    NO_EXT_MODELS = ("DS1054Z", "DS1074Z", "DS1104Z")

    @property
    def has_ext_trigger(self) -> bool:
        """Only the two-channel DS1000Z-E models (DS1102Z-E, DS1202Z-E) have an EXT TRIG input: the
        four-channel DS1000Z's edge trigger sources are D0-D15, CHANnel1-4 and AC (DS1000Z
        Programming Guide, :TRIGger:EDGe:SOURce)."""
        return self.n_channels == 2

    def _timebase_command(self, scale_s: float) -> str:
        return f":TIM:MAIN:SCAL {scale_s:.6g}"

    def _average_command(self, count: int) -> str:
        """``:ACQuire:AVERages``: a power of two from 2 to 1024 (DS1000Z Programming Guide)."""
        if count not in MDEP_AVERAGES:
            raise LimitError(f"averages = {count}: the DS1000Z averages 2, 4, ... 1024 records; "
                             "nothing was sent", limit="averages")
        return f":ACQ:AVER {count}"

    def set_record_points(self, points: int) -> None:
        """Memory depth (``:ACQuire:MDEPth``): the smallest the guide lists for the channels on
        (1: 12k..24M, 2: 6k..12M, 3-4: 3k..6M) holding ``points``; set while running; read back."""
        n = int(check_range("record points", points, 100, 24e6))
        # the channels switched on, as the scope has them (one left on from before counts too)
        on = max(1, sum(self.query(f":CHAN{c}:DISP?").strip().upper() in ("1", "ON")
                        for c in range(1, self.n_channels + 1)))
        depths = MDEP_DEPTHS[1 if on == 1 else 2 if on == 2 else 4]
        depth = next((d for d in depths if d >= n), depths[-1])
        self.write(":RUN")          # the depth can only be changed while the scope runs
        self._send_all([f":ACQ:MDEP {depth}"])
        got = self.query_int(":ACQ:MDEP?")
        if got != depth:
            raise InstrumentError(f":ACQ:MDEP? answers {got}, {depth} was set", instrument=self.name,
                                  command=":ACQ:MDEP?")
        self.state["record_points"] = depth

    def _offset_command(self, ch: int, centre_v: float) -> str:
        """The DS1000Z's ``:CHANnel<n>:OFFSet`` is added to the signal on screen: the screen's
        centre shows ``-OFFSet`` (DS1000Z Programming Guide: the edge trigger level ranges over
        ``(-5 x VerticalScale - OFFSet) to (5 x VerticalScale - OFFSet)``, i.e. about
        ``-OFFSet``; and ``:WAVeform:PREamble?`` volts ``(code - YORigin - YREFerence) x
        YINCrement`` give ``-YORigin x YINCrement`` at the centre code YREFerence). So the
        centre voltage is sent negated."""
        return f":CHAN{ch}:OFFS {0.0 - centre_v:.6g}"

    record_delay = True

    def set_record_delay(self, record_s: float, delay_s: float) -> None:
        """Record ``record_s`` from ``delay_s`` after the trigger: the main offset is the time of the
        screen's centre after the trigger (``:TIM:MAIN:OFFS``)."""
        rec = check_range("record_s", record_s, 1e-9, 5e4, "s")
        d = check_range("delay_s", delay_s, 0.0, 400.0, "s")
        self._send_all([f":TIM:MAIN:OFFS {rec / 2 + d:.9g}"])
        self.state["record_delay_s"] = d

    def _done(self) -> bool:
        return self.query(self._done_command).upper() == "STOP"

    def read_waveform(self, ch: int, fmt: str = "WORD") -> Waveform:
        c = self._ch(ch)
        f = check_choice("waveform format", fmt, ("BYTE", "WORD"))
        self.write(":STOP")      # RAW mode reads the memory, which must not change under us
        self._send_all([f":WAV:SOUR CHAN{c}", ":WAV:MODE RAW", f":WAV:FORM {f}"])
        pre = self.preamble()
        self._check_format(pre, f)
        width = 2 if f == "WORD" else 1
        per_read = self.max_block_bytes // width
        n = int(pre["points"])
        parts = []
        start = 1
        while start <= n:
            stop = min(start + per_read - 1, n)
            self.write(f":WAV:STAR {start}")
            self.write(f":WAV:STOP {stop}")
            chunk = self.query_binary(":WAV:DATA?", "H" if width == 2 else "B", big_endian=False)
            if chunk.size != stop - start + 1:
                raise InstrumentError(f"block holds {chunk.size} points, asked for "
                                      f"{start}..{stop} ({stop - start + 1})", instrument=self.name,
                                      command=":WAV:DATA?")
            parts.append(chunk)
            start = stop + 1
        data = np.concatenate(parts)
        if width == 2:
            data = data & 0xFF      # WORD: only the low byte carries the 8-bit sample
        volts = (data.astype(np.float64) - pre["yorig"] - pre["yref"]) * pre["yinc"]
        return Waveform(self._times(pre, 0, data.size), volts, pre["xinc"], c, pre)
