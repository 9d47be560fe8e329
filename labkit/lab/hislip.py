"""HiSLIP for the simulated instruments: ``TCPIP0::<host>::hislip0,<port>::INSTR``.

HiSLIP (IVI-6.1, High-Speed LAN Instrument Protocol) is what newer Keysight and Rigol
instruments offer beside VXI-11. A client opens two TCP connections to one port: the
synchronous channel (``Initialize``, answered by ``InitializeResponse`` with a session id;
then ``Data``/``DataEnd`` messages both ways, ``Trigger``, ``DeviceClearComplete``) and the
asynchronous channel (``AsyncInitialize`` with that session id; ``AsyncMaxMsgSize``,
``AsyncLock``, ``AsyncLockInfo``, ``AsyncStatusQuery``, ``AsyncDeviceClear``,
``AsyncRemoteLocalControl``). Every message starts with the 16-byte header
``"HS", type, control code, parameter (u32), payload length (u64)``, big-endian.

Served here in synchronized mode (overlap 0): a program message is run when its ``DataEnd``
arrives; its reply goes back as ``DataEnd`` (preceded by ``Data`` messages when longer than the
client's maximum message size) carrying the message id of the ``DataEnd`` it answers, which is
how the client discards a reply it no longer waits for. The port is an ephemeral one on
127.0.0.1 (4880, HiSLIP's own, is named in the resource after the comma), so no root is needed.
"""
from __future__ import annotations

import itertools
import socket
import struct
import threading
from dataclasses import dataclass, field
from typing import Any

from labkit.lab.transport import Framer, accept_loop, shut_down

HEADER = struct.Struct("!2sBBIQ")
#: IVI-6.1 message types
INITIALIZE, INITIALIZE_RESPONSE, FATAL_ERROR, ERROR = 0, 1, 2, 3
ASYNC_LOCK, ASYNC_LOCK_RESPONSE, DATA, DATA_END = 4, 5, 6, 7
DEVICE_CLEAR_COMPLETE, DEVICE_CLEAR_ACK, ASYNC_REMOTE_LOCAL, ASYNC_REMOTE_LOCAL_RESPONSE = 8, 9, 10, 11
TRIGGER = 12
ASYNC_MAX_MSG_SIZE, ASYNC_MAX_MSG_SIZE_RESPONSE, ASYNC_INITIALIZE, ASYNC_INITIALIZE_RESPONSE = 15, 16, 17, 18
ASYNC_DEVICE_CLEAR, ASYNC_STATUS_QUERY, ASYNC_STATUS_RESPONSE, ASYNC_DEVICE_CLEAR_ACK = 19, 21, 22, 23
ASYNC_LOCK_INFO, ASYNC_LOCK_INFO_RESPONSE = 24, 25
#: Error control codes: unrecognized message type; FatalError: invalid initialization sequence
UNRECOGNIZED, INVALID_INIT, POORLY_FORMED = 1, 3, 1
VERSION = 0x0100                       # protocol 1.0
#: the largest message accepted or sent (the client may ask for less)
MAX_MESSAGE_BYTES = 1 << 24
#: the id of a session's first message (IVI-6.1: 0xffffff00, then up by 2)
FIRST_MESSAGE_ID = 0xFFFFFF00


@dataclass
class Session:
    """One client: its id, the largest message it accepts (``AsyncMaxMsgSize``) and the id of the
    last message the synchronous channel has run (an ``AsyncStatusQuery`` waits for its turn)."""

    session_id: int
    max_message: int = 1 << 20
    done_id: int = FIRST_MESSAGE_ID - 2
    done: threading.Condition = field(default_factory=threading.Condition)

    def ran(self, message_id: int) -> None:
        with self.done:
            self.done_id = message_id
            self.done.notify_all()

    def wait_for(self, next_id: int, timeout_s: float = 1.0) -> None:
        """Until the message before ``next_id`` (ids go up by 2) has run, or ``timeout_s``."""
        with self.done:
            self.done.wait_for(lambda: self.done_id == (next_id - 2) & 0xFFFFFFFF, timeout_s)


def send(conn: socket.socket, kind: int, control: int = 0, param: int = 0, payload: bytes = b"") -> None:
    conn.sendall(HEADER.pack(b"HS", kind, control, param & 0xFFFFFFFF, len(payload)) + payload)


def _recv_exact(conn: socket.socket, n: int, stop: threading.Event) -> bytes:
    out = bytearray()
    while len(out) < n:
        try:
            chunk = conn.recv(min(n - len(out), 1 << 20))
        except TimeoutError:
            if stop.is_set():
                raise ConnectionError("server stopped") from None
            continue
        if not chunk:
            raise ConnectionError("closed by the client")
        out += chunk
    return bytes(out)


def receive(conn: socket.socket, stop: threading.Event) -> tuple[int, int, int, bytes]:
    """(type, control code, parameter, payload) of the next message."""
    prologue, kind, control, param, length = HEADER.unpack(_recv_exact(conn, HEADER.size, stop))
    if prologue != b"HS" or length > MAX_MESSAGE_BYTES:
        send(conn, FATAL_ERROR, POORLY_FORMED)
        raise ConnectionError("not a HiSLIP message")
    return kind, control, param, _recv_exact(conn, length, stop)


