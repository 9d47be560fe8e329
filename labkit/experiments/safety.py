"""Safe shutdown: the drive guard, interlocks, and signal handling around a run.

The runner alone owns the outputs that drive the PZT or the shaker (the
function generator's). :class:`DriveGuard` turns them on and off and, when the
link to the generator is lost, opens a fresh connection to send ``OUTP OFF``
(a dropped socket must not leave a shaker running). :func:`shielded` holds
every stop signal (SIGINT, SIGTERM, SIGHUP, SIGQUIT) while the drive is being
turned off, so a second Ctrl-C cannot cut the shutdown short; :func:`signals_raise`
makes them raise (KeyboardInterrupt, or :class:`labkit.errors.Interrupted` naming
the signal), as ``labkit.cli`` does, for library use.
"""
from __future__ import annotations

import contextlib
import logging
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any, TypedDict

from labkit.errors import DriveNotOff, InstrumentError, Interrupted
from labkit.experiments.protocols import FunctionGenerator
from labkit.jsonutil import Json

#: the shutdown path's log (``labkit -v``: INFO, ``-vv``: DEBUG, on stderr)
_log = logging.getLogger(__name__)


class Interlock(Exception):
    """A safety limit tripped during a point: the drive goes off, the point is recorded, then skip or end."""

    def __init__(self, reason: str) -> None:
        self.reason = reason
        super().__init__(reason)


#: how long a lost generator link is retried before its OFF counts as not confirmed, s
RECONNECT_WINDOW_S = 2.0


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

    def __init__(self, funcgen: FunctionGenerator, reopen: Callable[[], FunctionGenerator] | None = None,
                 log: Callable[[str], None] | None = None, *, where: str = "", config: str = "") -> None:
        self.funcgen = funcgen
        self.reopen = reopen
        self.where = where or getattr(funcgen, "name", "the generator")
        self.config = config
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
        _log.debug("%s: drive off (%s)", self.where, reason)

    def final_off(self, reason: str, attempts: int = 3) -> bool:
        """Every output of the generator off, whatever the state; reconnect if the link is lost.

        Returns True when an OFF was sent and confirmed. Raises
        :class:`labkit.errors.DriveNotOff` (exit 4; chained to the last
        InstrumentError) when every attempt failed: the person must act.
        """
        last: InstrumentError | None = None
        t0 = time.monotonic()
        attempt = 0
        _log.info("%s: final OFF (%s)", self.where, reason)
        # at least ``attempts`` tries, and for RECONNECT_WINDOW_S: a link that drops for a moment
        # (a switch, a cable nudged) is back before the run gives up on its OFF
        while attempt < attempts or time.monotonic() - t0 < RECONNECT_WINDOW_S:
            try:
                self.funcgen.safe_off()
                self.is_on = self.maybe_on = False
                self.log(f"drive off ({reason})" + (f" after {attempt} reconnect(s)" if attempt else ""))
                _log.info("%s: OFF confirmed after %d reconnect(s), %.2f s", self.where, attempt,
                          time.monotonic() - t0)
                return True
            except InstrumentError as exc:
                last = exc
                _log.info("%s: OFF attempt %d failed: %s", self.where, attempt + 1, exc)
                if self.reopen is None:
                    break
                try:
                    self.funcgen.close()
                except Exception as exc2:
                    _log.info("%s: closing the failed link: %s: %s", self.where, type(exc2).__name__, exc2)
                attempt += 1
                time.sleep(min(0.05 * attempt, 0.3))
                try:
                    self.funcgen = self.reopen()
                    _log.info("%s: reconnected (attempt %d)", self.where, attempt)
                except InstrumentError as exc2:
                    last = exc2
                    _log.info("%s: reconnect %d failed: %s", self.where, attempt, exc2)
        _log.warning("%s: OFF NOT CONFIRMED after %d reconnect(s), %.2f s: %s", self.where, attempt,
                     time.monotonic() - t0, last)
        self.log(f"DRIVE OFF NOT CONFIRMED ({reason}): {last}; turn the generator output off by hand")
        raise DriveNotOff("funcgen", self.where, str(last), original=reason, config=self.config) from last


    def close(self) -> None:
        """Close the generator's connection (the output state is left as it is)."""
        try:
            self.funcgen.close()
        except Exception as exc:
            _log.info("%s: closing the link: %s: %s", self.where, type(exc).__name__, exc)


#: the signals that end a run like Ctrl-C does: interrupt (Ctrl-C), terminate (kill, systemd),
#: hang-up (the terminal or SSH session closed) and quit (Ctrl-\\). Each turns the drive off first.
STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT)


