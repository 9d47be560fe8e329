"""Oscilloscopes: channel set-up, acquisition, binary transfers, scaling, faults."""
from __future__ import annotations

import time

import numpy as np
import pytest

from labkit.drivers.scope import InfiniiVision, RigolDS1000Z
from labkit.drivers.testing import STALL, Drop, expected_protocol
from labkit.errors import InstrumentError, LimitError

OK = b'+0,"No error"\n'
R_OK = b'0,"No error"\n'


def _w(*cmds: str):
    return [(c.encode() + b"\n", None) for c in cmds]


def block(payload: bytes, digits: int = 8) -> bytes:
    return b"#" + str(digits).encode() + str(len(payload)).zfill(digits).encode() + payload + b"\n"


def preamble(fmt, points, xinc, xorig, xref, yinc, yorig, yref) -> bytes:
    return (f"{fmt},0,{points},1,{xinc:E},{xorig:E},{xref},{yinc:E},{yorig:E},{yref}\n").encode()


KS_WORD_SETUP = _w(":WAV:SOUR CHAN2", ":WAV:FORM WORD", ":WAV:BYT MSBF", ":WAV:UNS 1",
                   ":WAV:POIN:MODE RAW", ":WAV:POIN MAX") + [(b":SYST:ERR?\n", OK)]


def test_infiniivision_setup_and_timebase():
    script = _w(":CHAN1:DISP 1", ":CHAN1:COUP AC", ":CHAN1:SCAL 0.05", ":CHAN1:OFFS -0.1") + [
        (b":SYST:ERR?\n", OK)] + _w(":TIM:SCAL 0.001") + [(b":SYST:ERR?\n", OK)] + _w(
        ":TRIG:MODE EDGE", ":TRIG:EDGE:SOUR CHAN2", ":TRIG:EDGE:LEV 0.1", ":TRIG:EDGE:SLOP NEG",
        ":TRIG:SWE NORM") + [(b":SYST:ERR?\n", OK)] + READBACK
    with expected_protocol(InfiniiVision, script) as sc:
        sc.setup_channel(1, volts_per_div=0.05, offset_v=-0.1, coupling="ac")
        sc.set_timebase(record_s=0.01)
        sc.set_trigger("chan2", 0.1, "NEG")
    assert sc.state["channels"]["1"]["coupling"] == "AC" and sc.state["time_per_div_s"] == 0.001
    assert sc.state["trigger"]["sweep"] == "NORM"


#: what set_trigger("CHAN2", 0.1, "NEG") reads back (3000 X-Series Programmer's Guide, :TRIGger
#: Commands: the queries answer the short forms)
READBACK = [(b":TRIG:EDGE:SOUR?\n", b"CHAN2\n"), (b":TRIG:EDGE:SLOP?\n", b"NEG\n"),
            (b":TRIG:SWE?\n", b"NORM\n"), (b":TRIG:EDGE:LEV?\n", b"+1.00000E-01\n")]
TRIGGER = _w(":TRIG:MODE EDGE", ":TRIG:EDGE:SOUR CHAN2", ":TRIG:EDGE:LEV 0.1", ":TRIG:EDGE:SLOP NEG",
             ":TRIG:SWE NORM") + [(b":SYST:ERR?\n", OK)]


@pytest.mark.parametrize("bad, match", [
    ((b":TRIG:SWE?\n", b"AUTO\n"), "TRIG:SWE"),              # the sweep did not take: AUTO records anyway
    ((b":TRIG:EDGE:SOUR?\n", b"CHAN1\n"), "TRIG:EDGE:SOUR"),
    ((b":TRIG:EDGE:LEV?\n", b"+2.00000E+00\n"), "trigger level"),
])
def test_trigger_settings_are_read_back(bad, match):
    """A scope that does not hold a trigger setting is an error, not a run on untriggered records."""
    rb = [bad if q == bad[0] else (q, r) for q, r in READBACK]
    upto = [q for q, _ in rb].index(bad[0]) + 1
    with expected_protocol(InfiniiVision, TRIGGER + rb[:upto]) as sc:
        with pytest.raises(InstrumentError, match=match):
            sc.set_trigger("CHAN2", 0.1, "NEG")


