"""-410 on raw sockets: a query whose reply is not read before the next message is interrupted
(IEEE 488.2 6.3.2.3: the unread response is discarded and ``-410,"Query INTERRUPTED"`` queued).

On a socket the instrument cannot see the client's reads, only what its link has taken: a reply
still queued in the instrument (the client's receive window is full) when the next message
arrives counts as unread. Real sockets: a client with a small receive buffer asks for a 2 MB
waveform block and, without reading it, sends the next query.
"""
from __future__ import annotations

import socket
import time

import pytest

from labkit.lab import VirtualLab

IDN_START = b"KEYSIGHT TECHNOLOGIES,"


def _client(resource: str, rcvbuf: int) -> socket.socket:
    _, host, port, _ = resource.split("::")
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)     # before connecting: the window
    s.settimeout(10)
    s.connect((host, int(port)))
    return s


def _line(s: socket.socket, buf: bytearray) -> bytes:
    while b"\n" not in buf:
        chunk = s.recv(65536)
        if not chunk:
            raise ConnectionError("closed")
        buf += chunk
    at = buf.index(b"\n")
    line = bytes(buf[:at])
    del buf[:at + 1]
    return line


@pytest.fixture(scope="module")
def lab():
    with VirtualLab(seed=21, scope_memory_points=1_000_000) as lab:
        yield lab


def _record(s: socket.socket) -> None:
    s.sendall(b":CHAN1:DISP 1;:TIM:RANG 1e-2;:TRIG:SWE AUTO;:SING\n")
    time.sleep(0.3)
    s.sendall(b":STOP;:WAV:SOUR CHAN1;:WAV:FORM WORD;:WAV:POIN:MODE RAW;:WAV:POIN 1000000\n")


def test_an_unread_block_is_interrupted_by_the_next_query(lab):
    s = _client(lab.resources["scope"], 4096)
    try:
        _record(s)
        s.sendall(b":WAV:DATA?\n")
        time.sleep(0.3)                     # the link takes what the small window allows, no more
        s.sendall(b"*IDN?\n")
        buf = bytearray()
        deadline = time.monotonic() + 10
        while IDN_START not in buf and time.monotonic() < deadline:
            buf += s.recv(1 << 20)
        head = buf.index(IDN_START)
        assert buf[:2] == b"#8" and 0 < head < 2_000_000, head      # part of the block, then the answer
        del buf[:head]
        assert _line(s, buf).startswith(IDN_START)
        for expect in (b'-410,"Query INTERRUPTED"', b'+0,"No error"'):
            s.sendall(b":SYST:ERR?\n")
            assert _line(s, buf).lstrip(b"+") == expect.lstrip(b"+")
    finally:
        s.close()


def test_a_block_read_in_full_is_not_interrupted(lab):
    """The same exchange with the block read before the next query: no -410."""
    s = _client(lab.resources["scope"], 4096)
    try:
        _record(s)
        s.sendall(b":WAV:DATA?\n")
        buf = bytearray()
        while len(buf) < 10:
            buf += s.recv(65536)
        size = int(buf[2:10])
        while len(buf) < 10 + size + 1:
            buf += s.recv(1 << 20)
        assert len(buf) == 10 + size + 1 and size == 2_000_000
        buf.clear()
        s.sendall(b"*IDN?\n")
        assert _line(s, buf).startswith(IDN_START)
        s.sendall(b":SYST:ERR?\n")
        assert _line(s, buf).lstrip(b"+") == b'0,"No error"'
    finally:
        s.close()
