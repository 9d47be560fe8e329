"""Leg-pattern labels from a knee's vertical velocity record (the paper's section 5.2).

Measured knee records (vibrometer) and simulated ones are labelled by the same
function, so that a pattern comparison compares like with like. It lives beside
the simulator because calibration labels simulated knees with it, and the
simulator imports no analysis; :mod:`labkit.analysis.compare` re-exports it.
"""
from __future__ import annotations

from typing import Any, TypedDict

import numpy as np

PATTERNS = ("firm_contact", "partial_contact", "jumping")


def _f(x: Any) -> float | None:
    """A float for JSON, or None for NaN/inf (JSON has no NaN)."""
    x = float(x)
    return x if np.isfinite(x) else None


def fundamental(t_s: np.ndarray, x: np.ndarray, freq_hz: float) -> dict[str, float]:
    """Amplitude and phase of the drive-frequency component, by linear least squares.

    Fits ``x ~ A sin(2 pi f t + phi) + c`` (the tray moves as ``sin``, so a
    signal in phase with the tray's displacement has ``phi = 0``).
    """
    t = np.asarray(t_s, float)
    x = np.asarray(x, float)
    w = 2 * np.pi * float(freq_hz) * t
    design = np.column_stack([np.sin(w), np.cos(w), np.ones_like(w)])
    (a, b, c), *_ = np.linalg.lstsq(design, x, rcond=None)
    return {"amplitude": float(np.hypot(a, b)), "phase_rad": float(np.arctan2(b, a)), "offset": float(c)}


class KneePattern(TypedDict):
    """:func:`classify_knee_pattern`'s label, the two figures it rests on (None: not finite), and how."""

    pattern: str
    distortion: float | None
    aperiodicity: float | None
    knee_to_tray_amplitude: float | None
    method: str


def classify_knee_pattern(t_s: np.ndarray, knee_vz_mm_s: np.ndarray, tray_vz_mm_s: np.ndarray | None,
                          freq_hz: float, *, firm_distortion: float = 0.03,
                          jump_aperiodicity: float = 0.3) -> KneePattern:
    """Label a measured knee velocity record as firm contact, partial contact or jumping.

    The paper's patterns (section 5.2), made operational (**choice**) from the
    knee record alone, because a knee in firm contact does not move like the
    tray (the leg flexes: it moves at the drive frequency with its own
    amplitude and phase):

    * firm contact: the knee moves as a pure sinusoid at the drive frequency —
      the residual after fitting that sinusoid is below ``firm_distortion``
      of its RMS;
    * jumping: the motion does not repeat from one drive period to the next
      (feet in the air for more than one period) — the RMS difference between
      the record and itself one period later exceeds ``jump_aperiodicity`` of
      the record's RMS;
    * partial contact: otherwise (periodic at the drive period, but not
      sinusoidal: adhesion holds the foot, then it lets go abruptly).

    Thresholds: a settled, pinned leg in the simulator gives a distortion
    below 0.005; 0.03 leaves room for vibrometer noise of a few per cent of
    the signal, while a foot that leaves the ground for part of each cycle
    already flattens the knee's waveform by more than that.

    ``tray_vz_mm_s`` is only used to report how closely the knee follows the tray.

    Returns
    -------
    KneePattern
        ``pattern``, ``distortion``, ``aperiodicity``, ``knee_to_tray_amplitude``, ``method``.
    """
    t = np.asarray(t_s, float)
    x = np.asarray(knee_vz_mm_s, float)
    fit = fundamental(t, x, freq_hz)
    w = 2 * np.pi * freq_hz * t
    pure = fit["amplitude"] * np.sin(w + fit["phase_rad"]) + fit["offset"]
    ac = x - fit["offset"]
    rms = float(np.sqrt(np.mean(ac ** 2))) or 1.0
    distortion = float(np.sqrt(np.mean((x - pure) ** 2)) / rms)
    period = 1.0 / freq_hz
    later = t + period
    ok = later <= t[-1]
    aperiodicity = (float(np.sqrt(np.mean((np.interp(later[ok], t, x) - x[ok]) ** 2)) / (np.sqrt(2) * rms))
                    if ok.sum() > 4 else float("nan"))
    if distortion < firm_distortion:
        label = "firm_contact"
    elif aperiodicity > jump_aperiodicity:
        label = "jumping"
    else:
        label = "partial_contact"
    ratio = None
    if tray_vz_mm_s is not None:
        tray_amp = fundamental(t, tray_vz_mm_s, freq_hz)["amplitude"]
        ratio = _f(fit["amplitude"] / tray_amp) if tray_amp > 0 else None
    return {"pattern": label, "distortion": _f(distortion), "aperiodicity": _f(aperiodicity),
            "knee_to_tray_amplitude": ratio,
            "method": f"firm if the residual after a drive-frequency sinusoid is < {firm_distortion:g} of the "
                      f"RMS; jumping if the record differs from itself one period later by > "
                      f"{jump_aperiodicity:g} of the RMS (x sqrt 2); else partial"}
