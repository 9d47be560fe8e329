"""Expected-protocol testing: a driver against a scripted peer over a real link.

:func:`expected_protocol` opens a driver class on a REAL loopback TCP socket
(or, for serial drivers, a pseudo-terminal), with a peer thread on the other
end that asserts every byte it receives against a script and sends the
scripted replies. Any unexpected, wrong or missing exchange fails the test
with an AssertionError that shows the transcript.

Examples
--------
>>> from labkit.drivers.funcgen import Agilent33220A
>>> with expected_protocol(Agilent33220A, [(b"OUTP OFF\\n", None), (b"*OPC?\\n", b"1\\n")],
...                        identity="Agilent Technologies,33220A,MY1,2.0") as fg:
...     fg.safe_off()              # after the handshake on open (connect_exchanges)
...     fg.identity
'Agilent Technologies,33220A,MY1,2.0'

Reply values
------------
``bytes``
    sent as is (may be garbage, a truncated block...).
``None`` / :data:`STALL`
    nothing is sent: a query then times out (``STALL`` reads better in tests
    that exercise a stalled instrument).
``Drop(partial=b"...")``
    send ``partial`` and close the connection (pty: close the master): a link
    that dies mid-transfer. Exchanges listed after a Drop count as missing.
"""
from __future__ import annotations

import os
import select
import socket
import threading
import time
import tty
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from labkit.drivers.base import Instrument

STALL = None  # no reply: the driver's read must time out


@dataclass(frozen=True)
class Drop:
    """Send ``partial`` then close the link."""

    partial: bytes = b""


Exchange = tuple[bytes | None, Any]

#: How long the peer waits for bytes the script expects before calling them missing.
PEER_WAIT_S = 10.0


class _Peer(threading.Thread):
    """Runs the script on one end of a link; collects failures for the test thread."""

    #: The VISA resource (or serial port) a driver opens to reach this peer.
    resource: str

    def __init__(self, exchanges: Sequence[Exchange]) -> None:
        super().__init__(daemon=True, name="expected-protocol-peer")
        self.exchanges = list(exchanges)
        self.failures: list[str] = []
        self.transcript: list[str] = []
        self.driver_closed = threading.Event()
        self.received = bytearray()       # every byte the driver sent
        self._buf = bytearray()

    # link primitives, by subclass -------------------------------------------------------------
    def _recv_some(self, timeout: float) -> bytes | None:
        """Bytes available within ``timeout``; b"" when nothing yet; None on EOF."""
        raise NotImplementedError

    def _send(self, data: bytes) -> None:
        raise NotImplementedError

    def _close_link(self) -> None:
        raise NotImplementedError

    def _connect(self) -> bool:
        return True

    # ------------------------------------------------------------------------------------------
    def _fill(self, n: int | None) -> None:
        """Receive into the buffer until it holds ``n`` bytes (None: until the driver goes quiet)."""
        deadline = time.monotonic() + PEER_WAIT_S
        while (n is None or len(self._buf) < n) and time.monotonic() < deadline:
            chunk = self._recv_some(0.05)
            if chunk is None:
                break
            if not chunk and self.driver_closed.is_set():
                # the driver is gone: take what is left, then stop
                chunk = self._recv_some(0.0)
                if not chunk:
                    break
            self._buf += chunk
            self.received += chunk

    def _read_exact(self, n: int) -> bytes:
        self._fill(n)
        out, self._buf = bytes(self._buf[:n]), self._buf[n:]
        return out

    def run(self) -> None:
        try:
            if not self._connect():
                self.failures.append("the driver never connected")
                return
            self._script()
        except Exception as exc:  # a peer crash must fail the test, not vanish
            self.failures.append(f"peer error: {exc!r}")
        finally:
            try:
                self._close_link()
            except OSError:
                pass

    def _script(self) -> None:
        for i, (expected, reply) in enumerate(self.exchanges):
            if expected:
                got = self._read_exact(len(expected))
                self.transcript.append(f"driver -> {got!r}")
                if got != expected:
                    what = "missing" if not got else "wrong bytes"
                    self.failures.append(f"exchange {i}: {what}: expected {expected!r}, "
                                         f"received {got!r}")
                    return
            if isinstance(reply, Drop):
                if reply.partial:
                    self._send(reply.partial)
                self.transcript.append(f"peer   -> {reply.partial!r} then DROP")
                rest = [e for e, _ in self.exchanges[i + 1:] if e]
                if rest:
                    self.failures.append(f"exchanges after the drop never happen: {rest!r}")
                return
            if reply:
                self._send(reply)
                self.transcript.append(f"peer   -> {reply[:60]!r}"
                                       + (f"... ({len(reply)} bytes)" if len(reply) > 60 else ""))
        # Script done: anything more the driver sends is unexpected.
        self._fill(None)
        extra, self._buf = bytes(self._buf), bytearray()
        if extra:
            self.transcript.append(f"driver -> {bytes(extra)!r}")
            self.failures.append(f"unexpected bytes after the script: {bytes(extra)!r}")


