"""The control channel, its Python client, the shaker set-up and the virtual camera."""
from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import pyvisa
from labhelpers import decoder_lag, drive_sine, fit_sine, lab, raw, read_word  # noqa: F401  (fixtures)

from labkit.errors import InstrumentError
from labkit.lab import VirtualLab
from labkit.lab.client import LabCamera, LabControl, parse_socket_resource


def test_control_language_over_pyvisa(lab):
    rm = pyvisa.ResourceManager("@py")
    ctl = rm.open_resource(lab.resources["control"], read_termination="\n", write_termination="\n",
                           timeout=2000)
    try:
        assert ctl.query("*IDN?").startswith("labkit,VirtualLab control")
        ctl.write("LAB:SPOT HIP")
        assert ctl.query("LAB:SPOT?") == "HIP" and lab.spot == "hip"
        ctl.write("LAB:SETUP SHAK")
        assert ctl.query("LAB:SETup?") == "SHAKER" and lab.setup == "shaker"
        ctl.write("LAB:SPOT ELBOW")
        assert ctl.query("SYST:ERR?").startswith("-224")
        assert lab.spot == "hip"
        ctl.write('LAB:FAULT funcgen,stall,0,"FREQ?"')
        assert ctl.query("SYST:ERR?") == '+0,"No error"'
        assert lab.servers["funcgen"].faults[0].match == "FREQ?"
        assert ctl.query("LAB:FAULT:CLEAR;*OPC?") == "1"
        assert lab.servers["funcgen"].faults == []
    finally:
        ctl.close()


def test_lab_control_client(lab):
    assert parse_socket_resource("TCPIP0::127.0.0.1::5025::SOCKET") == ("127.0.0.1", 5025)
    with LabControl(lab.resources["control"], timeout_s=2) as ctl:
        ctl.set_spot("body")
        assert ctl.spot() == "body" and lab.spot == "body"
        ctl.set_setup("shaker")
        assert ctl.setup() == "shaker"
        truth = ctl.truth()
        assert truth["tethered_modes"]["freq_hz"] == pytest.approx(lab.truth["tethered_modes"]["freq_hz"])
        assert truth["amplifier_gain_db"] == 20.0
        with pytest.raises(InstrumentError, match="lab-control"):
            ctl.set_spot("elbow")
        ctl.inject_fault("scope", "garbage", after=3)
        assert lab.servers["scope"].faults[0].after == 3


def test_control_client_fails_clearly_without_a_lab():
    with VirtualLab() as lab:
        resource = lab.resources["control"]
    with pytest.raises(InstrumentError, match="cannot connect"):
        LabControl(resource, timeout_s=0.5)


def test_shaker_setup_drives_the_tray_and_the_simulated_robot(lab, raw):
    fg, sc = raw("funcgen"), raw("scope")
    lab.set_setup("shaker")
    lab.set_spot("knee")
    freq_hz, amp_um = 240.0, 25.0
    vpp = 2 * amp_um / lab.chain.tray_amp_um(freq_hz, 1.0)
    drive_sine(fg, freq_hz, vpp)
    time.sleep(lab.chain.settle_s())
    sc.write(":CHAN1:DISP 1;:CHAN2:DISP 1;:CHAN3:DISP 1;:TIM:RANG 0.05")
    sc.write(":WAV:POIN:MODE RAW;:WAV:POIN 20000")
    assert sc.query(":DIG;*OPC?") == "1"
    scale = lab.vibrometer.scale_mm_s_per_v
    t, drive = read_word(sc, 1)
    _, knee = read_word(sc, 2)
    _, tray = read_word(sc, 3)
    # the tray: generator -> 20 dB -> shaker, 25 um at 240 Hz
    tray_v = fit_sine(t, tray * scale, freq_hz)
    assert abs(tray_v) / (2 * np.pi * freq_hz) * 1e3 == pytest.approx(amp_um, rel=0.01)
    h = lab.chain.tray_velocity_frf(freq_hz) * decoder_lag(lab, freq_hz)    # the decoder's output lags
    assert np.angle(tray_v / fit_sine(t, drive, freq_hz) / h) == pytest.approx(0, abs=0.01)
    # the knee: the hybrid simulator's answer for that tray motion (cached per freq, amp)
    from labkit.sim import Shaker, simulate
    res = simulate(lab.params, Shaker(freq_hz, round(lab.chain.tray_amp_um(freq_hz, lab.funcgen.drive(1).amp_v), 4)),
                   duration_s=lab.sim_duration_s, seed=lab.seed, record_dt_s=1 / (freq_hz * 64))
    sim_knee = np.asarray(res.knee_vz_mm_s)[:, 0]
    settled = res.t_s > res.t_s[-1] / 3
    assert np.std(knee * scale) == pytest.approx(np.std(sim_knee[settled]), rel=0.15)
    assert len(lab._sim_cache) == 1


