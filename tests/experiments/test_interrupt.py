"""Real signals on a real ``labkit`` subprocess running against its in-process virtual lab.

SIGINT and SIGTERM mid-sweep: exit 130, the lab's own record shows the drive
going off right after the signal, the file is readable and ``--resume``
completes it with every point exactly once. SIGKILL: the file still opens and
holds every completed point, and resumes too.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
from labcfg import inchip_toml, lab_timeline, wait_points

from clihelpers import REPO, last_json, run_cli
from labkit.commands.info import summarise_h5
from labkit.experiments.session import run_session

FREQS = [float(f) for f in np.round(np.geomspace(400, 4000, 12), 2)]
LOCS = ("body", "knee")


def _start(cfg, out):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "labkit", "sweep", "inchip", str(cfg), "--out", str(out),
                             "--lab", "--json"], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)


def _check_complete_once(out):
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "complete"
        idx = f["points/index"][...]
        assert sorted(idx) == list(range(len(FREQS) * len(LOCS)))      # every point, none twice
        for loc in LOCS:
            assert list(f[f"locations/{loc}/freq_hz"][...]) == FREQS
            assert np.all(np.isfinite(f[f"locations/{loc}/frf"][...]))
        return len(f["events/text"])


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_mid_sweep_turns_drive_off_and_resume_completes(tmp_path, sig):
    cfg = inchip_toml(tmp_path / "c.toml", FREQS, locations=LOCS, settle_s=0.03, dwell_cycles=20)
    out = tmp_path / "run.h5"
    proc = _start(cfg, out)
    try:
        wait_points(out, 4, proc)
        t_sig = time.monotonic()
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 130, stderr
    name = signal.Signals(sig).name
    assert f"interrupted by {name}" in stderr and "Traceback" not in stderr
    assert last_json(subprocess.CompletedProcess([], 130, stdout, stderr))["ok"] is False
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == f"interrupted: {name}"
        n = f["points/index"].shape[0]
        assert 4 <= n < len(FREQS) * len(LOCS)
        rows = sum(f[f"locations/{loc}/freq_hz"].shape[0] for loc in LOCS)
        assert rows == n                                     # no half-written point
        t, on = lab_timeline(f)
        assert on.any() and not on[-1]
        # the drive was on when the signal came and went off within half a second of it
        before = on[t <= t_sig]
        assert before[-1], "drive was not on at the signal"
        t_off = t[(t > t_sig) & ~on]
        assert len(t_off) and t_off[0] - t_sig < 0.5, t_off
        assert any("run ended: interrupted" in e for e in f["events/text"].asstr()[...])
    if sig == signal.SIGINT:        # the CLI's --resume, in a subprocess
        summary = last_json(run_cli("sweep", "inchip", str(cfg), "--resume", str(out), "--lab", "--json"))
    else:                           # the same code path in-process (saves a Python start-up)
        summary = run_session("inchip", cfg, None, resume=out, lab=True, quiet=True)
    assert summary["status"] == "complete" and summary["points_done"] == len(FREQS) * len(LOCS)
    _check_complete_once(out)


@pytest.mark.slow
def test_sigkill_leaves_every_completed_point(tmp_path):
    cfg = inchip_toml(tmp_path / "c.toml", FREQS, locations=LOCS, settle_s=0.03, dwell_cycles=20)
    out = tmp_path / "run.h5"
    proc = _start(cfg, out)
    try:
        wait_points(out, 5, proc)
        time.sleep(0.07)                 # land anywhere in a point
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == -signal.SIGKILL
    info = summarise_h5(out)                  # what `labkit info` prints
    assert info["kind"] == "run_inchip" and info["attrs"]["status"] == "running"
    with h5py.File(out, "r") as f:
        idx = f["points/index"][...]
        assert len(idx) >= 5 and list(idx) == list(range(len(idx)))
        body = f["locations/body"]
        n_body = int(np.sum(idx < len(FREQS)))
        # every completed point is there, whole (a row past the index may only be the cut point)
        assert body["freq_hz"].shape[0] in (n_body, n_body + 1)
        assert list(body["freq_hz"][:n_body]) == FREQS[:n_body]
        assert np.all(np.abs(body["frf"][:n_body]) > 0)
    summary = run_session("inchip", cfg, None, resume=out, lab=True, quiet=True)
    assert summary["status"] == "complete"
    _check_complete_once(out)


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_a_stop_whose_exception_python_dropped_still_stops():
    """Python runs a signal's handler in whatever code runs then; raised inside a ``__del__``
    or a weakref callback (the import system's lock clean-up, at a command's start) the
    exception is printed and dropped. The signal is remembered: the next check_stop (before
    every point, and when a command returns) raises it; once handled it is forgotten."""
    import gc

    from labkit.errors import Interrupted
    from labkit.experiments.safety import check_stop, raise_stop_signal, stop_handled

    class Dropper:
        def __del__(self):
            raise_stop_signal(signal.SIGQUIT, None)     # "Exception ignored in ..." and gone

    d = Dropper()
    del d
    gc.collect()
    with pytest.raises(Interrupted) as exc:
        check_stop()
    assert exc.value.signame == "SIGQUIT"
    check_stop()                                # raised once, then forgotten
    with pytest.raises(KeyboardInterrupt):
        raise_stop_signal(signal.SIGINT, None)
    stop_handled()                              # caught and acted on: nothing left behind
    check_stop()
