"""The common base and the expected-protocol helper, over real loopback links."""
from __future__ import annotations

import json
import socket
import time

import pytest

from labkit.drivers.base import Instrument, ScpiInstrument, SerialTransport, check_range, open_transport
from labkit.drivers.testing import STALL, Drop, expected_protocol
from labkit.errors import ConfigError, InstrumentError, LimitError


class Plain(Instrument):
    model = "plain"


class Safe(ScpiInstrument):
    """A driver whose safe_off sends one command, to test the context manager."""

    model = "safe"

    def safe_off(self) -> None:
        self.write("OUTP OFF")


def test_helper_passes_exact_exchange_and_identity():
    with expected_protocol(Plain, [(b"*IDN?\n", b"ACME,X1,7,1.0\n"), (b"FREQ 1000\n", None)]) as d:
        assert d.identity == "ACME,X1,7,1.0"
        assert d.identity == "ACME,X1,7,1.0"      # cached: asked once
        d.write("FREQ 1000")


def test_helper_fails_on_wrong_bytes():
    with pytest.raises(AssertionError, match="wrong bytes"):
        with expected_protocol(Plain, [(b"FREQ 1000\n", None)]) as d:
            d.write("FREQ 2000")


def test_helper_fails_on_missing_exchange():
    with pytest.raises(AssertionError, match="missing"):
        with expected_protocol(Plain, [(b"FREQ 1000\n", None)]):
            pass


def test_helper_fails_on_unexpected_bytes():
    with pytest.raises(AssertionError, match="unexpected bytes"):
        with expected_protocol(Plain, []) as d:
            d.write("OUTP ON")


def test_stall_times_out_within_timeout():
    t0 = time.monotonic()
    with expected_protocol(Plain, [(b"*IDN?\n", STALL)], timeout_s=0.2) as d:
        with pytest.raises(InstrumentError) as ei:
            d.query("*IDN?")
    assert time.monotonic() - t0 < 2.0
    assert ei.value.command == "*IDN?" and ei.value.instrument == d.name
    assert "no reply within 0.2 s" in str(ei.value)


def test_dropped_connection_mid_reply():
    t0 = time.monotonic()
    with expected_protocol(Plain, [(b"*IDN?\n", Drop(b"ACME,X"))], timeout_s=0.2) as d:
        with pytest.raises(InstrumentError, match="connection closed") as ei:
            d.query("*IDN?")
    assert time.monotonic() - t0 < 2.0
    assert ei.value.command == "*IDN?"


def test_write_after_drop_is_instrument_error():
    with expected_protocol(Plain, [(b"A\n", Drop())], timeout_s=0.2) as d:
        d.write("A")
        time.sleep(0.05)
        with pytest.raises(InstrumentError):
            for _ in range(50):          # the first send after a close may still succeed
                d.write("B")
                time.sleep(0.01)


@pytest.mark.parametrize("reply", [b"\xff\xfe\n", b"AB\x01C\n"])
def test_garbled_reply(reply):
    with expected_protocol(Plain, [(b"*IDN?\n", reply)]) as d:
        with pytest.raises(InstrumentError, match="garbled"):
            d.query("*IDN?")


def test_query_float_and_int_garbage():
    with expected_protocol(Plain, [(b"F?\n", b"1.5e3\n"), (b"F?\n", b"abc\n"),
                                   (b"N?\n", b"+1\n"), (b"N?\n", b"1.5\n")]) as d:
        assert d.query_float("F?") == 1500.0
        with pytest.raises(InstrumentError, match="expected a number"):
            d.query_float("F?")
        assert d.query_int("N?") == 1
        with pytest.raises(InstrumentError, match="integer"):
            d.query_int("N?")


def test_context_manager_safe_off_after_exception():
    with expected_protocol(Safe, [(b"OUTP OFF\n", None)]) as d:
        with pytest.raises(RuntimeError, match="boom"):
            with d:
                raise RuntimeError("boom")
        with pytest.raises(InstrumentError, match="closed"):
            d.write("X")                  # closed by the context manager


class SafeConfirming(Safe):
    """safe_off asks for a confirmation, so it fails on a link that has dropped."""

    def safe_off(self) -> None:
        self.query("OUTP?")


def test_context_manager_keeps_original_error_when_safe_off_fails():
    with expected_protocol(SafeConfirming, [(b"Q?\n", Drop())], timeout_s=0.2) as d:
        with pytest.raises(InstrumentError) as ei:
            with d:
                d.query("Q?")
    assert ei.value.command == "Q?"                                   # the original error is kept
    assert any("safe_off failed as well" in note for note in getattr(ei.value, "__notes__", []))


