"""Track the robot in top-view video: sub-pixel centroid and heading from image moments.

Method, per frame (the functions' docstrings say why):

1. Before the first frame, the static scene is modelled from 15 frames spread
   over the video (:func:`labkit.analysis.tracking.measure.background_model`):
   the tray's rim (dark, in every sample, reaching the border), static dark
   objects (dark in every sample, not moving, while the tray around them is
   dark in few: dust, however large, is never the robot; a robot that walks
   even a few pixels over the clip moves between the samples), the flat field (ring light shape,
   Teflon texture) and the pixel noise. The contrast threshold is 5 noise
   sigmas (at least 4 %) unless ``min_contrast`` is given.
2. A window around the predicted position (the whole region of interest when
   the robot is not yet found or was lost) is divided by the flat field and by
   its own smooth background (a grey closing wider than the chip, on a coarse
   grid: a lighting gradient and a frame's flicker go), then split into dark and
   light by Otsu's threshold on that window; a window whose dark/light contrast
   is below the threshold holds no robot.
3. Identity: the dark component of the robot's expected area (from the scale
   and the declared body, by default the 5 x 2 mm chip, then from the first
   confident frames) and, at
   acquisition, elongated shape, nearest the constant-velocity prediction, is
   the robot. A candidate beyond what the robot can walk since the last good
   frame (``max_speed_mm_s`` plus jitter) is an occlusion: the frame is lost
   and later bridged by the smoothed path. A second robot-sized candidate
   within reach is counted and warned about. A robot touching a masked static
   object and missing part of its darkness is flagged degraded.
4. Around that component (a band of ``margin_px``) each pixel gets a weight =
   its darkness relative to a plane fitted to the surrounding background ring
   (a constant when the ring is cut on one side), divided by the robot's own
   darkness: for an anti-aliased or blurred edge this is the pixel's area
   coverage, so the weighted moments give the centroid to a small fraction of
   a pixel (a binary mask would quantise it).
5. Orientation from the second central moments (``0.5 atan2(2 mu11, mu20 -
   mu02)``; never ``minAreaRect``, whose angle convention changed in OpenCV 5).
   The axis is defined modulo 180 degrees: it is unwrapped by continuity and
   the robot's front chosen, per stretch between losses, as the end it moves
   towards.

Conventions are those of :mod:`labkit.lab.render`: image ``u`` right, ``v``
down, pixel centres at integers; world ``x_mm`` right, ``y_mm`` up, measured
from the frame's bottom-left corner; ``heading_rad`` 0 = front towards +y,
counter-clockwise positive.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from labkit.analysis.tracking.measure import (
    Segmentation,
    _Blob,
    _Finder,
    background_model,
    body_length_px,
    small_median,
)
from labkit.errors import InputError

QUALITY_OK = 0        # robot fully seen: position and heading trusted
QUALITY_DEGRADED = 1  # seen but cut by the frame/ROI border or of an unexpected area: biased
QUALITY_LOST = 2      # not found (occluded, out of view): position is NaN
QUALITY_LABELS = "0 ok, 1 degraded (partly out of view or odd area), 2 lost"

ROBOT_LENGTH_MM = 5.0
# the position without the flat field (the illumination part of the budget) is measured every
# ALT_EVERY-th frame: its shift is smooth along the path and interpolated between
ALT_EVERY = 8
# body-length profiles taken (every third frame from the start): their median is the length
LENGTH_SAMPLES = 50


@dataclass
class Scale:
    """Image scale and its standard uncertainty, with how it was obtained."""

    mm_per_px: float
    mm_per_px_std: float
    method: str
    detail: dict = field(default_factory=dict)


@dataclass
class Track:
    """Per-frame robot pose. ``u_px``/``v_px`` are full-frame image coordinates."""

    t_s: np.ndarray
    u_px: np.ndarray
    v_px: np.ndarray
    heading_rad: np.ndarray
    quality: np.ndarray
    area_px: np.ndarray
    frame_size: tuple[int, int]
    roi: tuple[int, int, int, int]
    scale: Scale | None = None
    source: str = ""
    timestamps_source: str = "container"
    heading_sense: str = "motion"
    length_px: float = float("nan")
    length_px_std: float = float("nan")
    meta: dict = field(default_factory=dict)
    # per frame: the position without the flat-field model, and the outline's length (moments, px):
    # what the error budget (:mod:`~labkit.analysis.tracking.budget`) measures lighting and scale from
    u_alt_px: np.ndarray | None = None
    v_alt_px: np.ndarray | None = None
    major_px: np.ndarray | None = None

    @property
    def frames(self) -> int:
        return int(self.t_s.size)

    @property
    def lost_frames(self) -> int:
        return int(np.sum(self.quality == QUALITY_LOST))

    @property
    def mm_per_px(self) -> float:
        return float("nan") if self.scale is None else self.scale.mm_per_px

    @property
    def x_mm(self) -> np.ndarray:
        """World x (mm) from the frame's left edge."""
        return (self.u_px + 0.5) * self.mm_per_px

    @property
    def y_mm(self) -> np.ndarray:
        """World y (mm, up) from the frame's bottom edge."""
        return (self.frame_size[1] - 0.5 - self.v_px) * self.mm_per_px


# ----------------------------------------------------------------------------- scale
def scale_given(mm_per_px: float, mm_per_px_std: float = 0.0) -> Scale:
    """A scale the user knows (calibration slide): recorded as given."""
    if not (mm_per_px > 0 and np.isfinite(mm_per_px)):
        raise InputError(f"bad scale {mm_per_px!r}", key="mm_per_px", expected="a number > 0")
    return Scale(float(mm_per_px), float(mm_per_px_std), "given")


