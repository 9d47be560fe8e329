"""Fault injection: a full disk, a kill and flipped bits at random instants, on real processes and files.

``labkit sweep inchip`` runs in its own process against a virtual lab served from this
one (real TCP sockets and a pty). The disk-full trials write on a 24 MB tmpfs mounted for
the test (CI runs as root on a fresh clone; a size-limited mount needs root, and without
it the suite fails rather than skips). Each trial draws its instant from a seeded
generator, so a failure names a reproducible trial. About 2 minutes in all.
"""
from __future__ import annotations

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


@pytest.fixture(scope="module")
def lab():
    with VirtualLab(seed=11) as lab:
        yield lab


@pytest.fixture(scope="module")
def small_fs(tmp_path_factory):
    """A 24 MB tmpfs of its own (mounted as root; CI is root)."""
    with small_tmpfs(tmp_path_factory.mktemp("smallfs"), "24m") as mnt:
        yield mnt


def config(folder: Path, lab: VirtualLab, keep_raw: bool = False) -> Path:
    cfg = inchip_toml(folder / "c.toml", FREQS, locations=("hip",), settle_s=0.02, dwell_cycles=12,
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


def assert_whole(out: Path, lab: VirtualLab) -> None:
    """The run file is complete: every planned point measured once, each FRF near the lab's truth."""
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "complete", f.attrs["status"]
        idx = f["points/index"][...]
        assert sorted(idx.tolist()) == list(range(len(FREQS))), idx
        frf = f["locations/hip/frf"][...]
        freq = f["locations/hip/freq_hz"][...]
    assert sorted(freq.tolist()) == FREQS
    truth = lab.frf("hip", freq)
    assert np.all(np.abs(np.abs(frf) / np.abs(truth) - 1) < 0.15)


def resume_or_rerun(cfg: Path, out: Path, lab: VirtualLab) -> None:
    """What a person does after the fault: --resume the file (or start again when none was made)."""
    if out.exists():
        info = summarise_h5(out)           # readable (InputError would fail the trial)
        assert info["attrs"]["status"] != "complete" or info["attrs"]["points_planned"] == len(FREQS)
        if info["attrs"]["status"] != "complete":
            summary = run_session("inchip", cfg, None, resume=out, quiet=True)
            assert summary["status"] == "complete"
    else:
        run_session("inchip", cfg, out, quiet=True)
    assert_whole(out, lab)
    assert not list(out.parent.glob(".*.partial.*")), "a temporary file was left"


def test_disk_full_at_random_instants_no_crash_no_lost_point(tmp_path, lab, small_fs):
    """20 trials: another process fills the run file's file system to the last byte at a random
    instant (start-up included). labkit never crashes: exit 0 (the run's space was set aside
    before the first point, so the run completes) or exit 2 naming the disk (nothing sent
    yet, or the run stopped cleanly); the file always opens and its final status is written;
    after freeing space the run completes with every point."""
    cfg = config(tmp_path, lab)
    rng = random.Random(30)
    outcomes = {0: 0, 2: 0}
    for trial in range(20):
        out = small_fs / f"run{trial}.h5"
        delay = rng.uniform(0.0, 2.5)
        proc = start(cfg, out)
        time.sleep(delay)
        st = os.statvfs(small_fs)
        filler = small_fs / "filler"
        try:                    # the run may have taken the last block already: then it is full
            with open(filler, "wb") as fh:
                fh.write(b"\0" * (st.f_bavail * st.f_frsize))
        except OSError:
            pass
        _, err = proc.communicate(timeout=120)
        assert proc.returncode in (0, 2) and "Traceback" not in err, (trial, delay, proc.returncode, err)
        outcomes[proc.returncode] += 1
        if proc.returncode == 2:
            assert "room" in err, (trial, err)
        if out.exists():
            status = summarise_h5(out)["attrs"]["status"]
            assert status != "running", (trial, delay, status)      # the final status is always written
        filler.unlink(missing_ok=True)
        resume_or_rerun(cfg, out, lab)
        for left in small_fs.iterdir():       # the run file and what lives beside it (its live stream)
            left.unlink()
    assert outcomes[0] >= 5, outcomes          # most fills come after the space was set aside


@pytest.mark.parametrize("early", [True, False])
def test_a_kill_at_random_instants_leaves_a_readable_resumable_file(tmp_path, lab, early):
    """2 x 10 trials of SIGKILL: within the first 100 ms after the run file appears (``early``),
    or anywhere in the run. Every file left opens (``labkit info``: exit 0), and ``--resume``
    completes it with every point; a kill before the file appeared leaves no file (and no
    temporary one once the next run starts)."""
    cfg = config(tmp_path, lab)
    rng = random.Random(31 + early)
    for trial in range(10):
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
