"""Function generators: Keysight/Agilent 33220A, Keysight 33500B, Rigol DG1000Z.

They drive the PZT in-chip (through no amplifier: the volts at the output are
the volts at the film) or the shaker amplifier's input. Both loads are high
impedance, so every amplitude is preceded by the declared load (``load_ohm``,
default ``OUTP:LOAD INF``): with the factory 50 ohm setting a Keysight would
put twice the programmed voltage on the PZT. Amplitudes are given in volts
peak-to-peak at the load and sent in ``amplitude_unit`` (VPP, VRMS, or DBM into
a finite load), after ``VOLT:UNIT`` (docs/instruments.md).

Limits are declared settings checked BEFORE anything is sent:

``max_amp_vpp``
    the largest peak-to-peak amplitude allowed (the PZT's rating, or the
    amplifier's input cap, see :attr:`labkit.drivers.shaker.Amplifier2718.max_input_vpp`).
``max_v``
    the largest absolute voltage at the output, ``|offset| + amp/2``.
``max_freq_hz``
    the highest frequency allowed (optional).

Every setting method checks the error queue afterwards (``SYST:ERR?`` until
``+0,"No error"``); a non-zero entry raises InstrumentError carrying its text.
"""
from __future__ import annotations

import math
from typing import Any, ClassVar

from labkit.drivers.base import ScpiInstrument, check_choice, check_range
from labkit.errors import InstrumentError, LimitError


def _num(x: float) -> str:
    """SCPI number: shortest exact-enough text (``1000``, ``0.5``, ``1e-05``)."""
    return format(float(x), ".10g")


#: source impedance of every supported generator (ohm)
SOURCE_OHM = 50.0


def _unit_and_load(unit: str, load: float | str) -> tuple[str, float]:
    """Validate the ``amplitude_unit`` and ``load_ohm`` settings (ConfigError naming the key)."""
    from labkit.errors import ConfigError

    u = str(unit).upper()
    if u not in ("VPP", "VRMS", "DBM"):
        raise ConfigError(f"amplitude_unit {unit!r} is not VPP, VRMS or DBM", key="amplitude_unit",
                          expected='"VPP", "VRMS" or "DBM"')
    if isinstance(load, str) and load.strip().upper() in ("INF", "INFINITY"):
        r = math.inf
    else:
        try:
            r = float(load)
        except (TypeError, ValueError):
            r = math.nan
        if not 1.0 <= r <= 10e3:
            raise ConfigError(f"load_ohm {load!r} is not a load the generators accept", key="load_ohm",
                              expected='"INF" (high impedance: the PZT, an amplifier input) or 1 to 10000 ohm')
    if u == "DBM" and math.isinf(r):
        raise ConfigError("amplitude_unit DBM needs a finite load_ohm (power into a high-impedance load "
                          "is undefined; the generators refuse it)", key="amplitude_unit",
                          expected='"VPP" or "VRMS" with load_ohm = "INF", or a load_ohm in ohm')
    return u, r


def amplitude_in(unit: str, amp_vpp: float, load_ohm: float) -> float:
    """A sine's peak-to-peak volts at the load, in ``unit`` (VPP, VRMS, or DBM into ``load_ohm``)."""
    if unit == "VPP":
        return amp_vpp
    vrms = amp_vpp / (2 * math.sqrt(2))
    if unit == "VRMS":
        return vrms
    return 10 * math.log10(vrms ** 2 / load_ohm / 1e-3)


