"""Bench safety against a virtual lab that outlives the client (issue 18).

The lab runs in this (pytest) process and serves its instruments over real
TCP sockets and a pty; ``labkit`` runs in a separate process against them, as
it would against a bench. The lab's own records say when the generator's
output went on and off and when each triggered burst ended by itself
(:attr:`VirtualLab.burst_timeline`, :meth:`VirtualLab.drive_idle_after_s`).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from labcfg import inchip_toml, points_done, shaker_toml, small_tmpfs, wait_points

from clihelpers import REPO
from labkit.commands.info import summarise_h5
from labkit.errors import LimitError
from labkit.experiments.locks import RigBusy
from labkit.experiments.safety import turn_off
from labkit.experiments.session import run_session
from labkit.lab import VirtualLab

FREQS = [float(f) for f in np.round(np.geomspace(500, 3000, 10), 2)]
SETTLE_S, DWELL_CYCLES = 0.03, 20
#: the longest a point's burst lasts: settle + dwell at the lowest frequency, plus its margin cycles
POINT_S = SETTLE_S + DWELL_CYCLES / min(FREQS) + 2 / min(FREQS)

_PLACEHOLDERS = {"funcgen": "TCPIP0::192.0.2.1::5025::SOCKET", "scope": "TCPIP0::192.0.2.2::5025::SOCKET",
                 "vibrometer": "ASRL/dev/ttyUSB0::INSTR"}


@pytest.fixture(scope="module")
def lab():
    with VirtualLab(seed=5) as lab:
        yield lab


def on_lab(path: Path, lab: VirtualLab) -> Path:
    """Point a test config's instruments at a running lab (with its control channel for the spot)."""
    text = path.read_text()
    for role, placeholder in _PLACEHOLDERS.items():
        text = text.replace(placeholder, lab.resources[role])
    text = text.replace("[instruments.funcgen]",
                        f'[instruments.control]\nmodel = "LabControl"\nresource = "{lab.resources["control"]}"\n\n'
                        "[instruments.funcgen]", 1)
    path.write_text(text)
    return path


def start(cfg: Path, out: Path, *extra: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "labkit", "sweep", "inchip", str(cfg), "--out", str(out),
                             "--quiet", *extra], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)


def sweep_cfg(tmp_path: Path, lab: VirtualLab, freqs=FREQS, **kw) -> Path:
    """An in-chip sweep at the hip on the lab (points of :data:`POINT_S` at most, unless ``kw`` says)."""
    kw = {"settle_s": SETTLE_S, "dwell_cycles": DWELL_CYCLES} | kw
    return on_lab(inchip_toml(tmp_path / "c.toml", freqs, locations=("hip",), **kw), lab)


def act_mid_run(cfg: Path, out: Path, n: int, act, *extra: str, timeout_s: float = 120):
    """Start a sweep in another process, call ``act(proc)`` once ``n`` points are on disk (then a
    little into the next), wait for the process to end; return ``(proc, stdout, stderr, act's result)``."""
    proc = start(cfg, out, *extra)
    try:
        wait_points(out, n, proc)
        time.sleep(0.02)
        result = act(proc)
        stdout, stderr = proc.communicate(timeout=timeout_s)
    finally:
        proc.kill()
    return proc, stdout, stderr, result


def rx_count(lab: VirtualLab, instrument: str = "funcgen") -> int:
    return sum(1 for _, inst, kind, _ in lab.log if inst == instrument and kind == "rx")


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGHUP, signal.SIGQUIT, signal.SIGTERM, signal.SIGINT])
def test_stop_signals_mid_point_turn_the_drive_off_within_a_second(tmp_path, lab, sig):
    cfg, out = sweep_cfg(tmp_path, lab), tmp_path / "run.h5"

    def signal_it(proc):
        t = lab.now_s()
        proc.send_signal(sig)
        return t

    proc, _, stderr, t_sig = act_mid_run(cfg, out, 3, signal_it)
    name = signal.Signals(sig).name
    assert proc.returncode == 130, stderr
    assert f"interrupted by {name}" in stderr and "Traceback" not in stderr
    # the lab's record: the generator carries no signal from at most 1 s after the signal on
    assert lab.output_state("funcgen", 1) is False
    assert lab.drive_idle_after_s(1) - t_sig < 1.0
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == f"interrupted: {name}"
        assert bool(f.attrs["drive_bounded"])
        n = f["points/index"].shape[0]
        assert 3 <= n < len(FREQS) and f["locations/hip/freq_hz"].shape[0] == n


