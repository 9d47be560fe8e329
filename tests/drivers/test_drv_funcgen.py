"""Function generators: the exact bytes of every operation, limits, faults."""
from __future__ import annotations

import json
import time

import pytest

from labkit.drivers.funcgen import Agilent33220A, Keysight33500B, RigolDG1000Z
from labkit.drivers.testing import STALL, Drop, expected_protocol
from labkit.errors import ConfigError, InstrumentError, LimitError

OK = b'+0,"No error"\n'
RIGOL_OK = b'0,"No error"\n'


def _w(*cmds: str):
    """Writes with no reply."""
    return [(c.encode() + b"\n", None) for c in cmds]


SINE_33220A = _w("OUTP:LOAD INF", "FUNC SIN", "VOLT:UNIT VPP", "FREQ 1000", "VOLT 2",
                 "VOLT:OFFS 0.5") + [(b"SYST:ERR?\n", OK)]
SINE_33500B_CH2 = _w("OUTP2:LOAD INF", "SOUR2:FUNC SIN", "SOUR2:VOLT:UNIT VPP", "SOUR2:FREQ 1000",
                     "SOUR2:VOLT 2", "SOUR2:VOLT:OFFS 0.5") + [(b"SYST:ERR?\n", OK)]
SINE_RIGOL = _w(":OUTP1:LOAD INF", ":SOUR1:FUNC SIN", ":SOUR1:VOLT:UNIT VPP", ":SOUR1:FREQ 1000",
                ":SOUR1:VOLT 2", ":SOUR1:VOLT:OFFS 0.5") + [(b":SYST:ERR?\n", RIGOL_OK)]


@pytest.mark.parametrize("cls, kw, script", [
    (Agilent33220A, {}, SINE_33220A),
    (Keysight33500B, {"channel": 2}, SINE_33500B_CH2),
    (RigolDG1000Z, {}, SINE_RIGOL),
])
def test_set_sine_load_first_then_errors(cls, kw, script):
    with expected_protocol(cls, script, max_amp_vpp=10, **kw) as fg:
        fg.set_sine(freq_hz=1000, amp_vpp=2, offset_v=0.5)
        assert fg.state["amp_vpp"] == 2 and fg.state["load"] == "INF"


@pytest.mark.parametrize("cls, idn", [
    (Agilent33220A, b"Agilent Technologies,33220A,MY44012345,2.07-2.06-22-2\n"),
    (Keysight33500B, b"Keysight Technologies,33522B,MY52400000,4.00-1.19-2.00-58-00\n"),
    (RigolDG1000Z, b"RIGOL TECHNOLOGIES,DG1022Z,DG1ZA000000001,03.01.12\n"),
])
def test_identity(cls, idn):
    # asked once, in the handshake on open; the model word names the model
    with expected_protocol(cls, [], identity=idn.decode().strip()) as fg:
        assert fg.identity == idn.decode().strip()
        assert fg.instrument_model == idn.decode().split(",")[1]


def test_error_queue_nonempty_raises_with_text():
    script = SINE_33220A[:-1] + [(b"SYST:ERR?\n", b'-222,"Data out of range"\n'),
                                 (b"SYST:ERR?\n", OK)]
    with expected_protocol(Agilent33220A, script) as fg:
        with pytest.raises(InstrumentError) as ei:
            fg.set_sine(1000, 2, 0.5)
    assert '-222,"Data out of range"' in str(ei.value)
    assert ei.value.command == "VOLT:OFFS 0.5"


def test_rigol_error_format():
    with expected_protocol(RigolDG1000Z, _w(":OUTP1:LOAD INF") +
                           [(b":SYST:ERR?\n", b'-113,"Undefined header"\n'),
                            (b":SYST:ERR?\n", RIGOL_OK)]) as fg:
        with pytest.raises(InstrumentError, match="Undefined header"):
            fg.set_load_high_z()