class HislipServer:
    """Serves one simulated instrument's endpoint (:class:`labkit.lab.transport._Endpoint`: its
    ``process``, ``lines``, log and faults) over HiSLIP on ``host`` (an ephemeral port)."""

    def __init__(self, endpoint: Any, host: str = "127.0.0.1") -> None:
        self.endpoint = endpoint
        self.sock = socket.create_server((host, 0))
        self.host, self.port = self.sock.getsockname()[:2]
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._conns: set[socket.socket] = set()
        self._threads: list[threading.Thread] = []
        self._sessions: dict[int, Session] = {}
        self._ids = itertools.count(1)
        self._holder: int | None = None        # the session holding the exclusive lock

    @property
    def resource(self) -> str:
        return f"TCPIP0::{self.host}::hislip0,{self.port}::INSTR"

    def start(self) -> None:
        t = threading.Thread(target=accept_loop, args=(self.sock, self._stop, self._lock, self._conns,
                                                       self._threads, self._serve,
                                                       f"lab-hislip-{self.endpoint.name}"),
                             daemon=True, name=f"lab-hislip-{self.endpoint.name}-accept")
        t.start()
        self._threads.append(t)

    def close(self) -> None:
        shut_down(self._stop, [self.sock], self._lock, self._conns, self._threads)

    def _serve(self, conn: socket.socket) -> None:
        conn.settimeout(0.05)
        try:
            kind, _, param, _ = receive(conn, self._stop)
            if kind == INITIALIZE:
                session = Session(next(self._ids) & 0xFFFF)
                with self._lock:
                    self._sessions[session.session_id] = session
                send(conn, INITIALIZE_RESPONSE, 0, (VERSION << 16) | session.session_id)
                self._synchronous(conn, session)
            elif kind == ASYNC_INITIALIZE and param in self._sessions:
                send(conn, ASYNC_INITIALIZE_RESPONSE, 0, int.from_bytes(b"LK\0\0", "big"))
                self._asynchronous(conn, self._sessions[param])
            else:
                send(conn, FATAL_ERROR, INVALID_INIT)
        except (ConnectionError, OSError):
            return
        finally:
            with self._lock:
                self._conns.discard(conn)
            conn.close()

    def _synchronous(self, conn: socket.socket, session: Session) -> None:
        """Data/DataEnd in, each message's reply out as DataEnd with the message's id."""
        framer = Framer()
        while not self._stop.is_set():
            kind, control, param, payload = receive(conn, self._stop)
            if kind in (DATA, DATA_END):
                end = b"\n" if kind == DATA_END and not payload.endswith(b"\n") else b""
                for line in self.endpoint.lines(framer, payload + end):
                    reply, fault = self.endpoint.process(line)
                    if reply and fault != "stall":
                        self._reply(conn, session, param, reply)
                session.ran(param)
            elif kind == TRIGGER:
                self.endpoint.process("*TRG")
                session.ran(param)
            elif kind == DEVICE_CLEAR_COMPLETE:
                framer = Framer()
                send(conn, DEVICE_CLEAR_ACK, control)
            else:
                send(conn, ERROR, UNRECOGNIZED)

    @staticmethod
    def _reply(conn: socket.socket, session: Session, message_id: int, reply: bytes) -> None:
        """The reply in messages of at most the client's maximum size, the last one DataEnd."""
        room = max(1, session.max_message - HEADER.size)
        for at in range(0, len(reply), room):
            last = at + room >= len(reply)
            send(conn, DATA_END if last else DATA, 0, message_id, reply[at:at + room])

    def _asynchronous(self, conn: socket.socket, session: Session) -> None:
        while not self._stop.is_set():
            kind, control, param, payload = receive(conn, self._stop)
            if kind == ASYNC_MAX_MSG_SIZE and len(payload) == 8:
                session.max_message = max(HEADER.size + 1, min(struct.unpack("!Q", payload)[0], MAX_MESSAGE_BYTES))
                send(conn, ASYNC_MAX_MSG_SIZE_RESPONSE, 0, 0, struct.pack("!Q", session.max_message))
            elif kind == ASYNC_LOCK:
                send(conn, ASYNC_LOCK_RESPONSE, self._lock_request(session, control == 1))
            elif kind == ASYNC_LOCK_INFO:
                held = self._holder is not None
                send(conn, ASYNC_LOCK_INFO_RESPONSE, int(held), int(held))
            elif kind == ASYNC_STATUS_QUERY:
                session.wait_for(param)       # the status after the messages sent before the query
                send(conn, ASYNC_STATUS_RESPONSE, self._status_byte())
            elif kind == ASYNC_DEVICE_CLEAR:
                send(conn, ASYNC_DEVICE_CLEAR_ACK, 0)
            elif kind == ASYNC_REMOTE_LOCAL:
                send(conn, ASYNC_REMOTE_LOCAL_RESPONSE)
            else:
                send(conn, ERROR, UNRECOGNIZED)

    def _lock_request(self, session: Session, request: bool) -> int:
        """An exclusive lock: granted (1) when free or already this session's, else failure (0);
        released (1) by its holder, else error (3)."""
        with self._lock:
            if request:
                if self._holder in (None, session.session_id):
                    self._holder = session.session_id
                    return 1
                return 0
            if self._holder == session.session_id:
                self._holder = None
                return 1
            return 3

    def _status_byte(self) -> int:
        """The instrument's status byte (``*STB?`` without the message exchange), 0 if it has none."""
        stb = getattr(self.endpoint.handler, "status_byte", None)
        try:
            return int(stb()) & 0xFF if callable(stb) else 0
        except Exception:   # a status the simulator cannot give is no reason to drop the link
            return 0
