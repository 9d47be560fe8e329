"""Software written by others, against the virtual lab: PyMeasure's own drivers, and plain pyvisa.

PyMeasure (an optional test dependency, ``pymeasure`` in the ``test`` extra)
configures the 33500B with its ``Agilent33500`` driver, reads the scope with
its ``KeysightDSOX1102G`` driver (``:CHANnel1?`` parsed with headers, the
ASCii ``:WAVeform:DATA?`` block whose fixed 10-character ``#8nnnnnnnn``
header it cuts off by position), and both end with an empty error queue and
a clear status byte. The measured waveform is checked against the
generator's programmed sine by a least-squares fit.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from labhelpers import lab  # noqa: F401  (fixture)

pymeasure_agilent = pytest.importorskip("pymeasure.instruments.agilent")
pymeasure_keysight = pytest.importorskip("pymeasure.instruments.keysight")

VISA = {"visa_library": "@py", "read_termination": "\n", "write_termination": "\n"}


def _sine_fit(t: np.ndarray, y: np.ndarray, f_hz: float) -> tuple[float, float]:
    """(amplitude, rms residual) of the least-squares sine at ``f_hz`` (with an offset)."""
    a = np.column_stack([np.sin(2 * np.pi * f_hz * t), np.cos(2 * np.pi * f_hz * t), np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    return float(np.hypot(coef[0], coef[1])), float(np.sqrt(np.mean((a @ coef - y) ** 2)))


def test_pymeasure_configures_the_generator_acquires_and_leaves_no_error(lab):  # noqa: F811
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)   # PyMeasure's "SCPI or not" notice
        fg = pymeasure_agilent.Agilent33500(lab.resources["funcgen"], timeout=5000, **VISA)
        sc = pymeasure_keysight.KeysightDSOX1102G(lab.resources["scope"], **VISA)
    try:
        assert fg.id.startswith("Keysight Technologies,33522B")
        ch = fg.ch_1
        ch.output_load = "INF"          # the PZT is high impedance: load first, then amplitude
        ch.shape = "SIN"
        ch.amplitude_unit = "VPP"
        ch.frequency = 500
        ch.amplitude = 2.0
        ch.offset = 0.0
        ch.output = True
        # read back what a snapshot reads (the 33500B's documented queries, programmed defaults)
        assert (ch.shape, ch.frequency, ch.amplitude, ch.offset, ch.output) == ("SIN", 500.0, 2.0, 0.0, True)
        assert ch.output_load == pytest.approx(9.9e37)
        assert (ch.voltage_high, ch.voltage_low) == (1.0, -1.0)
        assert (ch.burst_state, ch.burst_mode, ch.burst_ncycles) == (False, "TRIG", 1)
        assert (ch.square_dutycycle, ch.ramp_symmetry, ch.pulse_hold) == (50.0, 100.0, "WIDT")
        drive = lab.funcgen.drive(1)
        assert drive.on and drive.freq_hz == 500 and drive.amp_v == pytest.approx(1.0)

        assert sc.id.startswith("KEYSIGHT TECHNOLOGIES,DSOX")
        sc.ch1.setup(coupling="dc", display=True, invert=False, label="drive", offset=0,
                     probe_attenuation=1, vertical_range=4)
        cfg = sc.ch1.current_configuration
        assert cfg["RANG"] == 4.0 and cfg["COUP"] == "DC" and cfg["DISP"] is True and cfg["LAB"] == '"DRIVE"'
        sc.timebase_range = 0.01
        assert sc.timebase["MAIN:RANG"] == 0.01
        data, pre = sc.download_data("channel1", points=1000)
        assert len(data) == pre["points"] == 1000 and pre["xincrement"] == pytest.approx(1e-5)
        t = (np.arange(len(data)) - pre["xreference"]) * pre["xincrement"] + pre["xorigin"]
        amp, resid = _sine_fit(t, np.asarray(data, float), 500.0)
        # 2 Vpp into the high-impedance input: 1 V peak; the scope's noise is 0.5 mV rms
        assert amp == pytest.approx(1.0, abs=0.01) and resid < 0.005

        assert fg.check_errors() == []
        assert sc.ask(":SYST:ERR?").strip() == '+0,"No error"'
        for inst in (fg, sc):
            assert int(inst.ask("*STB?")) & 4 == 0        # no error/event queue entry left
            assert int(inst.ask("*ESR?")) & 0b111100 == 0  # no command/execution/device/query error
    finally:
        fg.adapter.close()
        sc.adapter.close()


def test_plain_pyvisa_waits_for_opc_via_the_event_status_register(lab):  # noqa: F811
    """The IEEE 488.2 idiom ``*ESE 1;*OPC`` then poll ``*STB?`` for ESB (bit 5) must not hang."""
    import pyvisa

    rm = pyvisa.ResourceManager("@py")
    sc = rm.open_resource(lab.resources["scope"], read_termination="\n", write_termination="\n", timeout=5000)
    try:
        sc.write("*CLS;*ESE 1;*SRE 32")
        assert sc.query("*ESE?;*SRE?") == "+1;+32"
        sc.write(":TIM:RANG 2e-3;:TRIG:SWE AUTO;:SING;*OPC")
        stb = 0
        for _ in range(500):
            stb = int(sc.query("*STB?"))
            if stb & 32:
                break
        assert stb & 32 and stb & 64                     # ESB, and MSS since SRE enables ESB
        assert int(sc.query("*ESR?")) == 1               # OPC only; reading clears it
        assert int(sc.query("*ESR?")) == 0 and int(sc.query("*STB?")) & 96 == 0
        assert sc.query(":SYST:ERR?") == '+0,"No error"'
    finally:
        sc.close()      # not rm.close(): pyvisa shares one session per library in a process


def test_pymeasure_33220a_bus_triggered_burst():
    """PyMeasure's Agilent33220A: a sine, then a 5-cycle BUS-triggered burst fired by its trigger()."""
    from labkit.lab import VirtualLab

    with VirtualLab(seed=0, funcgen_model="33220A") as lab, warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        fg = pymeasure_agilent.Agilent33220A(lab.resources["funcgen"], timeout=5000, **VISA)
        try:
            assert fg.id.startswith("Agilent Technologies,33220A")
            fg.shape, fg.frequency, fg.amplitude_unit, fg.amplitude, fg.offset = "SIN", 500, "VPP", 1.5, 0.1
            fg.output = True
            assert (fg.shape, fg.frequency, fg.amplitude, fg.offset, fg.output) == ("SIN", 500.0, 1.5, 0.1, True)
            assert (fg.voltage_high, fg.voltage_low) == (0.85, -0.65)
            assert (fg.pulse_period, fg.pulse_width, fg.square_dutycycle) == (1e-3, 1e-4, 50.0)
            fg.burst_mode, fg.burst_ncycles, fg.trigger_source, fg.burst_state = "TRIG", 5, "BUS", True
            assert (fg.burst_state, fg.burst_ncycles, fg.burst_mode, fg.trigger_source) == (True, 5, "TRIG", "BUS")
            fg.trigger()                              # *TRG;*WAI
            assert fg.check_errors() == [] and int(fg.ask("*STB?")) & 4 == 0
            (start, inst, ch, end), = lab.burst_timeline
            assert (inst, ch) == ("funcgen", 1) and end - start == pytest.approx(5 / 500)
        finally:
            fg.adapter.close()
