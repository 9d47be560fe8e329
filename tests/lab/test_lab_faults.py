"""Fault injection: a dropped connection mid-block, a stall, garbage — seen quickly by clients."""
from __future__ import annotations

import socket
import time

import numpy as np
import pytest
import pyvisa
import serial
from labhelpers import Raw, lab, raw  # noqa: F401  (fixtures)

from labkit.lab.transport import Fault


def _arm_big_record(sc: Raw) -> None:
    sc.write(":TIM:RANG 1e-3;:WAV:POIN:MODE RAW;:WAV:POIN 200000;:WAV:FORM WORD;:WAV:SOUR CHAN1")
    assert sc.query(":DIG;*OPC?") == "1"


def test_fault_counting_and_matching():
    f = Fault("stall", after=2, match="data?")
    assert [f.hits(c) for c in (":WAV:PRE?", ":WAV:DATA?", ":WAV:DATA?", "*IDN?", ":WAV:DATA?", ":WAV:DATA?")] \
        == [False, False, False, False, True, False]
    with pytest.raises(ValueError):
        Fault("explode")


def test_drop_closes_the_connection_mid_block(lab, raw):
    sc = raw("scope")
    _arm_big_record(sc)
    lab.inject_fault("scope", "drop", match="DATA?")
    t0 = time.monotonic()
    with pytest.raises(ConnectionError, match="closed after"):
        sc.query_block(":WAV:DATA?")
    assert time.monotonic() - t0 < 1.0
    assert 1000 < len(sc.buf) < 400_010          # part of the block came, not all of it
    # the instrument itself survives: a new connection works and the fault is spent
    sc2 = raw("scope")
    assert sc2.query("*IDN?").startswith("KEYSIGHT")
    assert len(sc2.query_block(":WAV:DATA?")) == 400_000
    assert any(d == "fault" and "drop" in text for _, inst, d, text in lab.log if inst == "scope")


def test_stall_withholds_the_reply_then_recovers(lab, raw):
    fg = raw("funcgen", timeout_s=0.3)
    lab.inject_fault("funcgen", "stall", after=1)
    assert fg.query("*IDN?").startswith("Keysight")          # after=1: this one still answers
    with pytest.raises(socket.timeout):
        fg.query("FREQ?")
    fg.write("OUTP1 OFF")                                     # commands still get through
    assert fg.query("OUTP1?") == "0"


def test_garbage_reply_through_pyvisa(lab):
    rm = pyvisa.ResourceManager("@py")
    fg = rm.open_resource(lab.resources["funcgen"], read_termination="\n", write_termination="\n",
                          timeout=1000)
    try:
        lab.inject_fault("funcgen", "garbage")
        fg.write("FREQ?")
        raw_reply = fg.read_raw()
        assert raw_reply.endswith(b"\n") and all(b >= 128 for b in raw_reply[:-1])
        with pytest.raises(UnicodeDecodeError):
            raw_reply.decode("ascii")
        assert float(fg.query("FREQ?")) == 1000.0            # one reply spoiled, then normal
    finally:
        fg.close()


def test_plain_pyvisa_gives_up_on_a_drop_mid_block_within_its_timeout(lab, raw):
    """pyvisa-py cannot tell a dropped socket from a stall: it raises at its own timeout, not
    earlier (labkit.drivers.base wraps this in one InstrumentError; see tests/lab/test_lab_drivers.py)."""
    _arm_big_record(raw("scope"))
    rm = pyvisa.ResourceManager("@py")
    sc = rm.open_resource(lab.resources["scope"], read_termination="\n", write_termination="\n",
                          timeout=1000)
    try:
        sc.write(":WAV:POIN:MODE RAW;:WAV:POIN 200000;:WAV:FORM WORD;:WAV:SOUR CHAN1")
        lab.inject_fault("scope", "drop", match="DATA?")
        t0 = time.monotonic()
        with pytest.raises(pyvisa.errors.VisaIOError):
            sc.query_binary_values(":WAV:DATA?", datatype="H", is_big_endian=True, container=np.array)
        assert time.monotonic() - t0 < 2.0       # the 1 s timeout, plus slack: no hang
    finally:
        sc.close()


def test_pty_faults(lab):
    path = lab.resources["vibrometer"][4:-7]
    with serial.Serial(path, 115200, timeout=0.3) as port:
        lab.inject_fault("vibrometer", "garbage")
        port.write(b"Get,VeloDec,1,Range\n")
        junk = port.readline()
        assert junk.endswith(b"\n") and all(b >= 128 for b in junk[:-1])
        lab.inject_fault("vibrometer", "stall")
        port.write(b"Get,VeloDec,1,Range\n")
        assert port.readline() == b""
        lab.inject_fault("vibrometer", "drop")
        port.write(b"Get,VeloDec,1,Range\n")
        partial = port.readline()
        assert partial and not partial.endswith(b"\n")           # cut mid-reply
        port.write(b"Get,VeloDec,1,Range\n")
        assert port.readline() == b""                              # and the line stays dead
        lab.clear_faults("vibrometer")
        port.write(b"Get,VeloDec,1,Range\n")
        assert port.readline() == b"125mm/s/V\n"
