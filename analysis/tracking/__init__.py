"""Robot position, heading and speed from stereoscope video.

:func:`track_file` (in :mod:`~labkit.analysis.tracking.pipeline`) is the whole
chain in one call (outputs checked first, track, speed, files written): what
``labkit track`` and the demo call.

:func:`track_video` (in :mod:`~labkit.analysis.tracking.tracker`) gives a
:class:`Track`; :func:`track_speed` (in :mod:`~labkit.analysis.tracking.speed`)
turns it into a speed with a confidence interval. Frames come from
:mod:`~labkit.analysis.tracking.video_io`, segmentation from
:mod:`~labkit.analysis.tracking.measure`, files and figures from
:mod:`~labkit.analysis.tracking.output`.
"""
from __future__ import annotations

from labkit.analysis.tracking.pipeline import TrackResult, track_file
from labkit.analysis.tracking.speed import SpeedResult, track_speed
from labkit.analysis.tracking.tracker import Scale, Track, track_frames, track_video

__all__ = ["Scale", "Track", "track_frames", "track_video", "SpeedResult", "track_speed", "TrackResult",
           "track_file"]
