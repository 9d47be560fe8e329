"""Config writers and run-file readers shared by the experiment tests (the virtual lab replaces resources)."""
from __future__ import annotations

import contextlib
import subprocess
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

import h5py
import numpy as np

from labkit.experiments.session import lab_instruments_toml

_INSTRUMENTS = "\n" + lab_instruments_toml()


def inchip_toml(path: Path, freqs_hz: Iterable[float], *, locations=("body", "hip", "knee"),
                settle_s: float = 0.04, dwell_cycles: float = 20, scale_mm_s_per_v: float = 25.0,
                amp_vpp: float = 4.0, offset_v: float = 2.0, on_interlock: str = "skip",
                keep_raw: bool = False, timeout_s: float | None = None) -> Path:
    freqs = ", ".join(repr(float(f)) for f in freqs_hz)
    locs = ", ".join(f'"{x}"' for x in locations)
    inst = _INSTRUMENTS
    if timeout_s is not None:      # a lost link is noticed after this long
        inst = inst.replace("::SOCKET\"\n", f"::SOCKET\"\ntimeout_s = {timeout_s}\n")
    path.write_text(f"""# test config
[run]
locations = [{locs}]
on_interlock = "{on_interlock}"
{inst}
[drive]
amp_vpp = {amp_vpp}
offset_v = {offset_v}

[frequencies]
list_hz = [{freqs}]

[method]
kind = "stepped"
settle_s = {settle_s}
dwell_cycles = {dwell_cycles}
keep_raw = {str(keep_raw).lower()}

[scope]
drive_channel = 1
velocity_channel = 2

[vibrometer]
scale_mm_s_per_v = {scale_mm_s_per_v}
""")
    return path


def shaker_toml(path: Path, freqs_hz: Iterable[float], tray_amp_um: Iterable[float], *,
                robot_spot: str = "knee", video_s: float = 0.0, tray_max_um: float = 60.0,
                settle_s: float = 0.05, dwell_cycles: float = 15, on_interlock: str = "skip",
                timeout_s: float = 10.0) -> Path:
    f = ", ".join(f"{x:g}" for x in freqs_hz)
    a = ", ".join(f"{x:g}" for x in tray_amp_um)
    camera = ('\n[instruments.camera]\nmodel = "LabCamera"\nresource = "TCPIP0::192.0.2.3::5025::SOCKET"\n'
              if video_s > 0 else "")
    # generous link timeouts: on a loaded machine the lab's threads can stall for seconds while
    # the simulator computes (a timeout would then look like a lost instrument)
    inst = _INSTRUMENTS.replace("::SOCKET\"\n", f"::SOCKET\"\ntimeout_s = {timeout_s}\n")
    path.write_text(f"""# test config
[run]
robot_spot = "{robot_spot}"
video_s = {video_s}
on_interlock = "{on_interlock}"
{inst}{camera}
[amplifier]
gain_db = 20.0
attenuator_db = 0.0
current_limit_a = 1.0

[shaker]
payload_kg = 0.001

[grid]
freq_hz = [{f}]
tray_amp_um = [{a}]

[tray_control]
tolerance = 0.02

[method]
settle_s = {settle_s}
dwell_cycles = {dwell_cycles}

[scope]
drive_channel = 1
velocity_channel = 2

[vibrometer]
scale_mm_s_per_v = 125.0

[interlock]
tray_max_um = {tray_max_um}
""")
    return path


def points_done(path: Path) -> int:
    """Complete points in a run file another process is writing (0 while it cannot be read)."""
    try:
        with h5py.File(path, "r", locking=False) as f:
            return int(f["points/index"].shape[0])
    except Exception:
        return 0


def wait_points(path: Path, n: int, proc, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while points_done(path) < n:
        assert proc.poll() is None, f"labkit ended early ({proc.returncode}): {proc.stderr.read()}"
        assert time.monotonic() < deadline, f"fewer than {n} points after {timeout_s} s"
        time.sleep(0.05)


def lab_timeline(f: h5py.File, channel: str = "1") -> tuple[np.ndarray, np.ndarray]:
    """(monotonic times, on) of the lab's generator output ``channel`` stored in a run file."""
    g = f["virtual_lab/output_timeline"]
    inst = g["instrument"].asstr()[...]
    ch = g["channel"].asstr()[...]
    sel = (inst == "funcgen") & (ch == channel)
    t0 = float(f["virtual_lab"].attrs["t0_monotonic_s"])
    return t0 + g["t_s"][...][sel], g["on"][...][sel].astype(bool)


#: the placeholder resources of :func:`inchip_toml` / :func:`shaker_toml`, by role
PLACEHOLDERS = {"funcgen": "TCPIP0::192.0.2.1::5025::SOCKET", "scope": "TCPIP0::192.0.2.2::5025::SOCKET",
                "vibrometer": "ASRL/dev/ttyUSB0::INSTR"}


def on_lab_resources(cfg: Path, lab, **spelled: str) -> Path:
    """Point a test config at a running lab (with its control channel); ``spelled`` gives a role
    another spelling of its resource."""
    text = cfg.read_text()
    for role, placeholder in PLACEHOLDERS.items():
        text = text.replace(placeholder, spelled.get(role, lab.resources[role]))
    text = text.replace("[instruments.funcgen]", f'[instruments.control]\nmodel = "LabControl"\n'
                        f'resource = "{lab.resources["control"]}"\n\n[instruments.funcgen]', 1)
    cfg.write_text(text)
    return cfg


@contextlib.contextmanager
def small_tmpfs(mnt: Path, size: str, options: str = "") -> Iterator[Path]:
    """A size-limited tmpfs mounted at ``mnt`` for the block (needs root, as CI has; a test never skips)."""
    mnt.mkdir(exist_ok=True)
    opts = f"size={size}" + (f",{options}" if options else "")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(mnt)], capture_output=True)
    assert done.returncode == 0, f"cannot mount a tmpfs (needs root): {done.stderr.decode().strip()}"
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)
