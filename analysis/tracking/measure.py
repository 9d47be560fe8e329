"""Measuring the robot in one frame: threshold, component, coverage-weighted moments; the static scene.

Used by :mod:`labkit.analysis.tracking.tracker` (which explains the method); kept apart so each
module stays small. Coordinates: image ``u`` right, ``v`` down, pixel centres at
integers.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

_LEVELS = np.arange(256, dtype=np.float64)


def _otsu(hist: np.ndarray) -> tuple[int, float, float]:
    """Otsu threshold of a 256-bin histogram; returns (threshold, dark mean, light mean)."""
    p = hist.astype(np.float64).ravel()
    tot = p.sum()
    omega = np.cumsum(p)
    mu = np.cumsum(p * _LEVELS)
    denom = omega * (tot - omega)
    sb = np.full(256, -1.0)
    np.divide((mu[-1] * omega - mu * tot) ** 2, denom, out=sb, where=denom > 0)   # one class empty: -1
    k = int(np.argmax(sb))
    if sb[k] <= 0:
        return k, float("nan"), float("nan")
    return k, mu[k] / omega[k], (mu[-1] - mu[k]) / (tot - omega[k])


def small_median(values, axis: int | None = None):
    """``np.median`` of a short array (the tracker's recent areas, outlines, a profile's bins) by one
    sort: the same value at a tenth of numpy's per-call overhead (~12 us). No NaNs expected."""
    s = np.sort(np.asarray(values, np.float64), axis=axis)
    if axis is None:
        s = s.ravel()
    n = s.shape[0]
    m = n // 2
    return s[m] if n % 2 else 0.5 * (s[m - 1] + s[m])


def _at_least(a: np.ndarray, floor: float) -> np.ndarray:
    """``a`` (float32, contiguous) raised to ``floor`` in place: OpenCV's clamp takes under half of
    ``np.maximum``'s time (5.6 vs 13 us on a 180 x 180 window; no NaN handling, none expected)."""
    import cv2

    cv2.max(a, floor, dst=a)  # type: ignore[call-overload]  # cv2's stubs omit the scalar overload
    return a


_KERNELS: dict[int, np.ndarray] = {}


def _dilate(img: np.ndarray, r: int) -> np.ndarray:
    """Grey/binary dilation by a (2r+1)^2 square, as uint8 (typed for mypy: cv2's stubs are loose)."""
    import cv2

    return np.asarray(cv2.dilate(img, _square(r)), np.uint8)


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
    contrast: float = float("nan")   # (tray - robot) / tray, measured inside the body
    masked: bool = False             # its band reaches a never-search region (static dust, the rim)
    # the centroid without the static scene's brightness model (flat field and texture): how much
    # the lighting model moves the position (the illumination part of the speed's error budget)
    u_alt: float = float("nan")
    v_alt: float = float("nan")