def scale_from_bar(x1: float, y1: float, x2: float, y2: float, distance_mm: float,
                   click_std_px: float = 0.5) -> Scale:
    """Two points on a scale bar ``distance_mm`` apart; each point uncertain by ``click_std_px``."""
    d_px = float(np.hypot(x2 - x1, y2 - y1))
    if d_px < 5 or not distance_mm > 0:
        raise InputError(f"scale bar points {d_px:.1f} px apart, {distance_mm} mm", key="scale_bar",
                         expected="two points >= 5 px apart and a distance > 0 mm")
    s = distance_mm / d_px
    # the distance between two clicked points has std sqrt(2) * click_std
    return Scale(s, s * np.sqrt(2) * click_std_px / d_px, "scale_bar",
                 {"points_px": [x1, y1, x2, y2], "distance_mm": distance_mm, "click_std_px": click_std_px})


def scale_from_robot_length(track: Track, length_mm: float = ROBOT_LENGTH_MM,
                            length_std_mm: float = 0.05) -> Scale:
    """Scale from the robot's known body length and its length measured in the image."""
    if not np.isfinite(track.length_px) or track.length_px <= 0:
        raise InputError("cannot measure the robot's length in the image (too few clear frames)",
                         file=track.source, expected="a scale: --mm-per-px or --scale-bar")
    s = length_mm / track.length_px
    rel = np.hypot(length_std_mm / length_mm, track.length_px_std / track.length_px)
    return Scale(float(s), float(s * rel), "robot_length", {"length_mm": length_mm, "length_std_mm": length_std_mm,
                                              "length_px": track.length_px, "length_px_std": track.length_px_std})


# ----------------------------------------------------------------------------- the tracker
def finish_progress(pb: Any, decoded: int, listed: int) -> None:
    """End the bar at the frames that decoded, not at the container's count.

    A truncated or damaged file lists more frames than decode (80 listed, the last cut
    mid-write): the bar's total becomes the decoded count, its label says
    ``79 of 80 frames decodable``, and it stays on the terminal so the shortfall is seen.
    A container that listed fewer (an estimate) just gets the count it really had.
    """
    if pb.total is None or pb.total == decoded:
        return
    pb.total = decoded
    if listed and decoded < listed:
        pb.set_description_str(f"track: {decoded} of {listed} frames decodable", refresh=False)
        pb.leave = True
    pb.refresh()


def track_frames(frames: Iterable[tuple[np.ndarray, float]], frame_size: tuple[int, int], *,
                 roi: tuple[int, int, int, int] | None = None, valid: np.ndarray | None = None,
                 flat: np.ndarray | None = None, seg: Segmentation | None = None,
                 margin_px: int = 4, min_area_px: int = 20,
                 expected_area_px: float | None = None, max_speed_px_s: float | None = None,
                 max_speed_body_s: float | None = None, reacquire_s: float = 1.0,
                 progress: Any = None) -> dict:
    """Track over ``(grey frame, t_s)`` pairs (full frames); returns raw per-frame arrays.

    ``valid`` (bool, full frame) marks where the robot may be. The motion model
    (constant velocity) predicts the next position; a candidate farther from it
    than the robot can go (``max_speed_px_s``, or ``max_speed_body_s`` body
    lengths per second, by default one body length per frame interval, plus the
    vibration jitter)
    is not the robot: the frame is lost (an occlusion), and the gate grows with
    the time since the last good frame until, after ``reacquire_s``, the robot
    may be found anywhere. The per-frame work is :meth:`TrackerState.step`. See
    :func:`track_video` for the public entry point.
    """
    W, H = frame_size
    rx, ry, rw, rh = roi or (0, 0, W, H)
    seg = seg or Segmentation.for_frame(rw, rh, None, None)
    vroi = None if valid is None else np.ascontiguousarray(valid[ry:ry + rh, rx:rx + rw])
    froi = None if flat is None else np.ascontiguousarray(flat[ry:ry + rh, rx:rx + rw])
    state = TrackerState(_Finder(vroi, margin_px, seg, min_area_px, froi),
                         TrackLimits(max_speed_px_s, max_speed_body_s, reacquire_s),
                         (rx, ry, rw, rh), RobotModel(area_ref=expected_area_px))
    for k, (frame, t) in enumerate(frames):
        state.step(frame[ry:ry + rh, rx:rx + rw] if roi else frame, t, k)
        if progress is not None:
            progress.update(1)
    return state.result()


@dataclass
class TrackLimits:
    """How far the robot may go between frames (see :meth:`TrackerState.gate`)."""

    max_speed_px_s: float | None = None
    max_speed_body_s: float | None = None
    reacquire_s: float = 1.0


@dataclass
class FrameRow:
    """One frame's result (image coordinates of the full frame)."""

    t: float
    u: float = float("nan")
    v: float = float("nan")
    theta: float = float("nan")
    u_alt: float = float("nan")       # without the flat field
    v_alt: float = float("nan")
    major: float = float("nan")       # the outline's length from the moments (px)
    quality: int = QUALITY_LOST
    area: float = float("nan")        # the weighted (coverage) area
    raw_area: float = float("nan")    # the dark component's area


