"""VXI-11 for the simulated instruments: an ONC-RPC portmapper and a VXI-11 core channel.

``TCPIP0::<host>::inst0::INSTR`` is the resource form most VISA users write and the only
one some clients speak (the ``ds1054z`` package, python-ivi). A VXI-11 client first asks the
host's portmapper (ONC RPC program 100000 version 2, TCP port 111, RFC 1833 "PMAPPROC_GETPORT")
for the port of the VXI-11 core channel (program 0x0607AF, version 1), then calls its procedures
(VXI-11 specification, B.6: create_link, device_write, device_read, device_readstb,
device_trigger, device_clear, device_remote, device_local, device_lock, device_unlock,
destroy_link). Messages are ONC RPC (RFC 5531) in XDR (RFC 4506), over TCP record marking.

Each instrument gets its own loopback address (``127.x.y.z``, all of 127/8 is loopback on Linux),
so that its portmapper can own port 111 there: clients find the port of port 111's answer. Port
111 is privileged: the lab must run as root (it does in this project's tests and CI), else
:class:`Vxi11Server` raises PermissionError and the lab serves raw sockets only.

Semantics kept from the specification: a message is executed when the write carrying the END
flag arrives; its reply waits in the link's output buffer; ``device_read`` returns at most
``requestSize`` bytes with reason END when the reply is exhausted; a read with nothing to read
waits ``io_timeout`` and answers error 15 (I/O timeout); a new message executed while a reply is
unread discards it and queues ``-410,"Query INTERRUPTED"`` (IEEE 488.2 6.3.2.3).
"""
from __future__ import annotations

import random
import socket
import struct
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from labkit.lab.transport import Framer, accept_loop, shut_down

PMAP_PROG, PMAP_VERS, PMAP_GETPORT = 100000, 2, 3
CORE_PROG, CORE_VERS = 0x0607AF, 1
IPPROTO_TCP = 6
#: VXI-11 B.6 procedure numbers
CREATE_LINK, DEVICE_WRITE, DEVICE_READ, DEVICE_READSTB = 10, 11, 12, 13
DEVICE_TRIGGER, DEVICE_CLEAR, DEVICE_REMOTE, DEVICE_LOCAL = 14, 15, 16, 17
DEVICE_LOCK, DEVICE_UNLOCK, DEVICE_ENABLE_SRQ, DEVICE_DOCMD = 18, 19, 20, 22
DESTROY_LINK, CREATE_INTR_CHAN, DESTROY_INTR_CHAN = 23, 25, 26
#: Device_ErrorCode
NO_ERROR, INVALID_LINK, NOT_SUPPORTED, IO_TIMEOUT = 0, 4, 8, 15
#: Device_Flags and read reasons
FLAG_END, FLAG_TERMCHR = 8, 128
REASON_REQCNT, REASON_CHR, REASON_END = 1, 2, 4
MAX_RECV = 1 << 20
MAX_RECORD = 64 << 20


class Xdr:
    """XDR reading (RFC 4506): unsigned/signed ints and variable-length opaque data."""

    def __init__(self, data: bytes) -> None:
        self.data, self.pos = data, 0

    def u32(self) -> int:
        if self.pos + 4 > len(self.data):
            raise ValueError("XDR: message too short")
        (v,) = struct.unpack_from(">I", self.data, self.pos)
        self.pos += 4
        return int(v)

    def opaque(self) -> bytes:
        n = self.u32()
        if self.pos + n > len(self.data):
            raise ValueError("XDR: opaque beyond the message")
        out = self.data[self.pos:self.pos + n]
        self.pos += n + (-n % 4)
        return out


def u32(*values: int) -> bytes:
    return b"".join(struct.pack(">I", v & 0xFFFFFFFF) for v in values)


def opaque(data: bytes) -> bytes:
    return u32(len(data)) + data + b"\0" * (-len(data) % 4)


def _recv_exact(conn: socket.socket, n: int) -> bytes:
    buf = bytearray()
    while len(buf) < n:
        chunk = conn.recv(n - len(buf))
        if not chunk:
            raise ConnectionError("closed")
        buf += chunk
    return bytes(buf)


def recv_record(conn: socket.socket) -> bytes:
    """One RPC message: record-marking fragments (RFC 5531 11) up to the last one."""
    out = bytearray()
    while True:
        (mark,) = struct.unpack(">I", _recv_exact(conn, 4))
        size = mark & 0x7FFFFFFF
        if len(out) + size > MAX_RECORD:
            raise ConnectionError("record too long")
        out += _recv_exact(conn, size)
        if mark & 0x80000000:
            return bytes(out)


