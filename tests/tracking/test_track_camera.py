"""Any robot, any camera: declared robot sizes, a speed limit from physics, raw Bayer, colour and 16-bit frames,
and declared frame times for a video. Scenes from ``issue_scenes`` (an independent renderer)."""
from __future__ import annotations

import json

import numpy as np
import pytest
from issue_scenes import Camera, Leg, Robot, render
from render_scenes import write_avi, write_sequence

from labkit.analysis.tracking import track_speed, track_video
from labkit.analysis.tracking.video_io import detect_bayer, iter_frames, open_source
from labkit.cli import main


def _err(trk, truth) -> np.ndarray:
    return np.hypot(trk.u_px - truth.u_px, trk.v_px - truth.v_px)


@pytest.mark.parametrize("size", [(2.0, 0.8), (12.0, 5.0)])
def test_declared_robot_sizes(tmp_path, size):
    """A robot far from the 5 x 2 mm chip, declared: found in every frame, its scale from its length."""
    cam = Camera(n=45, mm_per_px=0.05 if size[0] < 5 else 0.15)
    # moving its own length in the clip (a robot that overlaps itself in every frame looks like dust)
    legs = [Leg(10, 1.5 if size[0] < 5 else 7.0, 0.2)]
    frames, truth = render(cam, Robot(length_mm=size[0], width_mm=size[1], legs=legs), seed=1)
    path = write_avi(tmp_path / "r.avi", frames, cam.fps)
    trk = track_video(path, mm_per_px=cam.mm_per_px, robot_size_mm=size)
    assert trk.lost_frames == 0 and np.max(_err(trk, truth)) < 0.15
    if size[0] < 5:
        # no scale: from the declared length (a robot wider than a sixth of the frame needs the scale first,
        # which sizes the background filter)
        own = track_video(path, robot_size_mm=f"{size[0]},{size[1]}")
        assert own.scale.method == "robot_length"
        assert own.mm_per_px == pytest.approx(cam.mm_per_px, rel=0.03)
    learned = track_video(path, mm_per_px=cam.mm_per_px, robot_size_mm="learn")
    assert learned.lost_frames == 0


def test_fast_robot_at_a_low_frame_rate(tmp_path, capsys):
    """40 mm/s at 15 fps (2.7 mm, half a body length, per frame): tracked by default, refused by a lower limit."""
    cam = Camera(n=20, fps=15.0, mm_per_px=0.2)
    rb = Robot(start_mm=(-26.0, 0.0), heading0_rad=-np.pi / 2, legs=[Leg(10, 40.0)])
    frames, truth = render(cam, rb, seed=2)
    path = write_avi(tmp_path / "fast.avi", frames, cam.fps)
    trk = track_video(path, mm_per_px=cam.mm_per_px)
    assert trk.lost_frames == 0
    assert track_speed(trk).mean_speed_mm_s == pytest.approx(40.0, rel=0.005)
    slow = track_video(path, mm_per_px=cam.mm_per_px, max_speed_mm_s=10.0)
    assert slow.meta["jumps_rejected"] > 0 and slow.lost_frames > 10
    code = main(["track", str(path), "--mm-per-px", "0.2", "--max-speed-mm-s", "60", "--json"])
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and out["mean_speed_mm_s"] == pytest.approx(40.0, rel=0.005)


def test_raw_bayer_frames_are_detected_and_demosaiced(tmp_path):
    cam = Camera(n=40, output="bayer")
    frames, truth = render(cam, Robot(), seed=3)
    assert detect_bayer(frames[0]) == "RGGB"
    folder = write_sequence(tmp_path / "bayer", frames)
    trk = track_video(folder, fps=cam.fps, mm_per_px=cam.mm_per_px)
    assert trk.lost_frames == 0 and np.sqrt(np.mean(_err(trk, truth) ** 2)) < 0.1
    assert any("Bayer" in w for w in trk.meta["warnings"])
    grey = render(Camera(n=2), Robot(), seed=3)[0]
    assert detect_bayer(grey[0]) is None                 # a grey frame is no mosaic


def test_colour_frames(tmp_path):
    cam = Camera(n=40, output="colour")
    frames, truth = render(cam, Robot(), seed=4)
    folder = write_sequence(tmp_path / "colour", frames)
    trk = track_video(folder, fps=cam.fps, mm_per_px=cam.mm_per_px)
    assert trk.lost_frames == 0 and np.sqrt(np.mean(_err(trk, truth) ** 2)) < 0.05


def test_dim_16_bit_frames_keep_their_depth(tmp_path):
    """A 12-bit sensor at 1 % of its range (tray ~40 counts, noise 0.5): 8-bit would leave grey levels 0-2."""
    cam = Camera(n=40, output="grey16", bits=12, level=40.0, noise=0.5)
    frames, truth = render(cam, Robot(), seed=5)
    assert frames.dtype == np.uint16 and frames.max() < 64
    folder = write_sequence(tmp_path / "deep", frames, pattern="frame_{:05d}.tif")
    cap, info = open_source(folder, fps=cam.fps)
    first, _ = next(iter_frames(cap, info))
    assert first.dtype == np.float32 and 150 < np.percentile(first, 99) < 250
    assert len(np.unique(first)) > 20
    trk = track_video(folder, fps=cam.fps, mm_per_px=cam.mm_per_px)
    assert trk.lost_frames == 0 and np.sqrt(np.mean(_err(trk, truth) ** 2)) < 0.1


def test_declared_frame_times_for_a_video(tmp_path, capsys):
    """--fps and --timestamps replace a video's own times (a high-speed camera's playback rate), never ignored."""
    cam = Camera(n=40)
    frames, truth = render(cam, Robot(legs=[Leg(10, 3.0)]), seed=6)
    path = write_avi(tmp_path / "hs.avi", frames, cam.fps)
    code = main(["track", str(path), "--mm-per-px", "0.1", "--fps", "300", "--json"])
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and out["timestamps_source"] == "fps"
    assert out["mean_speed_mm_s"] == pytest.approx(30.0, rel=0.01)      # ten times the rate, ten times the speed
    csv = tmp_path / "t.csv"
    csv.write_text("t_s\n" + "".join(f"{k / 60:.6f}\n" for k in range(40)))
    code = main(["track", str(path), "--mm-per-px", "0.1", "--timestamps", str(csv), "--json"])
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and out["timestamps_source"] == "csv"
    assert out["mean_speed_mm_s"] == pytest.approx(6.0, rel=0.01)
    csv.write_text("t_s\n" + "".join(f"{k / 60:.6f}\n" for k in range(30)))
    assert main(["track", str(path), "--mm-per-px", "0.1", "--timestamps", str(csv)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--timestamps" in err[0]


@pytest.mark.parametrize("argv, key", [(["--out", "t.txt"], "--out"), (["--robot-size-mm", "5"], "--robot-size-mm"),
                                       (["--max-speed-mm-s", "-1"], "--max-speed-mm-s"),
                                       (["--bayer", "XYZW"], "--bayer")])
def test_bad_camera_options_exit_2(tmp_path, capsys, argv, key):
    cam = Camera(n=12)
    frames, _ = render(cam, Robot(), seed=7)
    path = write_avi(tmp_path / "v.avi", frames, cam.fps)
    argv = [a if a != "t.txt" else str(tmp_path / "t.txt") for a in argv]
    assert main(["track", str(path), "--mm-per-px", "0.1", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0]
    assert not (tmp_path / "t.txt").exists()