class FunctionGenerator(ScpiInstrument):
    """Common driver for SCPI function generators; subclasses give the command prefixes.

    Parameters
    ----------
    channel:
        Output channel (1 for single-channel models).
    max_amp_vpp, max_v, max_freq_hz:
        Declared limits (see the module docstring); None = only the model's range.
    check_errors:
        Query the error queue after every setting (default True; see
        :class:`labkit.drivers.base.ScpiInstrument`).
    """

    model = "funcgen"
    #: Channels the model has; safe_off turns every one of them off. The class value is the
    #: family's most; :meth:`connect` narrows it to the identified model's.
    channels: tuple[int, ...] = (1,)
    #: The family's models (the ``*IDN?`` model word) and their channel counts.
    known_models: ClassVar[dict[str, int]] = {}
    connect_on_open = True
    #: Output range into a high-impedance load (all three models: +-10 V, 20 Vpp).
    model_max_v: ClassVar[float] = 10.0

    def __init__(self, transport, *, name: str | None = None, channel: int = 1,
                 max_amp_vpp: float | None = None, max_v: float | None = None,
                 max_freq_hz: float | None = None, amplitude_unit: str = "VPP",
                 load_ohm: float | str = "INF", **settings: Any) -> None:
        super().__init__(transport, name=name, **settings)
        self.amplitude_unit, self.load_ohm = _unit_and_load(amplitude_unit, load_ohm)
        if channel not in self.channels:
            from labkit.errors import ConfigError
            raise ConfigError(f"{self.model} has no channel {channel!r}", key="channel",
                              expected=f"one of {list(self.channels)}")
        self.channel = int(channel)
        self.max_amp_vpp = None if max_amp_vpp is None else check_range(
            "max_amp_vpp", max_amp_vpp, 0.0, 2 * self.model_max_v, "Vpp")
        self.max_v = None if max_v is None else check_range("max_v", max_v, 0.0, self.model_max_v,
                                                            "V")
        self.max_freq_hz = None if max_freq_hz is None else float(max_freq_hz)
        self.state = {"output_on": None, "load": None}
        self._amp_checked = False

    # -- identity ------------------------------------------------------------------------------
    def identify(self, identity: str) -> tuple[str, int]:
        """The model word must be one of :attr:`known_models` (case and spaces ignored)."""
        _, word = self._identity_fields(identity)
        key = word.replace(" ", "").upper()
        for model, n in self.known_models.items():
            if model.upper() == key:
                return model, n
        raise self._unknown_model(identity, "one of " + ", ".join(self.known_models))

    def identified(self, model: str, channels: int) -> None:
        """The model's channels replace the family's; the configured ``channel`` must be one."""
        if self.channel > channels:
            from labkit.errors import ConfigError
            raise ConfigError(f"{self.name}: the {model} has {channels} channel"
                              f"{'s' if channels > 1 else ''}, there is no channel {self.channel}; "
                              "nothing else was sent", key="channel",
                              expected=f"one of {list(range(1, channels + 1))}")
        self.channels = tuple(range(1, channels + 1))

    def snapshot(self) -> dict[str, Any]:
        snap = super().snapshot()
        snap.setdefault("connect", {})["channels"] = len(self.channels)
        return snap

    # -- command spelling, per model ----------------------------------------------------------
    def _src(self, cmd: str) -> str:
        return cmd

    def _outp(self, suffix: str = "", channel: int | None = None) -> str:
        return "OUTP" + suffix

    def _trig_source(self, source: str, mode: str) -> str:
        return f"TRIG:SOUR {source}"

    def _burst_state(self, on: bool) -> str:
        return self._src(f"BURS:STAT {'ON' if on else 'OFF'}")

    # -- helpers ------------------------------------------------------------------------------
    def settings(self) -> dict[str, Any]:
        return {**super().settings(), "channel": self.channel, "max_amp_vpp": self.max_amp_vpp,
                "max_v": self.max_v, "max_freq_hz": self.max_freq_hz,
                "amplitude_unit": self.amplitude_unit, "load_ohm": self._load_word()}

    def _load_word(self) -> str:
        return "INF" if math.isinf(self.load_ohm) else _num(self.load_ohm)

    def _max_v_at_load(self) -> float:
        """The output's peak into the declared load: +-10 V open circuit through the 50 ohm source."""
        r = self.load_ohm
        return self.model_max_v if math.isinf(r) else self.model_max_v * r / (r + SOURCE_OHM)

    def _level_commands(self, amp_vpp: float) -> list[str]:
        """Load, unit and amplitude, in that order: the amplitude is read in the unit and for the
        load in force when it arrives."""
        value = amplitude_in(self.amplitude_unit, amp_vpp, self.load_ohm)
        return [self._outp(f":LOAD {self._load_word()}"), self._src(f"VOLT:UNIT {self.amplitude_unit}"),
                self._src(f"VOLT {_num(value)}")]

    def _check_freq(self, limit: str, freq_hz: float) -> float:
        f = check_range(limit, freq_hz, 1e-6, None, "Hz")
        return check_range("max_freq_hz", f, None, self.max_freq_hz, "Hz")

    def _check_amplitude(self, amp_vpp: float, offset_v: float) -> tuple[float, float]:
        amp = check_range("amp_vpp > 0", amp_vpp, 1e-3, None, "Vpp")
        if self.max_amp_vpp is not None:
            check_range("max_amp_vpp", amp, None, self.max_amp_vpp, "Vpp")
        off = check_range("offset_v", offset_v, -self.model_max_v, self.model_max_v, "V")
        peak = abs(off) + amp / 2
        if self.max_v is not None and peak > self.max_v:
            raise LimitError(f"|offset| + amplitude/2 = {peak:g} V exceeds the limit max_v = "
                             f"{self.max_v:g} V; nothing was sent", limit="max_v")
        top = self._max_v_at_load()
        if peak > top:
            into = "high-Z" if math.isinf(self.load_ohm) else f"{self.load_ohm:g} ohm"
            raise LimitError(f"|offset| + amplitude/2 = {peak:g} V exceeds the model output range "
                             f"of the {self.model} (+-{top:g} V into {into}); "
                             "nothing was sent",
                             limit="model output range")
        return amp, off

    # -- settings -----------------------------------------------------------------------------
    def set_load_high_z(self) -> None:
        """Declare a high-impedance load (``OUTP:LOAD INF``) so volts programmed = volts out."""
        self._send_all([self._outp(":LOAD INF")])
        self.state["load"] = "INF"

    def set_load(self) -> None:
        """Declare the configured load (``load_ohm``: INF for the PZT or an amplifier input) and
        read it back: the generator scales every amplitude for it (into high-Z a 50 ohm setting
        gives twice the programmed voltage)."""
        cmd = self._outp(":LOAD?")
        self._send_all([self._outp(f":LOAD {self._load_word()}")])
        got = self.query(cmd)
        try:
            value = math.inf if got.upper() in ("INF", "INFINITY") else float(got)
        except ValueError:
            value = math.nan
        if not (value == self.load_ohm or value >= 9.9e37 and math.isinf(self.load_ohm)):
            raise InstrumentError(f"load not set: {cmd} answers {got[:40]!r}, {self._load_word()} was set",
                                  instrument=self.name, command=cmd)
        self.state["load"] = self._load_word()

    # -- sync: what the scope's EXT input triggers on --------------------------------------------
    def _sync_commands(self) -> list[str]:
        """The family's commands that put the drive channel's sync on the Sync connector."""
        return ["OUTP:SYNC ON"]

    def _sync_readback(self) -> list[tuple[str, tuple[str, ...]]]:
        """(query, accepted replies) confirming :meth:`_sync_commands` took effect."""
        return [("OUTP:SYNC?", ("1", "+1", "ON"))]

    def enable_sync(self) -> None:
        """Route the drive channel's sync to the Sync connector, switch it on and read it back.

        The sync marks phase zero of every cycle of a sine and the start of a
        sweep or burst; the scope's EXT trigger input is cabled to it. A
        generator left with its sync off (or on the other channel, or
        inverted) gives a scope in NORMal sweep no trigger at all and one in
        AUTO untriggered records, so the reply of every setting is checked:
        a mismatch raises InstrumentError naming the query and the reply.
        """
        self._send_all(self._sync_commands())
        for cmd, ok in self._sync_readback():
            reply = self.query(cmd)
            if reply.strip('"').upper() not in ok:
                raise InstrumentError(f"sync not set: {cmd} answers {reply[:40]!r}, expected {ok[0]} "
                                      "(the scope's EXT trigger would never fire)", instrument=self.name,
                                      command=cmd)
        self.state["sync"] = {"on": True, "channel": self.channel}

    def set_sine(self, freq_hz: float, amp_vpp: float, offset_v: float = 0.0) -> None:
        """Sine of ``amp_vpp`` volts peak-to-peak at ``freq_hz`` around ``offset_v``.

        Limits are checked first; then the load is set to high impedance, then
        function, unit, frequency, amplitude and offset; then the error queue.
        """
        f = self._check_freq("freq_hz > 0", freq_hz)
        amp, off = self._check_amplitude(amp_vpp, offset_v)
        old_off = self.state.get("offset_v")
        # The output may be on: between the amplitude and the offset the film sees one old and
        # one new value. Shrinking the offset first keeps that state below the old (checked)
        # peak; otherwise amplitude first keeps it below the new (checked) peak.
        load, unit, volt = self._level_commands(amp)
        level = [volt, self._src(f"VOLT:OFFS {_num(off)}")]
        if old_off is not None and abs(off) < abs(old_off):
            level.reverse()
        self._send_all([load, self._src("FUNC SIN"), unit, self._src(f"FREQ {_num(f)}"), *level])
        self.state.update(load=self._load_word(), function="SIN", freq_hz=f, amp_vpp=amp, offset_v=off,
                          amplitude_unit=self.amplitude_unit)
        self._amp_checked = True

    def set_frequency(self, freq_hz: float) -> None:
        """Change only the frequency (stepped sweeps); amplitude and offset stay."""
        f = self._check_freq("freq_hz > 0", freq_hz)
        self._send_all([self._src(f"FREQ {_num(f)}")])
        self.state["freq_hz"] = f

    def set_amplitude(self, amp_vpp: float) -> None:
        """Change only the amplitude (load set to high-Z first), within the limits."""
        amp, _ = self._check_amplitude(amp_vpp, self.state.get("offset_v", 0.0) or 0.0)
        if "offset_v" not in self.state:
            # the generator may hold any offset from an earlier session: the peak is unknown
            raise LimitError("the offset is unknown, so |offset| + amplitude/2 cannot be checked; "
                             "call set_sine() first; nothing was sent", limit="offset unknown")
        self._send_all(self._level_commands(amp))
        self.state.update(load=self._load_word(), amp_vpp=amp)
        self._amp_checked = True

    def output(self, on: bool) -> None:
        """Turn the output on or off.

        Turning on is refused (LimitError ``amplitude not set``) until an
        amplitude was set through this driver: the generator may still hold an
        unchecked amplitude from an earlier session.
        """
        if on and not self._amp_checked:
            raise LimitError("amplitude not set: refusing to turn the output on before "
                             "set_sine()/set_amplitude() "
                             "has set a checked amplitude; nothing was sent",
                             limit="amplitude not set")
        if on:   # limits may have been lowered since the amplitude was set
            self._check_amplitude(self.state["amp_vpp"], self.state.get("offset_v") or 0.0)
        self._send_all([self._outp(" ON" if on else " OFF")])
        self.state["output_on"] = bool(on)

    @property
    def output_on(self) -> bool:
        """The output state as the instrument reports it (``OUTP?``)."""
        cmd = self._outp("?")
        reply = self.query(cmd)
        if reply.upper() in ("1", "ON", "+1"):
            return True
        if reply.upper() in ("0", "OFF", "+0"):
            return False
        raise InstrumentError(f"garbled reply {reply[:40]!r} (expected 0/1/ON/OFF)",
                              instrument=self.name, command=cmd)

    def max_sweep_time_s(self) -> float:
        """The model's longest sweep time (``SWE:TIME? MAX``), asked once and cached."""
        if "max_sweep_time_s" not in self.state:
            self.state["max_sweep_time_s"] = self.query_float(self._src("SWE:TIME? MAX"))
        return self.state["max_sweep_time_s"]

    def set_sweep(self, start_hz: float, stop_hz: float, time_s: float, spacing: str = "LIN",
                  trigger_source: str = "IMM") -> None:
        """Frequency sweep ``start_hz`` -> ``stop_hz`` in ``time_s`` (LIN or LOG), and enable it.

        Set the sine's amplitude first (:meth:`set_sine`). ``time_s`` is checked
        against the instrument's own ``SWE:TIME? MAX``. ``trigger_source``:
        IMM (free-running), EXT or BUS (:meth:`trigger`).
        """
        a = self._check_freq("start_hz > 0", start_hz)
        b = self._check_freq("stop_hz > 0", stop_hz)
        sp = check_choice("spacing", spacing, ("LIN", "LOG"))
        src = check_choice("trigger_source", trigger_source, ("IMM", "EXT", "BUS"))
        if not self._amp_checked:
            raise LimitError("amplitude not set: set_sweep() needs set_sine() first "
                             "(a checked amplitude); "
                             "nothing was sent", limit="amplitude not set")
        check_range("sweep time_s", time_s, 1e-3, None, "s")
        tmax = self.max_sweep_time_s()
        t = check_range("sweep time (SWE:TIME? MAX)", time_s, 1e-3, tmax, "s")
        self._send_all([self._src(f"FREQ:STAR {_num(a)}"), self._src(f"FREQ:STOP {_num(b)}"),
                        self._src(f"SWE:SPAC {sp}"), self._src(f"SWE:TIME {_num(t)}"),
                        self._trig_source(src, "SWE"), self._src("SWE:STAT ON")])
        self.state["sweep"] = {"start_hz": a, "stop_hz": b, "time_s": t, "spacing": sp,
                               "trigger_source": src, "on": True}

    def sweep_off(self) -> None:
        """Disable the sweep (back to a fixed-frequency sine)."""
        self._send_all([self._src("SWE:STAT OFF")])
        self.state.setdefault("sweep", {})["on"] = False

    def burst(self, ncycles: int, trigger_source: str = "BUS", start_phase_deg: float | None = None) -> None:
        """Triggered burst of ``ncycles`` cycles of the current waveform, and enable it.

        ``start_phase_deg`` (``BURS:PHAS``) is where each burst starts; a sine burst of whole
        cycles also ends there, and between bursts the output holds that level (the 33220A and
        33500 guides: "the voltage level corresponding to the starting burst phase"), so
        ``offset + amp/2 * sin(phase)`` is what the load sees while idle (docs/faults.md).
        None leaves the generator's own start phase.
        """
        n = int(check_range("burst ncycles", ncycles, 1, 1e8, "cycles"))
        src = check_choice("trigger_source", trigger_source, ("IMM", "EXT", "BUS"))
        phase = None if start_phase_deg is None else check_range("burst start_phase_deg", start_phase_deg,
                                                                 -360.0, 360.0, "deg")
        if not self._amp_checked:
            raise LimitError("amplitude not set: burst() needs set_sine() first "
                             "(a checked amplitude); "
                             "nothing was sent", limit="amplitude not set")
        at = [] if phase is None else self._phase_commands(phase)
        self._send_all([self._src("BURS:MODE TRIG"), self._src(f"BURS:NCYC {n}"), *at,
                        self._trig_source(src, "BURS"), self._burst_state(True)])
        self.state["burst"] = {"ncycles": n, "trigger_source": src, "on": True}
        if phase is not None:
            self.state["burst"]["start_phase_deg"] = phase

    def _phase_commands(self, phase_deg: float) -> list[str]:
        """The burst start phase in degrees (Keysight: ``UNIT:ANGL DEG`` first, -360..360)."""
        return ["UNIT:ANGL DEG", self._src(f"BURS:PHAS {_num(phase_deg)}")]

    def burst_off(self) -> None:
        """Disable burst mode."""
        self._send_all([self._burst_state(False)])
        self.state.setdefault("burst", {})["on"] = False

    def trigger(self) -> None:
        """Software trigger (``*TRG``) for a BUS-triggered sweep or burst."""
        self._send_all(["*TRG"])

    def safe_off(self) -> None:
        """Turn every output of the instrument off, then confirm with ``*OPC?``.

        The confirmation makes sure the generator has processed the OFF commands
        before the link is closed (no error-queue check: this must be quick).
        """
        failed: InstrumentError | None = None
        for ch in self.channels:      # every channel is tried, even after one failed
            try:
                self.write(self._outp(" OFF", channel=ch))
            except InstrumentError as exc:
                failed = failed or exc
        if failed is not None:
            raise failed
        self.state["output_on"] = False
        if self.query_int("*OPC?") != 1:
            raise InstrumentError("*OPC? did not confirm the outputs off", instrument=self.name,
                                  command="*OPC?")