def send_record(conn: socket.socket, data: bytes) -> None:
    conn.sendall(u32(0x80000000 | len(data)) + data)


Handler = Callable[[int, Xdr], bytes | None]


def serve_rpc(conn: socket.socket, prog: int, vers: int, handler: Handler, stop: threading.Event) -> None:
    """Answer ONC RPC calls on ``conn`` until it closes: ``handler(proc, args)`` gives the results
    (None: no such procedure, PROC_UNAVAIL)."""
    conn.settimeout(None)
    while not stop.is_set():
        try:
            msg = Xdr(recv_record(conn))
            xid, mtype = msg.u32(), msg.u32()
            rpcvers, p, v, proc = msg.u32(), msg.u32(), msg.u32(), msg.u32()
            msg.u32(), msg.opaque(), msg.u32(), msg.opaque()        # credentials, verifier
        except (ConnectionError, OSError, ValueError, struct.error):
            return
        head = u32(xid, 1, 0, 0, 0)                                 # REPLY, MSG_ACCEPTED, AUTH_NONE
        if mtype != 0 or rpcvers != 2:
            body = u32(xid, 1, 1, 0, 2, 2)                          # MSG_DENIED, RPC_MISMATCH 2..2
            head, result = body, b""
        elif p != prog:
            result = u32(1)                                          # PROG_UNAVAIL
        elif v != vers:
            result = u32(2, vers, vers)                              # PROG_MISMATCH
        else:
            try:
                out = handler(proc, msg)
            except (ValueError, struct.error):
                out, result = None, u32(4)                           # GARBAGE_ARGS
            else:
                result = u32(3) if out is None else u32(0) + out     # PROC_UNAVAIL or SUCCESS
        try:
            send_record(conn, head + result)
        except OSError:
            return


@dataclass
class Link:
    """A VXI-11 link: the message being written, the reply waiting to be read."""

    lid: int
    incoming: bytearray = field(default_factory=bytearray)
    reply: bytearray = field(default_factory=bytearray)


