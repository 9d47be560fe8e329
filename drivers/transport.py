"""Transports: lines of text and IEEE 488.2 blocks over pyvisa-py or pyserial.

* :class:`VisaTransport` — pyvisa with the pure-Python backend
  (``ResourceManager("@py")``), for ``TCPIP0::host::port::SOCKET`` (raw SCPI
  sockets, port 5025 on real LAN instruments) and any other VISA resource
  pyvisa-py knows. No vendor VISA library is needed.
* :class:`SerialTransport` — pyserial, for ``ASRL/dev/pts/3::INSTR``, a plain
  ``/dev/ttyUSB0`` path, or a pyserial URL (``loop://``, ``socket://host:port``).

Transports raise :class:`TransportError` or the library's own exceptions;
:class:`labkit.drivers.base.Instrument` turns every one of them into an
InstrumentError naming the instrument and the command.
"""
from __future__ import annotations

import re
import threading
import time
from typing import Any

import numpy as np

TRANSPORT_KEYS = frozenset({"baud_rate", "bytesize", "parity", "stopbits", "read_termination",
                            "write_termination", "chunk_size", "fast_blocks"})

_RM = None
_RM_LOCK = threading.Lock()


def resource_manager():
    """The process-wide pyvisa ``ResourceManager("@py")`` (created on first use)."""
    global _RM
    with _RM_LOCK:
        if _RM is None:
            import pyvisa
            _RM = pyvisa.ResourceManager("@py")
        return _RM


class TransportError(Exception):
    """A transport-level failure; :class:`Instrument` turns it into InstrumentError."""


#: the longest reply line accepted (a line without its termination beyond this is an error)
MAX_LINE_BYTES = 16 << 20
#: a block's deadline grows by its length at this rate (a 100 Mbit/s LAN moves ~12 MB/s)
BLOCK_BYTES_PER_S = 10e6


def _block_size(head: bytes, read: Any) -> int:
    """The payload length of a block whose first two bytes are ``head`` (``read(n)`` reads on)."""
    if head[:1] != b"#" or not head[1:2].isdigit() or head[1:2] == b"0":
        raise TransportError(f"malformed block header {head!r} (expected '#<n><length>')")
    digits = read(int(head[1:2]))
    if not digits.isdigit():
        raise TransportError(f"malformed block length {digits!r}")
    return int(digits)


