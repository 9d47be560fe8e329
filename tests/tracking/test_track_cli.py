"""``labkit track``: outputs, JSON, and exit 2 with one clear line on bad input."""
from __future__ import annotations

import json

import cv2
import h5py
import numpy as np
import pytest
from trackhelpers import MM_PER_PX, make_video, true_speed_mm_s

from labkit.cli import main
from labkit.lab.render import write_video
from tests.conftest import last_json


@pytest.mark.slow
def test_track_cli_writes_everything(video_dir, tmp_path, cli):
    video, truth, (y, x, _h) = make_video(video_dir, "cli", "curve", n=60, jitter_px=1.0, blur_px=2.0,
                                          occlusion=[(1.0, 1.2)])
    out = tmp_path / "track.h5"
    proc = cli("track", str(video), "--mm-per-px", str(MM_PER_PX), "--out", str(out),
               "--overlay", str(tmp_path / "overlay.avi"), "--json")
    s = last_json(proc)
    for key in ("mean_speed_mm_s", "speed_ci_mm_s", "frames", "lost_frames", "frame_to_frame_speed_mm_s",
                "net_speed_mm_s", "mean_velocity_mm_s", "path_length_mm", "mm_per_px", "mm_per_px_std"):
        assert key in s, key
    lost = int((~truth.visible).sum())
    assert s["frames"] == 60 and s["lost_frames"] == lost > 0
    v_true = true_speed_mm_s(y, x, truth.t_s)
    assert s["mean_speed_mm_s"] == pytest.approx(v_true, rel=0.01)
    assert s["speed_ci_mm_s"][0] < s["mean_speed_mm_s"] < s["speed_ci_mm_s"][1]
    with h5py.File(out) as f:
        assert f.attrs["kind"] == "track"
        for name in ("t_s", "x_mm", "y_mm", "heading_rad", "quality"):
            assert f[name].shape == (60,) and "units" in f[name].attrs
        assert f["x_mm"].attrs["units"] == "mm" and f["t_s"].attrs["units"] == "s"
        assert f.attrs["mean_speed_mm_s"] == pytest.approx(s["mean_speed_mm_s"])
        assert len(f.attrs["speed_ci_mm_s"]) == 2
        assert f.attrs["mm_per_px"] == MM_PER_PX and f.attrs["mm_per_px_std"] == 0.0
        assert int(np.sum(f["quality"][()] == 2)) == lost
        assert np.isnan(f["x_mm"][()][~truth.visible]).all()
    import labkit
    back = labkit.open(out)
    assert back.kind == "track" and back.lost_frames == lost and back.mm_per_px == MM_PER_PX
    lines = (tmp_path / "track.csv").read_text().splitlines()
    assert lines[1].startswith("t_s,x_mm,y_mm,heading_rad,quality") and len(lines) == 62
    png = cv2.imread(str(tmp_path / "track.png"))
    assert png is not None and png.shape[0] > 300
    cap = cv2.VideoCapture(str(tmp_path / "overlay.avi"))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 60
    ok, frame = cap.read()
    assert ok and frame.ndim == 3 and (np.abs(frame[..., 2].astype(int) - frame[..., 0]) > 60).any()  # colour drawn


def _run(capsys, *argv):
    code = main(["track", *argv])
    err = capsys.readouterr().err.strip().splitlines()
    return code, err


def test_bad_inputs_exit_2_with_one_line(tmp_path, capsys):
    garbage = tmp_path / "garbage.avi"
    garbage.write_bytes(b"not a video" * 200)
    empty = tmp_path / "empty.avi"
    vw = cv2.VideoWriter(str(empty), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*"MJPG"), 30, (640, 480), False)
    vw.release()
    blank = write_video(tmp_path / "blank.avi", np.full((8, 240, 320), 200, np.uint8), 30)
    t = np.arange(12) / 30
    from labkit.lab.render import render_frames
    good = write_video(tmp_path / "good.avi", render_frames(3 * t, None, 0.0, t), 30)
    cases = [
        ((str(tmp_path / "missing.avi"),), "no such video file"),
        ((str(garbage),), "not a readable video"),
        ((str(empty),), "no frames"),
        ((str(blank),), "no robot found"),
        ((str(good), "--roi", "1,2,3"), "bad region of interest"),
        ((str(good), "--roi", "600,0,100,100"), "not inside the 640x480 frame"),
        ((str(good), "--scale-bar", "1,2,3"), "bad scale bar"),
        ((str(good), "--mm-per-px", "-1"), "bad scale"),
        ((str(good), "--out", str(tmp_path / "nowhere" / "t.h5")), "folder does not exist"),
    ]
    for argv, message in cases:
        code, err = _run(capsys, *argv)
        assert code == 2, (argv, err)
        assert len(err) == 1 and message in err[0] and err[0].startswith("labkit track: error:"), (argv, err)


def test_bad_input_json_and_real_exit_code(tmp_path, cli):
    proc = cli("track", str(tmp_path / "missing.avi"), "--json", check=2)
    s = last_json(proc)
    assert s["ok"] is False and s["exit_code"] == 2 and "missing.avi" in s["error"]
    assert len(proc.stderr.strip().splitlines()) == 1
    json.dumps(s)