#: stop signals whose exception may not have arrived: Python runs a signal's handler in
#: whatever code runs at that moment, and an exception raised inside a weakref callback or a
#: ``__del__`` (the import system's lock clean-up, say) is printed and dropped.
_PENDING: list[int] = []


def _stop_exception(signum: int) -> BaseException:
    if signum == signal.SIGINT:
        return KeyboardInterrupt()
    return Interrupted(signal.Signals(signum).name)


def raise_stop_signal(signum: int, frame: Any) -> None:
    """Signal handler: SIGINT raises KeyboardInterrupt, the other stop signals
    :class:`Interrupted`. The signal is also remembered until it is
    handled (:func:`check_stop`, :func:`stop_handled`), in case the exception was dropped."""
    _PENDING.append(signum)
    _log.debug("signal %s received", signal.Signals(signum).name)
    raise _stop_exception(signum)


def check_stop() -> None:
    """Raise the stop of a signal whose exception was dropped (see ``_PENDING``); else nothing.

    Called where a run can stop cleanly: before each point of a run, and when a command
    returns. A stop that did arrive is marked handled by whoever caught it (:func:`stop_handled`)."""
    if _PENDING:
        signum = _PENDING[0]
        _PENDING.clear()
        raise _stop_exception(signum)


def stop_handled() -> None:
    """The stop exception was caught and acted on: forget the signals behind it."""
    _PENDING.clear()


#: the unraisable-exception hook :func:`_stop_unraisable` passes everything else to
_UNRAISABLE: list[Any] = []


def _stop_unraisable(unraisable: Any) -> None:
    """A stop signal's exception raised where Python can only drop it (a weakref callback, a
    ``__del__``): no "Exception ignored" traceback, since :func:`check_stop` raises it again
    (it is in ``_PENDING``); anything else goes to the hook there was."""
    if isinstance(unraisable.exc_value, (KeyboardInterrupt, Interrupted)):
        _log.debug("a stop signal's exception was dropped in %r; it stops the command all the same",
                   unraisable.object)
        return
    (_UNRAISABLE[0] if _UNRAISABLE else sys.__unraisablehook__)(unraisable)


def install_stop_handlers(previous: dict[int, Any] | None = None) -> dict[int, Any]:
    """Make every stop signal raise (:func:`raise_stop_signal`) in the main thread; return the old handlers.

    Also ignores SIGXFSZ, so a file-size limit makes a write fail with an error
    (handled: the drive goes off, the run file is finished) instead of killing the
    process with the drive on. A shell starts background jobs with SIGINT and
    SIGQUIT ignored and Python keeps that; installing handlers undoes it.

    The old handlers go into ``previous`` (a new dict by default) one by one, each before
    its signal's new handler is set: a signal that arrives while the others are still being
    installed raises at once, and the caller, which called this inside its ``try``, can still
    restore exactly what was changed. (Called before the ``try``, such a signal escaped
    ``labkit``'s handling: a background job stopped at its very start died by SIGINT, exit -2,
    instead of exiting 130; seen on a loaded machine.)
    """
    previous = {} if previous is None else previous
    if threading.current_thread() is not threading.main_thread():
        return previous
    for s in (*STOP_SIGNALS, signal.SIGXFSZ):
        previous[s] = signal.getsignal(s)
        signal.signal(s, signal.SIG_IGN if s == signal.SIGXFSZ else raise_stop_signal)
    if getattr(sys.unraisablehook, "__name__", "") != _stop_unraisable.__name__:
        _UNRAISABLE[:] = [sys.unraisablehook]
        sys.unraisablehook = _stop_unraisable
    from labkit import early_signals

    _PENDING.extend(early_signals())      # noted while the command started: check_stop() raises them
    return previous


#: the run file of this process's latest run once it says "complete" (None while a run is going)
_COMPLETED: list[str | None] = [None]


def mark_completed(path: str | None) -> None:
    """The latest run's file ``path`` now says complete (None: a run has started)."""
    _COMPLETED[0] = path


def completed_run() -> str | None:
    """The latest run's file if it says complete, else None (``labkit``: a stop after it exits 0)."""
    return _COMPLETED[0]


def restore_handlers(previous: dict[int, Any]) -> None:
    for s, h in previous.items():
        signal.signal(s, h)


