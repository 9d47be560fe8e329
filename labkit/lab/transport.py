"""Real transports for the simulated instruments: raw TCP sockets and pseudo-terminals.

Both carry ``\\n``-terminated lines to an object with ``handle(line) ->
bytes | None`` (a :class:`labkit.lab.scpi.SimScpiInstrument`, the vibrometer,
the control channel) and send its reply back with one ``sendall``/``write``
(a 2 MB waveform block leaves in one call). Every line in and every reply out
goes to ``on_log(instrument, "rx"|"tx", text)``.

Faults (:class:`Fault`) are applied to replies: ``drop`` sends half of the
reply and closes the connection (a pulled cable, mid-block for a waveform),
``stall`` swallows the reply (a hung instrument), ``garbage`` replaces it with
random bytes and a ``\\n``, ``trickle`` sends it a byte at a time (sockets and ptys).
"""
from __future__ import annotations

import os
import re
import select
import socket
import threading
import tty
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np


class Handler(Protocol):
    name: str

    def handle(self, line: str) -> bytes | None: ...


LogFn = Callable[[str, str, str], None]


#: ``trickle``: the reply leaves one byte every ``interval_s`` (a scope whose link crawls)
FAULT_KINDS = ("drop", "stall", "garbage", "trickle")


@dataclass
class Fault:
    """A fault armed on one instrument.

    Parameters
    ----------
    kind:
        ``"drop"``, ``"stall"`` or ``"garbage"``.
    after:
        How many matching replies still go out normally before the fault hits.
    match:
        Only replies to commands containing this text (case-insensitive, e.g.
        ``"DATA?"``) count; None: every reply.
    count:
        How many replies the fault affects (then it disarms itself).
    """

    kind: str
    after: int = 0
    match: str | None = None
    count: int = 1
    interval_s: float = 0.5

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"fault kind must be one of {', '.join(FAULT_KINDS)}, not {self.kind!r}")

    def hits(self, command: str) -> bool:
        """Count a reply to ``command``; True when this one is to be spoiled."""
        if self.count <= 0:
            return False
        if self.match and self.match.upper() not in command.upper():
            return False
        if self.after > 0:
            self.after -= 1
            return False
        self.count -= 1
        return True


def describe(data: bytes) -> str:
    """Log text of a reply: binary blocks are summarised, not dumped."""
    if data.startswith(b"#") and len(data) > 2 and data[1:2].isdigit():
        n = int(data[1:2] or b"0")
        return f"{data[:2 + n].decode('ascii', 'replace')}<{len(data) - 3 - n} bytes>"
    text = data.rstrip(b"\n")
    if len(text) > 200:
        return text[:200].decode("ascii", "replace") + f"...<{len(text)} bytes>"
    return text.decode("ascii", "replace")


#: the longest program message a server accepts (a longer one is dropped whole: -223)
MAX_MESSAGE_BYTES = 8 << 20
_SPECIAL = re.compile(rb"[\n#\"']")


