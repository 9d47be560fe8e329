"""Simulated function generators on a raw SCPI socket: Keysight 33500B (33511B/33521B one channel,
33512B/33522B two), Rigol DG1000Z (its own dialect) and Agilent 33220A.

Commands (long and short forms; ``SOURce#``/``OUTPut#``/``TRIGger#`` default
to channel 1): ``FUNCtion``, ``FREQuency``, ``FREQuency:STARt|STOP``,
``VOLTage``, ``VOLTage:UNIT VPP|VRMS``, ``VOLTage:OFFSet``, ``PHASe``,
``APPLy:SINusoid``, ``SWEep:STATe|SPACing|TIME|HTIMe|RTIMe``,
``BURSt:STATe|MODE|NCYCles|INTernal:PERiod|PHASe``, ``OUTPut ON|OFF``,
``OUTPut:LOAD INF|<ohm>``, ``OUTPut:SYNC``, ``TRIGger:SOURce IMM|EXT|BUS|TIM``,
``TRIGger`` and ``*TRG``, plus the IEEE 488.2 commons and ``SYSTem:ERRor?``.

Like the real instrument, amplitudes are programmed for the declared load
(50 ohm by default): into the high-impedance PZT or amplifier input the
voltage is then twice the programmed one. Changing the load setting keeps the
output voltage and rescales the displayed amplitude.
"""
from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from decimal import Decimal

import numpy as np

from labkit.lab.models import MODELS_33500B, MODELS_DG1000Z
from labkit.lab.scpi import Call, ScpiError, SimScpiInstrument, parse_bool, parse_enum

MAX_FREQ_HZ = 30e6
MIN_FREQ_HZ = 1e-6
SOURCE_OHM = 50.0
MAX_VPP_OPEN = 20.0   # open-circuit (10 Vpp into 50 ohm)
#: a number and its suffix (the amplitude's unit may be in the suffix)
_NUMBER = re.compile(r"^\s*([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([A-Za-z]*)\s*$")


@dataclass(frozen=True)
class Drive:
    """One channel's output as a function of absolute (monotonic) time, for the physics.

    ``amp_v`` and ``offset_v`` are what a high-impedance load sees. ``t_epoch``
    is when this configuration took effect; the physics treats the system as
    at rest then (a documented simplification for setting changes).
    """

    on: bool = False
    func: str = "SIN"
    freq_hz: float = 1000.0
    amp_v: float = 0.1
    offset_v: float = 0.0
    phase_rad: float = 0.0
    burst_phase_rad: float = 0.0   # BURSt:PHASe: where each burst starts (PHASe is the waveform's)
    t_epoch: float = 0.0
    sweep: bool = False
    start_hz: float = 100.0
    stop_hz: float = 1000.0
    sweep_s: float = 1.0
    hold_s: float = 0.0
    return_s: float = 0.0
    log_spacing: bool = False
    burst: bool = False
    burst_gated: bool = False
    ncycles: float = 1      # cycles per burst; inf: until the burst mode or the output is switched off
    burst_period_s: float = 0.01
    trig_source: str = "IMM"
    trig_times: tuple[float, ...] = field(default=())

    # -- what kind of signal ------------------------------------------------------------------
    def is_sine(self) -> bool:
        """A plain continuous sine (the analytic steady state applies)."""
        return self.on and self.func == "SIN" and not self.sweep and not self.burst

    def sine_like(self) -> bool:
        """A sine, continuous or in (triggered or internally repeated) bursts: inside a burst the
        steady state of the continuous sine applies (a gated burst has no gate signal: silent)."""
        return self.on and self.func == "SIN" and not self.sweep and not (self.burst and self.burst_gated)

    def active(self, t: float) -> bool:
        """The output carries a signal at absolute time ``t`` (on, and not past its last burst)."""
        return self.on and t < self.idle_after() and (not self.burst or self.trig_source == "IMM"
                                                      or any(s <= t for s in self.trig_times))

    def burst_epochs(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(inside, epoch) per sample: whether it lies inside a burst (always, without bursts) and the
        time the sine's phase counts from there (the burst's start; :attr:`t_epoch` otherwise)."""
        t = np.asarray(t, dtype=float)
        if not self.burst:
            return np.ones(t.shape, dtype=bool), np.full(t.shape, self.t_epoch)
        inside = np.zeros(t.shape, dtype=bool)
        epoch = np.full(t.shape, self.t_epoch)
        length = self.burst_length_s()
        for s in self.starts(float(t.min()), float(t.max())):
            sel = (t >= s) & (t < s + length)
            inside |= sel
            epoch[sel] = s
        return inside, epoch

    def burst_length_s(self) -> float:
        """Duration of one burst (inf for ``BURS:NCYC INF``)."""
        return float(self.ncycles) / self.freq_hz

    def idle_after(self) -> float:
        """Absolute time after which the output carries no signal (inf: it never stops by itself).

        Off: since the change that switched it off (``t_epoch``). A triggered
        (BUS/EXT) burst: the end of the last burst. A gated burst with no gate
        signal wired: idle. Anything else runs on.
        """
        if not self.on:
            return self.t_epoch
        if self.burst and self.burst_gated:
            return self.t_epoch
        if self.burst and self.trig_source != "IMM":
            if not self.trig_times:
                return self.t_epoch
            last = self.trig_times[-1]
            return self.t_epoch if last < self.t_epoch else last + self.burst_length_s()
        return float("inf")

    def freq_range_hz(self) -> tuple[float, float]:
        if self.sweep:
            return min(self.start_hz, self.stop_hz), max(self.start_hz, self.stop_hz)
        return self.freq_hz, self.freq_hz

    # -- starts of sweeps/bursts ----------------------------------------------------------
    def _period(self) -> float:
        if self.sweep:
            return self.sweep_s + self.hold_s + self.return_s
        return self.burst_period_s

    def starts(self, t0: float, t1: float) -> np.ndarray:
        """Start times of sweeps or bursts that can affect [t0, t1]."""
        if self.trig_source == "IMM":
            period = self._period()
            k0 = max(0, int(np.floor((t0 - self.t_epoch) / period)) - 1)
            k1 = int(np.floor((t1 - self.t_epoch) / period)) + 1
            return self.t_epoch + period * np.arange(k0, k1 + 1)
        return np.array([t for t in self.trig_times if self.t_epoch <= t <= t1], dtype=float)

    def next_sync(self, t_min: float) -> float | None:
        """Time of the next sync pulse at or after ``t_min`` (scope trigger), or None."""
        if not self.on:
            return None
        if (self.sweep or self.burst) and self.trig_source != "IMM":
            # a BUS/EXT trigger may come at any time after the scope armed: every later one counts
            later_trig = [t for t in self.trig_times if t >= max(t_min, self.t_epoch)]
            return later_trig[0] if later_trig else None
        if self.sweep or self.burst:
            starts = self.starts(t_min, t_min + 2 * self._period())
            later = starts[starts >= t_min]
            return float(later[0]) if len(later) else None
        # a plain waveform: the sync marks phase zero of every cycle
        period = 1.0 / self.freq_hz
        t_zero = self.t_epoch - self.phase_rad / (2 * np.pi * self.freq_hz)
        k = np.ceil((t_min - t_zero) / period)
        return float(t_zero + k * period)

    # -- the waveform ------------------------------------------------------------------------
    def voltage(self, t: np.ndarray) -> np.ndarray:
        """Output voltage into a high-impedance load at absolute times ``t``."""
        t = np.asarray(t, dtype=float)
        if not self.on:
            return np.zeros_like(t)
        if self.func == "DC":
            return np.full_like(t, self.offset_v)
        if self.sweep:
            phase = self._sweep_phase(t)
            return self.offset_v + self.amp_v * np.sin(phase)
        phase = 2 * np.pi * self.freq_hz * (t - self.t_epoch) + self.phase_rad
        wave = _shape(self.func, phase)
        # between bursts a sine holds the level of its burst start phase (BURSt:PHASe: N whole
        # cycles end where they began; the 33220A/33500 guides: "the voltage level corresponding
        # to the starting burst phase"); other shapes rest at the offset
        idle = float(np.sin(self.burst_phase_rad)) if self.func == "SIN" else 0.0
        if self.burst and self.burst_gated:
            # gated bursts follow the rear-panel Ext Trig input: nothing is wired to it in the lab
            return np.full_like(t, self.offset_v + self.amp_v * idle)
        if self.burst:
            gate = np.zeros(t.shape, dtype=bool)
            length = self.burst_length_s()
            for s in self.starts(float(t.min()), float(t.max())):
                gate |= (t >= s) & (t < s + length)
            local = np.zeros_like(t)
            for s in self.starts(float(t.min()), float(t.max())):
                sel = (t >= s) & (t < s + length)
                local[sel] = 2 * np.pi * self.freq_hz * (t[sel] - s) + self.burst_phase_rad
            wave = np.where(gate, _shape(self.func, local), idle)
        return self.offset_v + self.amp_v * wave

    def _sweep_phase(self, t: np.ndarray) -> np.ndarray:
        f0, f1, T = self.start_hz, self.stop_hz, self.sweep_s
        H, R = self.hold_s, self.return_s
        # before any (triggered) sweep: a sine at the start frequency
        phase = 2 * np.pi * f0 * (t - self.t_epoch)
        starts = self.starts(float(t.min()), float(t.max()))
        for s in starts:
            end = s + (T + H + R if self.trig_source == "IMM" else np.inf)
            sel = (t >= s) & (t < end)
            if not sel.any():
                continue
            tau = t[sel] - s
            phase[sel] = _sweep_phase(tau, f0, f1, T, H, R, self.log_spacing)
        return phase


def _sweep_phase(tau: np.ndarray, f0: float, f1: float, T: float, H: float, R: float,
                 log: bool) -> np.ndarray:
    """Phase (rad) at time ``tau`` after a sweep's start: sweep, hold at f1, return to f0."""
    def in_sweep(x: np.ndarray) -> np.ndarray:
        if log and f0 > 0 and f1 > 0 and f0 != f1:
            k = np.log(f1 / f0)
            return 2 * np.pi * f0 * T / k * (np.exp(k * x / T) - 1)
        return 2 * np.pi * (f0 * x + (f1 - f0) * x ** 2 / (2 * T))

    out = np.empty_like(tau)
    a = tau < T
    out[a] = in_sweep(tau[a])
    p_t = float(in_sweep(np.array([T]))[0])
    b = (tau >= T) & (tau < T + H)
    out[b] = p_t + 2 * np.pi * f1 * (tau[b] - T)
    p_th = p_t + 2 * np.pi * f1 * H
    c = tau >= T + H
    sig = np.minimum(tau[c] - T - H, R)
    rest = tau[c] - T - H - sig    # after the return (triggered sweeps): wait at f0
    if R > 0:
        out[c] = p_th + 2 * np.pi * (f1 * sig + (f0 - f1) * sig ** 2 / (2 * R)) + 2 * np.pi * f0 * rest
    else:
        out[c] = p_th + 2 * np.pi * f0 * rest
    return out