def _frames(path: Path) -> np.ndarray:
    cap = cv2.VideoCapture(str(path))
    out = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        out.append(frame)
    cap.release()
    return np.array(out)


def test_camera_records_a_readable_video(lab, tmp_path):
    lab.set_setup("shaker")
    lab.camera_fps = 20
    with LabCamera(lab.resources["control"]) as cam:
        info = cam.record(tmp_path / "clip.avi", 1.0)
    assert info["frames"] == 20 and len(info["timestamps_s"]) == 20
    assert np.all(np.diff(info["timestamps_s"]) > 0)
    frames = _frames(tmp_path / "clip.avi")
    assert len(frames) == 20 and frames[0].shape[:2] == (480, 640)
    grey = frames[0].mean(axis=2)
    assert grey.min() < 100 < grey.max()           # a dark chip on the light tray
    # the slow turn: the heading changed over the clip
    hd = lab.last_recording.heading_rad
    assert hd[-1] - hd[0] == pytest.approx(np.deg2rad(1.5) * (info["timestamps_s"][-1]), rel=0.05, abs=0.01)


def test_the_same_seed_films_the_same_clips_whatever_the_queries_between(tmp_path):
    """The clip's noise and frame jitter come from (seed, take), take counting the clips filmed: two labs
    with one seed film the same frames although one answered many more queries before each clip."""
    clips = []
    for extra in (0, 25):
        with VirtualLab(seed=3) as lab, LabControl(lab.resources["control"], timeout_s=5) as ctl:
            lab.set_setup("shaker")
            lab.camera_fps = 10
            got = []
            for k in range(2):
                for _ in range(extra):
                    ctl.query("*IDN?")
                lab.record_video(tmp_path / f"{extra}-{k}.avi", 0.5)
                got.append(_frames(tmp_path / f"{extra}-{k}.avi"))
            assert lab.takes == 2
            clips.append(got)
    assert all(np.array_equal(a, b) for a, b in zip(clips[0], clips[1]))
    assert not np.array_equal(clips[0][0], clips[0][1])      # a second take is a new draw of the noise


def test_camera_bad_directory_is_a_clear_error(lab, tmp_path):
    with LabControl(lab.resources["control"], timeout_s=2) as ctl:
        t0 = time.monotonic()
        with pytest.raises(InstrumentError, match="camera: no such directory"):
            ctl.record_video(tmp_path / "missing" / "clip.avi", 0.2)
        assert time.monotonic() - t0 < 1.0


def test_a_late_bus_triggered_sine_burst_moves_the_robot_like_the_sine(lab, raw):
    """The scope armed on EXT sees a *TRG that comes well after :SING (not only within 20 ms), and inside
    the burst the knee moves as under the continuous sine (the simulator's answer), not with the tray."""
    fg, sc = raw("funcgen"), raw("scope")
    lab.set_setup("shaker")
    lab.set_spot("knee")
    freq_hz, amp_um = 240.0, 25.0
    vpp = 2 * amp_um / lab.chain.tray_amp_um(freq_hz, 1.0)
    fg.write("OUTP1:LOAD INF")
    fg.write(f"SOUR1:FUNC SIN;FREQ {freq_hz};VOLT {vpp};VOLT:OFFS 0")
    fg.write("SOUR1:BURS:MODE TRIG;NCYC 96;STAT ON;:TRIG1:SOUR BUS;:OUTP1 ON")
    assert fg.query("SYST:ERR?") == '+0,"No error"'
    settle = lab.chain.settle_s()
    sc.write(":CHAN1:DISP 1;:CHAN2:DISP 1;:CHAN3:DISP 1;:TRIG:SWE NORM;:TRIG:EDGE:SOUR EXT")
    sc.write(f":TIM:RANG 0.05;REF LEFT;POS {settle + 0.005 + 0.1 * 0.05}")
    sc.write(":WAV:POIN:MODE RAW;:WAV:POIN 20000;:SING")
    time.sleep(0.1)                          # the trigger comes 100 ms after the scope armed
    fg.write("*TRG")
    for _ in range(1000):
        if not int(sc.query(":OPER:COND?")) & 8:
            break
        time.sleep(0.01)
    assert sc.query(":TER?") == "+1"
    scale = lab.vibrometer.scale_mm_s_per_v
    t, drive = read_word(sc, 1)
    _, knee = read_word(sc, 2)
    _, tray = read_word(sc, 3)
    assert abs(fit_sine(t, drive, freq_hz)) == pytest.approx(vpp / 2, rel=0.02)   # inside the burst
    tray_v = fit_sine(t, tray * scale, freq_hz)
    assert abs(tray_v) / (2 * np.pi * freq_hz) * 1e3 == pytest.approx(amp_um, rel=0.02)
    from labkit.sim import Shaker, simulate
    res = simulate(lab.params, Shaker(freq_hz, round(lab.chain.tray_amp_um(freq_hz, lab.funcgen.drive(1).amp_v), 4)),
                   duration_s=lab.sim_duration_s, seed=lab.seed, record_dt_s=1 / (freq_hz * 64))
    sim_knee = np.asarray(res.knee_vz_mm_s)[:, 0][res.t_s > res.t_s[-1] / 3]
    assert np.std(knee * scale) == pytest.approx(np.std(sim_knee), rel=0.15)
    assert abs(np.std(knee) - np.std(tray)) > 0.2 * np.std(tray)    # not riding the tray