class Vxi11Server:
    """One instrument over VXI-11 on its own loopback address (portmapper on 111, core channel).

    ``endpoint`` is the instrument's :class:`labkit.lab.transport._Endpoint` (its ``process``
    runs a message with logging and faults); the endpoint's handler keeps its own lock.
    """

    def __init__(self, endpoint: Any, host: str | None = None) -> None:
        self.endpoint = endpoint
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._conns: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._links: dict[int, Link] = {}
        self._next_lid = 1
        self.host, self.pmap = self._bind_portmapper(host)
        self.core = socket.create_server((self.host, 0))
        self.core_port = self.core.getsockname()[1]

    @staticmethod
    def _bind_portmapper(host: str | None) -> tuple[str, socket.socket]:
        """Port 111 on ``host``, or on a free random ``127.x.y.z`` (PermissionError when not root)."""
        rng = random.Random()
        for _ in range(50):
            addr = host or f"127.{rng.randint(64, 254)}.{rng.randint(0, 255)}.{rng.randint(1, 254)}"
            try:
                return addr, socket.create_server((addr, 111))
            except PermissionError:
                raise
            except OSError:
                if host:
                    raise
        raise OSError("no free loopback address for a VXI-11 portmapper")

    @property
    def resource(self) -> str:
        return f"TCPIP0::{self.host}::inst0::INSTR"

    def start(self) -> None:
        for sock, prog, vers, handler in ((self.pmap, PMAP_PROG, PMAP_VERS, self._portmapper),
                                          (self.core, CORE_PROG, CORE_VERS, self._core)):
            t = threading.Thread(target=self._accept, args=(sock, prog, vers, handler), daemon=True,
                                 name=f"lab-vxi11-{self.endpoint.name}")
            t.start()
            self._threads.append(t)

    def _accept(self, sock: socket.socket, prog: int, vers: int, handler: Handler) -> None:
        accept_loop(sock, self._stop, self._lock, self._conns, self._threads,
                    lambda conn: self._serve(conn, prog, vers, handler), f"lab-vxi11-{self.endpoint.name}-conn")

    def _serve(self, conn: socket.socket, prog: int, vers: int, handler: Handler) -> None:
        try:
            serve_rpc(conn, prog, vers, handler, self._stop)
        finally:
            with self._lock:
                self._conns.discard(conn)
            conn.close()

    # -- the portmapper ---------------------------------------------------------------------
    def _portmapper(self, proc: int, args: Xdr) -> bytes | None:
        if proc == 0:
            return b""
        if proc == PMAP_GETPORT:
            prog, vers, prot = args.u32(), args.u32(), args.u32()
            ok = (prog, vers, prot) == (CORE_PROG, CORE_VERS, IPPROTO_TCP)
            return u32(self.core_port if ok else 0)
        return None

    # -- the core channel ---------------------------------------------------------------------
    def _link(self, lid: int) -> Link | None:
        with self._lock:
            return self._links.get(lid)

    def _core(self, proc: int, args: Xdr) -> bytes | None:
        if proc == 0:
            return b""
        if proc == CREATE_LINK:
            args.u32(), args.u32(), args.u32(), args.opaque()       # client id, lock, timeout, device
            with self._lock:
                lid, self._next_lid = self._next_lid, self._next_lid + 1
                self._links[lid] = Link(lid)
            return u32(NO_ERROR, lid, 0, MAX_RECV)
        if proc == DEVICE_WRITE:
            return self._write(args)
        if proc == DEVICE_READ:
            return self._read(args)
        lid = args.u32()
        link = self._link(lid)
        if proc == DESTROY_LINK:
            with self._lock:
                self._links.pop(lid, None)
            return u32(NO_ERROR if link else INVALID_LINK)
        if link is None:
            return u32(INVALID_LINK, 0) if proc == DEVICE_READSTB else u32(INVALID_LINK)
        if proc == DEVICE_READSTB:
            return u32(NO_ERROR, self._status_byte())
        if proc == DEVICE_CLEAR:        # 488.2 device clear: input and output buffers emptied
            link.incoming.clear()
            link.reply.clear()
            return u32(NO_ERROR)
        if proc == DEVICE_TRIGGER:
            self._run(link, "*TRG")
            return u32(NO_ERROR)
        if proc in (DEVICE_REMOTE, DEVICE_LOCAL, DEVICE_LOCK, DEVICE_UNLOCK, DEVICE_ENABLE_SRQ,
                    CREATE_INTR_CHAN, DESTROY_INTR_CHAN):
            return u32(NO_ERROR)
        if proc == DEVICE_DOCMD:
            return u32(NOT_SUPPORTED, 0)
        return None

    def _status_byte(self) -> int:
        stb = getattr(self.endpoint.handler, "status_byte", None)
        if stb is None:
            return 0
        with self.endpoint.handler_lock():
            return int(stb())

    def _write(self, args: Xdr) -> bytes:
        lid, _io, _lock, flags, data = args.u32(), args.u32(), args.u32(), args.u32(), args.opaque()
        link = self._link(lid)
        if link is None:
            return u32(INVALID_LINK, 0)
        link.incoming += data
        if flags & FLAG_END:        # the message is complete: LF-separated units, blocks kept whole
            message = bytes(link.incoming)
            link.incoming.clear()
            for line in self.endpoint.lines(Framer(), message if message.endswith(b"\n") else message + b"\n"):
                self._run(link, line)
        return u32(NO_ERROR, len(data))

    def _run(self, link: Link, text: str) -> None:
        if link.reply:          # a reply nobody read: 488.2 6.3.2.3, the query is interrupted
            link.reply.clear()
            push = getattr(self.endpoint.handler, "push_error", None)
            if push is not None:
                with self.endpoint.handler_lock():
                    push(-410, "Query INTERRUPTED")
        data, fault = self.endpoint.process(text)
        if data and fault != "stall":
            link.reply += data

    def _read(self, args: Xdr) -> bytes:
        lid, size, io_ms, _lock, flags, term = (args.u32(), args.u32(), args.u32(), args.u32(),
                                                args.u32(), args.u32())
        link = self._link(lid)
        if link is None:
            return u32(INVALID_LINK, 0) + opaque(b"")
        if not link.reply:      # nothing to read: the client's io_timeout, then error 15
            self._stop.wait(min(io_ms, 60_000) / 1000.0)
            if not link.reply:
                return u32(IO_TIMEOUT, 0) + opaque(b"")
        chunk = bytes(link.reply[:max(1, size)])
        reason = 0
        if flags & FLAG_TERMCHR and (term & 0xFF) in chunk:
            chunk = chunk[:chunk.index(term & 0xFF) + 1]
            reason |= REASON_CHR
        del link.reply[:len(chunk)]
        if not link.reply:
            reason |= REASON_END
        elif not reason:
            reason = REASON_REQCNT
        return u32(NO_ERROR, reason) + opaque(chunk)

    def close(self) -> None:
        shut_down(self._stop, [self.pmap, self.core], self._lock, self._conns, self._threads)
