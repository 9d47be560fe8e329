"""Test helpers shared by every test folder: run the real ``labkit`` CLI in a subprocess.

Import as ``from clihelpers import run_cli, last_json`` (``tests/`` is on pytest's
python path). Not named conftest: several folders have a conftest of their own.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def run_cli(*args: str, cwd: str | os.PathLike | None = None, timeout: float = 600,
            check: int | None = 0) -> subprocess.CompletedProcess:
    """Run ``python -m labkit ARGS`` and (with ``check``) assert its exit code."""
    proc = subprocess.run([sys.executable, "-m", "labkit", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout)
    if check is not None:
        assert proc.returncode == check, (
            f"labkit {' '.join(args)} exited {proc.returncode}, expected {check}\n"
            f"stdout:\n{proc.stdout[-3000:]}\nstderr:\n{proc.stderr[-3000:]}")
    return proc


def last_json(proc: subprocess.CompletedProcess) -> dict:
    """The JSON object on the last line of a ``--json`` run's stdout."""
    lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
    assert lines, f"no stdout; stderr:\n{proc.stderr}"
    return json.loads(lines[-1])



def stepped_inchip_toml(instruments: str, freqs_hz, *, locations=("knee",), run_extra: str = "") -> str:
    """An in-chip config for the virtual lab: a stepped sine of 4 Vpp about 2 V at ``freqs_hz``.

    ``instruments`` holds the ``[instruments.*]`` tables (they differ per test: models,
    resources, timeouts); ``run_extra`` adds lines to ``[run]``.
    """
    locs = ", ".join(f'"{loc}"' for loc in locations)
    freqs = ", ".join(repr(float(f)) for f in freqs_hz)
    return f"""[run]
locations = [{locs}]
{run_extra}
{instruments}

[drive]
amp_vpp = 4.0
offset_v = 2.0

[frequencies]
list_hz = [{freqs}]

[method]
kind = "stepped"
settle_s = 0.03
dwell_cycles = 12

[scope]
drive_channel = 1
velocity_channel = 2

[vibrometer]
scale_mm_s_per_v = 25.0
"""
