"""The virtual lab's physics: a linear modal model of the tethered robot, and the shaker chain.

In-chip (the robot still on its tethers, driven by its own PZT)
----------------------------------------------------------------
The vibrometer velocity at spot ``s`` per volt of PZT drive is a sum of
modes, each a velocity-output resonance with real modal constants
(proportional damping)::

    H_s(f) = sum_i  R_si * 2 zeta_i w_i (j w) / (w_i^2 - w^2 + 2 j zeta_i w_i w)
             [(mm/s)/V],   w = 2 pi f,   w_i = 2 pi f_i

so ``R_si`` is the velocity per volt at spot ``s`` exactly at resonance
``f_i`` (the "peak mobility"; its sign is the mode shape's sign there). The
modes are the hip (lateral, seen only weakly out of plane), the tether mode (a
rigid-body mode of the robot on its tethers) and the in-chip knee mode. The
hip mode's frequency and damping are the robot parameters' first mode
(:attr:`RobotParams.modal_freq_hz`), so a fitted parameter file feeds back
into the lab; the tether and knee modes exist only in-chip and are lab
parameters.

Out-of-chip (released robot on the shaker tray)
-----------------------------------------------
Generator -> amplifier (declared gain, flat) -> shaker. The tray's vertical
acceleration per volt at the amplifier output is a second-order high-pass
(a voice-coil shaker above its suspension resonance is mass-controlled:
acceleration proportional to current, flat above ~100 Hz)::

    A(s)/V_amp = K_a s^2 / (s^2 + 2 zeta_s w_s s + w_s^2)

The robot's response to the tray motion is the hybrid simulator's.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

SPOTS = ("body", "hip", "knee", "tray")

#: default peak mobilities R_si, (mm/s)/V, per spot for the modes (hip, tether, knee)
DEFAULT_SHAPES: dict[str, tuple[float, float, float]] = {
    "body": (0.05, 3.0, 0.3),
    "hip": (0.6, 2.2, -1.2),
    "knee": (0.25, 1.5, 6.0),
    "tray": (0.0, 0.0, 0.0),  # the chip frame: the tethers' anchor does not move
}


@dataclass(frozen=True)
class TetheredModel:
    """Linear modal model of the tethered robot: PZT volts -> velocity at a spot."""

    freq_hz: tuple[float, float, float] = (438.0, 830.0, 3400.0)
    damping_ratio: tuple[float, float, float] = (0.25, 0.02, 0.015)
    names: tuple[str, str, str] = ("hip", "tether", "knee")
    shapes_mm_s_per_v: dict[str, tuple[float, float, float]] = field(
        default_factory=lambda: dict(DEFAULT_SHAPES))

    def _check(self, spot: str) -> tuple[float, ...]:
        if spot not in self.shapes_mm_s_per_v:
            raise ValueError(f"spot must be one of {sorted(self.shapes_mm_s_per_v)}, not {spot!r}")
        return self.shapes_mm_s_per_v[spot]

    def frf(self, spot: str, freq_hz: np.ndarray | float) -> np.ndarray:
        """Velocity per drive volt at ``spot``, complex, (mm/s)/V."""
        shape = self._check(spot)
        w = 2 * np.pi * np.asarray(freq_hz, dtype=float)
        h = np.zeros(w.shape, dtype=complex)
        for r, f, z in zip(shape, self.freq_hz, self.damping_ratio):
            wi = 2 * np.pi * f
            h = h + r * 2 * z * wi * 1j * w / (wi ** 2 - w ** 2 + 2j * z * wi * w)
        return h

    def settle_s(self, decays: float = 12.0) -> float:
        """Time for the slowest mode's transient to fall by ``exp(-decays)``."""
        return decays * max(1 / (z * 2 * np.pi * f) for f, z in zip(self.freq_hz, self.damping_ratio))

    def transfer(self, spot: str) -> list[tuple[np.ndarray, np.ndarray]]:
        """Continuous-time (num, den) per mode, velocity (mm/s) per volt."""
        out = []
        for r, f, z in zip(self._check(spot), self.freq_hz, self.damping_ratio):
            wi = 2 * np.pi * f
            out.append((np.array([r * 2 * z * wi, 0.0]), np.array([1.0, 2 * z * wi, wi ** 2])))
        return out

    def max_freq_hz(self) -> float:
        return max(self.freq_hz)