@dataclass
class RobotModel:
    """What the tracker has learned of the robot: its area, outline, length and darkness."""

    area_ref: float | None = None     # expected, then the median of recent confident frames
    area_lo: float = 0.8              # a whole robot's area relative to area_ref (widened for a soft body)
    area_hi: float = 1.25
    area_hist: list[float] = field(default_factory=list)
    cov_hist: list[float] = field(default_factory=list)   # weighted area in clear frames
    shapes: list[tuple[float, float]] = field(default_factory=list)
    shape_ref: tuple[float, float] | None = None
    shape_spread: tuple[float, ...] = (0.0, 0.0)
    lengths: list[float] = field(default_factory=list)
    contrasts: list[float] = field(default_factory=list)
    major: float | None = None        # smoothed outline length (px): the gate and the window's size

    def area_tol(self) -> tuple[float, float]:
        """Area tolerance of a candidate: wide while only the expected area is known (blur and legs vary it)."""
        return (0.5, 2.0) if len(self.area_hist) < 5 else (0.45, 1.7)

    def quality(self, blob: _Blob) -> int:
        """OK, or degraded: cut by the border, of an odd area, or touching dust and missing darkness."""
        if blob.border or (self.area_ref and not self.area_lo < blob.area / self.area_ref < self.area_hi):
            return QUALITY_DEGRADED
        if blob.masked and self.cov_hist:
            recent = self.cov_hist[-25:]
            if abs(blob.coverage / float(small_median(recent)) - 1) > max(0.01, 5 * _log_spread(recent)):
                return QUALITY_DEGRADED      # partly hidden by static dust (or the rim)
        return QUALITY_OK

    def learn_area(self, area: float) -> bool:
        """Add a confident frame's area; True when the first five now define the robot."""
        self.area_hist.append(area)
        if not (len(self.area_hist) <= 25 or len(self.area_hist) % 10 == 0):
            return False
        self.area_ref = float(small_median(self.area_hist[-25:]))
        if len(self.area_hist) >= 5:
            spread = _log_spread(self.area_hist[-25:])
            self.area_lo, self.area_hi = min(0.8, np.exp(-5 * spread)), max(1.25, np.exp(5 * spread))
        return len(self.area_hist) == 5

    def learn_shape(self, blob: _Blob) -> bool:
        """Add a confident frame's outline (length, width); True when the reference outline changed.

        The reference is the median of the recent outlines; their robust spread is how much it
        varies by itself (a soft body, blur that changes with the speed)."""
        self.shapes.append((blob.major_px, blob.minor_px))
        if len(self.shapes) < 5 or not (len(self.shapes) <= 25 or len(self.shapes) % 10 == 0):
            return False
        arr = np.log(np.asarray(self.shapes[-25:]))
        med = small_median(arr, axis=0)
        self.shape_ref = (float(np.exp(med[0])), float(np.exp(med[1])))
        self.shape_spread = tuple(1.4826 * small_median(np.abs(arr - med), axis=0))
        return True