class _SocketPeer(_Peer):
    def __init__(self, exchanges: Sequence[Exchange]) -> None:
        super().__init__(exchanges)
        self._lsock = socket.create_server(("127.0.0.1", 0))
        self._lsock.settimeout(PEER_WAIT_S)
        self.port = self._lsock.getsockname()[1]
        self.resource = f"TCPIP0::127.0.0.1::{self.port}::SOCKET"
        self._conn: socket.socket | None = None

    def _connect(self) -> bool:
        deadline = time.monotonic() + PEER_WAIT_S
        try:
            while time.monotonic() < deadline and not self.driver_closed.is_set():
                r, _, _ = select.select([self._lsock], [], [], 0.05)
                if r:
                    self._conn, _ = self._lsock.accept()
                    break
            else:
                return False
        except OSError:
            return False
        finally:
            self._lsock.close()
        self._conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return True

    def _recv_some(self, timeout: float) -> bytes | None:
        conn = self._conn
        assert conn is not None, "called after _connect() succeeded"
        r, _, _ = select.select([conn], [], [], timeout)
        if not r:
            return b""
        try:
            data = conn.recv(65536)
        except OSError:
            return None
        return data or None

    def _send(self, data: bytes) -> None:
        assert self._conn is not None, "called after _connect() succeeded"
        self._conn.sendall(data)

    def _close_link(self) -> None:
        if self._conn is not None:
            self._conn.close()
        self._lsock.close()


class _PtyPeer(_Peer):
    def __init__(self, exchanges: Sequence[Exchange]) -> None:
        super().__init__(exchanges)
        self.master, slave = os.openpty()
        self.slave: int | None = slave
        tty.setraw(slave)      # no echo, no CR/LF translation: bytes pass untouched
        self.port = os.ttyname(slave)
        self.resource = self.port
        self._closed = False

    def release_slave(self) -> None:
        """Close our own slave fd once the driver holds the port."""
        if self.slave is not None:
            os.close(self.slave)
            self.slave = None

    def _recv_some(self, timeout: float) -> bytes | None:
        r, _, _ = select.select([self.master], [], [], timeout)
        if not r:
            return b""
        try:
            data = os.read(self.master, 65536)
        except OSError:          # EIO: every slave fd is closed
            return None
        return data or None

    def _send(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self.master, view)
            view = view[n:]

    def _close_link(self) -> None:
        if not self._closed:
            self._closed = True
            os.close(self.master)


#: The identity each family's scripted peer answers by default (a model of the family).
IDENTITIES = {
    "33220A": "Agilent Technologies,33220A,MY44012345,2.07-2.06-22-2",
    "33500B": "Keysight Technologies,33522B,MY52400000,4.03-1.19-2.00-52-00",
    "DG1000Z": "Rigol Technologies,DG1062Z,DG1ZA000000001,00.01.14",
    "InfiniiVision": "KEYSIGHT TECHNOLOGIES,DSOX3024T,MY58420000,07.50.2021102830",
    "DS1000Z": "RIGOL TECHNOLOGIES,DS1104Z,DS1ZA000000001,00.04.04.SP3",
}


