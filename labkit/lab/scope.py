"""A simulated Keysight InfiniiVision (4 channels) on a raw SCPI socket.

Acquisitions happen in real time: ``:SINGle`` or ``:DIGitize`` arms the scope,
it waits for its pre-trigger time, triggers (edge on ``CHANnel1``, or the
generator's sync on ``EXTernal``: phase zero of a sine, the start of a sweep
or burst, a ``*TRG``), and the record is complete ``range x (1 - reference)``
after the trigger. A background thread computes the record (numpy) while the
scope "acquires", so ``:WAVeform:DATA?`` only encodes and sends it.

``:WAVeform:FORMat BYTE|WORD|ASCii``, ``:WAVeform:POINts`` (at most 62 500
in ``:POINts:MODE NORMal``, 8 M in ``RAW``/``MAXimum``),
``:WAVeform:PREamble?`` (ten fields), ``:WAVeform:DATA?`` (an IEEE 488.2
definite-length block ``#8...``), ``:WAVeform:BYTeorder``,
``:WAVeform:UNSigned``. Volts = (code - yreference) * yincrement + yorigin,
where the codes span 10 divisions about the channel offset (codes beyond are
clipped, as the ADC clips).
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from labkit.lab.scpi import Call, ScpiError, SimScpiInstrument, parse_bool, parse_enum, parse_number

NORMAL_MAX_POINTS = 62_500
RAW_MAX_POINTS = 8_000_000
AUTO_TRIGGER_S = 0.05
MAX_SRATE_SA_S = 5e9


#: :MEASure queries answered (IV ":MEASure Commands"; a signal without edges answers 9.9E37)
MEASUREMENTS = ("VPP", "VAMPlitude", "VRMS", "VAVerage", "VMAX", "VMIN", "FREQuency", "PERiod")


def measure(item: str, volts: np.ndarray, dt_s: float) -> float:
    """One of :data:`MEASUREMENTS` on a record (``dt_s`` between samples)."""
    key = item.upper()[:4]
    if key in ("VPP", "VAMP"):
        return float(np.ptp(volts))
    if key == "VRMS":
        return float(np.sqrt(np.mean(volts ** 2)))
    if key == "VAVE":
        return float(np.mean(volts))
    if key in ("VMAX", "VMIN"):
        return float(np.max(volts) if key == "VMAX" else np.min(volts))
    mid = (np.max(volts) + np.min(volts)) / 2
    rising = np.flatnonzero((volts[:-1] < mid) & (volts[1:] >= mid))
    if len(rising) < 2 or np.ptp(volts) <= 0:
        return 9.9e37
    period = (rising[-1] - rising[0]) * dt_s / (len(rising) - 1)
    return float(1 / period if key == "FREQ" else period)


def screen_png(width: int = 800, height: int = 480) -> bytes:
    """The screen as a PNG (a blank grey graticule: the lab draws no traces)."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    row = b"\x00" + b"\x20" * width
    body = zlib.compress(row * height, 9)
    head = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", head) + chunk(b"IDAT", body) + chunk(b"IEND", b"")


# render(t_abs, rng, channels) -> {channel: volts}: the lab's physics, frozen at one moment
def yes_no(value: object) -> str:
    """A boolean reply: ``1`` or ``0``."""
    return "1" if value else "0"


def _label(text: str) -> str:
    """A channel label: a quoted string of at most 10 characters, kept upper-cased (as the scope shows it)."""
    text = text.strip()
    if len(text) < 2 or text[0] != text[-1] or text[0] not in "\"'":
        raise ScpiError(-151, "Invalid string data")
    body = text[1:-1]
    if len(body) > 10:
        raise ScpiError(-150, "String data error;label longer than 10 characters")
    return '"' + body.upper() + '"'


RenderFn = Callable[[np.ndarray, np.random.Generator, tuple[int, ...]], dict[int, np.ndarray]]
# signals() -> a RenderFn for the lab's present state; sync(source, t_min) -> trigger time or None
SignalFn = Callable[[], RenderFn]
SyncFn = Callable[[str, float], float | None]


@dataclass
class Acquisition:
    """One record: its geometry, the physics frozen at its trigger, and its digitised volts.

    The record is the full memory depth, but the volts are computed per
    decimation step (``volts[step][channel]``): a transfer of fewer points
    reads every ``step``-th sample, and only what is transferred is ever
    computed. The eager step is the one the transfer settings ask for when the
    acquisition completes, so the usual transfer only encodes and sends.
    """

    points: int
    xinc_s: float
    xorig_s: float
    t_arm: float
    t_trig: float | None = None
    channels: tuple[int, ...] = ()
    seed: tuple[int, ...] = ()
    render: RenderFn | None = None
    volts: dict[int, dict[int, np.ndarray]] = field(default_factory=dict)
    done: threading.Event = field(default_factory=threading.Event)
    lock: threading.Lock = field(default_factory=threading.Lock)
    cancelled: bool = False
    error: str | None = None
    averages: int = 1
    t_trigs: tuple[float, ...] = ()

    def _render_at(self, idx: np.ndarray, step: int) -> dict[int, np.ndarray]:
        """The record's samples ``idx``: one trigger's, or the mean over the averaged triggers."""
        assert self.render is not None and self.t_trig is not None
        trigs = self.t_trigs or (self.t_trig,)
        total: dict[int, np.ndarray] = {}
        for k, t0 in enumerate(trigs):
            rng = np.random.default_rng([*self.seed, step] if k == 0 else [*self.seed, step, k])
            for ch, v in self.render(t0 + self.xorig_s + self.xinc_s * idx, rng, self.channels).items():
                total[ch] = total[ch] + v if ch in total else v
        return {ch: v / len(trigs) for ch, v in total.items()}

    def get(self, step: int) -> dict[int, np.ndarray]:
        """Every ``step``-th sample of the record, per channel (computed once)."""
        with self.lock:
            if step not in self.volts:
                if self.render is None or self.t_trig is None:
                    self.volts[step] = {}
                else:
                    self.volts[step] = self._render_at(np.arange(0, self.points, step), step)
            return self.volts[step]