def test_rigol_memory_depth_for_the_channels_on_and_averaging():
    """DS1000Z :ACQuire:MDEPth: the smallest listed depth for two channels holding 5000 points is
    6k, set while running and read back; :ACQuire:AVERages takes powers of two only. The channels
    on are asked of the scope (one left on from before counts: the depths depend on it)."""
    script = []
    for ch in (1, 2):
        script += _w(f":CHAN{ch}:DISP 1", f":CHAN{ch}:COUP DC", f":CHAN{ch}:SCAL 0.5", f":CHAN{ch}:OFFS 0") + [
            (b":SYST:ERR?\n", R_OK)]
    script += [(f":CHAN{c}:DISP?\n".encode(), b"1\n" if c <= 2 else b"0\n") for c in (1, 2, 3, 4)]
    script += _w(":RUN", ":ACQ:MDEP 6000") + [(b":SYST:ERR?\n", R_OK), (b":ACQ:MDEP?\n", b"6000\n")]
    script += _w(":ACQ:TYPE AVER", ":ACQ:AVER 16") + [(b":SYST:ERR?\n", R_OK), (b":ACQ:TYPE?\n", b"AVER\n"),
                                                     (b":ACQ:AVER?\n", b"16\n")]
    # a scope that kept another count: the read-back says so
    script += _w(":ACQ:TYPE AVER", ":ACQ:AVER 32") + [(b":SYST:ERR?\n", R_OK), (b":ACQ:TYPE?\n", b"AVER\n"),
                                                     (b":ACQ:AVER?\n", b"16\n")]
    with expected_protocol(RigolDS1000Z, script) as sc:
        sc.setup_channel(1, 0.5)
        sc.setup_channel(2, 0.5)
        sc.set_record_points(5000)
        sc.set_averaging(16)
        assert sc.state["record_points"] == 6000 and sc.state["averages"] == 16
        assert sc.state["acquisition"] == "AVER"
        with pytest.raises(LimitError, match="averages 2, 4"):
            sc.set_averaging(12)
        with pytest.raises(InstrumentError, match=r":ACQ:AVER\? answers 16, 32 was set"):
            sc.set_averaging(32)


def test_infiniivision_averaging_count_read_back():
    """IV :ACQuire:TYPE, :ACQuire:COUNt: type and count set, both read back; 1 is NORMal."""
    script = _w(":ACQ:TYPE AVER", ":ACQ:COUN 100") + [(b":SYST:ERR?\n", R_OK), (b":ACQ:TYPE?\n", b"AVER\n"),
                                                      (b":ACQ:COUN?\n", b"+100\n")]
    script += _w(":ACQ:TYPE NORM") + [(b":SYST:ERR?\n", R_OK), (b":ACQ:TYPE?\n", b"NORM\n")]
    with expected_protocol(InfiniiVision, script) as sc:
        sc.set_averaging(100)
        assert (sc.state["acquisition"], sc.state["averages"]) == ("AVER", 100)
        sc.set_averaging(1)
        assert (sc.state["acquisition"], sc.state["averages"]) == ("NORM", 1)


@pytest.mark.parametrize("cls, model, channels, default, ext", [
    # DS1000Z Programming Guide, :TRIGger:EDGe:SOURce: D0-D15, CHANnel1-4, AC (no EXT on the four-channel
    # models); the two-channel DS1000Z-E has an EXT TRIG input; every InfiniiVision has one
    (RigolDS1000Z, "DS1054Z", 4, "CHAN1", False),
    (RigolDS1000Z, "DS1202Z-E", 2, "EXT", True),
    (InfiniiVision, "DSOX3024T", 4, "EXT", True),
])
def test_trigger_source_default_and_ext_per_model(cls, model, channels, default, ext):
    """Without a setting a run triggers on EXT where the scope has it, else on the drive channel;
    EXT asked of a scope without it is a ConfigError before anything is sent (the protocol is empty)."""
    from labkit.errors import ConfigError

    maker = "RIGOL TECHNOLOGIES" if cls is RigolDS1000Z else "KEYSIGHT TECHNOLOGIES"
    with expected_protocol(cls, [], identity=f"{maker},{model},S1,01.00") as sc:
        assert (sc.instrument_model, sc.n_channels, sc.has_ext_trigger) == (model, channels, ext)
        assert sc.trigger_source_for(None, 1) == default
        assert sc.trigger_source_for(None, 3) == default.replace("CHAN1", "CHAN3")
        assert sc.trigger_source_for("chan2", 1) == "CHAN2"
        with pytest.raises(LimitError, match="scope channel"):
            sc.set_trigger(f"CHAN{channels + 1}", 0.0)
        if not ext:
            with pytest.raises(ConfigError, match=f"the {model} has no external trigger input; nothing was set"):
                sc.set_trigger("EXT", 1.0)
            with pytest.raises(ConfigError, match="scope.trigger_source"):
                sc.trigger_source_for("EXT", 1)


