"""Temporary files a killed labkit left (``.partial``, ``.staging.*``) are removed by the next command
that writes there; a running command's own are left alone; a ``fit`` or ``report`` stopped by a
signal at any instant removes its own."""
from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
import time
import tomllib

import pytest

from clihelpers import REPO
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


def _leftovers(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*")
                  if ".partial" in p.name or p.name.startswith(".staging."))


_COMMANDS = {
    "fit": (["inchip_run.h5", "--out", "robot.toml"], ["robot.toml", "robot.fit.h5"]),
    "report": (["--runs", "inchip_run.h5", "shaker_run.h5", "--fit", "robot.fit.h5", "--out", "rep"],
               ["rep/report.html"]),
}


@pytest.mark.slow
@pytest.mark.parametrize("command", sorted(_COMMANDS))
def test_fit_and_report_stopped_at_random_instants_leave_no_temporaries(tmp_path, command):
    """A real ``labkit fit`` or ``labkit report`` process gets SIGINT or SIGTERM at a random
    instant of its run (4 trials each, drawn over the time an uninterrupted run takes): it exits
    130 (0 when it had already finished) and leaves no ``.partial`` file and no ``.staging.*``
    folder; outputs appear only whole (a stopped command leaves the ones it had not finished
    absent)."""
    args, outputs = _COMMANDS[command]
    rng = random.Random(33 if command == "fit" else 34)
    runs, stopped = [], 0
    for trial in range(5):
        work = tmp_path / f"t{trial}"
        work.mkdir()
        for name in ("inchip_run.h5", "shaker_run.h5") + (("robot.fit.h5",) if command == "report" else ()):
            shutil.copy(REPO / "sample_data" / name, work / name)
        t0 = time.monotonic()
        proc = subprocess.Popen([sys.executable, "-m", "labkit", command, *args, "--quiet"], cwd=work,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        sig = None
        if trial:                               # trial 0 runs whole: how long a run takes
            time.sleep(rng.uniform(0.0, runs[0]))
            sig = (signal.SIGINT, signal.SIGTERM)[trial % 2]
            proc.send_signal(sig)
        _, err = proc.communicate(timeout=240)
        runs.append(time.monotonic() - t0)
        assert proc.returncode in ((0, 130) if sig else (0,)) and "Traceback" not in err, (trial, sig, err)
        stopped += proc.returncode == 130
        assert _leftovers(work) == [], (trial, sig, _leftovers(work))
        if proc.returncode == 0:
            assert all((work / o).is_file() for o in outputs), (trial, sorted(os.listdir(work)))
        if command == "fit" and (work / "robot.toml").exists():
            tomllib.loads((work / "robot.toml").read_text())          # whole, never half-written
    assert stopped >= 2, stopped               # most instants fall inside the run
