"""Damaged and busy files are named for what they are: truncated, corrupt (which dataset), being written (by whom).

Every case is the real ``labkit`` in a subprocess on a real HDF5 file: exit 2, one line on
standard error, never a traceback.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time

import h5py
import pytest

from clihelpers import REPO, run_cli
from labkit.experiments import runfile as rf
from labkit.experiments.config import comparable, load_inchip

INCHIP = REPO / "sample_data" / "inchip.toml"


def make_run(path, n=12):
    """A finished in-chip run file with ``n`` points at the body (what a run writes, point by point)."""
    cfg = load_inchip(INCHIP)
    with rf.RunFile.create(path, cfg, comparable(cfg), 180) as run:
        for i in range(n):
            run.add_location_rows("body", {"freq_hz": 300.0 + i, "frf": 1 + 2j, "quality": 0.99,
                                           "drive_v": 2 + 0j, "velocity_mm_s": 2 + 4j, "point_index": i})
            run.end_point(i, {"location": "body", "freq_hz": 300.0 + i, "status": "ok", "reason": "",
                              "time_unix_s": 1.0, "duration_s": 0.1})
        run.finish("complete")
    return path


def one_line_error(proc, *words):
    """Exit 2, one line on stderr naming every word, no traceback."""
    err = proc.stderr.strip()
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and len(err.splitlines()) == 1, proc.stderr
    for w in words:
        assert w in err, err
    return err


@pytest.mark.parametrize("keep", [96, 800, 0.5])
def test_a_truncated_run_file_is_called_truncated_by_info_resume_fit_and_report(tmp_path, keep):
    good = make_run(tmp_path / "good.h5")
    data = good.read_bytes()
    n = int(len(data) * keep) if isinstance(keep, float) else keep
    cut = tmp_path / "cut.h5"
    cut.write_bytes(data[:n])
    err = one_line_error(run_cli("info", str(cut), check=None), "truncated", f"{n} bytes", str(cut))
    assert "being written" not in err
    one_line_error(run_cli("sweep", "inchip", str(INCHIP), "--resume", str(cut), check=None), "truncated")
    one_line_error(run_cli("fit", str(cut), "--out", str(tmp_path / "r.toml"), check=None), "truncated")
    one_line_error(run_cli("report", "--runs", str(cut), "--no-simulate", "--out", str(tmp_path / "rep"),
                           check=None), "truncated")
    assert not (tmp_path / "r.toml").exists()


def test_an_empty_file_is_truncated_not_busy(tmp_path):
    p = tmp_path / "empty.h5"
    p.write_bytes(b"")
    one_line_error(run_cli("info", str(p), check=None), "truncated: 0 bytes")


def test_a_flipped_bit_in_a_stored_dataset_names_the_dataset(tmp_path):
    path = make_run(tmp_path / "run.h5")
    with h5py.File(path, "r") as f:
        ds = f["points/index"]
        assert ds.fletcher32            # every stored dataset carries a checksum
        at = ds.id.get_chunk_info(0).byte_offset
    data = bytearray(path.read_bytes())
    data[at + 3] ^= 0x10            # point 0 becomes point 4096: without a checksum, accepted
    path.write_bytes(bytes(data))
    for args in (("info", str(path)), ("sweep", "inchip", str(INCHIP), "--resume", str(path)),
                 ("fit", str(path), "--out", str(tmp_path / "r.toml"))):
        one_line_error(run_cli(*args, check=None), "corrupt", "/points/index", "checksum")


_HOLD = """
import sys, time, h5py
from labkit.experiments.locks import lock_run
with lock_run([], sys.argv[1], "a.toml"), h5py.File(sys.argv[1], "a"):
    print("held", flush=True)
    time.sleep(60)
"""
_HOLD_HDF5_ONLY = """
import sys, time, h5py
with h5py.File(sys.argv[1], "a"):
    print("held", flush=True)
    time.sleep(60)
"""


def _holder(code, path):
    proc = subprocess.Popen([sys.executable, "-c", code, str(path)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "held"
    return proc


def test_a_file_being_written_names_its_writer_from_the_lock_file(tmp_path):
    path = make_run(tmp_path / "run.h5")
    proc = _holder(_HOLD, path)
    try:
        one_line_error(run_cli("fit", str(path), "--out", str(tmp_path / "r.toml"), check=None),
                       f"being written by PID {proc.pid}")
        info = run_cli("info", str(path), check=0)
        assert f"being written by PID {proc.pid}" in info.stdout
        one_line_error(run_cli("sweep", "inchip", str(INCHIP), "--resume", str(path), check=None),
                       f"PID {proc.pid}", "in use by another run")
    finally:
        proc.kill()
        proc.wait()
    # another program (no labkit lock) holding HDF5's own file lock is not called a labkit run
    proc = _holder(_HOLD_HDF5_ONLY, path)
    try:
        err = one_line_error(run_cli("fit", str(path), "--out", str(tmp_path / "r.toml"), check=None),
                             "another program")
        assert "PID" not in err
    finally:
        proc.kill()
        proc.wait()


def test_a_closed_pipe_is_not_a_traceback(tmp_path):
    path = make_run(tmp_path / "run.h5")
    r, w = os.pipe()
    os.close(r)                     # the reader has gone (``labkit info FILE | head`` after head exits)
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "labkit", "info", str(path)], stdout=w,
                          stderr=subprocess.PIPE, text=True, timeout=120)
    os.close(w)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "", proc.stderr
    assert time.monotonic() - t0 < 120
    head = subprocess.run(f"{sys.executable} -m labkit info {path} | head -1", shell=True,
                          capture_output=True, text=True, timeout=120)
    assert head.stdout.startswith(str(path)) and head.stderr == "", head.stderr
