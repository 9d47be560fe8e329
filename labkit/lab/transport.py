"""Real transports for the simulated instruments: raw TCP sockets and pseudo-terminals.

Both carry ``\\n``-terminated lines to an object with ``handle(line) ->
bytes | None`` (a :class:`labkit.lab.scpi.SimScpiInstrument`, the vibrometer,
the control channel) and send its reply back with one ``sendall``/``write``
(a 2 MB waveform block leaves in one call). Every line in and every reply out
goes to ``on_log(instrument, "rx"|"tx", text)``.

Faults (:class:`Fault`) are applied to replies: ``drop`` sends half of the
reply and closes the connection (a pulled cable, mid-block for a waveform),
``stall`` swallows the reply (a hung instrument), ``garbage`` replaces it with
random bytes and a ``\\n``.
"""
from __future__ import annotations

import os
import select
import socket
import threading
import tty
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np


class Handler(Protocol):
    name: str

    def handle(self, line: str) -> bytes | None: ...


LogFn = Callable[[str, str, str], None]


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

    def __post_init__(self) -> None:
        if self.kind not in ("drop", "stall", "garbage"):
            raise ValueError(f"fault kind must be drop, stall or garbage, not {self.kind!r}")

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


class _Endpoint:
    """What the TCP and pty servers share: faults, logging, reply shaping."""

    def __init__(self, handler: Handler, on_log: LogFn, seed: int = 0) -> None:
        self.handler = handler
        self.on_log = on_log
        self.faults: list[Fault] = []
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._stop = threading.Event()

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
        if fault.kind == "garbage":
            junk = bytes(self._rng.integers(128, 256, size=max(8, min(len(reply), 64)), dtype=np.uint8)) + b"\n"
            self.on_log(self.name, "fault", f"garbage: {junk[:-1]!r} instead of the reply to {line!r}")
            return junk, "garbage"
        part = reply[: max(1, len(reply) // 2)]
        self.on_log(self.name, "fault", f"drop: connection closed after {len(part)} of {len(reply)} bytes")
        return part, "drop"


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
        try:
            self.sock.settimeout(0.05)
        except OSError:         # the lab was closed before this thread ran (EBADF): nothing to serve
            return
        while not self._stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._conns.add(conn)
            t = threading.Thread(target=self._serve, args=(conn,), name=f"lab-{self.name}-conn",
                                 daemon=True)
            t.start()
            self._threads.append(t)

    def _serve(self, conn: socket.socket) -> None:
        buf = b""
        conn.settimeout(0.05)
        try:
            while not self._stop.is_set():
                try:
                    chunk = conn.recv(65536)
                except TimeoutError:
                    continue
                if not chunk:
                    return
                buf += chunk
                while b"\n" in buf:
                    raw, buf = buf.split(b"\n", 1)
                    line = raw.rstrip(b"\r").decode("ascii", "replace")
                    if not line.strip():
                        continue
                    data, fault = self.process(line)
                    if data:
                        conn.settimeout(None)
                        conn.sendall(data)
                        conn.settimeout(0.05)
                    if fault == "drop":
                        conn.shutdown(socket.SHUT_RDWR)
                        return
        except OSError:
            return
        finally:
            with self._lock:
                self._conns.discard(conn)
            conn.close()

    def close(self) -> None:
        self._stop.set()
        try:
            self.sock.close()
        except OSError:
            pass
        with self._lock:
            conns = list(self._conns)
        for c in conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        for t in self._threads:
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
        buf = b""
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
            buf += chunk
            while b"\n" in buf:
                raw, buf = buf.split(b"\n", 1)
                line = raw.rstrip(b"\r").decode("ascii", "replace")
                if not line.strip():
                    continue
                if self._dead:
                    self.on_log(self.name, "rx", line)
                    continue
                data, fault = self.process(line)
                if data:
                    self._write(data)
                if fault == "drop":
                    # a serial link cannot be "closed" from the far end: it goes quiet
                    self._dead = True

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