@dataclass
class TrackerState:
    """The tracker between frames: the finder, the motion model, what is learned of the robot, the rows.

    :meth:`step` handles one frame (ROI-cropped); :meth:`result` gives the raw arrays."""

    finder: _Finder
    limits: TrackLimits
    roi: tuple[int, int, int, int]                  # x, y, w, h
    robot: RobotModel
    rows: list[FrameRow] = field(default_factory=list)
    last: tuple[float, float, float] | None = None  # u, v, t of the last good frame (ROI coords)
    vel: tuple[float, float] = (0.0, 0.0)
    frame_dts: list[float] = field(default_factory=list)
    frame_dt: float = 0.0                           # the median frame interval (of the first 15)
    jumps: int = 0                                  # robot-like objects beyond reach
    unlike: int = 0                                 # robot-sized objects not shaped like it
    on_static: int = 0                              # found frames touching a never-search region

    def gate(self, dt: float) -> float | None:
        """How far (px) from the prediction the robot may be after ``dt``; None: anywhere."""
        major = self.robot.major
        if major is None or dt > self.limits.reacquire_s:
            return None
        if self.limits.max_speed_px_s:
            vmax = self.limits.max_speed_px_s
        elif self.limits.max_speed_body_s:
            vmax = self.limits.max_speed_body_s * major
        else:
            # one body length per frame interval: the physical limit of frame-to-frame identity
            vmax = major / (self.frame_dt if self.frame_dts else max(dt, 1e-6))
        # jitter of a vibrating robot (a tenth of its length) + what it can walk in dt
        return 3.0 + 0.1 * major + vmax * dt

    def step(self, img: np.ndarray, t: float, k: int) -> None:
        """Find the robot in frame ``k`` (time ``t``), record its row and update the models."""
        if self.rows and len(self.frame_dts) < 15 and t > self.rows[-1].t:
            self.frame_dts.append(t - self.rows[-1].t)
            self.frame_dt = float(np.median(self.frame_dts))
        blob, pred = self._search(img, t, k)
        rb = self.robot
        if (blob is not None and not blob.border and rb.shape_ref is not None
                and not _shaped_like(blob, rb.shape_ref, rb.shape_spread, pred, rb.major)):
            # robot-sized but not robot-shaped (a tweezer's prong, the robot merged with something)
            # and off the motion's prediction: not a position
            blob = None
            self.unlike += 1
        row = FrameRow(t)
        self.rows.append(row)
        if blob is None:
            if self.last is not None and t - self.last[2] > 1.0:
                self.vel = (0.0, 0.0)
            return
        self._record(row, blob)
        if row.quality == QUALITY_OK or (len(rb.area_hist) < 5 and not blob.border):
            self._learn(blob, row.quality, t)
        elif self.last is None:
            rb.major = blob.major_px
            self.last = (blob.u, blob.v, t)

    def _search(self, img: np.ndarray, t: float, k: int) -> tuple[_Blob | None, tuple[float, float] | None]:
        """The robot's blob near the prediction (a window grown once if it touched its edge), else over
        the whole region within the gate; also the prediction."""
        rb, finder = self.robot, self.finder
        rw, rh = self.roi[2], self.roi[3]
        tol = rb.area_tol()
        blob, pred, g = None, None, None
        if self.last is not None and rb.major is not None:
            dt = t - self.last[2]
            pred = (self.last[0] + self.vel[0] * dt, self.last[1] + self.vel[1] * dt)
            g = self.gate(dt)
            half = int(0.65 * rb.major + 3 * finder.margin + 10 + 1.5 * np.hypot(self.vel[0] * dt, self.vel[1] * dt))
            for grow in (1, 2):
                hw = half * grow
                x0, y0 = max(int(pred[0]) - hw, 0), max(int(pred[1]) - hw, 0)
                x1, y1 = min(int(pred[0]) + hw + 1, rw), min(int(pred[1]) + hw + 1, rh)
                if x1 - x0 < 8 or y1 - y0 < 8:
                    break
                blob, touched = finder.find(img, x0, y0, x1, y1, pred=pred, area_ref=rb.area_ref,
                                            keep_weights=len(rb.lengths) < LENGTH_SAMPLES and k % 3 == 0, gate_px=g,
                                            area_tol=tol, alt=k % ALT_EVERY == 0)
                if blob is None or not touched:
                    break
        if blob is None:
            blob = self._acquire(img, pred if g is not None else None, g, tol)
        return blob, pred

    def _acquire(self, img: np.ndarray, pred: tuple[float, float] | None, g: float | None,
                 tol: tuple[float, float]) -> _Blob | None:
        """(Re-)acquisition over the whole region of interest, within the gate ``g`` of ``pred``; a
        robot-like object beyond it is counted as a jump (an occlusion), not taken."""
        rw, rh = self.roi[2], self.roi[3]
        area_ref = self.robot.area_ref
        blob, _ = self.finder.find(img, 0, 0, rw, rh, pred=pred, area_ref=area_ref, keep_weights=True,
                                   gate_px=g, area_tol=tol)
        if blob is not None and pred is not None and g is not None and np.hypot(blob.u - pred[0],
                                                                                 blob.v - pred[1]) > g:
            blob = None
        if blob is None and g is not None:
            self.jumps += int(self.finder.find(img, 0, 0, rw, rh, pred=None, area_ref=area_ref,
                                               area_tol=tol)[0] is not None)
        return blob

    def _record(self, row: FrameRow, blob: _Blob) -> None:
        """Fill the frame's row from the blob (full-frame coordinates) and judge its quality."""
        rx, ry = self.roi[0], self.roi[1]
        rb = self.robot
        row.raw_area = blob.area
        row.quality = rb.quality(blob)
        self.on_static += int(blob.masked)
        if row.quality == QUALITY_OK and not blob.masked:
            rb.cov_hist.append(blob.coverage)
        row.u, row.v, row.theta, row.area = blob.u + rx, blob.v + ry, blob.theta, blob.coverage
        row.u_alt, row.v_alt, row.major = blob.u_alt + rx, blob.v_alt + ry, blob.major_px
        if row.quality == QUALITY_OK:
            rb.contrasts.append(blob.contrast)

    def _learn(self, blob: _Blob, q: int, t: float) -> None:
        """A confident frame: update the motion model and what is known of the robot."""
        rb = self.robot
        if self.last is not None and 0 < t - self.last[2] < 0.5:
            a = 0.5  # light smoothing of the velocity used only for the prediction
            dt = t - self.last[2]
            nv = ((blob.u - self.last[0]) / dt, (blob.v - self.last[1]) / dt)
            self.vel = (a * nv[0] + (1 - a) * self.vel[0], a * nv[1] + (1 - a) * self.vel[1])
        elif self.last is not None:
            self.vel = (0.0, 0.0)
        self.last = (blob.u, blob.v, t)
        if rb.learn_area(blob.area) and rb.area_ref:
            # the first confident frames now define the robot: re-check them
            for row in self.rows:
                if row.quality == QUALITY_OK and not rb.area_lo < row.raw_area / rb.area_ref < rb.area_hi:
                    row.quality = QUALITY_DEGRADED
        rb.major = blob.major_px if rb.major is None else 0.9 * rb.major + 0.1 * blob.major_px
        if q == QUALITY_OK and rb.learn_shape(blob) and rb.shape_ref is not None:
            width = rb.shape_ref[1]
            if self.finder.seg.body_width_px < 1.1 * width:
                # the robot is wider than the background filter was sized for (no size known
                # before): resized to the width just learned, so the filter never eats it
                self.finder.seg = _resized(self.finder.seg, self.roi[2], self.roi[3], width)
        if blob.weights is not None:
            rb.lengths.append(body_length_px(blob.weights, blob.u - blob.origin[0], blob.v - blob.origin[1],
                                             blob.theta))

    def result(self) -> dict:
        """The raw per-frame arrays and the counts (what :func:`track_frames` returns)."""
        rb = self.robot
        col = {name: np.array([getattr(r, name) for r in self.rows], float)
               for name in ("t", "u", "v", "theta", "u_alt", "v_alt", "major", "area")}
        t_a = col["t"]
        # the lighting model's shift of the position is smooth along the path: measured every
        # ALT_EVERY-th frame (a second measurement costs as much as the first), interpolated in time between
        for alt, pos in (("u_alt", "u"), ("v_alt", "v")):
            shift = col[alt] - col[pos]
            known = np.isfinite(shift)
            if known.sum() >= 1:
                col[alt] = col[pos] + np.interp(t_a, t_a[known], shift[known])
        lengths = np.asarray(rb.lengths, float)
        lengths = lengths[np.isfinite(lengths)]
        seg = self.finder.seg
        return dict(t_s=t_a, u_px=col["u"], v_px=col["v"], u_alt=col["u_alt"], v_alt=col["v_alt"],
                    major_px=col["major"], theta=col["theta"],
                    quality=np.array([r.quality for r in self.rows], np.int8), area_px=col["area"],
                    length_px=float(np.median(lengths)) if lengths.size else float("nan"),
                    length_px_std=(float(1.2533 * np.std(lengths) / np.sqrt(lengths.size))
                                   if lengths.size > 1 else float("nan")),
                    n_length=int(lengths.size), best_contrast=self.finder.best_contrast,
                    robot_contrast=float(np.median(rb.contrasts)) if rb.contrasts else float("nan"),
                    ambiguous=self.finder.ambiguous, jumps=self.jumps, unlike=self.unlike,
                    on_static=self.on_static, min_contrast=seg.min_contrast, noise=seg.noise)


def _log_spread(values: list[float]) -> float:
    """Robust sigma of the logarithms (a relative spread); 0 for fewer than 5 values."""
    if len(values) < 5:
        return 0.0
    la = np.log(np.maximum(np.asarray(values, float), 1e-12))
    return 1.4826 * float(small_median(np.abs(la - small_median(la))))


def _resized(seg: Segmentation, width: int, height: int, body_width_px: float) -> Segmentation:
    """``seg`` with its background filter sized for a body ``body_width_px`` wide (threshold kept)."""
    new = Segmentation.for_frame(width, height, body_width_px, seg.min_contrast, seg.noise)
    new.auto = seg.auto
    return new


