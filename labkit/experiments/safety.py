"""Safe shutdown: the drive guard, interlocks, and signal handling around a run.

The runner alone owns the outputs that drive the PZT or the shaker (the
function generator's). :class:`DriveGuard` turns them on and off and, when the
link to the generator is lost, opens a fresh connection to send ``OUTP OFF``
(a dropped socket must not leave a shaker running). :func:`shielded` holds
SIGINT/SIGTERM while the drive is being turned off, so a second Ctrl-C cannot
cut the shutdown short; :func:`sigterm_raises` makes SIGTERM raise
:class:`labkit.errors.Interrupted` (as ``labkit.cli`` does) for library use.
"""
from __future__ import annotations

import contextlib
import signal
import threading
import time
from typing import Any, Callable, Iterator

from labkit.errors import InstrumentError, Interrupted


class Interlock(Exception):
    """A safety limit tripped during a point: the drive goes off, the point is recorded, then skip or end."""

    def __init__(self, reason: str) -> None:
        self.reason = reason
        super().__init__(reason)


class DriveGuard:
    """The generator output(s) that drive the PZT or the shaker, with guaranteed shutdown.

    Parameters
    ----------
    funcgen:
        The open generator driver (``output(on)``, ``safe_off()``, ``close()``).
    reopen:
        Makes a new connection to the same generator (used when the link is lost).
    log:
        Called with a line of text for every on/off event (the run file's /events).
    """

    def __init__(self, funcgen: Any, reopen: Callable[[], Any] | None = None,
                 log: Callable[[str], None] | None = None) -> None:
        self.funcgen = funcgen
        self.reopen = reopen
        self.log = log or (lambda text: None)
        self.is_on = False          # what we last commanded (assume on after any failure)
        self.maybe_on = False       # True from the first ON until an OFF is confirmed

    def on(self) -> None:
        if self.is_on:
            return
        self.maybe_on = True
        self.funcgen.output(True)
        self.is_on = True
        self.log("drive on")

    def off(self, reason: str) -> None:
        """Turn the drive off (between points, on an interlock, before moving the spot)."""
        if not self.maybe_on:
            return
        try:
            self.funcgen.output(False)
        except InstrumentError:
            self.final_off(reason)      # reconnect and retry; raises if it cannot confirm
            return
        self.is_on = False
        self.maybe_on = False
        self.log(f"drive off ({reason})")

    def final_off(self, reason: str, attempts: int = 3) -> bool:
        """Every output of the generator off, whatever the state; reconnect if the link is lost.

        Returns True when an OFF was sent successfully. Raises the last
        InstrumentError when every attempt failed (the person must act).
        """
        last: InstrumentError | None = None
        for attempt in range(attempts):
            try:
                self.funcgen.safe_off()
                self.is_on = self.maybe_on = False
                self.log(f"drive off ({reason})" + (f" after {attempt} reconnect(s)" if attempt else ""))
                return True
            except InstrumentError as exc:
                last = exc
                if self.reopen is None:
                    break
                try:
                    self.funcgen.close()
                except Exception:
                    pass
                time.sleep(0.05 * (attempt + 1))
                try:
                    self.funcgen = self.reopen()
                except InstrumentError as exc2:
                    last = exc2
        self.log(f"DRIVE OFF NOT CONFIRMED ({reason}): {last}; turn the generator output off by hand")
        assert last is not None
        raise last


_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def shielded() -> Iterator[list[int]]:
    """Hold SIGINT and SIGTERM while the block runs (shutdown must not be cut short).

    Yields the list of signals that arrived meanwhile; they are not re-raised
    (the caller is shutting down already and reports them).
    """
    if threading.current_thread() is not threading.main_thread():
        yield []
        return
    arrived: list[int] = []

    def hold(signum: int, frame: Any) -> None:
        arrived.append(signum)

    previous = {s: signal.signal(s, hold) for s in _SIGNALS}
    try:
        yield arrived
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Hold SIGINT/SIGTERM during the block (a point's rows being written), then act on them.

    A signal that arrived meanwhile is raised right after the block, as
    KeyboardInterrupt (SIGINT) or Interrupted (SIGTERM), so a point's datasets
    are never left at different lengths by an interrupt.
    """
    with shielded() as arrived:
        yield
    if arrived:
        if arrived[0] == signal.SIGINT:
            raise KeyboardInterrupt
        raise Interrupted("SIGTERM")


def _raise_interrupted(signum: int, frame: Any) -> None:
    raise Interrupted("SIGTERM")


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """Make SIGTERM raise :class:`Interrupted` inside the block (then restore the old handler)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_interrupted)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
