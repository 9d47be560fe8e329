"""One rig, one run: an exclusive OS lock per instrument (and per run file).

A second run on the same instruments would switch the first one's drive off
with its start-up OFF and then measure a rig it does not own. Before any
instrument is opened, a run takes an exclusive, non-blocking ``flock`` on one
small file per instrument in the machine's lock folder
(:data:`labkit.lockfiles.LOCK_DIR`, shared by every user); the file holds the
holder's PID, command and run file as JSON. The kernel drops the lock when the
process ends in any way (SIGKILL, a crash), so a stale file never blocks.

An instrument is named by what it is, not how the config spells it:

* its resource normalised (:func:`resource_key`): the interface board number
  (``TCPIP`` is ``TCPIP0``), the host name resolved to its address
  (``localhost`` is ``127.0.0.1``), letter case, and the real path of a serial
  device (a symlink to ``/dev/ttyUSB0`` is ``/dev/ttyUSB0``);
* once connected, its ``*IDN?`` maker, model and serial number
  (:func:`claim_identity`, called before anything else is sent to it): the same
  generator reached through another address or a forwarded port is still one.

A run file being written is locked the same way, so ``labkit info`` and
``--resume`` can say "being written by PID n" instead of an HDF5 locking error.
Finding lock files and reading who holds one is :mod:`labkit.lockfiles` (base layer:
``labkit.open`` reads it too); this module takes and releases the locks.
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import socket
import sys
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, TypedDict, cast

from labkit.errors import InputError
from labkit.lockfiles import LockRecord, describe, file_key, lock_path, read_lock, read_record, runtime_dir
from labkit.outputs import process_alive


def resource_key(resource: str) -> str:
    """The lock key of a VISA resource: one spelling per instrument (see the module's docstring)."""
    r = resource.strip()
    m = re.match(r"(?i)^TCPIP(\d*)::([^:]+)::(.*)$", r)
    if m:
        board, host, rest = m.groups()
        rest = rest.upper()
        if rest == "INSTR":
            rest = "INST0::INSTR"
        return f"TCPIP{board or 0}::{_address(host)}::{rest}"
    m = re.match(r"(?i)^ASRL(.+?)::INSTR$", r)
    if m:
        dev = m.group(1)
        return f"ASRL{os.path.realpath(dev) if dev.startswith('/') else dev.upper()}::INSTR"
    m = re.match(r"(?i)^(USB|GPIB|VXI)(\d*)::(.*)$", r)
    if m:
        return f"{m.group(1).upper()}{m.group(2) or 0}::{m.group(3).upper()}"
    return r


def _address(host: str) -> str:
    """A host name's IPv4 address (``localhost`` -> ``127.0.0.1``); the name, lower case, if unresolved."""
    try:
        infos = socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        return host.lower()
    return str(infos[0][4][0]) if infos else host.lower()


def identity_key(identity: str) -> str | None:
    """The lock key of an instrument's ``*IDN?`` reply (maker, model, serial), None without a serial."""
    parts = [p.strip().upper() for p in identity.split(",")]
    if len(parts) < 3 or parts[2] in ("", "0"):
        return None
    return "idn:" + ",".join(parts[:3])


class RigBusy(InputError):
    """Another run holds one of the instruments (or the run file): nothing was opened or sent (exit 2)."""


class RunLocks:
    """The locks of one run; release with :meth:`release` (or use as a context manager)."""

    def __init__(self) -> None:
        self._fds: list[tuple[int, Path]] = []
        self.record: LockRecord = {}
        self.config = ""

    def take(self, key: str, what: str, record: LockRecord, *, file: str | None = None,
             conf_key: str | None = None) -> None:
        """Lock ``key`` or raise :class:`RigBusy` naming the run that holds it."""
        p = lock_path(key)
        writable = True
        try:
            fd = os.open(p, os.O_RDWR | os.O_CREAT, 0o666)
            with contextlib.suppress(OSError):
                os.fchmod(fd, 0o666)        # every user's runs share the lock (past the umask)
        except PermissionError:             # another user's file, made by an older labkit (mode 0600)
            fd = os.open(p, os.O_RDONLY)
            writable = False
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            other = read_lock(p)
            raise RigBusy(f"{what} is in use by another run: {describe(other)}; wait for it to end "
                          f"(or stop it), then start this one", file=file, key=conf_key) from None
        if writable:
            os.ftruncate(fd, 0)
            os.write(fd, json.dumps({**record, "key": key}).encode())
        self._fds.append((fd, p))
        self.record = record

    def release(self) -> None:
        for fd, _p in reversed(self._fds):
            try:
                os.ftruncate(fd, 0)
                fcntl.flock(fd, fcntl.LOCK_UN)
                os.close(fd)
            except OSError:
                pass
        self._fds.clear()

    def __enter__(self) -> RunLocks:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _holder(run_file: str | Path | None, config: str) -> LockRecord:
    """What a lock file says about its holder (this process)."""
    return {"pid": os.getpid(), "host": socket.gethostname(),
            "command": " ".join(["labkit", *sys.argv[1:]]) if sys.argv else "",
            "run_file": "" if run_file is None else os.fspath(run_file), "config": config,
            "since": time.strftime("%H:%M:%S")}


#: the locks of the run this process is making (:func:`lock_run`), for :func:`claim_identity`
_ACTIVE: list[RunLocks] = []


def _take_instruments(locks: RunLocks, resources: Iterable[tuple[str, str]], record: LockRecord,
                      config: str) -> None:
    seen: set[str] = set()
    for role, resource in resources:
        # roles may share one resource (the virtual lab's camera rides its control channel):
        # one lock each, or the run would find itself "busy"; keyed on the instrument, not its spelling
        key = resource_key(resource) if resource else ""
        if key and key not in seen:
            seen.add(key)
            locks.take("resource:" + key, f"the {role} ({resource})", record, file=config,
                       conf_key=f"instruments.{role}.resource")
    _ACTIVE.append(locks)


@contextlib.contextmanager
def lock_run(resources: Iterable[tuple[str, str]], run_file: str | Path, config: str) -> Iterator[RunLocks]:
    """Lock every ``(role, resource)`` and the run file, for the block; RigBusy if any is held."""
    record = _holder(run_file, config)
    locks = RunLocks()
    locks.config = config
    try:
        locks.take(file_key(run_file), f"the run file {run_file}", record, file=os.fspath(run_file), conf_key="--out")
        _take_instruments(locks, resources, record, config)
        yield locks
    finally:
        if locks in _ACTIVE:
            _ACTIVE.remove(locks)
        locks.release()


@contextlib.contextmanager
def lock_instruments(resources: Iterable[tuple[str, str]], config: str) -> Iterator[RunLocks]:
    """Lock every ``(role, resource)`` without a run file (``labkit check``); RigBusy if any is held."""
    locks = RunLocks()
    try:
        _take_instruments(locks, resources, _holder(None, config), config)
        yield locks
    finally:
        if locks in _ACTIVE:
            _ACTIVE.remove(locks)
        locks.release()


def claim_identity(role: str, identity: str, resource: str) -> None:
    """Lock the instrument by its ``*IDN?`` identity for the run being made (RigBusy if another holds it).

    Called right after connecting, before anything else is sent: a run that reached the
    same instrument through another address stops here, nothing switched. Outside a
    :func:`lock_run` block (library use) there is nothing to add to.
    """
    key = identity_key(identity)
    if key is None or not _ACTIVE:
        return
    locks = _ACTIVE[-1]
    serial = identity.split(",")[2].strip()
    locks.take(key, f"the {role} (serial {serial}, reached as {resource})", locks.record, file=locks.config,
               conf_key=f"instruments.{role}.resource")


# ----------------------------------------------------------------------------- a served virtual lab

def lab_file(pid: int | None = None) -> Path:
    """Where the ``labkit lab serve`` of process ``pid`` (default: this one) records its lab.

    One file per serving process, so two served labs never overwrite each other's record.
    """
    return runtime_dir() / f"lab-serve-{os.getpid() if pid is None else int(pid)}.json"


def announce_lab(resources: dict[str, str], models: dict[str, str], config: str | None = None,
                 **extra: Any) -> Path:
    """Record a served lab (this process): its resources, driver models and the config it wrote."""
    p = lab_file()
    tmp = p.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text(json.dumps({"pid": os.getpid(), "resources": resources, "models": models,
                               "config": config, "since": time.strftime("%H:%M:%S"),
                               "started": time.time()} | extra))
    os.replace(tmp, p)
    return p


def withdraw_lab() -> None:
    """Remove the record of this process's served lab (another process's is left alone)."""
    try:
        lab_file().unlink()
    except OSError:
        pass


def _alive(pid: Any) -> bool:
    return isinstance(pid, int) and pid > 0 and process_alive(pid)


class ServedLabRecord(TypedDict, total=False):
    """The record a ``labkit lab serve`` writes (:func:`announce_lab`, JSON) and readers find."""

    pid: int
    resources: dict[str, str]        # role -> resource
    models: dict[str, str]           # role -> driver model
    config: str | None               # the config it wrote for its lab
    since: str                       # HH:MM:SS
    started: float                   # Unix time
    setup: str                       # what it serves (``labkit lab serve --setup``)


def served_labs() -> list[ServedLabRecord]:
    """Every running ``labkit lab serve`` (their records), the newest first.

    A record whose process has ended (killed before it could remove it) is skipped
    and removed.
    """
    labs = []
    for p in runtime_dir().glob("lab-serve-*.json"):
        data = read_record(p)
        if not isinstance(data, dict) or not isinstance(data.get("resources"), dict):
            continue
        if not _alive(data.get("pid")):
            with contextlib.suppress(OSError):
                p.unlink()
                p.with_suffix(".toml").unlink(missing_ok=True)    # the config it wrote beside its record
            continue
        labs.append(cast(ServedLabRecord, data))        # its shape checked above
    return sorted(labs, key=lambda d: -float(d.get("started") or 0.0))


def served_lab() -> ServedLabRecord:
    """The newest running ``labkit lab serve`` (its record), or InputError when none runs."""
    labs = served_labs()
    if not labs:
        raise InputError("no virtual lab is being served", key="--lab",
                         expected="a running 'labkit lab serve' (or give a CONFIG)")
    return labs[0]