@dataclass(frozen=True)
class ShakerChain:
    """Generator -> B&K 2718-like amplifier (declared gain) -> 4809-like shaker -> tray."""

    amplifier_gain_db: float = 20.0
    accel_m_s2_per_v: float = 20.0      # tray acceleration per volt at the amplifier output
    suspension_hz: float = 25.0
    suspension_damping_ratio: float = 0.7

    @property
    def gain(self) -> float:
        return 10 ** (self.amplifier_gain_db / 20)

    def tray_velocity_frf(self, freq_hz: np.ndarray | float) -> np.ndarray:
        """Tray vertical velocity per generator volt, complex, (mm/s)/V."""
        s = 2j * np.pi * np.asarray(freq_hz, dtype=float)
        ws = 2 * np.pi * self.suspension_hz
        accel = self.gain * self.accel_m_s2_per_v * s ** 2 / (
            s ** 2 + 2 * self.suspension_damping_ratio * ws * s + ws ** 2)
        return accel / s * 1e3

    def tray_amp_um(self, freq_hz: float, drive_amp_v: float) -> float:
        """Tray displacement amplitude for a sine of ``drive_amp_v`` (peak) at the generator."""
        v = abs(self.tray_velocity_frf(freq_hz)) * drive_amp_v  # mm/s
        return float(v / (2 * np.pi * freq_hz) * 1e3)

    def transfer(self) -> list[tuple[np.ndarray, np.ndarray]]:
        ws = 2 * np.pi * self.suspension_hz
        k = self.gain * self.accel_m_s2_per_v * 1e3
        return [(np.array([k, 0.0]), np.array([1.0, 2 * self.suspension_damping_ratio * ws, ws ** 2]))]

    def settle_s(self, decays: float = 12.0) -> float:
        return decays / (self.suspension_damping_ratio * 2 * np.pi * self.suspension_hz)


def lti_response(parts: list[tuple[np.ndarray, np.ndarray]], u: np.ndarray, dt_s: float) -> np.ndarray:
    """Response of a sum of continuous-time systems to samples ``u`` (zero initial state).

    Discretised with a first-order hold (exact for piecewise-linear input), so
    the error is O((w dt)^2) — callers keep ``w dt`` small by oversampling.
    """
    y = np.zeros(len(u))
    for num, den in parts:
        bd, ad, _ = signal.cont2discrete((num, den), dt_s, method="foh")
        y += signal.lfilter(np.ravel(bd), ad, u)
    return y


def simulate_linear(parts: list[tuple[np.ndarray, np.ndarray]], drive: Callable[[np.ndarray], np.ndarray],
                    t_abs: np.ndarray, t_start: float, f_max_hz: float,
                    oversample: float = 128.0) -> np.ndarray:
    """Response at the uniformly spaced times ``t_abs`` to ``drive(t)``, at rest at ``t_start``.

    The system is simulated on a grid of at least ``oversample`` samples per
    period of ``f_max_hz``. A record sampled more coarsely than that is read
    off the grid (every k-th sample, as a scope decimates its fast ADC); a
    record sampled more finely is interpolated from the grid with a cubic
    spline (error ~ (w dt)^4 / 384, negligible), so a 1 M-point record of a few
    milliseconds does not cost a 1 M-point-per-millisecond simulation.
    """
    n = len(t_abs)
    xinc = (t_abs[-1] - t_abs[0]) / (n - 1) if n > 1 else 1e-6
    dt_max = 1.0 / (f_max_hz * oversample)
    if xinc > dt_max:
        step = int(np.ceil(xinc / dt_max))
        dt = xinc / step
        n_pre = max(0, int(np.ceil((t_abs[0] - t_start) / dt)))
        grid = t_abs[0] + (np.arange(n_pre + (n - 1) * step + 1) - n_pre) * dt
        y = lti_response(parts, drive(grid), dt)
        return y[n_pre::step][:n]
    from scipy.interpolate import CubicSpline

    dt = dt_max
    n_pre = max(0, int(np.ceil((t_abs[0] - t_start) / dt)))
    n_rec = int(np.ceil((t_abs[-1] - t_abs[0]) / dt)) + 2
    grid = t_abs[0] + (np.arange(n_pre + n_rec) - n_pre) * dt
    y = lti_response(parts, drive(grid), dt)
    keep = slice(max(0, n_pre - 2), None)
    return CubicSpline(grid[keep], y[keep])(t_abs)