class Framer:
    """Cuts a byte stream into program messages at LF (IEEE 488.2 7.5), in linear time.

    A LF inside a quoted string or inside a definite-length block (``#<n><length><bytes>``,
    488.2 7.7.6) does not end the message: the block is skipped by its length. A message
    longer than ``max_bytes`` is dropped up to its LF (only its start was kept); it comes
    out as ``None``, for the instrument to report (``-223,"Too much data"``).
    """

    def __init__(self, max_bytes: int = MAX_MESSAGE_BYTES) -> None:
        self.max_bytes = int(max_bytes)
        self.buf = bytearray()
        self.start = 0          # where the message being read begins
        self.pos = 0            # scanned up to here
        self.quote: int | None = None
        self.skip = 0           # block bytes still to pass over
        self.dropping = False   # inside a message that is too long

    def feed(self, data: bytes) -> list[bytes | None]:
        """The messages completed by ``data`` (without their LF; None: one that was too long)."""
        self.buf += data
        out: list[bytes | None] = []
        while self.pos < len(self.buf):
            if self.skip:
                n = min(self.skip, len(self.buf) - self.pos)
                self.skip -= n
                self.pos += n
                continue
            if self.quote is not None:
                end = self.buf.find(bytes([self.quote]), self.pos)
                if end < 0:
                    self.pos = len(self.buf)
                    break
                self.quote, self.pos = None, end + 1
                continue
            m = _SPECIAL.search(self.buf, self.pos)
            if m is None:
                self.pos = len(self.buf)
                break
            c, at = m.group()[0], m.start()
            if c == 0x0A:
                out.append(None if self.dropping else bytes(self.buf[self.start:at]))
                self.start = self.pos = at + 1
                self.dropping = False
            elif c == 0x23:         # '#': a block header, once it is all here
                if not self._block_at(at):
                    break
            else:
                self.quote, self.pos = c, at + 1
        if self.pos - self.start > self.max_bytes or self.dropping:   # too long: keep only the state
            self.dropping = True
            self.start = self.pos
        del self.buf[:self.start]
        self.pos -= self.start
        self.start = 0
        return out

    def _block_at(self, at: int) -> bool:
        """Pass a ``#<n><length>`` header at ``at`` (and arrange to skip its bytes); False: wait."""
        if at + 2 > len(self.buf):
            self.pos = at
            return False
        d = self.buf[at + 1]
        if not 0x31 <= d <= 0x39:           # '#0' (indefinite) or not a block: an ordinary byte
            self.pos = at + 1
            return True
        n = d - 0x30
        if at + 2 + n > len(self.buf):
            self.pos = at
            return False
        digits = bytes(self.buf[at + 2:at + 2 + n])
        self.pos = at + 2 + n
        self.skip = int(digits) if digits.isdigit() else 0
        return True


