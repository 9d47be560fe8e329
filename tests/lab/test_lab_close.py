"""A lab closed at once after it starts leaves no thread traceback (its accept thread met EBADF)."""
from __future__ import annotations

import threading

from labkit.lab.scpi import SimScpiInstrument
from labkit.lab.transport import TcpServer


def test_servers_closed_before_their_threads_run_end_quietly():
    seen: list[BaseException | None] = []
    old = threading.excepthook
    threading.excepthook = lambda args: seen.append(args.exc_value)
    try:
        for _ in range(50):
            srv = TcpServer(SimScpiInstrument(), lambda *log: None)
            srv.start()
            srv.close()              # often before the accept thread's first line
    finally:
        threading.excepthook = old
    assert seen == []
