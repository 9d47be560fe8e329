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

