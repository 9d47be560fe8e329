"""The common base of every instrument driver.

An :class:`Instrument` talks to its instrument through a transport
(:mod:`labkit.drivers.transport`): pyvisa with the pure-Python backend for VISA
resources (``TCPIP0::host::5025::SOCKET``), pyserial for
``ASRL/dev/pts/3::INSTR``, ``/dev/...`` paths and pyserial URLs.

Every transport fault — timeout, dropped connection, garbled or malformed
reply — becomes ONE :class:`labkit.errors.InstrumentError` naming the
instrument and the command in flight, raised within the timeout; nothing
here blocks without a deadline. Requested settings are checked against
declared limits before anything is sent (:func:`check_range` ->
:class:`labkit.errors.LimitError` naming the limit).

Use a driver as a context manager: on exit — normal or by an exception —
:meth:`Instrument.safe_off` runs first (outputs off), then
:meth:`Instrument.close`.

Examples
--------
>>> from labkit.drivers.funcgen import Keysight33500B                    # doctest: +SKIP
>>> with Keysight33500B.open("TCPIP0::10.0.0.5::5025::SOCKET", max_amp_vpp=20) as fg:
...     fg.set_sine(freq_hz=1000, amp_vpp=2.0)
...     fg.output(True)
"""
from __future__ import annotations

import logging
import re
import termios
from typing import Any, ClassVar

import numpy as np

from labkit.drivers.transport import (
    TRANSPORT_KEYS,
    SerialTransport,
    Transport,
    TransportError,
    VisaTransport,
    _Closed,
    open_transport,
    resource_manager,
)
from labkit.errors import ConfigError, InstrumentError, LimitError
from labkit.jsonutil import to_jsonable

__all__ = ["Instrument", "ScpiInstrument", "check_range", "check_choice", "Transport",
           "VisaTransport", "SerialTransport", "TransportError", "open_transport",
           "resource_manager", "TRANSPORT_KEYS"]

log = logging.getLogger(__name__)

# ---------------------------------------------------------------------------------------------
# limits