class Agilent33220A(FunctionGenerator):
    """Keysight/Agilent 33220A (one channel, commands without prefixes)."""

    model = "33220A"
    known_models = {"33220A": 1}


class Keysight33500B(FunctionGenerator):
    """Keysight 33500B series (33521B/33522B...): ``SOURn:``, ``OUTPn``, ``TRIGn:`` prefixes."""

    model = "33500B"
    channels = (1, 2)
    #: 33500B Series (and the 33500A models it replaced): odd model numbers one channel,
    #: even ones two (33500B Series data sheet, "Models and options")
    known_models = {"33509B": 1, "33510B": 2, "33511B": 1, "33512B": 2, "33519B": 1, "33520B": 2,
                    "33521B": 1, "33522B": 2, "33521A": 1, "33522A": 2}

    def _src(self, cmd: str) -> str:
        return f"SOUR{self.channel}:{cmd}"

    def _outp(self, suffix: str = "", channel: int | None = None) -> str:
        return f"OUTP{channel or self.channel}{suffix}"

    def _trig_source(self, source: str, mode: str) -> str:
        return f"TRIG{self.channel}:SOUR {source}"

    def _sync_commands(self) -> list[str]:
        # the front-panel Sync connector follows one channel (OUTPut:SYNC:SOURce); its mode and
        # polarity are per channel (OUTPut[1|2]:SYNC:MODE, :POLarity)
        ch = self.channel
        return [f"OUTP:SYNC:SOUR CH{ch}", f"OUTP{ch}:SYNC:MODE NORM", f"OUTP{ch}:SYNC:POL NORM", "OUTP:SYNC ON"]

    def _sync_readback(self) -> list[tuple[str, tuple[str, ...]]]:
        ch = self.channel
        return [("OUTP:SYNC:SOUR?", (f"CH{ch}",)), (f"OUTP{ch}:SYNC:MODE?", ("NORM",)),
                (f"OUTP{ch}:SYNC:POL?", ("NORM",)), ("OUTP:SYNC?", ("1", "+1", "ON"))]


