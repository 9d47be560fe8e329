"""An independent renderer of stereoscope scenes for the tracking tests (not labkit.lab.render).

The tracker must be tested on images made without its own code or the
virtual lab's camera: this module draws the scenes from first principles with
OpenCV's polygon filling and NumPy only, and knows the exact truth.

Image formation, per frame ``k`` at time ``t_k``::

    I(u, v) = L0 * illum(u, v) * (1 + flicker_k) * R_k(u, v) + noise

``R`` is the scene's reflectance (tray 1, dust, chip, tweezers composited
in that order, each with its own area coverage), ``illum`` a smooth uneven
ring light (a linear gradient plus a radial fall-off) and ``flicker_k`` a
per-frame brightness change (mains flicker aliased by the frame rate plus a
random part).

Chip geometry (body coordinates, mm, +y = front): a ``5 x 2`` mm body and
three leg stubs per long side, placed symmetrically about both axes, so the
chip's area centroid is its centre and its long axis is its heading. Coverage
is rasterised at ``SS`` x the pixel pitch with 1/16 sub-sample vertices
(``cv2.fillPoly`` with ``shift=4``) and box-averaged, so the rendered
darkness centroid is the centre to ~0.03 px and its area within 1.5 % (checked in
``test_track_scenes.py::test_renderer_truth``).

Conventions: image ``u`` right, ``v`` down, pixel centres at integers;
world ``x_mm`` right, ``y_mm`` up; ``heading`` 0 = front towards +y,
counter-clockwise positive; world ``(x, y)`` -> ``u = u0 + x / s``,
``v = v0 - y / s``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

SS = 8                       # supersampling factor of the coverage raster
BODY_MM = (2.0, 5.0)         # width, length
LEGS_Y_MM = (-1.6, 0.0, 1.6)
LEG_OUT_MM, LEG_W_MM = 0.5, 0.35


def chip_polygons_mm() -> list[np.ndarray]:
    """Body and six legs as rectangles in body coordinates (mm, +y front)."""
    w, length = BODY_MM

    def rect(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
        return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)

    polys = [rect(-w / 2, -length / 2, w / 2, length / 2)]
    for y in LEGS_Y_MM:
        for side in (-1, 1):
            x_in, x_out = side * w / 2, side * (w / 2 + LEG_OUT_MM)
            polys.append(rect(min(x_in, x_out), y - LEG_W_MM / 2, max(x_in, x_out), y + LEG_W_MM / 2))
    return polys


def chip_area_mm2() -> float:
    return BODY_MM[0] * BODY_MM[1] + 6 * LEG_OUT_MM * LEG_W_MM


def coverage(shape: tuple[int, int], polys_px: list[np.ndarray]) -> np.ndarray:
    """Area coverage (float32, 0..1) of the union of polygons given in pixel coordinates."""
    h, w = shape
    out = np.zeros((h, w), np.float32)
    allp = np.concatenate(polys_px)
    u0 = int(np.floor(allp[:, 0].min())) - 1
    v0 = int(np.floor(allp[:, 1].min())) - 1
    u1 = int(np.ceil(allp[:, 0].max())) + 2
    v1 = int(np.ceil(allp[:, 1].max())) + 2
    cu0, cv0, cu1, cv1 = max(u0, 0), max(v0, 0), min(u1, w), min(v1, h)
    if cu1 <= cu0 or cv1 <= cv0:
        return out
    bw, bh = u1 - u0, v1 - v0
    canvas = np.zeros((bh * SS, bw * SS), np.uint8)
    # pixel u covers [u - 0.5, u + 0.5]; sub-sample j of the box has its centre at
    # u0 - 0.5 + (j + 0.5) / SS, so a point u lies at j = (u - u0 + 0.5) * SS - 0.5
    pts = [np.round(((p - [u0, v0]) + 0.5) * SS * 16 - 0.5 * 16).astype(np.int32) for p in polys_px]
    # each (convex) polygon on its own: one fillPoly call over touching polygons treats their shared
    # edges unevenly (a leg against the body), which moves the centroid by a few hundredths of a pixel
    for q in pts:
        cv2.fillConvexPoly(canvas, q, 1, lineType=cv2.LINE_8, shift=4)
    cov = canvas.reshape(bh, SS, bw, SS).mean(axis=(1, 3), dtype=np.float32)
    out[cv0:cv1, cu0:cu1] = cov[cv0 - v0:cv1 - v0, cu0 - u0:cu1 - u0]
    return out


def place(polys_mm: list[np.ndarray], u: float, v: float, heading: float, mm_per_px: float) -> list[np.ndarray]:
    """Body-frame polygons (mm) -> image polygons (px) for a chip centred at (u, v)."""
    c, s = np.cos(heading), np.sin(heading)
    out = []
    for p in polys_mm:
        x = p[:, 0] * c - p[:, 1] * s          # rotate counter-clockwise in the world (y up)
        y = p[:, 0] * s + p[:, 1] * c
        out.append(np.column_stack([u + x / mm_per_px, v - y / mm_per_px]))
    return out


@dataclass
class Truth:
    t_s: np.ndarray
    u_px: np.ndarray
    v_px: np.ndarray
    heading_rad: np.ndarray
    visible_frac: np.ndarray     # share of the chip's area seen (not occluded, inside the frame)
    speed_mm_s: float            # the true time-averaged speed of the chip's path
    mm_per_px: float
    dust_px: list = field(default_factory=list)
    tweezer_frames: np.ndarray | None = None

    @property
    def whole(self) -> np.ndarray:
        return self.visible_frac > 0.999


@dataclass
class Scene:
    """Everything that makes one video. Defaults: a dark chip walking a gentle arc on even light."""

    width: int = 640
    height: int = 480
    mm_per_px: float = 0.05
    n: int = 60
    fps: float = 30.0
    t_s: np.ndarray | None = None           # own frame times (dropped frames); default k / fps
    speed_mm_s: float = 3.0
    turn_rad_s: float = 0.3
    heading0_rad: float = 0.4
    start_px: tuple[float, float] | None = None   # chip centre at t = 0 (default: frame centre)
    level: float = 200.0                    # tray grey level at the light's centre
    chip_reflectance: float = 0.2           # 0.72 = a grey chip at 28 % contrast
    gradient: float = 0.0                   # light falls by this share across the frame (linear)
    gradient_angle_rad: float = 0.3
    ring: float = 0.0                       # extra radial fall-off at the corners (share)
    flicker: float = 0.0                    # per-frame relative brightness change (amplitude)
    noise: float = 2.0                      # sensor noise, grey levels (std)
    blur_px: float = 0.0                    # Gaussian blur sigma (optics, vibration)
    jitter_px: float = 0.0                  # stroboscopic jitter of the chip (uniform +-, px)
    mottling: float = 0.0                   # the tray's blotchy texture: std of its reflectance (share)
    dust: list = field(default_factory=list)  # (u, v, a_px, b_px, angle_deg, reflectance): static ellipses
    tweezers: tuple[float, float] | None = None   # (t_in, t_out): the prongs cover the chip between
    others: list = field(default_factory=list)   # (u0_px, v0_px, heading_rad, speed_mm_s): more chips, straight
    seed: int = 0

    def times(self) -> np.ndarray:
        return np.arange(self.n) / self.fps if self.t_s is None else np.asarray(self.t_s, float)


def chip_path(sc: Scene, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre (u, v in px, jitter-free) and heading of a chip walking at constant speed on an arc."""
    h = sc.heading0_rad + sc.turn_rad_s * t
    if abs(sc.turn_rad_s) < 1e-12:
        x = -sc.speed_mm_s * np.sin(h) * t
        y = sc.speed_mm_s * np.cos(h) * t
    else:
        r = sc.speed_mm_s / sc.turn_rad_s      # front (-sin h, cos h) integrated over time
        x = r * (np.cos(h) - np.cos(sc.heading0_rad))
        y = r * (np.sin(h) - np.sin(sc.heading0_rad))
    u0, v0 = sc.start_px if sc.start_px is not None else ((sc.width - 1) / 2, (sc.height - 1) / 2)
    return u0 + x / sc.mm_per_px, v0 - y / sc.mm_per_px, h