@pytest.mark.parametrize("cls, ok, offs", [
    # InfiniiVision :CHANnel<n>:OFFSet: "the value represented at center screen" (3000 X-Series
    # Programmer's Guide); DS1000Z: the offset is added to the signal, the centre shows -OFFSet
    # (DS1000Z Programming Guide: edge trigger level range (-5 x VerticalScale - OFFSet) to
    # (5 x VerticalScale - OFFSet))
    (InfiniiVision, OK, [b":CHAN1:OFFS 2\n", b":CHAN2:OFFS -0.5\n", b":CHAN3:OFFS 0\n"]),
    (RigolDS1000Z, R_OK, [b":CHAN1:OFFS -2\n", b":CHAN2:OFFS 0.5\n", b":CHAN3:OFFS 0\n"]),
])
def test_offset_puts_the_given_voltage_at_the_screen_centre(cls, ok, offs):
    """``setup_channel(offset_v=V)`` means V at the screen's centre on every model: the bytes."""
    script = []
    for ch, off in zip((1, 2, 3), offs):
        script += [(f":CHAN{ch}:DISP 1\n".encode(), None), (f":CHAN{ch}:COUP DC\n".encode(), None),
                   (f":CHAN{ch}:SCAL 0.625\n".encode(), None), (off, None), (b":SYST:ERR?\n", ok)]
    with expected_protocol(cls, script) as sc:
        sc.setup_channel(1, 0.625, offset_v=2.0)
        sc.setup_channel(2, 0.625, offset_v=-0.5)
        sc.setup_channel(3, 0.625, offset_v=0.0)
    assert [sc.state["channels"][str(c)]["offset_v"] for c in (1, 2, 3)] == [2.0, -0.5, 0.0]


def test_scope_limits_before_sending():
    with expected_protocol(InfiniiVision, [], identity="KEYSIGHT TECHNOLOGIES,DSOX1102G,CN1,02.10") as sc:
        assert sc.n_channels == 2          # from the identity's model word
        with pytest.raises(LimitError, match="scope channel"):
            sc.setup_channel(3, 0.1)
        with pytest.raises(LimitError, match="volts_per_div"):
            sc.setup_channel(1, 50)
        with pytest.raises(LimitError, match="coupling"):
            sc.setup_channel(1, 0.1, coupling="GND50")
        with pytest.raises(LimitError, match="waveform format"):
            sc.read_waveform(1, fmt="ASCII")


def test_infiniivision_single_and_wait():
    script = _w(":SING") + [(b":OPER:COND?\n", b"+40\n"), (b":OPER:COND?\n", b"+32\n")]
    with expected_protocol(InfiniiVision, script) as sc:
        sc.single()
        sc.wait_done(timeout_s=2)


def test_wait_done_gives_up_at_its_timeout():
    script = [(b":OPER:COND?\n", b"+8\n")] * 3
    with expected_protocol(InfiniiVision, script) as sc:
        sc.poll_s = 0.05
        with pytest.raises(InstrumentError, match="not complete within 0.1 s"):
            sc.wait_done(timeout_s=0.1)


@pytest.mark.parametrize("fast_blocks", [True, False])
def test_infiniivision_word_waveform_scaled(fast_blocks):
    rng = np.random.default_rng(1)
    raw = rng.integers(0, 65535, 1000).astype(">u2")
    raw[:4] = [0x0A0A, 0x000A, 0x0A00, 0x2300]        # termination bytes and '#' inside the data
    pre = preamble(1, 1000, 1e-6, -5e-4, 0, 3e-5, 0.1, 32768)
    script = KS_WORD_SETUP + [(b":WAV:PRE?\n", pre), (b":WAV:DATA?\n", block(raw.tobytes()))]
    with expected_protocol(InfiniiVision, script, fast_blocks=fast_blocks) as sc:
        wf = sc.read_waveform(2, "WORD")
    np.testing.assert_allclose(wf.volts, (raw.astype(float) - 32768) * 3e-5 + 0.1)
    np.testing.assert_allclose(wf.t_s, np.arange(1000) * 1e-6 - 5e-4)
    assert wf.channel == 2 and wf.xinc_s == 1e-6 and wf.fs_hz == pytest.approx(1e6)


