"""Finding and identifying the instruments on the bench: ``labkit devices`` and ``labkit identify``.

:func:`list_devices` asks each back-end what it can see and sends nothing to
any instrument: pyvisa-py's resource listing (USB-TMC through pyusb, VXI-11 by
broadcast, HiSLIP by mDNS through zeroconf, GPIB through linux-gpib, serial
ports through pyserial), pyserial's port list with each port's USB identity,
and the virtual labs served on this machine (their records). Each back-end
says what it can list, and when it cannot, why.

:func:`identify` opens one resource with a short timeout and asks who it is:
``*IDN?`` (SCPI instruments), else the Polytec controllers' own queries
(OFV-5000 ``GetDevInfo,Controller,0,Name``, OFV-3001 ``VELO?``); matches the
reply to a labkit driver, drains the error queue, optionally runs the
self-test, and turns the usual failures into hints.
"""
from __future__ import annotations

import contextlib
import errno
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from labkit.errors import InstrumentError
from labkit.jsonutil import Json

if TYPE_CHECKING:  # pragma: no cover - annotations only
    from labkit.experiments.locks import ServedLabRecord

#: pyvisa-py's session types, the resource prefix each lists, and what it needs
_BACKENDS = (
    ("USB INSTR", "USB", "USB-TMC instruments (needs pyusb and libusb; on Linux a udev rule for access)"),
    ("TCPIP INSTR", "TCPIP", "LAN instruments: VXI-11 by broadcast on the local subnets, HiSLIP by mDNS "
                             "(needs zeroconf)"),
    ("GPIB INSTR", "GPIB", "GPIB instruments (needs linux-gpib or gpib-ctypes and an adapter)"),
    ("ASRL INSTR", "ASRL", "serial ports (through pyserial; the same ports are listed below with their "
                           "USB identity)"),
)


@dataclass
class Backend:
    """One back-end: can it list, what it found, and why not (if not)."""

    name: str
    can_list: bool
    note: str
    resources: list[str] = field(default_factory=list)


@dataclass
class SerialPort:
    """A serial port as pyserial sees it (USB identity when it is a USB adapter)."""

    device: str
    resource: str
    description: str
    usb: str = ""


@dataclass
class Devices:
    """Everything :func:`list_devices` found."""

    backends: list[Backend]
    serial_ports: list[SerialPort]
    labs: list[ServedLabRecord]

    def as_dict(self) -> dict[str, Json]:
        """What ``labkit devices --json`` prints."""
        import dataclasses

        return {"backends": [dataclasses.asdict(b) for b in self.backends],
                "serial_ports": [dataclasses.asdict(p) for p in self.serial_ports],
                "virtual_labs": [{"pid": lab.get("pid"),
                                  "resources": {r: v for r, v in lab.get("resources", {}).items()},
                                  "config": lab.get("config")} for lab in self.labs]}


def _visa_backends() -> list[Backend]:
    import warnings

    import pyvisa

    try:
        rm = pyvisa.ResourceManager("@py")
    except Exception as exc:   # pyvisa-py missing or broken
        return [Backend("pyvisa-py", False, f"cannot start pyvisa-py: {exc}")]
    try:
        info: dict[str, object] = dict(rm.visalib.get_debug_info())   # type: ignore[arg-type]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")     # the HiSLIP "install zeroconf" warning: said below instead
            found = list(rm.list_resources("?*"))
    finally:
        rm.close()
    out = []
    for key, prefix, what in _BACKENDS:
        status = info.get(key, "not available")
        if key == "GPIB INSTR" and not str(info.get("GPIB INTFC", "")).startswith("Available"):
            status = info.get("GPIB INTFC", status)     # listing GPIB needs the interface library
        ok = isinstance(status, str) and status.strip().startswith("Available")
        text = status if isinstance(status, str) else (
            " ".join(map(str, status)) if isinstance(status, (list, tuple)) else str(status))
        why = " ".join(text.split())
        res = [r for r in found if r.upper().startswith(prefix)]
        if key == "TCPIP INSTR":
            why = why.replace("Available", "").replace("Resource discovery:", "").replace(" - ", "; ").strip("; ")
            if "zeroconf not installed" in why:
                why += ": give HiSLIP instruments' addresses (or pip install zeroconf)"
        out.append(Backend(f"pyvisa-py {key}", ok, what + ("" if ok else f": cannot list: {why}")
                           + (f" [{why}]" if ok and key == "TCPIP INSTR" else "")))
        out[-1].resources = res
    out.append(Backend("pyvisa-py TCPIP SOCKET", False,
                       "raw SCPI sockets (port 5025, 5555 ...) cannot be discovered: nothing on the wire announces "
                       "them; give the address as TCPIP0::host::port::SOCKET"))
    return out