def illumination(sc: Scene) -> np.ndarray:
    """The ring light's smooth unevenness (1 at its brightest)."""
    vv, uu = np.mgrid[:sc.height, :sc.width].astype(np.float32)
    cu, cv = (sc.width - 1) / 2, (sc.height - 1) / 2
    d = ((uu - cu) * np.cos(sc.gradient_angle_rad) + (vv - cv) * np.sin(sc.gradient_angle_rad))
    span = np.abs(d).max() * 2 or 1.0
    lin = 1 - sc.gradient * (d / span + 0.5)
    r2 = ((uu - cu) ** 2 + (vv - cv) ** 2) / (cu ** 2 + cv ** 2)
    return (lin * (1 - sc.ring * r2)).astype(np.float32)


def _tweezer_polys(sc: Scene, u: float, v: float, frac: float) -> list[np.ndarray]:
    """Two dark prongs (1 mm wide, 1.2 mm apart) coming down from the top edge at 20 degrees.

    ``frac`` in 0..1: how far in they are (their tips cross the chip's centre at 0.5..1)."""
    w = 1.0 / sc.mm_per_px
    gap = 1.2 / sc.mm_per_px
    ang = np.radians(20)
    d = np.array([np.sin(ang), np.cos(ang)])       # down and a little to the right
    n = np.array([d[1], -d[0]])
    tip_v_end = v + 1.5 / sc.mm_per_px              # fully in: tips beyond the chip's centre
    start = -40.0
    tip_v = start + (tip_v_end - start) * frac
    tip = np.array([u + (tip_v - v) * d[0] / d[1], tip_v])
    polys = []
    for side in (-1, 1):
        c = tip + side * n * (gap / 2 + w / 2)
        back = c - d * (sc.height * 2)
        polys.append(np.array([c - n * w / 2, c + n * w / 2, back + n * w / 2, back - n * w / 2]))
    return polys