def check_range(limit: str, value: float | str, lo: float | None = None, hi: float | None = None,
                unit: str = "") -> float:
    """Return ``float(value)`` if ``lo <= value <= hi``, else raise LimitError naming ``limit``.

    Called before anything is sent, so a refused setting never reaches the
    instrument.
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise LimitError(f"{limit}: {value!r} is not a number", limit=limit) from None
    if not np.isfinite(v):
        raise LimitError(f"{limit}: {v} is not finite", limit=limit)
    u = f" {unit}" if unit else ""
    if lo is not None and v < lo:
        raise LimitError(f"{v:g}{u} is below the limit {limit} = {lo:g}{u}; nothing was sent",
                         limit=limit)
    if hi is not None and v > hi:
        raise LimitError(f"{v:g}{u} exceeds the limit {limit} = {hi:g}{u}; nothing was sent",
                         limit=limit)
    return v


def check_choice(name: str, value: str, choices: tuple[str, ...]) -> str:
    """Return ``value`` upper-cased if it is one of ``choices``, else LimitError naming ``name``."""
    v = str(value).upper()
    if v not in choices:
        raise LimitError(f"{name}: {value!r} is not one of {', '.join(choices)}", limit=name)
    return v


# ---------------------------------------------------------------------------------------------
# the base driver

# termios.error (a pty whose peer vanished, from pyserial's tcdrain) is not an OSError.
_WRAPPED = (TransportError, OSError, EOFError, ValueError, RuntimeError, UnicodeError, termios.error)


def _wrappable() -> tuple[type[BaseException], ...]:
    extra: list[type[BaseException]] = []
    try:
        from pyvisa.errors import Error as VisaError
        extra.append(VisaError)
    except ImportError:  # pragma: no cover - pyvisa is a dependency
        pass
    try:
        from serial import SerialException
        extra.append(SerialException)
    except ImportError:  # pragma: no cover
        pass
    return _WRAPPED + tuple(extra)


def _check_resource(resource: str) -> None:
    """ConfigError for a string that is neither a VISA resource nor a serial port/URL."""
    if not isinstance(resource, str) or not resource:
        raise ConfigError(f"bad resource {resource!r}", key="resource", expected=RESOURCE_FORMS)
    if resource.startswith("/dev/") or "://" in resource or resource.upper().startswith("ASRL"):
        return
    from pyvisa.rname import InvalidResourceName, parse_resource_name
    try:
        parse_resource_name(resource)
    except InvalidResourceName:
        raise ConfigError(f"bad resource {resource!r}", key="resource",
                          expected=RESOURCE_FORMS) from None


def open_failure(resource: str, exc: BaseException) -> str:
    """One line saying why ``resource`` did not open, and what to write instead where the
    back-end's own words mislead (pyvisa-py calls a missing HiSLIP server 'resource not present')."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    parts = resource.split("::")
    host = parts[1] if len(parts) > 2 else "?"
    kind = resource.upper()
    if "HISLIP" in kind and "RSRC_NFOUND" in text:
        return (f"no HiSLIP server answered at {host}, port 4880 (pyvisa-py: {text[:60]}...); "
                f"the instrument may not offer HiSLIP: try TCPIP0::{host}::inst0::INSTR (VXI-11) "
                f"or TCPIP0::{host}::5025::SOCKET")
    if kind.startswith("TCPIP") and kind.endswith("::INSTR") and "refused" in text.lower():
        return (f"no VXI-11 portmapper at {host}, port 111 ({text}): is the instrument on, its "
                f"VXI-11 (LAN) interface enabled? or try TCPIP0::{host}::5025::SOCKET")
    if kind.startswith("USB") and "usb" in text.lower():
        return "USB resources need the pyusb package and libusb, not installed here (" + text[:80] + ")"
    if kind.startswith("GPIB"):
        return "GPIB resources need linux-gpib or gpib-ctypes, not installed here (" + text[:80] + ")"
    return text


RESOURCE_FORMS = ("a VISA resource (TCPIP0::host::5025::SOCKET), ASRL/dev/ttyX::INSTR, "
                  "a /dev/... path or a pyserial URL (socket://host:port)")


