"""Shaker runs against the virtual lab: tray amplitudes reached by measurement, records, video, envelope."""
from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from labcfg import lab_timeline, shaker_toml

from labkit.errors import LimitError
from labkit.experiments.session import run_session
from labkit.lab import VirtualLab


@pytest.fixture(scope="module", autouse=True)
def compiled_simulator():
    """Compile the robot simulator once before the runs: a first JIT compile (a minute under
    load when its cache is stale) inside the lab's scope thread would look like a lost trigger."""
    from labkit.sim import RobotParams, Shaker, simulate

    simulate(RobotParams(), Shaker(freq_hz=150.0, amp_um=8.0), duration_s=0.02, seed=0)


@pytest.mark.slow
def test_shaker_grid_reaches_requested_tray_amplitudes(tmp_path):
    # falling frequencies: a runner that changed the frequency before lowering the amplitude
    # would take the tray from 20 um at 300 Hz to ~80 um at 150 Hz and fail the bound below
    freqs, amps = [300.0, 150.0], [8.0, 20.0]
    cfg = shaker_toml(tmp_path / "shaker.toml", freqs, amps, video_s=0.3)
    out = tmp_path / "shaker.h5"
    with VirtualLab(seed=3) as lab:
        summary = run_session("shaker", cfg, out, lab=lab, quiet=True)
        assert lab.output_state("funcgen", 1) is False
        chain = lab.chain
        # every generator state commanded on the way (frequency and amplitude changes, in the order
        # received) kept the tray inside the interlock limit: amplitudes fall before frequencies do
        f_hz, vpp, worst = None, None, 0.0
        for _, inst, direction, text in lab.log:
            if inst != "funcgen" or direction != "rx":
                continue
            if text.startswith("SOUR1:FREQ "):
                f_hz = float(text.split()[1])
            elif text.startswith("SOUR1:VOLT ") and not text.startswith("SOUR1:VOLT:"):
                vpp = float(text.split()[1])
            if f_hz and vpp:
                worst = max(worst, chain.tray_amp_um(f_hz, vpp / 2))
        assert 19.0 < worst < 60.0, worst
    assert summary["status"] == "complete" and summary["points_ok"] == 4
    with h5py.File(out, "r") as f:
        assert f.attrs["kind"] == "run_shaker" and f.attrs["robot_spot"] == "knee"
        assert json.loads(f.attrs["amplifier_json"])["gain_db"] == 20.0
        p = f["points"]
        req, got = p["tray_amp_request_um"][...], p["tray_amp_um"][...]
        assert p["tray_amp_um"].attrs["units"] == "um"
        assert np.all(np.abs(got / req - 1) < 0.05), (req, got)
        # the lab's own shaker chain says what the applied drive really gives
        for f_hz, vpp, r in zip(p["freq_hz"][...], p["drive_vpp"][...], req):
            assert abs(chain.tray_amp_um(f_hz, vpp / 2) / r - 1) < 0.05
        assert sorted(p["index"][...]) == [0, 1, 2, 3]
        assert np.all(p["iterations"][...] >= 1)
        T = p["transmissibility"][...]
        assert T.dtype == np.complex128 and np.all(np.isfinite(T)) and np.all(np.abs(T) > 0.1)
        # velocity records of tray and robot kept for every point
        for i in range(4):
            g = f[f"records/p{i:05d}"]
            tray = g["tray_velocity_mm_s"][...]
            assert g["tray_velocity_mm_s"].attrs["units"] == "mm/s" and tray.size > 100
            f_hz = p["freq_hz"][list(p["index"][...]).index(i)]
            # the record's own amplitude agrees with the stored tray displacement
            amp_um = (np.percentile(tray, 99.5) - np.percentile(tray, 0.5)) / 2 / (2 * np.pi * f_hz) * 1e3
            assert abs(amp_um / got[list(p["index"][...]).index(i)] - 1) < 0.15
        # one video per point, next to the run file, with frames
        videos = p["video"].asstr()[...]
        assert all(v.startswith("shaker_videos/") for v in videos)
        assert all((tmp_path / v).is_file() and (tmp_path / v).stat().st_size > 0 for v in videos)
        assert np.all(p["video_frames"][...] >= 3)
        _, on = lab_timeline(f)
        assert on.any() and not on[-1]