class _Endpoint:
    """What the TCP and pty servers share: faults, logging, reply shaping."""

    def __init__(self, handler: Handler, on_log: LogFn, seed: int = 0) -> None:
        self.handler = handler
        self.on_log = on_log
        self.faults: list[Fault] = []
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._trickle_s = 0.5

    @property
    def name(self) -> str:
        return self.handler.name

    def inject(self, fault: Fault) -> None:
        with self._lock:
            self.faults.append(fault)

    def clear_faults(self) -> None:
        with self._lock:
            self.faults.clear()

    def _fault_for(self, command: str) -> Fault | None:
        with self._lock:
            hit = None
            for fault in self.faults:
                if fault.hits(command):
                    hit = fault
                    break
            self.faults = [f for f in self.faults if f.count > 0]
            return hit

    def too_long(self) -> None:
        """A message longer than :data:`MAX_MESSAGE_BYTES` was dropped: the instrument says so
        (``-223,"Too much data"``, IEEE 488.2 / SCPI vol. 2 21.8.9), if it has an error queue."""
        self.on_log(self.name, "rx", f"<message over {MAX_MESSAGE_BYTES} bytes dropped>")
        push = getattr(self.handler, "push_error", None)
        if push is not None:
            with self.handler_lock():
                push(-223, "Too much data")

    def handler_lock(self) -> Any:
        return getattr(self.handler, "lock", None) or threading.Lock()

    def lines(self, framer: Framer, chunk: bytes) -> Iterator[str]:
        """The non-empty messages ``chunk`` completes, as text (bytes kept one to one: latin-1)."""
        for msg in framer.feed(chunk):
            if msg is None:
                self.too_long()
                continue
            line = msg.rstrip(b"\r").decode("latin-1")
            if line.strip():
                yield line

    def process(self, line: str) -> tuple[bytes | None, str | None]:
        """Run one line; return (bytes to send, fault kind or None)."""
        self.on_log(self.name, "rx", line)
        try:
            reply = self.handler.handle(line)
        except Exception as exc:  # a bug in a simulated instrument must not kill the server
            self.on_log(self.name, "error", f"{type(exc).__name__}: {exc}")
            reply = None
        if reply is None:
            return None, None
        fault = self._fault_for(line)
        if fault is None:
            self.on_log(self.name, "tx", describe(reply))
            return reply, None
        if fault.kind == "stall":
            self.on_log(self.name, "fault", f"stall: reply to {line!r} withheld")
            return None, "stall"
        if fault.kind == "trickle":
            self.on_log(self.name, "fault", f"trickle: the reply to {line!r} leaves a byte every "
                        f"{fault.interval_s:g} s")
            self._trickle_s = fault.interval_s
            return reply, "trickle"
        if fault.kind == "garbage":
            junk = bytes(self._rng.integers(128, 256, size=max(8, min(len(reply), 64)), dtype=np.uint8)) + b"\n"
            self.on_log(self.name, "fault", f"garbage: {junk[:-1]!r} instead of the reply to {line!r}")
            return junk, "garbage"
        part = reply[: max(1, len(reply) // 2)]
        self.on_log(self.name, "fault", f"drop: connection closed after {len(part)} of {len(reply)} bytes")
        return part, "drop"


#: the socket send buffer of a served connection (the kernel doubles it for its bookkeeping)
SEND_BUFFER_BYTES = 256 << 10


class TcpServer(_Endpoint):
    """A raw-socket line server on 127.0.0.1 (ephemeral port), one thread per client."""

    def __init__(self, handler: Handler, on_log: LogFn, seed: int = 0, host: str = "127.0.0.1") -> None:
        super().__init__(handler, on_log, seed)
        self.sock = socket.create_server((host, 0))
        self.host, self.port = self.sock.getsockname()[:2]
        self._threads: list[threading.Thread] = []
        self._conns: set[socket.socket] = set()

    @property
    def resource(self) -> str:
        return f"TCPIP0::{self.host}::{self.port}::SOCKET"

    def start(self) -> None:
        t = threading.Thread(target=self._accept, name=f"lab-{self.name}-accept", daemon=True)
        t.start()
        self._threads.append(t)

    def _accept(self) -> None:
        accept_loop(self.sock, self._stop, self._lock, self._conns, self._threads, self._serve,
                    f"lab-{self.name}-conn")

    def _serve(self, conn: socket.socket) -> None:
        """Read messages and send replies without blocking on either: a reply leaves as fast as
        the link takes it (the instrument's output queue, :meth:`_flush`), and a message that
        arrives while part of a reply is still queued interrupts it (:meth:`_interrupt`)."""
        framer = Framer()
        out = bytearray()
        # an instrument's LAN buffer is small: a fixed one (no autotuning to megabytes) keeps an
        # unread reply in the instrument, where the next message finds it
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER_BYTES)
        conn.setblocking(False)
        try:
            while not self._stop.is_set():
                readable, writable, _ = select.select([conn], [conn] if out else [], [], 0.05)
                if writable:
                    self._flush(conn, out)
                if not readable:
                    continue
                chunk = conn.recv(65536)
                if not chunk or not self._answer(conn, framer, chunk, out):
                    return
        except OSError:
            return
        finally:
            with self._lock:
                self._conns.discard(conn)
            conn.close()

    def _answer(self, conn: socket.socket, framer: Framer, chunk: bytes, out: bytearray) -> bool:
        """Process every complete message of ``chunk``, queueing (or trickling) the replies; False
        when a ``drop`` fault closed the link."""
        for line in self.lines(framer, chunk):
            if out:
                self._interrupt(out)
            data, fault = self.process(line)
            if data and fault == "trickle":
                self._send_trickle(conn, data)
            elif data:
                out += data
                self._flush(conn, out)
            if fault == "drop":
                conn.setblocking(True)
                conn.sendall(out)
                conn.shutdown(socket.SHUT_RDWR)
                return False
        return True

    @staticmethod
    def _flush(conn: socket.socket, out: bytearray) -> None:
        """Hand the link as much of the queued reply as it takes now."""
        try:
            n = conn.send(out)
        except BlockingIOError:
            return
        del out[:n]

    def _interrupt(self, out: bytearray) -> None:
        """A message arrived before the last reply was read (what the link has not taken counts as
        unread): the rest is discarded and ``-410,"Query INTERRUPTED"`` queued (IEEE 488.2
        6.3.2.3), where the instrument has an error queue; else the reply still goes out."""
        push = getattr(self.handler, "push_error", None)
        if push is None:
            return
        self.on_log(self.name, "fault", f"query interrupted: {len(out)} unread reply bytes discarded")
        out.clear()
        with self.handler_lock():
            push(-410, "Query INTERRUPTED")

    def _send_trickle(self, conn: socket.socket, data: bytes) -> None:
        """One byte every ``_trickle_s`` until the reply is out, the client leaves or the lab stops."""
        conn.setblocking(True)
        try:
            for i in range(len(data)):
                if self._stop.wait(self._trickle_s):
                    return
                conn.sendall(data[i:i + 1])
        finally:
            conn.setblocking(False)

    def close(self) -> None:
        shut_down(self._stop, [self.sock], self._lock, self._conns, self._threads)


def accept_loop(sock: socket.socket, stop: threading.Event, lock: Any, conns: set[socket.socket],
                threads: list[threading.Thread], serve: Callable[[socket.socket], None], name: str) -> None:
    """Accept connections on ``sock`` until ``stop``; each is served by ``serve(conn)`` in its own thread."""
    try:
        sock.settimeout(0.05)
    except OSError:         # the lab was closed before this thread ran (EBADF): nothing to serve
        return
    while not stop.is_set():
        try:
            conn, _ = sock.accept()
        except TimeoutError:
            continue
        except OSError:
            return
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        with lock:
            conns.add(conn)
        t = threading.Thread(target=serve, args=(conn,), name=name, daemon=True)
        t.start()
        threads.append(t)


def shut_down(stop: threading.Event, listeners: list[socket.socket], lock: Any,
              conns: set[socket.socket], threads: list[threading.Thread]) -> None:
    """Stop a socket server: the stop flag, its listening sockets closed, its connections shut
    down (their threads see it at once), then every thread joined."""
    stop.set()
    for sock in listeners:
        try:
            sock.close()
        except OSError:
            pass
    with lock:
        open_conns = list(conns)
    for c in open_conns:
        try:
            c.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
    for t in threads:
        t.join(timeout=2)


class PtyServer(_Endpoint):
    """A line server on a pseudo-terminal: clients open :attr:`path` (pyserial).

    The slave end stays open here too, so a client closing the port does not
    hang up the master (reads would fail with EIO).
    """

    def __init__(self, handler: Handler, on_log: LogFn, seed: int = 0) -> None:
        super().__init__(handler, on_log, seed)
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no CR/LF translation before a client configures it
        self.path = os.ttyname(self.slave)
        self._thread: threading.Thread | None = None
        self._dead = False  # after a "drop" the line stays silent until the fault is cleared

    @property
    def resource(self) -> str:
        return f"ASRL{self.path}::INSTR"

    def start(self) -> None:
        self._thread = threading.Thread(target=self._serve, name=f"lab-{self.name}-pty", daemon=True)
        self._thread.start()

    def clear_faults(self) -> None:
        super().clear_faults()
        self._dead = False

    def _serve(self) -> None:
        framer = Framer()
        while not self._stop.is_set():
            try:
                r, _, _ = select.select([self.master], [], [], 0.05)
            except (OSError, ValueError):       # closed meanwhile (EBADF)
                return
            if not r:
                continue
            try:
                chunk = os.read(self.master, 4096)
            except OSError:
                return
            for line in self.lines(framer, chunk):
                if not self._answer(line):
                    return

    def _answer(self, line: str) -> bool:
        """Process one message and write its reply (trickled under that fault); False when the lab stops."""
        if self._dead:
            self.on_log(self.name, "rx", line)
            return True
        data, fault = self.process(line)
        if data and fault == "trickle":
            for i in range(len(data)):        # a controller whose line crawls
                if self._stop.wait(self._trickle_s):
                    return False
                self._write(data[i:i + 1])
        elif data:
            self._write(data)
        if fault == "drop":
            # a serial link cannot be "closed" from the far end: it goes quiet
            self._dead = True
        return True

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view and not self._stop.is_set():
            _, w, _ = select.select([], [self.master], [], 0.05)
            if w:
                n = os.write(self.master, view)
                view = view[n:]

    def close(self) -> None:
        self._stop.set()
        if self._thread:
            self._thread.join(timeout=2)
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass
