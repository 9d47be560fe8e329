"""QCoDeS's own drivers against the virtual lab over TCP (a second third-party client beside PyMeasure).

``qcodes`` is in the ``test`` extra: these tests never skip. Each driver
connects (QCoDeS reads ``*IDN?`` and, on ``snapshot(update=True)``, every
parameter it declares), configures a sine, reads it back, and the run ends
with an empty error queue. What the instruments answer is checked against
the lab's own state (the programmed drive) and, for the scope, against the
drive by a least-squares sine fit.

What QCoDeS sends that the programming guides do not have, and the lab (like
the instrument) refuses:

* ``RigolDS1074Z.waveform_npoints`` is ``WAV:POIN?``. The MSO1000Z/DS1000Z
  Programming Guide's :WAVeform subsystem has no :POINts (the points of one
  read are chosen with :WAVeform:STARt/:STOP; the count is the preamble's
  third field), and a DS1054Z on the bench answers such InfiniiVision-only
  headers with -113. The simulated DS1000Z answers -113 and no reply, so
  QCoDeS's ``trace`` (whose shape validator asks for ``waveform_npoints``)
  times out; its data path (``trace.get_raw``: the preamble fields, ``:WAV:FORM
  WORD``, ``:WAV:SOUR``, ``WAV:DATA?``) works and is what is checked.
* ``RigolDG1062Burst.idle`` is ``:SOUR<n>:BURST:IDLE?``; the DG1000Z
  Programming Guide (PGB09103-1110) :SOURce:BURSt subsystem has no :IDLE (the
  DG4000/DG800 guides do): -113, a timeout in QCoDeS's snapshot.
* ``RigolDG1062Channel.duty_cycle`` raises inside QCoDeS for a sine (no
  instrument traffic), so its snapshot always warns about it.

QCoDeS has no InfiniiVision driver (its Keysight scope driver is for the
Infiniium series, another command set), so the DSOX sim has no QCoDeS test.
"""
from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest
from labhelpers import fit_sine, settle
from pyvisa.errors import VisaIOError
from qcodes.instrument import Instrument
from qcodes.instrument_drivers.Keysight import Keysight33522B
from qcodes.instrument_drivers.rigol import RigolDG1062, RigolDS1074Z

from labkit.lab import VirtualLab

OK_KS = (0, "No error")


@contextmanager
def qc(cls: type[Instrument], name: str, resource: str, timeout_s: float = 5.0) -> Iterator[Any]:
    """A QCoDeS instrument on the lab's resource (pyvisa-py), closed (and unregistered) after."""
    inst = cls(name, resource, visalib="@py", timeout=timeout_s)
    try:
        yield inst
    finally:
        inst.close()


def snapshot_failures(inst: Instrument, caplog: pytest.LogCaptureFixture) -> set[str]:
    """Names of the parameters ``snapshot(update=True)`` could not read (QCoDeS logs a warning each)."""
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="qcodes"):
        inst.snapshot(update=True)
    return {r.getMessage().rsplit(":", 1)[-1].strip() for r in caplog.records
            if "Could not update parameter" in r.getMessage()}


def rigol_errors(inst: Instrument) -> list[str]:
    out = []
    for _ in range(20):
        reply = inst.ask(":SYST:ERR?")
        if reply.startswith("0,"):
            return out
        out.append(reply)
    raise AssertionError(f"error queue not empty after 20 reads: {out}")


def test_qcodes_keysight_33522b_configures_a_sine_and_a_burst(caplog):
    with VirtualLab(seed=4) as lab, qc(Keysight33522B, "qc_fg", lab.resources["funcgen"]) as fg:
        assert fg.IDN()["model"] == "33522B" and fg.num_channels == 2
        # every parameter QCoDeS declares for both channels and the sync output is read
        assert snapshot_failures(fg, caplog) == set()
        ch = fg.ch1
        ch.function_type("SIN")
        ch.amplitude_unit("VPP")
        ch.frequency(1234.5)
        ch.amplitude(2.0)
        ch.offset(0.25)
        ch.output("ON")
        assert (ch.function_type(), ch.frequency(), ch.amplitude(), ch.offset(), ch.output()) == \
            ("SIN", 1234.5, 2.0, 0.25, "ON")
        drive = lab.funcgen.drive(1)
        # 50 ohm is the *RST load: 2 Vpp programmed is 4 Vpp into the lab's high-impedance PZT
        assert drive.on and drive.func == "SIN" and drive.freq_hz == 1234.5
        assert (drive.amp_v, drive.offset_v) == pytest.approx((2.0, 0.5))
        # a BUS-triggered 3-cycle burst: QCoDeS's force_trigger is *TRG
        ch.burst_mode("N Cycle")
        ch.burst_ncycles(3)
        ch.trigger_source("BUS")
        ch.trigger_delay(0.05)                         # TRIGger1:DELay: trigger to burst
        ch.burst_state("ON")
        assert (ch.burst_mode(), ch.burst_ncycles(), ch.trigger_source(), ch.trigger_delay(), ch.burst_state()) == \
            ("N Cycle", 3, "BUS", 0.05, "ON")
        before = len(lab.burst_timeline)
        t0 = lab.now_s()
        fg.force_trigger()
        fg.ask("*OPC?")
        (start, _, _, end), = lab.burst_timeline[before:]
        assert start - t0 == pytest.approx(0.05, abs=0.02) and end - start == pytest.approx(3 / 1234.5)
        ch.output("OFF")
        assert fg.error() == OK_KS


def test_qcodes_rigol_dg1062_applies_a_sine_and_a_delayed_burst(caplog):
    with VirtualLab(seed=5, funcgen_model="DG1062Z") as lab, \
            qc(RigolDG1062, "qc_dg", lab.resources["funcgen"], timeout_s=0.5) as fg:
        assert fg.IDN()["model"] == "DG1062Z"
        # the burst set-up of both channels (:BURS:TDEL?, :BURS:TRIG:SLOP?, :OUTPUT<n>:GAT:POL? ...)
        # reads; :BURST:IDLE? is not a DG1000Z command, duty_cycle raises in QCoDeS for a sine
        assert snapshot_failures(fg, caplog) == {"duty_cycle", "idle"}
        assert rigol_errors(fg) == ['-113,"Undefined header"'] * 2    # IDLE? of both channels
        ch = fg.ch1
        ch.impedance("HighZ")
        ch.apply(waveform="SIN", freq=2000.0, ampl=3.0, offset=-0.5, phase=0.0)
        assert ch.current_waveform() == {"waveform": "SIN", "freq": 2000.0, "ampl": 3.0, "offset": -0.5,
                                         "phase": 0.0}
        assert (ch.impedance(), ch.state()) == ("HighZ", "ON")     # :APPLy turns the output on
        drive = lab.funcgen.drive(1)
        assert drive.on and drive.freq_hz == 2000.0 and (drive.amp_v, drive.offset_v) == pytest.approx((1.5, -0.5))
        b = ch.burst
        b.mode("TRIG")
        b.ncycles(4)
        b.source("MAN")
        b.time_delay(0.05)
        b.trigger_slope("NEG")
        b.on("ON")
        # (QCoDeS passes these replies on as text)
        assert (b.mode(), float(b.ncycles()), b.source(), float(b.time_delay()), b.trigger_slope(), b.on()) == \
            ("TRIG", 4.0, "MAN", 0.05, "NEG", "ON")
        ch.polarity(0)                                 # :OUTPUT1:GAT:POL NEGATIVE
        assert ch.polarity() == 0
        before = len(lab.burst_timeline)
        t0 = lab.now_s()
        b.trigger()                                    # :SOUR1:BURS:TRIG
        fg.ask("*OPC?")
        (start, _, _, end), = lab.burst_timeline[before:]
        assert start - t0 == pytest.approx(0.05, abs=0.02)   # the burst starts TDELay after its trigger
        assert end - start == pytest.approx(4 / 2000.0)
        ch.state("OFF")
        assert rigol_errors(fg) == []


def test_qcodes_rigol_ds1074z_reads_the_drive(caplog):
    with VirtualLab(seed=6, funcgen_model="DG1062Z", scope_model="DS1074Z") as lab, \
            qc(RigolDG1062, "qc_dg2", lab.resources["funcgen"]) as fg, \
            qc(RigolDS1074Z, "qc_ds", lab.resources["scope"], timeout_s=0.5) as sc:
        fg.ch1.impedance("HighZ")
        fg.ch1.apply(waveform="SIN", freq=1000.0, ampl=2.0, offset=0.0, phase=0.0)
        settle(lab)
        assert sc.IDN()["model"] == "DS1074Z"
        # every parameter but WAV:POIN? (not a DS1000Z command: -113, no reply)
        assert snapshot_failures(sc, caplog) == {"waveform_npoints"}
        assert rigol_errors(sc) == ['-113,"Undefined header"']
        with pytest.raises(VisaIOError):
            sc.waveform_npoints()
        assert rigol_errors(sc) == ['-113,"Undefined header"']

        ch = sc.channels[0]
        ch.vertical_scale(0.5)
        sc.trigger_mode("edge")
        sc.trigger_edge_source("ch1")
        sc.trigger_edge_slope("positive")
        sc.trigger_level(0.1)
        assert (ch.vertical_scale(), sc.trigger_mode(), sc.trigger_edge_source(), sc.trigger_edge_slope(),
                float(sc.trigger_level())) == (0.5, "EDGE", "ch1", "POS", 0.1)
        sc.write(":TIM:MAIN:SCAL 0.0005")              # 12 divisions: 6 ms, six periods on screen
        volts = ch.trace.get_raw()                     # QCoDeS's data path, without the WAV:POIN? check
        assert sc.data_source() == "ch1" and len(volts) == 1200   # the screen's points (NORMal mode)
        t = sc.waveform_xorigin() + sc.waveform_xincrem() * np.arange(len(volts))
        assert sc.waveform_xincrem() == pytest.approx(6e-3 / 1200, rel=1e-3)
        amp = abs(fit_sine(t, volts, 1000.0))
        assert 2 * amp == pytest.approx(2.0, rel=0.01)
        assert rigol_errors(sc) == [] and rigol_errors(fg) == []
