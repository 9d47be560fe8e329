"""Temporary files a killed labkit left (``.partial``, ``.staging.*``) are removed by the next command
that writes there; a running command's own are left alone."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from labkit.outputs import check_output_dir, check_outputs

_WRITER = """
import sys, time
from pathlib import Path
from labkit.experiments.safety import install_stop_handlers
from labkit.outputs import atomic_output, staged_dir
install_stop_handlers()         # as the labkit command does: SIGTERM raises, clean-ups run
out = Path(sys.argv[1])
with atomic_output(out / "robot.toml") as tmp, staged_dir(out, ["a.png"]) as stage:
    tmp.write_text("half")
    (stage / "a.png").write_bytes(b"half")
    print("writing", flush=True)
    time.sleep(60)
"""


def _writer(folder):
    proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(folder)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "writing"
    return proc


def _temporaries(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_what_a_killed_writer_left_is_removed_a_running_ones_kept(tmp_path):
    running = _writer(tmp_path)
    killed = _writer(tmp_path)
    try:
        assert len(_temporaries(tmp_path)) == 4
        killed.send_signal(signal.SIGKILL)          # nothing can clean up after SIGKILL
        killed.wait()
        left = _temporaries(tmp_path)
        assert len(left) == 4 and any(str(killed.pid) in n for n in left)
        check_outputs([tmp_path / "robot.toml"])                    # the next command (fit, say)
        check_output_dir(tmp_path, names=["a.png"])                 # or report
        left = _temporaries(tmp_path)
        assert len(left) == 2 and all(str(running.pid) in n for n in left), left
    finally:
        running.send_signal(signal.SIGTERM)          # atomic_output and staged_dir clean up on SIGTERM
        running.communicate(timeout=30)
        killed.kill()
    deadline = time.monotonic() + 5
    while _temporaries(tmp_path) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _temporaries(tmp_path) == [] and not os.path.exists(tmp_path / "robot.toml")
