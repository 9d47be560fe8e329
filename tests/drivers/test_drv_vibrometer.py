"""Polytec controllers over a real pseudo-terminal through pyserial."""
from __future__ import annotations

import json
import time

import numpy as np
import pytest

from labkit.drivers.testing import STALL, Drop, expected_protocol
from labkit.drivers.vibrometer import OFV3001, OFV5000, parse_range_text
from labkit.errors import ConfigError, InstrumentError, LimitError


def test_ofv3001_read_range_ovd01():
    script = [(b"REN\n", None), (b"VELO?\n", b"3\n")]
    with expected_protocol(OFV3001, script, decoder="OVD-01") as v:
        assert v.scale_mm_s_per_v == 125.0
        np.testing.assert_allclose(v.to_velocity_mm_s(np.array([0.1, -0.2])), [12.5, -25.0])


def test_ofv3001_set_range_verified_ovd02():
    script = [(b"REN\n", None), (b"VELO6\n", None), (b"VELO?\n", b"6\n"), (b"OVR\n", b"1\n"),
              (b"OVR\n", b"0\n")]
    with expected_protocol(OFV3001, script, decoder="OVD-02",
                           resource_format="ASRL{}::INSTR") as v:
        v.scale_mm_s_per_v = 5
        assert v.over_range() is True
        assert v.over_range() is False
    assert v.state["scale_mm_s_per_v"] == 5.0


def test_ofv3001_silently_ignored_setting_is_caught():
    script = [(b"REN\n", None), (b"VELO2\n", None), (b"VELO?\n", b"3\n")]
    with expected_protocol(OFV3001, script) as v:
        with pytest.raises(InstrumentError, match="range not accepted") as ei:
            v.scale_mm_s_per_v = 25
    assert ei.value.command == "VELO2"


def test_ofv3001_range_not_in_table_refused_before_sending():
    with expected_protocol(OFV3001, [], decoder="OVD-02") as v:
        with pytest.raises(LimitError) as ei:
            v.scale_mm_s_per_v = 1.0           # OVD-02 has no 1 mm/s/V range
    assert ei.value.limit == "velocity range"


def test_ofv3001_overridable_table_and_baud():
    script = [(b"REN\n", None), (b"VELO?\n", b"12\n")]
    with expected_protocol(OFV3001, script, ranges={2.0: 12}, baud_rate=19200,
                           serial_number="123") as v:
        assert v.transport._ser.baudrate == 19200
        assert v.scale_mm_s_per_v == 2.0
    with pytest.raises(ConfigError, match="decoder"):
        with expected_protocol(OFV3001, [], decoder="OVD-99"):
            pass


def test_ofv3001_unknown_range_number_and_garbage():
    script = [(b"REN\n", None), (b"VELO?\n", b"42\n"), (b"OVR\n", b"??\n"), (b"VELO?\n", b"x\n")]
    with expected_protocol(OFV3001, script) as v:
        with pytest.raises(InstrumentError, match="range number 42"):
            v.scale_mm_s_per_v
        with pytest.raises(InstrumentError, match="garbled"):
            v.over_range()
        with pytest.raises(InstrumentError, match="garbled"):
            v.range_number


def test_ofv3001_snapshot_declares_identity():
    script = [(b"REN\n", None), (b"VELO?\n", b"1\n")]
    with expected_protocol(OFV3001, script, serial_number="SN7") as v:
        snap = json.loads(json.dumps(v.snapshot()))
    assert snap["identity"] == "Polytec,OFV-3001,SN7,OVD-01"
    assert snap["state"] == {"scale_mm_s_per_v": 5.0, "range_number": 1}
    assert snap["settings"]["ranges"]["1000"] == 4


def test_ofv5000_get_and_set_range():
    script = [(b"Get,VeloDec,2,Range\n", b"125mm/s/V\n"),
              (b"Set,VeloDec,2,Range,5mm/s/V\n", None),
              (b"Get,VeloDec,2,Range\n", b"5mm/s/V\n")]
    with expected_protocol(OFV5000, script, decoder_index=2) as v:
        assert v.transport._ser.baudrate == 115200
        assert v.scale_mm_s_per_v == 125.0
        v.scale_mm_s_per_v = 5
    assert v.state["scale_mm_s_per_v"] == 5.0


