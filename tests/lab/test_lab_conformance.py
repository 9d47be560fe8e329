"""Conformance tables: each simulated instrument, over its real transport, against its programming guide.

Every row names where the behaviour is documented, then lists what a client
sends and what the instrument answers: an exact string, a number (compared as
a number where the guide gives a value but not its digits), ``None`` for a
command that answers nothing, or a predicate (block headers, preambles). The
error codes the row leaves in the queue are listed last and read back with the
instrument's own error query; then ``*OPC?`` (or, on the serial controllers, a
plain query) must answer next, so a command that should answer nothing has
not sent a stray line, and an unknown command never hangs the instrument.

Guides (sections as titled there):

* KS: Keysight 33500B Series Operating and Service Guide, "SCPI Programming
  Reference" (subsystem, command) and "Factory Reset State"; the reply digits
  are those of the Trueform family's query replies (``+1.000000000000000E+03``,
  amplitude/offset/phase ``+1.0000000000000E-01``).
* IV: Keysight InfiniiVision 3000T X-Series Oscilloscopes Programmer's Guide.
* DG: Rigol DG1000Z Series Programming Guide.
* DS: Rigol MSO1000Z/DS1000Z Series Programming Guide.
* A2: Agilent 33220A User's Guide, chapter 4 "Remote Interface Reference".
* PV: docs/instruments.md, Polytec OFV-5000 / OFV-3001 (marked facts only).
* 488.2: IEEE 488.2-1992; SCPI: SCPI 1999.0.
"""
from __future__ import annotations

import os
import select
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest
from labhelpers import Raw

from labkit.lab.funcgen import SimAgilent33220A, SimKeysight33500B, SimRigolDG1000Z
from labkit.lab.scope import SimInfiniiVision, SimRigolDS1000Z
from labkit.lab.transport import PtyServer, TcpServer
from labkit.lab.vibrometer import SimOFV3001, SimOFV5000

Expect = Any   # str | float | None | Callable[[bytes], bool]
#: a line that is not sent: the client waits 0.2 s (an acquisition completes meanwhile)
PAUSE = "(pause)"


@dataclass
class Row:
    section: str
    exchanges: list[tuple[str, Expect]]
    errors: list[int] = field(default_factory=list)


def block(digits: int, length: int) -> Callable[[bytes], bool]:
    """A definite-length block with a ``digits``-wide length field holding ``length`` bytes."""
    def check(reply: bytes) -> bool:
        head = b"#" + str(digits).encode() + str(length).zfill(digits).encode()
        return reply.startswith(head) and len(reply) == len(head) + length
    check.__name__ = f"block #{digits}{str(length).zfill(digits)}"
    return check


def fields(n: int, **at: Any) -> Callable[[bytes], bool]:
    """A comma-separated reply of ``n`` fields, some of them (by index ``f<i>``) given exactly."""
    def check(reply: bytes) -> bool:
        parts = reply.decode().split(",")
        return len(parts) == n and all(parts[int(k[1:])] == v for k, v in at.items())
    check.__name__ = f"{n} fields {at}"
    return check


def model_word(word: str) -> Callable[[bytes], bool]:
    def check(reply: bytes) -> bool:
        parts = reply.decode().split(",")
        return len(parts) == 4 and parts[1] == word
    check.__name__ = f"identity of a {word}"
    return check


# ------------------------------------------------------------------------------------------------
# Keysight 33500B (33522B, two channels)

KS_RESET = [
    ("FUNC?", "SIN"), ("FREQ?", "+1.000000000000000E+03"), ("VOLT?", "+1.0000000000000E-01"),
    ("VOLT:OFFS?", "+0.0000000000000E+00"), ("VOLT:UNIT?", "VPP"), ("PHAS?", "+0.0000000000000E+00"),
    ("VOLT:HIGH?", "+5.000000000000000E-02"), ("VOLT:LOW?", "-5.000000000000000E-02"),
    ("OUTP1?", "0"), ("OUTP2?", "0"), ("OUTP1:LOAD?", "+5.000000000000000E+01"), ("OUTP:POL?", "NORM"),
    ("OUTP:SYNC?", "1"), ("OUTP:SYNC:SOUR?", "CH1"), ("OUTP:TRIG?", "0"),
    ("FREQ:MODE?", "CW"), ("FREQ:STAR?", "+1.000000000000000E+02"), ("FREQ:STOP?", "+1.000000000000000E+03"),
    ("SWE:STAT?", "0"), ("SWE:SPAC?", "LIN"), ("SWE:TIME?", "+1.000000000000000E+00"),
    ("SWE:HTIM?", "+0.000000000000000E+00"), ("SWE:RTIM?", "+0.000000000000000E+00"),
    ("BURS:STAT?", "0"), ("BURS:MODE?", "TRIG"), ("BURS:NCYC?", "+1.000000000000000E+00"),
    ("BURS:INT:PER?", "+1.000000000000000E-02"), ("BURS:PHAS?", "+0.0000000000000E+00"),
    ("BURS:GATE:POL?", "NORM"),
    ("FUNC:SQU:DCYC?", "+5.000000000000000E+01"), ("FUNC:RAMP:SYMM?", "+1.000000000000000E+02"),
    ("FUNC:PULS:WIDT?", "+1.000000000000000E-04"), ("FUNC:PULS:PER?", "+1.000000000000000E-03"),
    ("FUNC:PULS:HOLD?", "WIDT"),
    ("TRIG1:SOUR?", "IMM"), ("TRIG:SLOP?", "POS"), ("TRIG:COUN?", "+1.000000000000000E+00"),
    ("TRIG:DEL?", "+0.000000000000000E+00"), ("TRIG:TIM?", "+1.000000000000000E+00"),
]

