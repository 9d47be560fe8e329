"""Measures of single runs and of speed curves, shared by the scenarios."""
from __future__ import annotations

from typing import Any, TypedDict

import numpy as np

from labkit.sim.result import SimResult


def steady(r: SimResult, skip_s: float | None = None) -> np.ndarray:
    """Mask of the samples after the start-up transient (the last half by default)."""
    t = np.asarray(r.t_s)
    skip = t[-1] / 2 if skip_s is None else skip_s
    return t >= t[0] + skip


def aperiodicity(t_s: np.ndarray, z: np.ndarray, freq_hz: float, max_lag: int = 4) -> float:
    """How far a signal is from periodic at the drive period (or a multiple up to ``max_lag``).

    The signal is resampled 64 times per period; for every lag of 1..max_lag
    periods the RMS difference between the signal and itself one lag later is
    divided by the signal's RMS about its mean. The smallest value is
    returned: 0 for a periodic (or period-n subharmonic) motion, ~1.4 for
    unrelated cycles. NaN when fewer than ``max_lag + 2`` periods are given.
    """
    period = 1.0 / freq_hz
    n_per = int(np.floor((t_s[-1] - t_s[0]) / period))
    if n_per < max_lag + 2:
        return float("nan")
    grid = t_s[-1] - period * n_per + np.arange(n_per * 64) * (period / 64)
    zz = np.interp(grid, t_s, z).reshape(n_per, 64)
    scale = float(np.sqrt(np.mean((zz - zz.mean()) ** 2)))
    if scale == 0:
        return 0.0
    best = min(float(np.sqrt(np.mean((zz[lag:] - zz[:-lag]) ** 2))) for lag in range(1, max_lag + 1))
    return best / scale


def leg_motion_um(r: SimResult, foot: int | None = None) -> float:
    """Peak-to-peak vertical foot motion relative to the body over the steady part, um.

    Averaged over the feet unless one foot is given (relative to the body so
    the tray's own motion is not counted as leg motion).
    """
    m = steady(r)
    rel = np.asarray(r.foot_z_um)[m] - np.asarray(r.body_z_um)[m][:, None]
    p2p = rel.max(axis=0) - rel.min(axis=0)
    return float(p2p[foot] if foot is not None else p2p.mean())


def foot_rise_um(r: SimResult) -> float:
    """Highest foot clearance above the tray over the steady part (max over feet), um."""
    m = steady(r)
    gap = np.asarray(r.foot_z_um)[m] - np.asarray(r.ground_z_um)[m][:, None]
    return float(gap.max())


def leg_aperiodicity(r: SimResult) -> float:
    """Mean over feet of :func:`aperiodicity` of the leg's own motion (foot relative to body)."""
    m = steady(r)
    rel = np.asarray(r.foot_z_um)[m] - np.asarray(r.body_z_um)[m][:, None]
    ap = [aperiodicity(np.asarray(r.t_s)[m], rel[:, j], r.scenario.freq_hz) for j in range(rel.shape[1])]
    return float(np.nanmean(ap)) if np.isfinite(ap).any() else float("nan")


def contact_summary(r: SimResult) -> dict[str, float]:
    """Mean over feet of the fraction of time in each contact mode."""
    from labkit.sim.sweep import CONTACT_MODES, result_row

    frac = result_row(r).contact_fraction.mean(axis=0)
    return {m: float(f) for m, f in zip(CONTACT_MODES, frac)}


class RunInfo(TypedDict):
    """:func:`run_info`: what a single scenario run reports."""

    mean_speed_mm_s: float
    patterns: list[str]
    contact_fraction: dict[str, float]
    impacts: list[int]
    leg_motion_um: float
    foot_rise_um: float
    aperiodicity: float


def run_info(r: SimResult, freq_hz: float | None = None) -> RunInfo:
    """The numbers a single scenario run reports."""
    return {"mean_speed_mm_s": float(r.mean_speed_mm_s), "patterns": [str(p) for p in r.patterns],
            "contact_fraction": contact_summary(r), "impacts": [int(i) for i in r.impacts],
            "leg_motion_um": leg_motion_um(r), "foot_rise_um": foot_rise_um(r),
            "aperiodicity": leg_aperiodicity(r)}


def band(values: np.ndarray, speeds: np.ndarray, lo: float, hi: float, stat: str = "max") -> float:
    """Largest (or mean) |speed| of a curve over ``lo <= value <= hi``; NaN when no point is there."""
    values, speeds = np.asarray(values, float), np.asarray(speeds, float)
    m = (values >= lo) & (values <= hi)
    if not m.any():
        return float("nan")
    v = np.abs(speeds[m])
    return float(v.max() if stat == "max" else v.mean())


def at(values: np.ndarray, speeds: np.ndarray, x: float) -> float:
    """|speed| of a curve at ``x`` (linear interpolation; NaN outside the curve)."""
    values, speeds = np.asarray(values, float), np.asarray(speeds, float)
    if values.size == 0 or x < values.min() or x > values.max():
        return float("nan")
    order = np.argsort(values)
    return float(abs(np.interp(x, values[order], speeds[order])))