@contextlib.contextmanager
def shielded() -> Iterator[list[int]]:
    """Hold the stop signals while the block runs (shutdown must not be cut short).

    Yields the list of signals that arrived meanwhile; they are not re-raised
    (the caller is shutting down already and reports them).
    """
    if threading.current_thread() is not threading.main_thread():
        yield []
        return
    arrived: list[int] = []

    def hold(signum: int, frame: Any) -> None:
        arrived.append(signum)

    previous: dict[int, Any] = {s: signal.signal(s, hold) for s in STOP_SIGNALS}
    try:
        yield arrived
    finally:
        restore_handlers(previous)


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Hold the stop signals during the block (a point's rows being written), then act on them.

    A signal that arrived meanwhile is raised right after the block, as
    KeyboardInterrupt (SIGINT) or Interrupted (the others), so a point's datasets
    are never left at different lengths by an interrupt.
    """
    with shielded() as arrived:
        yield
    if arrived:
        raise_stop_signal(arrived[0], None)


@contextlib.contextmanager
def signals_raise() -> Iterator[None]:
    """Every stop signal raises inside the block (:func:`install_stop_handlers`), then the old handlers."""
    previous: dict[int, Any] = {}
    try:
        install_stop_handlers(previous)
        yield
    finally:
        restore_handlers(previous)


#: the former name (SIGTERM only); now every stop signal
sigterm_raises = signals_raise


class OffSummary(TypedDict, total=False):
    """``labkit off``'s result (its ``--json`` line): every output of the generator read back off."""

    ok: bool
    instrument: str                  # the model that answered
    resource: str
    channels_off: list[int]
    attempts: int                    # connections it took
    in_use_by: str                   # the run holding the generator's lock, when one did


def turn_off(config: str | None = None, *, model: str | None = None, resource: str | None = None,
             timeout_s: float = 3.0, attempts: int = 3) -> OffSummary:
    """``labkit off``: every output of a rig's generator off, confirmed by reading each one back.

    Reads only ``[instruments.funcgen]`` of ``config`` (the rest may be invalid), or takes
    ``model`` and ``resource``. Returns a summary; raises :class:`labkit.errors.DriveNotOff`
    (exit 4) when no attempt could confirm every output off, InputError for a config or
    arguments that name no generator.
    """
    from labkit.drivers.registry import open_instrument
    from labkit.errors import ConfigError, InputError
    from labkit.lockfiles import describe, holder

    settings: dict[str, Json] = {}
    if config is not None:
        from labkit.tomlio import load_toml

        data, _ = load_toml(config)
        inst = data.get("instruments")
        fg_table = inst.get("funcgen") if isinstance(inst, dict) else None
        if not isinstance(fg_table, dict):
            raise ConfigError("no generator to turn off", file=config, key="instruments.funcgen",
                              expected="an [instruments.funcgen] table with model and resource")
        model = model or fg_table.get("model")
        resource = resource or fg_table.get("resource")
        settings = {k: v for k, v in fg_table.items() if k == "channel"}
        if not isinstance(model, str) or not isinstance(resource, str) or not resource:
            raise ConfigError("the generator's model or resource is missing", file=config,
                              key="instruments.funcgen.resource" if model else "instruments.funcgen.model",
                              expected="model = \"33500B\" (or 33220A, DG1000Z) and resource = \"TCPIP0::...\"")
    if not model or not resource:
        raise InputError("no generator named", key="CONFIG", expected="a config file, or --model and --resource")
    busy = holder("resource:" + resource)
    where = f"{model} at {resource}"
    last: Exception | None = None
    for attempt in range(attempts):
        fg = None
        try:
            fg = open_instrument(model, resource, name="funcgen", timeout_s=timeout_s, **settings)
            fg.safe_off()                         # every channel, then *OPC?
            still_on = []
            for ch in fg.channels:                # read each back
                reply = fg.query(fg._outp("?", channel=ch)).strip().upper()
                if reply not in ("0", "OFF", "+0"):
                    still_on.append(ch)
            if still_on:
                raise InstrumentError(f"output(s) {still_on} still read on after OFF", instrument="funcgen",
                                      command="OUTP?")
            out: OffSummary = {"ok": True, "instrument": getattr(fg, "instrument_model", None) or model,
                                   "resource": resource, "channels_off": list(fg.channels),
                                   "attempts": attempt + 1}
            if busy:
                out["in_use_by"] = describe(busy)
            _log.info("%s: every output read back off (attempt %d)", where, attempt + 1)
            return out
        except InputError:
            raise
        except InstrumentError as exc:
            last = exc
            _log.info("%s: OFF attempt %d failed: %s", where, attempt + 1, exc)
        except OSError as exc:
            last = exc
            _log.info("%s: OFF attempt %d failed: %s", where, attempt + 1, exc)
        finally:
            if fg is not None:
                try:
                    fg.close()
                except Exception as exc:
                    _log.info("%s: closing the link: %s: %s", where, type(exc).__name__, exc)
        time.sleep(0.2 * (attempt + 1))
    raise DriveNotOff("funcgen", where, str(last), config=config or "")