KS_ROWS = [
    Row("488.2 10.14 *IDN?", [("*IDN?", "Keysight Technologies,33522B,MY5740LAB1,4.03-1.19-2.00-52-00")]),
    Row("KS Factory Reset State (after *RST)", KS_RESET),
    Row("SCPI 6.2.1 long and short forms, any case",
        [("SOURCE1:FREQUENCY 2000", None), ("sour1:freq?", "+2.000000000000000E+03"),
         ("Sour1:Frequency?", "+2.000000000000000E+03")]),
    Row("SCPI 6.2.1 a form between short and long is no header", [("FREQU 5", None), ("FREQ?", 1000.0)],
        [-113]),
    Row("KS SOURce:VOLTage[:LEVel][:IMMediate][:AMPLitude]: optional nodes",
        [("SOUR1:VOLT:LEV:IMM:AMPL 0.5", None), ("VOLT?", "+5.0000000000000E-01")]),
    Row("SCPI 6.2.4 leading colon optional", [(":SOUR1:FREQ 300", None), ("SOUR1:FREQ?", 300.0),
                                              (":FREQ?", 300.0)]),
    Row("SCPI 6.2.4 path rule in compound messages",
        [("SOUR2:FREQ 500;VOLT 0.4;:SOUR2:FREQ?;VOLT?", "+5.000000000000000E+02;+4.0000000000000E-01"),
         ("SOUR1:FREQ?", "+1.000000000000000E+03")]),
    Row("488.2 7.6.1.4 common commands leave the path alone",
        [("SOUR2:FREQ 700;*CLS;VOLT 0.3", None), ("SOUR2:FREQ?;VOLT?", "+7.000000000000000E+02;+3.0000000000000E-01")]),
    Row("488.2 7.4.3 header separator: any white space", [("FREQ\t500", None), ("FREQ?", "+5.000000000000000E+02")]),
    Row("488.2 7.7.3 suffix units (MHZ is megahertz, MV millivolt)",
        [("FREQ 1.5 MHZ", None), ("FREQ?", "+1.500000000000000E+06"), ("VOLT 100 MV", None),
         ("VOLT?", "+1.0000000000000E-01")]),
    Row("KS FREQuency?/VOLTage? {MINimum|MAXimum} (33522B sine: 1 uHz to 30 MHz, 1 mVpp to 10 Vpp in 50 ohm)",
        [("FREQ? MIN", "+1.000000000000000E-06"), ("FREQ? MAX", "+3.000000000000000E+07"),
         ("VOLT? MIN", "+1.0000000000000E-03"), ("VOLT? MAX", "+1.0000000000000E+01"),
         ("FUNC:SQU:DCYC? MAX", "+9.999000000000000E+01"), ("FREQ 500", None),
         ("FREQ? DEF", "+1.000000000000000E+03"), ("VOLT? DEF", "+1.0000000000000E-01"),
         ("SWE:TIME? MAX", "+3.600000000000000E+03"), ("FREQ? FOO", None)], [-224]),
    Row("KS out of range: clipped to the limit and -222", [("FREQ 1e12", None), ("FREQ?", "+3.000000000000000E+07")],
        [-222]),
    Row("SCPI vol. 2 21.8.4 numeric suffix beyond the channels: -114", [("SOUR3:FREQ?", None), ("OUTP3 ON", None)],
        [-114, -114]),
    Row("488.2 7.7 parameter errors: -104 data type, -108 too many, -109 missing",
        [("FREQ abc", None), ("FREQ 1,2", None), ("FREQ", None)], [-104, -108, -109]),
    Row("KS BURSt:NCYCles INFinity, OUTPut:LOAD INFinity: 9.9E37",
        [("BURS:NCYC INF", None), ("BURS:NCYC?", "+9.900000000000000E+37"), ("OUTP1:LOAD INF", None),
         ("OUTP1:LOAD?", "+9.900000000000000E+37")]),
    Row("KS OUTPut:LOAD keeps the output voltage; the displayed amplitude doubles into high Z",
        [("VOLT 1", None), ("OUTP1:LOAD INF", None), ("VOLT?", "+2.0000000000000E+00")]),
    Row("KS VOLTage:UNIT DBM (finite load only)",
        [("VOLT:UNIT DBM", None), ("VOLT?", "-1.6020599913280E+01"), ("OUTP1:LOAD INF", None),
         ("VOLT:UNIT?", "DBM"), ("VOLT:UNIT VPP", None), ("VOLT:UNIT DBM", None), ("VOLT:UNIT?", "VPP")],
        [-221]),
    Row("KS VOLTage: a VPP, VRMS or DBM suffix names the amplitude's unit, whatever VOLTage:UNIT says "
        "(a bare number is in VOLTage:UNIT's)",
        [("VOLT:UNIT VRMS", None), ("VOLT 2 VPP", None), ("VOLT:UNIT?;:VOLT?", "VRMS;+7.0710678118655E-01"),
         ("VOLT 0.5", None), ("VOLT:UNIT VPP", None), ("VOLT?", "+1.4142135623731E+00"),
         ("VOLT 0.5 VRMS", None), ("VOLT?", "+1.4142135623731E+00"), ("VOLT 500 MVPP", None),
         ("VOLT?", "+5.0000000000000E-01"), ("VOLT 10 DBM", None), ("VOLT?", "+2.0000000000000E+00"),
         ("OUTP1:LOAD INF", None), ("VOLT 10 DBM", None), ("VOLT?", "+4.0000000000000E+00")], [-221]),
    Row("KS OUTPut:SYNC, OUTPut:SYNC:SOURce CH1|CH2, OUTPut[1|2]:SYNC:MODE, OUTPut[1|2]:SYNC:POLarity",
        [("OUTP:SYNC OFF;:OUTP:SYNC:SOUR CH2;:OUTP2:SYNC:MODE MARK;:OUTP2:SYNC:POL INV", None),
         ("OUTP:SYNC?;:OUTP:SYNC:SOUR?;:OUTP2:SYNC:MODE?;:OUTP2:SYNC:POL?", "0;CH2;MARK;INV"),
         ("OUTP1:SYNC:MODE?;:OUTP1:SYNC:POL?", "NORM;NORM"), ("*RST", None),
         ("OUTP:SYNC?;:OUTP:SYNC:SOUR?;:OUTP2:SYNC:POL?", "1;CH1;NORM")]),
    Row("KS ? {MINimum|MAXimum|DEFault} on VOLTage:OFFSet, PHASe, OUTPut:LOAD, VOLTage:HIGH/LOW, BURSt:PHASe",
        [("VOLT:OFFS? MAX", "+5.0000000000000E+00"), ("VOLT:OFFS? DEF", "+0.0000000000000E+00"),
         ("PHAS? MIN", "-3.6000000000000E+02"), ("BURS:PHAS? MAX", "+3.6000000000000E+02"),
         ("OUTP1:LOAD? MIN;:OUTP1:LOAD? MAX;:OUTP1:LOAD? DEF",
          "+1.000000000000000E+00;+1.000000000000000E+04;+5.000000000000000E+01"),
         ("VOLT:HIGH? MAX;:VOLT:LOW? MIN", "+5.000000000000000E+00;-5.000000000000000E+00"),
         ("OUTP1:LOAD INF", None), ("VOLT:OFFS? MAX", "+1.0000000000000E+01")]),
    Row("KS UNIT:ANGLe DEGree|RADian: PHASe in that unit", [("UNIT:ANGL RAD", None), ("PHAS 1.5", None),
                                                           ("PHAS?", "+1.5000000000000E+00"), ("UNIT:ANGL DEG", None),
                                                           ("PHAS?", 85.94366926962348)]),
    Row("KS MARKer:FREQuency/CYCLe/POINt (stored, MIN/MAX)", [("MARK:FREQ 2500", None), ("MARK:FREQ?", 2500.0),
                                                             ("MARK:CYCL? MIN", 2.0)]),
    Row("KS DATA:ARBitrary <name>,<binary block> (float32, LF bytes inside), DATA:ATTRibute:POINts?",
        [("DATA:ARB sig,#232" + "\n" * 32, None), ('DATA:ATTR:POIN? "sig"', "+8.000000000000000E+00"),
         ("DATA:ARB two,1,-1", None)], [-222]),
    Row("488.2 10.27/10.29 *SAV/*RCL: settings back, outputs untouched",
        [("FREQ 2000;VOLT 0.3", None), ("*SAV 2", None), ("FREQ 5;VOLT 1", None), ("*RCL 2", None),
         ("FREQ?;VOLT?", "+2.000000000000000E+03;+3.0000000000000E-01"), ("*RCL 4", None)], [-221]),
    Row("KS VOLTage:HIGH/LOW set the levels", [("VOLT:HIGH 1", None), ("VOLT:LOW -0.5", None),
                                              ("VOLT?;VOLT:OFFS?", "+1.5000000000000E+00;+2.5000000000000E-01")]),
    Row("KS BURSt:PHASe (the burst's start phase) is not PHASe (the waveform's)",
        [("PHAS 90", None), ("BURS:PHAS -45", None),
         ("PHAS?;BURS:PHAS?", "+9.0000000000000E+01;-4.5000000000000E+01")]),
    Row("KS PHASe:SYNChronize, DISPlay:TEXT, SYSTem:BEEPer, FREQuency:MODE",
        [("PHAS:SYNC", None), ('DISP:TEXT "hello"', None), ("DISP:TEXT?", '"hello"'), ("SYST:BEEP", None),
         ("FREQ:MODE CW", None), ("FREQ:MODE?", "CW")]),
    Row("KS APPLy:SINusoid turns the output on; APPLy? answers function, frequency, amplitude, offset",
        [("APPL:SIN 5e3,3,-2.5", None), ("OUTP1?", "1"),
         ("APPL?", '"SIN +5.0000000000000E+03,+3.0000000000000E+00,-2.5000000000000E+00"')]),
    Row("488.2 11.5.1 *ESR? by error class, cleared by reading; the error queue stays",
        [("FREQU 1", None), ("*ESR?", "+32"), ("*ESR?", "+0"), ("FREQ 1e12", None), ("*ESR?", "+16")],
        [-113, -222]),
    Row("488.2 10.10/10.34 *ESE and *SRE store (bit 6 of *SRE ignored)",
        [("*ESE 61;*SRE 255", None), ("*ESE?;*SRE?", "+61;+191")]),
    Row("488.2 11.2 / SCPI vol. 1 9.1 status byte: EAV while the queue holds an error",
        [("FREQU 1", None), ("*STB?", "+4"), ("SYST:ERR?", '-113,"Undefined header"'), ("*STB?", "+0"),
         ("SYST:ERR?", '+0,"No error"')]),
    Row("488.2 11.3.2 ESB = ESR & ESE, MSS = STB & SRE",
        [("*ESE 32;*SRE 32", None), ("FREQU 1", None), ("*STB?", "+100")], [-113]),
    Row("488.2 12.5 *OPC sets ESR bit 0; *OPC? answers 1", [("*OPC", None), ("*ESR?", "+1"), ("*OPC?", "1")]),
    Row("488.2 10.3 *CLS clears the queue and the ESR",
        [("FREQU 1", None), ("*CLS", None), ("*ESR?", "+0"), ("SYST:ERR?", '+0,"No error"')]),
    Row("SCPI vol. 2 21.8.3 queue overflow: the last entry becomes -350",
        [(";".join(["FREQU 1"] * 25), None)], [-113] * 19 + [-350]),
    Row("SCPI vol. 1 9 / KS STATus Subsystem: OPERation and QUEStionable registers, STATus:PRESet",
        [("STAT:OPER:ENAB 512;:STAT:QUES:ENAB 4", None), ("STAT:OPER:ENAB?;:STAT:QUES:ENAB?", "+512;+4"),
         ("STAT:OPER?;:STAT:QUES?;:STAT:OPER:COND?", "+0;+0;+0"), ("STAT:PRES", None),
         ("STAT:OPER:ENAB?", "+0")]),
    Row("KS unknown command: -113 and no reply, never a hang", [("FOO:BAR?", None), ("DISP:WIND:FOO 3", None)],
        [-113, -113]),
]

