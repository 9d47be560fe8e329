"""Top-view video of the robot on the vibrating tray, with known truth.

The virtual lab's camera and the tracker's tests use these frames: a dark
5 mm x 2 mm chip with six leg stubs on light Teflon, seen from above through a
stereoscope, with the nuisances of the real bench (sensor noise, vibration
blur, stroboscopic jitter, slow lighting drift, a textured tray, the tray's
edge, stretches where the robot is hidden or out of view).

Geometry and conventions
------------------------
* World frame: ``x_mm`` to the right, ``y_mm`` up (seen from above).
* ``heading_rad`` is the robot's yaw about +z: 0 when its front points to +y
  (the simulator's walking direction), positive counter-clockwise. The front
  direction is ``(-sin h, cos h)``.
* Image frame: column ``u`` to the right, row ``v`` down, pixel centres at
  integers (OpenCV's convention). World ``(x, y)`` maps to
  ``u = u0 + x / mm_per_px``, ``v = v0 - y / mm_per_px``.
* The chip is drawn with two mirror symmetries, so its area centroid is its
  centre and its principal axis its long axis: the truth a moment-based
  tracker must find is exact.

Accuracy: the chip is rasterised at ``SUPERSAMPLE`` x the pixel pitch with
sub-pixel vertex coordinates and box-averaged down (an area-coverage
anti-aliasing), and blur kernels are symmetric, so the rendered darkness
centroid matches the truth to ~1e-3 px.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from labkit.video import write_video as write_video  # re-exported: the camera and older callers use it here

SUPERSAMPLE = 8
ROBOT_LENGTH_MM = 5.0
ROBOT_WIDTH_MM = 2.0
TEFLON_LEVEL = 205.0       # grey level of bare Teflon under nominal light
ROBOT_REFLECTANCE = 0.22   # the chip's reflectance relative to Teflon
RIM_REFLECTANCE = 0.45     # the tray's wall/rim beyond its edge, relative to Teflon

# Leg stubs seen from above: (position along the body from its centre, mm),
# sticking out of both long sides; front/back symmetric on purpose (see above).
_LEG_POS_MM = (-1.7, 0.0, 1.7)
_LEG_OUT_MM = 0.45
_LEG_W_MM = 0.3


@dataclass
class RenderTruth:
    """Where the robot really is in each frame (image pixels, as a tracker should see it).

    ``u_px``/``v_px`` include the stroboscopic jitter (it moves the whole
    scene in the image); ``u_world_px``/``v_world_px`` do not.
    ``visible`` is False while the robot is occluded or its centre is out of
    the frame; ``whole`` is True when the whole chip is inside the frame and not
    occluded.
    """

    t_s: np.ndarray
    u_px: np.ndarray
    v_px: np.ndarray
    u_world_px: np.ndarray
    v_world_px: np.ndarray
    heading_rad: np.ndarray
    visible: np.ndarray
    whole: np.ndarray
    mm_per_px: float
    origin_px: tuple[float, float]
    length_px: float
    width_px: float
    meta: dict = field(default_factory=dict)


def robot_polygons_mm(length_mm: float = ROBOT_LENGTH_MM,
                      width_mm: float = ROBOT_WIDTH_MM) -> list[np.ndarray]:
    """The chip outline as convex polygons in body coordinates (mm; +y = front).

    Returns the body rectangle and six leg stubs, each a (4, 2) array of
    ``(x, y)`` corners.
    """
    def rect(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
        return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)

    hw, hl = width_mm / 2, length_mm / 2
    polys = [rect(-hw, -hl, hw, hl)]
    scale = length_mm / ROBOT_LENGTH_MM
    for p in _LEG_POS_MM:
        p *= scale
        w = _LEG_W_MM * scale / 2
        polys.append(rect(hw - 1e-3, p - w, hw + _LEG_OUT_MM * scale, p + w))
        polys.append(rect(-hw - _LEG_OUT_MM * scale, p - w, -hw + 1e-3, p + w))
    return polys


def _texture_field(shape: tuple[int, int], amount: float, rng: np.random.Generator) -> np.ndarray:
    """A Teflon-like reflectance map: smooth mottling plus fine grain and a few scratches."""
    import cv2

    h, w = shape
    if amount <= 0:
        return np.ones(shape, np.float32)
    coarse = cv2.GaussianBlur(rng.standard_normal(shape).astype(np.float32), (0, 0), 9)
    fine = cv2.GaussianBlur(rng.standard_normal(shape).astype(np.float32), (0, 0), 1.2)
    field_ = coarse / (coarse.std() + 1e-9) + 0.6 * fine / (fine.std() + 1e-9)
    scratches = np.zeros(shape, np.float32)
    for _ in range(6):
        x0, y0 = rng.uniform(0, w), rng.uniform(0, h)
        ang = rng.uniform(0, np.pi)
        ln = rng.uniform(0.2, 0.6) * max(h, w)
        p0 = (int(x0 - ln * np.cos(ang)), int(y0 - ln * np.sin(ang)))
        p1 = (int(x0 + ln * np.cos(ang)), int(y0 + ln * np.sin(ang)))
        cv2.line(scratches, p0, p1, 1.0, 1, cv2.LINE_AA)
    field_ = field_ / (field_.std() + 1e-9) - 1.5 * scratches
    return (1.0 + amount * field_).astype(np.float32)


def _vibration_kernel(blur_px: float, angle_rad: float) -> np.ndarray | None:
    """Exposure-averaged sinusoidal motion: arcsine weights along a line of length ``blur_px``.

    Symmetric about its centre, so it blurs without moving any centroid.
    """
    if blur_px <= 0:
        return None
    half = blur_px / 2
    r = int(np.ceil(half)) + 1
    n = 2 * r + 1
    k = np.zeros((n, n), np.float64)
    phase = (np.arange(256) + 0.5) / 256 * 2 * np.pi
    s = half * np.sin(phase)
    xs, ys = r + s * np.cos(angle_rad), r + s * np.sin(angle_rad)
    # bilinear splat keeps each sample's first moment exact
    for x, y in zip(xs, ys):
        x0, y0 = int(np.floor(x)), int(np.floor(y))
        fx, fy = x - x0, y - y0
        k[y0, x0] += (1 - fx) * (1 - fy)
        k[y0, x0 + 1] += fx * (1 - fy)
        k[y0 + 1, x0] += (1 - fx) * fy
        k[y0 + 1, x0 + 1] += fx * fy
    k = 0.5 * (k + k[::-1, ::-1])  # exact point symmetry
    return (k / k.sum()).astype(np.float32)


def _coverage(u: float, v: float, heading: float, polys_px: list[np.ndarray],
              shape: tuple[int, int]) -> tuple[np.ndarray, tuple[int, int]] | None:
    """Area coverage (0..1) of the chip centred at (u, v); returns (patch, (row0, col0))."""
    import cv2

    c, s = np.cos(heading), np.sin(heading)
    # body (x right, y front) -> image (u right, v down): front (0, 1) -> (-sin h, -cos h)
    rot = np.array([[c, -s], [-s, -c]])
    pts = [p @ rot.T + (u, v) for p in polys_px]
    allp = np.vstack(pts)
    h, w = shape
    c0, r0 = int(np.floor(allp[:, 0].min())) - 2, int(np.floor(allp[:, 1].min())) - 2
    c1, r1 = int(np.ceil(allp[:, 0].max())) + 3, int(np.ceil(allp[:, 1].max())) + 3
    if c1 <= 0 or r1 <= 0 or c0 >= w or r0 >= h:
        return None
    ss = SUPERSAMPLE
    hi = np.zeros(((r1 - r0) * ss, (c1 - c0) * ss), np.uint8)
    shift = 4
    for p in pts:
        # image pixel k spans [k-0.5, k+0.5]; in hi-res units X = (u - c0 + 0.5) * ss sub-sample j
        # spans [j, j+1] and fillPoly tests its centre, which it calls j: hence the -0.5.
        q = ((p - (c0 - 0.5, r0 - 0.5)) * ss - 0.5) * (1 << shift)
        cv2.fillConvexPoly(hi, np.round(q).astype(np.int32), 255, cv2.LINE_8, shift)
    patch = cv2.resize(hi.astype(np.float32) / 255.0, (c1 - c0, r1 - r0), interpolation=cv2.INTER_AREA)
    return patch, (r0, c0)


def _polygons_px(length_mm: float, width_mm: float, mm_per_px: float) -> list[np.ndarray]:
    """The robot's polygons in pixels, each edge pulled in by half a sub-sample.

    fillPoly also fills sub-samples whose centres lie on an edge: pulling every edge in by half a
    sub-sample keeps the rasterised area (and the body's length) exact, not 1/16 px too big.
    """
    shrink = 0.5 / SUPERSAMPLE
    out = []
    for p in robot_polygons_mm(length_mm, width_mm):
        q = p / mm_per_px
        out.append(q - shrink * np.sign(q - q.mean(axis=0)))
    return out


def _background(shape: tuple[int, int], pad: int, texture: float,
                tray_rect_px: tuple[float, float, float, float] | None, rng: np.random.Generator) -> np.ndarray:
    """The tray's reflectance over ``shape`` (the frame plus ``pad`` on each side): texture and rim."""
    refl = _texture_field(shape, texture, rng)
    if tray_rect_px is None:
        return refl
    u0, v0, u1, v1 = tray_rect_px
    # anti-aliased inner edge: area coverage of the rectangle per pixel
    cols = np.arange(shape[1]) - pad
    rows = np.arange(shape[0]) - pad
    cu = np.clip(np.minimum(cols + 0.5, u1) - np.maximum(cols - 0.5, u0), 0, 1)
    cv_ = np.clip(np.minimum(rows + 0.5, v1) - np.maximum(rows - 0.5, v0), 0, 1)
    inside = np.outer(cv_, cu).astype(np.float32)
    return refl * inside + RIM_REFLECTANCE * (1 - inside)


def _shifted(refl: np.ndarray, jit: np.ndarray, pad: int, hw: tuple[int, int]) -> np.ndarray:
    """The frame's view of the padded background, shifted by the jitter ``jit`` (u, v) in pixels."""
    import cv2

    h, w = hw
    if pad and (jit != 0).any():
        # shift the scene: output(p) = refl(p - jit) in frame coordinates
        m = np.array([[1, 0, pad - jit[0]], [0, 1, pad - jit[1]]], np.float32)
        return cv2.warpAffine(refl, m, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_REFLECT)
    return refl[pad:pad + h, pad:pad + w].copy()


def _draw_robot(scene: np.ndarray, cov: tuple[np.ndarray, tuple[int, int]] | None) -> None:
    """Blend the robot's coverage patch (at its top-left corner ``(r0, c0)``) into ``scene``, in place."""
    if cov is None:
        return
    h, w = scene.shape
    patch, (r0, c0) = cov
    pr0, pc0 = max(r0, 0), max(c0, 0)
    pr1, pc1 = min(r0 + patch.shape[0], h), min(c0 + patch.shape[1], w)
    c = patch[pr0 - r0:pr1 - r0, pc0 - c0:pc1 - c0]
    sub = scene[pr0:pr1, pc0:pc1]
    scene[pr0:pr1, pc0:pc1] = sub * (1 - c) + ROBOT_REFLECTANCE * c


def _expose(img: np.ndarray, kernel: np.ndarray | None, noise: float, rng: np.random.Generator) -> np.ndarray:
    """The camera's frame of the lit scene ``img``: vibration blur, sensor noise, 8-bit grey levels."""
    import cv2

    if kernel is not None:
        img = cv2.filter2D(img, -1, kernel, borderType=cv2.BORDER_REFLECT)
    if noise > 0:
        img = img + rng.normal(0, noise, img.shape).astype(np.float32)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class _Lighting:
    """The illumination over the clip: a gain ``1 + a sin(phase)`` and a drifting left-right gradient."""

    t0_s: float
    span_s: float
    drift: float
    width_px: int

    def at(self, t_s: float) -> np.ndarray:
        """The light (grey level per unit reflectance) of each column at time ``t_s``, shape (1, width)."""
        uu = (np.arange(self.width_px, dtype=np.float32) - self.width_px / 2) / self.width_px
        phase = 2 * np.pi * (t_s - self.t0_s) / self.span_s
        gain = 1 + self.drift * np.sin(phase)
        grad = 0.5 * self.drift * np.sin(0.5 * phase + 0.7)
        return (gain + grad * uu)[None, :] * TEFLON_LEVEL


def render_frames(y_mm: ArrayLike, x_mm: ArrayLike | None, heading_rad: ArrayLike,
                  t_s: ArrayLike, *, size_px: tuple[int, int] = (640, 480), mm_per_px: float = 0.05,
                  noise: float = 2.0, blur_px: float = 0.0, blur_angle_rad: float = 0.0,
                  jitter_px: float = 0.0, lighting_drift: float = 0.0, texture: float = 0.0,
                  occlusion: Sequence[tuple[float, float]] | None = None,
                  tray_rect_px: tuple[float, float, float, float] | None = None,
                  origin_px: tuple[float, float] | None = None, length_mm: float = ROBOT_LENGTH_MM,
                  width_mm: float = ROBOT_WIDTH_MM, seed: int = 0, return_truth: bool = False):
    """Render the robot's top view for each time sample.

    Parameters
    ----------
    y_mm, x_mm:
        The robot centre's path in the world frame (mm); ``x_mm=None`` means 0.
    heading_rad:
        Yaw per sample (or one value): 0 = front towards +y, counter-clockwise positive.
    t_s:
        Frame times (s); only used for the lighting drift, occlusions and the truth.
    size_px:
        (width, height) of the frames.
    mm_per_px:
        Image scale.
    noise:
        Standard deviation of additive sensor noise (grey levels).
    blur_px, blur_angle_rad:
        Peak-to-peak length (px) and image direction of the vibration's motion blur.
    jitter_px:
        Stroboscopic jitter: each frame the whole scene is shifted by
        ``jitter_px * sin(phi)`` on each axis with independent uniform random phases
        (so ``jitter_px`` is the vibration's peak amplitude in the image).
    lighting_drift:
        Fractional amplitude of a slow change of the illumination over the clip:
        a global gain ``1 + a sin(...)`` plus a drifting left-right gradient of ``a/2``.
    texture:
        Fractional contrast of the Teflon's mottling, grain and scratches (0.05 is visible).
    occlusion:
        ``[(t0_s, t1_s), ...]`` stretches during which the robot is hidden.
    tray_rect_px:
        ``(u0, v0, u1, v1)``: the tray's inner edge; beyond it the darker rim is seen.
    origin_px:
        Image position of the world origin; default: centre the path in the frame.
    seed:
        Seeds noise, jitter and texture.
    return_truth:
        Also return a :class:`RenderTruth`.

    Returns
    -------
    frames : numpy.ndarray
        ``(N, height, width)`` uint8 grey frames; with ``return_truth`` the pair
        ``(frames, truth)``.
    """
    t = np.asarray(t_s, float)
    n = t.size
    y = np.broadcast_to(np.asarray(y_mm, float), (n,))
    x = np.zeros(n) if x_mm is None else np.broadcast_to(np.asarray(x_mm, float), (n,))
    hd = np.broadcast_to(np.asarray(heading_rad, float), (n,))
    w, h = int(size_px[0]), int(size_px[1])
    if n == 0:
        raise ValueError("render_frames: no time samples")
    if mm_per_px <= 0:
        raise ValueError("render_frames: mm_per_px must be > 0")
    rng = np.random.default_rng(seed)
    if origin_px is None:       # centre the path in the frame
        origin_px = ((w - 1 - (x.min() + x.max()) / mm_per_px) / 2, (h - 1 + (y.min() + y.max()) / mm_per_px) / 2)
    u_world, v_world = origin_px[0] + x / mm_per_px, origin_px[1] - y / mm_per_px
    jit = jitter_px * np.sin(rng.uniform(0, 2 * np.pi, (n, 2))) if jitter_px > 0 else np.zeros((n, 2))
    u, v = u_world + jit[:, 0], v_world + jit[:, 1]

    polys_px = _polygons_px(length_mm, width_mm, mm_per_px)
    # background reflectance (texture and rim), rendered with a margin so jitter shifts stay filled
    pad = int(np.ceil(jitter_px)) + 2
    refl = _background((h + 2 * pad, w + 2 * pad), pad, texture, tray_rect_px, rng)
    kernel = _vibration_kernel(blur_px, blur_angle_rad)
    hidden = np.zeros(n, bool)
    for t0, t1 in occlusion or ():
        hidden |= (t >= t0) & (t <= t1)
    light = _Lighting(t[0], max(t[-1] - t[0], 1e-9), lighting_drift, w)

    frames = np.empty((n, h, w), np.uint8)
    whole = np.zeros(n, bool)
    half_diag = np.hypot(length_mm / 2, width_mm / 2 + _LEG_OUT_MM) / mm_per_px
    for k in range(n):
        scene = _shifted(refl, jit[k], pad, (h, w))
        if not hidden[k]:
            _draw_robot(scene, _coverage(u[k], v[k], hd[k], polys_px, (h, w)))
            whole[k] = (half_diag + 1 < u[k] < w - 2 - half_diag) and (half_diag + 1 < v[k] < h - 2 - half_diag)
        frames[k] = _expose(scene * light.at(t[k]), kernel, noise, rng)

    if not return_truth:
        return frames
    visible = ~hidden & (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
    truth = RenderTruth(t_s=t.copy(), u_px=u, v_px=v, u_world_px=u_world, v_world_px=v_world,
                        heading_rad=hd.copy(), visible=visible, whole=whole & ~hidden,
                        mm_per_px=float(mm_per_px), origin_px=(float(origin_px[0]), float(origin_px[1])),
                        length_px=length_mm / mm_per_px, width_px=width_mm / mm_per_px,
                        meta=dict(noise=noise, blur_px=blur_px, jitter_px=jitter_px,
                                  lighting_drift=lighting_drift, texture=texture, seed=seed))
    return frames, truth