def _serial_ports() -> tuple[Backend, list[SerialPort]]:
    try:
        from serial.tools import list_ports
    except ImportError as exc:  # pragma: no cover - pyserial is a dependency
        return Backend("pyserial", False, f"cannot list serial ports: {exc}"), []
    ports = []
    for p in sorted(list_ports.comports(), key=lambda p: p.device):
        usb = ""
        if p.vid is not None:
            usb = (f"USB {p.vid:04x}:{p.pid or 0:04x}" + (f" {p.manufacturer}" if p.manufacturer else "")
                   + (f" {p.product}" if p.product else "") + (f" serial {p.serial_number}" if p.serial_number else ""))
        ports.append(SerialPort(p.device, f"ASRL{p.device}::INSTR", p.description or "", usb))
    note = ("serial ports with their USB identity (USB-RS-232 adapters, the vibrometer controllers' RS-232); "
            "pseudo-terminals (/dev/pts/N) are not listed: give their path")
    return Backend("pyserial", True, note, [p.resource for p in ports]), ports


def list_devices() -> Devices:
    """Every resource the back-ends can see, one :class:`Backend` each; nothing is sent to any instrument."""
    from labkit.experiments.locks import served_labs

    backends = _visa_backends()
    serial_backend, ports = _serial_ports()
    labs = served_labs()
    lab_backend = Backend("virtual labs", True, "labkit lab serve processes on this machine (from their records)",
                          [f"{role}: {res}" for lab in labs for role, res in lab["resources"].items()])
    return Devices(backends + [serial_backend, lab_backend], ports, labs)


# ----------------------------------------------------------------------------- identify

@dataclass
class Identity:
    """What one resource said about itself, and what labkit makes of it."""

    resource: str
    ok: bool
    reply: str = ""                  # the identity as the instrument gave it
    query: str = ""                  # the query that got it
    driver: str = "no driver"        # the labkit driver model (registry name), or "no driver"
    model: str = ""                  # the model word of the reply
    errors: list[str] = field(default_factory=list)   # error queue, drained
    self_test: str = ""
    problem: str = ""
    hint: str = ""

    def as_dict(self) -> dict[str, Json]:
        """What ``labkit identify --json`` prints of one resource."""
        import dataclasses

        return dataclasses.asdict(self)


def _match_driver(reply: str) -> tuple[str, str]:
    """(driver model, model word) for an ``*IDN?`` reply; ``"no driver"`` if no labkit driver knows it."""
    from labkit.drivers.funcgen import Agilent33220A, Keysight33500B, RigolDG1000Z
    from labkit.drivers.scope import InfiniiVision, RigolDS1000Z

    parts = [p.strip() for p in reply.split(",")]
    word = parts[1] if len(parts) > 1 else ""
    key = word.replace(" ", "").upper()
    for fg in (Agilent33220A, Keysight33500B, RigolDG1000Z):
        if key in {m.upper() for m in fg.known_models}:
            return fg.model, word
    for sc in (InfiniiVision, RigolDS1000Z):
        if sc.model_pattern.fullmatch(word.strip().upper()):
            return sc.model, word
    return "no driver", word


def _hint(resource: str, exc: BaseException | str) -> str:
    text = str(exc)
    low = text.lower()
    serial = resource.upper().startswith("ASRL") or resource.startswith("/dev/")
    if isinstance(exc, PermissionError) or "permission denied" in low or "errno 13" in low:
        return ("no permission: add yourself to the 'dialout' group (serial) or install the instrument's udev "
                "rule (USB-TMC), then log in again")
    if "no module named 'usb'" in low or "libusb" in low or "no backend available" in low:
        return "USB needs pyusb and libusb: pip install pyusb; apt install libusb-1.0-0"
    if "refused" in low or f"errno {errno.ECONNREFUSED}" in low:
        return "nothing listens at that address and port: check the instrument's LAN settings (and port 5025)"
    if "no such file" in low or "could not open port" in low:
        return "no such port: run 'labkit devices' for the ports this computer has"
    if "timeout" in low or "no reply" in low or "tmo" in low:
        if serial:
            return ("no reply: wrong baud rate or termination? (OFV-5000: 115200 8N1, OFV-3001: 9600; both end "
                    "lines with LF); is the controller on and its RS-232 cable a null-modem one?")
        return "no reply: wrong termination (SCPI sockets end lines with LF) or port, or the instrument is busy"
    return ""


