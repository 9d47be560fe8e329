"""Fault injection: a full disk, a kill and flipped bits at random instants, on real processes and files.

``labkit sweep inchip`` runs in its own process against a virtual lab served from this
one (real TCP sockets and a pty). The disk-full trials write on a 24 MB tmpfs mounted for
the test (CI runs as root on a fresh clone; a size-limited mount needs root, and without
it the suite fails rather than skips). Each trial draws its instant from a seeded
generator, so a failure names a reproducible trial. About 2 minutes in all.
"""
from __future__ import annotations

import contextlib
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from labcfg import inchip_toml, on_lab_resources, small_tmpfs

from clihelpers import REPO
from labkit.commands.info import summarise_h5
from labkit.errors import InputError
from labkit.experiments.session import run_session
from labkit.lab import VirtualLab

FREQS = [800.0, 1200.0, 1800.0, 2500.0]
#: the disk-full trials' plan: long enough that the disk fills with points still to measure
LONG = [700.0, 900.0, 1100.0, 1300.0, 1600.0, 1900.0, 2200.0, 2500.0]


@pytest.fixture(scope="module")
def lab():
    with VirtualLab(seed=11) as lab:
        yield lab


@pytest.fixture(scope="module")
def small_fs(tmp_path_factory):
    """A 24 MB tmpfs of its own (mounted as root; CI is root)."""
    with small_tmpfs(tmp_path_factory.mktemp("smallfs"), "24m") as mnt:
        yield mnt


def config(folder: Path, lab: VirtualLab, keep_raw: bool = False, freqs: list[float] = FREQS) -> Path:
    cfg = inchip_toml(folder / "c.toml", freqs, locations=("hip",), settle_s=0.02, dwell_cycles=12,
                      keep_raw=keep_raw)
    return on_lab_resources(cfg, lab)


def start(cfg: Path, out: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "labkit", "sweep", "inchip", str(cfg), "--out", str(out),
                             "--quiet"], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))


def wait_file(path: Path, proc: subprocess.Popen, timeout_s: float = 60.0) -> bool:
    """Until ``path`` exists (True) or the process ends (False)."""
    deadline = time.monotonic() + timeout_s
    while not path.exists():
        if proc.poll() is not None:
            return False
        assert time.monotonic() < deadline, "no run file"
        time.sleep(0.001)
    return True


def points_in(path: Path) -> int:
    """Complete points in a run file another process is writing (0 while it cannot be read)."""
    with contextlib.suppress(Exception), h5py.File(path, "r", locking=False) as f:
        return len(f["points/index"])
    return 0


def assert_whole(out: Path, lab: VirtualLab, freqs: list[float] = FREQS) -> None:
    """The run file is complete: every planned point measured once, each FRF near the lab's truth."""
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "complete", f.attrs["status"]
        idx = f["points/index"][...]
        assert sorted(idx.tolist()) == list(range(len(freqs))), idx
        frf = f["locations/hip/frf"][...]
        freq = f["locations/hip/freq_hz"][...]
    assert sorted(freq.tolist()) == freqs
    truth = lab.frf("hip", freq)
    assert np.all(np.abs(np.abs(frf) / np.abs(truth) - 1) < 0.15)


def resume_or_rerun(cfg: Path, out: Path, lab: VirtualLab, freqs: list[float] = FREQS) -> None:
    """What a person does after the fault: --resume the file (or start again when none was made)."""
    if out.exists():
        info = summarise_h5(out)           # readable (InputError would fail the trial)
        assert info["attrs"]["status"] != "complete" or info["attrs"]["points_planned"] == len(freqs)
        if info["attrs"]["status"] != "complete":
            summary = run_session("inchip", cfg, None, resume=out, quiet=True)
            assert summary["status"] == "complete"
    else:
        run_session("inchip", cfg, out, quiet=True)
    assert_whole(out, lab, freqs)
    assert not list(out.parent.glob(".*.partial.*")), "a temporary file was left"


def fill(folder: Path) -> Path:
    """Another process's file takes every free byte of ``folder``'s file system (it may be full already)."""
    st = os.statvfs(folder)
    filler = folder / "filler"
    with contextlib.suppress(OSError), open(filler, "wb") as fh:
        fh.write(b"\0" * (st.f_bavail * st.f_frsize))
    return filler