def _nr3(value: float, decimals: int) -> str:
    """``+9.999000000000000E+01`` for 99.99: the decimal value (15 significant digits, what a
    double holds for sure) printed with ``decimals`` digits, not the binary float's tail."""
    if not np.isfinite(value) or value == 0:
        return f"{value + 0.0:+.{decimals}E}"     # (-0.0 + 0.0 is +0.0)
    mantissa, exponent = format(Decimal(f"{float(value):.15g}"), f"+.{decimals}E").split("E")
    return f"{mantissa}E{int(exponent):+03d}"


def yes_no(value: object) -> str:
    """A boolean reply: ``1`` or ``0``."""
    return "1" if value else "0"


def _vpp_to_dbm(vpp: float, load_ohm: float) -> float:
    """Sine power into ``load_ohm`` in dBm for ``vpp`` volts peak-to-peak at the load."""
    vrms = vpp / (2 * 2 ** 0.5)
    return float(10 * np.log10(vrms ** 2 / load_ohm / 1e-3))


def _dbm_to_vpp(dbm: float, load_ohm: float) -> float:
    return float(2 * 2 ** 0.5 * np.sqrt(load_ohm * 1e-3 * 10 ** (dbm / 10)))


def _quoted(text: str) -> str:
    """A string parameter, kept in the instrument's reply form (double quotes)."""
    text = text.strip()
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "\"'":
        return '"' + text[1:-1].replace('"', '""') + '"'
    raise ScpiError(-151, "Invalid string data")


def _shape(func: str, phase: np.ndarray) -> np.ndarray:
    if func == "SQU":
        return np.where(np.sin(phase) >= 0, 1.0, -1.0)
    if func in ("RAMP", "TRI"):
        x = np.mod(phase / (2 * np.pi), 1.0)
        if func == "TRI":
            return 1 - 4 * np.abs(x - 0.5)
        return 2 * x - 1
    return np.sin(phase)



BurstFn = Callable[[int, float, float], None]


@dataclass
class SavedState:
    """What ``*SAV`` keeps: stored settings, loads, units, sync states and each channel's drive."""

    settings: dict
    load: dict[int, float]
    vunit: dict[int, str]
    sync: dict[int, bool]
    ch: dict[int, Drive]


