"""The paper's shaker as an amplitude law: tray displacement vs frequency at a constant drive.

The paper's Fig. 8 is a frequency sweep of a B&K 4809 vibration exciter driven
through a B&K 2718 power amplifier at a fixed generator voltage (Sec. 4.3: "the
vibration velocity from the shaker decreases with frequency"; Sec. 5.1: "maximum
amplitudes achievable by the shaker become smaller" at high frequency). A
constant 25 um up to 2 kHz would need 100 g at 1 kHz, beyond the 4809's force
rating with its own 60 g moving element. This module is the law the scenarios
use instead, built from the instruments' specifications, not fitted to the
robot's behaviour.

Sources (numbers restated here because :mod:`labkit.sim` may not import the
instrument drivers; the same values are in ``drivers/shaker.py`` and
``docs/instruments.md``):

====================================  ==========  ===============================================
quantity                              value       source
====================================  ==========  ===============================================
force rating (sine peak)              44.5 N      4809 product data; docs/instruments.md
moving element mass                   60 g        4809 product data; docs/instruments.md
stroke (overtravel stops)             8 mm p-p    4809 instruction manual, Sec. 2 (0.315 in)
peak velocity                         1.65 m/s    4809 product data; docs/instruments.md
constant-voltage response             see below   4809 instruction manual, Sec. 3.1, Fig. 3.1
suspension resonance                  ~150 Hz     same: "a damped peak at about 150 Hz ... the
                                                  suspension resonance of the Exciter"
mass-controlled band                  flat accel  same: "the acceleration level then remains
                                                  constant from 700 to 5000 Hz"
====================================  ==========  ===============================================

The law, at generator amplitude ``V`` (the paper's "2-8 V peak-to-peak"):

* Above the suspension resonance an electrodynamic exciter on a voltage-driven
  amplifier (the 2718) is mass controlled: coil current, hence force, hence
  **acceleration**, is constant at constant voltage. Below it the flexures
  take the force and the acceleration falls as ``f^2``. A second-order
  high-pass in acceleration reproduces Fig. 3.1's shape::

      a(f) = a_inf * V / V_ref * f^2 / |f^2 - f_s^2 + 2 j zeta f_s f|

  with ``f_s = suspension_hz`` (150 Hz) and ``zeta = suspension_damping_ratio``
  (0.5, a **choice**: the manual calls the peak "damped" and the flexures
  "highly damped", without a number).
* Displacement ``x = a / (2 pi f)^2``: falls as ``1/f^2`` in the mass-controlled band.
* ``a_inf`` is fixed by the paper's one stated operating point: 25 um at
  240 Hz (Sec. 5.1), taken at 8 V peak-to-peak (a **choice**: Sec. 5.2 measures
  the jumping pattern "at a temporary pause within robot lateral in-tray
  motions when the shaker is actuated at 8 V", and 25 um is the amplitude of
  those lateral motions). The amplitude is proportional to ``V`` (the chain is
  linear below its limits), so 2, 4, 6, 8 V give 6.25, 12.5, 18.75, 25 um at 240 Hz.
* Every point is then capped by the 4809's envelope: stroke 4 mm peak,
  velocity 1.65 m/s, force 44.5 N / (60 g + tray). The tray's mass is not in
  the paper (``tray_mass_kg``, default 0: the cap is then the bare table's,
  75.6 g); at the paper's drive the cap never binds between 100 Hz and 2 kHz,
  it matters only for drives far above the paper's (``limited_by`` says which
  limit set a point).

The law gives 25 um at 240 Hz, 36.2 um at 200 Hz, 55.9 um at 150 Hz, 5.25 um at
500 Hz, 1.27 um at 1 kHz and 0.39 um at 1.8 kHz at 8 V (5.1-5.8 g throughout):
:data:`PAPER_SHAKER`.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TypedDict

from labkit import specs
from labkit.errors import InputError

G0_M_S2 = 9.80665


@dataclass(frozen=True)
class ShakerLaw:
    """Tray displacement amplitude of a 4809-on-2718 shaker vs frequency at a constant drive."""

    ref_freq_hz: float = 240.0
    ref_amp_um: float = 25.0
    ref_drive_vpp: float = 8.0
    suspension_hz: float = 150.0
    suspension_damping_ratio: float = 0.5
    force_peak_n: float = specs.BK4809_FORCE_PEAK_N
    moving_mass_kg: float = specs.BK4809_MOVING_MASS_KG
    tray_mass_kg: float = 0.0
    stroke_peak_mm: float = specs.BK4809_STROKE_PEAK_MM
    velocity_peak_m_s: float = specs.BK4809_VELOCITY_PEAK_M_S

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            ok = math.isfinite(value) and (value >= 0 if name in ("tray_mass_kg", "suspension_hz") else value > 0)
            if not ok:
                raise InputError(f"shaker law: {name} = {value!r}", key=name, expected="a finite number > 0")

    def shape(self, freq_hz: float) -> float:
        """``|f^2 / (f^2 - f_s^2 + 2 j zeta f_s f)|``: acceleration per volt relative to the mass-controlled band."""
        f, fs, z = float(freq_hz), self.suspension_hz, self.suspension_damping_ratio
        if fs == 0:
            return 1.0
        return f * f / math.hypot(f * f - fs * fs, 2 * z * fs * f)

    @property
    def accel_inf_m_s2_per_v(self) -> float:
        """Acceleration amplitude per volt (peak-to-peak) in the mass-controlled band."""
        w = 2 * math.pi * self.ref_freq_hz
        a_ref = self.ref_amp_um * 1e-6 * w * w
        return a_ref / self.shape(self.ref_freq_hz) / self.ref_drive_vpp

    def envelope_um(self, freq_hz: float) -> float:
        """The largest amplitude the 4809 allows at ``freq_hz`` (stroke, velocity, force), um."""
        w = 2 * math.pi * float(freq_hz)
        m = self.moving_mass_kg + self.tray_mass_kg
        return 1e6 * min(self.stroke_peak_mm * 1e-3, self.velocity_peak_m_s / w, self.force_peak_n / (m * w * w))

    def drive_amp_um(self, freq_hz: float, drive_vpp: float | None = None) -> float:
        """The amplitude the drive asks for, before the envelope cap, um."""
        f = float(freq_hz)
        if not (math.isfinite(f) and f > 0):
            raise InputError(f"bad frequency {freq_hz!r}", key="freq_hz", expected="a frequency in Hz, > 0")
        v = self.ref_drive_vpp if drive_vpp is None else float(drive_vpp)
        if not (math.isfinite(v) and v >= 0):
            raise InputError(f"bad drive {drive_vpp!r}", key="drive_vpp", expected="a voltage in V p-p, >= 0")
        w = 2 * math.pi * f
        return 1e6 * self.accel_inf_m_s2_per_v * v * self.shape(f) / (w * w)

    def amp_um(self, freq_hz: float, drive_vpp: float | None = None) -> float:
        """Tray displacement amplitude (um, peak) at ``freq_hz`` for a generator amplitude ``drive_vpp``."""
        return min(self.drive_amp_um(freq_hz, drive_vpp), self.envelope_um(freq_hz))

    def limited_by(self, freq_hz: float, drive_vpp: float | None = None) -> str:
        """``"drive"`` when the drive sets the amplitude, else the envelope limit that cuts it."""
        want = self.drive_amp_um(freq_hz, drive_vpp)
        if want <= self.envelope_um(freq_hz):
            return "drive"
        w = 2 * math.pi * float(freq_hz)
        m = self.moving_mass_kg + self.tray_mass_kg
        caps = {"stroke": self.stroke_peak_mm * 1e3, "velocity": self.velocity_peak_m_s / w * 1e6,
                "force": self.force_peak_n / (m * w * w) * 1e6}
        return min(caps, key=lambda k: caps[k])

    def accel_g(self, freq_hz: float, drive_vpp: float | None = None) -> float:
        """Peak tray acceleration at that point, in g."""
        w = 2 * math.pi * float(freq_hz)
        return self.amp_um(freq_hz, drive_vpp) * 1e-6 * w * w / G0_M_S2

    def describe(self) -> ShakerLawDescription:
        """The law's settings (for scenario results and parameter provenance)."""
        return ShakerLawDescription(
            law="constant drive: mass-controlled 4809 on a 2718, 2nd-order suspension, envelope cap",
            ref_freq_hz=self.ref_freq_hz, ref_amp_um=self.ref_amp_um, ref_drive_vpp=self.ref_drive_vpp,
            suspension_hz=self.suspension_hz, suspension_damping_ratio=self.suspension_damping_ratio,
            force_peak_n=self.force_peak_n, moving_mass_kg=self.moving_mass_kg, tray_mass_kg=self.tray_mass_kg,
            stroke_peak_mm=self.stroke_peak_mm, velocity_peak_m_s=self.velocity_peak_m_s)