KS1_ROWS = [
    Row("KS data sheet: the 33511B has one channel", [("*IDN?", model_word("33511B")), ("OUTP1?", "0")]),
    Row("SCPI vol. 2 21.8.4 OUTPut2/SOURce2 on a one-channel model: -114",
        [("OUTP2 OFF", None), ("SOUR2:VOLT?", None)], [-114, -114]),
]

# ------------------------------------------------------------------------------------------------
# Keysight InfiniiVision (DSOX3024T)

IV_ROWS = [
    Row("488.2 10.14 *IDN?", [("*IDN?", model_word("DSOX3024T"))]),
    Row("IV :MEASure:VPP?/VRMS?/FREQuency? [<source>] on the latest record (no signal: 0 V, 9.9E37 Hz)",
        [(":STOP", None), (":MEAS:VPP?", 0.0), (":MEAS:VRMS? CHAN1", 0.0), (":MEAS:FREQ?", 9.9e37),
         (":MEAS:VPP? CHAN5", None)], [-224]),
    Row("IV :SYSTem:SETup? a block; sent back it restores the set-up; :DISPlay:DATA? a PNG block; *SAV/*RCL",
        [(":CHAN1:SCAL 0.2", None), (":SYST:SET?", lambda r: r[:2] == b"#8" and b"scale" in r),
         (":DISP:DATA? PNG,COL", lambda r: r[:2] == b"#8" and r[10:14] == b"\x89PNG"),
         (":CHAN1:SCAL 0.2;*SAV 3;:CHAN1:SCAL 0.5;*RCL 3", None), (":CHAN1:SCAL?", 0.2)]),
    Row("IV :WAVeform:POINts n in RAW: never more than asked (10 240 from a 1 M record)",
        [(":TIM:RANG 1e-3;:STOP;:WAV:POIN:MODE RAW;:WAV:POIN 10240", None),
         (":WAV:PRE?", lambda r: 9000 < int(r.split(b",")[2]) <= 10240),
         (":WAV:POIN?", lambda r: int(r) <= 10240)]),
    Row("IV *RST defaults (channel 1 on, 1 V/div, 1 ms range, edge trigger on CHAN1, BYTE, 1000 points)",
        [(":CHAN1:DISP?", "1"), (":CHAN2:DISP?", "0"), (":CHAN1:SCAL?", 1.0), (":CHAN1:OFFS?", 0.0),
         (":CHAN1:COUP?", "DC"), (":CHAN1:IMP?", "ONEM"), (":CHAN1:PROB?", 1.0), (":CHAN1:INV?", "0"),
         (":CHAN1:LAB?", '"1"'), (":TIM:RANG?", 1e-3), (":TIM:REF?", "CENT"), (":TIM:MODE?", "MAIN"),
         (":TRIG:MODE?", "EDGE"), (":TRIG:EDGE:SOUR?", "CHAN1"), (":TRIG:EDGE:SLOP?", "POS"),
         (":TRIG:SWE?", "AUTO"), (":ACQ:TYPE?", "NORM"), (":ACQ:MODE?", "RTIM"), (":WAV:FORM?", "BYTE"),
         (":WAV:SOUR?", "CHAN1"), (":WAV:POIN:MODE?", "NORM"), (":WAV:POIN?", "+1000"),
         (":WAV:XREF?", "+0"), (":WAV:COUN?", "+1"), (":WAV:TYPE?", "NORM")]),
    Row("IV headers without the leading colon", [("CHAN1:SCAL 0.5", None), ("CHAN1:SCAL?", 0.5),
                                                 ("chan1:scal?", 0.5)]),
    Row("SCPI 6.2.4 path rule: :CHAN1:SCAL 0.5;OFFS 0.1 and :TIM:SCAL 1e-4;POS 0",
        [(":CHAN1:SCAL 0.5;OFFS 0.1", None), (":CHAN1:SCAL?", 0.5), (":CHAN1:OFFS?", 0.1),
         (":TIM:SCAL 1e-4;POS 0", None), (":TIM:SCAL?", 1e-4), (":TIM:POS?", 0.0)]),
    Row("488.2 7.4.3 tab between header and value", [(":CHAN1:SCAL\t0.2", None), (":CHAN1:SCAL?", 0.2)]),
    Row("IV NR3 replies: 13 significant digits, as a DSOX1102G answers :TIMebase:POSition? (PyMeasure's "
        "with-device test)", [(":TIM:POS 1", None), (":TIM:POS?", "+1.000000000000E+00"),
                              (":CHAN1:SCAL 0.05", None), (":CHAN1:SCAL?", "+5.000000000000E-02")]),

    Row("IV :CHANnel<n>, n = 1..4: :CHAN5 is -114 and no value", [(":CHAN5:SCAL?", None)], [-114]),
    Row("IV queries take no MIN/MAX: -108, no reply", [(":TIM:SCAL? MIN", None), (":CHAN1:SCAL? MAX", None)],
        [-108, -108]),
    Row("IV :CHANnel<n>:LABel (quoted, upper-cased), :INVert",
        [(':CHAN1:LAB "drive"', None), (":CHAN1:LAB?", '"DRIVE"'), (":CHAN1:INV 1", None), (":CHAN1:INV?", "1")]),
    Row("IV :TRIGger[:EDGE]:LEVel <level>[,<source>]",
        [(":TRIG:EDGE:LEV 0.1,CHAN1", None), (":TRIG:EDGE:LEV? CHAN1", 0.1), (":TRIG:LEV?", 0.1)]),
    Row("IV :SYSTem:PRESet restores the defaults",
        [(":CHAN1:SCAL 0.2;:CHAN2:DISP 1", None), (":SYST:PRES", None), (":CHAN1:SCAL?", 1.0),
         (":CHAN2:DISP?", "0")]),
    Row("IV :WAVeform:DATA?: the fixed 8-digit block header #800001000",
        [(":WAV:POIN 1000", None), (":STOP", None), (":WAV:PRE?", fields(10, f0="+0", f2="+1000", f6="+0")),
         (":WAV:DATA?", block(8, 1000))]),
    Row("IV :CHANnel<n>:OFFSet: the value represented at center screen; 0 V at 1 V/div, offset 2 V: BYTE code "
        "(0 - YORigin) / YINCrement + YREFerence = -2 / (10/256) + 128 = 76.8 -> 77",
        [(":CHAN1:SCAL 1;OFFS 2;:WAV:POIN 1000", None), (":STOP", None),
         (":WAV:DATA?", lambda r: r[:10] == b"#800001000" and set(r[10:]) == {77})]),
    Row("IV WORD format: two bytes a point", [(":WAV:FORM WORD;POIN 1000", None), (":STOP", None),
                                               (":WAV:DATA?", block(8, 2000))]),
    Row("IV :WAVeform:POINts:MODE RAW: the whole record only while stopped",
        [(":TIM:RANG 2e-4", None), (":WAV:POIN:MODE RAW;:WAV:POIN 1000000", None), (":RUN", None),
         (":WAV:POIN?", "+62500"), (":STOP", None), (":WAV:POIN?", "+1000000")]),
    Row("IV :OPERegister:CONDition? bit 3 (Run) while running; :RSTate?",
        [(":RUN", None), (":OPER:COND?", "+8"), (":RST?", "RUN"), (":STOP", None), (":OPER:COND?", "+0"),
         (":RST?", "STOP")]),
    Row("IV :WAVeform:DATA? with the source channel off: -221 and no block",
        [(":WAV:SOUR CHAN2", None), (":STOP", None), (":WAV:DATA?", None)], [-221]),
    Row("488.2 11.5.1 *ESR?, 488.2 12.5 *OPC, *ESE/*SRE", [
        (":FOO?", None), ("*ESR?", "+32"), ("*ESR?", "+0"), ("*ESE 1;*SRE 32;*OPC", None), ("*STB?", "+100"),
        ("*ESR?", "+1"), ("*ESE?;*SRE?", "+1;+32")], [-113]),
    Row("IV empty error queue", [(":SYST:ERR?", '+0,"No error"')]),
    Row("IV :TRIGger:FORCe: a single acquisition waiting in NORMal sweep triggers now", [
        (":TRIG:SWE NORM;:TRIG:EDGE:SOUR EXT", None), (":SING", None), (PAUSE, None), (":OPER:COND?", "+8"),
        (":TRIG:FORC", None), (PAUSE, None), (":OPER:COND?", "+0"), (":WAV:DATA?", block(8, 1000))]),
]