def _block_array(data: bytes, size: int, term: bytes, datatype: str, big_endian: bool) -> np.ndarray:
    """The block's payload (``data`` holds it and the termination) as a numpy array."""
    if len(data) != size + len(term) or data[size:] != term:
        raise TransportError(f"block of {size} bytes not followed by the termination")
    dtype = np.dtype(datatype).newbyteorder(">" if big_endian else "<")
    if size % dtype.itemsize:
        raise TransportError(f"block of {size} bytes is not a whole number of {datatype!r}")
    return np.frombuffer(data, dtype=dtype, count=size // dtype.itemsize)


# ---------------------------------------------------------------------------------------------
# transports


class Transport:
    """What a driver needs from a link: lines of text and IEEE 488.2 binary blocks.

    Subclasses raise :class:`TransportError` (or let the library's own
    exception through; :class:`Instrument` wraps both).
    """

    resource: str = ""

    @property
    def timeout_s(self) -> float:
        raise NotImplementedError

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        raise NotImplementedError

    def write(self, text: str) -> None:
        raise NotImplementedError

    def read(self) -> str:
        raise NotImplementedError

    def query_block(self, command: str, datatype: str, big_endian: bool) -> np.ndarray:
        """Send ``command`` and read one definite-length block ``#<n><len><data>\\n``."""
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError


class VisaTransport(Transport):
    """A pyvisa-py message-based resource (raw TCP socket, VXI-11, USBTMC, ...).

    Parameters
    ----------
    resource:
        VISA resource string, e.g. ``"TCPIP0::127.0.0.1::5025::SOCKET"``.
    timeout_s:
        Per-operation timeout.
    read_termination, write_termination:
        Both ``"\\n"`` by default; pyvisa-py SOCKET resources time out on every
        query without a read termination.
    chunk_size:
        Bytes per low-level read for binary blocks (large chunks: fewer calls).
    fast_blocks:
        Read definite-length blocks with the termination character disabled
        (default). False uses pyvisa's ``query_binary_values`` as is.
    """

    def __init__(self, resource: str, timeout_s: float = 2.0, *, read_termination: str = "\n",
                 write_termination: str = "\n", chunk_size: int = 1 << 20,
                 fast_blocks: bool = True) -> None:
        self.resource = resource
        self.chunk_size = int(chunk_size)
        self.fast_blocks = bool(fast_blocks)
        ms = max(1, int(round(timeout_s * 1000)))
        self._res = resource_manager().open_resource(
            resource, read_termination=read_termination, write_termination=write_termination,
            timeout=ms, open_timeout=ms)
        # pyvisa-py 0.8 reports success for a refused TCP connect: check the socket ourselves
        sock = self._socket()
        if sock is not None:
            import os
            import socket
            err = sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
            if err:
                self._res.close()
                raise TransportError(f"connection failed: {os.strerror(err)}")
            # Without TCP_NODELAY a query written after unanswered commands waits
            # for the peer's delayed ACK (~40 ms on Linux) under Nagle's algorithm.
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        # Raw sockets are read here, not by pyvisa-py: its timeout restarts with every chunk that
        # arrives, so an instrument trickling a byte at a time never times out. Ours is one
        # deadline per reply (see _deadline_read).
        self._sock = sock
        self._rbuf = bytearray()
        self._rterm = read_termination.encode()

    def _socket(self):
        import socket
        try:
            sock = self._res.visalib.sessions[self._res.session].interface
        except (AttributeError, KeyError, TypeError):
            return None
        return sock if isinstance(sock, socket.socket) else None

    @property
    def timeout_s(self) -> float:
        return self._res.timeout / 1000.0

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        self._res.timeout = max(1, int(round(value * 1000)))

    def write(self, text: str) -> None:
        self._res.write(text)

    def read(self) -> str:
        if self._sock is None or not self._rterm:
            return self._res.read()
        deadline = time.monotonic() + self.timeout_s
        while True:
            at = self._rbuf.find(self._rterm)
            if at >= 0:
                line = bytes(self._rbuf[:at])
                del self._rbuf[:at + len(self._rterm)]
                return line.decode("ascii")
            if len(self._rbuf) > MAX_LINE_BYTES:
                self._rbuf.clear()
                raise TransportError(f"reply longer than {MAX_LINE_BYTES} bytes without a termination")
            self._recv_some(deadline, f"partial reply {bytes(self._rbuf[:40])!r}")

    def _recv_some(self, deadline: float, got: str) -> None:
        """Append what the socket has to the buffer, waiting at most until ``deadline`` (monotonic)."""

        assert self._sock is not None
        left = deadline - time.monotonic()
        if left <= 0:
            raise TransportError(f"timeout after {self.timeout_s:g} s ({got}; the deadline covers the "
                                 "whole reply)")
        was = self._sock.gettimeout()
        self._sock.settimeout(left)
        try:
            chunk = self._sock.recv(1 << 20)
        except TimeoutError:
            raise TransportError(f"timeout after {self.timeout_s:g} s ({got})") from None
        finally:
            self._sock.settimeout(was)
        if not chunk:
            raise TransportError("connection closed by the instrument")
        self._rbuf += chunk

    def _read_exact(self, n: int, deadline: float) -> bytes:
        while len(self._rbuf) < n:
            self._recv_some(deadline, f"got {len(self._rbuf)} of {n} bytes")
        out = bytes(self._rbuf[:n])
        del self._rbuf[:n]
        return out

    def _socket_block(self, command: str, datatype: str, big_endian: bool) -> np.ndarray:
        """A definite-length block read from the socket under one deadline: the timeout, plus the
        block's length at :data:`BLOCK_BYTES_PER_S` (a 16 MB record over a LAN)."""
        self._res.write(command)
        deadline = time.monotonic() + self.timeout_s
        head = self._read_exact(2, deadline)
        size = _block_size(head, lambda n: self._read_exact(n, deadline))
        deadline += size / BLOCK_BYTES_PER_S
        data = self._read_exact(size + len(self._rterm), deadline)
        return _block_array(data, size, self._rterm, datatype, big_endian)

    def query_block(self, command: str, datatype: str, big_endian: bool) -> np.ndarray:
        if self._sock is not None and self.fast_blocks:
            return self._socket_block(command, datatype, big_endian)
        if not self.fast_blocks:
            return self._res.query_binary_values(
                command, datatype=datatype, is_big_endian=big_endian, container=np.array,
                chunk_size=self.chunk_size, raise_on_late_block=True)
        # Fast path: parse the header ourselves, then read the payload with the
        # termination character disabled. pyvisa-py 0.8 otherwise stops at every
        # 0x0A byte inside binary data, 4 KB at a time (~18 MB/s on loopback).
        from pyvisa import constants

        self._res.write(command)
        head = bytes(self._res.read_bytes(2))
        size = _block_size(head, lambda n: bytes(self._res.read_bytes(n)))
        term = (self._res.read_termination or "").encode()
        self._res.set_visa_attribute(constants.ResourceAttribute.termchar_enabled, False)
        try:
            data = self._res.read_bytes(size + len(term), chunk_size=self.chunk_size)
        finally:
            self._res.set_visa_attribute(constants.ResourceAttribute.termchar_enabled, True)
        return _block_array(bytes(data), size, term, datatype, big_endian)

    def dropped(self) -> bool:
        """True when the peer has closed the connection (raw sockets only)."""
        import socket
        sock = self._socket()
        if sock is None:
            return False
        try:
            return sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
        except BlockingIOError:
            return False
        except OSError:
            return True

    def close(self) -> None:
        self._rbuf.clear()
        self._res.close()


_ASRL_PATH = re.compile(r"^ASRL(/.+?)::INSTR$", re.IGNORECASE)


class SerialTransport(Transport):
    """A serial port through pyserial (a tty, a pseudo-terminal, or a pyserial URL).

    Every read has one overall deadline of ``timeout_s``; a port that vanishes
    (pty master closed, USB adapter pulled) raises at once.
    """

    def __init__(self, port: str, timeout_s: float = 2.0, *, baud_rate: int = 9600,
                 bytesize: int = 8, parity: str = "N", stopbits: float = 1,
                 read_termination: str = "\n", write_termination: str = "\n") -> None:
        import serial

        self.resource = port
        self._rterm = read_termination.encode()
        self._wterm = write_termination.encode()
        self._timeout = float(timeout_s)
        self._rbuf = bytearray()     # bytes read past the last reply line
        self._ser = serial.serial_for_url(
            port, baudrate=int(baud_rate), bytesize=int(bytesize), parity=str(parity),
            stopbits=stopbits, timeout=self._timeout, write_timeout=self._timeout,
            exclusive=None if "://" in port else True)

    @property
    def timeout_s(self) -> float:
        return self._timeout

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        self._timeout = float(value)
        self._ser.timeout = self._timeout
        self._ser.write_timeout = self._timeout

    def write(self, text: str) -> None:
        self._ser.write(text.encode("ascii") + self._wterm)
        self._ser.flush()

    def _read_exact(self, n: int, deadline: float) -> bytes:
        buf = self._rbuf[:n]
        del self._rbuf[:n]
        while len(buf) < n:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TransportError(f"timeout: got {len(buf)} of {n} bytes")
            self._ser.timeout = left
            buf += self._ser.read(n - len(buf))
        return bytes(buf)

    def read(self) -> str:
        """One reply line under one deadline: pyserial's own ``read_until`` waits its timeout per
        byte (a controller sending a byte every 0.7 s would never time out with 1 s)."""
        deadline = time.monotonic() + self._timeout
        while (end := self._rbuf.find(self._rterm)) < 0:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TransportError(f"timeout after {self._timeout:g} s (partial reply {bytes(self._rbuf[:40])!r}; "
                                     "the deadline covers the whole reply)")
            if len(self._rbuf) > MAX_LINE_BYTES:
                self._rbuf.clear()
                raise TransportError(f"reply longer than {MAX_LINE_BYTES} bytes without a termination")
            self._ser.timeout = left
            self._rbuf += self._ser.read(max(1, self._ser.in_waiting))
        line = bytes(self._rbuf[:end])
        del self._rbuf[:end + len(self._rterm)]
        return line.decode("ascii")

    def query_block(self, command: str, datatype: str, big_endian: bool) -> np.ndarray:
        self.write(command)
        deadline = time.monotonic() + self._timeout
        head = self._read_exact(2, deadline)
        size = _block_size(head, lambda n: self._read_exact(n, deadline))
        data = self._read_exact(size + len(self._rterm), deadline + size / BLOCK_BYTES_PER_S)
        return _block_array(data, size, self._rterm, datatype, big_endian).copy()

    def close(self) -> None:
        self._ser.close()


def open_transport(resource: str, timeout_s: float = 2.0, **kw: Any) -> Transport:
    """Open ``resource`` with the right transport.

    ``ASRL<path>::INSTR``, ``/dev/...`` paths and ``scheme://`` URLs go to
    pyserial; every other string is a VISA resource for pyvisa-py. Keyword
    settings that do not apply to the chosen transport (a baud rate for a
    socket, a chunk size for a serial port) are ignored, so one model's
    defaults work on either link.
    """
    m = _ASRL_PATH.match(resource)
    port = m.group(1) if m else (resource if resource.startswith("/dev/") or "://" in resource
                                 else None)
    if port is not None:
        skw = {k: v for k, v in kw.items() if k in _SERIAL_KEYS}
        return SerialTransport(port, timeout_s, **skw)
    vkw = {k: v for k, v in kw.items() if k in _VISA_KEYS}
    return VisaTransport(resource, timeout_s, **vkw)


_SERIAL_KEYS = ("baud_rate", "bytesize", "parity", "stopbits", "read_termination",
                "write_termination")
_VISA_KEYS = ("read_termination", "write_termination", "chunk_size", "fast_blocks")


class _Closed(Transport):
    """Stands in for a closed link: every use raises TransportError."""

    def __init__(self, resource: str) -> None:
        self.resource = resource

    @property
    def timeout_s(self) -> float:
        return 0.0

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        pass

    def write(self, text: str) -> None:
        raise TransportError("connection is closed")

    def read(self) -> str:
        raise TransportError("connection is closed")

    def close(self) -> None:
        pass

    def query_block(self, command: str, datatype: str, big_endian: bool) -> np.ndarray:
        raise TransportError("connection is closed")