@pytest.mark.parametrize("kw, call, limit", [
    ({"max_amp_vpp": 1.0}, lambda fg: fg.set_sine(1000, 2.0), "max_amp_vpp"),
    ({"max_v": 1.0}, lambda fg: fg.set_sine(1000, 1.0, offset_v=0.8), "max_v"),
    ({}, lambda fg: fg.set_sine(1000, 15.0, offset_v=5), "model output range"),
    ({}, lambda fg: fg.set_sine(-5, 1.0), "freq_hz > 0"),
    ({"max_freq_hz": 5000}, lambda fg: fg.set_sine(6000, 1.0), "max_freq_hz"),
    ({}, lambda fg: fg.set_sine(1000, 0.0), "amp_vpp > 0"),
    ({}, lambda fg: fg.output(True), "amplitude not set"),
    ({}, lambda fg: fg.set_sweep(10, 100, 1.0), "amplitude not set"),
    ({}, lambda fg: fg.burst(0), "burst ncycles"),
    ({"max_amp_vpp": 1.0}, lambda fg: fg.set_amplitude(1.5), "max_amp_vpp"),
])
def test_limits_refused_before_anything_is_sent(kw, call, limit):
    with expected_protocol(Keysight33500B, [], **kw) as fg:   # the peer must see no bytes
        with pytest.raises(LimitError) as ei:
            call(fg)
    assert ei.value.limit == limit
    assert limit in str(ei.value)


def test_bad_channel_and_limit_settings():
    # refused when constructed: not a byte is sent
    with pytest.raises(ConfigError, match="channel"):
        with expected_protocol(Agilent33220A, [], channel=2, handshake=False):
            pass
    with pytest.raises(LimitError):
        with expected_protocol(Keysight33500B, [], max_amp_vpp=50, handshake=False):
            pass


def test_output_on_after_sine_and_state_query():
    script = SINE_33500B_CH2 + _w("OUTP2 ON") + [(b"SYST:ERR?\n", OK), (b"OUTP2?\n", b"1\n"),
                                                 (b"OUTP2?\n", b"maybe\n")]
    with expected_protocol(Keysight33500B, script, channel=2) as fg:
        fg.set_sine(1000, 2, 0.5)
        fg.output(True)
        assert fg.output_on is True
        with pytest.raises(InstrumentError, match="garbled"):
            fg.output_on


def test_output_on_rechecks_lowered_limit():
    with expected_protocol(Agilent33220A, SINE_33220A, max_amp_vpp=10) as fg:
        fg.set_sine(1000, 2, 0.5)
        fg.max_amp_vpp = 1.0          # e.g. the amplifier's cap declared after the sine was set
        with pytest.raises(LimitError, match="max_amp_vpp"):
            fg.output(True)           # nothing sent: the script ends with the sine


def test_sweep_queries_max_time_then_sets():
    script = SINE_33220A + [(b"SWE:TIME? MAX\n", b"+5.00000000000000E+02\n")] + _w(
        "FREQ:STAR 100", "FREQ:STOP 5000", "SWE:SPAC LOG", "SWE:TIME 2", "TRIG:SOUR BUS",
        "SWE:STAT ON") + [(b"SYST:ERR?\n", OK)] + _w("*TRG") + [(b"SYST:ERR?\n", OK)]
    with expected_protocol(Agilent33220A, script) as fg:
        fg.set_sine(1000, 2, 0.5)
        fg.set_sweep(100, 5000, 2.0, spacing="log", trigger_source="BUS")
        fg.trigger()
    assert fg.state["sweep"]["spacing"] == "LOG" and fg.state["max_sweep_time_s"] == 500.0


def test_sweep_time_over_instrument_max_refused():
    script = SINE_RIGOL + [(b":SOUR1:SWE:TIME? MAX\n", b"300\n")]
    with expected_protocol(RigolDG1000Z, script) as fg:
        fg.set_sine(1000, 2, 0.5)
        with pytest.raises(LimitError) as ei:
            fg.set_sweep(100, 5000, 400.0)
    assert "SWE:TIME? MAX" in ei.value.limit