class SimKeysight33500B(SimScpiInstrument):
    """The simulated 33500B generator (33522B by default); ``drive(ch)`` is its output for the physics.

    Parameters
    ----------
    model:
        One of :data:`MODELS_33500B`: the identity and the number of channels
        (``SOUR2``/``OUTP2`` on a one-channel model: ``-114``).
    on_output:
        Called with (channel, on) whenever an output is switched.
    on_burst:
        Called with (channel, start, end) (absolute clock times) when a
        triggered burst starts, and again with the shortened end when one is
        cut short (output or burst mode off, ``*RST``).
    """

    name = "funcgen"
    idn = "Keysight Technologies,33522B,MY5740LAB1,4.03-1.19-2.00-52-00"
    models: dict[str, int] = MODELS_33500B
    idn_format = "Keysight Technologies,{model},MY5740LAB1,4.03-1.19-2.00-52-00"

    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 on_output: Callable[[int, bool], None] | None = None, *, model: str = "33522B",
                 on_burst: BurstFn | None = None) -> None:
        if model not in self.models:
            raise ValueError(f"{type(self).__name__} model must be one of {', '.join(self.models)}, "
                             f"not {model!r}")
        self.model = model
        self.n_channels = self.models[model]
        self.idn = self.idn_format.format(model=model)
        self.suffix_limits = {"SOUR": self.n_channels, "OUTP": self.n_channels, "TRIG": self.n_channels}
        self.clock = clock
        self.on_output = on_output or (lambda ch, on: None)
        self.on_burst = on_burst or (lambda ch, start, end: None)
        chans = range(1, self.n_channels + 1)
        self.ch = {n: self._default() for n in chans}
        self.load = {n: self.default_load_ohm for n in chans}   # declared load, ohm (inf for high Z)
        self.vunit = {n: "VPP" for n in chans}
        self.sync = {n: n == 1 for n in chans}
        super().__init__()

    def fnum(self, value: float) -> str:
        """NR3 replies as the Trueform generators send them: ``+1.000000000000000E+03``.

        The amplitude, offset and phases answer with two digits fewer
        (``+1.0000000000000E-01``), the infinite load and cycle count as
        ``+9.900000000000000E+37`` (query replies of the 33500B/33600A family).
        """
        return _nr3(value, 15)

    def flevel(self, value: float) -> str:
        """The amplitude/offset/phase reply format (``+1.0000000000000E-01``)."""
        return _nr3(value, 13)

    #: what an infinite load or cycle count answers (SCPI's 9.9E37 for infinity)
    inf_reply = "+9.900000000000000E+37"

    #: ``*RST`` amplitude (Vpp for the default load) and load (ohm; inf: high Z)
    default_vpp = 0.1
    default_load_ohm = SOURCE_OHM

    def _default(self) -> Drive:
        # 33500B power-on: 1 kHz sine, 100 mVpp into 50 ohm (200 mV peak-to-peak open circuit)
        load = self.default_load_ohm
        factor = 1.0 if np.isinf(load) else (load + SOURCE_OHM) / load
        return Drive(amp_v=self.default_vpp * factor / 2, t_epoch=self.clock())

    def reset(self) -> None:
        super().reset()
        for n in self.ch:
            was_on = self.ch[n].on
            self._cut_burst(n)
            self.ch[n] = self._default()
            self.load[n] = self.default_load_ohm
            self.vunit[n] = "VPP"
            self.sync[n] = n == 1
            if was_on:
                self.on_output(n, False)

    def _cut_burst(self, n: int) -> None:
        """A running triggered burst ends now (output, burst mode or configuration changed)."""
        d = self.ch[n]
        if d.burst and d.trig_times and d.trig_source != "IMM":
            end = d.trig_times[-1] + d.burst_length_s()
            now = self.clock()
            if d.trig_times[-1] >= d.t_epoch and end > now:
                self.on_burst(n, d.trig_times[-1], now)

    def drive(self, channel: int = 1) -> Drive:
        with self.lock:
            return self.ch[channel]

    # -- the Sync connector (cabled to the scope's EXT input) -----------------------------------
    def sync_channel(self) -> int | None:
        """The channel whose sync reaches the Sync connector, or None when the connector is off
        (``OUTPut:SYNC:SOURce`` picks the channel, ``OUTPut:SYNC`` switches it)."""
        src = self.settings.get("sync_source", "CH1")
        n = int(str(src)[-1]) if str(src)[-1].isdigit() else 1
        return n if n in self.ch and self.sync[n] else None

    def sync_inverted(self, n: int) -> bool:
        """Whether channel ``n``'s sync pulse is inverted (its rising edge at half a cycle)."""
        return self.get("sync_pol", n) == "INV"

    def sync_edge(self, t_min: float) -> float | None:
        """The next rising edge at the Sync connector at or after ``t_min``, or None.

        The connector is off, or follows another channel: whatever that channel does
        (nothing, if it is off). A plain waveform's sync rises at phase zero of each
        cycle, inverted at half a cycle; sweeps and bursts mark their starts.
        """
        with self.lock:
            n = self.sync_channel()
            if n is None or self.get("sync_mode", n) != "NORM":
                return None
            d = self.ch[n]
            inverted = self.sync_inverted(n)
        if inverted and not (d.sweep or d.burst):
            half = 0.5 / d.freq_hz
            t = d.next_sync(t_min - half)
            return None if t is None else t + half
        return d.next_sync(t_min)

    # -- helpers ------------------------------------------------------------------------------
    def _chan(self, c: Call, i: int = 0) -> int:
        n = c.suffix(i)
        if n not in self.ch:
            raise ScpiError(-114)
        return n

    def _update(self, n: int, new_epoch: bool = True, **kw: object) -> None:
        if new_epoch:
            self._cut_burst(n)
            kw["t_epoch"] = self.clock()
        self.ch[n] = replace(self.ch[n], **kw)  # type: ignore[arg-type]

    def _factor(self, n: int) -> float:
        """Open-circuit volts per programmed volt for the declared load."""
        load = self.load[n]
        return 1.0 if np.isinf(load) else (load + SOURCE_OHM) / load

    def _display_vpp(self, n: int) -> float:
        return 2 * self.ch[n].amp_v / self._factor(n)

    def _amp_unit(self, n: int, text: str) -> tuple[str, str]:
        """(unit, number) of an amplitude: a ``VPP``/``MVPP``, ``VRMS``/``MVRMS`` or ``DBM`` suffix
        names its own unit; a bare number (or ``V``/``MV``) is in ``VOLTage:UNIT``'s."""
        m = _NUMBER.match(text)
        suffix = m.group(2).upper() if m else ""
        for unit, forms in (("VPP", ("VPP", "MVPP")), ("VRMS", ("VRMS", "MVRMS")), ("DBM", ("DBM",))):
            if suffix in forms and m is not None:
                scale = 1e-3 if suffix.startswith("MV") else 1.0
                return unit, repr(float(m.group(1)) * scale)
        return self.vunit[n], text

    def _set_amp(self, n: int, text: str) -> None:
        f = self._factor(n)
        limit = MAX_VPP_OPEN / f
        unit, text = self._amp_unit(n, text)
        if unit == "DBM" and np.isinf(self.load[n]):
            raise ScpiError(-221, "Settings conflict;dBm units not allowed with high impedance load")
        if unit == "VRMS":
            value = self.num(text, "V", 1e-3 / (2 * 2 ** 0.5), limit / (2 * 2 ** 0.5), 0.1 / (2 * 2 ** 0.5))
            vpp = value * 2 * 2 ** 0.5
        elif unit == "DBM":
            dbm = self.num(text, "", _vpp_to_dbm(1e-3, self.load[n]), _vpp_to_dbm(limit, self.load[n]),
                           _vpp_to_dbm(0.1, self.load[n]))
            vpp = _dbm_to_vpp(dbm, self.load[n])
        else:
            vpp = self.num(text, "V", 1e-3, limit, 0.1)
        # amplitude and offset together must stay inside the output's +-10 V (open circuit)
        if vpp * f / 2 + abs(self.ch[n].offset_v) > MAX_VPP_OPEN / 2 + 1e-12:
            self.push_error(-221, "Settings conflict;amplitude changed due to offset")
            vpp = 2 * (MAX_VPP_OPEN / 2 - abs(self.ch[n].offset_v)) / f
        self._update(n, amp_v=vpp * f / 2)

    def _amp_query(self, n: int, c: Call) -> str:
        if c.params:
            return self.flevel(self.query_limit(c, (1e-3, MAX_VPP_OPEN / self._factor(n)), self.default_vpp))
        vpp = self._display_vpp(n)
        if self.vunit[n] == "DBM":
            return self.flevel(_vpp_to_dbm(vpp, self.load[n]))
        return self.flevel(vpp / (2 * 2 ** 0.5) if self.vunit[n] == "VRMS" else vpp)

    def _set_output(self, n: int, on: bool) -> None:
        if self.ch[n].on != on:
            self._update(n, on=on)
            self.on_output(n, on)

    # -- table --------------------------------------------------------------------------------
    def build(self) -> None:
        S = "[SOURce#:]"
        add = self.add

        def fset(key: str, unit: str, lo: float, hi: float, default: float, epoch: bool = True):
            def do(c: Call) -> None:
                n = self._chan(c)
                self._update(n, epoch, **{key: self.num(c.one(), unit, lo, hi, default)})
            return do

        def fget(key: str, lo: float, hi: float):
            def do(c: Call) -> str:
                n = self._chan(c)
                if c.params:      # {MINimum|MAXimum|DEFault}: the limits and the *RST value
                    return self.fnum(self.query_limit(c, (lo, hi), getattr(self._default(), key)))
                return self.fnum(getattr(self.ch[n], key))
            return do

        add(S + "FUNCtion[:SHAPe]",
            set=lambda c: self._update(self._chan(c), func=parse_enum(
                c.one(), ["SINusoid", "SQUare", "RAMP", "TRIangle", "DC", "NOISe", "PULSe", "PRBS", "ARB"])),
            query=lambda c: self.ch[self._chan(c)].func)
        add(S + "FREQuency[:CW]", set=fset("freq_hz", "HZ", MIN_FREQ_HZ, MAX_FREQ_HZ, 1000.0),
            query=fget("freq_hz", MIN_FREQ_HZ, MAX_FREQ_HZ))
        add(S + "FREQuency:STARt", set=fset("start_hz", "HZ", MIN_FREQ_HZ, MAX_FREQ_HZ, 100.0),
            query=fget("start_hz", MIN_FREQ_HZ, MAX_FREQ_HZ))
        add(S + "FREQuency:STOP", set=fset("stop_hz", "HZ", MIN_FREQ_HZ, MAX_FREQ_HZ, 1000.0),
            query=fget("stop_hz", MIN_FREQ_HZ, MAX_FREQ_HZ))
        add(S + "VOLTage[:LEVel][:IMMediate][:AMPLitude]",
            set=lambda c: self._set_amp(self._chan(c), c.one()),
            query=lambda c: self._amp_query(self._chan(c), c))
        add(S + "VOLTage:UNIT", set=self._set_unit, query=lambda c: self.vunit[self._chan(c)])
        add(S + "VOLTage[:LEVel][:IMMediate]:OFFSet", set=self._set_offset,
            query=self._limited(lambda c: self.ch[self._chan(c)].offset_v / self._factor(self._chan(c)),
                                lambda c: self._offset_limits(self._chan(c)), 0.0))
        add(S + "PHASe[:ADJust]",
            set=lambda c: self._update(self._chan(c), phase_rad=self._angle(c.one())),
            query=self._limited(lambda c: self._angle_out(self.ch[self._chan(c)].phase_rad),
                                lambda c: self._angle_limits(), 0.0))
        add(S + "APPLy:SINusoid", set=self._apply_sin, query=None)
        add(S + "APPLy", query=lambda c: self._apply_query(self._chan(c)))
        add(S + "SWEep:STATe", set=lambda c: self._update(self._chan(c), sweep=parse_bool(c.one())),
            query=lambda c: "1" if self.ch[self._chan(c)].sweep else "0")
        add(S + "SWEep:SPACing",
            set=lambda c: self._update(self._chan(c), log_spacing=parse_enum(
                c.one(), ["LINear", "LOGarithmic"]) == "LOG"),
            query=lambda c: "LOG" if self.ch[self._chan(c)].log_spacing else "LIN")
        add(S + "SWEep:TIME", set=fset("sweep_s", "S", 1e-3, 3600.0, 1.0),
            query=fget("sweep_s", 1e-3, 3600.0))
        add(S + "SWEep:HTIMe", set=fset("hold_s", "S", 0.0, 3600.0, 0.0), query=fget("hold_s", 0.0, 3600.0))
        add(S + "SWEep:RTIMe", set=fset("return_s", "S", 0.0, 3600.0, 0.0),
            query=fget("return_s", 0.0, 3600.0))
        add(S + "BURSt:STATe", set=lambda c: self._update(self._chan(c), burst=parse_bool(c.one())),
            query=lambda c: "1" if self.ch[self._chan(c)].burst else "0")
        add(S + "BURSt:MODE",
            set=lambda c: self._update(self._chan(c), burst_gated=parse_enum(
                c.one(), ["TRIGgered", "GATed"]) == "GAT"),
            query=lambda c: "GAT" if self.ch[self._chan(c)].burst_gated else "TRIG")
        add(S + "BURSt:NCYCles", set=self._set_ncycles, query=self._ncycles_query)
        add(S + "BURSt:INTernal:PERiod", set=fset("burst_period_s", "S", 1e-6, 8000.0, 0.01),
            query=fget("burst_period_s", 1e-6, 8000.0))
        add(S + "BURSt:PHASe",
            set=lambda c: self._update(self._chan(c), burst_phase_rad=self._angle(c.one())),
            query=self._limited(lambda c: self._angle_out(self.ch[self._chan(c)].burst_phase_rad),
                                lambda c: self._angle_limits(), 0.0))
        add("OUTPut#[:STATe]", set=lambda c: self._set_output(self._chan(c), parse_bool(c.one())),
            query=lambda c: "1" if self.ch[self._chan(c)].on else "0")
        add("OUTPut#:LOAD", set=self._set_load, query=self._load_query)
        add("OUTPut#:SYNC[:STATe]", set=lambda c: self.sync.__setitem__(self._chan(c), parse_bool(c.one())),
            query=lambda c: "1" if self.sync[self._chan(c)] else "0")
        add("TRIGger#:SOURce",
            set=lambda c: self._update(self._chan(c), False, trig_source=parse_enum(
                c.one(), ["IMMediate", "EXTernal", "BUS", "TIMer"])),
            query=lambda c: self.ch[self._chan(c)].trig_source)
        add("TRIGger#[:IMMediate]", set=lambda c: self._trigger([self._chan(c)], force=True))
        add("*TRG", set=lambda c: self._trigger(list(self.ch), force=False))
        self._build_more()
        self._build_status()

    def _build_status(self) -> None:
        """SCPI's STATus subsystem (SCPI 1999 vol. 1, 9; KS "STATus Subsystem"): OPERation and
        QUEStionable condition (nothing in the simulation sets one), event (cleared by reading
        and ``*CLS``) and enable registers; ``STATus:PRESet`` clears the enables. Their
        summaries are status-byte bits 7 and 3."""
        self.status_regs = {"OPER": [0, 0, 0], "QUES": [0, 0, 0]}   # condition, event, enable

        def register(name: str) -> tuple[Callable[[Call], str], Callable[[Call], str],
                                          Callable[[Call], None], Callable[[Call], str]]:
            reg = self.status_regs[name]

            def event(c: Call) -> str:
                value, reg[1] = reg[1], 0
                return self.fmt_int(value)

            def set_enable(c: Call) -> None:
                reg[2] = int(self.num(c.one(), "", 0, 32767))

            return event, lambda c: self.fmt_int(reg[0]), set_enable, lambda c: self.fmt_int(reg[2])

        for long, name in (("OPERation", "OPER"), ("QUEStionable", "QUES")):
            event, condition, set_enable, enable = register(name)
            self.add(f"STATus:{long}[:EVENt]", query=event)
            self.add(f"STATus:{long}:CONDition", query=condition)
            self.add(f"STATus:{long}:ENABle", set=set_enable, query=enable)
        self.add("STATus:PRESet", set=lambda c: [reg.__setitem__(2, 0) for reg in self.status_regs.values()])

    def summary_bits(self) -> int:
        oper, ques = self.status_regs["OPER"], self.status_regs["QUES"]
        return (128 if oper[1] & oper[2] else 0) | (8 if ques[1] & ques[2] else 0)

    def clear_status(self) -> None:
        super().clear_status()
        for reg in self.status_regs.values():
            reg[1] = 0

    def _set_ncycles(self, c: Call) -> None:
        n = self._chan(c)
        word = c.one().strip().upper()
        cycles = float("inf") if word in ("INF", "INFINITY") else float(int(self.num(word, "", 1, 1e8, 1)))
        self._update(n, ncycles=cycles)

    def _ncycles_query(self, c: Call) -> str:
        n = self._chan(c)
        if c.params:
            return self.fnum(self.query_limit(c, (1.0, 1e8), 1.0))
        cycles = self.ch[n].ncycles
        return self.inf_reply if np.isinf(cycles) else self.fnum(cycles)

    # -- high/low levels and dBm ---------------------------------------------------------------
    def _levels(self, n: int) -> tuple[float, float]:
        """(high, low) as displayed for the declared load."""
        vpp = self._display_vpp(n)
        off = self.ch[n].offset_v / self._factor(n)
        return off + vpp / 2, off - vpp / 2

    def _set_level(self, c: Call, which: str) -> None:
        n = self._chan(c)
        f = self._factor(n)
        high, low = self._levels(n)
        limit = (MAX_VPP_OPEN / 2) / f
        value = self.num(c.one(), "V", -limit, limit, 0.05 if which == "HIGH" else -0.05)
        if which == "HIGH":
            high = value
        else:
            low = value
        if high <= low:
            raise ScpiError(-221, "Settings conflict;high level must be above low level")
        self._update(n, amp_v=(high - low) * f / 2, offset_v=(high + low) / 2 * f)

    def _set_unit(self, c: Call) -> None:
        n = self._chan(c)
        unit = parse_enum(c.one(), ["VPP", "VRMS", "DBM"])
        if unit == "DBM" and np.isinf(self.load[n]):
            # dBm needs a finite load (Operating and Service Guide, VOLTage:UNIT)
            raise ScpiError(-221, "Settings conflict;dBm units not allowed with high impedance load")
        self.vunit[n] = unit

    def _build_more(self) -> None:
        """Documented commands third-party drivers send (PyMeasure Agilent33500, QCoDeS): stored,
        answered, reset by ``*RST`` to the Operating and Service Guide's defaults."""
        S = "[SOURce#:]"
        add = self.add
        add(S + "VOLTage[:LEVel][:IMMediate]:HIGH", set=lambda c: self._set_level(c, "HIGH"),
            query=self._limited(lambda c: self._levels(self._chan(c))[0],
                                lambda c: self._offset_limits(self._chan(c)), 0.05, self.fnum))
        add(S + "VOLTage[:LEVel][:IMMediate]:LOW", set=lambda c: self._set_level(c, "LOW"),
            query=self._limited(lambda c: self._levels(self._chan(c))[1],
                                lambda c: self._offset_limits(self._chan(c)), -0.05, self.fnum))
        self._build_common()
        self.setting(S + "FUNCtion:SQUare:DCYCle", "square_dcyc", 50.0,
                     lambda t: self.num(t, "", 0.01, 99.99), self.fnum, True, (0.01, 99.99))
        self.setting(S + "FUNCtion:RAMP:SYMMetry", "ramp_symm", 100.0,
                     lambda t: self.num(t, "", 0.0, 100.0), self.fnum, True, (0.0, 100.0))
        self.setting(S + "FUNCtion:PULSe:WIDTh", "pulse_width", 1e-4,
                     lambda t: self.num(t, "S", 16e-9, 1e6), self.fnum, True, (16e-9, 1e6))
        self.setting(S + "FUNCtion:PULSe:PERiod", "pulse_period", 1e-3,
                     lambda t: self.num(t, "S", 33e-9, 1e6), self.fnum, True, (33e-9, 1e6))
        self.setting(S + "FUNCtion:PULSe:DCYCle", "pulse_dcyc", 10.0,
                     lambda t: self.num(t, "", 0.0, 100.0), self.fnum, True, (0.0, 100.0))
        self.setting(S + "FUNCtion:PULSe:HOLD", "pulse_hold", "WIDT",
                     lambda t: parse_enum(t, ["WIDTh", "DCYCle"]), str, True)
        self.setting(S + "FUNCtion:PULSe:TRANsition[:BOTH]", "pulse_edge", 1e-8,
                     lambda t: self.num(t, "S", 8.4e-9, 1e-6), self.fnum, True, (8.4e-9, 1e-6))
        self.setting(S + "FUNCtion:ARBitrary", "arb_name", '"INT:\\BUILTIN\\EXP_RISE.ARB"',
                     lambda t: t.strip(), str, True)
        self.setting(S + "FUNCtion:ARBitrary:SRATe", "arb_srate", 4e4,
                     lambda t: self.num(t, "", 1e-6, 250e6), self.fnum, True, (1e-6, 250e6))
        self.setting(S + "FUNCtion:ARBitrary:FILTer", "arb_filter", "STEP",
                     lambda t: parse_enum(t, ["NORMal", "STEP", "OFF"]), str, True)
        self.setting(S + "FUNCtion:ARBitrary:ADVance", "arb_advance", "SRAT",
                     lambda t: parse_enum(t, ["TRIGger", "SRATe"]), str, True)
        self.setting(S + "FREQuency:MODE", "freq_mode", "CW",
                     lambda t: parse_enum(t, ["CW", "FIXed", "LIST", "SWEep"]), lambda v: "CW" if v == "FIX" else v,
                     True)
        self.setting(S + "BURSt:GATE:POLarity", "gate_pol", "NORM",
                     lambda t: parse_enum(t, ["NORMal", "INVerted"]), str, True)
        self.setting("OUTPut#:POLarity", "polarity", "NORM", lambda t: parse_enum(t, ["NORMal", "INVerted"]),
                     str, True)
        self.setting("OUTPut:SYNC:SOURce", "sync_source", "CH1", lambda t: parse_enum(t, ["CH1", "CH2"]), str)
        self.setting("OUTPut#:SYNC:MODE", "sync_mode", "NORM",
                     lambda t: parse_enum(t, ["NORMal", "CARRier", "MARKer"]), str, True)
        self.setting("OUTPut#:SYNC:POLarity", "sync_pol", "NORM",
                     lambda t: parse_enum(t, ["NORMal", "INVerted"]), str, True)
        self.setting("OUTPut:TRIGger[:STATe]", "trig_out", False, parse_bool, yes_no)
        self.setting("OUTPut:TRIGger:SLOPe", "trig_out_slope", "POS",
                     lambda t: parse_enum(t, ["POSitive", "NEGative"]), str)
        self.setting("OUTPut:TRIGger:SOURce", "trig_out_source", "CH1", lambda t: parse_enum(t, ["CH1", "CH2"]), str)
        self.setting("TRIGger#:SLOPe", "trig_slope", "POS", lambda t: parse_enum(t, ["POSitive", "NEGative"]),
                     str, True)
        self.setting("TRIGger#:COUNt", "trig_count", 1.0,
                     lambda t: float("inf") if t.strip().upper() in ("INF", "INFINITY")
                     else self.num(t, "", 1, 1e6), lambda v: self.inf_reply if np.isinf(v) else self.fnum(v),
                     True, (1.0, 1e6))
        self.setting("TRIGger#:DELay", "trig_delay", 0.0, lambda t: self.num(t, "S", 0.0, 1000.0), self.fnum,
                     True, (0.0, 1000.0))
        self.setting("TRIGger#:TIMer", "trig_timer", 1.0, lambda t: self.num(t, "S", 1e-6, 8000.0), self.fnum,
                     True, (1e-6, 8000.0))
        self.setting("TRIGger#:LEVel", "trig_level", 1.0, lambda t: self.num(t, "V", 0.9, 3.8), self.fnum,
                     True, (0.9, 3.8))
        self.setting("DISPlay:TEXT[:DATA]", "display_text", '""', _quoted, str)
        self.add("DISPlay:TEXT:CLEar", set=lambda c: self.settings.__setitem__("display_text", '""'))
        self.setting("DISPlay[:STATe]", "display", True, parse_bool, yes_no)
        self.add("SYSTem:BEEPer[:IMMediate]", set=lambda c: None)
        self.add(S + "PHASe:SYNChronize", set=lambda c: self._phase_sync())
        self.add(S + "DATA:VOLatile:CLEar", set=lambda c: None)
        self.add(S + "DATA:VOLatile:CATalog", query=lambda c: '"INT:\\BUILTIN\\EXP_RISE.ARB"')

    def _phase_sync(self) -> None:
        """``PHASe:SYNChronize``: both channels restart at their programmed phase now."""
        now = self.clock()
        for n in self.ch:
            self.ch[n] = replace(self.ch[n], t_epoch=now)

    # -- ? MIN|MAX|DEF on every numeric query, angles, and the rest of the common commands ----------
    def _limited(self, value: Callable[[Call], float], limits: Callable[[Call], tuple[float, float]],
                 default: float, fmt: Callable[[float], str] | None = None) -> Callable[[Call], str]:
        """A numeric query answering ``? MIN|MAX|DEF`` (the limits now, the ``*RST`` value) too."""
        out = fmt or self.flevel

        def query(c: Call) -> str:
            if c.params:
                return out(self.query_limit(c, limits(c), default))
            return out(value(c))
        return query

    def _offset_limits(self, n: int) -> tuple[float, float]:
        """Offset (and high/low level) range for the declared load: +-10 V open circuit."""
        lim = (MAX_VPP_OPEN / 2) / self._factor(n)
        return -lim, lim

    #: UNIT:ANGLe: radians per unit (SECond is a time: the phase as a delay at the frequency)
    _ANGLE = {"DEG": np.pi / 180, "RAD": 1.0}

    def _angle_unit(self) -> str:
        return str(self.settings.get("angle_unit", "DEG"))

    def _angle(self, text: str) -> float:
        """A phase in ``UNIT:ANGLe``'s unit (-360..360 degrees) as radians."""
        k = self._ANGLE[self._angle_unit()]
        return self.num(text, "", -2 * np.pi / k, 2 * np.pi / k, 0.0) * k

    def _angle_out(self, rad: float) -> float:
        return rad / self._ANGLE[self._angle_unit()]

    def _angle_limits(self) -> tuple[float, float]:
        k = self._ANGLE[self._angle_unit()]
        return -2 * np.pi / k, 2 * np.pi / k

    def _build_common(self) -> None:
        """UNIT:ANGLe, MARKer, DATA:ARBitrary, *SAV/*RCL (KS "UNIT Subsystem", "MARKer Subsystem",
        "DATA Subsystem", IEEE 488.2 10.27/10.29)."""
        S = "[SOURce#:]"
        self.setting("UNIT:ANGLe", "angle_unit", "DEG", lambda t: parse_enum(t, ["DEGree", "RADian"]), str)
        self.setting(S + "MARKer:FREQuency", "marker_hz", 500.0, lambda t: self.num(t, "HZ", MIN_FREQ_HZ, MAX_FREQ_HZ),
                     self.fnum, True, (MIN_FREQ_HZ, MAX_FREQ_HZ))
        self.setting(S + "MARKer:CYCLe", "marker_cycle", 2.0, lambda t: self.num(t, "", 2, 1e8), self.fnum, True,
                     (2.0, 1e8))
        self.setting(S + "MARKer:POINt", "marker_point", 32.0, lambda t: self.num(t, "", 4, 65536), self.fnum, True,
                     (4.0, 65536.0))
        self.arbs: dict[str, int] = {}
        self.add(S + "DATA:ARBitrary", set=self._data_arb)
        self.add(S + "DATA:ATTRibute:POINts", query=lambda c: self.fnum(self._arb(c.one())))
        self.saved: dict[int, SavedState] = {}
        self.add("*SAV", set=lambda c: self.saved.__setitem__(self._slot(c), self._state_copy()))
        self.add("*RCL", set=lambda c: self._recall(self._slot(c)))

    def _arb(self, name: str) -> int:
        key = name.strip().strip('"').upper()
        if key not in self.arbs:
            raise ScpiError(-224, "Illegal parameter value;no such arbitrary waveform")
        return self.arbs[key]

    def _data_arb(self, c: Call) -> None:
        """``DATA:ARB <name>,<block of float32>`` or ``<name>,<v>,<v>...`` (values -1..1, 8 to 65536
        points): kept in volatile memory under ``name``."""
        if len(c.params) < 2:
            raise ScpiError(-109)
        name, data = c.params[0].strip().strip('"'), c.params[1:]
        if len(data) == 1 and data[0].startswith("#"):
            raw = data[0].encode("latin-1")
            n = int(raw[1:2])
            size = int(raw[2:2 + n]) if n else -1
            if n == 0 or len(raw) != 2 + n + size or size % 4:
                raise ScpiError(-161, "Invalid block data")
            points = size // 4
        else:
            values = [self.num(v, "", -1.0, 1.0) for v in data]
            points = len(values)
        if not 8 <= points <= 65536:
            raise ScpiError(-222, "Data out of range;8 to 65536 points")
        self.arbs[name.upper()] = points

    def _slot(self, c: Call) -> int:
        return int(self.num(c.one(), "", 0, 4))

    def _state_copy(self) -> SavedState:
        import copy
        return SavedState(copy.deepcopy(self.settings), dict(self.load), dict(self.vunit), dict(self.sync),
                          dict(self.ch))

    def _recall(self, slot: int) -> None:
        """``*RCL``: the saved settings back; outputs stay as they are (488.2 10.29: the state, not
        the outputs, which the 33500B turns off on recall only from power-on)."""
        import copy
        if slot not in self.saved:
            raise ScpiError(-221, "Settings conflict;nothing stored in that state")
        saved = self.saved[slot]
        self.settings.update(copy.deepcopy(saved.settings))
        self.load.update(saved.load)
        self.vunit.update(saved.vunit)
        self.sync.update(saved.sync)
        keep = ("on", "t_epoch", "trig_times")
        for n, d in saved.ch.items():
            self._update(n, **{k: v for k, v in d.__dict__.items() if k not in keep})

    def _set_offset(self, c: Call) -> None:
        n = self._chan(c)
        f = self._factor(n)
        limit = (MAX_VPP_OPEN / 2) / f
        off = self.num(c.one(), "V", -limit, limit, 0.0) * f
        if abs(off) + self.ch[n].amp_v > MAX_VPP_OPEN / 2 + 1e-12:
            self.push_error(-221, "Settings conflict;offset changed due to amplitude")
            off = np.sign(off) * (MAX_VPP_OPEN / 2 - self.ch[n].amp_v)
        self._update(n, offset_v=off)

    def _set_load(self, c: Call) -> None:
        n = self._chan(c)
        word = c.one().strip().upper()
        if word in ("INF", "INFINITY"):
            load = float("inf")
        else:
            load = self.num(word, "OHM", 1.0, 10e3, 50.0)
        self.load[n] = load  # the output voltage is kept; the displayed amplitude rescales

    def _load_query(self, c: Call) -> str:
        if c.params:     # OUTPut:LOAD? {MINimum|MAXimum|DEFault}: 1 ohm, 10 kohm, 50 ohm
            return self.fnum(self.query_limit(c, (1.0, 10e3), 50.0))
        load = self.load[self._chan(c)]
        return self.inf_reply if np.isinf(load) else self.fnum(load)

    def _apply_sin(self, c: Call) -> None:
        n = self._chan(c)
        params = c.params
        self._update(n, func="SIN", sweep=False, burst=False)
        if len(params) > 0 and params[0].upper() not in ("DEF", ""):
            self._update(n, freq_hz=self.num(params[0], "HZ", MIN_FREQ_HZ, MAX_FREQ_HZ, 1000.0))
        if len(params) > 1 and params[1].upper() not in ("DEF", ""):
            self._set_amp(n, params[1])
        if len(params) > 2 and params[2].upper() not in ("DEF", ""):
            self._set_offset(Call([params[2]], [n], c.header, False))
        if len(params) > 3:
            raise ScpiError(-108)
        self._set_output(n, True)  # APPLy turns the output on, as on the instrument

    def _apply_query(self, n: int) -> str:
        d = self.ch[n]
        return (f'"{d.func} {self.flevel(d.freq_hz)},{self.flevel(self._display_vpp(n))},'
                f'{self.flevel(d.offset_v / self._factor(n))}"')

    def _trigger(self, channels: list[int], force: bool, source: str = "BUS") -> None:
        """A trigger event: each channel waiting for ``source`` (or any, with ``force``) starts.

        As on the instrument, a trigger that arrives while a burst is still
        being output is ignored.
        """
        now = self.clock()
        for n in channels:
            d = self.ch[n]
            if not (force or d.trig_source == source):
                continue
            if d.burst and d.trig_times and d.trig_times[-1] >= d.t_epoch and \
                    now < d.trig_times[-1] + d.burst_length_s():
                continue
            start = now + self.trigger_delay(n)
            self.ch[n] = replace(d, trig_times=(d.trig_times + (start,))[-64:])
            if d.burst and d.on and not d.burst_gated:
                self.on_burst(n, start, start + d.burst_length_s())

    def trigger_delay(self, n: int) -> float:
        """Seconds from a trigger to the triggered burst or sweep (``TRIGger<n>:DELay``)."""
        return float(self.get("trig_delay", n))

    def external_trigger(self) -> None:
        """A rising edge at the rear-panel Ext Trig input (channels with ``TRIG:SOUR EXT``)."""
        with self.lock:
            self._trigger(list(self.ch), force=False, source="EXT")