# ------------------------------------------------------------------------------------------------
# Rigol DG1000Z (DG1062Z)

DG_ROWS = [
    Row("488.2 10.14 *IDN?", [("*IDN?", model_word("DG1062Z"))]),
    Row("DG factory defaults: 1 kHz sine, 5 Vpp, 0 V, HighZ, output off",
        [(":SOUR1:FUNC?", "SIN"), (":SOUR1:FREQ?", "1.000000E+03"), (":SOUR1:VOLT?", "5.000000E+00"),
         (":SOUR1:VOLT:OFFS?", "0.000000E+00"), (":OUTP1:LOAD?", "INFINITY"), (":OUTP1?", "OFF"),
         (":OUTP2?", "OFF"), (":SOUR1:BURS?", "OFF"), (":SOUR1:BURS:MODE?", "TRIG"),
         (":SOUR1:BURS:TRIG:SOUR?", "INT"),
         (":SOUR1:APPL?", '"SIN,1.000000E+03,5.000000E+00,0.000000E+00,0.000000E+00"')]),
    Row("DG :OUTPut<n>[:STATe] ON|OFF answers ON/OFF", [(":OUTP1 ON", None), (":OUTP1?", "ON"),
                                                        (":OUTP1:STAT OFF", None), (":OUTP1?", "OFF")]),
    Row("DG :OUTPut<n>:LOAD <ohms>|INFinity; :IMPedance the same",
        [(":OUTP1:LOAD 50", None), (":OUTP1:LOAD?", "5.000000E+01"), (":OUTP1:IMP INF", None),
         (":OUTP1:IMP?", "INFINITY")]),
    Row("DG :SOURce<n>:BURSt[:STATe], :MODE TRIGgered|GATed|INFinity, :NCYCles, :TRIGger:SOURce INT|EXT|MAN",
        [(":SOUR1:BURS ON", None), (":SOUR1:BURS?", "ON"), (":SOUR1:BURS:NCYC 5", None),
         (":SOUR1:BURS:NCYC?", "5.000000E+00"), (":SOUR1:BURS:MODE INF", None), (":SOUR1:BURS:MODE?", "INF"),
         (":SOUR1:BURS:TRIG:SOUR MAN", None), (":SOUR1:BURS:TRIG:SOUR?", "MAN")]),
    Row("DG [:SOURce[<n>]]:BURSt:TDELay (0 to 100 s, *RST 0), :BURSt:TRIGger:SLOPe POSitive|NEGative (*RST "
        "POSitive), :OUTPut[<n>]:GATe:POLarity POSitive|NEGative (*RST POSitive; answered as the full word, the "
        "form QCoDeS's RigolDG1062 maps)",
        [(":SOUR1:BURS:TDEL?;TRIG:SLOP?", "0.000000E+00;POS"), (":OUTP1:GAT:POL?", "POSITIVE"),
         (":SOUR1:BURS:TDEL 0.25;TRIG:SLOP NEG", None), (":OUTP1:GAT:POL NEGATIVE", None),
         (":SOUR1:BURS:TDEL?;TRIG:SLOP?", "2.500000E-01;NEG"), (":OUTP1:GAT:POL?", "NEGATIVE"),
         (":SOUR2:BURS:TDEL?", "0.000000E+00"), ("*RST", None), (":SOUR1:BURS:TDEL?", "0.000000E+00"),
         (":OUTP1:GAT:POL?", "POSITIVE")]),
    Row("DG the guide's :SOURce:BURSt subsystem has no :IDLE (QCoDeS's RigolDG1062 asks :BURST:IDLE?): -113",
        [(":SOUR1:BURST:IDLE?", None)], [-113]),
    Row("DG :SOURce<n>:APPLy:SINusoid <freq>,<amp>,<offset>,<phase> turns the output on",
        [(":SOUR1:APPL:SIN 2000,2,0.5,90", None), (":OUTP1?", "ON"),
         (":SOUR1:APPL?", '"SIN,2.000000E+03,2.000000E+00,5.000000E-01,9.000000E+01"')]),
    Row("DG :OUTPut<n>:SYNC[:STATe] ON|OFF", [(":OUTP1:SYNC OFF", None), (":OUTP1:SYNC?", "OFF")]),
    Row("DG :OUTPut<n>:SYNC:POLarity POSitive|NEGative", [(":OUTP1:SYNC:POL?", "POS"), (":OUTP1:SYNC:POL NEG", None),
                                                          (":OUTP1:SYNC:POL?", "NEG"), (":OUTP1:SYNC:POL INV", None)],
        [-224]),
    Row("DG :SOURce<n>:VOLTage:UNIT VPP|VRMS|DBM and unit suffixes",
        [(":OUTP1:LOAD 50", None), (":SOUR1:VOLT:UNIT VRMS", None), (":SOUR1:VOLT 1", None),
         (":SOUR1:VOLT:UNIT VPP", None), (":SOUR1:VOLT?", "2.828427E+00"), (":SOUR1:VOLT 13 DBM", None),
         (":SOUR1:VOLT?", "2.825075E+00")]),
    Row("SCPI 6.2.4 path rule and optional colon", [(":SOUR2:FREQ 250;VOLT 1", None),
                                                    ("SOUR2:FREQ?;VOLT?", "2.500000E+02;1.000000E+00")]),
    Row("DG channels 1 and 2 only: -114", [(":SOUR3:FREQ?", None)], [-114]),
    Row("DG :SYSTem:ERRor? and 488.2 *ESR? (integers without a sign)",
        [(":FOO", None), ("*ESR?", "32"), (":SYST:ERR?", '-113,"Undefined header"'),
         (":SYST:ERR?", '0,"No error"')]),
    Row("488.2 *OPC, *ESE/*SRE store", [("*ESE 1;*SRE 32;*OPC", None), ("*STB?", "96"), ("*ESR?", "1")]),
]

