"""Clients of the lab's control channel: :class:`LabControl` and a Camera over it.

Plain sockets (no pyvisa needed), ``\\n``-terminated lines; every failure is
an :class:`labkit.errors.InstrumentError` naming ``lab-control`` and the
command, within the timeout.
"""
from __future__ import annotations

import json
import re
import socket
from pathlib import Path
from typing import TYPE_CHECKING, Any

from labkit.errors import InstrumentError
from labkit.jsonutil import Json

if TYPE_CHECKING:
    from labkit.lab.control import LabTruth

_TCP = re.compile(r"^TCPIP\d*::([^:]+)::(\d+)::SOCKET$", re.IGNORECASE)


def parse_socket_resource(resource: str) -> tuple[str, int]:
    """``TCPIP0::127.0.0.1::5025::SOCKET`` (or ``host:port``) -> (host, port)."""
    m = _TCP.match(resource.strip())
    if m:
        return m.group(1), int(m.group(2))
    host, _, port = resource.rpartition(":")
    if host and port.isdigit():
        return host, int(port)
    raise ValueError(f"not a socket resource: {resource!r} (expected TCPIP0::host::port::SOCKET)")


class LabControl:
    """Talk to a running virtual lab's control channel.

    Parameters
    ----------
    resource:
        The lab's ``resources["control"]``.
    timeout_s:
        Per reply; recording video waits ``timeout_s + 10 * duration_s``.
    """

    name = "lab-control"

    def __init__(self, resource: str, timeout_s: float = 5.0) -> None:
        self.resource = resource
        self.timeout_s = float(timeout_s)
        host, port = parse_socket_resource(resource)
        try:
            self._sock = socket.create_connection((host, port), timeout=self.timeout_s)
        except OSError as exc:
            raise InstrumentError(f"cannot connect to {resource}: {exc}", instrument=self.name) from None
        self._buf = b""

    # -- plumbing -------------------------------------------------------------------------------
    def write(self, command: str) -> None:
        try:
            self._sock.sendall(command.encode("ascii") + b"\n")
        except OSError as exc:
            raise InstrumentError(f"send failed: {exc}", instrument=self.name, command=command) from None

    def query(self, command: str, timeout_s: float | None = None) -> str:
        self.write(command)
        self._sock.settimeout(self.timeout_s if timeout_s is None else timeout_s)
        try:
            while b"\n" not in self._buf:
                chunk = self._sock.recv(65536)
                if not chunk:
                    raise InstrumentError("connection closed", instrument=self.name, command=command)
                self._buf += chunk
        except TimeoutError:
            raise InstrumentError("timeout", instrument=self.name, command=command) from None
        except OSError as exc:
            raise InstrumentError(f"receive failed: {exc}", instrument=self.name, command=command) from None
        line, self._buf = self._buf.split(b"\n", 1)
        try:
            return line.decode("ascii")
        except UnicodeDecodeError:
            raise InstrumentError(f"garbled reply {line[:40]!r}", instrument=self.name, command=command) from None

    def check(self, command: str) -> None:
        """Raise if the control channel queued an error (after a setting)."""
        err = self.query("SYST:ERR?")
        if not err.startswith(("+0", "0")):
            raise InstrumentError(f"refused: {err}", instrument=self.name, command=command)

    # -- what a person does -------------------------------------------------------------------
    def set_spot(self, spot: str) -> None:
        cmd = f"LAB:SPOT {spot.upper()}"
        self.write(cmd)
        self.check(cmd)

    def spot(self) -> str:
        return self.query("LAB:SPOT?").lower()

    def set_setup(self, setup: str) -> None:
        cmd = f"LAB:SETUP {setup.upper()}"
        self.write(cmd)
        self.check(cmd)

    def setup(self) -> str:
        return self.query("LAB:SETUP?").lower()

    def truth(self) -> LabTruth:
        return json.loads(self.query("LAB:TRUTH?"))

    def inject_fault(self, instrument: str, kind: str, after: int = 0, match: str | None = None,
                     count: int = 1) -> None:
        cmd = f'LAB:FAULT {instrument},{kind},{int(after)},"{match or ""}",{int(count)}'
        self.write(cmd)
        self.check(cmd)

    def record_video(self, path: str | Path, duration_s: float) -> dict[str, Json]:
        """Film ``duration_s`` into ``path``; -> Camera dict. The lab films into its own folder
        (``CAM:DIR?``, on this machine); the clip is then moved to ``path``."""
        import shutil

        path = Path(path)
        if not path.parent.is_dir():
            raise InstrumentError(f"camera: no such directory: {path.parent}", instrument=self.name,
                                  command="CAM:REC")
        name = path.name.lstrip(".") or "clip.mkv"      # the lab takes a plain name (no leading dot)
        cmd = f'CAM:REC "{name}",{float(duration_s):g}'
        reply = self.query(cmd, timeout_s=self.timeout_s + 10 * float(duration_s))
        if not reply.strip().lstrip("+").isdigit() or int(reply) == 0:
            self.check(cmd)
            raise InstrumentError(f"unexpected reply {reply[:40]!r}", instrument=self.name, command=cmd)
        folder = Path(self.query("CAM:DIR?").strip().strip('"'))
        shutil.move(str(folder / name), str(path))
        stamps = self.query("CAM:TIMESTAMPS?")
        times = [float(v) for v in stamps.split(",") if v.strip()]
        return {"path": str(path), "frames": int(reply), "timestamps_s": list[Json](times)}

    def close(self) -> None:
        try:
            self._sock.close()
        except OSError:
            pass

    def __enter__(self) -> LabControl:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class LabCamera:
    """The drivers' Camera protocol over the lab's control channel (``record`` only).

    ``read()`` (live frames) is not offered: the virtual camera films whole
    clips; replay a recording with ``labkit.drivers.camera.FileCamera``.
    """

    def __init__(self, resource: str | LabControl, timeout_s: float = 5.0) -> None:
        self.control = resource if isinstance(resource, LabControl) else LabControl(resource, timeout_s)

    def record(self, path: str | Path, duration_s: float) -> dict[str, Json]:
        return self.control.record_video(path, duration_s)

    def snapshot(self) -> dict[str, Json]:
        return {"type": type(self).__name__}

    def read(self):  # pragma: no cover - documented limitation
        raise InstrumentError("the virtual camera records clips only; use FileCamera to replay",
                              instrument="lab-camera", command="read")

    def close(self) -> None:
        self.control.close()

    def __enter__(self) -> LabCamera:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