class SimInfiniiVision(SimScpiInstrument):
    name = "scope"
    idn = "KEYSIGHT TECHNOLOGIES,DSOX3024T,MY5842LAB2,07.50.2021102830"
    #: ":WAVeform:DATA? ... the block header "#800001000" would be sent" (3000 X-Series
    #: Programmer's Guide, :WAVeform Commands, "Data Format for Transfer")
    block_digits = 8
    suffix_limits = {"CHAN": 4}
    query_params_default = False

    def fnum(self, value: float) -> str:
        """An NR3 reply with 13 significant digits, ``+1.000000000000E+00``: what a DSOX1102G
        (firmware 01.01.2016092800) answers to ``:TIMebase:POSition?`` after ``:TIMebase:POSition
        1`` (PyMeasure's with-device test, tests/instruments/keysight/test_keysightDSOX1102G.py,
        test_autoscale). The Programmer's Guide gives the values, not their digits."""
        return f"{value:+.12E}"

    def __init__(self, signals: SignalFn, sync: SyncFn, seed: int = 0,
                 clock: Callable[[], float] = time.monotonic, memory_points: int = 1_000_000) -> None:
        self.signals = signals
        self.memory_points = int(memory_points)
        self.sync = sync
        self.seed = seed
        self.clock = clock
        self.acq: Acquisition | None = None
        self.n_acq = 0
        self.run_state = "RUN"
        self.triggered = False
        self._cond = threading.Condition()
        self.forced = False     # :TRIGger:FORCe / :TFORce: the armed acquisition triggers now
        self.trig_levels: dict[str, float] = {}
        super().__init__()

    # -- settings -------------------------------------------------------------------------------
    def build(self) -> None:
        pos = lambda lo, hi: (lambda t: self.num(t, "", lo, hi))  # noqa: E731
        self.setting(":CHANnel#:SCALe", "scale", 1.0, lambda t: self.num(t, "V", 1e-3, 50.0), self.fnum, True)
        self.setting(":CHANnel#:OFFSet", "offset", 0.0, lambda t: self.num(t, "V", -400.0, 400.0), self.fnum, True)
        self.setting(":CHANnel#:COUPling", "coupling", "DC", lambda t: parse_enum(t, ["DC", "AC"]), str, True)
        self.setting(":CHANnel#:DISPlay", "display", False, parse_bool, lambda v: "1" if v else "0", True)
        self.settings["display"][1] = True   # power-on: channel 1 only
        self.setting(":CHANnel#:PROBe", "probe", 1.0, pos(1e-3, 1e4), self.fnum, True)
        self.setting(":CHANnel#:IMPedance", "impedance", "ONEM", lambda t: parse_enum(t, ["ONEMeg", "FIFTy"]),
                     str, True)
        self.setting(":CHANnel#:BWLimit", "bwlimit", False, parse_bool, lambda v: "1" if v else "0", True)
        self.add(":CHANnel#:RANGe", set=lambda c: self._chan_range(c), query=lambda c: self.fnum(
            8 * self.get("scale", self._ch(c))))
        self.setting(":TIMebase:RANGe", "range", 1e-3, lambda t: self.num(t, "S", 2e-8, 500.0), self.fnum)
        self.add(":TIMebase:SCALe", set=lambda c: self.settings.__setitem__(
            "range", 10 * self.num(c.one(), "S", 2e-9, 50.0)), query=lambda c: self.fnum(self.get("range") / 10))
        self.setting(":TIMebase:POSition", "position", 0.0, lambda t: self.num(t, "S", -500.0, 500.0), self.fnum)
        self.setting(":TIMebase:REFerence", "reference", "CENT",
                     lambda t: parse_enum(t, ["LEFT", "CENTer", "RIGHt"]), str)
        self.setting(":TIMebase:MODE", "tb_mode", "MAIN", lambda t: parse_enum(t, ["MAIN", "WINDow", "XY", "ROLL"]),
                     str)
        self.setting(":ACQuire:TYPE", "acq_type", "NORM",
                     lambda t: parse_enum(t, ["NORMal", "AVERage", "HRESolution", "PEAK"]), str)
        self.setting(":ACQuire:COUNt", "acq_count", 8, lambda t: int(self.num(t, "", 1, 65536)), self.fmt_int)
        self.setting(":TRIGger:MODE", "trig_mode", "EDGE", lambda t: parse_enum(t, ["EDGE", "GLITch", "PATTern"]), str)
        self.setting(":TRIGger[:EDGE]:SOURce", "trig_source", "CHAN1",
                     lambda t: parse_enum(t, ["CHANnel1", "CHANnel2", "CHANnel3", "CHANnel4", "EXTernal", "LINE"]),
                     str)
        self.add(":TRIGger[:EDGE]:LEVel", set=self._set_trig_level, query=self._trig_level_query,
                 query_params=True)
        self.setting(":TRIGger[:EDGE]:SLOPe", "trig_slope", "POS",
                     lambda t: parse_enum(t, ["POSitive", "NEGative", "EITHer", "ALTernate"]), str)
        self.setting(":TRIGger:SWEep", "trig_sweep", "AUTO", lambda t: parse_enum(t, ["AUTO", "NORMal"]), str)
        self.setting(":WAVeform:SOURce", "wav_source", "CHAN1",
                     lambda t: parse_enum(t, ["CHANnel1", "CHANnel2", "CHANnel3", "CHANnel4"]), str)
        self.setting(":WAVeform:FORMat", "wav_format", "BYTE", lambda t: parse_enum(t, ["BYTE", "WORD", "ASCii"]),
                     lambda v: "ASC" if v == "ASC" else v)
        self.setting(":WAVeform:POINts:MODE", "points_mode", "NORM",
                     lambda t: parse_enum(t, ["NORMal", "MAXimum", "RAW"]), str)
        self.add(":WAVeform:POINts", set=self._set_points, query=lambda c: self.fmt_int(self._scaling()[5]))
        self.setting(":WAVeform:BYTeorder", "byteorder", "MSBF", lambda t: parse_enum(t, ["MSBFirst", "LSBFirst"]),
                     str)
        self.setting(":WAVeform:UNSigned", "unsigned", True, parse_bool, lambda v: "1" if v else "0")
        self.add(":WAVeform:PREamble", query=lambda c: self._preamble())
        self.add(":WAVeform:DATA", query=lambda c: self._data())
        self.add(":WAVeform:XINCrement", query=lambda c: self.fnum(self._scaling()[0]))
        self.add(":WAVeform:XORigin", query=lambda c: self.fnum(self._scaling()[1]))
        self.add(":WAVeform:YINCrement", query=lambda c: self.fnum(self._scaling()[2]))
        self.add(":WAVeform:YORigin", query=lambda c: self.fnum(self._scaling()[3]))
        self.add(":WAVeform:YREFerence", query=lambda c: self.fmt_int(self._scaling()[4]))
        self.add(":ACQuire:POINts", query=lambda c: self.fmt_int(self._last_acq().points))
        self.add(":ACQuire:SRATe", query=lambda c: self.fnum(self._record_geometry()[0] / self.get("range")))
        self.add(":DIGitize", set=self._digitize)
        self.add(":TRIGger:FORCe", set=lambda c: self._force())
        self.add(":SINGle", set=lambda c: self._arm("SING"))
        self.add(":RUN", set=lambda c: self._run())
        self.add(":STOP", set=lambda c: self._stop())
        self.add(":AUToscale", set=lambda c: None)
        self.add(":RSTate", query=lambda c: self.run_state if self.run_state != "SING" or not self._done()
                 else "STOP")
        self.add(":ASTate", query=lambda c: self._astate())
        self.add(":TER", query=lambda c: self._ter())
        self.add(":OPERegister:CONDition", query=lambda c: self.fmt_int(0 if self._stopped() else 8))
        self.add(":OPERegister[:EVENt]", query=lambda c: self.fmt_int(0 if self._stopped() else 8))
        self._build_more()

    def _build_more(self) -> None:
        """Documented commands third-party drivers send (PyMeasure's KeysightDSOX1102G, QCoDeS):
        stored, answered, and back to the programmer's guide defaults after ``*RST``."""
        self.setting(":CHANnel#:INVert", "invert", False, parse_bool, yes_no, True)
        self.labels: dict[int, str] = {}
        self.add(":CHANnel#:LABel", set=lambda c: self.labels.__setitem__(self._ch(c), _label(c.one())),
                 query=lambda c: self.labels.get(self._ch(c), f'"{self._ch(c)}"'))
        self.setting(":CHANnel#:UNITs", "units", "VOLT", lambda t: parse_enum(t, ["VOLT", "AMPere"]), str, True)
        self.setting(":CHANnel#:PROBe:SKEW", "skew", 0.0, lambda t: self.num(t, "S", -100e-9, 100e-9), self.fnum,
                     True)
        self.setting(":CHANnel#:PROBe:STYPe", "stype", "SING", lambda t: parse_enum(t, ["DIFFerential", "SINGle"]),
                     str, True)
        self.setting(":CHANnel#:VERNier", "vernier", False, parse_bool, yes_no, True)
        self.add(":CHANnel#", query=self._channel_summary)
        self.add(":TIMebase", query=lambda c: self._timebase_summary())
        self.add(":TIMebase:MAIN:RANGe", set=lambda c: self.settings.__setitem__(
            "range", self.num(c.one(), "S", 2e-8, 500.0)), query=lambda c: self.fnum(self.get("range")))
        self.add(":TIMebase:MAIN:SCALe", set=lambda c: self.settings.__setitem__(
            "range", 10 * self.num(c.one(), "S", 2e-9, 50.0)), query=lambda c: self.fnum(self.get("range") / 10))
        self.setting(":ACQuire:MODE", "acq_mode", "RTIM",
                     lambda t: parse_enum(t, ["RTIMe", "ETIMe", "SEGMented"]), str)
        self.add(":WAVeform:XREFerence", query=lambda c: self.fmt_int(0))
        self.add(":WAVeform:COUNt", query=lambda c: self.fmt_int(
            self.get("acq_count") if self.get("acq_type") == "AVER" else 1))
        self.add(":WAVeform:TYPE", query=lambda c: {"NORM": "NORM", "PEAK": "PEAK", "AVER": "AVER",
                                                     "HRES": "HRES"}[self.get("acq_type")])
        self.add(":WAVeform:VIEW", set=lambda c: parse_enum(c.one(), ["MAIN"]), query=lambda c: "MAIN")
        self.add(":SYSTem:PRESet", set=lambda c: self.reset())
        self.setting(":TRIGger:HFReject", "hf_reject", False, parse_bool, yes_no)
        self.setting(":TRIGger:NREJect", "n_reject", False, parse_bool, yes_no)
        self.setting(":TRIGger[:EDGE]:COUPling", "trig_coupling", "DC",
                     lambda t: parse_enum(t, ["AC", "DC", "LFReject"]), str)
        self.setting(":TRIGger:HOLDoff", "holdoff", 40e-9, lambda t: self.num(t, "S", 40e-9, 10.0), self.fnum)
        self.setting(":DISPlay:LABel", "display_label", False, parse_bool, yes_no)
        self._build_common()

    # -- measurements, set-ups, the screen, saved states -----------------------------------------
    def _build_common(self) -> None:
        """IV ":MEASure Commands" (VPP, VAMPlitude, VRMS, VAVerage, FREQuency, PERiod: on the
        latest record), ":SYSTem:SETup" (a definite-length block holding the set-up; sent back, it
        restores it), ":DISPlay:DATA?" (the screen as a PNG block), 488.2 ``*SAV``/``*RCL``."""
        for item in MEASUREMENTS:
            self.add(f":MEASure:{item}", query=self._measure_query(item), query_params=True)
        self.add(":SYSTem:SETup", set=self._set_setup, query=lambda c: self.block(self._setup_bytes()))
        self.add(":DISPlay:DATA", query=lambda c: self.block(screen_png()), query_params=True)
        self.saved: dict[int, bytes] = {}
        self.add("*SAV", set=lambda c: self.saved.__setitem__(self._slot(c), self._setup_bytes()))
        self.add("*RCL", set=lambda c: self._load_setup(self.saved.get(self._slot(c))))

    def _measure_query(self, item: str) -> Callable[[Call], str]:
        return lambda c: self.fnum(self._measure(item, c))

    def _slot(self, c: Call) -> int:
        return int(self.num(c.one(), "", 0, 9))

    def _setup_bytes(self) -> bytes:
        import json

        return json.dumps({"settings": self.settings, "levels": self.trig_levels},
                          default=lambda o: sorted(o) if isinstance(o, set) else str(o)).encode()

    def _set_setup(self, c: Call) -> None:
        text = c.one()
        raw = text.encode("latin-1")
        if not raw.startswith(b"#") or not raw[1:2].isdigit() or raw[1:2] == b"0":
            raise ScpiError(-161, "Invalid block data")
        n = int(raw[1:2])
        self._load_setup(raw[2 + n:])

    def _load_setup(self, data: bytes | None) -> None:
        import json

        if data is None:
            raise ScpiError(-221, "Settings conflict;nothing stored there")
        try:
            saved = json.loads(data)
            for key, value in saved["settings"].items():
                if key not in self.setting_defaults:
                    continue
                per_suffix = self.setting_defaults[key][1]
                self.settings[key] = {int(k): v for k, v in value.items()} if per_suffix else value
            self.trig_levels = {str(k): float(v) for k, v in saved["levels"].items()}
        except (ValueError, KeyError, AttributeError, TypeError):
            raise ScpiError(-161, "Invalid block data;not a set-up of this scope") from None

    def _measure(self, item: str, c: Call) -> float:
        """One measurement on the latest record of ``c``'s source (default: channel 1)."""
        ch = 1
        if c.params:
            ch = int(parse_enum(c.one(), ["CHANnel1", "CHANnel2", "CHANnel3", "CHANnel4"])[-1])
        acq = self._last_acq()
        volts = acq.get(max(1, acq.points // 10_000)).get(ch)
        if volts is None or volts.size < 4:
            raise ScpiError(-221, "Settings conflict;source channel is off")
        return measure(item, volts, acq.xinc_s * max(1, acq.points // 10_000))

    def _channel_summary(self, c: Call) -> str:
        """``:CHANnel<n>?``: every channel setting, with headers (the form PyMeasure parses)."""
        n = self._ch(c)
        label = self.labels.get(n, f'"{n}"')
        return (f":CHAN{n}:RANG {self.fnum(8 * self.get('scale', n))};OFFS {self.fnum(self.get('offset', n))};"
                f"COUP {self.get('coupling', n)};IMP {self.get('impedance', n)};"
                f"DISP {int(bool(self.get('display', n)))};BWL {int(self.get('bwlimit', n))};"
                f"INV {int(self.get('invert', n))};LAB {label};UNIT {self.get('units', n)};"
                f"PROB {self.fnum(self.get('probe', n))};PROB:SKEW {self.fnum(self.get('skew', n))};"
                f"STYP {self.get('stype', n)}")

    def _timebase_summary(self) -> str:
        """``:TIMebase?``: mode, reference, range and position, with headers."""
        return (f":TIM:MODE {self.get('tb_mode')};REF {self.get('reference')};"
                f"MAIN:RANG {self.fnum(self.get('range'))};POS {self.fnum(self.get('position'))}")

    def trigger_level(self, source: str | None = None) -> float:
        """The edge trigger level (V) of ``source`` (default: the trigger source now)."""
        src = source or self.get("trig_source")
        return float(self.trig_levels.get(src, 0.0))

    def _set_trig_level(self, c: Call) -> None:
        if not c.params:
            raise ScpiError(-109)
        if len(c.params) > 2:
            raise ScpiError(-108)
        src = self.get("trig_source")
        if len(c.params) == 2:
            src = parse_enum(c.params[1], ["CHANnel1", "CHANnel2", "CHANnel3", "CHANnel4", "EXTernal"])
        self.trig_levels[src] = self.num(c.params[0], "V", -400.0, 400.0)

    def _trig_level_query(self, c: Call) -> str:
        src = None
        if c.params:
            src = parse_enum(c.one(), ["CHANnel1", "CHANnel2", "CHANnel3", "CHANnel4", "EXTernal"])
        return self.fnum(self.trigger_level(src))

    def reset(self) -> None:
        super().reset()
        self.trig_levels = {}
        self.labels = {}
        self._cancel()
        self.acq = None
        self.run_state = "RUN"
        self.settings["points"] = 1000
        self.settings["display"] = {1: True}

    def _ch(self, c: Call) -> int:
        n = c.suffix()
        if n not in (1, 2, 3, 4):
            raise ScpiError(-113, "Undefined header;channel suffix")
        return n

    def _chan_range(self, c: Call) -> None:
        self.settings["scale"][self._ch(c)] = self.num(c.one(), "V", 8e-3, 400.0) / 8

    def _set_points(self, c: Call) -> None:
        word = c.one().strip().upper()
        if word in ("MAX", "MAXIMUM"):
            self.settings["points"] = RAW_MAX_POINTS
        else:
            self.settings["points"] = int(self.num(word, "", 100, RAW_MAX_POINTS))

    # -- acquisition --------------------------------------------------------------------------
    def _record_geometry(self) -> tuple[int, float, float]:
        """Acquisition depth: the whole memory, unless the maximum sample rate limits it.

        As on the instrument, the depth does not depend on ``:WAVeform:POINts``:
        a transfer decimates the record (to at most 62 500 points in NORMal mode).
        """
        rng = self.get("range")
        points = int(min(self.memory_points, max(100, rng * MAX_SRATE_SA_S)))
        ref = {"LEFT": 0.1, "CENT": 0.5, "RIGH": 0.9}[self.get("reference")]
        xinc = rng / points
        xorig = self.get("position") - ref * rng
        return int(points), xinc, xorig

    def _arm(self, state: str) -> Acquisition:
        self._cancel()
        self.forced = False
        points, xinc, xorig = self._record_geometry()
        self.n_acq += 1
        acq = Acquisition(points, xinc, xorig, t_arm=self.clock(), channels=self._displayed(),
                          seed=(self.seed, self.n_acq), averages=self.averages())
        self.acq = acq
        self.run_state = state
        source = self.get("trig_source")
        sweep_mode = self.get("trig_sweep")
        threading.Thread(target=self._acquire, args=(acq, source, sweep_mode), daemon=True,
                         name="lab-scope-acq").start()
        return acq

    def averages(self) -> int:
        """Records one acquisition averages (``:ACQuire:TYPE AVERage``, ``:ACQuire:COUNt``)."""
        return int(self.get("acq_count")) if self.get("acq_type") == "AVER" else 1

    def _step_for(self, acq: Acquisition | None) -> int:
        """Decimation step a transfer with today's ``:WAVeform:POINts`` settings uses."""
        # RAW/MAXimum reach the whole acquisition record only when the scope is stopped; a
        # running scope serves the measurement record (3000 X-Series Programmer's Guide,
        # :WAVeform:POINts:MODE)
        raw = self.get("points_mode") != "NORM" and self._stopped()
        want = min(self.settings.get("points", 1000), RAW_MAX_POINTS if raw else NORMAL_MAX_POINTS)
        depth = acq.points if acq is not None else self._record_geometry()[0]
        # never more points than asked: "the number of points actually transferred may be fewer"
        return max(1, -(-depth // max(1, want)))

    def _force(self) -> None:
        """A forced trigger: an armed acquisition that waits for its trigger takes it now."""
        if self.acq is not None and not self.acq.done.is_set() and self.acq.t_trig is None:
            self.forced = True

    def _acquire(self, acq: Acquisition, source: str, sweep_mode: str) -> None:
        """Wait for a trigger in real time, then for the post-trigger time; compute the record.

        Averaging (``:ACQuire:TYPE AVERage``) takes ``acq.averages`` records, each armed
        when the one before it is complete and aligned on its own trigger."""
        try:
            t_min = acq.t_arm + max(0.0, -acq.xorig_s)  # the pre-trigger part must be filled first
            trigs: list[float] = []
            while len(trigs) < acq.averages:
                t_trig = self._wait_trigger(acq, source, sweep_mode, t_min)
                if t_trig is None:
                    return
                if not trigs:
                    acq.t_trig = t_trig
                trigs.append(t_trig)
                t_end = t_trig + acq.xorig_s + acq.points * acq.xinc_s
                while not acq.cancelled and self.clock() < t_end:
                    time.sleep(min(0.01, max(0.0, t_end - self.clock())))
                if acq.cancelled:
                    return
                t_min = t_end + max(0.0, -acq.xorig_s)
            acq.t_trigs = tuple(trigs)
            acq.render = self.signals()
            acq.get(self._step_for(acq))     # digitise now what the next transfer will ask for
            self.triggered = True
        except Exception as exc:  # keep the scope answering; the transfer reports the error
            acq.error = f"{type(exc).__name__}: {exc}"
        finally:
            acq.done.set()
            with self._cond:
                self._cond.notify_all()

    def _wait_trigger(self, acq: Acquisition, source: str, sweep_mode: str, t_min: float) -> float | None:
        """The trigger time (None when cancelled): an edge of ``source``; a forced trigger; in AUTO
        sweep, no edge within :data:`AUTO_TRIGGER_S` triggers anyway (an untriggered record)."""
        while not acq.cancelled:
            now = self.clock()
            t_trig = max(now, t_min) if self.forced else self.sync(source, t_min)
            if t_trig is None and sweep_mode == "AUTO" and now >= t_min + AUTO_TRIGGER_S:
                t_trig = now   # auto trigger: no edge came
            if t_trig is not None:
                return t_trig
            time.sleep(0.002)
        return None

    def _displayed(self) -> tuple[int, ...]:
        """Channels switched on: only these are digitised (and cost time)."""
        return tuple(n for n in (1, 2, 3, 4) if self.get("display", n))

    def _cancel(self) -> None:
        if self.acq is not None and not self.acq.done.is_set():
            self.acq.cancelled = True
            self.acq.done.wait(2.0)

    def _done(self) -> bool:
        return self.acq is not None and self.acq.done.is_set() and not self.acq.cancelled

    def _stopped(self) -> bool:
        if self.run_state == "STOP":
            return True
        return self.run_state == "SING" and self._done()

    def _digitize(self, c: Call) -> None:
        acq = self._arm("SING")
        # :DIGitize holds off every later command until the record is complete; the lock
        # is released while waiting so the scope's other connections are not frozen
        self.lock.release()
        try:
            acq.done.wait()
        finally:
            self.lock.acquire()
        self.run_state = "STOP"

    def _run(self) -> None:
        self._cancel()
        self.run_state = "RUN"

    def _stop(self) -> None:
        if self.run_state == "RUN":
            self._immediate()
        self.run_state = "STOP"

    def _immediate(self) -> Acquisition:
        """The latest record of a running scope: the one that ended just now."""
        points, xinc, xorig = self._record_geometry()
        now = self.clock()
        self.n_acq += 1
        acq = Acquisition(points, xinc, xorig, t_arm=now, channels=self._displayed(),
                          seed=(self.seed, self.n_acq), render=self.signals())
        acq.t_trig = now - (xorig + points * xinc)
        acq.done.set()
        self.acq = acq
        return acq

    def _last_acq(self) -> Acquisition:
        if self.run_state == "RUN":
            # a running scope: the newest record (reused for 0.1 s so that a preamble
            # and the data that follows it describe the same record)
            acq = self.acq
            if acq is not None and acq.done.is_set() and acq.t_trig is not None and \
                    self.clock() - acq.t_arm < 0.1:
                return acq
            return self._immediate()
        if self.acq is None:
            raise ScpiError(-230, "Data corrupt or stale;no acquisition")
        if not self.acq.done.is_set():
            raise ScpiError(-230, "Data corrupt or stale;acquisition not complete")
        return self.acq

    def _astate(self) -> str:
        if self.acq is None or self.run_state == "STOP":
            return "ADONE" if self._done() else "ARM"
        if self.acq.done.is_set():
            return "ADONE"
        return "TRIG" if self.acq.t_trig is not None else "ARM"

    def _ter(self) -> str:
        was, self.triggered = self.triggered, False
        return "+1" if was else "+0"

    def opc(self) -> str:
        return "1"

    # -- transfer -----------------------------------------------------------------------------
    def _source(self) -> int:
        return int(self.get("wav_source")[-1])

    def _scaling(self, acq: Acquisition | None = None) -> tuple[float, float, float, float, int, int]:
        """(xinc, xorig, yinc, yorig, yref, points) of the transfer with today's settings."""
        acq = acq or self.acq
        ch = self._source()
        scale = self.get("scale", ch)
        offset = self.get("offset", ch)
        fmt = self.get("wav_format")
        points, xinc, xorig = ((acq.points, acq.xinc_s, acq.xorig_s) if acq is not None
                               else self._record_geometry())
        step = self._step_for(acq)
        points = len(range(0, points, step))
        xinc *= step
        if fmt == "BYTE":
            yinc, yref = 10 * scale / 256, 128
        else:
            yinc, yref = 10 * scale / 65536, 32768
        if not self.get("unsigned"):
            yref = 0   # signed codes are centred on zero
        return xinc, xorig, yinc, offset, yref, points

    def _preamble(self) -> str:
        acq = self._last_acq()
        xinc, xorig, yinc, yorig, yref, points = self._scaling(acq)
        fmt = {"BYTE": 0, "WORD": 1, "ASC": 4}[self.get("wav_format")]
        typ = {"NORM": 0, "PEAK": 1, "AVER": 2, "HRES": 3}[self.get("acq_type")]
        count = self.get("acq_count") if typ == 2 else 1
        return (f"{fmt:+d},{typ:+d},{points:+d},{count:+d},{xinc:+.8E},{xorig:+.8E},+0,"
                f"{yinc:+.8E},{yorig:+.8E},{yref:+d}")

    def _data(self) -> bytes:
        acq = self._last_acq()
        ch = self._source()
        if not self.get("display", ch):
            raise ScpiError(-221, "Settings conflict;waveform source channel is off")
        xinc, xorig, yinc, yorig, yref, points = self._scaling(acq)
        if acq.error:
            raise ScpiError(-300, f"Device-specific error;{acq.error}"[:200])
        volts = acq.get(self._step_for(acq)).get(ch)
        if volts is None:   # switched on after the acquisition: nothing was digitised
            raise ScpiError(-230, "Data corrupt or stale;channel was off during the acquisition")
        volts = volts[:points]
        fmt = self.get("wav_format")
        full = 5 * self.get("scale", ch)   # the ADC spans +-5 divisions about the offset
        if fmt == "ASC":
            text = ",".join(f"{v:+.6E}" for v in np.clip(volts, yorig - full, yorig + full))
            return self.block(text.encode("ascii"))
        span = 65536 if fmt == "WORD" else 256
        lo = 0 if self.get("unsigned") else -span // 2
        codes = np.clip(np.rint((volts - yorig) / yinc + yref), lo, lo + span - 1)
        if fmt == "WORD":
            order = ">" if self.get("byteorder") == "MSBF" else "<"
            kind = "u2" if self.get("unsigned") else "i2"
            payload = codes.astype(order + kind).tobytes()
        else:
            payload = codes.astype("u1" if self.get("unsigned") else "i1").tobytes()
        return self.block(payload)

    def close(self) -> None:
        self._cancel()


#: DS1000Z: bytes one :WAVeform:DATA? sends at most, per format (DS1000Z Programming Guide,
#: :WAVeform:STARt: "BYTE 250000, WORD 125000, ASCii 15625" points)
RIGOL_MAX_POINTS = {"BYTE": 250_000, "WORD": 125_000, "ASC": 15_625}
RIGOL_SCREEN_POINTS = 1200
#: DS1000Z Programming Guide, :ACQuire:MDEPth: depths per channels on (1, 2, 3-4), and the
#: maximum sample rate (data sheet: 1 GSa/s single channel, 500 MSa/s dual, 250 MSa/s more)
RIGOL_MDEPTHS = {1: (12_000, 120_000, 1_200_000, 12_000_000, 24_000_000),
                 2: (6_000, 60_000, 600_000, 6_000_000, 12_000_000),
                 4: (3_000, 30_000, 300_000, 3_000_000, 6_000_000)}
RIGOL_MAX_SRATE = {1: 1e9, 2: 5e8, 4: 2.5e8}


class SimRigolDS1000Z(SimInfiniiVision):
    """The simulated Rigol DS1000Z (DS1104Z by default): the same acquisitions, Rigol's dialect.

    DS1000Z Programming Guide facts used (chapter 2): 12 horizontal divisions
    (``:TIMebase[:MAIN]:SCALe``, ``:OFFSet``); ``:WAVeform:MODE
    NORMal|MAXimum|RAW`` (NORMal: the 1200 screen points; RAW: the memory,
    read only when stopped, so a running scope serves the screen);
    ``:WAVeform:STARt``/``:STOP`` (1-based, inclusive) select the points of one
    read, at most 250 000 in BYTE (125 000 WORD, 15 625 ASCii), else
    ``-222`` and an empty block; ``:WAVeform:DATA?`` answers a TMC block
    ``#9000001200...`` (nine digits); ``:WAVeform:PREamble?`` answers
    ``format,type,points,count,xinc,xorig,xref,yinc,yorig,yref`` with format
    0 BYTE / 1 WORD / 2 ASC and type 0 NORM / 1 MAX / 2 RAW, volts
    ``(d - yorigin - yreference) * yincrement`` with 25 codes per division
    about ``yreference`` 127; WORD points are two bytes, low byte first,
    the high byte 0; ``:TRIGger:STATus?`` answers TD, WAIT, RUN, AUTO or
    STOP; the empty error queue answers ``0,"No error"``.
    """

    idn = "RIGOL TECHNOLOGIES,DS1104Z,DS1ZA000000001,00.04.04.SP3"
    #: ``:ACQuire:MDEPth`` (None: AUTO)
    mdepth: int | None = None
    block_digits = 9
    int_sign = False
    no_error = '0,"No error"'
    divisions = 12

    def fnum(self, value: float) -> str:
        return f"{value:e}"

    def build(self) -> None:
        super().build()
        drop = {":TIMebase:SCALe", ":TIMebase:MAIN:SCALe", ":WAVeform:FORMat", ":CHANnel#:OFFSet",
                # InfiniiVision commands the DS1000Z does not have (-113 there)
                ":DIGitize", ":RSTate", ":ASTate", ":TER", ":OPERegister:CONDition", ":OPERegister[:EVENt]",
                ":WAVeform:POINts", ":WAVeform:POINts:MODE", ":WAVeform:BYTeorder", ":WAVeform:UNSigned",
                ":WAVeform:VIEW", ":WAVeform:YORigin", ":TRIGger:FORCe", ":TRIGger[:EDGE]:SLOPe",
                # replaced by the DS1000Z's own forms below
                ":TRIGger[:EDGE]:SOURce", ":TRIGger[:EDGE]:LEVel", ":TRIGger:SWEep", ":ACQuire:TYPE",
                ":ACQuire:COUNt", ":CHANnel#:BWLimit"}
        self.commands = [cmd for cmd in self.commands if cmd.pattern not in drop]
        self.add(":TFORce", set=lambda c: self._force())
        self.add(":CHANnel#:OFFSet", set=self._set_offset,
                 query=lambda c: self.fnum(self.get("offset", self._ch(c))))
        # the Y origin is an integer code offset (:WAVeform:YORigin?, and the preamble's field)
        self.add(":WAVeform:YORigin", query=lambda c: self.fmt_int(int(self._scaling()[3])))
        self.settings["range"] = 12 * 1e-6   # *RST: 1 us/div
        self.setting_defaults["range"] = (12e-6, False)
        self.add(":TIMebase[:MAIN]:SCALe", set=lambda c: self.settings.__setitem__(
            "range", self.divisions * self.num(c.one(), "S", 5e-9, 50.0)),
            query=lambda c: self.fnum(self.get("range") / self.divisions))
        self.add(":TIMebase[:MAIN]:OFFSet", set=lambda c: self.settings.__setitem__(
            "position", self.num(c.one(), "S", -500.0, 500.0)), query=lambda c: self.fnum(self.get("position")))
        self.setting(":WAVeform:FORMat", "wav_format", "BYTE", lambda t: parse_enum(t, ["WORD", "BYTE", "ASCii"]),
                     str)
        self.setting(":WAVeform:MODE", "wav_mode", "NORM", lambda t: parse_enum(t, ["NORMal", "MAXimum", "RAW"]),
                     str)
        self.setting(":WAVeform:STARt", "wav_start", 1, lambda t: int(self.num(t, "", 1, 24_000_000)),
                     self.fmt_int)
        self.setting(":WAVeform:STOP", "wav_stop", RIGOL_SCREEN_POINTS,
                     lambda t: int(self.num(t, "", 1, 24_000_000)), self.fmt_int)
        self.add(":TRIGger:STATus", query=lambda c: self._trigger_status())
        self.add(":ACQuire:MDEPth", set=self._set_mdepth, query=lambda c: self._mdepth_query())
        # :MEASure:ITEM? <item>[,<source>] (DS ":MEASure:ITEM"): VPP, VAMP, VRMS, VAVG, VMAX, VMIN, FREQ, PER
        self.add(":MEASure:ITEM", query=self._measure_item, query_params=True)
        # :ACQuire:TYPE {NORMal|AVERages|PEAK|HRESolution}, :ACQuire:AVERages 2^n (n = 1..10)
        self.setting(":ACQuire:TYPE", "acq_type", "NORM",
                     lambda t: parse_enum(t, ["NORMal", "AVERages", "PEAK", "HRESolution"]), str)
        self.setting(":ACQuire:AVERages", "acq_count", 2, self._parse_averages, self.fmt_int)
        self.setting(":TRIGger:SWEep", "trig_sweep", "AUTO", lambda t: parse_enum(t, ["AUTO", "NORMal", "SINGle"]),
                     str)
        # :TRIGger:EDGe:SOURce/SLOPe/LEVel: the DS1000Z's node is EDGe (short form EDG)
        self.setting(":TRIGger[:EDGe]:SOURce", "trig_source", "CHAN1", self._parse_trig_source, str)
        self.setting(":TRIGger[:EDGe]:SLOPe", "trig_slope", "POS",
                     lambda t: parse_enum(t, ["POSitive", "NEGative", "RFALl"]), str)
        self.add(":TRIGger[:EDGe]:LEVel", set=self._set_trig_level, query=self._trig_level_query)
        # :CHANnel<n>:BWLimit {20M|OFF}
        self.setting(":CHANnel#:BWLimit", "bwlimit", "OFF", lambda t: parse_enum(t, ["20M", "OFF"]), str, True)

    def _parse_trig_source(self, text: str) -> str:
        """The four-channel DS1000Z triggers on CHANnel1-4 or AC (DS :TRIGger:EDGe:SOURce: no EXT input);
        the two-channel DS1000Z-E on CHANnel1-2, EXT or AC (its front panel's EXT TRIG). Else -224."""
        n = self.suffix_limits["CHAN"]
        chans = [f"CHANnel{k}" for k in range(1, n + 1)]
        return parse_enum(text, chans + (["EXTernal"] if n == 2 else []) + ["AC"])

    def _measure_item(self, c: Call) -> str:
        if not c.params or len(c.params) > 2:
            raise ScpiError(-109 if not c.params else -108)
        item = parse_enum(c.params[0], ["VPP", "VAMP", "VRMS", "VAVG", "VMAX", "VMIN", "FREQuency", "PERiod"])
        src = Call(c.params[1:], c.suffixes, c.header, True)
        return self.fnum(self._measure({"VAVG": "VAVE"}.get(item, item), src))

    def _parse_averages(self, text: str) -> int:
        n = int(self.num(text, "", 2, 1024))
        if n & (n - 1):
            raise ScpiError(-224, "Illegal parameter value;averages must be a power of two")
        return n

    def averages(self) -> int:
        return int(self.get("acq_count")) if self.get("acq_type") == "AVER" else 1

    def _channels_on(self) -> int:
        on = len(self._displayed())
        return 1 if on <= 1 else 2 if on == 2 else 4

    def _set_mdepth(self, c: Call) -> None:
        """``:ACQuire:MDEPth AUTO|<points>``: only a depth the guide lists for the channels now on,
        and only while running (else -221)."""
        word = c.one().strip().upper()
        if word == "AUTO":
            self.mdepth = None
            return
        depth = int(parse_number(word, ""))
        allowed = RIGOL_MDEPTHS[self._channels_on()]
        if depth not in allowed:
            raise ScpiError(-224, f"Illegal parameter value;memory depth {depth} not one of {allowed}")
        if self.run_state != "RUN":
            raise ScpiError(-221, "Settings conflict;memory depth can only be set while running")
        self.mdepth = depth

    def _mdepth_query(self) -> str:
        if self.mdepth is None:
            return "AUTO"
        return self.fmt_int(self._record_geometry()[0])

    def _record_geometry(self) -> tuple[int, float, float]:
        """A set memory depth fills the screen's 12 divisions, at most at the channels' maximum
        sample rate (1 GSa/s one channel, 500 MSa/s two, 250 MSa/s more); AUTO: as the base."""
        depth = self.mdepth
        if depth is None:
            return super()._record_geometry()
        rng = self.get("range")
        points = int(min(depth, max(100, rng * RIGOL_MAX_SRATE[self._channels_on()])))
        xinc = rng / points
        ref = {"LEFT": 0.1, "CENT": 0.5, "RIGH": 0.9}[self.get("reference")]
        return points, xinc, self.get("position") - ref * rng

    def reset(self) -> None:
        super().reset()
        self.mdepth = None

    def offset_limit(self, ch: int) -> float:
        """The largest ``|:CHANnel<n>:OFFSet|`` at the channel's scale and probe ratio (DS1000Z
        Programming Guide, :CHANnel<n>:OFFSet: probe 1X, scale >= 500 mV/div: +-100 V, below:
        +-2 V; 10X: >= 5 V/div +-1000 V, below +-20 V)."""
        probe, scale = self.get("probe", ch), self.get("scale", ch)
        return probe * (100.0 if scale / probe >= 0.5 else 2.0)

    def _set_offset(self, c: Call) -> None:
        """The offset is added to the signal on screen: the centre shows ``-OFFSet`` (see
        :meth:`_scaling`); beyond :meth:`offset_limit` it is clipped there and -222 queued."""
        ch = self._ch(c)
        lim = self.offset_limit(ch)
        self.settings["offset"][ch] = self.num(c.one(), "V", -lim, lim)

    def _trigger_status(self) -> str:
        if self._stopped():
            return "STOP"
        if self.run_state == "RUN":
            return "AUTO" if self.get("trig_sweep") == "AUTO" else "RUN"
        return "TD" if self.acq is not None and self.acq.t_trig is not None else "WAIT"

    def _raw(self) -> bool:
        """Memory (not screen) points: RAW, or MAXimum on a stopped scope; only when stopped."""
        return self.get("wav_mode") in ("RAW", "MAX") and self._stopped()

    def _step_for(self, acq: Acquisition | None) -> int:
        depth = acq.points if acq is not None else self._record_geometry()[0]
        if self._raw():
            return 1
        return max(1, depth // RIGOL_SCREEN_POINTS)

    def _scaling(self, acq: Acquisition | None = None) -> tuple[float, float, float, float, int, int]:
        acq = acq or self.acq
        ch = self._source()
        points, xinc, xorig = ((acq.points, acq.xinc_s, acq.xorig_s) if acq is not None
                               else self._record_geometry())
        step = self._step_for(acq)
        points = len(range(0, points, step))
        if not self._raw():
            points = min(points, RIGOL_SCREEN_POINTS)   # NORMal: the screen's 1200 points, no more
        yinc = self.get("scale", ch) / 25.0
        # the offset is added to the signal: code = volts / yinc + yorigin + yreference, so the
        # centre code (yreference) is the input voltage -offset
        yorig = float(round(self.get("offset", ch) / yinc))
        return xinc * step, xorig, yinc, yorig, 127, points

    def _preamble(self) -> str:
        acq = self._last_acq()
        xinc, xorig, yinc, yorig, yref, points = self._scaling(acq)
        fmt = {"BYTE": 0, "WORD": 1, "ASC": 2}[self.get("wav_format")]
        typ = {"NORM": 0, "MAX": 1, "RAW": 2}[self.get("wav_mode")]
        return (f"{fmt},{typ},{points},1,{xinc:e},{xorig:e},0,{yinc:e},{int(yorig)},{yref}")

    def _data(self) -> bytes:
        acq = self._last_acq()
        ch = self._source()
        if not self.get("display", ch):
            raise ScpiError(-221, "Settings conflict;waveform source channel is off")
        if acq.error:
            raise ScpiError(-300, f"Device-specific error;{acq.error}"[:200])
        xinc, xorig, yinc, yorig, yref, points = self._scaling(acq)
        fmt = self.get("wav_format")
        start, stop = self.get("wav_start"), min(self.get("wav_stop"), points)
        if start > stop:
            raise ScpiError(-221, "Settings conflict;start after stop")
        if stop - start + 1 > RIGOL_MAX_POINTS[fmt]:
            self.push_error(-222, f"Data out of range;more than {RIGOL_MAX_POINTS[fmt]} points in one read")
            return self.block(b"")
        volts = acq.get(self._step_for(acq)).get(ch)
        if volts is None:
            raise ScpiError(-230, "Data corrupt or stale;channel was off during the acquisition")
        volts = volts[start - 1:stop]
        if fmt == "ASC":
            full = 4 * self.get("scale", ch)
            off = yorig * yinc
            return self.block(",".join(f"{v:e}" for v in np.clip(volts, -off - full, -off + full)).encode())
        codes = np.clip(np.rint(volts / yinc + yorig + yref), 0, 255)
        payload = codes.astype("<u2" if fmt == "WORD" else "u1").tobytes()
        return self.block(payload)