class Instrument:
    """Base of every remote-controlled instrument.

    Parameters
    ----------
    transport:
        An open :class:`Transport` (use :meth:`open` to make one from a
        resource string).
    name:
        How errors and logs name the instrument (default: ``"<model> at <resource>"``).
    **settings:
        Driver settings (limits, channel, ...). Unknown names raise ConfigError.

    Notes
    -----
    Constructing sends nothing; :meth:`open` then runs :meth:`connect`, which
    is empty here and the SCPI generators' and scopes' handshake there
    (:meth:`ScpiInstrument.connect`). The identity is otherwise asked for
    lazily (:attr:`identity`).
    """

    #: Model name used by :mod:`labkit.drivers.registry` and in snapshots.
    model: ClassVar[str] = "instrument"
    #: Transport settings this model needs by default (e.g. a serial baud rate).
    transport_defaults: ClassVar[dict[str, Any]] = {}
    #: ``"socket"`` or ``"serial"``: how :mod:`labkit.drivers.testing` connects a scripted peer.
    link: ClassVar[str] = "socket"

    def __init__(self, transport: Transport, *, name: str | None = None, **settings: Any) -> None:
        if settings:
            key = sorted(settings)[0]
            raise ConfigError(f"unknown setting for {self.model}", key=key,
                              expected=f"one of {sorted(self.setting_names())}")
        self.transport = transport
        self.resource = transport.resource
        self.name = name or f"{self.model} at {self.resource}"
        self._identity: str | None = None
        #: What this driver has commanded, by setting name with units (for snapshots).
        self.state: dict[str, Any] = {}
        self._errors = _wrappable()

    @classmethod
    def setting_names(cls) -> set[str]:
        """Keyword settings :meth:`open` accepts besides the transport's."""
        import inspect
        names: set[str] = set()
        for klass in cls.__mro__:
            init = klass.__dict__.get("__init__")
            if init is None:
                continue
            for p in inspect.signature(init).parameters.values():
                if p.kind == p.KEYWORD_ONLY:
                    names.add(p.name)
        return names | set(TRANSPORT_KEYS) | {"timeout_s"}

    @classmethod
    def open(cls, resource: str, *, timeout_s: float = 2.0, name: str | None = None,
             **settings: Any):
        """Open ``resource`` and return a connected driver.

        Transport settings (``baud_rate``, ``parity``, ``read_termination``...)
        are split from driver settings; a connection that cannot be made
        raises InstrumentError with command ``"open"``.
        """
        tkw = dict(cls.transport_defaults)
        tkw.update({k: settings.pop(k) for k in list(settings) if k in TRANSPORT_KEYS})
        label = name or f"{cls.model} at {resource}"
        _check_resource(resource)
        try:
            transport = open_transport(resource, timeout_s, **tkw)
        except Exception as exc:  # pyvisa-py raises bare Exception for unreachable hosts
            raise InstrumentError(f"cannot open {resource}: {open_failure(resource, exc)}",
                                  instrument=label, command="open") from exc
        try:
            inst = cls(transport, name=name, **settings)
            inst.connect()
            return inst
        except BaseException:
            transport.close()
            raise

    def connect(self) -> None:
        """What :meth:`open` does once the link is up, before returning the driver (base: nothing)."""

    # -- timeouts ---------------------------------------------------------------------------
    @property
    def timeout_s(self) -> float:
        """Per-operation timeout in seconds (get/set)."""
        return self.transport.timeout_s

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        self.transport.timeout_s = check_range("timeout_s", value, 1e-3, 3600.0, "s")

    # -- I/O --------------------------------------------------------------------------------
    def _fail(self, exc: BaseException, command: str, what: str = "") -> InstrumentError:
        text = str(exc) or type(exc).__name__
        dropped = getattr(self.transport, "dropped", None)
        if dropped is not None and dropped():
            return InstrumentError("connection closed by the instrument", instrument=self.name,
                                   command=command)
        if "VI_ERROR_TMO" in text:
            return InstrumentError(f"no reply within {self.timeout_s:g} s", instrument=self.name,
                                   command=command)
        if "timeout" in text.lower():
            kind = f"no reply within {self.timeout_s:g} s"
        else:
            kind = what or "transport failure"
        return InstrumentError(f"{kind}: {text}", instrument=self.name, command=command)

    def write(self, command: str) -> None:
        """Send one command line."""
        log.debug("%s <- %s", self.name, command)
        try:
            self.transport.write(command)
        except self._errors as exc:
            raise self._fail(exc, command, "write failed") from exc

    def query(self, command: str) -> str:
        """Send ``command`` and return the reply line (termination stripped)."""
        self.write(command)
        try:
            reply = self.transport.read()
        except UnicodeError as exc:
            raise self._fail(exc, command, "garbled reply (not ASCII)") from exc
        except self._errors as exc:
            raise self._fail(exc, command, "read failed") from exc
        log.debug("%s -> %s", self.name, reply)
        if any(ord(c) < 32 and c not in "\t\r" for c in reply):
            raise InstrumentError(f"garbled reply {reply[:40]!r}", instrument=self.name,
                                  command=command)
        return reply.strip()

    def query_float(self, command: str) -> float:
        """Query a number; a reply that is not one raises InstrumentError."""
        reply = self.query(command)
        try:
            return float(reply)
        except ValueError:
            raise InstrumentError(f"garbled reply {reply[:40]!r} (expected a number)",
                                  instrument=self.name, command=command) from None

    def query_int(self, command: str) -> int:
        """Query an integer (``"+1"``, ``"0"``); anything else raises InstrumentError."""
        reply = self.query(command)
        try:
            return int(reply)
        except ValueError:
            try:
                f = float(reply)
            except ValueError:
                f = float("nan")
            if f.is_integer():
                return int(f)
            raise InstrumentError(f"garbled reply {reply[:40]!r} (expected an integer)",
                                  instrument=self.name, command=command) from None

    def query_binary(self, command: str, datatype: str = "B", big_endian: bool = False
                     ) -> np.ndarray:
        """Send ``command`` and read its IEEE 488.2 definite-length block as a numpy array."""
        log.debug("%s <- %s (binary)", self.name, command)
        try:
            return self.transport.query_block(command, datatype, big_endian)
        except self._errors as exc:
            raise self._fail(exc, command, "bad binary block") from exc

    # -- identity, snapshot, shutdown -------------------------------------------------------
    @property
    def identity(self) -> str:
        """The instrument's ``*IDN?`` reply (asked once, then cached)."""
        if self._identity is None:
            self._identity = self.query("*IDN?")
        return self._identity

    def settings(self) -> dict[str, Any]:
        """Declared driver settings (limits, channel...); subclasses extend."""
        return {"timeout_s": self.timeout_s}

    def snapshot(self) -> dict[str, Any]:
        """Identity, declared settings and everything commanded so far; JSON-able."""
        return {"model": self.model, "name": self.name, "resource": self.resource,
                "identity": self.identity, "settings": to_jsonable(self.settings()),
                "state": to_jsonable(self.state)}

    def safe_off(self) -> None:
        """Put the instrument in a safe state (outputs off). The base has nothing to do."""

    def close(self) -> None:
        """Close the link (idempotent; never raises)."""
        t, self.transport = self.transport, _Closed(self.resource)
        try:
            t.close()
        except Exception as exc:  # closing a dead link must not mask the real error
            log.debug("%s: close failed: %s", self.name, exc)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            self.safe_off()
        except Exception as off_exc:
            if exc is None:
                raise
            # Keep the original error; say that shutdown failed too.
            exc.add_note(f"{self.name}: safe_off failed as well: {off_exc}")
        finally:
            self.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name}>"


