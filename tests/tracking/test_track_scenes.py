"""The tracker on what a real stereoscope bench produces, rendered by an independent renderer.

Every video here comes from ``render_scenes`` (OpenCV polygon filling and NumPy, no labkit
code) with known truth: uneven ring light, flicker, a grey low-contrast chip, static dust
larger than the chip, an occluding tweezer, a chip leaving the frame, dropped frames, a
truncated file, image sequences; and the interval's coverage over many noise seeds.
Videos are small (320 x 240 at 0.1 mm/px: the chip is 50 x 20 px) and short, so the whole
file runs in well under a minute.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from render_scenes import (
    Scene,
    chip_area_mm2,
    chip_polygons_mm,
    coverage,
    place,
    render,
    truncate,
    write_avi,
    write_mkv,
    write_mp4,
    write_sequence,
)

from labkit.analysis.tracking import track_file, track_speed, track_video
from labkit.analysis.tracking.tracker import QUALITY_LOST, QUALITY_OK
from labkit.cli import main
from labkit.errors import InputError

S = 0.1      # mm per px


def scene(**kw) -> Scene:
    base = dict(width=320, height=240, mm_per_px=S, n=60, fps=30.0)
    base.update(kw)
    return Scene(**base)


def video(tmp_path, name: str, sc: Scene, kind: str = "avi"):
    frames, truth = render(sc)
    if kind == "avi":
        path = write_avi(tmp_path / f"{name}.avi", frames, sc.fps)
    elif kind == "mkv":
        path = write_mkv(tmp_path / f"{name}.mkv", frames, truth.t_s)
    elif kind == "mp4":
        path = write_mp4(tmp_path / f"{name}.mp4", frames, sc.fps)
    else:
        path = write_sequence(tmp_path / name, frames, truth.t_s if kind == "csv" else None)
    return path, truth


def pos_err(track, truth) -> np.ndarray:
    return np.hypot(track.u_px - truth.u_px, track.v_px - truth.v_px)


def run_cli(capsys, *argv) -> tuple[int, list[str], list[str]]:
    code = main(["track", *argv])
    cap = capsys.readouterr()
    return code, cap.out.strip().splitlines(), cap.err.strip().splitlines()


def test_renderer_truth():
    """The independent renderer's darkness centroid is the chip's centre; its area the drawn area."""
    sc = scene(noise=0.0)
    rng = np.random.default_rng(0)
    vv, uu = np.mgrid[:240, :320]
    for _ in range(5):
        u, v, h = rng.uniform(120, 200), rng.uniform(90, 150), rng.uniform(-np.pi, np.pi)
        cov = coverage((240, 320), place(chip_polygons_mm(), u, v, h, S))
        assert (cov * uu).sum() / cov.sum() == pytest.approx(u, abs=0.03)
        assert (cov * vv).sum() / cov.sum() == pytest.approx(v, abs=0.03)
        assert cov.sum() * S ** 2 == pytest.approx(chip_area_mm2(), rel=0.015)
    frames, truth = render(sc)
    assert frames.shape == (60, 240, 320) and np.all(truth.visible_frac > 0.99)


@pytest.mark.parametrize("name,kw", [
    ("ring_light", dict(gradient=0.3, ring=0.15)),                       # 30 % across, darker corners
    ("flicker", dict(gradient=0.3, flicker=0.15)),                        # +-15 % frame to frame
    ("grey_chip", dict(chip_reflectance=0.72)),                           # 28 % contrast
    ("grey_chip_uneven", dict(chip_reflectance=0.72, gradient=0.3, flicker=0.08, noise=2.5)),
    ("mottled_tray", dict(mottling=0.05, gradient=0.2)),                  # blotches of +-5 %, ~2 mm across
    ("grey_chip_mottled", dict(chip_reflectance=0.7, mottling=0.03, gradient=0.3)),   # the chip is opaque
])
def test_adaptive_segmentation(tmp_path, name, kw):
    path, truth = video(tmp_path, name, scene(seed=3, **kw))
    track = track_video(path, mm_per_px=S)
    assert np.all(track.quality == QUALITY_OK), track.meta["warnings"]
    assert not track.meta["static_objects"]                 # mottling is not dust
    assert np.sqrt(np.mean(pos_err(track, truth) ** 2)) <= 0.15
    sp = track_speed(track)
    assert sp.mean_speed_mm_s == pytest.approx(truth.speed_mm_s, rel=0.01)
    # the contrast found is stated, and the threshold came from the data's noise
    expected = 1 - kw.get("chip_reflectance", 0.2)
    assert track.meta["robot_contrast"] == pytest.approx(expected, abs=0.04)
    assert track.meta["min_contrast"] < 0.15 and np.isfinite(track.meta["noise"])


def test_mp4_with_uneven_light(tmp_path):
    path, truth = video(tmp_path, "ring_mp4", scene(gradient=0.3, ring=0.15, seed=2), kind="mp4")
    track = track_video(path, mm_per_px=S)
    assert np.all(track.quality == QUALITY_OK)
    assert np.sqrt(np.mean(pos_err(track, truth) ** 2)) <= 0.15
    assert track_speed(track).mean_speed_mm_s == pytest.approx(truth.speed_mm_s, rel=0.01)


def test_static_dust_larger_than_the_chip_is_not_the_robot(tmp_path):
    # a dark speck 7 x 3 mm (the chip: 5 x 2 mm), darker than the chip; the chip walks into it
    dust = [(75.0, 110.0, 35.0, 15.0, 60.0, 0.15)]
    path, truth = video(tmp_path, "dust", scene(dust=dust, heading0_rad=0.9, turn_rad_s=0.2, seed=4))
    track = track_video(path, mm_per_px=S)
    assert any("static dark object" in w for w in track.meta["warnings"])
    q = track.quality
    assert np.mean(q == QUALITY_OK) >= 0.75 and not np.any(q == QUALITY_LOST)
    e = pos_err(track, truth)
    assert np.nanmax(e[q == QUALITY_OK]) <= 0.3           # the right object in every frame called good
    assert np.nanmax(e) <= 3.0                            # touching the dust: degraded, never on the dust
    sp = track_speed(track)
    assert sp.mean_speed_mm_s == pytest.approx(truth.speed_mm_s, rel=0.01)
    assert sp.mean_speed_mm_s > 2.0                       # not the dust's 0 mm/s


def test_only_dust_no_robot_exits_2(tmp_path, capsys):
    dust = [(90.0, 70.0, 35.0, 15.0, 20.0, 0.15)]
    path, _ = video(tmp_path, "dust_only", scene(dust=dust, chip_reflectance=1.0, n=20))
    code, _, err = run_cli(capsys, str(path), "--mm-per-px", str(S))
    assert code == 2 and len(err) == 1
    assert "no robot found" in err[0] and "static" in err[0], err


def test_a_second_chip_is_warned_and_the_first_one_kept(tmp_path):
    # a second, identical chip walking elsewhere: which one is "the robot" cannot be known at the
    # start (warned); once acquired, the motion model keeps the same one throughout
    sc = scene(others=[(60.0, 200.0, -1.2, 2.0)], start_px=(230.0, 80.0), heading0_rad=2.0, turn_rad_s=0.0,
               seed=13)
    path, truth = video(tmp_path, "two_chips", sc)
    track = track_video(path, mm_per_px=S)
    assert any("second robot-sized object" in w for w in track.meta["warnings"])
    assert track.meta["ambiguous_frames"] >= 1
    e = pos_err(track, truth)
    on_first = e < 1.0
    assert on_first.all() or not on_first.any()        # never switches from one chip to the other


def test_robot_vibrating_in_place_is_not_dust(tmp_path):
    # a drive that does not make it walk: the chip jitters in place beside a static speck of dust;
    # only the object of the robot's size and length is taken, and its speed is ~0, not an error
    dust = [(60.0, 60.0, 35.0, 15.0, 20.0, 0.15)]
    path, truth = video(tmp_path, "still", scene(speed_mm_s=0.0, turn_rad_s=0.0, jitter_px=1.0, n=40, dust=dust))
    track = track_video(path, mm_per_px=S)
    assert any("hardly moved" in w for w in track.meta["warnings"])
    assert np.nanmax(pos_err(track, truth)) <= 0.2
    sp = track_speed(track)
    lo, hi = sp.speed_ci_mm_s
    assert lo == 0.0 and hi < 0.5                    # a jitter of 0.1 mm: the interval holds 0


@pytest.mark.parametrize("grey", [False, True])
def test_tweezer_occlusion_flagged_and_bridged(tmp_path, grey):
    # the prongs are darker than a grey chip: then they, not the chip, are the darkest robot-sized thing
    if grey:      # 640 x 480: the prongs cross the chip's whole window
        sc = scene(width=640, height=480, mm_per_px=0.05, n=90, tweezers=(1.2, 2.0), speed_mm_s=2.0,
                   turn_rad_s=-0.27, heading0_rad=2.56, chip_reflectance=0.7, gradient=0.3, ring=0.1, flicker=0.1,
                   noise=2.5, blur_px=1.0, seed=0)
    else:
        sc = scene(n=90, tweezers=(1.0, 2.0), seed=5)
    path, truth = video(tmp_path, f"tweezer_{grey}", sc)
    track = track_video(path, mm_per_px=sc.mm_per_px)
    q = track.quality
    hidden = truth.visible_frac < 0.9
    assert hidden.sum() >= 10
    assert not np.any(q[hidden] == QUALITY_OK)                      # a covered chip is never "good"
    e = pos_err(track, truth)
    assert np.nanmax(e[q == QUALITY_OK]) <= 0.3                     # never pulled onto a prong
    assert track.meta["lost_stretches_s"] and any("lost" in w for w in track.meta["warnings"])
    sp = track_speed(track)                                         # bridged by the smoothed path
    assert sp.mean_speed_mm_s == pytest.approx(truth.speed_mm_s, rel=0.01)
    assert sp.t_s[0] < sc.tweezers[0] < sc.tweezers[1] < sp.t_s[-1]


def test_chip_leaving_the_frame(tmp_path):
    sc = scene(n=60, speed_mm_s=4.0, heading0_rad=-np.pi / 2, turn_rad_s=0.0, start_px=(230.0, 120.0), seed=6)
    path, truth = video(tmp_path, "leaving", sc)
    track = track_video(path, mm_per_px=S)
    q = track.quality
    cut = truth.visible_frac < 0.99
    assert cut.sum() >= 10 and np.all(q[cut] != QUALITY_OK)
    assert np.all(q[truth.visible_frac < 0.3] == QUALITY_LOST)
    assert np.nanmax(pos_err(track, truth)[q == QUALITY_OK]) <= 0.2
    assert track_speed(track).mean_speed_mm_s == pytest.approx(4.0, rel=0.01)


def test_dropped_frames_use_the_container_times(tmp_path):
    rng = np.random.default_rng(8)
    t = np.cumsum(np.r_[0.0, rng.choice([1, 2, 3], 59, p=[0.6, 0.3, 0.1]) / 30])
    path, truth = video(tmp_path, "dropped", scene(t_s=t, seed=8), kind="mkv")
    track = track_video(path, mm_per_px=S)
    assert np.abs(track.t_s - t).max() <= 0.0006
    assert track_speed(track).mean_speed_mm_s == pytest.approx(truth.speed_mm_s, rel=0.01)
    from labkit.analysis.tracking.video_io import open_video
    cap, info = open_video(path)
    cap.release()
    assert info.frame_count == 60                                   # the progress bar's total is right


def test_truncated_file_keeps_every_decodable_frame(tmp_path, capsys):
    path, truth = video(tmp_path, "trunc", scene(n=50, seed=9))
    truncate(path)
    track = track_video(path, mm_per_px=S)
    assert 45 <= track.frames <= 49
    assert any("could not be decoded" in w for w in track.meta["warnings"])
    k = track.frames
    assert np.allclose(track.t_s, truth.t_s[:k], atol=1e-6)
    assert np.nanmax(np.hypot(track.u_px - truth.u_px[:k], track.v_px - truth.v_px[:k])) <= 0.2
    assert track_speed(track).mean_speed_mm_s == pytest.approx(truth.speed_mm_s, rel=0.01)
    code, out, _ = run_cli(capsys, str(path), "--mm-per-px", str(S), "--json")
    s = json.loads(out[-1])
    assert code == 0 and s["frames"] == k and s["undecodable_frames"] == 50 - k


def test_truncated_file_progress_ends_at_the_decodable_frames(tmp_path, monkeypatch):
    """The container lists 80 frames, the last is cut mid-write: the bar must not stop at 79/80."""
    import io

    from tqdm import tqdm

    import labkit.progress

    path, _ = video(tmp_path, "trunc80", scene(n=80, seed=9))
    truncate(path)
    bars, text = [], io.StringIO()

    def visible_bar(total=None, desc="", *, quiet=False, unit="pt"):    # labkit.progress.progress, shown
        bars.append(tqdm(total=total, desc=desc, unit=unit, file=text, leave=False, ascii=True))
        return bars[-1]

    monkeypatch.setattr(labkit.progress, "progress", visible_bar)
    track = track_video(path, mm_per_px=S)
    k = track.frames
    assert k == 79 and track.meta["undecodable_frames"] == 1        # as the decoder sees the file
    (pb,) = bars
    assert (pb.n, pb.total) == (k, k) and pb.leave                 # finished, and left on the terminal
    assert f"{k} of 80 frames decodable" in text.getvalue().rsplit("\r", 1)[-1]
    # an intact file keeps the container's total and its plain label
    bars.clear()
    whole, _ = video(tmp_path, "whole", scene(n=40, seed=9))
    track_video(whole, mm_per_px=S)
    assert (bars[0].n, bars[0].total, bars[0].desc, bars[0].leave) == (40, 40, "track", False)


def test_image_sequences(tmp_path, capsys):
    rng = np.random.default_rng(10)
    t = np.cumsum(np.r_[0.0, rng.choice([1, 2], 44, p=[0.8, 0.2]) / 30])
    folder, truth = video(tmp_path, "seq_csv", scene(t_s=t, seed=10), kind="csv")
    track = track_video(folder, mm_per_px=S)            # a folder with timestamps.csv beside the images
    assert track.timestamps_source == "csv" and np.allclose(track.t_s, t, atol=1e-6)
    assert track_speed(track).mean_speed_mm_s == pytest.approx(truth.speed_mm_s, rel=0.01)
    # a pattern and a frame rate, through the command line
    plain, truth2 = video(tmp_path, "seq_fps", scene(n=45, seed=11), kind="png")
    pattern = str(plain / "frame_%05d.png")
    overlay = tmp_path / "seq_overlay.avi"
    code, out, err = run_cli(capsys, pattern, "--fps", "30", "--mm-per-px", str(S), "--overlay", str(overlay), "--json")
    assert code == 0, err
    s = json.loads(out[-1])
    assert s["frames"] == 45 and s["timestamps_source"] == "fps"
    import cv2
    cap = cv2.VideoCapture(str(overlay))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 45
    cap.release()
    assert s["mean_speed_mm_s"] == pytest.approx(truth2.speed_mm_s, rel=0.01)
    # no times at all: refused with the way out named
    code, _, err = run_cli(capsys, pattern, "--mm-per-px", str(S))
    assert code == 2 and len(err) == 1 and "--fps" in err[0]


def test_outputs_checked_before_work_and_preview(tmp_path, capsys):
    path, _ = video(tmp_path, "outs", scene(n=30, gradient=0.3, seed=12))
    existing = tmp_path / "t.h5"
    existing.write_text("old")
    for argv, msg in [(("--out", str(existing)), "already exists"),
                      (("--overlay", str(tmp_path / "out.txt")), "unsupported file type"),
                      (("--out", str(tmp_path / "nowhere" / "t.h5")), "folder does not exist"),
                      (("--min-contrast", "1.5"), "bad contrast"),
                      (("--preview", "999", "--preview-png", str(tmp_path / "p.png")), "no frame 999")]:
        code, _, err = run_cli(capsys, str(path), "--mm-per-px", str(S), *argv)
        assert code == 2 and len(err) == 1 and msg in err[0], (argv, err)
    assert existing.read_text() == "old"
    png = tmp_path / "preview.png"
    code, out, _ = run_cli(capsys, str(path), "--mm-per-px", str(S), "--preview", "10", "--preview-png", str(png),
                           "--json")
    s = json.loads(out[-1])
    import cv2
    img = cv2.imread(str(png))
    assert code == 0 and img.shape == (240, 320, 3) and s["robot_like"] == 1
    assert s["strongest_contrast"] == pytest.approx(0.8, abs=0.05)
    # the library call writes everything, all or nothing
    res = track_file(path, out=tmp_path / "lib.h5", mm_per_px=S)
    assert set(res.written) == {"track_h5", "track_csv", "path_png"} and res.summary["frames"] == 30
    with pytest.raises(InputError, match="already exists"):
        track_file(path, out=tmp_path / "lib.h5", mm_per_px=S)


def test_interval_coverage_over_seeds(tmp_path):
    """The 95 % interval holds the true speed in >= 90 % of 24 videos that differ in noise seed."""
    hits, n, errs = 0, 24, []
    for seed in range(n):
        rng = np.random.default_rng(100 + seed)
        sc = scene(speed_mm_s=float(rng.uniform(2, 4)), turn_rad_s=float(rng.uniform(-0.4, 0.4)),
                   heading0_rad=float(rng.uniform(-np.pi, np.pi)), jitter_px=1.0, noise=3.0, gradient=0.2,
                   flicker=0.05, seed=seed, mm_per_px=0.08)
        path, truth = video(tmp_path, f"cov{seed}", sc)
        sp = track_speed(track_video(path, mm_per_px=0.08))
        lo, hi = sp.speed_ci_mm_s
        hits += lo <= truth.speed_mm_s <= hi
        errs.append(sp.mean_speed_mm_s / truth.speed_mm_s - 1)
    print(f"\n95 % interval held the true speed in {hits} of {n} videos; "
          f"errors {100 * np.min(errs):+.2f} .. {100 * np.max(errs):+.2f} %")
    assert hits >= 0.9 * n
    assert np.max(np.abs(errs)) < 0.02