def test_infiniivision_byte_waveform():
    raw = np.arange(256, dtype=np.uint8)
    pre = preamble(0, 256, 2e-6, 0.0, 10, 0.01, -0.5, 128)
    script = _w(":WAV:SOUR CHAN1", ":WAV:FORM BYTE", ":WAV:POIN:MODE RAW", ":WAV:POIN 1000") + [
        (b":SYST:ERR?\n", OK), (b":WAV:PRE?\n", pre), (b":WAV:DATA?\n", block(raw.tobytes()))]
    with expected_protocol(InfiniiVision, script, points=1000) as sc:
        wf = sc.read_waveform(1, "BYTE")
    np.testing.assert_allclose(wf.volts, (np.arange(256) - 128) * 0.01 - 0.5)
    np.testing.assert_allclose(wf.t_s, (np.arange(256) - 10) * 2e-6)


@pytest.mark.parametrize("fast_blocks", [True, False])
@pytest.mark.parametrize("data_reply, match", [
    (b"garbage\n", "bad binary block"),
    (b"#A0000\n", "bad binary block"),
    (block(b"\x00\x01" * 999), "preamble says 1000"),
])
def test_bad_blocks(data_reply, match, fast_blocks):
    pre = preamble(1, 1000, 1e-6, 0, 0, 1e-3, 0, 0)
    script = KS_WORD_SETUP + [(b":WAV:PRE?\n", pre), (b":WAV:DATA?\n", data_reply)]
    with expected_protocol(InfiniiVision, script, fast_blocks=fast_blocks) as sc:
        with pytest.raises(InstrumentError, match=match) as ei:
            sc.read_waveform(2)
    assert ei.value.command == ":WAV:DATA?"


@pytest.mark.parametrize("pre, match", [
    (b"1,0,1000\n", "garbled preamble"),
    (b"1,0,x,1,1,1,1,1,1,1\n", "garbled preamble"),
    (b"1,0,0,1,1e-6,0,0,1e-3,0,0\n", "implausible preamble"),
    (b"0,0,1000,1,1e-6,0,0,1e-3,0,0\n", "is not WORD"),
])
def test_bad_preamble(pre, match):
    with expected_protocol(InfiniiVision, KS_WORD_SETUP + [(b":WAV:PRE?\n", pre)]) as sc:
        with pytest.raises(InstrumentError, match=match):
            sc.read_waveform(2)


def test_block_without_termination_is_error():
    pre = preamble(1, 4, 1e-6, 0, 0, 1e-3, 0, 0)
    script = KS_WORD_SETUP + [(b":WAV:PRE?\n", pre),
                              (b":WAV:DATA?\n", b"#18" + b"\x00" * 8 + b"X\n")]
    with expected_protocol(InfiniiVision, script, timeout_s=0.3) as sc:
        with pytest.raises(InstrumentError, match="not followed by the termination"):
            sc.read_waveform(2)


def test_drop_mid_transfer_within_timeout():
    raw = np.zeros(100_000, ">u2").tobytes()
    pre = preamble(1, 100_000, 1e-6, 0, 0, 1e-3, 0, 0)
    script = KS_WORD_SETUP + [(b":WAV:PRE?\n", pre), (b":WAV:DATA?\n", Drop(block(raw)[:50_000]))]
    t0 = time.monotonic()
    with expected_protocol(InfiniiVision, script, timeout_s=0.3) as sc:
        with pytest.raises(InstrumentError, match="connection closed") as ei:
            sc.read_waveform(2)
    assert time.monotonic() - t0 < 3.0 and ei.value.command == ":WAV:DATA?"


def test_stall_mid_transfer_within_timeout():
    pre = preamble(1, 1000, 1e-6, 0, 0, 1e-3, 0, 0)
    script = KS_WORD_SETUP + [(b":WAV:PRE?\n", pre), (b":WAV:DATA?\n", b"#800002000\x00\x01")]
    t0 = time.monotonic()
    with expected_protocol(InfiniiVision, script, timeout_s=0.3) as sc:
        with pytest.raises(InstrumentError, match="no reply within"):
            sc.read_waveform(2)
    assert time.monotonic() - t0 < 3.0