_ERR = re.compile(r'^\s*([+-]?\d+)\s*,\s*"?(.*?)"?\s*$')
#: an error summary longer than this is cut (the entries left out are counted)
SUMMARY_CHARS = 240


def summarise_errors(errors: list[str]) -> str:
    """The error-queue entries as one short line: repeats counted (``-113,"Undefined header"
    x32``), at most :data:`SUMMARY_CHARS` characters, the rest counted, never a newline."""
    counted: dict[str, int] = {}
    for e in errors:
        text = " ".join(e.split())[:80]
        counted[text] = counted.get(text, 0) + 1
    parts = [t if n == 1 else f"{t} x{n}" for t, n in counted.items()]
    out: list[str] = []
    for i, part in enumerate(parts):
        if sum(len(p) + 2 for p in out) + len(part) > SUMMARY_CHARS:
            out.append(f"... {len(parts) - i} more kinds")
            break
        out.append(part)
    return "; ".join(out)


class ScpiInstrument(Instrument):
    """An instrument with a SCPI error queue (``SYST:ERR?`` -> ``+0,"No error"``).

    Parameters
    ----------
    check_errors:
        Read the error queue after every group of settings (default True);
        a non-zero entry raises InstrumentError with the instrument's text.
    """

    err_command: ClassVar[str] = "SYST:ERR?"
    max_error_reads: ClassVar[int] = 32
    #: Run the identity / error-queue handshake (:meth:`connect`) when opened.
    connect_on_open: ClassVar[bool] = False

    def __init__(self, transport: Transport, *, name: str | None = None,
                 check_errors: bool = True, **settings: Any) -> None:
        super().__init__(transport, name=name, **settings)
        self.auto_check_errors = bool(check_errors)
        #: The model word of the identity (``"33522B"``), once :meth:`connect` has run.
        self.instrument_model: str | None = None
        #: Errors the instrument held when the driver connected (``-113,"Undefined header"``...).
        self.errors_at_connect: list[str] = []

    def settings(self) -> dict[str, Any]:
        return {**super().settings(), "check_errors": self.auto_check_errors}

    # -- the handshake on open ------------------------------------------------------------
    def identify(self, identity: str) -> tuple[str, int]:
        """(model, channel count) from the ``*IDN?`` reply; ConfigError for a model the driver
        does not know (subclasses with :attr:`connect_on_open`)."""
        raise NotImplementedError

    def identified(self, model: str, channels: int) -> None:
        """Called by :meth:`connect` with what :meth:`identify` found (subclasses check settings)."""

    def connect(self) -> None:
        """Handshake: identity -> model and channel count; drain the error queue; ``*CLS``.

        1. ``*IDN?``: the model word says the model and its channel count; a model
           this driver does not know raises ConfigError (nothing else is sent).
        2. The error query until the queue is empty: what an earlier program or the
           front panel left there is kept in :attr:`errors_at_connect` (and the
           snapshot), not blamed on the first setting.
        3. ``*CLS``: the event registers are cleared too.
        """
        if not self.connect_on_open:
            return
        model, channels = self.identify(self.identity)
        self.instrument_model = model
        self.identified(model, channels)
        stale = self.read_error_queue()
        self.write("*CLS")
        self.errors_at_connect = stale
        if stale:
            log.warning("%s: errors queued before this connection (cleared): %s", self.name,
                        summarise_errors(stale))

    def snapshot(self) -> dict[str, Any]:
        snap = super().snapshot()
        if self.connect_on_open:
            snap["connect"] = {"instrument_model": self.instrument_model,
                               "errors_at_connect": list(self.errors_at_connect)}
        return snap

    def _identity_fields(self, identity: str) -> tuple[str, str]:
        """(manufacturer, model) of an ``*IDN?`` reply; InstrumentError if it has no model field."""
        parts = [p.strip() for p in identity.split(",")]
        if len(parts) < 2 or not parts[1]:
            raise InstrumentError(f"garbled identity {identity[:60]!r} (expected "
                                  "'maker,model,serial,firmware')", instrument=self.name,
                                  command="*IDN?")
        return parts[0], parts[1]

    def _unknown_model(self, identity: str, known: str) -> ConfigError:
        return ConfigError(f"{self.name}: the instrument identifies as {identity[:80]!r}, not a model "
                           f"the {self.model} driver knows; nothing else was sent", key="model",
                           expected=known)

    def _send_all(self, commands: list[str]) -> None:
        for cmd in commands:
            self.write(cmd)
        if self.auto_check_errors:
            self.check_errors(after=commands[-1] if commands else None)

    def check_errors(self, after: str | None = None) -> None:
        """Read the error queue until it is empty; raise InstrumentError if it held errors.

        ``after`` names the command the errors are reported against (default:
        the error query itself).
        """
        errors = self.read_error_queue()
        if errors:
            raise InstrumentError("instrument reported " + summarise_errors(errors), instrument=self.name,
                                  command=after or self.err_command)

    def read_error_queue(self) -> list[str]:
        """Read the error queue until it is empty; return its entries (``'-113,"Undefined header"'``)."""
        errors: list[str] = []
        for _ in range(self.max_error_reads):
            reply = self.query(self.err_command)
            m = _ERR.match(reply)
            if not m:
                raise InstrumentError(f"garbled error-queue reply {reply[:40]!r}",
                                      instrument=self.name, command=self.err_command)
            if int(m.group(1)) == 0:
                break
            errors.append(f"{int(m.group(1))},\"{m.group(2)}\"")
        else:
            errors.append(f"(queue not empty after {self.max_error_reads} reads)")
        return errors