#: Rigol trigger-source words and the simulation's (INTernal, EXTernal, MANual = *TRG)
_RIGOL_TRIG = {"INT": "IMM", "EXT": "EXT", "MAN": "BUS"}


class SimRigolDG1000Z(SimKeysight33500B):
    """The simulated Rigol DG1000Z (DG1062Z by default): the same output physics, Rigol's dialect.

    DG1000Z Programming Guide facts used: ``:SOURce<n>:`` and ``:OUTPut<n>``
    prefixes; the output state answers ``ON``/``OFF``; ``:OUTPut<n>:LOAD``
    (also ``:IMPedance``) ``<ohm>|INFinity``, answering ``INFINITY``;
    numbers answer as ``1.000000E+03``; integers without a sign; the empty
    error queue answers ``0,"No error"``; bursts ``:SOURce<n>:BURSt[:STATe]
    ON|OFF``, ``:BURSt:MODE TRIGgered|GATed|INFinity``, ``:BURSt:NCYCles``,
    trigger sources ``:SOURce<n>:BURSt:TRIGger:SOURce INTernal|EXTernal|MANual``
    and ``:SOURce<n>:SWEep:TRIGger:SOURce`` (same words), ``*TRG`` or
    ``:SOURce<n>:BURSt:TRIGger[:IMMediate]``.
    """

    name = "funcgen"
    int_sign = False
    no_error = '0,"No error"'
    models = MODELS_DG1000Z
    idn_format = "Rigol Technologies,{model},DG1ZA000000001,00.01.14"
    #: DG1000Z factory defaults: 1 kHz sine, 5 Vpp, offset 0, output impedance HighZ
    default_vpp = 5.0
    default_load_ohm = float("inf")

    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 on_output: Callable[[int, bool], None] | None = None, *, model: str = "DG1062Z",
                 on_burst: BurstFn | None = None) -> None:
        super().__init__(clock, on_output, model=model, on_burst=on_burst)

    def fnum(self, value: float) -> str:
        return f"{value:E}"

    def flevel(self, value: float) -> str:
        return f"{value:E}"

    inf_reply = "9.900000E+37"

    def build(self) -> None:
        super().build()
        S = ":SOURce#:"
        add = self.add
        # Rigol answers ON/OFF for the output state (the table is searched in order: first wins)
        self.commands = [cmd for cmd in self.commands if cmd.pattern not in ("OUTPut#[:STATe]",)]
        add("OUTPut#[:STATe]", set=lambda c: self._set_output(self._chan(c), parse_bool(c.one())),
            query=lambda c: "ON" if self.ch[self._chan(c)].on else "OFF")
        add("OUTPut#:IMPedance", set=self._set_load, query=self._load_query)
        add(S + "BURSt[:STATe]", set=lambda c: self._update(self._chan(c), burst=parse_bool(c.one())),
            query=lambda c: "ON" if self.ch[self._chan(c)].burst else "OFF")
        add(S + "BURSt:TRIGger:SOURce", set=self._set_rigol_trig, query=self._rigol_trig_query)
        self.commands = [cmd for cmd in self.commands
                         if cmd.pattern not in ("[SOURce#:]BURSt:MODE", "[SOURce#:]APPLy")]
        add(S + "BURSt:MODE", set=self._set_rigol_burst_mode, query=self._rigol_burst_mode_query)
        add(S + "APPLy", query=lambda c: self._rigol_apply_query(self._chan(c)))
        self.commands = [cmd for cmd in self.commands if cmd.pattern not in ("[SOURce#:]APPLy:SINusoid",
                                                                             "OUTPut#:SYNC[:STATe]",
                                                                             "OUTPut#:SYNC:POLarity")]
        add(S + "APPLy:SINusoid", set=self._rigol_apply_sin)
        add("OUTPut#:SYNC[:STATe]", set=lambda c: self.sync.__setitem__(self._chan(c), parse_bool(c.one())),
            query=lambda c: "ON" if self.sync[self._chan(c)] else "OFF")
        self.setting("OUTPut#:SYNC:POLarity", "sync_pol", "POS", lambda t: parse_enum(t, ["POSitive", "NEGative"]),
                     str, True)
        add(S + "SWEep:TRIGger:SOURce", set=self._set_rigol_trig, query=self._rigol_trig_query)
        add(S + "BURSt:TRIGger[:IMMediate]", set=lambda c: self._trigger([self._chan(c)], force=True))
        add(S + "SWEep:TRIGger[:IMMediate]", set=lambda c: self._trigger([self._chan(c)], force=True))
        # burst settings QCoDeS's RigolDG1062 reads on snapshot (DG1000Z Programming Guide,
        # PGB09103-1110, :SOURce:BURSt and :OUTPut): stored, answered, reset by *RST. TDELay
        # delays a triggered burst (external/manual trigger: 0 to 100 s). The guide has no
        # :BURSt:IDLE (a DG4000/DG800 command): -113 here too.
        self.setting(S + "BURSt:TDELay", "burst_tdelay", 0.0, lambda t: self.num(t, "S", 0.0, 100.0), self.fnum,
                     True, (0.0, 100.0))
        self.setting(S + "BURSt:TRIGger:SLOPe", "burst_trig_slope", "POS",
                     lambda t: parse_enum(t, ["POSitive", "NEGative"]), str, True)
        self.setting("OUTPut#:GATe:POLarity", "gate_out_pol", "POSITIVE",
                     lambda t: {"POS": "POSITIVE", "NEG": "NEGATIVE"}[parse_enum(t, ["POSitive", "NEGative"])],
                     str, True)

    def sync_channel(self) -> int | None:
        """The lab cables channel 1's rear-panel sync to the scope: on with ``:OUTPut1:SYNC ON``."""
        return 1 if self.sync[1] else None

    def sync_inverted(self, n: int) -> bool:
        return self.get("sync_pol", n) == "NEG"

    def trigger_delay(self, n: int) -> float:
        """``:SOURce<n>:BURSt:TDELay``: the burst starts this long after its trigger."""
        return float(self.get("burst_tdelay", n)) if self.ch[n].burst else 0.0

    def _load_query(self, c: Call) -> str:
        load = self.load[self._chan(c)]
        return "INFINITY" if np.isinf(load) else self.fnum(load)

    def _set_rigol_burst_mode(self, c: Call) -> None:
        """``TRIGgered`` (N cycles), ``GATed``, ``INFinity`` (cycles until the burst is switched off)."""
        n = self._chan(c)
        mode = parse_enum(c.one(), ["TRIGgered", "GATed", "INFinity"])
        if mode == "INF":
            self._update(n, burst_gated=False, ncycles=float("inf"))
        else:
            cycles = self.ch[n].ncycles
            self._update(n, burst_gated=mode == "GAT", ncycles=1.0 if np.isinf(cycles) else cycles)

    def _rigol_burst_mode_query(self, c: Call) -> str:
        d = self.ch[self._chan(c)]
        return "GAT" if d.burst_gated else ("INF" if np.isinf(d.ncycles) else "TRIG")

    def _rigol_apply_sin(self, c: Call) -> None:
        """``:SOURce<n>:APPLy:SINusoid [<freq>[,<amp>[,<offset>[,<phase>]]]]`` (DG1000Z: a fourth, the phase)."""
        if len(c.params) > 4:
            raise ScpiError(-108)
        if len(c.params) == 4 and c.params[3].upper() not in ("DEF", ""):
            self._update(self._chan(c), phase_rad=np.deg2rad(self.num(c.params[3], "", 0, 360, 0)))
        self._apply_sin(Call(c.params[:3], c.suffixes, c.header, False))

    def _rigol_apply_query(self, n: int) -> str:
        """``"SIN,1.000000E+03,5.000000E+00,0.000000E+00,0.000000E+00"``: function, frequency,
        amplitude, offset, phase."""
        d = self.ch[n]
        values = (d.freq_hz, self._display_vpp(n), d.offset_v / self._factor(n), np.rad2deg(d.phase_rad))
        return '"' + ",".join([d.func, *(self.fnum(v) for v in values)]) + '"'

    def _set_rigol_trig(self, c: Call) -> None:
        word = parse_enum(c.one(), ["INTernal", "EXTernal", "MANual"])
        self._update(self._chan(c), False, trig_source=_RIGOL_TRIG[word])

    def _rigol_trig_query(self, c: Call) -> str:
        src = self.ch[self._chan(c)].trig_source
        return {v: k for k, v in _RIGOL_TRIG.items()}.get(src, "INT")


