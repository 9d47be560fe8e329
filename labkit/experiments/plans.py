"""Plans: plain descriptions of an experiment's steps (Bluesky style) that never touch hardware.

A plan is an ordered tuple of immutable steps; the one runner
(:mod:`labkit.experiments.runner`) executes them and alone owns the
instruments and their safe shutdown. Plans are built from a validated config
and the set of plan indices already finished (``done``), so a resumed run
continues after its last complete point without repeating one.

Steps
-----
:class:`MoveSpot`
    point the laser vibrometer at ``spot`` (the runner turns the drive off
    first, then asks the person, or tells the virtual lab).
:class:`SinePoint`
    one stepped-sine point of an in-chip sweep.
:class:`ChirpPoint`
    one chirp measurement (all frequencies of a location at once).
:class:`ShakerPoint`
    one grid point of a shaker run (tray measurement, drive adjustment,
    robot measurement, optional video).
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from labkit.experiments.config import InchipConfig, ShakerConfig

#: Per-point time the runner needs beyond settle and dwell (estimate, for the progress bar).
OVERHEAD_S = 0.02


@dataclass(frozen=True)
class MoveSpot:
    spot: str


@dataclass(frozen=True)
class SinePoint:
    index: int
    location: str
    freq_hz: float
    amp_vpp: float
    offset_v: float
    settle_s: float
    dwell_s: float

    @property
    def est_s(self) -> float:
        return self.settle_s + self.dwell_s + OVERHEAD_S


@dataclass(frozen=True)
class ChirpPoint:
    index: int
    location: str
    start_hz: float
    stop_hz: float
    spacing: str            # "LIN" | "LOG"
    length_s: float
    averages: int
    amp_vpp: float
    offset_v: float

    @property
    def est_s(self) -> float:
        return self.averages * (self.length_s + 0.1) + OVERHEAD_S


@dataclass(frozen=True)
class ShakerPoint:
    index: int
    freq_hz: float
    tray_amp_um: float | None     # requested tray displacement amplitude, or ...
    drive_vpp: float | None       # ... a fixed drive
    robot_spot: str
    settle_s: float
    dwell_s: float
    video_s: float
    max_iterations: int

    @property
    def est_s(self) -> float:
        tries = 3 if self.tray_amp_um is not None else 1
        return (tries + 1) * (self.settle_s + self.dwell_s + OVERHEAD_S) + self.video_s


Step = MoveSpot | SinePoint | ChirpPoint | ShakerPoint
Point = SinePoint | ChirpPoint | ShakerPoint


@dataclass(frozen=True)
class Plan:
    """An ordered tuple of steps, with what the progress bar needs."""

    kind: str                     # "inchip" | "shaker"
    steps: tuple[Step, ...]
    points_total: int             # points in the whole run (done ones included)

    @property
    def points(self) -> tuple[Point, ...]:
        return tuple(s for s in self.steps if not isinstance(s, MoveSpot))

    @property
    def est_s(self) -> float:
        return sum(p.est_s for p in self.points)


def inchip_plan(cfg: InchipConfig, done: Iterable[int] = ()) -> Plan:
    """Location by location (one laser move each), every frequency in order.

    Plan indices are ``location_number * n_freqs + freq_number`` for stepped
    sine and ``location_number`` for chirps, stable across resumes.
    """
    done = set(done)
    steps: list[Step] = []
    m = cfg.method
    if m.kind == "chirp":
        f0, f1 = min(cfg.freqs_hz), max(cfg.freqs_hz)
        # A log-spaced frequency list asks for a log sweep (constant time per decade).
        spacing = "LOG" if len(cfg.freqs_hz) > 2 and _is_log(cfg.freqs_hz) else "LIN"
        for i, loc in enumerate(cfg.locations):
            if i in done:
                continue
            steps += [MoveSpot(loc), ChirpPoint(i, loc, f0, f1, spacing, m.length_s, m.averages,
                                                cfg.amp_vpp, cfg.offset_v)]
        return Plan("inchip", tuple(steps), len(cfg.locations))
    n = len(cfg.freqs_hz)
    for i, loc in enumerate(cfg.locations):
        pts = [SinePoint(i * n + j, loc, f, cfg.amp_vpp, cfg.offset_v, m.settle_time_s(f), m.dwell_time_s(f))
               for j, f in enumerate(cfg.freqs_hz) if i * n + j not in done]
        if pts:
            steps.append(MoveSpot(loc))
            steps.extend(pts)
    return Plan("inchip", tuple(steps), n * len(cfg.locations))


def shaker_plan(cfg: ShakerConfig, done: Iterable[int] = ()) -> Plan:
    """Frequency by frequency, amplitudes rising (the drive estimate carries over upward).

    Plan index is ``freq_number * n_amplitudes + amplitude_number`` in the
    config's order; the laser moves between tray and robot inside each point.
    """
    done = set(done)
    m = cfg.method
    amps = list(cfg.amplitudes)
    order = sorted(range(len(amps)), key=lambda k: amps[k])
    steps: list[Step] = []
    for i, f in enumerate(cfg.freqs_hz):
        for k in order:
            idx = i * len(amps) + k
            if idx in done:
                continue
            tray = amps[k] if cfg.amplitude_kind == "tray_amp_um" else None
            drive = amps[k] if cfg.amplitude_kind == "drive_vpp" else None
            steps.append(ShakerPoint(idx, f, tray, drive, cfg.robot_spot, m.settle_time_s(f), m.dwell_time_s(f),
                                     cfg.video_s, cfg.control.max_iterations))
    return Plan("shaker", tuple(steps), len(cfg.freqs_hz) * len(amps))


def _is_log(freqs: tuple[float, ...]) -> bool:
    import numpy as np

    f = np.asarray(sorted(freqs))
    if f[0] <= 0:
        return False
    r = f[1:] / f[:-1]
    d = np.diff(f)
    return bool(np.ptp(r) < 1e-6 * r.mean() and np.ptp(d) > 1e-6 * d.mean())
