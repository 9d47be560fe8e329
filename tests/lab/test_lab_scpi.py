"""The SCPI framework and the simulated 33500B, over a raw loopback socket."""
from __future__ import annotations

import pytest
from labhelpers import lab, raw  # noqa: F401  (fixtures)

from labkit.lab.scpi import SimScpiInstrument, compile_pattern, definite_block, parse_number, split_commands


def test_pattern_accepts_short_and_long_forms_only():
    rx = compile_pattern("[SOURce#:]FREQuency[:CW]")
    for ok in ("FREQ", "FREQUENCY", ":SOUR2:FREQ", "SOURCE1:FREQUENCY:CW", "SOUR:FREQ:CW"):
        assert rx.fullmatch(ok), ok
    for bad in ("FREQU", "FRE", "SOURC1:FREQ", "FREQ:C", "SOUR1FREQ"):
        assert not rx.fullmatch(bad), bad
    assert rx.fullmatch("SOUR2:FREQ").group(1) == "2"


def test_numbers_units_and_limits():
    assert parse_number("1 KHZ", "HZ") == 1000.0
    assert parse_number("2.5e3", "HZ") == 2500.0
    assert parse_number("5 MV", "V") == pytest.approx(5e-3)
    assert parse_number("MAX", "HZ", minimum=1, maximum=9) == 9
    assert parse_number("12", "", minimum=1, maximum=9, clip=True) == 9
    assert definite_block(b"abc") == b"#13abc"
    assert split_commands('A 1;B "x;y";C?') == ["A 1", 'B "x;y"', "C?"]


def test_error_queue_overflow_keeps_first_entries():
    inst = SimScpiInstrument()
    for _ in range(25):
        assert inst.handle("NOPE") is None
    replies = [inst.handle("SYST:ERR?").decode().strip() for _ in range(21)]
    assert replies[0] == '-113,"Undefined header"'
    assert replies[19] == '-350,"Queue overflow"'
    assert replies[20] == '+0,"No error"'


def test_identity_long_short_forms_and_error_queue(raw):
    fg = raw("funcgen")
    assert fg.query("*IDN?").startswith("Keysight Technologies,33522B,")
    fg.write("SOURce1:FREQuency 1234.5")
    assert float(fg.query("FREQ?")) == 1234.5
    assert float(fg.query(":SOUR1:FREQUENCY?")) == 1234.5
    fg.write("sour2:freq 2 khz")              # case-insensitive, with a unit suffix
    assert float(fg.query("SOUR2:FREQ?")) == 2000.0
    assert float(fg.query("SOUR1:FREQ?")) == 1234.5
    fg.write("FREQU 10")                      # neither the short nor the long form
    fg.write("SOUR1:FREQ abc")
    assert fg.query("SYST:ERR?") == '-113,"Undefined header"'
    assert fg.query("SYSTem:ERRor?").startswith("-10")     # a data type / syntax error
    assert fg.query("SYST:ERR?") == '+0,"No error"'
    assert float(fg.query("FREQ?")) == 1234.5             # the bad commands changed nothing


def test_compound_commands_follow_the_scpi_path_rule(raw):
    fg = raw("funcgen")
    assert fg.query("SOUR2:FREQ 500;VOLT 0.4;:SOUR2:FREQ?;VOLT?") == \
        "+5.000000000000000E+02;+4.0000000000000E-01"
    assert float(fg.query("SOUR1:FREQ?")) == 1000.0      # channel 1 untouched


def test_load_setting_doubles_the_voltage_at_a_high_z_load(lab, raw):
    fg = raw("funcgen")
    fg.write("VOLT 2")                        # programmed for the default 50 ohm load
    assert fg.query("*OPC?") == "1"
    assert lab.funcgen.drive(1).amp_v == pytest.approx(2.0)   # the PZT (high Z) sees 4 Vpp
    fg.write("OUTP1:LOAD INF")                # the output is kept, the display rescales
    assert float(fg.query("VOLT?")) == pytest.approx(4.0)
    assert float(fg.query("OUTP1:LOAD?")) > 1e37
    fg.write("VOLT 2")
    assert fg.query("*OPC?") == "1"
    assert lab.funcgen.drive(1).amp_v == pytest.approx(1.0)


def test_out_of_range_amplitude_is_clipped_with_error(raw):
    fg = raw("funcgen")
    fg.write("OUTP:LOAD INF;:VOLT 50")
    assert fg.query("SYST:ERR?").startswith('-222,"Data out of range')
    assert float(fg.query("VOLT?")) == pytest.approx(20.0)
    assert float(fg.query("SWE:TIME? MAX")) > 1.0


def test_outputs_are_logged_and_put_on_the_timeline(lab, raw):
    fg = raw("funcgen")
    fg.write("OUTP1 ON")
    fg.write("OUTPut2 ON")
    fg.write("OUTP1 OFF")
    assert fg.query("OUTP1?") == "0" and fg.query("OUTP2?") == "1"
    changes = [(inst, ch, on) for _, inst, ch, on in lab.output_timeline]
    assert changes == [("funcgen", 1, False), ("funcgen", 2, False), ("funcgen", 1, True),
                       ("funcgen", 2, True), ("funcgen", 1, False)]
    times = [t for t, *_ in lab.output_timeline]
    assert times == sorted(times)
    rx = [text for _, inst, d, text in lab.log if inst == "funcgen" and d == "rx"]
    assert rx[:3] == ["OUTP1 ON", "OUTPut2 ON", "OUTP1 OFF"]
    tx = [text for _, inst, d, text in lab.log if inst == "funcgen" and d == "tx"]
    assert tx == ["0", "1"]
    assert fg.query("*RST;*OPC?") == "1"          # *RST switches outputs off
    assert lab.output_state("funcgen", 2) is False


def test_lab_close_switches_outputs_off(raw, lab):
    fg = raw("funcgen")
    fg.write("OUTP1 ON")
    assert fg.query("*OPC?") == "1"
    lab.close()
    assert lab.output_timeline[-1][1:] == ("funcgen", 1, False)
