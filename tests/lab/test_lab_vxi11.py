"""VXI-11 (``TCPIP0::host::inst0::INSTR``) beside the raw sockets: labkit's drivers, a third-party
client that speaks nothing else (the ``ds1054z`` package, over ``python-vxi11``), and plain pyvisa
scripts written from each maker's programming examples.

The lab's portmapper owns port 111 on its own loopback address (these tests run as root, as CI
does). VXI-11 specification B.6 (core channel), RFC 1833 (portmapper), IEEE 488.2 6.3.2.3
(-410 on an interrupted query).
"""
from __future__ import annotations

import time

import numpy as np
import pytest
import pyvisa
from labhelpers import knee_frf_over, settle

from labkit.drivers import registry
from labkit.lab import VirtualLab


@pytest.fixture(scope="module")
def lab():
    with VirtualLab(seed=7, vxi11=True, scope_memory_points=100_000) as lab:
        yield lab


@pytest.fixture(scope="module")
def rigol_lab():
    with VirtualLab(seed=8, vxi11=True, funcgen_model="DG1062Z", scope_model="DS1104Z",
                    scope_memory_points=100_000) as lab:
        yield lab


def test_labkit_drivers_measure_the_frf_over_vxi11(lab):
    res = lab.vxi11_resources
    assert res["scope"].endswith("::inst0::INSTR") and res["funcgen"].endswith("::inst0::INSTR")
    ratio = knee_frf_over(lab, res["funcgen"], res["scope"])
    assert abs(ratio) == pytest.approx(1.0, rel=0.01) and abs(np.angle(ratio)) < 0.01


def test_an_unread_reply_is_interrupted_by_the_next_message(lab):
    rm = pyvisa.ResourceManager("@py")
    fg = rm.open_resource(lab.vxi11_resources["funcgen"], timeout=3000, read_termination="\n")
    try:
        fg.write("*CLS")
        fg.write("FREQ?")              # its reply is never read ...
        fg.write("*OPC")               # ... when the next message arrives
        assert fg.query("SYST:ERR?") == '-410,"Query INTERRUPTED"'
        assert fg.query("SYST:ERR?") == '+0,"No error"'
        assert fg.read_stb() == 0
    finally:
        fg.close()


def test_ds1054z_package_reads_the_lab_scope_over_vxi11(rigol_lab):
    """The ``ds1054z`` package (0.4, vxi11 only): identity, 1200 screen samples in NORMal mode at
    20 us/div (the 1201/1200 case it failed on), the whole memory in RAW mode, volts that match the
    drive, and a screenshot."""
    from ds1054z import DS1054Z

    lab = rigol_lab
    host = lab.vxi11_resources["scope"].split("::")[1]
    with registry.driver_class("DG1000Z").open(lab.resources["funcgen"], timeout_s=5) as fg:
        fg.set_sine(5000.0, 2.0)
        fg.output(True)
        scope = DS1054Z(host)
        try:
            assert scope.idn.startswith("RIGOL TECHNOLOGIES,DS1104Z")
            scope.write(":CHAN1:DISP 1;:CHAN1:SCAL 0.5;:TIM:MAIN:SCAL 2e-5;:TRIG:EDG:SOUR CHAN1;:TRIG:EDG:LEV 0")
            scope.write(":TRIG:SWE NORM")
            scope.run()
            scope.write(":ACQ:MDEP 12000")      # one channel on: 12k is a listed depth
            settle(lab)
            normal = np.asarray(scope.get_waveform_samples("CHAN1", mode="NORMal"))
            assert normal.size == 1200
            raw = np.asarray(scope.get_waveform_samples("CHAN1", mode="RAW"))
            assert raw.size == 12000 == int(scope.query(":ACQ:MDEP?"))
            assert np.ptp(raw) == pytest.approx(2.0, rel=0.05)
            png = scope.display_data
            assert png[:4] == b"\x89PNG"
            assert scope.query(":SYST:ERR?") == '0,"No error"'
        finally:
            scope.close()


