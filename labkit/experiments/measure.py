"""One acquisition and its reduction: scope records -> phasors, FRF and quality.

The runner calls these with the rig's drivers; they never change an output.
Demodulation and spectral estimates come from :mod:`labkit.analysis.frf` (shared
with the fitting code).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from labkit.errors import InstrumentError


@dataclass
class Records:
    """Drive and velocity-output records of one acquisition (volts, common time base)."""

    drive_v: np.ndarray
    velocity_v: np.ndarray
    dt_s: float

    @property
    def fs_hz(self) -> float:
        return 1.0 / self.dt_s


@dataclass
class SinePhasors:
    """Complex amplitudes (peak) at the drive frequency, and the fit quality."""

    drive_v: complex
    velocity_mm_s: complex
    quality: float

    @property
    def frf(self) -> complex:
        """Velocity over drive, (mm/s)/V."""
        return self.velocity_mm_s / self.drive_v if self.drive_v != 0 else complex("nan")

    @property
    def velocity_re_drive(self) -> complex:
        """The velocity phasor with its phase referred to the drive's (mm/s)."""
        if self.drive_v == 0:
            return complex("nan")
        return self.velocity_mm_s * abs(self.drive_v) / self.drive_v


def acquire(scope: Any, channels: tuple[int, int], record_s: float, timeout_s: float,
            averages: int = 1) -> Records:
    """One single-shot acquisition of the (drive, velocity) ``channels`` (timebase already set for
    ``record_s``); a scope set to average ``averages`` records takes that many triggers (the
    drive's sync, every cycle)."""
    scope.single()
    # The record cannot be complete before it has been acquired: sleep through it, then poll.
    time.sleep(record_s * averages)
    scope.wait_done(timeout_s)
    return _read(scope, *channels)


def acquire_burst(scope: Any, fire: Any, drive_channel: int, velocity_channel: int, settle_s: float,
                  dwell_s: float, timeout_s: float, averages: int = 1) -> Records:
    """Arm the scope, start the generator's burst (``fire()``, a ``*TRG``), record its settled part.

    The scope's record was placed ``settle_s`` after its trigger (the burst's start,
    :meth:`set_record_delay`), so it holds ``dwell_s`` of the steady response. A scope set
    to average ``averages`` records gets one burst per record (``fire`` waits for the last
    burst's end), each response starting from rest at its own trigger.
    """
    arm(scope)
    for _ in range(averages):
        fire()
        time.sleep(settle_s + dwell_s)
    scope.wait_done(timeout_s)
    return _read(scope, drive_channel, velocity_channel)


def arm(scope: Any) -> None:
    """``:SING``, confirmed: a query answered after it means the scope has armed, so a trigger sent
    to the generator next cannot come before it (the two instruments are separate links; nothing
    else orders their commands). *STB? never waits (an *OPC? may be held until an armed single
    acquisition completes, i.e. forever here)."""
    scope.single()
    confirm = getattr(scope, "query", None)
    if confirm is not None:
        confirm("*STB?")


def _read(scope: Any, drive_channel: int, velocity_channel: int) -> Records:
    wd = scope.read_waveform(drive_channel)
    wv = scope.read_waveform(velocity_channel)
    d = np.asarray(wd.volts, dtype=float)
    v = np.asarray(wv.volts, dtype=float)
    if d.shape != v.shape or d.size < 16:
        raise InstrumentError(f"records of {d.size} and {v.size} samples", instrument="scope",
                              command=":WAV:DATA?")
    return Records(d, v, float(wd.xinc_s))


def delay_correction(freq_hz: Any, delay_s: float) -> Any:
    """The factor undoing a signal delay: the decoder's output at ``t`` is the velocity at
    ``t - delay_s``, i.e. its phasor ``exp(-j w delay_s)`` times the velocity's."""
    return np.exp(2j * np.pi * np.asarray(freq_hz, dtype=float) * delay_s)


def sine_phasors(rec: Records, freq_hz: float, scale_mm_s_per_v: float, delay_s: float = 0.0) -> SinePhasors:
    """Least-squares sine fit of both channels at ``freq_hz`` (:func:`labkit.analysis.frf.demodulate`);
    the velocity's phase corrected for the decoder's ``delay_s``."""
    from labkit.analysis.frf import demodulate

    dem = demodulate(np.vstack([rec.drive_v, rec.velocity_v]), rec.fs_hz, freq_hz)
    velocity = complex(dem.amplitude[1]) * scale_mm_s_per_v * complex(delay_correction(freq_hz, delay_s))
    return SinePhasors(complex(dem.amplitude[0]), velocity, float(np.min(dem.quality)))


def chirp_h1(records: list[Records], scale_mm_s_per_v: float, f_lo_hz: float, f_hi_hz: float,
             delay_s: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H1 and coherence from chirp records (one Welch segment per record, rectangular window).

    A chirp fills its record, so each record is one segment (no taper that
    would weight some frequencies less); averaging is over the records.
    Returns ``(freq_hz, frf (mm/s)/V, coherence)`` inside ``[f_lo_hz, f_hi_hz]``.
    """
    from labkit.analysis.frf import estimate_frf

    n = min(r.drive_v.size for r in records)
    x = np.concatenate([r.drive_v[:n] for r in records])
    y = np.concatenate([r.velocity_v[:n] for r in records]) * scale_mm_s_per_v
    est = estimate_frf(x, y, records[0].fs_hz, nperseg=n, noverlap=0, window="boxcar")
    keep = (est.freq_hz >= f_lo_hz) & (est.freq_hz <= f_hi_hz)
    coh = np.nan_to_num(est.coherence[keep], nan=0.0)
    f = est.freq_hz[keep]
    return f, est.h1[keep] * delay_correction(f, delay_s), coh


def displacement_um(velocity_mm_s: complex, freq_hz: float) -> float:
    """Displacement amplitude of a sine from its velocity amplitude: ``x = v / (2 pi f)``."""
    return abs(velocity_mm_s) / (2 * math.pi * freq_hz) * 1e3


def clipped(volts: np.ndarray, full_scale_v: float | None, margin: float = 0.98) -> bool:
    """True when a record touches the screen's edge (its peak is not trustworthy)."""
    if full_scale_v is None:
        return False
    return bool(np.max(np.abs(volts)) >= margin * full_scale_v)