def _shaped_like(blob: Any, ref: tuple[float, float], spread: tuple[float, ...],
                 pred: tuple[float, float] | None, major: float | None) -> bool:
    """Whether a candidate may be the robot by its outline.

    Its length and width must be within the fixed tolerance of the robot's recent
    outline (0.8-1.25 x length, 0.7-1.45 x width) widened to 5 of the outline's own
    robust sigmas (a soft body or a blur that changes with the speed varies by
    itself); a candidate outside that but where the motion predicted the robot
    (within 2 px + 5 % of its length) is the robot changing shape, not something else.
    """
    lo_l, hi_l = min(0.8, np.exp(-5 * spread[0])), max(1.25, np.exp(5 * spread[0]))
    lo_w, hi_w = min(0.7, np.exp(-5 * spread[1])), max(1.45, np.exp(5 * spread[1]))
    if lo_l < blob.major_px / ref[0] < hi_l and lo_w < blob.minor_px / ref[1] < hi_w:
        return True
    return (pred is not None and major is not None
            and bool(np.hypot(blob.u - pred[0], blob.v - pred[1]) < 2.0 + 0.05 * major))


def resolve_heading(t_s: np.ndarray, u_px: np.ndarray, v_px: np.ndarray, theta: np.ndarray,
                    quality: np.ndarray, min_travel_px: float = 3.0) -> tuple[np.ndarray, str]:
    """Turn image axis angles (mod pi) into a continuous heading (world convention, rad).

    Within each stretch of found frames the axis is unwrapped by continuity;
    the stretch's front is the end the robot moves towards (summed over the
    stretch), or, when it hardly moves, the one closest to the previous
    stretch's heading. Returns the heading and ``"motion"``, ``"continuity"``
    or ``"unknown"`` (how the front of the first stretch was decided).
    """
    n = theta.size
    heading = np.full(n, np.nan)
    found = np.isfinite(theta)
    # image axis angle -> world heading modulo pi (front (-sin h, cos h); image v is -y)
    h_mod = np.mod(-theta - np.pi / 2, np.pi)
    idx = np.flatnonzero(found)
    if idx.size == 0:
        return heading, "unknown"
    # stretches: split where frames were lost
    breaks = np.flatnonzero(np.diff(idx) > 1) + 1
    sense = "unknown"
    prev_end: float | None = None
    for seg_i, seg in enumerate(np.split(idx, breaks)):
        h = np.empty(seg.size)
        h[0] = h_mod[seg[0]]
        if prev_end is not None:
            h[0] += np.pi * np.round((prev_end - h[0]) / np.pi)
        for j in range(1, seg.size):
            x = h_mod[seg[j]]
            h[j] = x + np.pi * np.round((h[j - 1] - x) / np.pi)
        # direction of travel in world coordinates (x right, y up)
        dx = np.diff(u_px[seg])
        dy = -np.diff(v_px[seg])
        fwd = np.array([-np.sin(h[:-1]), np.cos(h[:-1])])
        score = float(np.sum(fwd[0] * dx + fwd[1] * dy))
        travel = float(np.hypot(u_px[seg[-1]] - u_px[seg[0]], v_px[seg[-1]] - v_px[seg[0]]))
        if travel >= min_travel_px and abs(score) > 0.3 * travel:
            if score < 0:
                h += np.pi
            if seg_i == 0:
                sense = "motion"
        elif prev_end is not None:
            if seg_i == 0:
                sense = "continuity"
        heading[seg] = h
        prev_end = float(h[-1])
    # start in (-pi, pi]; later values stay continuous (they may leave that range)
    heading -= 2 * np.pi * np.round(heading[idx[0]] / (2 * np.pi))
    return heading, sense


def lost_stretches(t_s: np.ndarray, quality: np.ndarray) -> list[tuple[float, float]]:
    """``(first, last)`` times of each run of lost frames (bridged by the speed's smoothing)."""
    lost = np.r_[False, quality == QUALITY_LOST, False].astype(np.int8)
    d = np.diff(lost)
    return [(float(t_s[i]), float(t_s[j - 1])) for i, j in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1))]


CHIP_AREA_MM2 = 5.0 * 2.0 + 6 * 0.45 * 0.3    # body and six leg stubs, seen from above
ROBOT_WIDTH_MM = 2.0


@dataclass
class RobotSize:
    """What the tracker expects of the robot's outline (``None`` parts are learned from the first confident frames)."""

    length_mm: float | None
    width_mm: float | None
    area_mm2: float | None

    @property
    def declared(self) -> bool:
        return self.area_mm2 is not None


def robot_size(size_mm: tuple[float, float] | str | None) -> RobotSize:
    """``None``: the lab's 5 x 2 mm chip (with its leg stubs); ``(length, width)`` mm: any robot, a
    rectangle's area; ``"learn"``: nothing assumed, the outline learned from the first confident frames."""
    if size_mm is None:
        return RobotSize(ROBOT_LENGTH_MM, ROBOT_WIDTH_MM, CHIP_AREA_MM2)
    vals: list[float] = []
    if isinstance(size_mm, str):
        if size_mm.strip().lower() == "learn":
            return RobotSize(None, None, None)
        try:
            vals = [float(v) for v in size_mm.split(",")]
        except ValueError:
            vals = []
    else:
        vals = [float(v) for v in size_mm]
    if len(vals) != 2 or not all(np.isfinite(v) and v > 0 for v in vals):
        raise InputError(f"bad robot size {size_mm!r}", key="--robot-size-mm",
                         expected="LENGTH,WIDTH in mm (both > 0), or 'learn'")
    length, width = max(vals), min(vals)
    return RobotSize(length, width, length * width)


@dataclass
class PreparedScene:
    """What is known before tracking: the search region, the static scene, the segmentation."""

    roi: tuple[int, int, int, int]
    valid: np.ndarray | None
    seg: Segmentation
    static: Any
    flat: np.ndarray | None
    warnings: list[str]
    valid_with_objects: np.ndarray | None = None    # the mask with static objects left searchable


