"""``labkit track VIDEO``: the robot's path, heading and speed (with a confidence interval) from video."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from labkit.errors import InputError
from labkit.outputs import atomic_outputs, check_outputs

NAME = "track"
HELP = "track the robot in a top-view video: path, heading, speed with confidence interval"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("video", help="video file (.avi, .mkv, .mp4, ...)")
    sc = parser.add_mutually_exclusive_group()
    sc.add_argument("--mm-per-px", type=float, metavar="X", help="image scale (mm per pixel)")
    sc.add_argument("--scale-bar", metavar="x1,y1,x2,y2,MM",
                    help="two points (px) on a scale bar and the distance between them (mm)")
    sc.add_argument("--robot-length-mm", type=float, metavar="MM",
                    help="scale from the robot's known body length (the default, 5 mm)")
    parser.add_argument("--mm-per-px-std", type=float, default=0.0, metavar="X",
                        help="standard uncertainty of --mm-per-px (default 0)")
    parser.add_argument("--roi", metavar="x,y,w,h", help="search only this region (pixels)")
    parser.add_argument("--mask", metavar="PNG", help="mask image of the frame's size, non-zero = search")
    parser.add_argument("--window-s", type=float, default=None,
                        help="smoothing window for the speed (s; default 1 s, >= 7 frames)")
    parser.add_argument("--out", metavar="FILE",
                        help="track HDF5 file (kind 'track'); a .csv and a .png are written beside it")
    parser.add_argument("--overlay", metavar="FILE", help="overlay video with trajectory and heading (.avi or .mkv)")
    parser.add_argument("--force", action="store_true",
                        help="replace existing outputs (--out, its .csv and .png, --overlay)")


def _scale_bar(text: str):
    from labkit.analysis.tracking.tracker import scale_from_bar

    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != 5:
        raise InputError(f"bad scale bar {text!r}", key="--scale-bar", expected="x1,y1,x2,y2,MM")
    return scale_from_bar(*vals)


def run(args: argparse.Namespace) -> dict[str, Any]:
    import numpy as np

    from labkit.analysis.tracking.output import plot_path, save_track_csv, save_track_h5, summary, write_overlay
    from labkit.analysis.tracking.speed import track_speed
    from labkit.analysis.tracking.tracker import ROBOT_LENGTH_MM, scale_given, track_video

    scale = None
    if args.mm_per_px is not None:
        if not args.mm_per_px > 0:
            raise InputError(f"bad scale {args.mm_per_px}", key="--mm-per-px", expected="a number > 0")
        scale = scale_given(args.mm_per_px, args.mm_per_px_std)
    elif args.scale_bar is not None:
        scale = _scale_bar(args.scale_bar)
    length = args.robot_length_mm if args.robot_length_mm is not None else ROBOT_LENGTH_MM
    if not length > 0:
        raise InputError(f"bad robot length {length}", key="--robot-length-mm", expected="a length > 0 mm")
    if args.window_s is not None and not args.window_s > 0:
        raise InputError(f"bad window {args.window_s}", key="--window-s", expected="a duration > 0 s")

    # every output, sidecars included, is checked before a frame is read
    out = Path(args.out) if args.out else None
    if out is not None:
        if out.suffix.lower() in (".csv", ".png"):
            raise InputError("the track file would clash with its own .csv/.png sidecar", file=out,
                             key="--out", expected="a .h5 file name")
        check_outputs([out, out.with_suffix(".csv"), out.with_suffix(".png")], force=args.force)
    check_outputs([args.overlay], force=args.force, key="--overlay", suffixes=(".avi", ".mkv"))
    if args.overlay and out is not None:
        check_outputs([out, out.with_suffix(".csv"), out.with_suffix(".png"), args.overlay], force=True)
    track = track_video(args.video, roi=args.roi, mask=args.mask, scale=scale, robot_length_mm=length,
                        quiet=args.quiet)
    speed = track_speed(track, window_s=args.window_s)
    result = summary(track, speed)
    jobs: list[tuple[str, Path, Any]] = []
    if out is not None:
        jobs += [("track_h5", out, lambda p: save_track_h5(p, track, speed)),
                 ("track_csv", out.with_suffix(".csv"), lambda p: save_track_csv(p, track, speed)),
                 ("path_png", out.with_suffix(".png"), lambda p: plot_path(p, track, speed))]
    if args.overlay:
        jobs.append(("overlay", Path(args.overlay), lambda p: write_overlay(args.video, track, p, speed)))
    # all written to temporary names first, renamed together: every old file survives any failed write
    with atomic_outputs([target for _, target, _ in jobs]) as temps:
        for (_, _, write), tmp in zip(jobs, temps):
            write(tmp)
    written = {name: str(target) for name, target, _ in jobs}
    result["written"] = written
    if not args.json:
        lo, hi = speed.speed_ci_mm_s
        print(f"{track.source}: {track.frames} frames ({track.lost_frames} lost), "
              f"scale {track.mm_per_px:.5g} +- {track.scale.mm_per_px_std:.2g} mm/px ({track.scale.method})")
        print(f"  mean speed {speed.mean_speed_mm_s:.4g} mm/s, {int(100 * speed.ci_level)}% CI "
              f"[{lo:.4g}, {hi:.4g}] (smoothed path, window {speed.window_s:.3g} s)")
        print(f"  frame-to-frame {speed.frame_to_frame_speed_mm_s:.4g} mm/s (overstates under jitter), "
              f"net displacement {speed.net_speed_mm_s:.4g} mm/s (understates on curves)")
        vx, vy = speed.mean_velocity_mm_s
        print(f"  mean velocity ({vx:.4g}, {vy:.4g}) mm/s, path {speed.path_length_mm:.4g} mm, "
              f"turning {np.degrees(speed.mean_turn_rate_rad_s):.3g} deg/s")
        for k, v in written.items():
            print(f"  wrote {k}: {v}")
    return result
