"""The speed's error budget: the random part and the systematic parts, each by name, in the interval.

A smoothed path's mean speed is uncertain for reasons the residuals cannot show:
they are the same in every frame or change slowly across the field. Each is
measured from the video or declared, given as a standard uncertainty (mm/s),
and added in quadrature to the random part (:func:`speed_uncertainty
<labkit.analysis.tracking.speed.speed_uncertainty>`):

* ``position noise`` (random, measured): the residuals about the smoothed path.
* ``timestamp jitter`` (random, measured): the frame times' scatter; with a
  declared ``timestamp_std_s`` (the clock's accuracy per frame) the larger of
  the two.
* ``scale`` (systematic): the image scale's own uncertainty (declared with
  ``--mm-per-px-std``, or from the robot's length or a scale bar).
* ``scale across the field`` (systematic, measured): perspective (a tilted
  stand) and lens distortion change the scale over the field. The robot's
  outline length (image moments, every frame) is fitted as ``log L = a + b u +
  c v``; the scale at each position relative to the reference (the field's
  centre for a given scale, the track's mean for one from the robot's length)
  deviates by ``d_i``; the part is the speed times the RMS of ``d_i`` along the
  path (the fit's own uncertainty included).
* ``illumination`` (systematic, measured): the static scene's flat field
  (ring light, texture) is divided out before the robot is measured; the same
  robot is also measured without it, and the part is the difference of the two
  speeds.
* ``rolling shutter`` (systematic, declared or assumed): a sensor read row by
  row sees row ``v`` ``v x line_time`` late. With a declared ``line_time_s``
  the frame times are corrected at the robot's row and the part is the speed's
  change over ``line_time_std_s`` (0 for a declared global shutter).
  Undeclared, anything from a global shutter to a readout filling the frame
  interval is possible: the part is that bound (the speed's change at a line
  time of frame interval / rows) over sqrt(3), a uniform spread.

A part whose variance is over half the total is named in a warning.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np


@dataclass
class BudgetPart:
    """One named part of the mean speed's standard uncertainty."""

    name: str
    std_mm_s: float
    kind: str          # "random" or "systematic"
    source: str        # "measured", "declared" or "assumed"
    detail: str = ""


@dataclass
class ErrorBudget:
    parts: list[BudgetPart]
    total_std_mm_s: float
    warnings: list[str] = field(default_factory=list)
    rolling_shutter_bound_mm_s: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        return {"total_std_mm_s": self.total_std_mm_s, "parts": [asdict(p) for p in self.parts],
                "rolling_shutter_bound_mm_s": self.rolling_shutter_bound_mm_s}


def field_scale_part(track: Any, speed: Any) -> tuple[float, str]:
    """The ``scale across the field`` part (mm/s) and its description (see the module docstring)."""
    major = track.major_px
    if major is None:
        return 0.0, "no per-frame outline"
    ok = (track.quality == 0) & np.isfinite(major) & (major > 0) & np.isfinite(track.u_px)
    if ok.sum() < 8:
        return 0.0, "too few clear frames"
    W, H = track.frame_size
    du, dv = track.u_px[ok] - (W - 1) / 2, track.v_px[ok] - (H - 1) / 2
    A = np.column_stack([np.ones(du.size), du, dv])
    y = np.log(major[ok])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    res = y - A @ coef
    s2 = float(res @ res) / max(y.size - 3, 1)
    cov = s2 * np.linalg.pinv(A.T @ A)
    # where the speed was measured (the smoothed path's samples, weighted by their speed)
    t_all = track.t_s
    u_s = np.interp(speed.t_s, t_all[ok], track.u_px[ok]) - (W - 1) / 2
    v_s = np.interp(speed.t_s, t_all[ok], track.v_px[ok]) - (H - 1) / 2
    G = np.column_stack([u_s, v_s])
    if track.scale is not None and track.scale.method == "robot_length":
        G = G - np.average(G, axis=0, weights=np.maximum(speed.speed_mm_s, 0) + 1e-12)
    # mm/px goes as 1 / length: d_i = -(b u_i + c v_i); its variance from the fit's covariance
    d = -(G @ coef[1:])
    var_d = np.einsum("ij,jk,ik->i", G, cov[1:, 1:], G)
    w = np.maximum(speed.speed_mm_s, 0) + 1e-12
    rms = float(np.sqrt(np.average(d ** 2 + var_d, weights=w)))
    span = float(np.ptp(d))
    return float(abs(speed.mean_speed_mm_s) * rms), (f"the robot's outline length changes {100 * span:.2f} % along the "
                                              f"path; scale off its reference by {100 * rms:.2f} % RMS there")


def error_budget(track: Any, speed: Any, *, alt_speed_mm_s: float, rs_bound_mm_s: float,
                 line_time_s: float | None, rs_part_mm_s: float, timestamp_std_s: float | None) -> ErrorBudget:
    """Collect the parts (see the module docstring); ``speed`` is the :class:`SpeedResult` to widen."""
    unc = speed.meta["uncertainty"]
    parts = [BudgetPart("position noise", unc["noise_part_mm_s"], "random", "measured",
                        f"residuals about the smoothed path, AR(1) {unc['noise_ar1']:.2f}")]
    ts_part, ts_src = unc["timestamp_part_mm_s"], "measured"
    if timestamp_std_s is not None:
        declared = timestamp_std_s * unc["timestamp_sensitivity_mm_s2"]
        if declared > ts_part:
            ts_part, ts_src = declared, "declared"
    parts.append(BudgetPart("timestamp jitter", ts_part, "random", ts_src,
                            f"frame times' scatter {1e3 * unc['timestamp_jitter_s']:.3g} ms"))
    scale_src = "declared" if track.scale is not None and track.scale.method == "given" else "measured"
    parts.append(BudgetPart("scale", unc["scale_part_mm_s"], "systematic", scale_src,
                            f"relative uncertainty {100 * speed.meta['mm_per_px_rel_std']:.3g} %"))
    fs, fs_detail = field_scale_part(track, speed)
    parts.append(BudgetPart("scale across the field", fs, "systematic", "measured", fs_detail))
    ill = abs(alt_speed_mm_s - speed.mean_speed_mm_s) if np.isfinite(alt_speed_mm_s) else 0.0
    parts.append(BudgetPart("illumination", ill, "systematic", "measured",
                            "speed with the flat-field model minus without it"))
    if line_time_s is not None:
        parts.append(BudgetPart("rolling shutter", rs_part_mm_s, "systematic", "declared",
                                f"line time {1e6 * line_time_s:.4g} us, frame times corrected"))
    else:
        # not declared: anything from a global shutter to a readout filling the frame interval
        parts.append(BudgetPart("rolling shutter", float(rs_bound_mm_s / np.sqrt(3)), "systematic", "assumed",
                                f"shutter not declared: up to {rs_bound_mm_s:.3g} mm/s if the readout fills the "
                                f"frame interval (declare --line-time-us, 0 for a global shutter)"))
    total = float(np.sqrt(sum(p.std_mm_s ** 2 for p in parts)))
    warnings = []
    for p in parts:
        if p.kind == "systematic" and total > 0 and p.std_mm_s ** 2 > 0.5 * total ** 2:
            warnings.append(f"the speed's uncertainty is dominated by {p.name} ({p.std_mm_s:.3g} of "
                            f"{total:.3g} mm/s): {p.detail}")
    return ErrorBudget(parts, total, warnings, rs_bound_mm_s)
