"""The lab forgives nothing a bench would not, and nothing a client sends can make it hang or hoard.

IEEE 488.2-1992 7.5 (a program message ends at LF), 7.7.6 (definite-length block data: its length
says where it ends, LF bytes inside included); SCPI 1999 vol. 1 6.2.4 (the header path); vol. 2
21.8 (-223 "Too much data", -350 "Queue overflow"). Speeds are measured by bench/lab_fuzz.py; here
only what must hold: answers, errors, bounded memory.
"""
from __future__ import annotations

import pytest
from labhelpers import Raw, lab, raw  # noqa: F401  (fixtures)

from labkit.lab.core import LOG_ENTRIES, LOG_TEXT_CHARS, LogRing
from labkit.lab.transport import MAX_MESSAGE_BYTES, Framer


def test_a_block_holding_lf_and_commands_is_data_not_commands(lab, raw):
    """``#217\\nOUTP1 ON\\nOUTP1 ON`` inside a DISP:TEXT-like block parameter: framed by its length
    (before, the LF split it and the bytes after it turned output 1 on)."""
    fg = raw("funcgen")
    payload = (b"\nOUTP1 ON\n;*RST;" * 8)[:64]               # 16 float32 points of 'data'
    fg.sock.sendall(b"DATA:ARB lab,#264" + payload + b"\n")
    assert fg.query("OUTP1?") == "0"
    assert lab.output_state("funcgen", 1) is False
    assert fg.query("SYST:ERR?") == '+0,"No error"'
    assert fg.query('DATA:ATTR:POIN? "lab"') == "+1.600000000000000E+01"


def test_framer_cuts_at_lf_outside_quotes_and_blocks():
    f = Framer()
    msgs = f.feed(b'DISP:TEXT "a\nb";*OPC?\nX #15ab\ncd;Y\n#210\n')
    assert msgs[:2] == [b'DISP:TEXT "a\nb";*OPC?', b"X #15ab\ncd;Y"]
    assert f.feed(b"123456789\n") == [b"#210\n123456789"]


def test_framer_memory_is_bounded_and_a_long_message_is_reported_once():
    f = Framer(max_bytes=1 << 20)
    chunk = b"A" * 65536
    out = []
    for _ in range(48 * 16):                  # 48 MiB without a LF
        out += f.feed(chunk)
        assert len(f.buf) <= (1 << 20) + 65536
    out += f.feed(b"\n*IDN?\n")
    assert out == [None, b"*IDN?"]


def test_unterminated_48_mib_then_a_query_is_answered_with_minus_223(lab, raw):
    fg = raw("funcgen", timeout_s=120)
    fg.sock.sendall(b"DISP:TEXT " + b"A" * (48 << 20))
    fg.write("")
    assert fg.query("SYST:ERR?") == '-223,"Too much data"'
    assert fg.query("*IDN?").startswith("Keysight")
    assert MAX_MESSAGE_BYTES < 48 << 20


def test_a_relative_header_repeated_100k_times_does_not_grow_the_path(lab, raw):
    """``SOUR1:FREQ 1000;SOUR1:FREQ 1000``: the second is relative (SOUR1:SOUR1:FREQ, -113); the path
    then returns to the root, so every other one is valid and the queue overflows at its 20 entries."""
    fg = raw("funcgen", timeout_s=300)
    fg.write(";".join(["SOUR1:FREQ 1234"] * 100_000))
    errors = [fg.query("SYST:ERR?") for _ in range(21)]
    assert errors[:19] == ['-113,"Undefined header"'] * 19
    assert errors[19:] == ['-350,"Queue overflow"', '+0,"No error"']
    assert fg.query("SOUR1:FREQ?") == "+1.234000000000000E+03"


def test_the_log_keeps_the_newest_entries_and_short_texts(lab, raw):
    fg = raw("funcgen")
    for _ in range(3):
        fg.write('DISP:TEXT "' + "x" * (1 << 20) + '"')
    assert fg.query("*OPC?") == "1"
    assert max(len(text) for *_, text in lab.log) < LOG_TEXT_CHARS + 40
    ring = LogRing(maxlen=5)
    for i in range(12):
        ring.append((float(i), "x", "rx", str(i)))
    assert len(ring) == 12 and [e[3] for e in ring] == ["7", "8", "9", "10", "11"]
    assert [e[3] for e in ring[9:]] == ["9", "10", "11"] and ring[-1][3] == "11"
    with pytest.raises(IndexError):
        ring[2]
    assert LOG_ENTRIES <= 20_000


def test_a_non_ascii_byte_is_answered_not_a_hang(lab, raw):
    fg = raw("funcgen", timeout_s=5)
    fg.sock.sendall(b'DISP:TEXT "caf\xe9"\n')
    assert fg.query("DISP:TEXT?") == '"caf?"'