def test_snapshot_is_json():
    with expected_protocol(Safe, [(b"*IDN?\n", b"ACME,S,1,2\n")]) as d:
        snap = d.snapshot()
    text = json.dumps(snap)
    assert snap["identity"] == "ACME,S,1,2" and snap["model"] == "safe"
    assert snap["settings"]["check_errors"] is True and "timeout_s" in text


def test_error_queue_drained_and_reported():
    ok = b'+0,"No error"\n'
    with expected_protocol(Safe, [(b"SYST:ERR?\n", b'-113,"Undefined header"\n'),
                                  (b"SYST:ERR?\n", b'-222,"Data out of range"\n'),
                                  (b"SYST:ERR?\n", ok)]) as d:
        with pytest.raises(InstrumentError) as ei:
            d.check_errors(after="FREQ 1")
    assert '-113,"Undefined header"' in str(ei.value) and '-222' in str(ei.value)
    assert ei.value.command == "FREQ 1"


def test_error_queue_garbage():
    with expected_protocol(Safe, [(b"SYST:ERR?\n", b"what\n")]) as d:
        with pytest.raises(InstrumentError, match="garbled error-queue"):
            d.check_errors()


def test_unknown_setting_is_config_error():
    with pytest.raises(ConfigError, match="no_such"):
        with expected_protocol(Plain, [], no_such=1):
            pass


def test_open_refused_port_is_instrument_error():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    with pytest.raises(InstrumentError) as ei:
        Plain.open(f"TCPIP0::127.0.0.1::{port}::SOCKET", timeout_s=0.3)
    assert ei.value.command == "open"


def test_serial_url_and_asrl_resource():
    t = open_transport("loop://", 0.2)
    assert isinstance(t, SerialTransport)
    t.write("PING")
    assert t.read() == "PING"
    t.close()
    with expected_protocol(Plain, [(b"*IDN?\n", b"X,Y,1,2\n")], link="serial",
                           resource_format="ASRL{}::INSTR", baud_rate=115200) as d:
        assert d.identity == "X,Y,1,2"
        assert d.resource.startswith("/dev/")


def test_serial_drop_and_stall():
    with expected_protocol(Plain, [(b"A?\n", Drop(b"12"))], link="serial", timeout_s=0.2) as d:
        with pytest.raises(InstrumentError) as ei:
            d.query("A?")
    assert ei.value.command == "A?"
    t0 = time.monotonic()
    with expected_protocol(Plain, [(b"A?\n", STALL)], link="serial", timeout_s=0.2) as d:
        with pytest.raises(InstrumentError, match="timeout"):
            d.query("A?")
    assert time.monotonic() - t0 < 2.0


def test_check_range_names_limit():
    assert check_range("x", 3, 0, 5) == 3.0
    with pytest.raises(LimitError) as ei:
        check_range("max_amp_vpp", 6, 0, 5, "Vpp")
    assert ei.value.limit == "max_amp_vpp" and "max_amp_vpp" in str(ei.value)
    with pytest.raises(LimitError):
        check_range("y", float("nan"))
    with pytest.raises(LimitError):
        check_range("y", "abc")


def test_timeout_setter_validated():
    with expected_protocol(Plain, [], timeout_s=0.25) as d:
        assert d.timeout_s == pytest.approx(0.25)
        d.timeout_s = 0.4
        assert d.timeout_s == pytest.approx(0.4)
        with pytest.raises(LimitError):
            d.timeout_s = -1


def test_transport_settings_for_the_other_link_are_ignored():
    t = open_transport("loop://", 0.2, chunk_size=1024, fast_blocks=False, baud_rate=9600)
    assert isinstance(t, SerialTransport)
    t.close()
    with expected_protocol(Plain, [(b"*IDN?\n", b"A,B,C,D\n")], baud_rate=9600,
                           parity="N") as d:
        assert d.identity == "A,B,C,D"


@pytest.mark.parametrize("resource", ["garbage::x", "nonsense", ""])
def test_malformed_resource_is_config_error(resource):
    with pytest.raises(ConfigError) as ei:
        Plain.open(resource, timeout_s=0.2)
    assert ei.value.key == "resource"


def test_missing_serial_port_is_instrument_error(tmp_path):
    with pytest.raises(InstrumentError) as ei:
        Plain.open(str(tmp_path / "ttyNOPE").replace(str(tmp_path), "/dev/labkit-none"),
                   timeout_s=0.2)
    assert ei.value.command == "open"