# ------------------------------------------------------------------------------------------------
# Rigol DS1000Z (DS1104Z)

DS_ROWS = [
    Row("488.2 10.14 *IDN?", [("*IDN?", model_word("DS1104Z"))]),
    Row("DS *RST defaults: 1 us/div, NORMal mode, BYTE, points 1..1200, empty queue 0",
        [(":TIM:MAIN:SCAL?", "1.000000e-06"), (":TIM:SCAL?", "1.000000e-06"), (":TIM:MAIN:OFFS?", "0.000000e+00"),
         (":WAV:MODE?", "NORM"), (":WAV:FORM?", "BYTE"), (":WAV:STAR?", "1"), (":WAV:STOP?", "1200"),
         (":CHAN1:SCAL?", "1.000000e+00"), (":SYST:ERR?", '0,"No error"')]),
    Row("DS :WAVeform:PREamble? <format>: 0 (BYTE), 1 (WORD) or 2 (ASC); <type>: 0 NORM, 1 MAX, 2 RAW",
        [(":STOP", None), (":WAV:PRE?", fields(10, f0="0", f1="0", f2="1200", f3="1", f6="0", f9="127")),
         (":WAV:FORM WORD;MODE RAW", None), (":WAV:PRE?", fields(10, f0="1", f1="2", f9="127"))]),
    Row("DS :WAVeform:DATA?: TMC block with a 9-digit length, #9000001200",
        [(":STOP", None), (":WAV:DATA?", block(9, 1200))]),
    Row("DS :WAVeform:STARt/STOP select the points of one read",
        [(":STOP;:WAV:STAR 101;STOP 600", None), (":WAV:DATA?", block(9, 500))]),
    Row("DS more than 250 000 BYTE points in one read: -222 and an empty block",
        [(":TIM:MAIN:SCAL 1e-3", None), (":STOP;:WAV:MODE RAW;STAR 1;STOP 300000", None),
         (":WAV:DATA?", block(9, 0))], [-222]),
    Row("DS :TRIGger:STATus? TD|WAIT|RUN|AUTO|STOP", [(":RUN", None), (":TRIG:STAT?", "AUTO"), (":STOP", None),
                                                     (":TRIG:STAT?", "STOP")]),
    Row("SCPI 6.2.4 path rule, no leading colon", [("CHAN1:SCAL 0.5;OFFS 0.1", None),
                                                   (":CHAN1:SCAL?;OFFS?", "5.000000e-01;1.000000e-01")]),
    Row("DS :SYSTem:ERRor?, *ESR? (integers without a sign)", [(":FOO", None), ("*ESR?", "32")], [-113]),
    Row("DS :WAVeform:XREFerence?/YORigin?/YREFerence? are integers",
        [(":WAV:XREF?", "0"), (":WAV:YOR?", "0"), (":WAV:YREF?", "127")]),
    Row("DS :CHANnel<n>:OFFSet is added to the signal: the centre shows -OFFSet (:TRIGger:EDGe:LEVel range "
        "(-5 x VerticalScale - OFFSet) to (5 x VerticalScale - OFFSet)); :WAVeform:YORigin? = OFFSet/YINCrement, "
        "so 0 V reads (code - YORigin - YREFerence) x YINCrement = 0 at code 127 + 50",
        [(":CHAN1:SCAL 1;OFFS 2", None), (":WAV:YOR?", "50"), (":STOP", None),
         (":WAV:DATA?", lambda r: r[:11] == b"#9000001200" and set(r[11:]) == {177})]),
    Row("DS :CHANnel<n>:OFFSet range, probe 1X: +-100 V from 500 mV/div, +-2 V below",
        [(":CHAN1:SCAL 0.5;OFFS -50", None), (":CHAN1:OFFS?", "-5.000000e+01"),
         (":CHAN1:SCAL 0.2;OFFS 1.5", None), (":CHAN1:OFFS?", "1.500000e+00"),
         (":CHAN1:OFFS 3", None), (":CHAN1:OFFS?", "2.000000e+00")], [-222]),
    Row("DS :TRIGger:EDGe:SLOPe {POSitive|NEGative|RFALl} (answers POS, NEG, RFAL); the InfiniiVision's "
        "EITHer is a parameter error", [(":TRIG:EDGE:SLOP?", "POS"), (":TRIG:EDGE:SLOP RFAL", None),
                                        (":TRIG:EDGE:SLOP?", "RFAL"), (":TRIG:EDGE:SLOP EITH", None),
                                        (":TRIG:EDGE:SLOP?", "RFAL")], [-224]),
    Row("DS :TRIGger:EDGe:SOURce/SLOPe/LEVel in their short forms (EDG), :TRIGger:SWEep AUTO|NORMal|SINGle",
        [(":TRIG:EDG:SOUR CHAN2;SLOP NEG;LEV 0.25", None), (":TRIG:EDG:SOUR?;SLOP?;LEV?", "CHAN2;NEG;2.500000e-01"),
         (":TRIG:EDGE:SOUR?", "CHAN2"), (":TRIG:SWE NORM", None), (":TRIG:SWE?", "NORM"),
         (":TRIG:SWE SING", None), (":TRIG:SWE?", "SING")]),
    Row("DS :ACQuire:TYPE NORMal|AVERages|PEAK|HRESolution, :ACQuire:AVERages 2^n (2 to 1024)",
        [(":ACQ:TYPE?;AVER?", "NORM;2"), (":ACQ:TYPE AVER;AVER 64", None), (":ACQ:TYPE?;AVER?", "AVER;64"),
         (":ACQ:AVER 48", None), (":ACQ:AVER?", "64")], [-224]),
    Row("DS :CHANnel<n>:BWLimit 20M|OFF", [(":CHAN1:BWL?", "OFF"), (":CHAN1:BWL 20M", None), (":CHAN1:BWL?", "20M"),
                                           (":CHAN1:BWL ON", None)], [-224]),
    Row("DS :ACQuire:MDEPth AUTO|<depth for the channels on> (one channel: 12k 120k 1.2M 12M 24M; set while "
        "running; two channels: 6k ...); the memory, read in RAW, holds that depth",
        [(":ACQ:MDEP?", "AUTO"), (":RUN;:ACQ:MDEP 12000", None), (":ACQ:MDEP?", "12000"),
         (":ACQ:MDEP 6000", None), (":CHAN2:DISP 1", None), (":ACQ:MDEP 6000", None),
         (":TIM:MAIN:SCAL 1e-3;:STOP;:WAV:MODE RAW;STAR 1;STOP 6000", None),
         (":WAV:PRE?", fields(10, f0="0", f1="2", f2="6000")), (":WAV:DATA?", block(9, 6000)),
         (":ACQ:MDEP 60000", None)], [-224, -221]),
    Row("DS :WAVeform:MODE NORMal at 20 us/div and slower: the preamble and the block both hold the 1200 screen "
        "points", [(":TIM:MAIN:SCAL 2e-5", None), (":STOP", None), (":WAV:PRE?", fields(10, f2="1200")),
                   (":WAV:DATA?", block(9, 1200)), (":TIM:MAIN:SCAL 5e-4;:RUN", None), (":STOP", None),
                   (":WAV:PRE?", fields(10, f2="1200")), (":WAV:DATA?", block(9, 1200))]),
    Row("DS :MEASure:ITEM? <item>[,<source>]", [(":STOP", None), (":MEAS:ITEM? VPP,CHAN1", 0.0),
                                                (":MEAS:ITEM? FREQ", 9.9e37), (":MEAS:ITEM? FOO", None)], [-224]),
    Row("DS has no InfiniiVision :DIGitize, :OPERegister, :WAVeform:POINts", [
        (":DIG", None), (":OPER:COND?", None), (":WAV:POIN?", None)], [-113, -113, -113]),
    Row("DS :TFORce: a single acquisition waiting in NORMal sweep triggers now", [
        (":TRIG:SWE NORM;:TRIG:EDGE:SOUR AC", None), (":SING", None), (":TRIG:STAT?", "WAIT"),
        (":TFOR", None), (PAUSE, None), (":TRIG:STAT?", "STOP"), (":WAV:DATA?", block(9, 1200))]),
    Row("DS :TRIGger:EDGe:SOURce D0-D15|CHANnel1-4|AC: the four-channel DS1000Z has no EXT input (-224)", [
        (":TRIG:EDG:SOUR EXT", None), (":TRIG:EDG:SOUR?", "CHAN1"), (":TRIG:EDG:SOUR CHANnel4", None),
        (":TRIG:EDG:SOUR?", "CHAN4"), (":TRIG:EDG:SOUR AC", None), (":TRIG:EDG:SOUR?", "AC")], [-224]),
]