def connect_exchanges(driver_cls: type[Instrument], identity: str | None = None,
                      errors: Sequence[str] = ()) -> list[Exchange]:
    """The handshake :meth:`ScpiInstrument.connect` sends on open, as script exchanges.

    ``*IDN?`` (answered with ``identity``, default :data:`IDENTITIES` of the
    family), the error query answered with each of ``errors`` and then the
    empty queue (``0,"No error"`` in the family's spelling), ``*CLS``. Empty
    for drivers without the handshake.
    """
    if not getattr(driver_cls, "connect_on_open", False):
        return []
    idn = identity if identity is not None else IDENTITIES[driver_cls.model]
    err = getattr(driver_cls, "err_command", "SYST:ERR?").encode() + b"\n"
    empty = b'0,"No error"\n' if idn.upper().startswith("RIGOL") else b'+0,"No error"\n'
    out: list[Exchange] = [(b"*IDN?\n", idn.encode() + b"\n")]
    out += [(err, e.encode() + b"\n") for e in errors]
    out.append((err, empty))
    out.append((b"*CLS\n", None))
    return out


def _report(peer: _Peer) -> str:
    return ("; ".join(peer.failures) + "\ntranscript:\n  " + "\n  ".join(peer.transcript))


@contextmanager
def expected_protocol(driver_cls: type[Instrument], exchanges: Sequence[Exchange], *, timeout_s: float = 0.3,
                      link: str | None = None, resource_format: str = "{}",
                      identity: str | None = None, errors_at_connect: Sequence[str] = (),
                      handshake: bool = True, **settings: Any) -> Iterator[Any]:
    """Yield ``driver_cls`` opened on a scripted peer that asserts every byte.

    Parameters
    ----------
    driver_cls:
        A :class:`labkit.drivers.base.Instrument` subclass.
    exchanges:
        ``[(bytes the driver must send, reply), ...]`` in order; see the module
        docstring for reply values. An empty list asserts that nothing is sent
        after the handshake.
    identity, errors_at_connect, handshake:
        For drivers that shake hands on open (the SCPI generators and scopes),
        :func:`connect_exchanges` of ``identity`` and ``errors_at_connect`` is
        put before ``exchanges``; ``handshake=False``: the script gives it.
    timeout_s:
        The driver's timeout (short, so stall tests stay fast).
    link:
        ``"socket"`` or ``"serial"``; default ``driver_cls.link``.
    resource_format:
        Format for the resource string, e.g. ``"ASRL{}::INSTR"`` to open a pty
        through the VISA-style serial name.
    **settings:
        Passed to ``driver_cls.open``.

    Raises
    ------
    AssertionError
        On any unexpected, wrong or missing exchange (with the transcript),
        also when the test body raised.
    """
    link = link or getattr(driver_cls, "link", "socket")
    if handshake:
        exchanges = connect_exchanges(driver_cls, identity, errors_at_connect) + list(exchanges)
    peer: _Peer = _PtyPeer(exchanges) if link == "serial" else _SocketPeer(exchanges)
    peer.start()
    driver = None
    try:
        driver = driver_cls.open(resource_format.format(peer.resource), timeout_s=timeout_s,
                                 **settings)
        if isinstance(peer, _PtyPeer):
            peer.release_slave()
        yield driver
    except BaseException as exc:
        _finish(peer, driver)
        if peer.failures:
            raise AssertionError(_report(peer)) from exc
        raise
    else:
        _finish(peer, driver)
        if peer.failures:
            raise AssertionError(_report(peer))
    finally:
        if isinstance(peer, _PtyPeer):
            peer.release_slave()


def _finish(peer: _Peer, driver: Any) -> None:
    if driver is not None:
        driver.close()
    peer.driver_closed.set()
    if isinstance(peer, _PtyPeer):
        peer.release_slave()
    peer.join(PEER_WAIT_S + 2)
    if peer.is_alive():
        peer.failures.append("peer did not finish")