def test_tray_interlock_stops_the_point(tmp_path):
    # the interlock limit sits just above the request: the first overshoot trips it
    cfg = shaker_toml(tmp_path / "il.toml", [200.0], [10.0, 20.0], tray_max_um=20.5)
    text = cfg.read_text().replace("start_vpp = ", "#").replace("[tray_control]\n",
                                                                "[tray_control]\nstart_vpp = 0.4\n")
    cfg.write_text(text)
    out = tmp_path / "il.h5"
    with VirtualLab(seed=4) as lab:
        summary = run_session("shaker", cfg, out, lab=lab, quiet=True)
        assert lab.output_state("funcgen", 1) is False
    with h5py.File(out, "r") as f:
        st = list(f["points/status"].asstr()[...])
        reasons = list(f["points/reason"].asstr()[...])
        _, on = lab_timeline(f)
        events = list(f["events/text"].asstr()[...])
    # 0.4 Vpp at 200 Hz is ~25 um: above the 20.5 um limit on the first try
    assert st[0] == "interlock" and "above interlock.tray_max_um" in reasons[0]
    assert summary["points_interlocked"] >= 1
    assert any(e.startswith("drive off (interlock: tray displacement") for e in events)
    assert list(on[:3]) == [False, True, False] and not on[-1]


class _PersonThenCtrlC:
    """Moves the lab's laser as asked; presses Ctrl-C at the prompt number ``stop_at``."""

    def __init__(self, lab, stop_at=None):
        self.lab, self.stop_at, self.n = lab, stop_at, 0

    def readline(self):
        self.n += 1
        if self.n == self.stop_at:
            raise KeyboardInterrupt
        self.lab.set_spot("tray" if self.n % 2 else "knee")      # tray, robot, tray, robot ...
        return "\n"


def test_shaker_ctrl_c_then_resume(tmp_path):
    cfg = shaker_toml(tmp_path / "r.toml", [200.0, 250.0], [10.0], settle_s=0.03, dwell_cycles=10)
    out = tmp_path / "r.h5"
    with VirtualLab(seed=7) as lab:
        with pytest.raises(KeyboardInterrupt):       # Ctrl-C while asked to aim at the tray for point 2
            run_session("shaker", cfg, out, lab=lab, quiet=True, stdin=_PersonThenCtrlC(lab, stop_at=3))
        assert lab.output_state("funcgen", 1) is False
        with h5py.File(out, "r") as f:
            assert f.attrs["status"] == "interrupted: SIGINT"
            assert list(f["points/index"][...]) == [0] and list(f["records"]) == ["p00000"]
        summary = run_session("shaker", cfg, None, resume=out, lab=lab, quiet=True, stdin=_PersonThenCtrlC(lab))
        assert lab.output_state("funcgen", 1) is False
    assert summary["status"] == "complete" and summary["points_done"] == 2
    with h5py.File(out, "r") as f:
        assert list(f["points/index"][...]) == [0, 1] and list(f["points/freq_hz"][...]) == [200.0, 250.0]
        assert sorted(f["records"]) == ["p00000", "p00001"]
        got, req = f["points/tray_amp_um"][...], f["points/tray_amp_request_um"][...]
        assert np.all(np.abs(got / req - 1) < 0.05)


def test_envelope_interlock_with_fixed_drive_ends_the_run(tmp_path):
    # a declared stroke of 10 um peak: 0.2 Vpp at 150 Hz moves the tray ~23 um, outside it
    cfg = shaker_toml(tmp_path / "env.toml", [150.0, 200.0], [1.0], on_interlock="end", settle_s=0.03,
                      dwell_cycles=10)
    text = cfg.read_text().replace("tray_amp_um = [1]", "drive_vpp = [0.2]")
    cfg.write_text(text.replace("payload_kg = 0.001", "payload_kg = 0.001\nstroke_peak_mm = 0.01"))
    out = tmp_path / "env.h5"
    with VirtualLab(seed=8) as lab:
        with pytest.raises(LimitError, match="shaker envelope.*stroke.*run ended"):
            run_session("shaker", cfg, out, lab=lab, quiet=True)
        assert lab.output_state("funcgen", 1) is False
    with h5py.File(out, "r") as f:
        assert f.attrs["status"].startswith("aborted: interlock: shaker envelope")
        assert list(f["points/status"].asstr()[...]) == ["interlock"]      # the 200 Hz point never ran
        assert f["points/drive_request_vpp"][0] == 0.2
