"""Measuring the robot in one frame: threshold, component, coverage-weighted moments; the static scene.

Used by :mod:`analysis.tracking` (which explains the method); kept apart so each
module stays small. Coordinates: image ``u`` right, ``v`` down, pixel centres at
integers.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _otsu(hist: np.ndarray) -> tuple[int, float, float]:
    """Otsu threshold of a 256-bin histogram; returns (threshold, dark mean, light mean)."""
    p = hist.astype(np.float64).ravel()
    tot = p.sum()
    omega = np.cumsum(p)
    mu = np.cumsum(p * np.arange(256))
    with np.errstate(divide="ignore", invalid="ignore"):
        sb = (mu[-1] * omega - mu * tot) ** 2 / (omega * (tot - omega))
    sb[~np.isfinite(sb)] = -1
    k = int(np.argmax(sb))
    if sb[k] <= 0:
        return k, float("nan"), float("nan")
    return k, mu[k] / omega[k], (mu[-1] - mu[k]) / (tot - omega[k])


_KERNELS: dict[int, np.ndarray] = {}


def _square(r: int) -> np.ndarray:
    """A (2r+1)^2 square structuring element (separable, so dilation is cheap)."""
    if r not in _KERNELS:
        _KERNELS[r] = np.ones((2 * r + 1, 2 * r + 1), np.uint8)
    return _KERNELS[r]


@dataclass
class _Blob:
    u: float
    v: float
    theta: float          # image axis angle (rad), from +u towards +v, modulo pi
    area: float           # area of the dark component's outline (px)
    coverage: float       # weighted area (px)
    major_px: float       # sqrt(12 * variance along the axis): a rectangle's length
    minor_px: float
    border: bool          # cut by the ROI border
    weights: np.ndarray | None = None
    origin: tuple[int, int] = (0, 0)


class _Finder:
    """Find and measure the robot in one (ROI-cropped) grey frame."""

    def __init__(self, valid: np.ndarray | None, margin_px: int, min_contrast: float, min_area_px: int,
                 flat: np.ndarray | None = None):
        self.valid = None if valid is None else valid.astype(np.uint8)  # 0 = never the robot
        self.flat = flat  # background reflectance (float32, ~1), ROI-sized, or None
        self.margin = margin_px
        self.min_contrast = min_contrast
        self.min_area = min_area_px

    def find(self, img: np.ndarray, x0: int, y0: int, x1: int, y1: int, *, pred: tuple[float, float] | None,
             area_ref: float | None, keep_weights: bool = False) -> tuple[_Blob | None, bool]:
        """Search the window [x0:x1, y0:y1]; returns (blob or None, touched the window's edge)."""
        import cv2

        win = img[y0:y1, x0:x1]
        vmask = None if self.valid is None else self.valid[y0:y1, x0:x1]
        # Otsu on every other pixel: the histogram's shape, at a quarter of the cost
        sub = win[::2, ::2]
        hist = np.bincount(sub[vmask[::2, ::2] > 0] if vmask is not None else sub.ravel(), minlength=256)
        thr, dark, light = _otsu(hist)
        if not np.isfinite(dark) or (light - dark) < self.min_contrast * light:
            return None, False
        binary = (win <= thr).astype(np.uint8)
        if vmask is not None:
            binary &= vmask
        contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cands = []
        for c in contours:
            if len(c) < 4:
                continue
            a = cv2.contourArea(c)
            if a < self.min_area or (area_ref and not 0.45 * area_ref < a < 1.7 * area_ref):
                continue
            bx, by, bw, bh = cv2.boundingRect(c)
            cands.append((a, bx + bw / 2, by + bh / 2, c, (bx, by, bw, bh)))
        if not cands:
            return None, False
        if pred is not None:
            score = [np.hypot(cx + x0 - pred[0], cy + y0 - pred[1])
                     + (20.0 * abs(np.log(a / area_ref)) if area_ref else 0.0) for a, cx, cy, _, _ in cands]
        elif area_ref:
            score = [abs(np.log(a / area_ref)) for a, *_ in cands]
        else:
            score = [-a for a, *_ in cands]
        area, _, _, contour, (bx, by, bw, bh) = cands[int(np.argmin(score))]
        h, w = win.shape
        touched = bx == 0 or by == 0 or bx + bw == w or by + bh == h
        H, W = img.shape
        border = bx + x0 == 0 or by + y0 == 0 or bx + bw + x0 == W or by + bh + y0 == H
        # measure in the component's box grown by the band and the background ring
        g = self.margin + 4
        cx0, cy0 = max(bx - g, 0), max(by - g, 0)
        cx1, cy1 = min(bx + bw + g, w), min(by + bh + g, h)
        comp = np.zeros((cy1 - cy0, cx1 - cx0), np.uint8)
        cv2.drawContours(comp, [contour], -1, 1, thickness=-1, offset=(-cx0, -cy0))
        flat = None if self.flat is None else self.flat[y0 + cy0:y0 + cy1, x0 + cx0:x0 + cx1]
        blob = self._measure(win[cy0:cy1, cx0:cx1], comp, binary[cy0:cy1, cx0:cx1],
                             None if vmask is None else vmask[cy0:cy1, cx0:cx1], keep_weights, flat)
        if blob is None:
            return None, bool(touched)
        ox, oy = x0 + cx0, y0 + cy0
        blob.u += ox
        blob.v += oy
        blob.origin = (ox, oy)
        blob.area = float(area)
        blob.border = bool(border)
        return blob, bool(touched and not border)

    def _measure(self, win: np.ndarray, comp: np.ndarray, binary: np.ndarray, vmask: np.ndarray | None,
                 keep_weights: bool, flat: np.ndarray | None = None) -> _Blob | None:
        import cv2

        m = self.margin
        band = cv2.dilate(comp, _square(m))
        outer = cv2.dilate(comp, _square(m + 3))
        others = binary & (1 - comp)
        if others.any():
            band &= 1 - others
            ring = outer & (1 - band) & (1 - cv2.dilate(others, _square(m)))
        else:
            ring = outer & (1 - band)
        if vmask is not None:
            band &= vmask
            ring &= vmask
        f = win.astype(np.float32)
        if flat is not None:
            f /= flat   # flat-field: divides out the Teflon's texture
        # background under the robot: least-squares plane through the ring around it
        # (lighting gradients), from the ring's moments: no pixel lists needed
        mr = cv2.moments(ring, binaryImage=True)
        if mr["m00"] < 12:
            return None
        mf = cv2.moments(f * ring)
        n, su, sv = mr["m00"], mr["m10"], mr["m01"]
        ata = np.array([[n, su, sv], [su, mr["m20"], mr["m11"]], [sv, mr["m11"], mr["m02"]]])
        atb = np.array([mf["m00"], mf["m10"], mf["m01"]])
        # a plane only when the ring surrounds the robot; a ring cut on one side (the tray's rim,
        # the frame's edge) would let the slope extrapolate freely over the robot: a constant then
        mc = cv2.moments(comp, binaryImage=True)
        off = np.hypot(su / n - mc["m10"] / max(mc["m00"], 1), sv / n - mc["m01"] / max(mc["m00"], 1))
        spread = np.sqrt(max((mr["mu20"] + mr["mu02"]) / n, 1e-9))
        coef = np.array([mf["m00"] / n, 0.0, 0.0])
        if off < 0.1 * spread:
            try:
                coef = np.linalg.solve(ata, atb)
            except np.linalg.LinAlgError:
                pass
        hh, ww = win.shape
        uu = np.arange(ww, dtype=np.float32)
        vv = np.arange(hh, dtype=np.float32)
        bg = np.float32(coef[0]) + np.float32(coef[1]) * uu[None, :] + np.float32(coef[2]) * vv[:, None]
        ratio = f / np.maximum(bg, np.float32(1.0))
        inner = cv2.erode(comp, _square(2))
        if cv2.countNonZero(inner) < 5:
            inner = comp
        rho = float(cv2.mean(ratio, mask=inner)[0])
        if rho > 0.9:
            return None
        # weight = darkness / the robot's darkness = area coverage of each pixel (1 inside)
        w = np.clip((1.0 - ratio) * np.float32(1.0 / (1.0 - rho)), -0.5, 1.5)
        w *= band
        mo = cv2.moments(w)
        if mo["m00"] <= 0:
            return None
        cu, cv_ = mo["m10"] / mo["m00"], mo["m01"] / mo["m00"]
        a, b, c = mo["mu20"] / mo["m00"], mo["mu02"] / mo["m00"], mo["mu11"] / mo["m00"]
        theta = 0.5 * np.arctan2(2 * c, a - b)
        common = np.sqrt(((a - b) / 2) ** 2 + c ** 2)
        lam1, lam2 = (a + b) / 2 + common, max((a + b) / 2 - common, 0.0)
        return _Blob(cu, cv_, theta, 0.0, mo["m00"], float(np.sqrt(12 * lam1)), float(np.sqrt(12 * lam2)),
                     False, w if keep_weights else None)


def body_length_px(weights: np.ndarray, cu: float, cv_: float, theta: float) -> float:
    """The body's end-to-end length (px) from its darkness profile along the long axis.

    The weights are projected onto the axis; the ends are where the profile falls
    to half its level near the ends (a symmetric blur leaves that crossing in
    place). The leg stubs stick out of the long sides, not the ends, so they do not
    move it.
    """
    vv, uu = np.nonzero(weights != 0)
    wt = weights[vv, uu].astype(np.float64)
    s = (uu - cu) * np.cos(theta) + (vv - cv_) * np.sin(theta)
    binw = 0.5
    lo = np.floor(s.min() / binw) - 2
    idx = (np.floor(s / binw) - lo).astype(int)
    prof = np.bincount(idx, wt, minlength=idx.max() + 3) / binw
    prof = np.convolve(prof, np.ones(3) / 3, mode="same")
    centres = (np.arange(prof.size) + lo + 0.5) * binw
    half_len = 0.5 * float(np.ptp(centres[prof > 0.5 * prof.max()]))
    ends = []
    for sign in (1, -1):
        # just inside the end, clear of the leg stubs (at 0.68 of the half length)
        sel = (sign * centres > 0.76 * half_len) & (sign * centres < 0.9 * half_len)
        if sel.sum() < 3:
            return float("nan")
        level = np.median(prof[sel])
        order = np.argsort(sign * centres)
        c_sorted, p_sorted = sign * centres[order], prof[order]
        beyond = np.flatnonzero((c_sorted > 0.9 * half_len) & (p_sorted < 0.5 * level))
        if beyond.size == 0:
            return float("nan")
        j = beyond[0]
        # linear interpolation of the half-level crossing between bins j-1 and j
        p0, p1 = p_sorted[j - 1], p_sorted[j]
        frac = (p0 - 0.5 * level) / (p0 - p1) if p0 != p1 else 0.5
        ends.append(c_sorted[j - 1] + frac * (c_sorted[j] - c_sorted[j - 1]))
    return float(ends[0] + ends[1])


# ----------------------------------------------------------------------------- static structure
def background_model(samples: list[np.ndarray], dark_ratio: float = 0.6, grow_px: int = 8
                     ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Static structure from frames spread over the video: ``(rim mask, flat field)``.

    Each frame is normalised by its Teflon's level (lighting drift). The per-pixel
    maximum removes the moving (dark) robot: dark structure left in it that
    reaches the frame's border is the tray's rim, returned as a mask (only
    border-connected structure, so a robot that sits still is never masked
    away). The flat field is the Teflon's own reflectance (texture, scratches,
    vignetting), which the tracker divides out: the per-pixel mean over the
    samples of the pixels that are not dark nor within ``grow_px`` of dark
    (the robot and its blurred edge); where every sample is dark there, 1 (no
    correction).
    """
    import cv2

    if len(samples) < 5:
        return None, None
    h, w = samples[0].shape
    norms = []
    for s in samples:
        # normalise by the median of the Teflon alone (pixels > 0.75 x its bright end): a median
        # of the whole frame would shift with how much robot and rim the frame shows
        sub = s[::4, ::4]
        level = float(np.median(sub[sub > 0.75 * np.percentile(sub, 99)]))
        norms.append(s.astype(np.float32) * np.float32(1.0 / max(level, 1.0)))
    peak = np.max(norms, axis=0)
    dark = (peak < dark_ratio).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(dark, connectivity=8)
    rim = np.zeros((h, w), bool)
    for i in range(1, n):
        x, y, bw, bh, _a = stats[i]
        if x == 0 or y == 0 or x + bw == w or y + bh == h:
            rim |= labels == i
    # flat field: mean over the samples of each pixel while it is clear of the robot (and of
    # its blurred edge); the rim is static, so the Teflon right beside it counts as clear
    total = np.zeros((h, w), np.float32)
    count = np.zeros((h, w), np.float32)
    grow = _square(grow_px)
    for norm in norms:
        robot = ((norm < dark_ratio) & ~rim).view(np.uint8)
        clear = 1 - cv2.dilate(robot, grow)
        total += norm * clear
        count += clear
    flat = np.ones((h, w), np.float32)
    np.divide(total, count, out=flat, where=count > 0)
    flat[rim | (flat < dark_ratio)] = 1.0
    # grow the rim by 1 px so its own anti-aliased edge cannot bridge robot and rim
    return (cv2.dilate(rim.view(np.uint8), _square(1)).astype(bool) if rim.any() else None), flat