def test_ofv5000_set_not_accepted():
    script = [(b"Set,VeloDec,1,Range,25mm/s/V\n", None),
              (b"Get,VeloDec,1,Range\n", b"125mm/s/V\n")]
    with expected_protocol(OFV5000, script) as v:
        with pytest.raises(InstrumentError, match="range not accepted"):
            v.scale_mm_s_per_v = 25


def test_ofv5000_declared_ranges_refused_before_sending():
    with expected_protocol(OFV5000, [], ranges_mm_s_per_v=(5, 25, 125)) as v:
        with pytest.raises(LimitError, match="velocity range"):
            v.scale_mm_s_per_v = 7


def test_ofv5000_overridable_commands():
    # over-range and identity commands are (unverified): the test sets its own
    script = [(b"Get,VeloDec,0,OvrFlag\n", b"1\n"), (b"Get,Controller,0,Name\n", b"OFV-5000\n"),
              (b"GetDevInfo,VeloDec,0,Range\n", b"5mm/s/V,25mm/s/V\n")]
    with expected_protocol(OFV5000, script, decoder_index=0,
                           over_range_command="Get,VeloDec,{i},OvrFlag",
                           identity_command="Get,Controller,0,Name") as v:
        assert v.over_range() is True
        assert v.identity == "OFV-5000"
        assert v.device_info() == "5mm/s/V,25mm/s/V"


def test_ofv5000_garbage_drop_and_stall():
    with expected_protocol(OFV5000, [(b"Get,VeloDec,1,Range\n", b"fast\n")]) as v:
        with pytest.raises(InstrumentError, match="garbled"):
            v.scale_mm_s_per_v
    with expected_protocol(OFV5000, [(b"Get,VeloDec,1,Range\n", Drop(b"12"))]) as v:
        with pytest.raises(InstrumentError) as ei:
            v.scale_mm_s_per_v
    assert ei.value.command == "Get,VeloDec,1,Range"
    t0 = time.monotonic()
    with expected_protocol(OFV5000, [(b"Get,VeloDec,1,Range\n", STALL)], timeout_s=0.2) as v:
        with pytest.raises(InstrumentError, match="timeout"):
            v.scale_mm_s_per_v
    assert time.monotonic() - t0 < 2.0


def test_parse_range_text():
    assert parse_range_text("125mm/s/V") == 125.0
    assert parse_range_text("1m/s/V") == 1000.0
    assert parse_range_text(" 0.5 mm/s/V ") == 0.5
    with pytest.raises(ValueError):
        parse_range_text("125")


def test_ofv5000_signal_delay_asked_once_and_decoder_settings_read_back():
    """The decoder's signal delay (``Get,VeloDec,1,SignalDelay`` -> ``7.6us``) is asked once and kept;
    Filter/Tracking settings are read back (the controller ignores an invalid value silently)."""
    script = [(b"Get,VeloDec,1,SignalDelay\n", b"7.6us\n"), (b"Set,VeloDec,1,Filter,20kHz\n", None),
              (b"Get,VeloDec,1,Filter\n", b"20kHz\n"), (b"Set,VeloDec,1,Tracking,Maybe\n", None),
              (b"Get,VeloDec,1,Tracking\n", b"Off\n")]
    with expected_protocol(OFV5000, script, handshake=False) as v:
        assert v.signal_delay_s == pytest.approx(7.6e-6)
        assert v.signal_delay_s == pytest.approx(7.6e-6)       # cached: not asked again
        v.set_decoder("Filter", "20kHz")
        with pytest.raises(InstrumentError, match="Tracking not accepted"):
            v.set_decoder("Tracking", "Maybe")
    assert v.state["filter"] == "20kHz"


def test_declared_signal_delay_is_not_asked_and_garbled_delay_is_an_error():
    with expected_protocol(OFV5000, [], handshake=False, signal_delay_s=3e-6) as v:
        assert v.signal_delay_s == 3e-6
    with expected_protocol(OFV3001, [], signal_delay_s=2e-6) as v3:
        assert v3.signal_delay_s == 2e-6 and v3.settings()["signal_delay_s"] == 2e-6
    with expected_protocol(OFV5000, [(b"Get,VeloDec,1,SignalDelay\n", b"soon\n")], handshake=False) as v:
        with pytest.raises(InstrumentError, match="garbled reply 'soon'"):
            _ = v.signal_delay_s