def smooth_background(win: np.ndarray, cell_px: int, kernel_cells: int) -> np.ndarray:
    """The tray's smooth brightness under a window (float32, the window's shape).

    The window is averaged down to cells of ``cell_px`` (sensor noise and texture
    fall by ``cell_px``), closed (a grey maximum then minimum filter of
    ``kernel_cells`` cells, wider than the chip: a dark object narrower than the
    kernel vanishes, a smooth gradient stays as it is) and interpolated back.
    Dividing a frame by it removes the ring light's unevenness and a frame's
    flicker without knowing either.
    """
    import cv2

    h, w = win.shape
    r = max(kernel_cells // 2, 1)
    sh, sw = h // cell_px, w // cell_px
    if sh < 1 or sw < 1:
        sh, sw = max(int(round(h / cell_px)), 1), max(int(round(w / cell_px)), 1)
        coarse = cv2.resize(win, (sw, sh), interpolation=cv2.INTER_AREA).astype(np.float32)
        return cv2.resize(cv2.morphologyEx(coarse, cv2.MORPH_CLOSE, _square(r)), (w, h), interpolation=cv2.INTER_LINEAR)
    # whole cells from the top-left corner: OpenCV's area averaging by a whole factor is ten times
    # faster than by a fractional one (0.07 vs 0.77 ms for a 520 x 520 window); the rows and columns
    # past the last whole cell (fewer than a cell) take the edge cells' level, as they would beyond
    # the last cell's centre anyway
    cells = cv2.resize(win[:sh * cell_px, :sw * cell_px], (sw, sh), interpolation=cv2.INTER_AREA)
    closed = cv2.morphologyEx(np.asarray(cells, np.float32), cv2.MORPH_CLOSE, _square(r))
    bg = cv2.resize(closed, (sw * cell_px, sh * cell_px), interpolation=cv2.INTER_LINEAR)
    if bg.shape == (h, w):
        return bg
    return cv2.copyMakeBorder(bg, 0, h - bg.shape[0], 0, w - bg.shape[1], cv2.BORDER_REPLICATE)


@dataclass
class Segmentation:
    """How dark objects are told from the tray (see :func:`smooth_background`)."""

    cell_px: int
    kernel_cells: int
    min_contrast: float            # (tray - object) / tray a robot must have
    noise: float = float("nan")    # the tray's pixel noise, relative to its level
    auto: bool = True              # min_contrast derived from the noise
    body_width_px: float = 40.0    # the chip's expected width (or a guess from the frame's size)

    @classmethod
    def for_frame(cls, width: int, height: int, body_width_px: float | None, min_contrast: float | None,
                  noise: float = float("nan")) -> Segmentation:
        # kernel: wider than the chip with its legs (about 1.5 body widths), else a sixth of the frame
        k_px = 1.8 * body_width_px if body_width_px else max(min(width, height) / 6, 24)
        cell = max(int(k_px // 6), 2)
        kernel = max(int(np.ceil(k_px / cell)) | 1, 3)
        auto = min_contrast is None
        if min_contrast is None:
            # 5 noise sigmas of one pixel: the mean of a chip-sized object is then far beyond noise
            mc = max(5 * noise, 0.04) if np.isfinite(noise) else 0.08
        else:
            mc = float(min_contrast)
        return cls(cell, kernel, float(mc), float(noise), auto, k_px / 1.8)

    def ratio(self, win: np.ndarray, flat: np.ndarray | None = None) -> np.ndarray:
        """The window relative to the tray's local level (1 = tray, the chip's reflectance inside)."""
        f = win.astype(np.float32)
        if flat is not None:
            f /= flat
        bg = smooth_background(f, self.cell_px, self.kernel_cells)
        _at_least(bg, 1.0)
        return np.divide(f, bg, out=f)       # in place: no per-frame temporaries


class _Finder:
    """Find and measure the robot in one (ROI-cropped) grey frame."""

    def __init__(self, valid: np.ndarray | None, margin_px: int, seg: Segmentation, min_area_px: int,
                 flat: np.ndarray | None = None):
        self.valid = None if valid is None else valid.astype(np.uint8)  # 0 = never the robot
        self.flat = flat  # the static scene's brightness (float32, ~1), ROI-sized, or None
        # its fine part (the tray's texture, without the ring light's smooth shape): the robot is
        # opaque, so its brightness follows the light but not the tray's texture under it
        self.tex: np.ndarray | None = None
        if flat is not None:
            # the smooth part from the searchable tray only (the rim and dust would darken it beside them)
            known = np.ones(flat.shape, np.float32) if valid is None else valid.astype(np.float32)
            sig = max(2.5 * seg.body_width_px, 8.0)
            smooth = _wide_blur(flat * known, sig) / np.maximum(_wide_blur(known, sig), np.float32(1e-3))
            tex = flat / np.maximum(smooth, np.float32(1e-3))
            if valid is not None:
                tex[~valid.astype(bool)] = 1.0
            self.tex = np.asarray(tex, np.float32)
        self.margin = margin_px
        self.seg = seg
        self.min_area = min_area_px
        self.best_contrast = 0.0     # the strongest dark object's contrast seen (for messages)
        self.ambiguous = 0           # searches with more than one robot-like candidate

    def find(self, img: np.ndarray, x0: int, y0: int, x1: int, y1: int, *, pred: tuple[float, float] | None,
             area_ref: float | None, keep_weights: bool = False, gate_px: float | None = None,
             area_tol: tuple[float, float] = (0.45, 1.7), alt: bool = True) -> tuple[_Blob | None, bool]:
        """Search the window [x0:x1, y0:y1]; returns (blob or None, touched the window's edge).

        ``gate_px``: a candidate farther than this from ``pred`` is not the robot
        (a jump no robot makes between two frames). ``alt``: also measure it without the flat
        field (``u_alt``, ``v_alt``; NaN otherwise)."""
        import cv2

        flat = None if self.flat is None else self.flat[y0:y1, x0:x1]
        ratio = self.seg.ratio(img[y0:y1, x0:x1], flat)
        # 8-bit copy for the histogram and the threshold (200 = the tray)
        q = cv2.convertScaleAbs(ratio, alpha=200.0)
        vmask = None if self.valid is None else self.valid[y0:y1, x0:x1]
        # Otsu on every other pixel: the histogram's shape, at a quarter of the cost
        hist = cv2.calcHist([q[::2, ::2]], [0], None if vmask is None else vmask[::2, ::2], [256], [0, 256]).ravel()
        thr, dark, light = _otsu(hist)
        if not np.isfinite(dark) or light <= 0:
            return None, False
        contrast = (light - dark) / light
        self.best_contrast = max(self.best_contrast, float(contrast))
        if contrast < self.seg.min_contrast:
            return None, False
        binary = cv2.threshold(q, thr, 1, cv2.THRESH_BINARY_INV)[1]     # q <= thr, as uint8 0/1
        if vmask is not None:
            cv2.bitwise_and(binary, vmask, dst=binary)
        contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        lo, hi = area_tol
        cands = []
        for c in contours:
            if len(c) < 4:
                continue
            a = cv2.contourArea(c)
            if a < self.min_area or (area_ref and not lo * area_ref < a < hi * area_ref):
                continue
            bx, by, bw, bh = cv2.boundingRect(c)
            cx, cy = bx + bw / 2 + x0, by + bh / 2 + y0
            if pred is not None and gate_px is not None and np.hypot(cx - pred[0], cy - pred[1]) > gate_px:
                continue
            if pred is None:
                # acquisition: an elongated object (the chip is 5 x 2 mm), not a round speck or a long prong
                m = cv2.moments(c)
                if m["m00"] > 0:
                    a20, a02, a11 = m["mu20"] / m["m00"], m["mu02"] / m["m00"], m["mu11"] / m["m00"]
                    com = np.sqrt(((a20 - a02) / 2) ** 2 + a11 ** 2)
                    l1, l2 = (a20 + a02) / 2 + com, max((a20 + a02) / 2 - com, 1e-9)
                    touches = bx == 0 or by == 0 or bx + bw == x1 - x0 or by + bh == y1 - y0
                    if not touches and not 1.4 < np.sqrt(l1 / l2) < 5.0:
                        continue
            cands.append((a, cx - x0, cy - y0, c, (bx, by, bw, bh)))
        if not cands:
            return None, False
        if pred is not None:
            score = [np.hypot(cx + x0 - pred[0], cy + y0 - pred[1])
                     + (20.0 * abs(np.log(a / area_ref)) if area_ref else 0.0) for a, cx, cy, _, _ in cands]
        elif area_ref:
            score = [abs(np.log(a / area_ref)) for a, *_ in cands]
        else:
            score = [-a for a, *_ in cands]
        order = np.argsort(score)
        if len(cands) > 1 and area_ref:
            # a second candidate of the robot's size within reach: the choice may be wrong
            a2 = cands[int(order[1])][0]
            if 0.8 < a2 / area_ref < 1.25:
                self.ambiguous += 1
        area, _, _, contour, (bx, by, bw, bh) = cands[int(order[0])]
        h, w = ratio.shape
        touched = bx == 0 or by == 0 or bx + bw == w or by + bh == h
        H, W = img.shape
        border = bx + x0 == 0 or by + y0 == 0 or bx + bw + x0 == W or by + bh + y0 == H
        # measure in the component's box grown by the band and the background ring
        g = self.margin + 4
        cx0, cy0 = max(bx - g, 0), max(by - g, 0)
        cx1, cy1 = min(bx + bw + g, w), min(by + bh + g, h)
        comp = np.zeros((cy1 - cy0, cx1 - cx0), np.uint8)
        cv2.drawContours(comp, [contour], -1, 1, thickness=-1, offset=(-cx0, -cy0))
        sub_v = None if vmask is None else vmask[cy0:cy1, cx0:cx1]
        blob = self._measure(ratio[cy0:cy1, cx0:cx1], comp, binary[cy0:cy1, cx0:cx1], sub_v, keep_weights,
                             None if self.tex is None else self.tex[y0 + cy0:y0 + cy1, x0 + cx0:x0 + cx1])
        if blob is None:
            return None, bool(touched)
        ox, oy = x0 + cx0, y0 + cy0
        blob.u_alt, blob.v_alt = (blob.u, blob.v) if alt else (np.nan, np.nan)
        if flat is not None and alt:
            # the same robot measured without the flat field (its division undone, no texture)
            other = self._measure(ratio[cy0:cy1, cx0:cx1] * flat[cy0:cy1, cx0:cx1], comp,
                                  binary[cy0:cy1, cx0:cx1], sub_v, False, None)
            if other is not None:
                blob.u_alt, blob.v_alt = other.u, other.v
        blob.u += ox
        blob.v += oy
        blob.u_alt += ox
        blob.v_alt += oy
        blob.origin = (ox, oy)
        blob.area = float(area)
        blob.border = bool(border)
        return blob, bool(touched and not border)

    def _measure(self, win: np.ndarray, comp: np.ndarray, binary: np.ndarray, vmask: np.ndarray | None,
                 keep_weights: bool, tex: np.ndarray | None = None) -> _Blob | None:
        import cv2

        m = self.margin
        band = _dilate(comp, m)
        outer = _dilate(comp, m + 3)
        others = np.asarray(binary & (1 - comp), np.uint8)
        if others.any():
            band &= 1 - others
            ring = outer & (1 - band) & (1 - _dilate(others, m))
        else:
            ring = outer & (1 - band)
        masked = False
        if vmask is not None:
            masked = bool(np.any(band & (1 - vmask)))    # part of the robot's band is never-search (dust, rim)
            band &= vmask
            ring &= vmask
        f = np.asarray(win, np.float32)    # read only here: no copy
        # background under the robot: least-squares plane through the ring around it
        # (lighting gradients), from the ring's moments: no pixel lists needed
        mr = cv2.moments(ring)      # 0/1 images: their plain moments are the binary ones, at half the cost
        if mr["m00"] < 12:
            return None
        mf = cv2.moments(f * ring)
        n, su, sv = mr["m00"], mr["m10"], mr["m01"]
        ata = np.array([[n, su, sv], [su, mr["m20"], mr["m11"]], [sv, mr["m11"], mr["m02"]]])
        atb = np.array([mf["m00"], mf["m10"], mf["m01"]])
        # a plane only when the ring surrounds the robot; a ring cut on one side (the tray's rim,
        # the frame's edge) would let the slope extrapolate freely over the robot: a constant then
        mc = cv2.moments(comp)
        off = np.hypot(su / n - mc["m10"] / max(mc["m00"], 1), sv / n - mc["m01"] / max(mc["m00"], 1))
        spread = np.sqrt(max((mr["mu20"] + mr["mu02"]) / n, 1e-9))
        coef = np.array([mf["m00"] / n, 0.0, 0.0])
        if off < 0.1 * spread:
            solved, sol = cv2.solve(ata, atb.reshape(3, 1), flags=cv2.DECOMP_LU)   # numpy's costs 10x more
            if solved:
                coef = sol.ravel()
        hh, ww = win.shape
        uu = np.arange(ww, dtype=np.float32)
        vv = np.arange(hh, dtype=np.float32)
        ratio = np.add.outer(np.float32(coef[2]) * vv + np.float32(coef[0]), np.float32(coef[1]) * uu)
        _at_least(ratio, 1e-3)
        np.divide(f, ratio, out=ratio)      # the window over the background plane
        inner = cv2.erode(comp, _square(2))
        if cv2.countNonZero(inner) < 5:
            inner = comp
        if tex is None:
            rho = float(cv2.mean(ratio, mask=inner)[0])
            if 1.0 - rho < 0.5 * self.seg.min_contrast:
                return None
            # weight = darkness / the robot's darkness = area coverage of each pixel (1 inside)
            w = np.clip((1.0 - ratio) * np.float32(1.0 / (1.0 - rho)), -0.5, 1.5)
        else:
            # ratio = I / (light x texture); the robot's own level, relative to the light alone, is
            # rho = mean(ratio x texture) inside it, so a pixel covered by a share c of robot shows
            # 1 - ratio = c (1 - rho / texture): the weight divides by that, pixel by pixel
            rho = float(cv2.mean(ratio * tex, mask=inner)[0])
            if 1.0 - rho < 0.5 * self.seg.min_contrast:
                return None
            denom = _at_least(tex.copy(), 1e-3)
            np.divide(np.float32(-rho), denom, out=denom)
            denom += np.float32(1.0)
            _at_least(denom, 1e-3)
            w = np.subtract(np.float32(1.0), ratio, out=ratio)
            w /= denom
            np.clip(w, -0.5, 1.5, out=w)
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
                     False, w if keep_weights else None, contrast=1.0 - rho, masked=masked)


def body_length_px(weights: np.ndarray, cu: float, cv_: float, theta: float) -> float:
    """The body's end-to-end length (px) from its darkness profile along the long axis.

    The weights are projected onto the axis; the ends are where the profile falls
    to half its level near the ends (a symmetric blur leaves that crossing in
    place). The leg stubs stick out of the long sides, not the ends, so they do not
    move it.
    """
    vv, uu = np.nonzero(weights)
    wt = np.tile(weights[vv, uu].astype(np.float64) / 4, 4)
    # each pixel as four quarter-pixel samples: along an image axis the centres alone would
    # project onto whole pixels only, leaving every other half-pixel bin empty (a -4 % length)
    c, sn = np.cos(theta), np.sin(theta)
    binw = 0.5
    # positions in bins, in float32 (1e-5 px over the chip's length, far below a bin), floored in place
    s0 = ((uu.astype(np.float32) - np.float32(cu)) * np.float32(c / binw)
          + (vv.astype(np.float32) - np.float32(cv_)) * np.float32(sn / binw))
    n = s0.size
    s = np.empty(4 * n, np.float32)
    for i, (du, dv) in enumerate(((-1, -1), (1, -1), (-1, 1), (1, 1))):
        np.add(s0, np.float32(0.25 * (du * c + dv * sn) / binw), out=s[i * n:(i + 1) * n])
    np.floor(s, out=s)
    lo = float(s.min()) - 2
    idx = (s - np.float32(lo)).astype(np.intp)
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
        level = small_median(prof[sel])
        c_sorted, p_sorted = sign * centres[::sign], prof[::sign]    # centres increase: sorted by slicing
        beyond = np.flatnonzero((c_sorted > 0.9 * half_len) & (p_sorted < 0.5 * level))
        if beyond.size == 0:
            return float("nan")
        j = beyond[0]
        # linear interpolation of the half-level crossing between bins j-1 and j
        p0, p1 = p_sorted[j - 1], p_sorted[j]
        frac = (p0 - 0.5 * level) / (p0 - p1) if p0 != p1 else 0.5
        ends.append(c_sorted[j - 1] + frac * (c_sorted[j] - c_sorted[j - 1]))
    return float(ends[0] + ends[1])


def _wide_blur(img: np.ndarray, sigma: float) -> np.ndarray:
    """A Gaussian blur of a wide ``sigma``, computed on a grid ``sigma / 4`` coarser and interpolated back."""
    import cv2

    h, w = img.shape
    f = max(int(sigma // 4), 1)
    if f == 1:
        return np.asarray(cv2.GaussianBlur(img, (0, 0), sigma))
    small = cv2.resize(img, (max(w // f, 1), max(h // f, 1)), interpolation=cv2.INTER_AREA)
    return np.asarray(cv2.resize(cv2.GaussianBlur(small, (0, 0), sigma / f), (w, h), interpolation=cv2.INTER_LINEAR))


# ----------------------------------------------------------------------------- static structure
@dataclass
class StaticScene:
    """What does not move over the video, from frames spread over it (:func:`background_model`)."""

    rim: np.ndarray | None            # dark structure reaching the border (the tray's wall), grown 1 px
    flat: np.ndarray | None           # the static scene's brightness (float32, ~1), divided out first
    noise: float                      # pixel noise relative to the tray's level
    objects: np.ndarray | None        # static dark objects inside the frame (dust), grown by a margin
    object_boxes: list[tuple[int, int, int, int]]   # (x, y, w, h) of each static object
    samples: int = 0
    overlays: np.ndarray | None = None  # burnt-in text (timestamps, a scale bar's label), grown by a margin
    overlay_boxes: list[tuple[int, int, int, int]] = field(default_factory=list)


def background_model(samples: list[np.ndarray], seg: Segmentation | None = None, grow_px: int = 8,
                     dark_ratio: float = 0.6) -> StaticScene:
    """Static structure from frames spread over the video (in time order).

    Each sample is divided by its own smooth background (:func:`smooth_background`:
    the ring light's unevenness and the frame's flicker go). Then:

    * ``noise``: the pixel noise, from the difference of two samples where both
      show bare tray (the tray's texture cancels in it), as a robust sigma;
    * dark = darker than the tray by more than the segmentation's contrast
      threshold (or 6 noise sigmas while that is not known);
    * dark in *every* sample and reaching the frame's border: the tray's rim,
      masked (a robot touching it must not merge with it) (:func:`_rim`);
    * dark in every sample inside the frame, robot-sized and clearly dark, not
      moving and with the tray around it rarely dark: a static object (dust, a
      scratch), masked (:func:`static_objects`). A robot that moves even a few
      pixels over the clip is never taken for dust;
    * the flat field is the static scene's brightness (ring light, texture,
      rim, dust), relative to its median (:func:`_flat_field`). Dividing a
      frame by it leaves only what moves.
    """
    if len(samples) < 5:
        return StaticScene(None, None, float("nan"), None, [], len(samples))
    h, w = samples[0].shape
    if seg is None:
        seg = Segmentation.for_frame(w, h, None, None)
    if h * w >= DECIMATE_FROM_PX and seg.body_width_px >= 32:
        return _decimated_model(samples, seg, grow_px, dark_ratio)
    rim = _rim(samples, dark_ratio)
    rim_g = _dilate(rim.view(np.uint8), grow_px) if rim.any() else np.zeros((h, w), np.uint8)
    # smaller things relative to the local tray (smooth background: ring light, flicker)
    ratios = [seg.ratio(s) for s in samples]
    noise = _pixel_noise(ratios[0], ratios[len(ratios) // 2])
    thr = seg.min_contrast if not seg.auto else max(6 * noise, 0.04)
    rim_keep = np.asarray(1 - rim_g, np.uint8)
    objects, boxes = static_objects(ratios, thr, seg.body_width_px, rim_keep)
    ov_m, ov_boxes = burnt_in_overlays(ratios, thr, seg.body_width_px, rim_keep)
    static = rim | (objects > 0) | (ov_m if ov_m is not None else False)
    # what moves is judged at a higher darkness than the noise (texture dimples are static and must
    # stay in the flat field; a robot's blurred edge below it is covered by the growth)
    thr_b = max(thr, min(0.12, 0.5 * (seg.min_contrast if not seg.auto else 0.24)))
    flat = _flat_field(samples, ratios, static, rim, FlatSettings(thr_b, grow_px, seg.body_width_px))
    rim_m = _dilate(rim.view(np.uint8), 1).astype(bool) if rim.any() else None
    # static objects grown by the measuring band, so the robot passing by is cut off them
    obj_m = _dilate(objects, 3).astype(bool) if boxes else None
    return StaticScene(rim_m, flat, noise, obj_m, boxes, len(samples), ov_m, ov_boxes)


DECIMATE_FROM_PX = 300_000   # frames from 640 x 480 up, with a body >= 32 px wide, are modelled at half resolution


def _decimated_model(samples: list[np.ndarray], seg: Segmentation, grow_px: int, dark_ratio: float) -> StaticScene:
    """:func:`background_model` of a large frame (a body >= 32 px wide), computed on the samples halved
    (2 x 2 pixel means) and brought back to full size: the static structure is several pixels wide and
    the flat field smooth at that scale, at a quarter of the cost. The rim and the pixel noise are
    measured at full resolution (halving would move the rim's edge and average the noise down)."""
    import cv2

    h, w = samples[0].shape
    half = [np.asarray(cv2.resize(s, (w // 2, h // 2), interpolation=cv2.INTER_AREA)) for s in samples]
    seg_h = Segmentation.for_frame(w // 2, h // 2, seg.body_width_px / 2, None if seg.auto else seg.min_contrast)
    sc = background_model(half, seg_h, max(grow_px // 2, 1), dark_ratio)

    def up(m: np.ndarray | None) -> np.ndarray | None:
        if m is None:
            return None
        return np.asarray(cv2.resize(m.view(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST), bool)

    sc.noise = _pixel_noise(seg.ratio(samples[0]), seg.ratio(samples[len(samples) // 2]))
    rim = _rim(samples, dark_ratio)     # the rim's edge to the pixel: a robot walks along it
    sc.rim = _dilate(rim.view(np.uint8), 1).astype(bool) if rim.any() else None
    sc.objects, sc.overlays = up(sc.objects), up(sc.overlays)
    if sc.flat is not None:
        sc.flat = np.asarray(cv2.resize(sc.flat, (w, h), interpolation=cv2.INTER_LINEAR), np.float32)
    sc.object_boxes = [(2 * x, 2 * y, 2 * bw, 2 * bh) for x, y, bw, bh in sc.object_boxes]
    sc.overlay_boxes = [(2 * x, 2 * y, 2 * bw, 2 * bh) for x, y, bw, bh in sc.overlay_boxes]
    return sc


def _tray_level(sub: np.ndarray) -> float:
    """The bright tray's level of a (sub-sampled) frame: the median of the pixels brighter than 0.75
    of its 99th percentile. An 8-bit frame's order statistics come from its histogram (one pass,
    no sort: the same values as ``np.percentile`` and ``np.median``, at a tenth of their cost)."""
    if sub.dtype != np.uint8:
        return float(np.median(sub[sub > 0.75 * np.percentile(sub, 99)]))
    cum = np.cumsum(np.bincount(sub.ravel(), minlength=256))

    def kth(k: int, lo: int = 0) -> float:
        # the k-th smallest (from 0) of the values above ``lo - 1``
        return float(np.searchsorted(cum, k + (cum[lo - 1] if lo else 0), side="right"))

    pos = 0.99 * (int(cum[-1]) - 1)
    i = int(np.floor(pos))
    t = pos - i
    a, b = kth(i), kth(min(i + 1, int(cum[-1]) - 1))
    p99 = b - (b - a) * (1 - t) if t >= 0.5 else a + (b - a) * t      # numpy's linear interpolation
    cut = 0.75 * p99
    lo = int(np.floor(cut)) + 1                 # the levels strictly above the cut
    n = int(cum[-1] - (cum[lo - 1] if lo else 0))
    if n % 2:
        return kth(n // 2, lo)
    return (kth(n // 2 - 1, lo) + kth(n // 2, lo)) / 2


def _rim(samples: list[np.ndarray], dark_ratio: float) -> np.ndarray:
    """The tray's rim: dark (< ``dark_ratio`` of the tray's level) in every sample and reaching the border.

    Each sample is taken relative to its bright tray (lighting drift); the per-pixel maximum
    removes anything that moves."""
    import cv2

    h, w = samples[0].shape
    dark = np.ones((h, w), bool)
    for smp in samples:
        level = _tray_level(smp[::4, ::4])
        inv = np.float32(1.0 / max(level, 1.0))
        if smp.dtype == np.uint8:
            # dark in this sample: the grey levels whose scaled value (the same float32 product)
            # is below the ratio, levels 0 .. cut - 1; compared as bytes, no float frame
            cut = int(np.count_nonzero(np.arange(256, dtype=np.float32) * inv < dark_ratio))
            if cut <= 255:
                dark &= smp < np.uint8(cut)
        else:
            dark &= smp.astype(np.float32) * inv < dark_ratio
    n, labels, stats, _ = cv2.connectedComponentsWithStats(dark.view(np.uint8), connectivity=8)
    rim = np.zeros((h, w), bool)
    for i in range(1, n):
        x, y, bw, bh, _a = stats[i]
        if x == 0 or y == 0 or x + bw == w or y + bh == h:
            rim |= labels == i
    return rim


def _pixel_noise(a: np.ndarray, b: np.ndarray) -> float:
    """The pixel noise relative to the tray: robust sigma of the difference of two samples (ratios to
    their smooth background) where both show bare tray, over sqrt 2."""
    both = (a > 0.9) & (b > 0.9)
    diff = (a - b)[both][::7]
    if diff.size <= 100:
        return 0.01
    return float(1.4826 * np.median(np.abs(diff - np.median(diff))) / np.sqrt(2))


def static_objects(ratios: list[np.ndarray], thr: float, body_width_px: float, keep: np.ndarray
                   ) -> tuple[np.ndarray, list[tuple[int, int, int, int]]]:
    """Static dark objects (dust, a scratch): their mask (uint8) and boxes (x, y, w, h).

    ``ratios``: sample frames (in time order) relative to their smooth background; ``thr``:
    the darkness that counts as dark; ``keep`` (uint8, 1 = may be marked) leaves the rim out.
    A candidate is dark in every sample, robot-sized (at least half a body width squared: a
    speck needs no mask) and clearly dark (by at least 15 % and 3 thresholds in three samples
    of four: the tray's mottling is not, even where a fast robot crossed it in a few samples).
    It is set aside only if it does not move (:func:`drifts`: its darkness centroid keeps its
    place over the samples) and the tray around it is dark in under a
    quarter of the samples on average (the robot passing by darkens it in a few). A robot
    that moves even a few pixels over the clip keeps its place in no sample; one that never
    moves at all cannot be told from dust here (the tracker tries it as the robot when
    nothing else is found).
    """
    import cv2

    darks = [np.asarray(r < 1 - thr, np.uint8) & keep for r in ratios]
    inter = darks[0].copy()
    for d in darks[1:]:
        inter &= d
    n, labels, stats, _ = cv2.connectedComponentsWithStats(inter, connectivity=8)
    h, w = inter.shape
    objects = np.zeros((h, w), np.uint8)
    boxes: list[tuple[int, int, int, int]] = []
    if n <= 1:
        return objects, boxes
    dark_count = None
    r = int(max(body_width_px / 2, 4))
    # texture and specks (hundreds of components of the tray's mottling) are never robot-sized and
    # need no mask: only components of at least half a body width squared are looked at
    for i in np.flatnonzero(stats[1:, 4] >= 0.5 * body_width_px ** 2) + 1:
        x, y, bw, bh = (int(v) for v in stats[i, :4])
        box = np.s_[max(y - r - 3, 0):min(y + bh + r + 3, h), max(x - r - 3, 0):min(x + bw + r + 3, w)]
        comp = np.asarray(labels[box] == i, np.uint8)
        # its own darkness: clear in most samples (the lower quartile), not the mean, which a fast
        # robot crossing a dimple of the tray's mottling in a few samples makes look like dust
        darkness = 1.0 - float(np.percentile([float(rt[box][comp > 0].mean()) for rt in ratios], 75))
        if darkness < max(3 * thr, 0.15):
            continue      # the tray's mottling: faint, static, divided out by the flat field
        ring = _dilate(comp, r) & (1 - _dilate(comp, 2))
        if dark_count is None:
            dark_count = np.zeros((h, w), np.int32)
            for d in darks:
                dark_count += d
        ring_frac = float(dark_count[box][ring > 0].mean()) / len(darks) if ring.any() else 0.0
        if ring_frac < 0.25 and not drifts([rt[box] for rt in ratios], _dilate(comp, r), thr):
            objects[box] |= _dilate(comp, 2)
            boxes.append((x, y, bw, bh))
    return objects, boxes


def drifts(wins: list[np.ndarray], region: np.ndarray, thr: float, min_px: float = 1.0) -> bool:
    """Whether a dark object moves over the samples (``wins``: its surroundings in each, in time order).

    Its darkness centroid (pixels of ``region`` darker than ``thr``, weighted by their
    darkness) is found in each sample. Samples whose dark area there is not the usual one
    (within 6 %) are left out: something else (the robot passing by dust) is in them; a robot
    moving slowly keeps its area. The object moves if the median centroid of the last third of
    the rest is farther from that of the first third than ``min_px`` and than 3 sigmas of the
    centroid's own frame-to-frame scatter (the tray's vibration, the noise: dust shakes with the
    tray but goes nowhere), and the middle third's lies on the way (20-80 % of it): a walk, not
    a change at one end (a robot touching dust late in the clip). A robot that moves only in
    part of the clip may fail this; the tracker then tries the static object as the robot.
    """
    import cv2

    cents, areas = [], []
    for win in wins:
        dark = (win < 1 - thr) & (region > 0)
        m = cv2.moments((np.clip(1.0 - win, 0.0, None) * dark).astype(np.float32))
        if m["m00"] <= 0:
            return True         # not dark in one sample: not static
        cents.append((m["m10"] / m["m00"], m["m01"] / m["m00"]))
        areas.append(float(np.count_nonzero(dark)))
    a = np.asarray(areas)
    c = np.asarray(cents)[np.abs(a - np.median(a)) <= 0.06 * np.median(a) + 10]
    if len(c) < 6:
        return False
    k = len(c) // 3
    first, middle, last = (np.median(c[sl], axis=0) for sl in (np.s_[:k], np.s_[k:-k], np.s_[-k:]))
    d = last - first
    drift = float(np.hypot(*d))
    steps = np.diff(c, axis=0)
    scatter = 1.4826 * np.median(np.abs(steps - np.median(steps, axis=0)), axis=0) / np.sqrt(2)
    if drift <= max(min_px, 3.0 * float(np.hypot(*scatter))):
        return False
    # a walk passes the middle third on its way; a change at one end only is something else
    return bool(0.2 < float(np.dot(middle - first, d)) / drift ** 2 < 0.8)


@dataclass
class FlatSettings:
    """How :func:`_flat_field` tells what moves: darker than ``1 - thr_b``, grown by ``grow_px``; holes
    (covered in every sample) are filled from the tray within a body width."""

    thr_b: float
    grow_px: int
    body_width_px: float


def _flat_field(samples: list[np.ndarray], ratios: list[np.ndarray], static: np.ndarray, rim: np.ndarray,
                fs: FlatSettings) -> np.ndarray:
    """The static scene's brightness B, relative to its median (float32).

    Each pixel's mean over the samples where nothing moving is dark within ``grow_px`` (static
    structure -- rim, dust, texture, the ring light's shape -- stays in it); each sample scaled
    to a common brightness first (flicker). The rim (static, never walked on) keeps its mean over
    all samples; where the robot covered a pixel in every sample, the tray around it
    (:func:`_fill_holes`)."""
    import cv2

    h, w = samples[0].shape
    gains = np.array([float(np.median(smp[::4, ::4])) for smp in samples])
    gains /= np.median(gains)
    total = np.zeros((h, w), np.float32)
    count = np.zeros((h, w), np.float32)
    grow = _square(fs.grow_px)
    not_static = np.asarray(~static, np.uint8)
    flat = np.zeros((h, w), np.float32)
    for smp, g, rat in zip(samples, gains, ratios):
        moving = np.asarray(rat < 1 - fs.thr_b, np.uint8) & not_static
        clear = (1 - np.asarray(cv2.dilate(moving, grow), np.float32))
        scaled = smp.astype(np.float32) * np.float32(1 / g)
        total += scaled * clear
        count += clear
        flat += scaled * np.float32(1 / len(samples))
    np.divide(total, count, out=flat, where=count > 0)
    holes = (count == 0) & ~rim
    if holes.any():
        _fill_holes(flat, holes, ((count > 0) & ~rim), fs.body_width_px)
    flat /= np.float32(np.median(flat[::4, ::4]))
    return flat


def _fill_holes(flat: np.ndarray, holes: np.ndarray, known_b: np.ndarray, body_width_px: float) -> None:
    """Fill ``holes`` of ``flat`` in place from the ``known_b`` tray around them: a normalised Gaussian
    average, widening until every hole is reached (the rim is never a source: it would darken the
    tray beside it)."""
    known = known_b.astype(np.float32)
    src = flat * known
    sigma = max(body_width_px / 2, 4.0)
    todo = holes.copy()
    for _ in range(6):
        num = _wide_blur(src, sigma)
        den = _wide_blur(known, sigma)
        ok = todo & (den > 1e-3)
        flat[ok] = num[ok] / den[ok]
        todo &= ~ok
        if not todo.any():
            break
        sigma *= 2
    flat[todo] = float(np.median(flat[~holes]))


def burnt_in_overlays(ratios: list[np.ndarray], thr: float, body_width_px: float, keep: np.ndarray | None = None
                      ) -> tuple[np.ndarray | None, list[tuple[int, int, int, int]]]:
    """Text burnt into every frame (a timestamp, a scale bar's label): mask and boxes (x, y, w, h).

    ``ratios``: sample frames relative to their smooth background. High-contrast marks
    (darker or brighter than the tray by ``max(3 thr, 0.2)``) are grown by a third of the
    body's width (3 to 8 px) up and down and three times that sideways, so a line of characters
    becomes one block. A block that is there in
    every sample, covers at least 60 % of everything marked around it over the samples
    (it does not move; a timestamp's changing digits stay inside it) and holds, in most
    samples, at least four separate marks in a row at least 2.5 times as wide as high, is
    text: its characters may change from frame to frame, one of them may be as dark and
    as large as the robot, and it is masked. A robot, even a still one, is one mark; a
    static dark object alone is left to the dust rule of :func:`background_model`. ``keep``
    (uint8, 1 = may be marked) leaves the tray's rim out. Most clips have no overlay: the
    samples' blocks are intersected first and the search stops as soon as nothing is left.
    """
    import cv2

    if len(ratios) < 5:
        return None, []
    t = max(3 * thr, 0.2)
    g = int(np.clip(body_width_px // 3, 3, 8))         # text's gaps are a few pixels, whatever the robot's size
    grow = np.ones((2 * g + 1, 6 * g + 1), np.uint8)     # wider than high: a line of text, gaps between words

    def marked(r: np.ndarray) -> np.ndarray:
        m = np.asarray((r < 1 - t) | (r > 1 + t), np.uint8)
        return m if keep is None else m & keep

    inter = np.ones(ratios[0].shape, np.uint8)
    for r in ratios:
        inter &= np.asarray(cv2.dilate(marked(r), grow), np.uint8)
        if not inter.any():
            return None, []
    marks = [marked(r) for r in ratios]
    union = np.zeros_like(inter)
    for m in marks:
        union |= np.asarray(cv2.dilate(m, grow), np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(inter, connectivity=8)
    mask = np.zeros(inter.shape, np.uint8)
    boxes = []
    for i in range(1, n):
        x, y, bw, bh, area = stats[i]
        if bw < 2.5 * bh or area < 20:
            continue
        sl = np.s_[y:y + bh, x:x + bw]
        comp = np.asarray(labels[sl] == i, np.uint8)
        if area < 0.6 * int(np.count_nonzero(union[sl])):
            continue                                    # marked around it in some samples only: it moves
        pieces = [cv2.connectedComponents(m[sl] & comp, connectivity=8)[0] - 1 for m in marks]
        if np.median(pieces) < 4:
            continue
        mask[sl] |= comp
        boxes.append((int(x), int(y), int(bw), int(bh)))
    return (cv2.dilate(mask, _square(2)).astype(bool) if boxes else None), boxes