class ShakerLawDescription(TypedDict):
    """:meth:`ShakerLaw.describe` (JSON in scenario results)."""

    law: str
    ref_freq_hz: float
    ref_amp_um: float
    ref_drive_vpp: float
    suspension_hz: float
    suspension_damping_ratio: float
    force_peak_n: float
    moving_mass_kg: float
    tray_mass_kg: float
    stroke_peak_mm: float
    velocity_peak_m_s: float


class TableLawDescription(TypedDict):
    """:meth:`TableLaw.describe` (JSON in scenario results)."""

    law: str
    source: str
    ref_drive_vpp: float
    freq_hz: list[float]
    amp_um: list[float]


#: The paper's shaker: 25 um at 240 Hz and 8 V p-p, 4809 suspension and envelope.
PAPER_SHAKER = ShakerLaw()


@dataclass(frozen=True)
class TableLaw:
    """A tray amplitude law from data: a measured amplitude per frequency at one drive (e.g. a
    ``labkit shaker`` transmissibility run, or the paper's Fig. 6 tray velocity read off), linear
    in the drive, interpolated log-log between the table's frequencies (none outside them)."""

    freqs_hz: tuple[float, ...]
    amps_um: tuple[float, ...]
    ref_drive_vpp: float = 8.0
    source: str = ""

    def __post_init__(self) -> None:
        f, a = self.freqs_hz, self.amps_um
        if len(f) < 2 or len(f) != len(a):
            raise InputError(f"tray law {self.source}: {len(f)} frequencies, {len(a)} amplitudes", key="freq_hz",
                             expected="two or more (frequency, amplitude) pairs")
        if any(not (math.isfinite(x) and x > 0) for x in (*f, *a)) or any(y <= x for x, y in zip(f, f[1:])):
            raise InputError(f"tray law {self.source}: frequencies must increase and all values be > 0",
                             key="freq_hz/amp_um", expected="increasing frequencies (Hz) and amplitudes (um) > 0")
        if not (math.isfinite(self.ref_drive_vpp) and self.ref_drive_vpp > 0):
            raise InputError(f"tray law {self.source}: drive {self.ref_drive_vpp!r}", key="drive_vpp",
                             expected="the table's drive in V p-p, > 0")

    def amp_um(self, freq_hz: float, drive_vpp: float | None = None) -> float:
        """Tray amplitude (um) at ``freq_hz`` for the drive ``drive_vpp`` (default: the table's)."""
        f = float(freq_hz)
        if not (self.freqs_hz[0] <= f <= self.freqs_hz[-1]):
            raise InputError(f"tray law {self.source}: {f:g} Hz is outside the table "
                             f"({self.freqs_hz[0]:g}-{self.freqs_hz[-1]:g} Hz)", key="freq_hz",
                             expected=f"a frequency in {self.freqs_hz[0]:g}-{self.freqs_hz[-1]:g} Hz")
        lf = [math.log(x) for x in self.freqs_hz]
        la = [math.log(x) for x in self.amps_um]
        k = max(i for i in range(len(lf) - 1) if lf[i] <= math.log(f)) if f < self.freqs_hz[-1] else len(lf) - 2
        t = (math.log(f) - lf[k]) / (lf[k + 1] - lf[k])
        v = self.ref_drive_vpp if drive_vpp is None else float(drive_vpp)
        return math.exp(la[k] + t * (la[k + 1] - la[k])) * v / self.ref_drive_vpp

    def describe(self) -> TableLawDescription:
        """The table and its source (for scenario results)."""
        return TableLawDescription(law="table", source=self.source, ref_drive_vpp=self.ref_drive_vpp,
                                   freq_hz=list(self.freqs_hz), amp_um=list(self.amps_um))