def fig8_checks(freqs: Any, speeds: Any) -> dict[str, bool]:
    """Paper Fig. 8 as two coarse tests on a speed-vs-frequency curve (the ``shaker-speed`` scenario).

    * ``mm_s_between_150_and_300_hz``: the largest |speed| in 150-300 Hz is
      between 0.5 and 20 mm/s;
    * ``none_from_500_hz_to_1800_hz``: |speed| stays below 0.1 mm/s there.

    The paper's observations with their sources and tolerances are the
    ``paper-fig8`` scenario's (:mod:`labkit.sim.paper.observations`).
    """
    f, s = np.asarray(freqs, float), np.abs(np.asarray(speeds, float))
    low = s[(f >= 150) & (f <= 300)]
    high = s[(f >= 500) & (f <= 1800)]
    return {"mm_s_between_150_and_300_hz": bool(low.size and 0.5 <= low.max() <= 20.0),
            "none_from_500_hz_to_1800_hz": bool(high.size and high.max() < 0.1)}


def lockin(t_s: np.ndarray, x: np.ndarray, freq_hz: float) -> complex:
    """Complex amplitude of ``x`` at ``freq_hz`` over the whole number of periods at the end of the record."""
    from scipy.integrate import trapezoid

    t, x = np.asarray(t_s, float), np.asarray(x, float)
    n_per = int(np.floor((t[-1] - t[0]) * freq_hz))
    if n_per < 1:
        return complex("nan")
    m = t >= t[-1] - n_per / freq_hz
    w = 2 * np.pi * freq_hz
    tt = t[m]
    # trapezoid weights: the record may be unevenly spaced (a long run's dense tail)
    return complex(2.0 * trapezoid(x[m] * np.exp(-1j * w * tt), tt) / (tt[-1] - tt[0]))


def knee_z_um(r: SimResult) -> np.ndarray:
    """The knees' vertical displacement (um; time x leg), the knee velocity integrated as a
    vibrometer's displacement trace is (trapezoids from the first sample)."""
    from scipy.integrate import cumulative_trapezoid

    return cumulative_trapezoid(np.asarray(r.knee_vz_mm_s), np.asarray(r.t_s), axis=0, initial=0.0) * 1e3


def knee_amplitude_um(r: SimResult) -> float:
    """Largest knee displacement amplitude (half peak-to-peak over the steady part, max over legs), um:
    the quantity of the paper's "amplitudes (200 um) ... ground amplitude (25 um)" (Sec. 5.2, an LDV
    trace at the knee)."""
    m = steady(r)
    z = knee_z_um(r)[m]
    return float(((z.max(axis=0) - z.min(axis=0)) / 2).max())


def release_jumps(r: SimResult) -> tuple[int, float]:
    """Releases of a foot from the tray over the steady part and the median jump of the knee's
    velocity relative to the tray across one record interval at a release, in units of the tray's
    velocity amplitude (NaN without releases or tray motion). A film or adhesion that lets go
    gradually gives ~0; a force "broken suddenly" (paper Sec. 5.2, Fig. 10) a finite jump."""
    m = steady(r)
    t = np.asarray(r.t_s)
    tray_v = np.gradient(np.asarray(r.ground_z_um), t) * 1e-3
    scale = float(np.abs(tray_v[m]).max()) if m.any() else 0.0
    rel = np.asarray(r.knee_vz_mm_s) - tray_v[:, None]
    held = np.asarray(r.contact) != 0
    rel_ev = held[:-1] & ~held[1:] & m[1:, None]
    k, leg = np.nonzero(rel_ev)
    if not k.size or scale <= 0:
        return int(k.size), float("nan")
    jumps = np.abs(rel[k + 1, leg] - rel[k, leg]) / scale
    return int(k.size), float(np.median(jumps))


def response_gains(r: SimResult) -> tuple[float, float]:
    """Knee (mean over legs) and body vertical velocity relative to the tray, per tray velocity, at the
    drive frequency: the out-of-chip transmissibility of the paper's Fig. 6 (right)."""
    m = steady(r)
    t = np.asarray(r.t_s)[m]
    f = r.scenario.freq_hz
    w = 2j * np.pi * f
    tray = w * lockin(t, np.asarray(r.ground_z_um)[m], f) * 1e-3
    if not abs(tray) > 0:
        return float("nan"), float("nan")
    knee = np.mean([abs(lockin(t, np.asarray(r.knee_vz_mm_s)[m, j], f) - tray) for j in range(6)])
    body = abs(w * lockin(t, np.asarray(r.body_z_um)[m], f) * 1e-3 - tray)
    return float(knee / abs(tray)), float(body / abs(tray))


#: The per-run measures :func:`run_measures` adds to a scenario run's row.
RUN_MEASURES = ("knee_amp_um", "releases", "release_jump", "knee_gain", "body_gain")


def run_measures(r: SimResult) -> dict[str, float]:
    """The per-run measures of the paper scenarios beyond speed and patterns (:data:`RUN_MEASURES`)."""
    n, jump = release_jumps(r)
    knee, body = response_gains(r)
    return {"knee_amp_um": knee_amplitude_um(r), "releases": float(n), "release_jump": jump,
            "knee_gain": knee, "body_gain": body}


def slope(values: np.ndarray, speeds: np.ndarray, lo: float, hi: float) -> float:
    """Least-squares slope of |speed| against the value over ``lo <= value <= hi`` (NaN with < 2 points)."""
    x, y = np.asarray(values, float), np.abs(np.asarray(speeds, float))
    m = (x >= lo) & (x <= hi) & np.isfinite(y)
    if m.sum() < 2:
        return float("nan")
    return float(np.polyfit(x[m], y[m], 1)[0])