@pytest.mark.slow
def test_sigkill_the_burst_stops_by_itself_then_off_and_resume(tmp_path, lab):
    cfg, out = sweep_cfg(tmp_path, lab), tmp_path / "run.h5"

    def kill_it(proc):
        t = lab.now_s()
        proc.send_signal(signal.SIGKILL)
        return t

    proc, _, _, t_kill = act_mid_run(cfg, out, 3, kill_it)
    assert proc.returncode == -signal.SIGKILL
    # nobody turned the output off, but the point's burst ended by itself within one point
    assert lab.output_state("funcgen", 1) is True
    idle = lab.drive_idle_after_s(1)
    assert idle - t_kill <= POINT_S + 1.0, (idle - t_kill, POINT_S)
    time.sleep(max(0.0, idle - lab.now_s()) + 0.05)
    assert lab.drive_idle_after_s(1) == idle            # nothing restarted it
    # labkit off: the way back to a safe rig
    done = subprocess.run([sys.executable, "-m", "labkit", "off", str(cfg), "--json"], cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert lab.output_state("funcgen", 1) is False and lab.output_state("funcgen", 2) is False
    assert summarise_h5(out)["attrs"]["status"] == "running"
    summary = run_session("inchip", cfg, None, resume=out, quiet=True)
    assert summary["status"] == "complete" and summary["points_ok"] == len(FREQS)
    with h5py.File(out, "r") as f:
        assert sorted(f["points/index"][...]) == list(range(len(FREQS)))


@pytest.mark.slow
def test_second_run_is_refused_and_the_first_is_unharmed(tmp_path, lab):
    freqs = [float(f) for f in np.round(np.geomspace(500, 3000, 24), 2)]
    cfg, out_a, out_b = sweep_cfg(tmp_path, lab, freqs), tmp_path / "a.h5", tmp_path / "b.h5"

    def second_run(proc):
        # the file being written is reported as such (labkit info, --resume)
        assert summarise_h5(out_a)["being_written_by"]["pid"] == proc.pid
        with pytest.raises(RigBusy, match=f"run file .*a.h5 is in use by another run: PID {proc.pid}"):
            run_session("inchip", cfg, None, resume=out_a, quiet=True)
        second = subprocess.run([sys.executable, "-m", "labkit", "sweep", "inchip", str(cfg), "--out", str(out_b)],
                                cwd=REPO, capture_output=True, text=True, timeout=60)
        assert points_done(out_a) < len(freqs), "run A ended before run B tried: test nothing"
        return second

    proc, _, stderr, second = act_mid_run(cfg, out_a, 2, second_run)
    assert second.returncode == 2
    assert f"in use by another run: PID {proc.pid}" in second.stderr and "a.h5" in second.stderr
    assert "Traceback" not in second.stderr and not out_b.exists()
    assert proc.returncode == 0, stderr
    with h5py.File(out_a, "r") as f:
        assert f.attrs["status"] == "complete"
        assert list(f["points/status"].asstr()[...]) == ["ok"] * len(freqs)
        frf = f["locations/hip/frf"][...]
        truth = lab.frf("hip", f["locations/hip/freq_hz"][...])
        assert np.all(np.abs(np.abs(frf) / np.abs(truth) - 1) < 0.1)


def test_second_run_sends_nothing(tmp_path, lab):
    """While a run holds the rig (here: its locks, taken by this process), another is refused before
    any instrument is opened: the lab receives no command at all."""
    from labkit.experiments.locks import lock_run

    cfg = sweep_cfg(tmp_path, lab, FREQS[:2])
    before = {inst: rx_count(lab, inst) for inst in ("funcgen", "scope", "vibrometer", "control")}
    roles = [(r, lab.resources[r]) for r in ("funcgen", "scope", "vibrometer", "control")]
    with lock_run(roles, tmp_path / "a.h5", str(cfg)):
        second = subprocess.run([sys.executable, "-m", "labkit", "sweep", "inchip", str(cfg), "--out",
                                 str(tmp_path / "b.h5")], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert second.returncode == 2 and "is in use by another run" in second.stderr
    assert f"PID {os.getpid()}" in second.stderr
    assert {inst: rx_count(lab, inst) for inst in before} == before
    assert not (tmp_path / "b.h5").exists()


def test_a_read_only_out_folder_is_refused_before_any_command(tmp_path, lab, capsys):
    """A folder nobody may write in (a read-only mount: root ignores file modes) ends the run
    before the first byte to an instrument (31 commands were sent first)."""
    from labkit.cli import main

    cfg = sweep_cfg(tmp_path, lab, FREQS[:2])
    with small_tmpfs(tmp_path / "ro", "1m", "ro") as ro:
        before = {inst: rx_count(lab, inst) for inst in ("funcgen", "scope", "vibrometer", "control")}
        assert main(["sweep", "inchip", str(cfg), "--out", str(ro / "run.h5"), "--quiet"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(ro) in err[0] and "cannot write in this folder" in err[0], err
        assert {inst: rx_count(lab, inst) for inst in before} == before


@pytest.mark.slow
def test_output_switched_off_behind_the_runs_back_is_caught(tmp_path, lab):
    cfg, out = sweep_cfg(tmp_path, lab), tmp_path / "run.h5"

    def switch_off(proc):
        turn_off(model="33500B", resource=lab.resources["funcgen"])     # someone else's connection
        return points_done(out)

    proc, _, stderr, n_off = act_mid_run(cfg, out, 3, switch_off)
    assert proc.returncode == 0, stderr
    with h5py.File(out, "r") as f:
        status = list(f["points/status"].asstr()[...])
        reasons = list(f["points/reason"].asstr()[...])
        assert f.attrs["status"] == "complete" and len(status) == len(FREQS)
        bad = [i for i, s in enumerate(status) if s != "ok"]
        # the point in progress or the next one is flagged; the run turns the drive back on after it
        assert len(bad) == 1 and n_off <= bad[0] <= n_off + 1, (bad, n_off)
        assert "drive measured" in reasons[bad[0]] and "commanded 4 Vpp" in reasons[bad[0]]
        assert status[bad[0] + 1:] == ["ok"] * (len(FREQS) - bad[0] - 1)
    # --resume --retry-interlocked measures that point again (a plain --resume counted it as done)
    summary = run_session("inchip", cfg, None, resume=out, quiet=True, retry_interlocked=True)
    assert summary["status"] == "complete" and summary["points_ok"] == len(FREQS), summary
    assert summary["points_retried"] == 1 and summary["points_interlocked"] == 0
    with h5py.File(out, "r") as f:
        status = list(f["points/status"].asstr()[...])
        index = list(f["points/index"][...])
        assert status[bad[0]] == "interlock, retried" and status[-1] == "ok" and index[-1] == index[bad[0]]
        assert sorted(f["locations/hip/point_index"][...].tolist()) == list(range(len(FREQS)))


def _shaker_cfg(tmp_path: Path, lab: VirtualLab, grid: str, extra: str = "") -> Path:
    cfg = shaker_toml(tmp_path / "s.toml", [150.0], [10.0])
    text = cfg.read_text().replace("tray_amp_um = [10]", grid)
    if extra:
        text = text.replace("payload_kg = 0.001", "payload_kg = 0.001\n" + extra)
    cfg.write_text(text)
    return on_lab(cfg, lab)


@pytest.mark.parametrize("grid, extra, key, words", [
    # 1 Vpp at 5 Hz: below the 4809's 10 Hz
    ("freq_hz = [5.0]\ndrive_vpp = [1.0]", "", "grid.freq_hz[0]", "outside the 4809 frequency range"),
    # 2 Vpp at 10 Hz with the declared sensitivity: far beyond the stroke
    ("freq_hz = [10.0]\ndrive_vpp = [2.0]", "accel_m_s2_per_v = 20.0", "grid.drive_vpp[0] at grid.freq_hz[0]",
     "predicted to move the tray"),
    # 50 um asked of the tray at 5 kHz (within the interlock's 60 um): beyond the 4809's force
    ("freq_hz = [5000.0]\ntray_amp_um = [50.0]", "", "grid.tray_amp_um[0] at grid.freq_hz[0]",
     "over the 4809 force limit"),
])
def test_shaker_limits_refused_before_any_command(tmp_path, lab, grid, extra, key, words):
    cfg = _shaker_cfg(tmp_path, lab, grid, extra)
    cfg.write_text(cfg.read_text().replace("freq_hz = [150]\n", ""))
    before = {inst: rx_count(lab, inst) for inst in ("funcgen", "scope", "control")}
    out = tmp_path / "s.h5"
    with pytest.raises(LimitError) as err:
        run_session("shaker", cfg, out, quiet=True)
    assert err.value.key == key and words in err.value.message and err.value.file == str(cfg)
    assert {inst: rx_count(lab, inst) for inst in before} == before
    assert not out.exists()


@pytest.mark.slow
def test_shaker_soft_start_stops_before_the_stroke(tmp_path, lab):
    """No declared sensitivity: the drive is ramped while the tray is measured; the step that would
    pass interlock.tray_max_um is never sent."""
    cfg = _shaker_cfg(tmp_path, lab, "drive_vpp = [2.0]")
    out = tmp_path / "s.h5"
    first = len(lab.log)
    summary = run_session("shaker", cfg, out, quiet=True)
    assert summary["points_interlocked"] == 1
    reason = summary["interlocks"][0]["reason"]
    assert "would move the tray" in reason and "not sent" in reason
    # every amplitude the generator received kept the tray under the limit (the lab's chain says)
    worst = 0.0
    for _, inst, kind, text in lab.log[first:]:
        if inst == "funcgen" and kind == "rx" and text.startswith("SOUR1:VOLT ") and not text.startswith("SOUR1:VOLT:"):
            worst = max(worst, lab.chain.tray_amp_um(150.0, float(text.split()[1]) / 2))
    assert 0 < worst < 60.0
    assert lab.output_state("funcgen", 1) is False


def _limit_fsize(soft: int):
    import resource

    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, resource.RLIM_INFINITY))
    return apply


def test_preflight_refuses_a_run_that_does_not_fit(tmp_path, lab):
    cfg = sweep_cfg(tmp_path, lab, keep_raw=True)
    out = tmp_path / "run.h5"
    before = rx_count(lab)
    proc = subprocess.run([sys.executable, "-m", "labkit", "sweep", "inchip", str(cfg), "--out", str(out)],
                          cwd=REPO, capture_output=True, text=True, timeout=60, preexec_fn=_limit_fsize(1 << 20))
    assert proc.returncode == 2 and "not enough room for this run" in proc.stderr and "--out" in proc.stderr
    assert "Traceback" not in proc.stderr and not out.exists() and rx_count(lab) == before


@pytest.mark.slow
def test_disk_full_mid_run_drive_off_file_readable_resume_completes(tmp_path, lab):
    """The file-size limit is lowered under a running sweep (as a disk filling up): the run stops
    before a write could fail, with the drive off and every completed point readable."""
    import resource

    cfg, out = sweep_cfg(tmp_path, lab), tmp_path / "run.h5"

    def fill_up(proc):
        soft = out.stat().st_size + 3 * (1 << 19)           # 1.5 MB more: less than the reserve
        resource.prlimit(proc.pid, resource.RLIMIT_FSIZE, (soft, resource.RLIM_INFINITY))

    proc, _, stderr, _ = act_mid_run(cfg, out, 3, fill_up)
    assert proc.returncode == 2, stderr
    assert "not enough room to write the next point" in stderr and "--resume" in stderr
    assert "Traceback" not in stderr and "Segmentation" not in stderr
    assert lab.output_state("funcgen", 1) is False
    info = summarise_h5(out)
    assert info["attrs"]["status"].startswith("aborted: DiskFull")
    with h5py.File(out, "r") as f:
        n = f["points/index"].shape[0]
        assert 3 <= n < len(FREQS) and f["locations/hip/freq_hz"].shape[0] == n
        assert np.all(np.isfinite(f["locations/hip/frf"][...]))
    summary = run_session("inchip", cfg, None, resume=out, quiet=True)    # room again: no limit here
    assert summary["status"] == "complete" and summary["points_ok"] == len(FREQS)
    with h5py.File(out, "r") as f:
        assert sorted(f["points/index"][...]) == list(range(len(FREQS)))


@pytest.mark.slow
def test_unconfirmed_off_is_loud_then_labkit_off_recovers(tmp_path, lab):
    """The generator's link fails mid-run and every reconnection too: exit 4, a banner naming it and what to do, the
    original fault too; the file says so; once it answers again, ``labkit off`` turns it off."""
    cfg, out = sweep_cfg(tmp_path, lab, timeout_s=0.4), tmp_path / "run.h5"
    try:
        proc, _, stderr, _ = act_mid_run(cfg, out, 2, lambda proc: lab.inject_fault(
            "funcgen", "drop", count=100_000), "-v")           # every link dropped at its next reply
    finally:
        lab.clear_faults()
    assert proc.returncode == 4, stderr
    # -v: the shutdown path's log on stderr, each attempt and its end
    log = [line for line in stderr.splitlines() if line.startswith("labkit labkit.experiments.")]
    assert any("shutdown: aborted: InstrumentError" in line for line in log), stderr
    assert any("OFF attempt 1 failed" in line for line in log), stderr
    assert any("OFF NOT CONFIRMED after" in line for line in log), stderr
    assert any("run file and live stream finished" in line for line in log), stderr
    assert "DRIVE MAY STILL BE ON: funcgen" in stderr and lab.resources["funcgen"] in stderr
    assert "TURN THE GENERATOR OUTPUT OFF BY HAND" in stderr and f"labkit off {cfg}" in stderr
    # the original fault: the run stopped because the generator timed out
    assert "the run had stopped because: aborted: InstrumentError: funcgen" in stderr
    assert "Traceback" not in stderr
    with h5py.File(out, "r") as f:
        assert f.attrs["status"].endswith("DRIVE OFF NOT CONFIRMED")
        assert any("DRIVE OFF NOT CONFIRMED" in e for e in f["events/text"].asstr()[...])
    # the OFF went out on a link without the handshake, but no *OPC? came back: not confirmed, so
    # exit 4 all the same (whether the generator obeyed is for the person, or labkit off, to find)
    done = subprocess.run([sys.executable, "-m", "labkit", "off", str(cfg)], cwd=REPO, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "off (confirmed)" in done.stdout and lab.output_state("funcgen", 1) is False
    assert "labkit labkit." not in done.stderr          # without -v: no log lines


@pytest.mark.parametrize("kind, old, new, key", [
    ("inchip", "settle_s = 0.04", "settle_s = inf", "method.settle_s"),
    ("inchip", "settle_s = 0.04", "settle_s = nan", "method.settle_s"),
    ("inchip", "list_hz = [1000.0", "list_hz = [50e6", "frequencies.list_hz[0]"),
    ("inchip", "dwell_cycles = 20", "dwell_cycles = 1e6", "method.dwell_cycles"),      # 1000 s records
    ("inchip", 'list_hz = [1000.0, 2000.0]\n\n[method]\nkind = "stepped"\nsettle_s = 0.04',   # a 5e8-cycle burst
     'list_hz = [1000.0, 1e6]\n\n[method]\nkind = "stepped"\nsettle_s = 500.0', "method.settle_s"),
    ("inchip", "offset_v = 2.0", "offset_v = 2.0\npzt_max_v = 30", "drive.pzt_max_v"),
    ("inchip", "amp_vpp = 4.0\noffset_v = 2.0", "amp_vpp = 14.0\noffset_v = 5.0\npzt_max_v = 20",
     "drive.amp_vpp"),
    ("shaker", "payload_kg = 0.001", "payload_kg = 0.001\nforce_peak_n = 1e6", "shaker.force_peak_n"),
    ("shaker", "payload_kg = 0.001", "payload_kg = 0.001\nmoving_mass_kg = 0.01", "shaker.moving_mass_kg"),
    ("shaker", "current_limit_a = 1.0", "current_limit_a = 1.0\nmax_input_vrms = 5", "amplifier.max_input_vrms"),
    ("shaker", "tray_max_um = 60.0", "tray_max_um = inf", "interlock.tray_max_um"),
    ("shaker", "tray_max_um = 60.0", "tray_max_um = 9000.0", "interlock.tray_max_um"),
    # below what any generator puts out (it was sent, and a run file made, without naming the key)
    ("inchip", "amp_vpp = 4.0", "amp_vpp = 1e-9", "drive.amp_vpp"),
    ("shaker", "start_vpp", "start_vpp", "grid.drive_vpp[0]"),         # (replaced below: a 1e-9 Vpp grid)
    # a link timeout of -1 or 0 s silently became 1 ms; nan or 1e9 s ended in exit 3 after connecting
    ("inchip", 'model = "33500B"', 'model = "33500B"\ntimeout_s = -1', "instruments.funcgen.timeout_s"),
    ("inchip", 'model = "33500B"', 'model = "33500B"\ntimeout_s = 0', "instruments.funcgen.timeout_s"),
    ("inchip", 'model = "33500B"', 'model = "33500B"\ntimeout_s = nan', "instruments.funcgen.timeout_s"),
    ("inchip", 'model = "33500B"', 'model = "33500B"\ntimeout_s = 1e9', "instruments.funcgen.timeout_s"),
    # the 33500B family has two channels: channel 3 was found only after connecting
    ("inchip", 'model = "33500B"', 'model = "33500B"\nchannel = 3', "instruments.funcgen.channel"),
    ("inchip", "velocity_channel = 2", "velocity_channel = 2\nsamples_per_cycle = 1e300", "scope.samples_per_cycle"),
])
def test_bad_config_exits_2_naming_file_and_key_nothing_sent(tmp_path, lab, capsys, kind, old, new, key):
    from labkit.cli import main

    if kind == "inchip":
        cfg = inchip_toml(tmp_path / "c.toml", [1000.0, 2000.0], locations=("hip",))
    else:
        cfg = shaker_toml(tmp_path / "c.toml", [150.0], [10.0])
    text = cfg.read_text()
    if old == "start_vpp":
        old, new = "tray_amp_um = [10]", "drive_vpp = [1e-9]"
    assert old in text
    cfg.write_text(text.replace(old, new))
    on_lab(cfg, lab)
    before = {inst: rx_count(lab, inst) for inst in ("funcgen", "scope", "control")}
    out = tmp_path / "run.h5"
    args = ["sweep", "inchip"] if kind == "inchip" else ["shaker"]
    assert main([*args, str(cfg), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(cfg) in err[0] and f"key '{key}'" in err[0], err
    assert {inst: rx_count(lab, inst) for inst in before} == before
    assert not out.exists()


def test_writer_failure_turns_the_drive_off_then_reports(tmp_path, lab, capsys, monkeypatch):
    """An HDF5/disk error while writing a point: the drive goes off first, then one line (exit 2);
    the file holds every point before it and --resume completes it."""
    from labkit.cli import main
    from labkit.experiments import runfile

    cfg = sweep_cfg(tmp_path, lab, FREQS[:6])
    out = tmp_path / "run.h5"
    real = runfile.RunFile.add_location_rows
    calls = []

    def failing(self, location, rows):
        calls.append(lab.now_s())
        if len(calls) == 3:
            raise OSError(28, "No space left on device (injected)")
        return real(self, location, rows)

    monkeypatch.setattr(runfile.RunFile, "add_location_rows", failing)
    assert main(["sweep", "inchip", str(cfg), "--out", str(out), "--quiet"]) == 2
    t_reported = lab.now_s()
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if not ln.startswith("labkit: warning:")]
    assert len(err) == 1 and "writing point 2 failed" in err[0] and "--resume" in err[0], err
    # the lab's record: the output went off after the failed write and before the report
    offs = [t for t, inst, ch, on in lab.output_timeline if inst == "funcgen" and ch == 1 and not on]
    assert lab.output_state("funcgen", 1) is False and calls[2] <= offs[-1] <= t_reported
    with h5py.File(out, "r") as f:
        assert f.attrs["status"].startswith("aborted: WriteFailed")
        assert list(f["points/index"][...]) == [0, 1]
    monkeypatch.setattr(runfile.RunFile, "add_location_rows", real)
    summary = run_session("inchip", cfg, None, resume=out, quiet=True)
    assert summary["status"] == "complete" and summary["points_ok"] == 6


def _caught(pid: int, sig: int) -> bool:
    """Whether process ``pid`` has a handler installed for ``sig`` (/proc/PID/status SigCgt)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("SigCgt:"):
                return bool(int(line.split()[1], 16) >> (sig - 1) & 1)
    except OSError:
        pass
    return False


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGQUIT])
def test_a_background_job_is_stopped_by_sigint_and_sigquit_from_its_start(tmp_path, lab, sig):
    """A shell starts background jobs with SIGINT and SIGQUIT ignored: labkit handles them anyway,
    from before it opens anything (here: while it starts up against the lab)."""
    cfg = sweep_cfg(tmp_path, lab)
    out = tmp_path / "run.h5"

    def background() -> None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGQUIT, signal.SIG_IGN)

    proc = subprocess.Popen([sys.executable, "-m", "labkit", "sweep", "inchip", str(cfg), "--out", str(out),
                             "--quiet"], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=background)
    try:
        deadline = time.monotonic() + 30
        while not _caught(proc.pid, sig):
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.002)
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 130, stderr
    assert f"interrupted by {signal.Signals(sig).name}" in stderr
    assert lab.output_state("funcgen", 1) is False


def test_labkit_off_lab_turns_off_the_served_labs_generator(tmp_path):
    import json

    from labkit.drivers.registry import open_instrument

    env = dict(os.environ, PYTHONUNBUFFERED="1", XDG_RUNTIME_DIR=str(tmp_path))
    serve = subprocess.Popen([sys.executable, "-m", "labkit", "lab", "serve", "--json"], cwd=REPO, env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = serve.stdout.readline()
        assert line.startswith("{"), f"lab serve: {line!r} {serve.poll()} {serve.stderr.read() if serve.poll() else ''}"
        resources = json.loads(line)
        fg = open_instrument("33500B", resources["funcgen"], name="funcgen")
        try:
            fg.set_load_high_z()
            fg.set_sine(200.0, 1.0)
            fg.output(True)                         # a drive left on (by a run that died, say)
            assert fg.output_on
            off = subprocess.run([sys.executable, "-m", "labkit", "off", "--lab", "--json"], cwd=REPO, env=env,
                                 capture_output=True, text=True, timeout=60)
            assert off.returncode == 0, off.stderr
            assert json.loads(off.stdout.strip().splitlines()[-1])["resource"] == resources["funcgen"]
            assert fg.output_on is False            # read back over the generator's own link
        finally:
            fg.close()
    finally:
        serve.send_signal(signal.SIGTERM)
        serve.communicate(timeout=30)
    none = subprocess.run([sys.executable, "-m", "labkit", "off", "--lab"], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=60)
    assert none.returncode == 2 and "no virtual lab is being served" in none.stderr


@pytest.mark.parametrize("lab_model, driver", [("33220A", "33220A"), ("33511B", "33500B"), ("DG1062Z", "DG1000Z")])
def test_every_generator_drives_finite_bursts(tmp_path, lab_model, driver):
    """Each supported generator's point is a burst that ends by itself after settle + dwell
    (+2) cycles, and the FRF measured that way is the lab's true one."""
    freqs = FREQS[:3]
    with VirtualLab(seed=2, funcgen_model=lab_model) as glab:
        cfg = sweep_cfg(tmp_path, glab, freqs)
        cfg.write_text(cfg.read_text().replace('model = "33500B"', f'model = "{driver}"'))
        summary = run_session("inchip", cfg, tmp_path / "r.h5", quiet=True)
        bursts = [(start, end) for start, inst, ch, end in glab.burst_timeline if inst == "funcgen" and ch == 1]
    assert summary["points_ok"] == len(freqs)
    assert len(bursts) == len(freqs)             # one burst per point
    for (start, end), f_hz in zip(bursts, freqs):
        n = np.ceil((SETTLE_S + DWELL_CYCLES / f_hz) * f_hz) + 2
        assert end - start == pytest.approx(n / f_hz, rel=1e-6)     # it ended by itself
    with h5py.File(tmp_path / "r.h5", "r") as f:
        assert bool(f.attrs["drive_bounded"])
        frf, fr = f["locations/hip/frf"][...], f["locations/hip/freq_hz"][...]
        assert np.all(np.abs(frf / glab.frf("hip", fr) - 1) < 0.03)


@pytest.fixture
def small_fs(tmp_path):
    """A 6 MB tmpfs mounted for the test (CI runs as root; a test never skips)."""
    with small_tmpfs(tmp_path / "small", "6m") as mnt:
        yield mnt


@pytest.mark.slow
@pytest.mark.parametrize("leave_bytes", [0, 1 << 20])
def test_full_filesystem_mid_run(tmp_path, lab, small_fs, leave_bytes):
    """Another process fills the run file's file system mid-run (to the last byte, or to 1 MB):
    the space the run set aside before its first point (``fallocate``, kept by the file) is
    not the filler's to take, so the run completes: exit 0, every point, status complete
    (it stopped with "running" or a crash before)."""
    cfg, out = sweep_cfg(tmp_path, lab), small_fs / "run.h5"

    def fill(proc):
        st = os.statvfs(small_fs)
        with open(small_fs / "filler", "wb") as f:
            try:
                f.write(b"\0" * max(0, st.f_bavail * st.f_frsize - leave_bytes))
            except OSError:
                pass
        return os.statvfs(small_fs).f_bavail * os.statvfs(small_fs).f_frsize

    proc, _, stderr, free = act_mid_run(cfg, out, 3, fill)
    assert free <= leave_bytes
    assert proc.returncode == 0 and "Traceback" not in stderr, stderr
    assert lab.output_state("funcgen", 1) is False
    assert summarise_h5(out)["attrs"]["status"] == "complete"
    with h5py.File(out, "r") as f:
        assert f["points/index"].shape[0] == len(FREQS)
        assert np.all(np.isfinite(f["locations/hip/frf"][...]))
    # what the run did not use went back to the file system
    assert os.stat(out).st_blocks * 512 - os.stat(out).st_size < 1 << 16
    (small_fs / "filler").unlink()