def render(sc: Scene) -> tuple[np.ndarray, Truth]:
    """Frames (n, H, W) uint8 and the truth."""
    rng = np.random.default_rng(sc.seed)
    t = sc.times()
    n = t.size
    u_w, v_w, h = chip_path(sc, t)
    jit = rng.uniform(-sc.jitter_px, sc.jitter_px, (n, 2)) if sc.jitter_px > 0 else np.zeros((n, 2))
    u, v = u_w + jit[:, 0], v_w + jit[:, 1]
    shape = (sc.height, sc.width)
    light = sc.level * illumination(sc)
    base = np.ones(shape, np.float32)
    if sc.mottling > 0:
        blobs = cv2.GaussianBlur(np.random.default_rng(sc.seed + 7).standard_normal(shape).astype(np.float32),
                                 (0, 0), 1.0 / sc.mm_per_px)
        base = base * (1 + sc.mottling * blobs / blobs.std())
    for (du, dv, a, b, ang, refl) in sc.dust:
        # an ellipse as a 64-gon: coverage rasterised like the chip
        phi = np.linspace(0, 2 * np.pi, 64, endpoint=False)
        c, s = np.cos(np.radians(ang)), np.sin(np.radians(ang))
        poly = np.column_stack([du + a * np.cos(phi) * c - b * np.sin(phi) * s,
                                dv + a * np.cos(phi) * s + b * np.sin(phi) * c])
        cov = coverage(shape, [poly])
        base = base * (1 - cov) + refl * cov
    flick = np.zeros(n)
    if sc.flicker > 0:
        flick = sc.flicker * (0.6 * np.sin(2 * np.pi * 100.0 * t + 0.7) + 0.4 * rng.uniform(-1, 1, n))
    polys = chip_polygons_mm()
    # the rasterised area of a whole chip (within 1 % of chip_area_mm2 / s^2)
    full_area = float(coverage((200 + int(6 / sc.mm_per_px),) * 2,
                               place(polys, 100 + 3 / sc.mm_per_px, 100 + 3 / sc.mm_per_px, 0.3,
                                     sc.mm_per_px)).sum())
    frames = np.empty((n, *shape), np.uint8)
    vis = np.zeros(n)
    tw_frames = np.zeros(n, bool)
    for k in range(n):
        cov = coverage(shape, place(polys, u[k], v[k], h[k], sc.mm_per_px))
        refl = base * (1 - cov) + sc.chip_reflectance * cov
        for (ou, ov, oh, osp) in sc.others:
            d = osp * (t[k] - t[0]) / sc.mm_per_px
            oc = coverage(shape, place(polys, ou - d * np.sin(oh), ov - d * np.cos(oh), oh, sc.mm_per_px))
            refl = refl * (1 - oc) + sc.chip_reflectance * oc
        seen = cov
        if sc.tweezers is not None and sc.tweezers[0] <= t[k] <= sc.tweezers[1]:
            t0, t1 = sc.tweezers
            ph = (t[k] - t0) / (t1 - t0)
            frac = min(1.0, 4 * ph, 4 * (1 - ph))     # in, hold, out
            # the prongs follow where the chip is at the middle of the crossing
            km = int(np.argmin(np.abs(t - (t0 + t1) / 2)))
            tcov = coverage(shape, _tweezer_polys(sc, u_w[km], v_w[km], frac))
            refl = refl * (1 - tcov) + 0.18 * tcov
            seen = cov * (1 - tcov)
            tw_frames[k] = tcov.max() > 0
        vis[k] = seen.sum() / full_area
        if sc.blur_px > 0:
            refl = cv2.GaussianBlur(refl, (0, 0), sc.blur_px)
        img = light * np.float32(1 + flick[k]) * refl
        if sc.noise > 0:
            img = img + rng.normal(0, sc.noise, shape).astype(np.float32)
        frames[k] = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    truth = Truth(t, u, v, h, vis, sc.speed_mm_s, sc.mm_per_px,
                  dust_px=[(d[0], d[1]) for d in sc.dust], tweezer_frames=tw_frames)
    return frames, truth