def _until(done, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < deadline, "the acquisition did not complete"
        time.sleep(0.005)


@pytest.mark.parametrize("which", ["keysight", "rigol"])
def test_a_makers_programming_example_runs_over_vxi11(which, lab, rigol_lab):
    """Plain pyvisa, the steps of the makers' examples (33500B Operating and Service Guide,
    "Burst Mode" example; InfiniiVision 3000T Programmer's Guide, "Programming Examples: VISA
    Python"; DG1000Z Programming Guide, "Programming Examples"; DS1000Z Programming Guide,
    ":WAVeform" example): configure, burst, acquire, empty the error queue. The four-channel DS1104Z
    has no EXT input (DS :TRIGger:EDGe:SOURce): it triggers on the drive, channel 1."""
    bench = lab if which == "keysight" else rigol_lab
    rm = pyvisa.ResourceManager("@py")
    gen = rm.open_resource(bench.vxi11_resources["funcgen"], timeout=5000, read_termination="\n",
                           write_termination="\n")
    osc = rm.open_resource(bench.vxi11_resources["scope"], timeout=10000, read_termination="\n",
                           write_termination="\n")
    try:
        if which == "keysight":
            for cmd in ("*RST", "*CLS", "OUTP1:LOAD INF", "SOUR1:FUNC SIN", "SOUR1:FREQ 2000", "SOUR1:VOLT 1",
                        "SOUR1:BURS:MODE TRIG", "SOUR1:BURS:NCYC 20", "TRIG1:SOUR BUS", "SOUR1:BURS:STAT ON",
                        "OUTP:SYNC ON", "OUTP1 ON"):
                gen.write(cmd)
            # (reference LEFT, position one division: the record starts at the trigger, no pre-trigger
            # time during which a trigger would be ignored)
            for cmd in ("*RST", ":CHAN1:DISP 1", ":CHAN1:SCAL 0.2", ":TIM:RANG 5e-3", ":TIM:REF LEFT", ":TIM:POS 5e-4",
                        ":TRIG:EDGE:SOUR EXT", ":TRIG:EDGE:LEV 1", ":TRIG:SWE NORM", ":WAV:FORM WORD",
                        ":WAV:BYT MSBF", ":WAV:UNS 1", ":WAV:POIN:MODE RAW", ":WAV:POIN 5000", ":SING"):
                osc.write(cmd)
            osc.query("*STB?")
            gen.write("*TRG")
            _until(lambda: not int(osc.query(":OPER:COND?")) & 8)
            pre = osc.query(":WAV:PRE?").split(",")
            data = osc.query_binary_values(":WAV:DATA?", datatype="H", is_big_endian=True, container=np.array)
            volts = (data - float(pre[9])) * float(pre[7]) + float(pre[8])
            errors = [osc.query(":SYST:ERR?"), gen.query("SYST:ERR?")]
            ok = ["+0,\"No error\""] * 2
        else:
            for cmd in ("*RST", "*CLS", ":OUTP1:LOAD INF", ":SOUR1:APPL:SIN 2000,2,0,0", ":SOUR1:BURS:MODE TRIG",
                        ":SOUR1:BURS:NCYC 20", ":SOUR1:BURS:TRIG:SOUR MAN", ":SOUR1:BURS ON", ":OUTP1:SYNC ON",
                        ":OUTP1 ON"):
                gen.write(cmd)
            for cmd in ("*RST", ":CHAN1:DISP 1", ":CHAN1:SCAL 0.2", ":TIM:MAIN:SCAL 5e-4", ":TIM:MAIN:OFFS 3e-3",
                        ":TRIG:EDG:SOUR CHAN1", ":TRIG:EDG:LEV 0.5", ":TRIG:SWE NORM", ":SING"):
                osc.write(cmd)
            osc.query("*STB?")
            gen.write("*TRG")
            _until(lambda: osc.query(":TRIG:STAT?") == "STOP")
            osc.write(":WAV:SOUR CHAN1;:WAV:MODE NORM;:WAV:FORM BYTE")
            pre = osc.query(":WAV:PRE?").split(",")
            data = osc.query_binary_values(":WAV:DATA?", datatype="B", container=np.array)
            volts = (data - float(pre[8]) - float(pre[9])) * float(pre[7])
            errors = [osc.query(":SYST:ERR?"), gen.query(":SYST:ERR?")]
            ok = ['0,"No error"'] * 2
        assert errors == ok
        assert int(pre[2]) == len(data) > 1000
        amp = 0.5 if which == "keysight" else 1.0
        assert np.max(np.abs(volts)) == pytest.approx(amp, rel=0.05)     # the burst is in the record
        assert np.min(np.abs(volts[-50:])) < 0.05 * amp or np.ptp(volts[:50]) < 0.1 * amp
    finally:
        gen.close()
        osc.close()


def test_python_vxi11_client_drives_the_generator(lab):
    """python-vxi11's own ONC-RPC client (not pyvisa's) on the 33522B: ask/write, device trigger
    (VXI-11 device_trigger: the instrument's *TRG), the status byte, lock/unlock, device clear."""
    import vxi11

    host = lab.vxi11_resources["funcgen"].split("::")[1]
    inst = vxi11.Instrument(host)
    try:
        assert inst.ask("*IDN?").startswith("Keysight Technologies,33522B")
        inst.write("*RST;*CLS;:OUTP1:LOAD INF;:SOUR1:FREQ 1000;VOLT 2;BURS:NCYC 3;:SOUR1:BURS:STAT ON;:TRIG1:SOUR BUS")
        inst.write("OUTP1 ON")
        inst.lock()
        inst.trigger()
        inst.unlock()
        assert any(inst_ == "funcgen" and ch == 1 for _, inst_, ch, _ in lab.burst_timeline)
        assert inst.read_stb() == 0
        inst.write("FREQ?")
        inst.clear()                          # device clear empties the output buffer: no -410
        assert inst.ask("SYST:ERR?") == '+0,"No error"'
        inst.write("OUTP1 OFF")
    finally:
        inst.close()
