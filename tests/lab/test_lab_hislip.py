"""HiSLIP (IVI-6.1) beside raw sockets and VXI-11: pyvisa-py's own HiSLIP client
(``TCPIP0::host::hislip0,<port>::INSTR``) against the lab, and labkit's drivers through it.

Synchronized mode: a message runs when its DataEnd arrives; the reply is a DataEnd carrying that
message's id, split into Data messages beyond the client's maximum message size.
"""
from __future__ import annotations

import time

import numpy as np
import pytest
import pyvisa
from labhelpers import knee_frf_over

from labkit.lab import VirtualLab


@pytest.fixture(scope="module")
def lab():
    with VirtualLab(seed=31, hislip=True, scope_memory_points=100_000) as lab:
        yield lab


def test_pyvisa_py_speaks_hislip_to_the_lab(lab):
    """Open (Initialize, AsyncInitialize, AsyncMaxMsgSize), queries, a 200 kB block split into Data
    messages of a 64 kB maximum, the status byte (AsyncStatusQuery), device clear, trigger, lock."""
    rm = pyvisa.ResourceManager("@py")
    res = lab.hislip_resources
    assert res["scope"].startswith("TCPIP0::127.0.0.1::hislip0,") and res["scope"].endswith("::INSTR")
    sc = rm.open_resource(res["scope"], timeout=10000, read_termination="\n", write_termination="\n")
    fg = rm.open_resource(res["funcgen"], timeout=5000, read_termination="\n", write_termination="\n")
    try:
        assert sc.query("*IDN?").split(",")[1] == "DSOX3024T"
        assert fg.query("*IDN?").split(",")[1] == "33522B"
        sc.set_visa_attribute(pyvisa.constants.ResourceAttribute.tcpip_hislip_max_message_kb, 64)
        sc.write(":CHAN1:DISP 1;:TIM:RANG 1e-3;:TRIG:SWE AUTO;:SING")
        deadline = time.monotonic() + 5           # AUTO: an untriggered record after 50 ms
        while int(sc.query(":OPER:COND?")) & 8 and time.monotonic() < deadline:
            time.sleep(0.02)
        sc.write(":STOP;:WAV:SOUR CHAN1;:WAV:FORM WORD;:WAV:POIN:MODE RAW;:WAV:POIN 100000")
        data = sc.query_binary_values(":WAV:DATA?", datatype="H", is_big_endian=True, container=np.array)
        assert data.size == int(sc.query(":WAV:PRE?").split(",")[2]) == 100_000
        fg.write("*ESE 1;*CLS;*OPC")
        assert fg.read_stb() & 0x20            # ESB: the operation-complete event, by AsyncStatusQuery
        fg.clear()
        assert fg.query("SYST:ERR?") == '+0,"No error"'
    finally:
        sc.close()
        fg.close()      # not rm.close(): pyvisa shares one session per library in a process


def test_pyvisa_py_hislip_protocol_trigger_lock_and_remote(lab):
    """What pyvisa-py's session does not expose, through its protocol class (pyvisa_py.protocols.hislip):
    the Trigger message (the instrument's *TRG, in order with the data messages), AsyncLock
    request/release, AsyncLockInfo, AsyncRemoteLocalControl."""
    from pyvisa_py.protocols.hislip import Instrument

    host, port = lab.hislip_resources["funcgen"].split("::")[1:3]
    inst = Instrument(host, timeout=5.0, port=int(port.split(",")[1]))
    try:
        inst.send(b"BURS:MODE TRIG;NCYC 2;STAT ON;:TRIG:SOUR BUS;:OUTP1 ON\n")
        inst.trigger()
        inst.send(b"SYST:ERR?\n")
        assert bytes(inst.receive(4096)) == b'+0,"No error"\n'
        assert inst.async_lock_info() == 0
        assert inst.async_lock_request(1.0) == "success" and inst.async_lock_info() == 1
        assert inst.async_lock_release() == "success" and inst.async_lock_info() == 0
        assert inst.async_lock_release() == "error"            # not held
        inst.async_remote_local_control("enableRemote")
        inst.send(b"*RST\n")                  # output off, burst off: the next test starts clean
    finally:
        inst.close()
    rx = [t for _, who, d, t in lab.log if who == "funcgen" and d == "rx"]
    at = rx.index("*TRG")
    assert rx[at - 1].endswith(":OUTP1 ON") and rx[at + 1] == "SYST:ERR?"


def test_labkit_drivers_measure_the_frf_over_hislip(lab):
    res = lab.hislip_resources
    ratio = knee_frf_over(lab, res["funcgen"], res["scope"])
    assert abs(ratio) == pytest.approx(1.0, rel=0.01) and abs(np.angle(ratio)) < 0.01
    assert lab.output_state("funcgen", 1) is False       # the driver's close switched it off