def _open(resource: str, timeout_s: float, **transport: Any) -> Any:
    """A generic SCPI driver on ``resource`` (no handshake): only write/query and the error queue are used."""
    from labkit.drivers.base import ScpiInstrument

    return ScpiInstrument.open(resource, timeout_s=timeout_s, name=resource, **transport)


def _scpi(resource: str, timeout_s: float, self_test: bool) -> Identity:
    with contextlib.closing(_open(resource, timeout_s)) as inst:
        reply = inst.query("*IDN?")
        driver, word = _match_driver(reply)
        ident = Identity(resource, True, reply, "*IDN?", driver, word)
        inst.err_command = ":SYST:ERR?" if driver in ("DG1000Z", "InfiniiVision", "DS1000Z") else "SYST:ERR?"
        try:
            ident.errors = inst.read_error_queue()
        except InstrumentError as exc:          # it answered *IDN?: identified, its queue unreadable
            ident.errors = [f"(error queue unreadable: {exc})"]
        if self_test:
            ident.self_test = "passed" if inst.query("*TST?").strip().lstrip("+") == "0" else "FAILED"
        return ident


def _polytec(resource: str, timeout_s: float) -> Identity:
    """The Polytec controllers have no ``*IDN?``: the OFV-5000's device info, else the OFV-3001's range query."""
    with contextlib.closing(_open(resource, timeout_s, baud_rate=115200)) as inst:
        try:
            name = inst.query("GetDevInfo,Controller,0,Name")
            if name and name != "Not Available":
                return Identity(resource, True, f"Polytec,{name}", "GetDevInfo,Controller,0,Name",
                                "OFV-5000" if name.upper().startswith("OFV-5") else "no driver", name)
        except InstrumentError:
            pass
    with contextlib.closing(_open(resource, timeout_s, baud_rate=9600)) as inst:
        reply = inst.query("VELO?")
        if reply.strip().isdigit():
            return Identity(resource, True, f"Polytec,OFV-3001 (range number {reply.strip()})", "VELO?",
                            "OFV-3001", "OFV-3001")
        raise InstrumentError(f"unexpected reply {reply[:40]!r} to VELO?", instrument=resource, command="VELO?")


def identify(resource: str, timeout_s: float = 0.5, self_test: bool = False) -> Identity:
    """Ask ``resource`` who it is (see the module docstring); never raises for an instrument's fault."""
    serial = resource.upper().startswith("ASRL") or resource.startswith("/dev/")
    first: BaseException | None = None
    try:
        return _scpi(resource, timeout_s, self_test)
    except (InstrumentError, OSError) as exc:
        first = exc
    if serial:
        try:
            return _polytec(resource, timeout_s)
        except (InstrumentError, OSError) as exc:
            first = first or exc
    cause = first.__cause__ if first is not None and first.__cause__ is not None else first
    return Identity(resource, False, problem=str(first), hint=_hint(resource, cause or ""))


#: labkit driver model -> role in a config
ROLE_OF_DRIVER = {"33220A": "funcgen", "33500B": "funcgen", "DG1000Z": "funcgen", "InfiniiVision": "scope",
                  "DS1000Z": "scope", "OFV-5000": "vibrometer", "OFV-3001": "vibrometer"}


def by_role(found: list[Identity]) -> dict[str, list[Identity]]:
    """The identified instruments that have a labkit driver, grouped by the role they can play."""
    roles: dict[str, list[Identity]] = {"funcgen": [], "scope": [], "vibrometer": []}
    for ident in found:
        role = ROLE_OF_DRIVER.get(ident.driver)
        if ident.ok and role is not None:
            roles[role].append(ident)
    return roles
