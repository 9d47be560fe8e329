"""Where run locks live and who holds one (base layer: read by ``labkit.h5io`` too).

A run takes an exclusive ``flock`` on one small file per instrument (its normalised
resource, and once connected its ``*IDN?`` identity) and per run file
(:mod:`labkit.experiments.locks`), in one folder shared by every user of the machine
(:data:`LOCK_DIR`, sticky and world-writable like ``/tmp``; the lock files are readable and
writable by all, so one user's run keeps another's off the rig). The file holds the holder's
PID, host, command and run file as JSON. This module only finds those files and reads who
holds one, so that anything that meets a file being written (``labkit.open``, ``labkit
info``, ``--resume``) can name the run writing it.
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import os
import re
from pathlib import Path
from typing import TypedDict, cast

from labkit.jsonutil import Json


class LockRecord(TypedDict, total=False):
    """What a lock file holds (JSON): who holds it and for what (``pid`` is ``"?"`` when unreadable)."""

    pid: int | str
    host: str
    command: str
    run_file: str
    config: str
    since: str
    key: str


#: the one folder of run locks on this machine (not per user: two users' runs share the rig)
LOCK_DIR = Path("/tmp/labkit-locks")


def runtime_dir() -> Path:
    """The per-user folder of this user's records (a served lab's), created with mode 0700."""
    base = os.environ.get("XDG_RUNTIME_DIR")
    folder = Path(base) / "labkit" if base and Path(base).is_dir() else Path(f"/tmp/labkit-{os.getuid()}")
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    return folder


def lock_dir() -> Path:
    """:data:`LOCK_DIR`, created sticky and world-writable (mode 1777) when missing."""
    if not LOCK_DIR.is_dir():
        try:
            LOCK_DIR.mkdir(parents=True)
            os.chmod(LOCK_DIR, 0o1777)
        except FileExistsError:
            pass
    return LOCK_DIR


def lock_path(key: str) -> Path:
    """The lock file for a resource string or a run file's absolute path."""
    slug = re.sub(r"[^A-Za-z0-9._-]+", "_", key)[-60:]
    digest = hashlib.sha1(key.encode()).hexdigest()[:12]
    return lock_dir() / f"{slug}.{digest}.lock"


def file_key(path: str | Path) -> str:
    """The lock key of a run file (its real path)."""
    return "file:" + os.path.realpath(path)


def read_record(p: Path) -> dict[str, Json] | None:
    """The JSON object in a record file (a lock's, a served lab's), or None when it cannot be read."""
    try:
        data = json.loads(p.read_text() or "{}")
        return data if isinstance(data, dict) else None
    except (OSError, ValueError):
        return None


def read_lock(p: Path) -> LockRecord:
    """Who holds the lock file ``p``, as its record says (``{"pid": "?"}`` when it cannot be read)."""
    return cast(LockRecord, read_record(p) or {"pid": "?"})


def holder(key: str) -> LockRecord | None:
    """Who holds the lock on ``key`` now (its JSON record), or None when nobody does."""
    p = lock_path(key)
    if not p.exists():
        return None
    try:
        fd = os.open(p, os.O_RDONLY)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return read_lock(p)
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


def writer_of(path: str | Path) -> LockRecord | None:
    """The run writing ``path`` now (its lock record: ``pid``, ``host``, ``command``, ``since``), else None."""
    return holder(file_key(path))


def describe(info: LockRecord) -> str:
    """``PID 123 on bench-pc (labkit sweep inchip a.toml --out run.h5, run file run.h5, since 16:40:02)``."""
    parts = [f"PID {info.get('pid', '?')}" + (f" on {info['host']}" if info.get("host") else "")]
    extra = []
    if info.get("command"):
        extra.append(str(info["command"]))
    if info.get("run_file"):
        extra.append(f"run file {info['run_file']}")
    if info.get("since"):
        extra.append(f"since {info['since']}")
    return parts[0] + (f" ({', '.join(extra)})" if extra else "")