def test_camera_walk_stops_at_the_end_of_a_triggered_burst():
    from types import SimpleNamespace

    from labkit.lab.camera import robot_path

    t_sim = np.linspace(0.0, 0.3, 3001)
    sim = SimpleNamespace(t_s=t_sim, body_y_um=2000.0 * t_sim, body_angles_rad=np.zeros((len(t_sim), 3)))
    t = np.linspace(0.0, 1.0, 101)
    y, _, speed = robot_path(sim, t, move_s=0.4)
    assert speed == pytest.approx(2.0)                       # mm/s: 2000 um/s
    assert y[t <= 0.4] == pytest.approx(2.0 * t[t <= 0.4], abs=1e-9)
    assert np.all(y[t >= 0.4] == y[40])                      # stands where the burst left it


def test_camera_sees_the_robot_walk_during_a_sine_burst_only(lab, raw, tmp_path):
    fg = raw("funcgen")
    lab.set_setup("shaker")
    lab.camera_fps = 10
    freq_hz, amp_um = 240.0, 25.0
    vpp = 2 * amp_um / lab.chain.tray_amp_um(freq_hz, 1.0)
    drive_sine(fg, freq_hz, vpp)
    lab.record_video(tmp_path / "sine.avi", 0.5)
    walking = lab.last_recording.speed_mm_s
    assert walking != 0.0
    assert fg.query("SOUR1:BURS:MODE TRIG;NCYC 2400;STAT ON;:TRIG1:SOUR BUS;*OPC?") == "1"   # 10 s bursts
    lab.record_video(tmp_path / "armed.avi", 0.5)
    assert lab.last_recording.speed_mm_s == 0.0                     # no trigger yet: no drive
    assert fg.query("*TRG;*OPC?") == "1"
    lab.record_video(tmp_path / "burst.avi", 0.5)
    assert lab.last_recording.speed_mm_s == walking                 # inside the burst: as the sine


def test_cam_rec_writes_only_inside_the_labs_folder_and_leaves_the_channel_free(lab, raw, tmp_path):
    """A path with a directory part is refused (it overwrote an unrelated file); a clip's length does not
    hold the control channel (LAB:SPOT? answers meanwhile); too many frames is refused up front."""
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    ctl, other = raw("control"), raw("control")
    for bad in (str(victim), "../victim.txt", ".hidden.avi"):
        assert ctl.query(f'CAM:REC "{bad}",0.1') == "0"
        assert "file name only" in ctl.query("SYST:ERR?")
    assert victim.read_text() == "keep me"
    assert ctl.query("CAM:FPS 1000;:CAM:REC? \"big.avi\",600") == "0"
    assert "more than 20000 frames" in ctl.query("SYST:ERR?")
    ctl.write("CAM:FPS 20")
    ctl.write('CAM:REC "clip.avi",1.5')
    t0 = time.monotonic()
    assert other.query("LAB:SPOT?") in ("KNEE", "HIP", "BODY", "TRAY")
    assert time.monotonic() - t0 < 0.5                  # not held for the clip's 1.5 s
    assert ctl.readline() == "30"
    folder = ctl.query("CAM:DIR?").strip('"')
    assert (Path(folder) / "clip.avi").is_file() and Path(folder) == lab.recordings_dir