#: the two-channel DS1000Z-E (DS1202Z-E): the same dialect, channels 1-2 and an EXT TRIG input
DSE_ROWS = [
    Row("488.2 10.14 *IDN?", [("*IDN?", model_word("DS1202Z-E"))]),
    Row("DS1000Z-E :TRIGger:EDGe:SOURce CHANnel1|CHANnel2|EXT|AC: EXT accepted, CHANnel3 refused (-224); "
        ":CHANnel3 is no header suffix there (-114)", [
            (":TRIG:EDG:SOUR EXT", None), (":TRIG:EDG:SOUR?", "EXT"), (":TRIG:EDG:SOUR CHAN3", None),
            (":TRIG:EDG:SOUR?", "EXT"), (":CHAN3:DISP 1", None)], [-224, -114]),
]

# ------------------------------------------------------------------------------------------------
# Agilent 33220A

A2_ROWS = [
    Row("488.2 10.14 *IDN?", [("*IDN?", model_word("33220A"))]),
    Row("A2 *RST: 1 kHz sine, 100 mVpp, 0 V, 50 ohm, output off",
        [("FUNC?", "SIN"), ("FREQ?", "+1.000000000000000E+03"), ("VOLT?", "+1.0000000000000E-01"),
         ("VOLT:OFFS?", "+0.0000000000000E+00"), ("OUTP:LOAD?", "+5.000000000000000E+01"), ("OUTP?", "0")]),
    Row("A2 one output: a suffix 2 is refused (-114)", [("OUTP2 ON", None)], [-114]),
    Row("A2 PULSe:PERiod (no FUNCtion: prefix), FUNCtion USER",
        [("PULS:PER 0.002", None), ("PULS:PER?", "+2.000000000000000E-03"), ("*RST", None),
         ("PULS:PER?", "+1.000000000000000E-03"), ("FUNC USER", None), ("FUNC?", "USER")]),
    Row("A2 BURSt, TRIGger:SOURce, *TRG", [("BURS:MODE TRIG;NCYC 3;STAT ON", None), ("TRIG:SOUR BUS", None),
                                          ("BURS:NCYC?", "+3.000000000000000E+00"), ("TRIG:SOUR?", "BUS"),
                                          ("*TRG", None)]),
]


