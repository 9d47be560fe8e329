"""The handshake on open: identity -> model and channels, the error queue drained and recorded, ``*CLS``."""
from __future__ import annotations

import json

import pytest

from labkit.drivers.funcgen import Agilent33220A, Keysight33500B, RigolDG1000Z
from labkit.drivers.scope import InfiniiVision, RigolDS1000Z
from labkit.drivers.testing import expected_protocol
from labkit.errors import ConfigError, InstrumentError

OK = b'+0,"No error"\n'


def _w(*cmds: str):
    return [(c.encode() + b"\n", None) for c in cmds]


def test_stale_errors_are_drained_recorded_and_not_blamed_on_the_first_setting():
    # an earlier program left two errors; the first set_sine must not raise them
    stale = ['-113,"Undefined header"', '-222,"Data out of range"']
    script = _w("OUTP1:LOAD INF", "SOUR1:FUNC SIN", "SOUR1:VOLT:UNIT VPP", "SOUR1:FREQ 1000",
                "SOUR1:VOLT 2", "SOUR1:VOLT:OFFS 0") + [(b"SYST:ERR?\n", OK)]
    with expected_protocol(Keysight33500B, script, errors_at_connect=stale, max_amp_vpp=10) as fg:
        assert fg.errors_at_connect == stale
        fg.set_sine(1000, 2, 0.0)
        snap = json.loads(json.dumps(fg.snapshot()))
    assert snap["connect"]["errors_at_connect"] == stale


def test_handshake_bytes_in_order():
    """*IDN?, the error query until empty, *CLS: exactly these bytes, nothing else."""
    script = [(b"*IDN?\n", b"Rigol Technologies,DG1022Z,DG1ZA1,00.01.14\n"),
              (b":SYST:ERR?\n", b'-113,"Undefined header"\n'), (b":SYST:ERR?\n", b'0,"No error"\n'),
              (b"*CLS\n", None)]
    with expected_protocol(RigolDG1000Z, script, handshake=False) as fg:
        assert fg.errors_at_connect == ['-113,"Undefined header"']
        assert fg.channels == (1, 2)


@pytest.mark.parametrize("model, channels", [("33511B", 1), ("33521B", 1), ("33512B", 2), ("33522B", 2)])
def test_33500b_channel_count_from_identity_safe_off_touches_only_existing_outputs(model, channels):
    idn = f"Keysight Technologies,{model},MY1,4.03"
    offs = [f"OUTP{ch} OFF" for ch in range(1, channels + 1)]
    with expected_protocol(Keysight33500B, _w(*offs) + [(b"*OPC?\n", b"1\n")], identity=idn) as fg:
        assert fg.channels == tuple(range(1, channels + 1))
        fg.safe_off()


def test_channel_two_on_a_one_channel_model_is_refused_after_the_identity():
    script = [(b"*IDN?\n", b"Keysight Technologies,33511B,MY1,4.03\n")]
    with pytest.raises(ConfigError, match="33511B has 1 channel") as ei:
        with expected_protocol(Keysight33500B, script, handshake=False, channel=2):
            pass
    assert ei.value.key == "channel"


@pytest.mark.parametrize("cls, idn", [
    (Keysight33500B, "Keysight Technologies,34461A,MY1,A.02"),       # a multimeter
    (Keysight33500B, "Agilent Technologies,33220A,MY1,2.07"),        # another generator family
    (Agilent33220A, "Keysight Technologies,33522B,MY1,4.03"),
    (RigolDG1000Z, "Rigol Technologies,DG4062,DG4A1,00.01"),
    (InfiniiVision, "TEKTRONIX,TDS 2024B,0,CF:91.1CT"),
    (RigolDS1000Z, "RIGOL TECHNOLOGIES,DS2072A,DS2A1,00.03"),
])
def test_unknown_model_is_refused_with_a_clear_error_and_nothing_else_sent(cls, idn):
    with pytest.raises(ConfigError) as ei:
        with expected_protocol(cls, [(b"*IDN?\n", idn.encode() + b"\n")], handshake=False):
            pass
    text = str(ei.value)
    assert idn.split(",")[1] in text and cls.model in text and ei.value.key == "model"


def test_garbled_identity_is_an_instrument_error():
    with pytest.raises(InstrumentError, match="garbled identity") as ei:
        with expected_protocol(Keysight33500B, [(b"*IDN?\n", b"hello\n")], handshake=False):
            pass
    assert ei.value.command == "*IDN?"


@pytest.mark.parametrize("cls, word, channels", [
    (InfiniiVision, "DSOX3024T", 4), (InfiniiVision, "DSOX1102G", 2), (InfiniiVision, "DSO-X 2024A", 4),
    (InfiniiVision, "MSOX4154A", 4), (InfiniiVision, "EDUX1052G", 2),
    (RigolDS1000Z, "DS1104Z", 4), (RigolDS1000Z, "DS1054Z", 4), (RigolDS1000Z, "DS1202Z-E", 2),
])
def test_scope_channel_count_from_identity(cls, word, channels):
    maker = "RIGOL TECHNOLOGIES" if cls is RigolDS1000Z else "KEYSIGHT TECHNOLOGIES"
    with expected_protocol(cls, [], identity=f"{maker},{word},X1,1.0") as sc:
        assert sc.n_channels == channels and sc.instrument_model == word
        assert sc.snapshot()["connect"]["channels"] == channels


def test_declared_scope_channels_must_agree_with_the_identity():
    with pytest.raises(ConfigError, match="channels = 4 declared") as ei:
        with expected_protocol(InfiniiVision, [(b"*IDN?\n", b"KEYSIGHT TECHNOLOGIES,DSOX1102G,X,1\n")],
                               handshake=False, channels=4):
            pass
    assert ei.value.key == "channels"


@pytest.mark.parametrize("resource, says", [
    ("TCPIP0::127.9.9.9::hislip0::INSTR", "no HiSLIP server answered at 127.9.9.9, port 4880"),
    ("TCPIP0::127.9.9.9::inst0::INSTR", "no VXI-11 portmapper at 127.9.9.9, port 111"),
    ("USB0::0x0957::0x2C07::MY1::INSTR", "USB resources need the pyusb package"),
    ("GPIB0::10::INSTR", "GPIB resources need linux-gpib or gpib-ctypes"),
])
def test_every_resource_form_fails_with_one_clear_line(resource, says):
    """Every form a user writes is accepted; where nothing answers or a back-end is missing, one line
    says which and what to write instead (pyvisa-py's own 'resource not present' for HiSLIP misleads)."""
    with pytest.raises(InstrumentError) as exc:
        Keysight33500B.open(resource, timeout_s=1)
    text = str(exc.value)
    assert says in text and "\n" not in text and exc.value.command == "open"
