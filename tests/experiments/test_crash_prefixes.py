"""A crash at every instant of a real run: each prefix of its disk writes reads as of a flush.

A SIGKILL stops a process between two system calls: what is on disk is a prefix of the
writes it made (the page cache keeps them). So instead of killing at random instants and
hoping to land inside a flush (tests/experiments/test_faults.py does that too), this
records every ``pwrite``/``pwritev``/``ftruncate`` a real in-chip sweep against the virtual lab makes to
its run file and journal (at :mod:`labkit.h5journal`'s ``os``, the edge of the disk), then
rebuilds the two files after each prefix and opens them as ``labkit info`` does: read-only
(a committed journal overlaid) and after :func:`labkit.h5journal.recover`. Every prefix must
open, list every dataset, verify every checksum, and hold a number of complete points that
never falls as the prefix grows. Without the journal (HDF5 writing in place, as its own
driver does) the same check finds unreadable prefixes: the test can fail.
"""
from __future__ import annotations

import os
import types
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from labcfg import inchip_toml, on_lab_resources

import labkit.experiments.runfile as rf
import labkit.h5journal as hj
from labkit.commands.info import summarise_h5
from labkit.errors import InputError
from labkit.experiments.session import run_session
from labkit.lab import VirtualLab


@dataclass
class DiskLog:
    """Every write to the run file (``main``) and its journal, in order; ``link`` when the file appeared."""

    writes: list[tuple[str, str, int, bytes]] = field(default_factory=list)
    fds: dict[int, str] = field(default_factory=dict)

    def os_module(self) -> types.ModuleType:
        log, real = self, os

        class Recording(types.ModuleType):
            def __getattr__(self, name):
                return getattr(real, name)

            def open(self, path, flags, mode=0o777):
                fd = real.open(path, flags, mode)
                log.fds[fd] = "journal" if str(path).endswith(".journal") else "main"
                if flags & real.O_TRUNC:
                    log.writes.append((log.fds[fd], "t", 0, b""))
                return fd

            def pwrite(self, fd, data, off):
                log.writes.append((log.fds[fd], "w", off, bytes(data)))
                return real.pwrite(fd, data, off)

            def pwritev(self, fd, buffers, off):          # one system call: a kill cannot split it
                data = b"".join(bytes(b) for b in buffers)
                log.writes.append((log.fds[fd], "w", off, data))
                return real.pwrite(fd, data, off)

            def ftruncate(self, fd, n):
                log.writes.append((log.fds[fd], "t", n, b""))
                return real.ftruncate(fd, n)

        return Recording("os")


def record_run(tmp_path: Path, monkeypatch, keep_raw: bool) -> DiskLog:
    tmp_path.mkdir()
    log = DiskLog()
    monkeypatch.setattr(hj, "os", log.os_module())
    link = rf._link_into_place

    def linked(tmp, path):
        log.writes.append(("link", "", 0, b""))
        link(tmp, path)

    monkeypatch.setattr(rf, "_link_into_place", linked)
    with VirtualLab(seed=11) as lab:
        cfg = inchip_toml(tmp_path / "c.toml", [800.0, 1200.0, 1800.0], locations=("hip",), settle_s=0.02,
                          dwell_cycles=12, keep_raw=keep_raw)
        run_session("inchip", on_lab_resources(cfg, lab), tmp_path / "run.h5", quiet=True)
    monkeypatch.undo()
    return log


def _apply(image: bytearray, kind: str, off: int, data: bytes) -> None:
    if kind == "w":
        if len(image) < off + len(data):
            image.extend(bytes(off + len(data) - len(image)))
        image[off: off + len(data)] = data
    else:
        del image[off:]
        image.extend(bytes(off - len(image)))


def prefixes(log: DiskLog):
    """``(k, main bytes, journal bytes or None)`` for every prefix from the file's appearance on."""
    images = {"main": bytearray(), "journal": bytearray()}
    journal_made = False
    linked = next(i for i, w in enumerate(log.writes) if w[0] == "link")
    for k, (name, kind, off, data) in enumerate(log.writes):
        if k >= linked:
            yield k, bytes(images["main"]), bytes(images["journal"]) if journal_made else None
        if name != "link":
            _apply(images[name], kind, off, data)
            journal_made |= name == "journal"
    yield len(log.writes), bytes(images["main"]), bytes(images["journal"]) if journal_made else None


def points_after_crash(folder: Path, main: bytes, journal: bytes | None, recover: bool) -> int:
    """Complete points ``labkit info`` reads in the files a crash left (InputError if it cannot)."""
    path = folder / "run.h5"
    path.write_bytes(main)
    hj.journal_path(path).unlink(missing_ok=True)
    if journal is not None:
        hj.journal_path(path).write_bytes(journal)
    if recover:
        hj.recover(path)
    info = summarise_h5(path)
    content = info.get("content", {})
    if "error" in content:                  # the typed reader (labkit.open) failed on a listed file
        raise InputError(str(content["error"]), file=path)
    return next(int(d["shape"][0]) for d in info["datasets"] if d["name"] == "points/index")


@pytest.mark.parametrize("keep_raw", [False, True])
def test_every_crash_instant_leaves_a_file_as_of_a_flush(tmp_path, monkeypatch, keep_raw):
    log = record_run(tmp_path / "rec", monkeypatch, keep_raw)
    check = tmp_path / "check"
    check.mkdir()
    seen = {False: 0, True: 0}
    n = 0
    for k, main, journal in prefixes(log):
        for recover in (False, True):
            try:
                points = points_after_crash(check, main, journal, recover)
            except InputError as exc:
                pytest.fail(f"a crash after write {k} of {len(log.writes)} left {exc}")
            assert points >= seen[recover], (k, recover, points, seen)
            seen[recover] = points
        n += 1
    assert n > 100 and seen == {False: 3, True: 3}, (n, seen)


def test_without_the_journal_the_same_check_finds_unreadable_files(tmp_path, monkeypatch):
    """HDF5 writing in place (the journal never started): some crash instants leave no readable file."""
    monkeypatch.setattr(hj.JournalIO, "start_journal", lambda self, path=None, reserve_bytes=0.0: None)
    log = record_run(tmp_path / "rec", monkeypatch, keep_raw=False)
    assert not any(w[0] == "journal" for w in log.writes)
    check = tmp_path / "check"
    check.mkdir()
    broken = []
    for k, main, journal in prefixes(log):
        try:
            points_after_crash(check, main, journal, recover=False)
        except InputError as exc:
            broken.append((k, str(exc)))
    assert broken and all("corrupt" in why or "truncated" in why for _, why in broken), broken[:3]
