"""``labkit track VIDEO``: the robot's path, heading and speed (with a confidence interval) from video."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

from labkit.errors import InputError
from labkit.outputs import atomic_output, check_outputs

if TYPE_CHECKING:
    from labkit.analysis.tracking.pipeline import TrackResult
    from labkit.analysis.tracking.tracker import Scale

NAME = "track"


class _VideoOptions(TypedDict):
    """How the video is read and searched, the same for tracking and for a preview (the options as given)."""

    roi: str | None
    mask: str | None
    min_contrast: float | None
    fps: float | None
    timestamps: str | None
    bayer: str
    robot_size_mm: str | None
HELP = "track the robot in a top-view video: path, heading, speed with confidence interval"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("video", help="video file (.avi, .mkv, .mp4, ...), a folder of images, or a pattern "
                                      "such as frames/frame_%%05d.png")
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
    parser.add_argument("--min-contrast", type=float, metavar="C",
                        help="darkness (tray - robot) / tray a robot must have (default: from the pixel noise)")
    parser.add_argument("--fps", type=float, metavar="RATE",
                        help="frame rate: of an image sequence without a timestamps.csv, or replacing a video's "
                             "own frame times (a high-speed camera that wrote its playback rate)")
    parser.add_argument("--timestamps", metavar="CSV",
                        help="frame times (a CSV with a t_s column, optionally file): of an image sequence, or "
                             "one per frame replacing a video's own")
    parser.add_argument("--robot-size-mm", metavar="L,W",
                        help="the robot's length and width (mm; default the 5 x 2 mm chip), or 'learn' to assume "
                             "nothing and learn its outline from the first clear frames")
    parser.add_argument("--max-speed-mm-s", type=float, metavar="V",
                        help="fastest the robot can go (a farther candidate is an occlusion); default one body "
                             "length per frame interval")
    parser.add_argument("--line-time-us", type=float, metavar="US",
                        help="rolling shutter: the delay between rows (us; 0 = global shutter); frame times are "
                             "corrected at the robot's row. Undeclared, the error budget allows for any shutter")
    parser.add_argument("--line-time-std-us", type=float, default=0.0, metavar="US",
                        help="standard uncertainty of --line-time-us (default 0)")
    parser.add_argument("--timestamp-std-ms", type=float, metavar="MS",
                        help="the camera clock's accuracy per frame (ms), if worse than the frame times' own scatter")
    parser.add_argument("--bayer", default="auto", metavar="PATTERN",
                        help="raw Bayer frames: auto (detected), none, RGGB, BGGR, GRBG or GBRG (demosaiced to grey)")
    parser.add_argument("--preview", type=int, metavar="FRAME",
                        help="only draw frame FRAME (0-based) with the segmentation and the ROI into a PNG "
                             "(--preview-png), to see why a video fails")
    parser.add_argument("--preview-png", metavar="PNG",
                        help="where --preview writes (default: VIDEO-STEM_preview_FRAME.png here)")
    parser.add_argument("--force", action="store_true",
                        help="replace existing outputs (--out, its .csv and .png, --overlay, --preview-png)")


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

    from labkit.analysis.tracking.pipeline import track_file
    from labkit.analysis.tracking.tracker import ROBOT_LENGTH_MM, robot_size

    scale = _scale(args)
    length = args.robot_length_mm
    if length is None:
        length = robot_size(args.robot_size_mm).length_mm or ROBOT_LENGTH_MM
    if not length > 0:
        raise InputError(f"bad robot length {length}", key="--robot-length-mm", expected="a length > 0 mm")
    _check_limits(args)
    common = _VideoOptions(roi=args.roi, mask=args.mask, min_contrast=args.min_contrast, fps=args.fps,
                           timestamps=args.timestamps, bayer=args.bayer, robot_size_mm=args.robot_size_mm)
    if args.preview is not None:
        return _preview(args, scale, common)
    if args.preview_png is not None:
        raise InputError("--preview-png needs --preview FRAME", key="--preview-png")
    for key, val in (("--line-time-us", args.line_time_us), ("--line-time-std-us", args.line_time_std_us),
                     ("--timestamp-std-ms", args.timestamp_std_ms)):
        if val is not None and not val >= 0:
            raise InputError(f"bad {key} {val}", key=key, expected="a time >= 0")
    res = track_file(args.video, out=args.out, overlay=args.overlay, force=args.force, scale=scale,
                     line_time_s=None if args.line_time_us is None else 1e-6 * args.line_time_us,
                     line_time_std_s=1e-6 * args.line_time_std_us,
                     timestamp_std_s=None if args.timestamp_std_ms is None else 1e-3 * args.timestamp_std_ms,
                     robot_length_mm=length, max_speed_mm_s=args.max_speed_mm_s, window_s=args.window_s,
                     quiet=args.quiet, **common)
    if not args.json:
        _print_result(res)
    return res.summary


def _scale(args: argparse.Namespace) -> Scale | None:
    """The scale given (``--mm-per-px`` or ``--scale-bar``), or None: the robot's length in the video sets it."""
    from labkit.analysis.tracking.tracker import scale_given

    if args.mm_per_px is not None:
        if not args.mm_per_px > 0:
            raise InputError(f"bad scale {args.mm_per_px}", key="--mm-per-px", expected="a number > 0")
        return scale_given(args.mm_per_px, args.mm_per_px_std)
    if args.scale_bar is not None:
        return _scale_bar(args.scale_bar)
    return None


