"""Exit codes that hold under repeated signals, at start-up, and after a run has completed.

Real ``labkit`` processes against a virtual lab served from this one; signals at seeded
random instants.
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
import pytest
from labcfg import inchip_toml, on_lab_resources, wait_points

from clihelpers import REPO
from labkit.lab import VirtualLab

STOPS = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT]


@pytest.fixture(scope="module")
def lab():
    with VirtualLab(seed=7) as lab:
        yield lab


def _config(tmp_path: Path, lab: VirtualLab, freqs=(600.0, 900.0, 1300.0, 1800.0, 2400.0, 3000.0)) -> Path:
    cfg = inchip_toml(tmp_path / "c.toml", freqs, locations=("hip",), settle_s=0.03, dwell_cycles=15)
    return on_lab_resources(cfg, lab)


def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "labkit", *args], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))


def test_a_second_signal_while_exiting_keeps_exit_130(tmp_path, lab):
    """8 trials: a stop signal mid-run, then one or two more 0-40 ms later (while the drive is
    turned off and the error reported). Always exit 130, one error line, no traceback, output
    off (it was -3/-1/-2/-15 or a traceback in 7 of 8)."""
    cfg = _config(tmp_path, lab)
    rng = random.Random(60)
    for trial in range(8):
        out = tmp_path / f"run{trial}.h5"
        proc = _start("sweep", "inchip", str(cfg), "--out", str(out), "--quiet")
        try:
            wait_points(out, 1, proc)
            proc.send_signal(rng.choice(STOPS))
            for _ in range(rng.choice((1, 2))):
                time.sleep(rng.uniform(0.0, 0.04))
                if proc.poll() is None:
                    proc.send_signal(rng.choice(STOPS))
            _, err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert proc.returncode == 130 and "Traceback" not in err, (trial, proc.returncode, err)
        lines = [ln for ln in err.strip().splitlines() if not ln.startswith("labkit: warning:")]
        assert len(lines) == 1 and "interrupted by" in lines[0], (trial, err)
        assert "DC on the PZT" not in err            # the bursts rest at 0 V (test_burst_idle.py)
        assert lab.output_state("funcgen", 1) is False
        with h5py.File(out, "r") as f:
            assert str(f.attrs["status"]).startswith("interrupted")


def _python_start_s() -> float:
    """How long this interpreter takes to start (site and all) and exit: the slowest of 3."""
    times = []
    for _ in range(3):
        t0 = time.monotonic()
        subprocess.run([sys.executable, "-c", "pass"], check=True)
        times.append(time.monotonic() - t0)
    return max(times)


def test_a_signal_at_start_up_is_exit_130(tmp_path):
    """16 trials: SIGINT or SIGTERM at a random instant of labkit's first 150 ms (after the
    interpreter's own start-up, measured first). Every one that reaches labkit exits 130 with
    one line (a signal in the imports was a traceback). One that lands in Python's own
    start-up after all (the machine is loaded) is Python's: SIGTERM kills (-15), SIGINT is a
    KeyboardInterrupt traceback with no labkit frame past the package's first lines, where
    its handlers are installed; nothing of labkit ran, nothing was sent."""
    target = tmp_path / "c.toml"
    target.write_text("[run]\n")
    rng = random.Random(61)
    start_s = _python_start_s()
    codes = []
    for trial in range(16):
        sig = rng.choice((signal.SIGINT, signal.SIGTERM))
        proc = _start("info", str(target))
        time.sleep(start_s + rng.uniform(0.0, 0.15))
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
        codes.append(proc.returncode)
        if proc.returncode == 130:
            assert "Traceback" not in err and len(err.strip().splitlines()) == 1 and "interrupted by" in err, err
        elif "Traceback" in err or proc.returncode == -sig:     # Python's start-up, before labkit
            frames = [ln for ln in err.splitlines() if str(REPO / "labkit") in ln]
            assert all("labkit/__init__.py" in ln for ln in frames), (trial, err)
        else:
            assert proc.returncode == 0 and err == "", (trial, proc.returncode, err)   # too late: info done
    assert sum(c == 130 for c in codes) >= 8, (start_s, codes)


def test_a_stop_after_the_run_completed_exits_0_and_says_complete(tmp_path, lab):
    """SIGTERM once the run file says complete (while labkit stores the lab's record and
    reports): exit 0, "arrived after the run had completed" (it printed "interrupted" and
    exited 130, though the file said complete)."""
    cfg = _config(tmp_path, lab, freqs=(900.0, 1500.0))
    alive = 0
    for trial in range(4):
        out = tmp_path / f"run{trial}.h5"
        proc = _start("sweep", "inchip", str(cfg), "--lab", "--out", str(out), "--quiet", "--json")
        deadline = time.monotonic() + 120
        while proc.poll() is None and time.monotonic() < deadline:
            try:
                with h5py.File(out, "r", locking=False) as f:
                    if f.attrs.get("status") == "complete":
                        break
            except (OSError, KeyError):
                pass
            time.sleep(0.002)
        alive += proc.poll() is None
        proc.send_signal(signal.SIGTERM)
        stdout, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, (trial, proc.returncode, err)
        assert "interrupted" not in err and "Traceback" not in err, (trial, err)
        assert '"status": "complete"' in stdout.strip().splitlines()[-1], stdout
    assert alive >= 2, alive          # the signal reached a running labkit (its file said complete)


def test_a_stop_dropped_where_python_cannot_raise_prints_no_traceback(monkeypatch):
    """A stop signal's exception raised inside a weakref callback (``labkit report`` met it mid-run)
    is dropped by Python, which printed "Exception ignored ... Traceback"; the command stops all the
    same (``check_stop``), so that is silenced; any other dropped exception still reaches the hook."""
    import gc
    import weakref

    from labkit.errors import Interrupted
    from labkit.experiments import safety

    seen: list[BaseException] = []
    with safety.signals_raise():
        assert sys.unraisablehook is safety._stop_unraisable
        monkeypatch.setattr(safety, "_UNRAISABLE", [lambda u: seen.append(u.exc_value)])

        class Thing:
            pass

        def stop(_ref):
            raise Interrupted("SIGTERM")

        def other(_ref):
            raise ValueError("shown")

        a, b = Thing(), Thing()
        refs = [weakref.ref(a, stop), weakref.ref(b, other)]
        del a, b
        gc.collect()
    assert [type(e) for e in seen] == [ValueError] and len(refs) == 2