# ------------------------------------------------------------------------------------------------
# the runner

def _zeros() -> Any:
    return lambda t, rng, channels: {c: np.zeros(len(t)) for c in channels}


def _now(source: str, t_min: float) -> float | None:
    return None if source in ("EXT", "AC") else t_min   # an edge at once on the inputs; nothing on EXT, AC


def _two_channel(scope: Any, model: str) -> Any:
    """The simulated DS1000Z as the lab builds a two-channel model (labkit/lab/core.py)."""
    scope.suffix_limits = {"CHAN": 2}
    scope.idn = scope.idn.replace("DS1104Z", model)
    return scope


FACTORIES: dict[str, Callable[[], Any]] = {
    "33522B": lambda: SimKeysight33500B(model="33522B"),
    "33511B": lambda: SimKeysight33500B(model="33511B"),
    "DG1062Z": lambda: SimRigolDG1000Z(model="DG1062Z"),
    "33220A": lambda: SimAgilent33220A(),
    "DSOX3024T": lambda: SimInfiniiVision(_zeros, _now),
    "DS1104Z": lambda: SimRigolDS1000Z(_zeros, _now),
    "DS1202Z-E": lambda: _two_channel(SimRigolDS1000Z(_zeros, _now), "DS1202Z-E"),
}
ERR_QUERY = {"DG1062Z": ":SYST:ERR?", "DSOX3024T": ":SYST:ERR?", "DS1104Z": ":SYST:ERR?", "DS1202Z-E": ":SYST:ERR?"}
TABLES = {"33522B": KS_ROWS, "33511B": KS1_ROWS, "DSOX3024T": IV_ROWS, "DG1062Z": DG_ROWS, "DS1104Z": DS_ROWS,
          "DS1202Z-E": DSE_ROWS, "33220A": A2_ROWS}


