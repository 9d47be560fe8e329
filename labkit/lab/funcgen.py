"""A simulated Keysight 33500B (33522B, two channels) on a raw SCPI socket.

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

import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from labkit.lab.scpi import Call, ScpiError, ScpiInstrument, fmt_num, parse_bool, parse_enum

MAX_FREQ_HZ = 30e6
MIN_FREQ_HZ = 1e-6
SOURCE_OHM = 50.0
MAX_VPP_OPEN = 20.0   # open-circuit (10 Vpp into 50 ohm)


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
    t_epoch: float = 0.0
    sweep: bool = False
    start_hz: float = 100.0
    stop_hz: float = 1000.0
    sweep_s: float = 1.0
    hold_s: float = 0.0
    return_s: float = 0.0
    log_spacing: bool = False
    burst: bool = False
    ncycles: int = 1
    burst_period_s: float = 0.01
    trig_source: str = "IMM"
    trig_times: tuple[float, ...] = field(default=())

    # -- what kind of signal ------------------------------------------------------------------
    def is_sine(self) -> bool:
        """A plain continuous sine (the analytic steady state applies)."""
        return self.on and self.func == "SIN" and not self.sweep and not self.burst

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
        if self.burst:
            gate = np.zeros(t.shape, dtype=bool)
            length = self.ncycles / self.freq_hz
            for s in self.starts(float(t.min()), float(t.max())):
                gate |= (t >= s) & (t < s + length)
            local = np.zeros_like(t)
            for s in self.starts(float(t.min()), float(t.max())):
                sel = (t >= s) & (t < s + length)
                local[sel] = 2 * np.pi * self.freq_hz * (t[sel] - s) + self.phase_rad
            wave = np.where(gate, _shape(self.func, local), 0.0)
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


def _shape(func: str, phase: np.ndarray) -> np.ndarray:
    if func == "SQU":
        return np.where(np.sin(phase) >= 0, 1.0, -1.0)
    if func in ("RAMP", "TRI"):
        x = np.mod(phase / (2 * np.pi), 1.0)
        if func == "TRI":
            return 1 - 4 * np.abs(x - 0.5)
        return 2 * x - 1
    return np.sin(phase)


class Keysight33500B(ScpiInstrument):
    """The simulated two-channel generator; ``drive(ch)`` is its output for the physics."""

    name = "funcgen"
    idn = "Keysight Technologies,33522B,MY5740LAB1,4.03-1.19-2.00-52-00"

    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 on_output: Callable[[int, bool], None] | None = None) -> None:
        self.clock = clock
        self.on_output = on_output or (lambda ch, on: None)
        self.ch = {1: self._default(), 2: self._default()}
        self.load = {1: SOURCE_OHM, 2: SOURCE_OHM}   # declared load, ohm (inf for high Z)
        self.vunit = {1: "VPP", 2: "VPP"}
        self.sync = {1: True, 2: False}
        super().__init__()

    def _default(self) -> Drive:
        # 33500B power-on: 1 kHz sine, 100 mVpp into 50 ohm (200 mV peak-to-peak open circuit)
        return Drive(amp_v=0.1, t_epoch=self.clock())

    def reset(self) -> None:
        super().reset()
        for n in (1, 2):
            was_on = self.ch[n].on
            self.ch[n] = self._default()
            self.load[n] = SOURCE_OHM
            self.vunit[n] = "VPP"
            if was_on:
                self.on_output(n, False)

    def drive(self, channel: int = 1) -> Drive:
        with self.lock:
            return self.ch[channel]

    # -- helpers ------------------------------------------------------------------------------
    def _chan(self, c: Call, i: int = 0) -> int:
        n = c.suffix(i)
        if n not in (1, 2):
            raise ScpiError(-113, "Undefined header;channel suffix")
        return n

    def _update(self, n: int, new_epoch: bool = True, **kw) -> None:
        if new_epoch:
            kw["t_epoch"] = self.clock()
        self.ch[n] = replace(self.ch[n], **kw)

    def _factor(self, n: int) -> float:
        """Open-circuit volts per programmed volt for the declared load."""
        load = self.load[n]
        return 1.0 if np.isinf(load) else (load + SOURCE_OHM) / load

    def _display_vpp(self, n: int) -> float:
        return 2 * self.ch[n].amp_v / self._factor(n)

    def _set_amp(self, n: int, text: str) -> None:
        f = self._factor(n)
        limit = MAX_VPP_OPEN / f
        if self.vunit[n] == "VRMS":
            value = self.num(text, "V", 1e-3 / (2 * 2 ** 0.5), limit / (2 * 2 ** 0.5), 0.1 / (2 * 2 ** 0.5))
            vpp = value * 2 * 2 ** 0.5
        else:
            vpp = self.num(text, "V", 1e-3, limit, 0.1)
        # amplitude and offset together must stay inside the output's +-10 V (open circuit)
        if vpp * f / 2 + abs(self.ch[n].offset_v) > MAX_VPP_OPEN / 2 + 1e-12:
            self.push_error(-221, "Settings conflict;amplitude changed due to offset")
            vpp = 2 * (MAX_VPP_OPEN / 2 - abs(self.ch[n].offset_v)) / f
        self._update(n, amp_v=vpp * f / 2)

    def _amp_query(self, n: int, c: Call) -> str:
        if c.params:
            word = c.params[0].upper()[:3]
            if word == "MAX":
                return fmt_num(MAX_VPP_OPEN / self._factor(n))
            if word == "MIN":
                return fmt_num(1e-3)
        vpp = self._display_vpp(n)
        return fmt_num(vpp / (2 * 2 ** 0.5) if self.vunit[n] == "VRMS" else vpp)

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
                if c.params and c.params[0].upper().startswith("MIN"):
                    return fmt_num(lo)
                if c.params and c.params[0].upper().startswith("MAX"):
                    return fmt_num(hi)
                return fmt_num(getattr(self.ch[n], key))
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
        add(S + "VOLTage:UNIT",
            set=lambda c: self.vunit.__setitem__(self._chan(c), parse_enum(c.one(), ["VPP", "VRMS"])),
            query=lambda c: self.vunit[self._chan(c)])
        add(S + "VOLTage[:LEVel][:IMMediate]:OFFSet", set=self._set_offset,
            query=lambda c: fmt_num(self.ch[self._chan(c)].offset_v / self._factor(self._chan(c))))
        add(S + "PHASe[:ADJust]",
            set=lambda c: self._update(self._chan(c), phase_rad=np.deg2rad(self.num(c.one(), "", -360, 360, 0))),
            query=lambda c: fmt_num(np.rad2deg(self.ch[self._chan(c)].phase_rad)))
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
        add(S + "BURSt:MODE", set=lambda c: parse_enum(c.one(), ["TRIGgered", "GATed"]),
            query=lambda c: "TRIG")
        add(S + "BURSt:NCYCles",
            set=lambda c: self._update(self._chan(c), ncycles=int(self.num(c.one(), "", 1, 1e8, 1))),
            query=lambda c: fmt_num(self.ch[self._chan(c)].ncycles))
        add(S + "BURSt:INTernal:PERiod", set=fset("burst_period_s", "S", 1e-6, 8000.0, 0.01),
            query=fget("burst_period_s", 1e-6, 8000.0))
        add(S + "BURSt:PHASe",
            set=lambda c: self._update(self._chan(c), phase_rad=np.deg2rad(self.num(c.one(), "", -360, 360, 0))),
            query=lambda c: fmt_num(np.rad2deg(self.ch[self._chan(c)].phase_rad)))
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
        add("*TRG", set=lambda c: self._trigger([1, 2], force=False))

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
        load = self.load[self._chan(c)]
        return "+9.9E+37" if np.isinf(load) else fmt_num(load)

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
        return f'"{d.func} {d.freq_hz:+.15E},{self._display_vpp(n):+.15E},{d.offset_v / self._factor(n):+.15E}"'

    def _trigger(self, channels: list[int], force: bool) -> None:
        now = self.clock()
        for n in channels:
            d = self.ch[n]
            if force or d.trig_source == "BUS":
                self.ch[n] = replace(d, trig_times=(d.trig_times + (now,))[-64:])