def load_tray_law(path: str) -> TableLaw:
    """A :class:`TableLaw` from a CSV file (columns ``freq_hz,amp_um``, ``#`` comments, one optional
    header line; the drive in a ``# drive_vpp = X`` comment, default 8) or a TOML file
    (``freq_hz = [...]``, ``amp_um = [...]``, optional ``drive_vpp``). Errors name the file."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"no such file: {p}", key="tray law", expected="a CSV or TOML file of freq_hz, amp_um")
    if p.suffix.lower() == ".toml":
        from labkit.tomlio import load_toml

        table, _ = load_toml(p)
        try:
            return TableLaw(tuple(float(x) for x in table["freq_hz"]), tuple(float(x) for x in table["amp_um"]),
                            float(table.get("drive_vpp", 8.0)), str(p))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{p}: {exc!r}", key="freq_hz/amp_um",
                             expected="freq_hz = [...] and amp_um = [...] (numbers)") from None
    freqs: list[float] = []
    amps: list[float] = []
    drive = 8.0
    for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1):
        text = line.strip()
        if text.startswith("#") and "drive_vpp" in text and "=" in text:
            drive = _number(text.split("=", 1)[1], p, n)
        if not text or text.startswith("#") or (not freqs and text.lower().startswith("freq")):
            continue
        cells = [c.strip() for c in text.split(",")]
        if len(cells) < 2:
            raise InputError(f"{p}: line {n} has {len(cells)} column(s)", key=f"line {n}",
                             expected="freq_hz,amp_um")
        freqs.append(_number(cells[0], p, n))
        amps.append(_number(cells[1], p, n))
    return TableLaw(tuple(freqs), tuple(amps), drive, str(p))


def _number(text: str, path: Path, line: int) -> float:
    try:
        return float(text)
    except ValueError:
        raise InputError(f"{path}: line {line}: not a number: {text.strip()!r}", key=f"line {line}",
                         expected="a number") from None