class RigolDG1000Z(FunctionGenerator):
    """Rigol DG1000Z (DG1022Z, DG1062Z): ``:SOURn:``, ``:OUTPn``; ``0,"No error"``."""

    model = "DG1000Z"
    channels = (1, 2)
    known_models = {"DG1022Z": 2, "DG1032Z": 2, "DG1062Z": 2}
    err_command = ":SYST:ERR?"
    _TRIG = {"IMM": "INT", "EXT": "EXT", "BUS": "MAN"}

    def _src(self, cmd: str) -> str:
        return f":SOUR{self.channel}:{cmd}"

    def _outp(self, suffix: str = "", channel: int | None = None) -> str:
        return f":OUTP{channel or self.channel}{suffix}"

    def _trig_source(self, source: str, mode: str) -> str:
        return self._src(f"{mode}:TRIG:SOUR {self._TRIG[source]}")

    def _burst_state(self, on: bool) -> str:
        return self._src(f"BURS {'ON' if on else 'OFF'}")

    def _phase_commands(self, phase_deg: float) -> list[str]:
        # DG1000Z: degrees only, 0 to 360 (no UNIT:ANGL)
        return [self._src(f"BURS:PHAS {_num(phase_deg % 360.0)}")]

    def _sync_commands(self) -> list[str]:
        # each channel has its own rear-panel sync (:OUTPut<n>:SYNC[:STATe], :POLarity)
        return [self._outp(":SYNC:POL POS"), self._outp(":SYNC ON")]

    def _sync_readback(self) -> list[tuple[str, tuple[str, ...]]]:
        return [(self._outp(":SYNC:POL?"), ("POS", "POSITIVE")), (self._outp(":SYNC?"), ("ON", "1"))]
