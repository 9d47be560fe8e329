"""A second independent renderer, written from the bench's description of what goes wrong, not from the tracker.

Nothing here comes from labkit or from ``render_scenes``: each pixel's value is
integrated from the physics of the camera, point by point.

* **Scene**: a dark rectangular robot (``length_mm`` x ``width_mm``, any size)
  on a bright tray, walking a path made of stretches (still, straight, arcs:
  starts, stops, pauses, turns), shaken by the drive at ``vib_hz`` with an
  amplitude ``vib_mm`` (the shaker's vibration: stroboscopic jitter and, over
  the exposure, blur).
* **Lens and stand**: world millimetres -> pixels through a perspective
  projection of a tray tilted about the image's x axis, so the scale changes
  by ``tilt_share`` from the top of the field to its bottom (the stereoscope's
  tilted stand).
* **Light**: a ring light whose brightness falls off as ``1 - ring * r^2``
  (``r`` = 1 at the frame's corners: ``ring = 0.22`` is a 22 % corner
  fall-off).
* **Sensor**: an exposure of ``exposure_s`` integrated over ``sub`` instants;
  a rolling shutter reads row ``v`` ``v * line_s`` after row 0; shot/read
  noise; output as 8-bit grey, 16-bit (a 12-bit sensor's counts, ``bits=12``,
  dim when ``level`` is low), RGB colour or a raw RGGB Bayer mosaic.

Each pixel is supersampled ``ss x ss`` times: every sample point is taken back
to the tray (inverse projection), to its instant (frame time + exposure
offset + its row's readout delay), and tested against the robot's rectangle at
that instant. The truth is the robot's world path (mm) and its true mean speed
over the clip and over its moving part.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Leg:
    """One stretch of the path: ``duration_s`` at ``speed_mm_s``, turning at ``turn_rad_s``."""

    duration_s: float
    speed_mm_s: float
    turn_rad_s: float = 0.0


@dataclass
class Camera:
    width: int = 320
    height: int = 240
    mm_per_px: float = 0.1          # at the field's centre
    fps: float = 30.0
    n: int = 60
    exposure_s: float = 0.0         # 0 = an instant
    line_s: float = 0.0             # rolling shutter: delay per row (s); 0 = global shutter
    tilt_share: float = 0.0         # the scale's change from the top of the field to its bottom
    ring: float = 0.0               # ring light's fall-off at the corners (share)
    level: float = 200.0            # tray's brightness at the centre (counts)
    noise: float = 2.0              # read noise (counts, std)
    output: str = "grey8"           # grey8, grey16, colour, bayer
    bits: int = 8                   # grey16: the sensor's bit depth (counts up to 2**bits - 1)
    ss: int = 4                     # supersampling per axis
    sub: int = 4                    # instants over the exposure


@dataclass
class Robot:
    length_mm: float = 5.0
    width_mm: float = 2.0
    reflectance: float = 0.2
    start_mm: tuple[float, float] = (0.0, 0.0)   # from the field's centre, y up
    heading0_rad: float = 0.4                     # 0 = front towards +y, counter-clockwise
    legs: list[Leg] = field(default_factory=lambda: [Leg(10.0, 3.0, 0.3)])
    vib_mm: float = 0.0
    vib_hz: float = 317.0
    vib_angle_rad: float = 0.7
    breathe: tuple[float, float] = (0.0, 1.0)      # a soft body: length x (1 + a sin 2 pi f t), width / that


@dataclass
class Truth:
    t_s: np.ndarray
    x_mm: np.ndarray            # robot's centre (world, mm, from the field's centre, y up) at each frame's time
    y_mm: np.ndarray
    u_px: np.ndarray            # its projection (px), for position checks
    v_px: np.ndarray
    speed_mm_s: float           # path length / clip duration (vibration excluded: the walk)
    moving_speed_mm_s: float    # path length / time spent moving
    moving_s: float


def pose(rb: Robot, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Walk (x, y mm, heading) at times ``t``: stretches integrated exactly (arcs and lines)."""
    t = np.asarray(t, float)
    x = np.full(t.shape, rb.start_mm[0])
    y = np.full(t.shape, rb.start_mm[1])
    h = np.full(t.shape, rb.heading0_rad)
    t0 = 0.0
    x0, y0, h0 = rb.start_mm[0], rb.start_mm[1], rb.heading0_rad
    for leg in rb.legs:
        tau = np.clip(t - t0, 0.0, leg.duration_s)
        active = t > t0
        if abs(leg.turn_rad_s) < 1e-12:
            dx, dy, dh = -leg.speed_mm_s * np.sin(h0) * tau, leg.speed_mm_s * np.cos(h0) * tau, 0 * tau
        else:
            r = leg.speed_mm_s / leg.turn_rad_s
            dh = leg.turn_rad_s * tau
            dx, dy = r * (np.cos(h0 + dh) - np.cos(h0)), r * (np.sin(h0 + dh) - np.sin(h0))
        x = np.where(active, x0 + dx, x)
        y = np.where(active, y0 + dy, y)
        h = np.where(active, h0 + dh, h)
        end = np.array([leg.duration_s])
        if abs(leg.turn_rad_s) < 1e-12:
            x0, y0 = x0 - leg.speed_mm_s * np.sin(h0) * end[0], y0 + leg.speed_mm_s * np.cos(h0) * end[0]
        else:
            r = leg.speed_mm_s / leg.turn_rad_s
            h1 = h0 + leg.turn_rad_s * end[0]
            x0, y0, h0 = x0 + r * (np.cos(h1) - np.cos(h0)), y0 + r * (np.sin(h1) - np.sin(h0)), h1
        t0 += leg.duration_s
    return x, y, h