def _check_limits(args: argparse.Namespace) -> None:
    """Frame rate, contrast threshold and speed limit, when given, within their meaning (exit 2 if not)."""
    if args.fps is not None and not args.fps > 0:
        raise InputError(f"bad frame rate {args.fps}", key="--fps", expected="frames per second > 0")
    if args.min_contrast is not None and not 0 < args.min_contrast < 1:
        raise InputError(f"bad contrast {args.min_contrast}", key="--min-contrast",
                         expected="a share between 0 and 1, e.g. 0.1")
    if args.max_speed_mm_s is not None and not args.max_speed_mm_s > 0:
        raise InputError(f"bad speed limit {args.max_speed_mm_s}", key="--max-speed-mm-s", expected="a speed > 0 mm/s")


def _print_result(res: TrackResult) -> None:
    """The track's headline for a person: frames, scale, speeds with their intervals, contrast, files."""
    import numpy as np

    track, speed = res.track, res.speed
    lo, hi = speed.speed_ci_mm_s
    assert track.scale is not None
    print(f"{track.source}: {track.frames} frames ({track.lost_frames} lost), "
          f"scale {track.mm_per_px:.5g} +- {track.scale.mm_per_px_std:.2g} mm/px ({track.scale.method})")
    print(f"  mean speed {speed.mean_speed_mm_s:.4g} mm/s, {int(100 * speed.ci_level)}% CI "
          f"[{lo:.4g}, {hi:.4g}] (smoothed path, window {speed.window_s:.3g} s)")
    if np.isfinite(speed.moving_speed_mm_s) and speed.moving_s < 0.98 * speed.duration_s:
        mlo, mhi = speed.moving_speed_ci_mm_s
        print(f"  while moving ({speed.moving_s:.3g} of {speed.duration_s:.3g} s): "
              f"{speed.moving_speed_mm_s:.4g} mm/s [{mlo:.4g}, {mhi:.4g}]; "
              f"the mean above is over the whole clip, pauses included")
    print(f"  frame-to-frame {speed.frame_to_frame_speed_mm_s:.4g} mm/s (overstates under jitter), "
          f"net displacement {speed.net_speed_mm_s:.4g} mm/s (understates on curves)")
    vx, vy = speed.mean_velocity_mm_s
    print(f"  mean velocity ({vx:.4g}, {vy:.4g}) mm/s, path {speed.path_length_mm:.4g} mm, "
          f"turning {np.degrees(speed.mean_turn_rate_rad_s):.3g} deg/s")
    for part in speed.meta.get("budget", {}).get("parts", []):
        print(f"  +- {part['std_mm_s']:.2g} mm/s {part['name']} ({part['kind']}, {part['source']})")
    c, thr, nz = (track.meta.get(k, float("nan")) for k in ("robot_contrast", "min_contrast", "noise"))
    print(f"  contrast: robot {100 * c:.1f} % darker than the tray; threshold {100 * thr:.1f} % "
          f"(pixel noise {100 * nz:.2f} %)")
    for w in res.warnings:
        print(f"  warning: {w}")
    for k, v in res.written.items():
        print(f"  wrote {k}: {v}")


def _preview(args: argparse.Namespace, scale: Any, common: _VideoOptions) -> dict[str, Any]:
    from labkit.analysis.tracking.preview import preview_frame

    if args.out or args.overlay:
        raise InputError("--preview draws one frame only", key="--preview", expected="no --out/--overlay with it")
    png = Path(args.preview_png) if args.preview_png else Path(f"{Path(args.video).stem}_preview_{args.preview}.png")
    check_outputs([png], force=args.force, key="--preview-png", suffixes=(".png",))
    with atomic_output(png) as tmp:
        res = preview_frame(args.video, args.preview, tmp, scale=scale, **common)
    res["preview_png"] = str(png)
    if not args.json:
        print(f"{args.video}: frame {res['frame']} (t = {res['t_s']:.3f} s): threshold "
              f"{100 * res['min_contrast']:.1f} %, pixel noise {100 * res['pixel_noise']:.2f} %, strongest dark "
              f"object {100 * res['strongest_contrast']:.1f} %, {res['robot_like']} robot-like object(s)")
        print(f"  wrote preview_png: {png}")
    return res