def prepare_scene(cap: Any, info: Any, *, roi: tuple[int, int, int, int] | str | None = None, mask: Any = None,
                  scale: Scale | None = None, min_contrast: float | None = None,
                  static_mask: bool = True, size: RobotSize | None = None,
                  samples: list[np.ndarray] | None = None) -> PreparedScene:
    """Region of interest, mask, static scene (rim, dust, flat field, noise) and contrast threshold.

    Reads sample frames from ``cap`` and rewinds it (see :func:`track_video`), unless ``samples``
    are given (frames spread over the clip, already decoded)."""
    from labkit.analysis.tracking.video_io import load_mask, parse_roi, read_sample_frames

    W, H = info.width, info.height
    roi_t = parse_roi(roi, W, H)
    valid = load_mask(mask, W, H)
    if min_contrast is not None and not 0 < min_contrast < 1:
        raise InputError(f"bad contrast {min_contrast}", key="--min-contrast", expected="a share between 0 and 1")
    size = size or robot_size(None)
    body_w = size.width_mm / scale.mm_per_px if scale is not None and size.width_mm else None
    seg = Segmentation.for_frame(roi_t[2], roi_t[3], body_w, min_contrast)
    static = None
    flat = None
    with_objects = valid
    warnings: list[str] = []
    if static_mask:
        static = background_model(samples if samples is not None else read_sample_frames(cap, info, 15), seg)
        seg = Segmentation.for_frame(roi_t[2], roi_t[3], body_w, min_contrast, noise=static.noise)
        flat = static.flat
        if static.rim is not None:
            valid = ~static.rim if valid is None else valid & ~static.rim
        with_objects = valid
        if static.objects is not None:
            valid = ~static.objects if valid is None else valid & ~static.objects
        if static.overlays is not None:
            valid = ~static.overlays if valid is None else valid & ~static.overlays
            with_objects = ~static.overlays if with_objects is None else with_objects & ~static.overlays
            warnings.append(f"{len(static.overlay_boxes)} burnt-in overlay(s) set aside (text in every frame, not "
                            f"moving: a timestamp, a scale bar's label) at x,y,w,h "
                            + "; ".join(",".join(str(v) for v in b) for b in static.overlay_boxes[:3]))
        if static.object_boxes:
            warnings.append(f"{len(static.object_boxes)} static dark object(s) set aside (never moved: dust, "
                            f"not the robot) at x,y,w,h " + "; ".join(",".join(str(v) for v in b)
                                                                      for b in static.object_boxes[:3]))
    return PreparedScene(roi_t, valid, seg, static, flat, warnings,
                         valid_with_objects=with_objects if static_mask else valid)


@dataclass
class TrackPass:
    """What a tracking pass over a source needs (the first one, and one over a static object)."""

    source: str | Path
    fps: float | None
    timestamps: str | Path | None
    bayer: str
    size: RobotSize
    scale: Scale | None
    margin_px: int = 4
    max_speed_mm_s: float | None = None
    robot_length_mm: float = ROBOT_LENGTH_MM
    roi: tuple[int, int, int, int] | str | None = None    # as given (None: the whole frame)
    mask: Any = None
    min_contrast: float | None = None
    static_mask: bool = True
    quiet: bool = True

    @property
    def expected_area_px(self) -> float | None:
        """The robot's area in pixels, from the declared outline and a known scale."""
        if self.scale is None or not self.size.area_mm2:
            return None
        return self.size.area_mm2 / self.scale.mm_per_px ** 2

    def speed_limits(self) -> tuple[float | None, float | None]:
        """(px/s, body lengths/s): a declared limit in pixels with a scale, in body lengths without."""
        v = self.max_speed_mm_s
        if not v:
            return None, None
        if self.scale is not None:
            return v / self.scale.mm_per_px, None
        return None, v / self.robot_length_mm


def _static_robot(tp: TrackPass, frame_size: tuple[int, int], roi: tuple[int, int, int, int] | None,
                  valid: np.ndarray | None, seg: Segmentation) -> dict | None:
    """Track again with static objects searchable (and no flat field, which holds them); the result
    only if an object shaped like the declared robot was found in most frames: with a scale, of
    its area and length; without one, of its proportions (area / length squared)."""
    from labkit.analysis.tracking.video_io import iter_frames, open_source

    cap, info = open_source(tp.source, fps=tp.fps, timestamps=tp.timestamps, bayer=tp.bayer)
    try:
        raw = track_frames(iter_frames(cap, info), frame_size, roi=roi, valid=valid, flat=None, seg=seg,
                           margin_px=tp.margin_px, expected_area_px=tp.expected_area_px,
                           max_speed_px_s=tp.speed_limits()[0])
    finally:
        cap.release()
    found = raw["quality"] != QUALITY_LOST
    if found.mean() < 0.5 or not np.isfinite(raw["length_px"]):
        return None
    area = float(np.median(raw["area_px"][found]))
    length = float(raw["length_px"])
    length_mm, area_mm2 = tp.size.length_mm, tp.size.area_mm2
    if length_mm is None or area_mm2 is None:
        return None         # nothing declared ("learn"): a static object is never the robot
    if tp.scale is None:
        # no scale: the outline's proportions (area over length squared, the same at any scale)
        # must be the declared robot's; a round speck or a thin fibre is not
        return raw if 0.75 < (area / length ** 2) / (area_mm2 / length_mm ** 2) < 1.33 else None
    # the size and the length at the known scale
    expected = tp.expected_area_px
    ok = 0.75 < area / expected < 1.33 if expected else True
    return raw if ok and abs(length * tp.scale.mm_per_px / length_mm - 1) < 0.12 else None