def test_rigol_sweep_and_burst_commands():
    script = SINE_RIGOL + [(b":SOUR1:SWE:TIME? MAX\n", b"500\n")] + _w(
        ":SOUR1:FREQ:STAR 10", ":SOUR1:FREQ:STOP 20", ":SOUR1:SWE:SPAC LIN", ":SOUR1:SWE:TIME 1",
        ":SOUR1:SWE:TRIG:SOUR INT", ":SOUR1:SWE:STAT ON") + [(b":SYST:ERR?\n", RIGOL_OK)] + _w(
        ":SOUR1:SWE:STAT OFF") + [(b":SYST:ERR?\n", RIGOL_OK)] + _w(
        ":SOUR1:BURS:MODE TRIG", ":SOUR1:BURS:NCYC 5", ":SOUR1:BURS:TRIG:SOUR MAN",
        ":SOUR1:BURS ON") + [(b":SYST:ERR?\n", RIGOL_OK)]
    with expected_protocol(RigolDG1000Z, script) as fg:
        fg.set_sine(1000, 2, 0.5)
        fg.set_sweep(10, 20, 1)
        fg.sweep_off()
        fg.burst(5)


def test_33500b_burst_and_trigger():
    script = SINE_33500B_CH2 + _w("SOUR2:BURS:MODE TRIG", "SOUR2:BURS:NCYC 10", "TRIG2:SOUR BUS",
                                  "SOUR2:BURS:STAT ON") + [(b"SYST:ERR?\n", OK)] + _w("*TRG") + [
        (b"SYST:ERR?\n", OK)] + _w("SOUR2:BURS:STAT OFF") + [(b"SYST:ERR?\n", OK)]
    with expected_protocol(Keysight33500B, script, channel=2) as fg:
        fg.set_sine(1000, 2, 0.5)
        fg.burst(10)
        fg.trigger()
        fg.burst_off()


def test_set_frequency_only():
    with expected_protocol(Keysight33500B, _w("SOUR1:FREQ 250.5") + [(b"SYST:ERR?\n", OK)]) as fg:
        fg.set_frequency(250.5)
    assert fg.state["freq_hz"] == 250.5


@pytest.mark.parametrize("cls, off", [
    (Agilent33220A, ["OUTP OFF"]),
    (Keysight33500B, ["OUTP1 OFF", "OUTP2 OFF"]),
    (RigolDG1000Z, [":OUTP1 OFF", ":OUTP2 OFF"]),
])
def test_context_manager_turns_outputs_off_on_exception(cls, off):
    with expected_protocol(cls, _w(*off) + [(b"*OPC?\n", b"1\n")]) as fg:
        with pytest.raises(KeyError):
            with fg:
                raise KeyError("user code failed")
    assert fg.state["output_on"] is False


def test_stall_on_error_query_is_instrument_error_then_outputs_off():
    script = SINE_33500B_CH2[:-1] + [(b"SYST:ERR?\n", STALL)] + _w("OUTP1 OFF", "OUTP2 OFF") + [
        (b"*OPC?\n", b"+1\n")]
    t0 = time.monotonic()
    with expected_protocol(Keysight33500B, script, channel=2, timeout_s=0.2) as fg:
        with pytest.raises(InstrumentError) as ei:
            with fg:
                fg.set_sine(1000, 2, 0.5)
    assert ei.value.command == "SYST:ERR?"
    assert time.monotonic() - t0 < 3.0


def test_safe_off_unconfirmed_is_error():
    with expected_protocol(Agilent33220A, _w("OUTP OFF") + [(b"*OPC?\n", b"0\n")]) as fg:
        with pytest.raises(InstrumentError, match="did not confirm"):
            fg.safe_off()


def test_drop_mid_settings_is_instrument_error():
    script = SINE_33220A[:-1] + [(b"SYST:ERR?\n", Drop(b'+0,"No'))]
    with expected_protocol(Agilent33220A, script, timeout_s=0.2) as fg:
        with pytest.raises(InstrumentError, match="connection closed"):
            fg.set_sine(1000, 2, 0.5)