class SimAgilent33220A(SimKeysight33500B):
    """The simulated Agilent 33220A: one channel, commands without ``SOURce``/``OUTPut`` suffixes.

    The 33500B's command set is the 33220A's with channel suffixes, so the
    same table serves (33220A User's Guide, chapter 4: ``FUNC``, ``FREQ``,
    ``VOLT``, ``VOLT:OFFS``, ``OUTP:LOAD``, ``OUTP``, ``BURS:...``,
    ``TRIG:SOUR``, ``*TRG``); a suffix 2 is ``-114``.
    """

    models = {"33220A": 1}
    idn_format = "Agilent Technologies,{model},MY44000000,2.07-2.06-22-2"

    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 on_output: Callable[[int, bool], None] | None = None, *, model: str = "33220A",
                 on_burst: BurstFn | None = None) -> None:
        super().__init__(clock, on_output, model=model, on_burst=on_burst)

    def build(self) -> None:
        """The 33500B table, with the 33220A's own spellings: ``PULSe:PERiod`` (not
        ``FUNCtion:PULSe:PERiod``) and the arbitrary waveform as ``FUNCtion USER``."""
        super().build()
        self.commands = [cmd for cmd in self.commands if cmd.pattern != "[SOURce#:]FUNCtion[:SHAPe]"]
        self.add("[SOURce#:]FUNCtion[:SHAPe]",
                 set=lambda c: self._update(self._chan(c), func=parse_enum(
                     c.one(), ["SINusoid", "SQUare", "RAMP", "PULSe", "NOISe", "DC", "USER"])),
                 query=lambda c: self.ch[self._chan(c)].func)
        def set_period(c: Call) -> None:   # the same setting as FUNCtion:PULSe:PERiod (reset by *RST)
            self.settings["pulse_period"][self._chan(c)] = self.num(c.one(), "S", 200e-9, 2000.0)

        self.add("[SOURce#:]PULSe:PERiod", set=set_period, query=lambda c: self.fnum(
            self.query_limit(c, (200e-9, 2000.0), 1e-3) if c.params else self.get("pulse_period", self._chan(c))))