def _rigol_chunks(raw: np.ndarray, per_read: int, width: int) -> list:
    out = []
    n = raw.size
    start = 1
    while start <= n:
        stop = min(start + per_read - 1, n)
        out += _w(f":WAV:STAR {start}", f":WAV:STOP {stop}")
        out.append((b":WAV:DATA?\n", block(raw[start - 1:stop].tobytes(), 9)))
        start = stop + 1
    return out


def test_rigol_raw_word_chunked_and_scaled():
    n = 1000
    samples = (np.arange(n) % 256).astype(np.uint16)
    raw = samples.astype("<u2")
    raw[::7] |= 0xAB00             # WORD: only the low byte is the sample; the high byte is ignored
    pre = preamble(1, n, 1e-6, -1e-4, 0, 0.04, 10, 127)   # DS1000Z format 1: WORD
    script = _w(":STOP", ":WAV:SOUR CHAN3", ":WAV:MODE RAW", ":WAV:FORM WORD") + [
        (b":SYST:ERR?\n", R_OK), (b":WAV:PRE?\n", pre)] + _rigol_chunks(raw, 150, 2)
    with expected_protocol(RigolDS1000Z, script, max_block_bytes=300) as sc:
        wf = sc.read_waveform(3, "WORD")
    np.testing.assert_allclose(wf.volts, (samples.astype(float) - 10 - 127) * 0.04)
    np.testing.assert_allclose(wf.t_s, np.arange(n) * 1e-6 - 1e-4)
    assert sum(1 for e, _ in script if e == b":WAV:DATA?\n") == 7


def test_rigol_byte_default_chunks_of_250000():
    n = 600_000
    raw = (np.arange(n) % 251).astype(np.uint8)
    pre = preamble(0, n, 1e-7, 0, 0, 0.01, 0, 128)        # DS1000Z format 0: BYTE
    script = _w(":STOP", ":WAV:SOUR CHAN1", ":WAV:MODE RAW", ":WAV:FORM BYTE") + [
        (b":SYST:ERR?\n", R_OK), (b":WAV:PRE?\n", pre)] + _rigol_chunks(raw, 250_000, 1)
    assert [e for e, _ in script if e and e.startswith(b":WAV:STOP")] == [
        b":WAV:STOP 250000\n", b":WAV:STOP 500000\n", b":WAV:STOP 600000\n"]
    with expected_protocol(RigolDS1000Z, script, timeout_s=2.0) as sc:
        wf = sc.read_waveform(1, "BYTE")
    np.testing.assert_allclose(wf.volts, (raw.astype(float) - 128) * 0.01)


def test_rigol_short_chunk_is_error():
    pre = preamble(0, 10, 1e-6, 0, 0, 0.01, 0, 128)
    script = _w(":STOP", ":WAV:SOUR CHAN1", ":WAV:MODE RAW", ":WAV:FORM BYTE") + [
        (b":SYST:ERR?\n", R_OK), (b":WAV:PRE?\n", pre)] + _w(":WAV:STAR 1", ":WAV:STOP 10") + [
        (b":WAV:DATA?\n", block(b"\x00" * 9, 9))]
    with expected_protocol(RigolDS1000Z, script) as sc:
        with pytest.raises(InstrumentError, match="asked for 1..10"):
            sc.read_waveform(1, "BYTE")


def test_rigol_timebase_single_and_wait():
    script = _w(":TIM:MAIN:SCAL 0.001") + [(b":SYST:ERR?\n", R_OK)] + _w(":SING") + [
        (b":TRIG:STAT?\n", b"WAIT\n"), (b":TRIG:STAT?\n", b"STOP\n")]
    with expected_protocol(RigolDS1000Z, script) as sc:
        sc.set_timebase(0.012)           # 12 divisions
        sc.single()
        sc.wait_done(1.0)


def test_wait_done_stall_is_instrument_error():
    with expected_protocol(RigolDS1000Z, [(b":TRIG:STAT?\n", STALL)], timeout_s=0.2) as sc:
        with pytest.raises(InstrumentError, match="no reply"):
            sc.wait_done(5.0)


def test_infiniivision_record_points_mode_read_back():
    script = _w(":WAV:POIN:MODE RAW", ":WAV:POIN 20000") + [(b":SYST:ERR?\n", OK),
                                                           (b":WAV:POIN:MODE?\n", b"NORM\n")]
    with expected_protocol(InfiniiVision, script) as sc:
        with pytest.raises(InstrumentError, match="WAV:POIN:MODE.*RAW was set"):
            sc.set_record_points(20000)