def test_snapshot_records_settings_and_state():
    script = SINE_33500B_CH2
    with expected_protocol(Keysight33500B, script, channel=2, max_amp_vpp=5, max_v=4,
                           identity="Keysight Technologies,33522B,MY1,4") as fg:
        fg.set_sine(1000, 2, 0.5)
        snap = json.loads(json.dumps(fg.snapshot()))
    assert snap["settings"] == {"timeout_s": pytest.approx(0.3), "check_errors": True, "channel": 2,
                                "max_amp_vpp": 5.0, "max_v": 4.0, "max_freq_hz": None,
                                "amplitude_unit": "VPP", "load_ohm": "INF"}
    assert snap["state"]["freq_hz"] == 1000 and snap["state"]["offset_v"] == 0.5
    assert snap["identity"].startswith("Keysight")
    assert snap["connect"] == {"instrument_model": "33522B", "channels": 2, "errors_at_connect": []}


def test_check_errors_can_be_disabled():
    with expected_protocol(Agilent33220A, _w("OUTP:LOAD INF"), check_errors=False) as fg:
        fg.set_load_high_z()


def test_set_amplitude_refuses_while_the_offset_is_unknown():
    with expected_protocol(Keysight33500B, [], max_v=5.0) as fg:     # the peer must see no byte
        with pytest.raises(LimitError) as ei:
            fg.set_amplitude(2.0)
    assert ei.value.limit == "offset unknown"


def test_shrinking_offset_is_sent_before_the_amplitude():
    """Output on at 4 V offset, then 8 Vpp around 0 V with max_v = 5: sending VOLT 8 first would
    put 4 + 4 = 8 V on the film between the two commands; the offset must go first."""
    first = _w("OUTP1:LOAD INF", "SOUR1:FUNC SIN", "SOUR1:VOLT:UNIT VPP", "SOUR1:FREQ 1000",
                  "SOUR1:VOLT 1", "SOUR1:VOLT:OFFS 4") + [(b"SYST:ERR?\n", OK)]
    second = _w("OUTP1:LOAD INF", "SOUR1:FUNC SIN", "SOUR1:VOLT:UNIT VPP", "SOUR1:FREQ 1000",
                   "SOUR1:VOLT:OFFS 0", "SOUR1:VOLT 8") + [(b"SYST:ERR?\n", OK)]
    with expected_protocol(Keysight33500B, first + second, max_v=5.0) as fg:
        fg.set_sine(1000, 1.0, 4.0)
        fg.set_sine(1000, 8.0, 0.0)


@pytest.mark.parametrize("cls, kw, script", [
    # 33220A User's Guide, OUTPut:SYNC {OFF|ON}: one Sync connector, one channel
    (Agilent33220A, {}, _w("OUTP:SYNC ON") + [(b"SYST:ERR?\n", OK), (b"OUTP:SYNC?\n", b"1\n")]),
    # 33500B Operating and Service Guide, OUTPut:SYNC:SOURce {CH1|CH2}, OUTPut[1|2]:SYNC:MODE,
    # OUTPut[1|2]:SYNC:POLarity, OUTPut:SYNC: the connector follows the drive channel
    (Keysight33500B, {"channel": 2},
     _w("OUTP:SYNC:SOUR CH2", "OUTP2:SYNC:MODE NORM", "OUTP2:SYNC:POL NORM", "OUTP:SYNC ON")
     + [(b"SYST:ERR?\n", OK), (b"OUTP:SYNC:SOUR?\n", b"CH2\n"), (b"OUTP2:SYNC:MODE?\n", b"NORM\n"),
        (b"OUTP2:SYNC:POL?\n", b"NORM\n"), (b"OUTP:SYNC?\n", b"1\n")]),
    # DG1000Z Programming Guide, :OUTPut<n>:SYNC[:STATe], :OUTPut<n>:SYNC:POLarity {POSitive|NEGative}
    (RigolDG1000Z, {}, _w(":OUTP1:SYNC:POL POS", ":OUTP1:SYNC ON")
     + [(b":SYST:ERR?\n", RIGOL_OK), (b":OUTP1:SYNC:POL?\n", b"POS\n"), (b":OUTP1:SYNC?\n", b"ON\n")]),
])
def test_enable_sync_routes_the_drive_channel_and_reads_it_back(cls, kw, script):
    with expected_protocol(cls, script, **kw) as fg:
        fg.enable_sync()
    assert fg.state["sync"] == {"on": True, "channel": kw.get("channel", 1)}