def test_disk_full_at_random_instants_no_crash_no_lost_point(tmp_path, lab, small_fs):
    """20 trials: another process fills the run file's file system to the last byte at a random
    instant mid-run: after a random number (1 to 4) of the 8 points is in the file, plus a random
    delay, so that every trial meets a full disk with points still to measure whatever the
    machine's load. labkit never crashes: the run's space was set aside before its first point, so
    it completes (exit 0); the file
    opens, its final status is written, no completed point is lost, and after freeing space it
    reads whole. (Where space cannot be set aside, the room checks stop a run cleanly with exit 2
    naming the disk: tests/experiments/test_bench_safety.py.)"""
    cfg = config(tmp_path, lab, freqs=LONG)
    rng = random.Random(30)
    for trial in range(20):
        out = small_fs / f"run{trial}.h5"
        after, delay = rng.randint(1, 4), rng.uniform(0.0, 0.1)
        proc = start(cfg, out)
        while points_in(out) < after:
            assert proc.poll() is None, (trial, proc.communicate())
            time.sleep(0.005)
        time.sleep(delay)
        before = points_in(out)
        filler = fill(small_fs)
        assert os.statvfs(small_fs).f_bavail * os.statvfs(small_fs).f_frsize < 64 * 1024      # full
        assert before < len(LONG), (trial, before)          # mid-run: points still to measure
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 0 and "Traceback" not in err, (trial, after, delay, proc.returncode, err)
        info = summarise_h5(out)
        assert info["attrs"]["status"] == "complete", (trial, info["attrs"]["status"])
        assert points_in(out) == len(LONG), (trial, before)       # nothing lost, nothing doubled
        filler.unlink(missing_ok=True)
        resume_or_rerun(cfg, out, lab, LONG)
        for left in small_fs.iterdir():       # the run file and what lives beside it (its live stream)
            left.unlink()


@pytest.mark.parametrize("early", [True, False])
def test_a_kill_at_random_instants_leaves_a_readable_resumable_file(tmp_path, lab, early):
    """20 trials of SIGKILL within the first 100 ms after the run file appears (``early``), and
    10 anywhere in the run. Every file left opens (``labkit info``: exit 0), and ``--resume``
    completes it with every point; a kill before the file appeared leaves no file (and no
    temporary one once the next run starts)."""
    cfg = config(tmp_path, lab)
    rng = random.Random(31 + early)
    for trial in range(20 if early else 10):
        out = tmp_path / f"run{trial}.h5"
        proc = start(cfg, out)
        if early:
            made = wait_file(out, proc)
            time.sleep(rng.uniform(0.0, 0.1))
        else:
            made = True
            time.sleep(rng.uniform(0.0, 3.0))
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=60)
        assert made or proc.returncode == 0
        if out.exists():
            info = subprocess.run([sys.executable, "-m", "labkit", "info", str(out)], cwd=REPO,
                                  capture_output=True, text=True, timeout=60)
            assert info.returncode == 0 and "Traceback" not in info.stderr, (trial, info.stderr)
        resume_or_rerun(cfg, out, lab)


def _stored_chunks(path: Path) -> list[tuple[str, int, int]]:
    """``(dataset, byte offset, size)`` of every stored chunk of a checksummed dataset."""
    out = []
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and obj.fletcher32 and obj.size:
                for i in range(obj.id.get_num_chunks()):
                    ci = obj.id.get_chunk_info(i)
                    out.append((name, ci.byte_offset, ci.size))
        f.visititems(visit)
    return out


def test_flipped_bits_exit_2_naming_the_dataset(tmp_path, lab):
    """20 random bit flips in the stored data of a real run file (measured FRFs, indices, times,
    kept records): ``labkit info`` and ``fit`` exit 2 naming the dataset hit, never a traceback,
    and ``--resume`` refuses the file the same way."""
    cfg = config(tmp_path, lab, keep_raw=True)
    good = tmp_path / "good.h5"
    run_session("inchip", cfg, good, quiet=True)
    chunks = _stored_chunks(good)
    names = {c[0] for c in chunks}
    assert {"points/index", "locations/hip/frf", "raw/p00000/velocity_v"} <= names, names
    data = good.read_bytes()
    rng = random.Random(32)
    for trial in range(20):
        name, at, size = rng.choice(chunks)
        byte = at + rng.randrange(size)
        bad = bytearray(data)
        bad[byte] ^= 1 << rng.randrange(8)
        path = tmp_path / f"flip{trial}.h5"
        path.write_bytes(bytes(bad))
        args = ("info", str(path)) if trial % 2 else ("fit", str(path), "--out", str(tmp_path / "r.toml"))
        proc = subprocess.run([sys.executable, "-m", "labkit", *args], cwd=REPO, capture_output=True, text=True,
                              timeout=120)
        err = proc.stderr.strip()
        assert proc.returncode == 2 and "Traceback" not in err and len(err.splitlines()) == 1, (trial, err)
        assert f"corrupt: dataset /{name} fails its checksum" in err, (trial, name, err)
        with pytest.raises(InputError, match=f"/{name}"):
            run_session("inchip", cfg, None, resume=path, quiet=True)
        path.unlink()
