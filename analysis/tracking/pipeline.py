"""One library call for the whole tracking chain: :func:`track_file` (used by ``labkit track`` and the demo).

Checks every output before a frame is read (exit 2 on a clash, a missing
folder or a wrong suffix), tracks the video or image sequence, measures the
speed with its interval, and writes what was asked for (all through temporary
names renamed together, so the old files survive any failed write).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from labkit.analysis.tracking.speed import SpeedResult
from labkit.analysis.tracking.tracker import Scale, Track
from labkit.errors import InputError


@dataclass
class TrackResult:
    """What :func:`track_file` produced."""

    track: Track
    speed: SpeedResult
    summary: dict[str, Any]
    written: dict[str, str] = field(default_factory=dict)

    @property
    def warnings(self) -> list[str]:
        return list(self.track.meta.get("warnings", []))


def output_paths(out: str | Path | None) -> list[Path]:
    """The files ``--out`` stands for: the track (HDF5) and its ``.csv`` and ``.png`` beside it."""
    if out is None:
        return []
    out = Path(out)
    if out.suffix.lower() not in (".h5", ".hdf5"):
        # the track is HDF5: a .txt or .csv name would hold something other than it says
        raise InputError(f"the track file is HDF5, not {out.suffix or 'suffix-less'}", file=out,
                         key="--out", expected="a .h5 file name (the .csv and .png are written beside it)")
    return [out, out.with_suffix(".csv"), out.with_suffix(".png")]


def track_file(source: str | Path, *, out: str | Path | None = None, overlay: str | Path | None = None,
               force: bool = False, scale: Scale | None = None, mm_per_px: float | None = None,
               window_s: float | None = None, quiet: bool = True, line_time_s: float | None = None,
               line_time_std_s: float = 0.0, timestamp_std_s: float | None = None, **track_kw: Any) -> TrackResult:
    """Track ``source`` (a video, an image folder or a ``frame_%05d.png`` pattern) and write the results.

    Parameters
    ----------
    out:
        Track file (HDF5, kind ``"track"``); a ``.csv`` and a ``.png`` (path and
        speed) are written beside it.
    overlay:
        Overlay video (``.avi`` or ``.mkv``) with the trajectory and heading.
    force:
        Replace existing outputs (otherwise they are refused before any work).
    scale, mm_per_px, window_s, quiet, track_kw:
        Passed to :func:`~labkit.analysis.tracking.tracker.track_video` (``roi``,
        ``mask``, ``robot_length_mm``, ``min_contrast``, ``fps``, ``timestamps``,
        ...) and :func:`~labkit.analysis.tracking.speed.track_speed`.
    line_time_s, line_time_std_s, timestamp_std_s:
        Declared camera properties for the error budget (see
        :func:`~labkit.analysis.tracking.speed.track_speed`).

    Returns
    -------
    TrackResult
        The track, the speed, the JSON-ready summary (with ``warnings``) and the
        files written.
    """
    from labkit.analysis.tracking.output import plot_path, save_track_csv, save_track_h5, summary, write_overlay
    from labkit.analysis.tracking.speed import track_speed
    from labkit.analysis.tracking.tracker import track_video
    from labkit.outputs import atomic_outputs, check_outputs

    if window_s is not None and not window_s > 0:
        raise InputError(f"bad window {window_s}", key="--window-s", expected="a duration > 0 s")
    outs = output_paths(out)
    # every output, sidecars included, is checked before a frame is read
    check_outputs(outs, force=force, key="--out")
    check_outputs([overlay], force=force, key="--overlay", suffixes=(".avi", ".mkv"))
    if overlay is not None and outs:
        check_outputs([*outs, overlay], force=True, key="--overlay")      # not the same file twice
    track = track_video(source, scale=scale, mm_per_px=mm_per_px, quiet=quiet, **track_kw)
    speed = track_speed(track, window_s=window_s, line_time_s=line_time_s, line_time_std_s=line_time_std_s,
                        timestamp_std_s=timestamp_std_s)
    result = summary(track, speed)
    jobs: list[tuple[str, Path, Callable[[Path], Any]]] = []
    if outs:
        jobs += [("track_h5", outs[0], lambda p: save_track_h5(p, track, speed)),
                 ("track_csv", outs[1], lambda p: save_track_csv(p, track, speed)),
                 ("path_png", outs[2], lambda p: plot_path(p, track, speed))]
    if overlay is not None:
        jobs.append(("overlay", Path(overlay),
                     lambda p: write_overlay(source, track, p, speed, fps=track_kw.get("fps"),
                                             timestamps=track_kw.get("timestamps"),
                                             bayer=track_kw.get("bayer", "auto"))))
    # all written to temporary names first, renamed together: every old file survives any failed write
    with atomic_outputs([target for _, target, _ in jobs]) as temps:
        for (_, _, write), tmp in zip(jobs, temps):
            write(tmp)
    written = {name: str(target) for name, target, _ in jobs}
    result["written"] = written
    return TrackResult(track, speed, result, written)