def test_sync_that_does_not_take_is_an_error():
    """A generator whose Sync connector stays off: the scope would never trigger; say so."""
    script = _w("OUTP:SYNC ON") + [(b"SYST:ERR?\n", OK), (b"OUTP:SYNC?\n", b"0\n")]
    with expected_protocol(Agilent33220A, script) as fg:
        with pytest.raises(InstrumentError, match="sync not set.*OUTP:SYNC.*never fire"):
            fg.enable_sync()


@pytest.mark.parametrize("kw, level", [
    # 2 Vpp at the load: 0.7071 Vrms (a sine's rms is its peak over sqrt 2); into 50 ohm that is
    # 10 log10(0.7071^2 / 50 / 1 mW) = 10 dBm (33500B Operating and Service Guide, VOLTage:UNIT)
    ({"amplitude_unit": "VRMS"}, ("INF", "VRMS", "0.7071067812")),
    ({"amplitude_unit": "DBM", "load_ohm": 50}, ("50", "DBM", "10")),
    ({"amplitude_unit": "vpp", "load_ohm": 600}, ("600", "VPP", "2")),
])
def test_amplitude_unit_and_load_as_configured(kw, level):
    load, unit, volt = level
    script = _w(f"OUTP1:LOAD {load}", "SOUR1:FUNC SIN", f"SOUR1:VOLT:UNIT {unit}", "SOUR1:FREQ 1000",
                f"SOUR1:VOLT {volt}", "SOUR1:VOLT:OFFS 0") + [(b"SYST:ERR?\n", OK)]
    with expected_protocol(Keysight33500B, script, **kw) as fg:
        fg.set_sine(1000, 2.0)
    assert fg.state["amp_vpp"] == 2.0 and fg.state["load"] == load


def test_a_finite_load_lowers_the_output_range_and_is_read_back():
    """+-10 V open circuit through the 50 ohm source: +-5 V into 50 ohm (data sheet: 10 Vpp into
    50 ohm); refused before anything is sent. The load is read back after it is set."""
    script = _w("OUTP1:LOAD 50") + [(b"SYST:ERR?\n", OK), (b"OUTP1:LOAD?\n", b"+5.000000000000000E+01\n")]
    script += _w("OUTP1:LOAD 50") + [(b"SYST:ERR?\n", OK), (b"OUTP1:LOAD?\n", b"+9.900000000000000E+37\n")]
    with expected_protocol(Keysight33500B, script, load_ohm=50) as fg:
        with pytest.raises(LimitError, match=r"\+-5 V into 50 ohm"):
            fg.set_sine(1000, 12.0)
        fg.set_load()
        assert fg.state["load"] == "50"
        with pytest.raises(InstrumentError, match="load not set"):
            fg.set_load()


@pytest.mark.parametrize("kw, key", [
    ({"amplitude_unit": "DBM"}, "amplitude_unit"),       # dBm into high Z: undefined
    ({"amplitude_unit": "VOLTS"}, "amplitude_unit"),
    ({"load_ohm": 0.5}, "load_ohm"),
    ({"load_ohm": "open"}, "load_ohm"),
])
def test_bad_unit_or_load_is_a_config_error_before_anything_is_sent(kw, key):
    with pytest.raises(ConfigError) as exc:
        with expected_protocol(Keysight33500B, [], handshake=False, **kw):
            pass
    assert exc.value.key == key
