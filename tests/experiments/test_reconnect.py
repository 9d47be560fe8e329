"""A link dropped mid-run is replaced within the reconnect window and the run goes on.

The lab serves its instruments in this process; ``labkit`` runs in another, against them,
as against a bench. The lab closes the socket of one instrument in the middle of a reply
(its ``drop`` fault: the peer shuts the connection down), as a pulled cable or a switch
that resets does. The run reconnects (``labkit.experiments.safety.RECONNECT_WINDOW_S``),
checks that the same instrument answers (``*IDN?``) and that the generator's output reads
off, and measures the interrupted point again: every point once, none twice. A link that
does not come back ends the run as before: drive off, exit 3, the file resumable.
"""
from __future__ import annotations

import subprocess
import sys
import time

import h5py
import pytest
from labcfg import wait_points
from test_bench_safety import FREQS, start, sweep_cfg

from clihelpers import REPO
from labkit.experiments.safety import RECONNECT_WINDOW_S
from labkit.lab import VirtualLab


@pytest.fixture(scope="module")
def lab():
    with VirtualLab(seed=11) as lab:
        yield lab


def _connections(lab: VirtualLab, instrument: str) -> int:
    """Handshakes the lab's ``instrument`` answered (each new link asks ``*IDN?`` first)."""
    return sum(1 for _, inst, kind, text in lab.log if inst == instrument and kind == "rx"
               and text.strip().upper() == "*IDN?")


def _run_with_drop(tmp_path, lab, instrument: str, count: int, after_points: int = 2):
    cfg, out = sweep_cfg(tmp_path, lab), tmp_path / "run.h5"
    proc = start(cfg, out)
    try:
        wait_points(out, after_points, proc)
        links = _connections(lab, instrument)
        lab.inject_fault(instrument, "drop", after=0, count=count)
        t_drop = time.monotonic()
        stdout, stderr = proc.communicate(timeout=180)
    finally:
        proc.kill()
        lab.clear_faults(instrument)
    return proc, stderr, out, cfg, links, t_drop


def _events(out) -> list[str]:
    with h5py.File(out, "r") as f:
        return [t.decode() if isinstance(t, bytes) else str(t) for t in f["events/text"][...]]


@pytest.mark.slow
@pytest.mark.parametrize("instrument", ["funcgen", "scope"])
def test_a_dropped_link_is_replaced_and_the_run_completes(tmp_path, lab, instrument):
    proc, stderr, out, _, links, _ = _run_with_drop(tmp_path, lab, instrument, count=1)
    assert proc.returncode == 0, stderr
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "complete"
        index = list(f["points/index"][...])
        assert sorted(index) == list(range(len(FREQS)))           # every point, none twice
        assert f["locations/hip/freq_hz"].shape[0] == len(FREQS)
        assert all(s == b"ok" or s == "ok" for s in f["points/status"][...])
    events = _events(out)
    assert any(f"the {instrument}'s link dropped" in e for e in events), events
    assert any(f"the {instrument} is back (same *IDN?)" in e for e in events), events
    assert _connections(lab, instrument) >= links + 1               # a new link was made
    assert lab.output_state("funcgen", 1) is False


@pytest.mark.slow
def test_a_link_that_stays_down_ends_the_run_drive_off_exit_3(tmp_path, lab):
    """The scope drops every reply from mid-run on (its new links too): after the window the run
    gives up, the generator's OFF is confirmed, exit 3 with one line; --resume later completes."""
    proc, stderr, out, cfg, _, t_drop = _run_with_drop(tmp_path, lab, "scope", count=10**6)
    took = time.monotonic() - t_drop
    assert proc.returncode == 3, stderr
    assert "Traceback" not in stderr and "scope" in stderr
    assert took < RECONNECT_WINDOW_S + 30, took
    assert lab.output_state("funcgen", 1) is False
    events = _events(out)
    assert any("the scope did not come back" in e for e in events), events
    with h5py.File(out, "r") as f:
        assert str(f.attrs["status"]).startswith("aborted")
        n = f["points/index"].shape[0]
    assert 2 <= n < len(FREQS)
    done = subprocess.run([sys.executable, "-m", "labkit", "sweep", "inchip", str(cfg), "--resume", str(out),
                           "--quiet"], cwd=REPO, capture_output=True, text=True, timeout=180)
    assert done.returncode == 0, done.stderr
    with h5py.File(out, "r") as f:
        assert sorted(f["points/index"][...]) == list(range(len(FREQS)))