def vibration(rb: Robot, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The shaker's displacement (mm) at times ``t``."""
    d = rb.vib_mm * np.sin(2 * np.pi * rb.vib_hz * np.asarray(t, float))
    return d * np.cos(rb.vib_angle_rad), d * np.sin(rb.vib_angle_rad)


def _focal(cam: Camera) -> float:
    # a tray tilted about the image's x axis: the magnification goes as 1 / (1 - k y) (y in
    # centre-scale pixels, up), so it changes by ~ k * height from the field's top to its bottom
    return cam.tilt_share / cam.height if cam.tilt_share else 0.0


def world_to_px(cam: Camera, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Projection (mm from the centre, y up) -> pixel centres (u right, v down); a homography."""
    k = _focal(cam)
    cu, cv = (cam.width - 1) / 2, (cam.height - 1) / 2
    xs, ys = np.asarray(x) / cam.mm_per_px, -np.asarray(y) / cam.mm_per_px
    den = 1 - k * ys
    return cu + xs / den, cv + ys / den


def px_to_world(cam: Camera, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`world_to_px`."""
    k = _focal(cam)
    cu, cv = (cam.width - 1) / 2, (cam.height - 1) / 2
    du, dv = np.asarray(u) - cu, np.asarray(v) - cv
    ys = dv / (1 + k * dv)
    xs = du * (1 - k * ys)
    return xs * cam.mm_per_px, -ys * cam.mm_per_px


def coverage(cam: Camera, rb: Robot, t_frame: float, rng_box: tuple[int, int, int, int]) -> np.ndarray:
    """Time- and area-averaged robot coverage (0..1) in the pixel box ``(u0, v0, u1, v1)``."""
    u0, v0, u1, v1 = rng_box
    ss = cam.ss
    off = (np.arange(ss) + 0.5) / ss - 0.5
    uu = (np.arange(u0, u1)[:, None] + off[None, :]).ravel()
    vv = (np.arange(v0, v1)[:, None] + off[None, :]).ravel()
    U, V = np.meshgrid(uu, vv)
    X, Y = px_to_world(cam, U, V)
    acc = np.zeros(U.shape, np.float32)
    sub = cam.sub if cam.exposure_s > 0 else 1
    for j in range(sub):
        te = (j + 0.5) / sub * cam.exposure_s - cam.exposure_s / 2
        ts = t_frame + te + np.clip(V, 0, cam.height) * cam.line_s       # each row's own instant
        px, py, ph = pose(rb, ts)
        vx, vy = vibration(rb, ts)
        dx, dy = X - (px + vx), Y - (py + vy)
        # body coordinates: front (-sin h, cos h), side (cos h, sin h)
        s_side = dx * np.cos(ph) + dy * np.sin(ph)
        s_front = -dx * np.sin(ph) + dy * np.cos(ph)
        k = 1 + rb.breathe[0] * np.sin(2 * np.pi * rb.breathe[1] * ts)
        acc += ((np.abs(s_side) <= rb.width_mm / 2 / k) & (np.abs(s_front) <= rb.length_mm / 2 * k)).astype(np.float32)
    acc /= sub
    h, w = v1 - v0, u1 - u0
    return acc.reshape(h, ss, w, ss).mean(axis=(1, 3))


def light(cam: Camera) -> np.ndarray:
    vv, uu = np.mgrid[:cam.height, :cam.width].astype(np.float32)
    cu, cv = (cam.width - 1) / 2, (cam.height - 1) / 2
    r2 = ((uu - cu) ** 2 + (vv - cv) ** 2) / (cu ** 2 + cv ** 2)
    return (cam.level * (1 - cam.ring * r2)).astype(np.float32)


TRAY_RGB = np.array([0.95, 0.9, 0.75], np.float32)      # a warm light on Teflon (R, G, B)
ROBOT_RGB = np.array([0.9, 1.0, 1.2], np.float32)       # the chip's tint relative to its grey


def render(cam: Camera, rb: Robot, seed: int = 0) -> tuple[np.ndarray, Truth]:
    """Frames (n, H, W[, 3]) and the truth. 8-bit outputs are uint8, ``grey16`` uint16, ``bayer`` uint8."""
    rng = np.random.default_rng(seed)
    t = np.arange(cam.n) / cam.fps
    L = light(cam)
    frames = []
    for tk in t:
        # the box the robot can touch this frame (the exposure and the readout widen it)
        span = np.linspace(tk - cam.exposure_s, tk + cam.exposure_s + cam.height * cam.line_s, 9)
        px, py, _ = pose(rb, span)
        r = 0.6 * np.hypot(rb.length_mm, rb.width_mm) + 2 * rb.vib_mm
        bu, bv = world_to_px(cam, np.r_[px - r, px + r, px - r, px + r], np.r_[py - r, py - r, py + r, py + r])
        u0, u1 = int(max(np.floor(bu.min()) - 2, 0)), int(min(np.ceil(bu.max()) + 3, cam.width))
        v0, v1 = int(max(np.floor(bv.min()) - 2, 0)), int(min(np.ceil(bv.max()) + 3, cam.height))
        refl = np.ones((cam.height, cam.width), np.float32)
        if u1 > u0 and v1 > v0:
            c = coverage(cam, rb, tk, (u0, v0, u1, v1))
            refl[v0:v1, u0:u1] = 1 - c + rb.reflectance * c
        img = L * refl
        if cam.output in ("colour", "bayer"):
            robot = (1 - refl) / (1 - rb.reflectance)
            col = img[..., None] * TRAY_RGB * (1 - robot[..., None] + ROBOT_RGB * robot[..., None])
            col = col + rng.normal(0, cam.noise, col.shape).astype(np.float32)
            if cam.output == "bayer":
                # RGGB: R at (even row, even col), B at (odd, odd), G elsewhere
                mosaic = np.empty((cam.height, cam.width), np.float32)
                mosaic[0::2, 0::2] = col[0::2, 0::2, 0]
                mosaic[0::2, 1::2] = col[0::2, 1::2, 1]
                mosaic[1::2, 0::2] = col[1::2, 0::2, 1]
                mosaic[1::2, 1::2] = col[1::2, 1::2, 2]
                frames.append(np.clip(np.rint(mosaic), 0, 255).astype(np.uint8))
            else:
                frames.append(np.clip(np.rint(col[..., ::-1]), 0, 255).astype(np.uint8))   # BGR, as OpenCV
            continue
        img = img + rng.normal(0, cam.noise, img.shape).astype(np.float32)
        if cam.output == "grey16":
            frames.append(np.clip(np.rint(img), 0, 2 ** cam.bits - 1).astype(np.uint16))
        else:
            frames.append(np.clip(np.rint(img), 0, 255).astype(np.uint8))
    x, y, _ = pose(rb, t)
    u, v = world_to_px(cam, x, y)
    # the true walk's length over the clip (fine steps) and the time spent moving
    tf = np.linspace(0, t[-1], 20001)
    fx, fy, _ = pose(rb, tf)
    path = float(np.sum(np.hypot(np.diff(fx), np.diff(fy))))
    moving = 0.0
    t0 = 0.0
    for leg in rb.legs:
        a, b = max(t0, 0.0), min(t0 + leg.duration_s, t[-1])
        if b > a and leg.speed_mm_s > 0:
            moving += b - a
        t0 += leg.duration_s
    dur = float(t[-1])
    truth = Truth(t, x, y, u, v, path / dur, path / moving if moving > 0 else 0.0, moving)
    return np.asarray(frames), truth