@pytest.fixture(scope="module")
def served():
    servers: dict[str, tuple[TcpServer, Raw]] = {}

    def get(model: str) -> Raw:
        if model not in servers:
            server = TcpServer(FACTORIES[model](), lambda *a: None)
            server.start()
            servers[model] = (server, Raw(server.resource))
        return servers[model][1]

    yield get
    for server, client in servers.values():
        client.close()
        close = getattr(server.handler, "close", None)
        if close is not None:        # the scope: its acquisition thread
            close()
        server.close()


def _check(expect: Expect, got: bytes) -> bool:
    if callable(expect):
        return bool(expect(got))
    if isinstance(expect, float):
        return float(got) == pytest.approx(expect, rel=1e-12, abs=1e-15)
    return got.decode() == expect


CASES = [pytest.param(model, row, id=f"{model}: {row.section[:60]}") for model, rows in TABLES.items()
         for row in rows]


@pytest.mark.parametrize("model, row", CASES)
def test_conformance(served, model, row):
    c = served(model)
    c.write("*RST;*CLS;*ESE 0;*SRE 0")
    for line, expect in row.exchanges:
        if line == PAUSE:
            time.sleep(0.2)
            continue
        c.write(line)
        if expect is not None:
            got = c.reply()
            assert _check(expect, got), f"{row.section}: {line!r} -> {got[:80]!r}, expected {expect!r}"
    err = ERR_QUERY.get(model, "SYST:ERR?")
    codes = []
    for _ in range(25):
        c.write(err)
        code = int(c.reply().split(b",")[0])
        if code == 0:
            break
        codes.append(code)
    assert codes == row.errors, f"{row.section}: errors {codes}, expected {row.errors}"
    c.write("*OPC?")                          # the next line is this answer: nothing stray was sent
    assert c.reply() == b"1"


# ------------------------------------------------------------------------------------------------
# the serial controllers

class Serial:
    def __init__(self, path: str) -> None:
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
        self.buf = b""

    def send(self, line: str) -> None:
        os.write(self.fd, line.encode("ascii") + b"\n")

    def reply(self, timeout_s: float = 2.0) -> bytes:
        deadline = time.monotonic() + timeout_s
        while b"\n" not in self.buf:
            left = deadline - time.monotonic()
            r, _, _ = select.select([self.fd], [], [], max(0.0, left))
            if not r:
                raise TimeoutError("no reply")
            self.buf += os.read(self.fd, 4096)
        line, self.buf = self.buf.split(b"\n", 1)
        return line


PV5_ROWS = [
    Row("PV OFV-5000: Get,<Dev>,<i>,<Prop>", [("Get,VeloDec,1,Range", "125mm/s/V"), ("Get,VeloDec,1,Name", "VD-09")]),
    Row("PV OFV-5000: Set answers nothing; the setting reads back",
        [("Set,VeloDec,1,Range,5mm/s/V", None), ("Get,VeloDec,1,Range", "5mm/s/V"),
         ("Set,VeloDec,1,Range,125mm/s/V", None), ("Get,VeloDec,1,Range", "125mm/s/V")]),
    Row("PV OFV-5000: an invalid value is ignored silently",
        [("Set,VeloDec,1,Range,7mm/s/V", None), ("Get,VeloDec,1,Range", "125mm/s/V")]),
    Row("PV OFV-5000: GetDevInfo lists the allowed values",
        [("GetDevInfo,VeloDec,1,Range", "1mm/s/V,5mm/s/V,25mm/s/V,125mm/s/V,1000mm/s/V"),
         ("GetDevInfo,Nothing,0,Name", "Not Available")]),
]
PV3_ROWS = [
    Row("PV OFV-3001: settings before REN are ignored", [("VELO1", None), ("VELO?", "3")]),
    Row("PV OFV-3001: REN, VELOn, VELO? (OVD-01 range numbers 1-5)",
        [("REN", None), ("VELO1", None), ("VELO?", "1"), ("VELO3", None), ("VELO?", "3")]),
    Row("PV OFV-3001: an invalid range is ignored silently", [("REN", None), ("VELO7", None), ("VELO?", "3")]),
    Row("PV OFV-3001: OVR answers 0 or 1", [("OVR", "0")]),
]


@pytest.mark.parametrize("cls, rows, probe", [
    (SimOFV5000, PV5_ROWS, ("Get,Controller,0,Name", b"OFV-5000")),
    (SimOFV3001, PV3_ROWS, ("OVR", b"0")),
], ids=["OFV-5000", "OFV-3001"])
def test_serial_controller_conformance(cls, rows, probe):
    server = PtyServer(cls(), lambda *a: None)
    server.start()
    port = Serial(server.path)
    try:
        for row in rows:
            for line, expect in row.exchanges:
                port.send(line)
                if expect is not None:
                    got = port.reply()
                    assert got.decode() == expect, f"{row.section}: {line!r} -> {got!r}, expected {expect!r}"
            port.send(probe[0])                   # nothing stray before this answer
            assert port.reply() == probe[1], row.section
    finally:
        os.close(port.fd)
        server.close()