def track_video(source: str | Path, *, roi: tuple[int, int, int, int] | str | None = None,
                mask: Any = None, scale: Scale | None = None, mm_per_px: float | None = None,
                robot_length_mm: float | None = None, robot_length_std_mm: float = 0.05,
                robot_size_mm: tuple[float, float] | str | None = None,
                margin_px: int = 4, min_contrast: float | None = None, static_mask: bool = True,
                max_speed_mm_s: float | None = None, fps: float | None = None,
                timestamps: str | Path | None = None, bayer: str = "auto", quiet: bool = True) -> Track:
    """Track the robot through a video file or an image sequence.

    Parameters
    ----------
    source:
        Video path (anything OpenCV's FFmpeg backend reads), a folder of images,
        or an image pattern such as ``frames/frame_%05d.png``.
    roi:
        ``(x, y, w, h)`` or ``"x,y,w,h"`` in pixels: search only there.
    mask:
        Bool/uint8 image or PNG path of the frame's size; non-zero = the robot may be there.
    scale, mm_per_px:
        The image scale; without either, it is measured from the robot's known
        ``robot_length_mm`` (uncertain by ``robot_length_std_mm``). A known scale
        also gives the robot's expected size in pixels (its identity).
    robot_size_mm:
        The robot's outline: ``None`` the lab's 5 x 2 mm chip, ``(length, width)``
        in mm any other robot, ``"learn"`` nothing assumed (learned from the first
        confident frames). With a known scale it gives the robot's expected area and
        width in pixels (its identity at acquisition); its length is the default
        ``robot_length_mm``.
    margin_px:
        Width of the band around the dark component whose pixels weigh in the
        moments: at least the blur's half-length.
    min_contrast:
        Minimum (tray - object) / tray for an object to be the robot; default
        (None): 5 x the tray's measured pixel noise, at least 4 %.
    static_mask:
        Model the static scene from frames spread over the video: the tray's
        rim, static dark objects (dust) and the tray's texture
        (:func:`~labkit.analysis.tracking.measure.background_model`).
    max_speed_mm_s:
        What the robot can walk: a candidate beyond it (plus jitter) from the
        predicted position is an occlusion, not the robot. Default (None): one
        body length per frame interval (beyond that no tracker can tell which
        object is which from frame to frame), i.e. the robot's length times the
        frame rate -- 150 mm/s for the 5 mm chip at 30 fps.
    bayer:
        Raw Bayer frames (a sensor's mosaic, one colour per pixel): ``"auto"``
        (detected from the 2 x 2 pattern of the first frame), ``"none"``, or the
        pattern ``"RGGB"``, ``"BGGR"``, ``"GRBG"``, ``"GBRG"``; demosaiced to grey.
    fps, timestamps:
        Frame times of an image sequence (a rate, or a CSV with a ``t_s`` column).

    Returns
    -------
    Track
        ``meta["warnings"]`` lists what the user should know (skipped frames,
        ambiguous candidates, rejected jumps, static objects set aside).
        Raises :class:`InputError` if the source is missing, unreadable, empty,
        or no robot is found (the message gives the contrast found).
    """
    if scale is None and mm_per_px is not None:
        scale = scale_given(mm_per_px)
    size = robot_size(robot_size_mm)
    if max_speed_mm_s is not None and not max_speed_mm_s > 0:
        raise InputError(f"bad speed limit {max_speed_mm_s}", key="--max-speed-mm-s", expected="a speed > 0 mm/s")
    tp = TrackPass(source, fps, timestamps, bayer, size, scale, margin_px, max_speed_mm_s,
                   robot_length_mm or size.length_mm or ROBOT_LENGTH_MM, roi, mask, min_contrast, static_mask, quiet)
    raw, scene, info, warnings = _first_pass(tp)
    raw = _still_robot(raw, tp, scene, info, warnings)
    t_s, ts_source, faulty = _frame_times(raw, info, tp, warnings)
    if np.all(raw["quality"] == QUALITY_LOST):
        raise _no_robot(raw, scene.static, t_s.size, source)
    stretches = lost_stretches(t_s, raw["quality"])
    warnings.extend(_track_warnings(raw, stretches))
    heading, sense = resolve_heading(t_s, raw["u_px"], raw["v_px"], raw["theta"], raw["quality"])
    static = scene.static
    track = Track(t_s=t_s, u_px=raw["u_px"], v_px=raw["v_px"], heading_rad=heading, quality=raw["quality"],
                  area_px=raw["area_px"], frame_size=(info.width, info.height), roi=scene.roi, source=str(source),
                  timestamps_source=ts_source, heading_sense=sense, length_px=raw["length_px"],
                  length_px_std=raw["length_px_std"], u_alt_px=raw["u_alt"], v_alt_px=raw["v_alt"],
                  major_px=raw["major_px"],
                  meta={"fps_nominal": info.fps_nominal, "fourcc": info.fourcc,
                        "timestamp_faults": int(faulty.sum()), "undecodable_frames": info.undecodable,
                        "static_mask_px": int(static.rim.sum()) if static is not None and static.rim is not None
                        else 0,
                        "static_objects": static.object_boxes if static is not None else [],
                        "noise": raw["noise"], "min_contrast": raw["min_contrast"],
                        "contrast_found": raw["best_contrast"], "robot_contrast": raw["robot_contrast"],
                        "ambiguous_frames": raw["ambiguous"],
                        "jumps_rejected": raw["jumps"], "unlike_frames": raw.get("unlike", 0),
                        "lost_stretches_s": stretches,
                        "length_samples": raw["n_length"], "warnings": warnings})
    track.scale = scale if scale is not None else scale_from_robot_length(track, tp.robot_length_mm,
                                                                          robot_length_std_mm)
    return track


def _first_pass(tp: TrackPass) -> tuple[dict, PreparedScene, Any, list[str]]:
    """Open the source, model its static scene and track it once: (raw arrays, scene, video info, warnings)."""
    from labkit.analysis.tracking.video_io import SpooledFrames, iter_frames, open_source, spools
    from labkit.progress import progress as bar

    cap, info = open_source(tp.source, fps=tp.fps, timestamps=tp.timestamps, bayer=tp.bayer)
    warnings: list[str] = []
    spool = None
    if info.bayer:
        warnings.append(f"raw Bayer frames ({info.bayer}{', detected' if tp.bayer == 'auto' else ''}): demosaiced "
                        f"to grey")
    try:
        if info.width <= 0 or info.height <= 0:
            raise InputError("the video holds no frames", file=tp.source)
        # a decoded video is decoded once, into a spool: samples and tracking read it (no seeking)
        spool = SpooledFrames(cap, info) if spools(info) else None
        frames = spool if spool is not None else iter_frames(cap, info)
        scene = prepare_scene(cap, info, roi=tp.roi, mask=tp.mask, scale=tp.scale, min_contrast=tp.min_contrast,
                              static_mask=tp.static_mask, size=tp.size,
                              samples=spool.samples(15) if spool is not None else None)
        warnings.extend(scene.warnings)
        vmax, body_s = tp.speed_limits()
        with bar(info.frame_count or None, "track", quiet=tp.quiet, unit="frame") as pb:
            raw = track_frames(frames, (info.width, info.height), roi=scene.roi if tp.roi is not None else None,
                               valid=scene.valid, flat=scene.flat, seg=scene.seg, margin_px=tp.margin_px,
                               expected_area_px=tp.expected_area_px, max_speed_px_s=vmax, max_speed_body_s=body_s,
                               progress=pb)
            finish_progress(pb, int(raw["t_s"].size), info.frame_count)
    finally:
        cap.release()
        if spool is not None:
            spool.close()
    return raw, scene, info, warnings


