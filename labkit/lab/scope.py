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
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from labkit.lab.scpi import (Call, ScpiError, ScpiInstrument, definite_block, fmt_int, fmt_num,
                             parse_bool, parse_enum)

NORMAL_MAX_POINTS = 62_500
RAW_MAX_POINTS = 8_000_000
AUTO_TRIGGER_S = 0.05


@dataclass
class Acquisition:
    """One record: its times (relative to the trigger) and every channel's volts."""

    points: int
    xinc_s: float
    xorig_s: float
    t_arm: float
    t_trig: float | None = None
    volts: dict[int, np.ndarray] = field(default_factory=dict)
    done: threading.Event = field(default_factory=threading.Event)
    cancelled: bool = False
    error: str | None = None


# signals(t_abs, rng, channels) -> {channel: volts}; sync(source, t_min) -> trigger time or None
SignalFn = Callable[[np.ndarray, np.random.Generator, tuple[int, ...]], dict[int, np.ndarray]]
SyncFn = Callable[[str, float], float | None]


class InfiniiVision(ScpiInstrument):
    name = "scope"
    idn = "KEYSIGHT TECHNOLOGIES,DSOX3024T,MY5842LAB2,07.50.2021102830"

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
        super().__init__()

    # -- settings -------------------------------------------------------------------------------
    def build(self) -> None:
        pos = lambda lo, hi: (lambda t: self.num(t, "", lo, hi))  # noqa: E731
        self.setting(":CHANnel#:SCALe", "scale", 1.0, lambda t: self.num(t, "V", 1e-3, 50.0), fmt_num, True)
        self.setting(":CHANnel#:OFFSet", "offset", 0.0, lambda t: self.num(t, "V", -400.0, 400.0), fmt_num, True)
        self.setting(":CHANnel#:COUPling", "coupling", "DC", lambda t: parse_enum(t, ["DC", "AC"]), str, True)
        self.setting(":CHANnel#:DISPlay", "display", False, parse_bool, lambda v: "1" if v else "0", True)
        self.settings["display"][1] = True   # power-on: channel 1 only
        self.setting(":CHANnel#:PROBe", "probe", 1.0, pos(1e-3, 1e4), fmt_num, True)
        self.setting(":CHANnel#:IMPedance", "impedance", "ONEM", lambda t: parse_enum(t, ["ONEMeg", "FIFTy"]),
                     str, True)
        self.setting(":CHANnel#:BWLimit", "bwlimit", False, parse_bool, lambda v: "1" if v else "0", True)
        self.add(":CHANnel#:RANGe", set=lambda c: self._chan_range(c), query=lambda c: fmt_num(
            8 * self.get("scale", self._ch(c))))
        self.setting(":TIMebase:RANGe", "range", 1e-3, lambda t: self.num(t, "S", 2e-8, 500.0), fmt_num)
        self.add(":TIMebase:SCALe", set=lambda c: self.settings.__setitem__(
            "range", 10 * self.num(c.one(), "S", 2e-9, 50.0)), query=lambda c: fmt_num(self.get("range") / 10))
        self.setting(":TIMebase:POSition", "position", 0.0, lambda t: self.num(t, "S", -500.0, 500.0), fmt_num)
        self.setting(":TIMebase:REFerence", "reference", "CENT",
                     lambda t: parse_enum(t, ["LEFT", "CENTer", "RIGHt"]), str)
        self.setting(":TIMebase:MODE", "tb_mode", "MAIN", lambda t: parse_enum(t, ["MAIN", "WINDow", "XY", "ROLL"]),
                     str)
        self.setting(":ACQuire:TYPE", "acq_type", "NORM",
                     lambda t: parse_enum(t, ["NORMal", "AVERage", "HRESolution", "PEAK"]), str)
        self.setting(":ACQuire:COUNt", "acq_count", 8, lambda t: int(self.num(t, "", 1, 65536)), fmt_int)
        self.setting(":TRIGger:MODE", "trig_mode", "EDGE", lambda t: parse_enum(t, ["EDGE", "GLITch", "PATTern"]), str)
        self.setting(":TRIGger[:EDGE]:SOURce", "trig_source", "CHAN1",
                     lambda t: parse_enum(t, ["CHANnel1", "CHANnel2", "CHANnel3", "CHANnel4", "EXTernal", "LINE"]),
                     str)
        self.setting(":TRIGger[:EDGE]:LEVel", "trig_level", 0.0, lambda t: self.num(t, "V", -400.0, 400.0), fmt_num)
        self.setting(":TRIGger[:EDGE]:SLOPe", "trig_slope", "POS",
                     lambda t: parse_enum(t, ["POSitive", "NEGative", "EITHer", "ALTernate"]), str)
        self.setting(":TRIGger:SWEep", "trig_sweep", "AUTO", lambda t: parse_enum(t, ["AUTO", "NORMal"]), str)
        self.setting(":WAVeform:SOURce", "wav_source", "CHAN1",
                     lambda t: parse_enum(t, ["CHANnel1", "CHANnel2", "CHANnel3", "CHANnel4"]), str)
        self.setting(":WAVeform:FORMat", "wav_format", "BYTE", lambda t: parse_enum(t, ["BYTE", "WORD", "ASCii"]),
                     lambda v: "ASC" if v == "ASC" else v)
        self.setting(":WAVeform:POINts:MODE", "points_mode", "NORM",
                     lambda t: parse_enum(t, ["NORMal", "MAXimum", "RAW"]), str)
        self.add(":WAVeform:POINts", set=self._set_points, query=lambda c: fmt_int(self._points_out()))
        self.setting(":WAVeform:BYTeorder", "byteorder", "MSBF", lambda t: parse_enum(t, ["MSBFirst", "LSBFirst"]),
                     str)
        self.setting(":WAVeform:UNSigned", "unsigned", True, parse_bool, lambda v: "1" if v else "0")
        self.add(":WAVeform:PREamble", query=lambda c: self._preamble())
        self.add(":WAVeform:DATA", query=lambda c: self._data())
        self.add(":WAVeform:XINCrement", query=lambda c: fmt_num(self._scaling()[0]))
        self.add(":WAVeform:XORigin", query=lambda c: fmt_num(self._scaling()[1]))
        self.add(":WAVeform:YINCrement", query=lambda c: fmt_num(self._scaling()[2]))
        self.add(":WAVeform:YORigin", query=lambda c: fmt_num(self._scaling()[3]))
        self.add(":WAVeform:YREFerence", query=lambda c: fmt_int(self._scaling()[4]))
        self.add(":ACQuire:POINts", query=lambda c: fmt_int(self._last_acq().points))
        self.add(":ACQuire:SRATe", query=lambda c: fmt_num(self._points_out() / self.get("range")))
        self.add(":DIGitize", set=self._digitize)
        self.add(":SINGle", set=lambda c: self._arm("SING"))
        self.add(":RUN", set=lambda c: self._run())
        self.add(":STOP", set=lambda c: self._stop())
        self.add(":AUToscale", set=lambda c: None)
        self.add(":RSTate", query=lambda c: self.run_state if self.run_state != "SING" or not self._done()
                 else "STOP")
        self.add(":ASTate", query=lambda c: self._astate())
        self.add(":TER", query=lambda c: self._ter())
        self.add(":OPERegister:CONDition", query=lambda c: fmt_int(0 if self._stopped() else 8))
        self.add(":OPERegister[:EVENt]", query=lambda c: fmt_int(0 if self._stopped() else 8))

    def reset(self) -> None:
        super().reset()
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

    def _points_out(self) -> int:
        """Points a transfer returns: the request, capped by the mode and what was acquired."""
        want = self.settings.get("points", 1000)
        if self.get("points_mode") == "NORM":
            want = min(want, NORMAL_MAX_POINTS)
        acq = self.acq
        if acq is not None and acq.done.is_set():
            want = min(want, acq.points)
        return int(want)

    # -- acquisition --------------------------------------------------------------------------
    def _record_geometry(self) -> tuple[int, float, float]:
        """Acquisition depth: the requested transfer size, within the memory (and 62 500 in NORMal)."""
        points = min(self.settings.get("points", 1000), self.memory_points)
        if self.get("points_mode") == "NORM":
            points = min(points, NORMAL_MAX_POINTS)
        rng = self.get("range")
        ref = {"LEFT": 0.1, "CENT": 0.5, "RIGH": 0.9}[self.get("reference")]
        xinc = rng / points
        xorig = self.get("position") - ref * rng
        return int(points), xinc, xorig

    def _arm(self, state: str) -> Acquisition:
        self._cancel()
        points, xinc, xorig = self._record_geometry()
        acq = Acquisition(points, xinc, xorig, t_arm=self.clock())
        self.acq = acq
        self.run_state = state
        self.n_acq += 1
        source = self.get("trig_source")
        sweep_mode = self.get("trig_sweep")
        seed = (self.seed, self.n_acq)
        threading.Thread(target=self._acquire, args=(acq, source, sweep_mode, seed), daemon=True,
                         name="lab-scope-acq").start()
        return acq

    def _acquire(self, acq: Acquisition, source: str, sweep_mode: str, seed: tuple[int, int]) -> None:
        """Wait for a trigger in real time, then for the post-trigger time; compute the record."""
        try:
            t_min = acq.t_arm + max(0.0, -acq.xorig_s)  # the pre-trigger part must be filled first
            while not acq.cancelled:
                now = self.clock()
                t_trig = self.sync(source, t_min)
                if t_trig is None and sweep_mode == "AUTO" and now >= t_min + AUTO_TRIGGER_S:
                    t_trig = now   # auto trigger: no edge came
                if t_trig is not None:
                    break
                time.sleep(0.002)
            if acq.cancelled:
                return
            acq.t_trig = t_trig
            t_end = t_trig + acq.xorig_s + acq.points * acq.xinc_s
            while not acq.cancelled and self.clock() < t_end:
                time.sleep(min(0.01, max(0.0, t_end - self.clock())))
            if acq.cancelled:
                return
            t_abs = t_trig + acq.xorig_s + acq.xinc_s * np.arange(acq.points)
            acq.volts = self.signals(t_abs, np.random.default_rng(list(seed)), self._displayed())
            self.triggered = True
        except Exception as exc:  # keep the scope answering; the record reads as zeros
            acq.error = f"{type(exc).__name__}: {exc}"
            acq.volts = {}
        finally:
            acq.done.set()
            with self._cond:
                self._cond.notify_all()

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
        acq = Acquisition(points, xinc, xorig, t_arm=now)
        acq.t_trig = now - (xorig + points * xinc)
        self.n_acq += 1
        t_abs = acq.t_trig + xorig + xinc * np.arange(points)
        acq.volts = self.signals(t_abs, np.random.default_rng([self.seed, self.n_acq]), self._displayed())
        acq.done.set()
        self.acq = acq
        return acq

    def _last_acq(self) -> Acquisition:
        if self.run_state == "RUN":
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
        if acq is None:
            points, xinc, xorig = self._record_geometry()
            step = 1
        else:
            points, xinc, xorig = acq.points, acq.xinc_s, acq.xorig_s
            want = min(self.settings.get("points", 1000),
                       NORMAL_MAX_POINTS if self.get("points_mode") == "NORM" else RAW_MAX_POINTS)
            step = max(1, points // max(1, want))
            points = len(range(0, acq.points, step))
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
        step = max(1, acq.points // points) if points else 1
        volts = acq.volts.get(ch)
        if volts is None:   # switched on after the acquisition: nothing was digitised
            raise ScpiError(-230, "Data corrupt or stale;channel was off during the acquisition")
        volts = volts[::step][:points]
        fmt = self.get("wav_format")
        full = 5 * self.get("scale", ch)   # the ADC spans +-5 divisions about the offset
        if fmt == "ASC":
            text = ",".join(f"{v:+.6E}" for v in np.clip(volts, yorig - full, yorig + full))
            return definite_block(text.encode("ascii"))
        span = 65536 if fmt == "WORD" else 256
        lo = 0 if self.get("unsigned") else -span // 2
        codes = np.clip(np.rint((volts - yorig) / yinc + yref), lo, lo + span - 1)
        if fmt == "WORD":
            order = ">" if self.get("byteorder") == "MSBF" else "<"
            kind = "u2" if self.get("unsigned") else "i2"
            payload = codes.astype(order + kind).tobytes()
        else:
            payload = codes.astype("u1" if self.get("unsigned") else "i1").tobytes()
        return definite_block(payload)

    def close(self) -> None:
        self._cancel()