# ----------------------------------------------------------------------------- files
def write_avi(path: Path, frames: np.ndarray, fps: float, quality: int = 95) -> Path:
    """Motion-JPEG in AVI, the stereoscope cameras' usual file."""
    h, w = frames.shape[1:]
    vw = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*"MJPG"), float(fps), (w, h), False)
    assert vw.isOpened(), path
    vw.set(cv2.VIDEOWRITER_PROP_QUALITY, float(quality))
    for f in frames:
        vw.write(f)
    vw.release()
    return Path(path)


def write_mp4(path: Path, frames: np.ndarray, fps: float) -> Path:
    """MPEG-4 part 2 in MP4 (inter-frame compression, as consumer cameras write)."""
    h, w = frames.shape[1:]
    vw = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*"mp4v"), float(fps), (w, h), False)
    assert vw.isOpened(), path
    for f in frames:
        vw.write(f)
    vw.release()
    return Path(path)


def write_mkv(path: Path, frames: np.ndarray, t_s: np.ndarray, quality: int = 95) -> Path:
    """Matroska with each frame's own time (dropped frames): JPEG packets with a 1 ms time base."""
    h, w = frames.shape[1:]
    vw = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*"MJPG"), 1000.0, (w, h),
                         [cv2.VIDEOWRITER_PROP_RAW_VIDEO, 1])
    assert vw.isOpened(), path
    for f, t in zip(frames, t_s):
        ok, buf = cv2.imencode(".jpg", f, [cv2.IMWRITE_JPEG_QUALITY, quality])
        vw.set(cv2.VIDEOWRITER_PROP_PTS, float(round((t - t_s[0]) * 1000)))
        vw.write(buf.reshape(1, -1))
    vw.release()
    return Path(path)


def write_sequence(folder: Path, frames: np.ndarray, t_s: np.ndarray | None = None,
                   pattern: str = "frame_{:05d}.png") -> Path:
    """PNG files, and a ``timestamps.csv`` (frame file, t_s) beside them when ``t_s`` is given."""
    folder.mkdir(parents=True, exist_ok=True)
    names = []
    for k, f in enumerate(frames):
        name = pattern.format(k)
        cv2.imwrite(str(folder / name), f)
        names.append(name)
    if t_s is not None:
        with open(folder / "timestamps.csv", "w") as fh:
            fh.write("file,t_s\n")
            for name, t in zip(names, t_s):
                fh.write(f"{name},{t:.6f}\n")
    return folder


def truncate(path: Path, keep_frac_of_last: float = 0.4) -> int:
    """Cut an AVI inside its last frame's data (a camera or copy that stopped mid-write).

    Returns the new size in bytes."""
    data = path.read_bytes()
    # JPEG frames start with FF D8: cut partway into the last one
    last = data.rfind(b"\xff\xd8\xff")
    end = data.rfind(b"\xff\xd9")
    cut = last + int((end - last) * keep_frac_of_last)
    path.write_bytes(data[:cut])
    return cut