def _still_robot(raw: dict, tp: TrackPass, scene: PreparedScene, info: Any, warnings: list[str]) -> dict:
    """The first pass's arrays, or those of a static object that is the robot after all.

    When nothing (or little) moved, or what was found clings to a static object (a piece of
    it sticking out of its mask), a static object may still be the robot standing or vibrating
    in place (a drive that does not make it walk). Only an object shaped like the declared
    robot counts, never dust, and only if it is found in more frames (:func:`_static_robot`)."""
    static = scene.static
    n = raw["t_s"].size
    found = int(np.sum(raw["quality"] != QUALITY_LOST))
    if static is None or not static.object_boxes or not n or (found >= 0.5 * n and raw["on_static"] <= 0.5 * found):
        return raw
    still = _static_robot(tp, (info.width, info.height), scene.roi if tp.roi is not None else None,
                          scene.valid_with_objects, scene.seg)
    if still is None or np.sum(still["quality"] != QUALITY_LOST) < found:
        return raw
    if len(static.object_boxes) == 1:       # the one static object set aside is the robot
        warnings[:] = [w for w in warnings if not w.startswith("1 static dark object(s) set aside")]
    warnings.append("the robot hardly moved: it was set aside as a static object at first, and is tracked as the "
                    "robot because its " + ("size and length match the robot's at this scale" if tp.scale is not None
                                            else "proportions match the declared robot's")
                    + " (a still robot's speed is ~0, not dust's)")
    return still


def _frame_times(raw: dict, info: Any, tp: TrackPass, warnings: list[str]) -> tuple[np.ndarray, str, np.ndarray]:
    """The checked frame times, where they came from, and the faulty frames (flagged lost in ``raw``)."""
    from labkit.analysis.tracking.video_io import check_timestamps

    if raw["t_s"].size == 0:
        if info.undecodable:
            raise InputError(f"none of the {info.undecodable} frames could be decoded", file=tp.source)
        raise InputError("the video holds no frames", file=tp.source)
    if info.times is not None and raw["t_s"].size + info.undecodable != info.times.size:
        raise InputError(f"{info.times.size} declared times for {raw['t_s'].size + info.undecodable} frames",
                         file=tp.timestamps, key="--timestamps", expected="one time per frame of the video")
    if info.undecodable:
        warnings.insert(0, f"{info.undecodable} frame(s) could not be decoded and were skipped "
                           f"(damaged or truncated file); {raw['t_s'].size} kept")
    t_s, ts_source, faulty = check_timestamps(raw["t_s"], info.fps_nominal, str(tp.source))
    if info.timestamps_from != "container":
        ts_source = info.timestamps_from
    if faulty.any():
        for key in ("u_px", "v_px", "theta", "area_px", "u_alt", "v_alt", "major_px"):
            raw[key][faulty] = np.nan
        raw["quality"][faulty] = QUALITY_LOST
    return t_s, ts_source, faulty


def _no_robot(raw: dict, static: Any, frames: int, source: str | Path) -> InputError:
    """The error for a video where the robot was never found: the contrast found, and any static objects."""
    found = raw["best_contrast"]
    noise = raw["noise"]
    what = (f"the strongest dark object had {100 * found:.1f} % contrast against the tray"
            f"{f' (pixel noise {100 * noise:.1f} %)' if np.isfinite(noise) else ''}; a robot needs "
            f"{100 * raw['min_contrast']:.1f} % (--min-contrast)")
    if static is not None and static.object_boxes:
        boxes = "; ".join(",".join(str(v) for v in b) for b in static.object_boxes[:2])
        what = (f"only {len(static.object_boxes)} static dark object(s) (never moving: dust, or a robot that "
                f"never moved) at x,y,w,h {boxes} were found and set aside"
                f" (none of them shaped like the declared robot; --robot-size-mm L,W declares it)"
                f"; otherwise {what}")
    return InputError(f"no robot found in any of {frames} frames: {what}", file=source,
                      expected="a chip darker than the tray that moves (see --preview FRAME)")


def _track_warnings(raw: dict, stretches: list[tuple[float, float]]) -> list[str]:
    """What the user should know about the frames: lost stretches, ambiguous, unlike or jumping candidates."""
    out = []
    if stretches:
        n_lost = int(np.sum(raw["quality"] == QUALITY_LOST))
        shown = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in stretches[:4]) + (" ..." if len(stretches) > 4 else "")
        out.append(f"{n_lost} frame(s) lost in {len(stretches)} stretch(es) ({shown}): occluded, out of view "
                   f"or unlike the robot; bridged by the smoothed path, not used for the speed")
    if raw["ambiguous"]:
        out.append(f"{raw['ambiguous']} frame(s) had a second robot-sized object within reach: check the "
                   f"overlay (--overlay) or narrow the search (--roi/--mask)")
    if raw.get("unlike"):
        out.append(f"{raw['unlike']} frame(s) had a robot-sized object not shaped like the robot (its length "
                   f"or width off: a tweezer, the robot merged with something): flagged lost")
    if raw["jumps"]:
        out.append(f"{raw['jumps']} frame(s) showed a robot-like object farther than the robot can walk: "
                   f"flagged lost (an occlusion), not taken as a position")
    return out
