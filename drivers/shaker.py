"""The shaker chain: B&K 2718 power amplifier (declared knobs) and the B&K 4809 envelope.

The 2718 has no remote interface: its gain (20 or 40 dB), input attenuator and
current limit are front-panel knobs. The software never guesses them: they
are declared in the experiment config, recorded in every run file
(:meth:`Amplifier2718.snapshot`) and used to cap the generator's amplitude.

The 4809's envelope rejects a drive before anything is sent:

=================  ==============================
frequency range    10 Hz - 20 kHz
force              44.5 N sine peak
stroke             8 mm peak-to-peak (4 mm peak)
peak velocity      1.65 m/s
moving mass        60 g (+ payload)
=================  ==============================

For a sine of displacement amplitude ``x`` at ``f``: ``v = 2 pi f x``,
``a = (2 pi f)^2 x``, force ``= (m + payload) a``. Below about 66 Hz the
stroke limits, above about 71 Hz the force.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

from labkit import specs
from labkit.errors import ConfigError, LimitError

SQRT2 = math.sqrt(2.0)


@dataclass(frozen=True)
class Amplifier2718:
    """B&K 2718 power amplifier as declared by the person at the bench.

    Parameters
    ----------
    gain_db:
        The gain switch: 20 or 40 dB.
    attenuator_db:
        Input attenuator setting in dB (>= 0).
    current_limit_a:
        Current-limit knob in A (> 0).
    max_input_vrms:
        Cap on the amplifier's input (V rms). Default: 0.8 V rms at 20 dB and
        ten times less at 40 dB (a public rig's values), overridable. The cap
        applies to the input regardless of the attenuator (conservative).
    """

    gain_db: float
    attenuator_db: float
    current_limit_a: float
    max_input_vrms: float | None = None
    model: str = field(default="B&K 2718", init=False)

    def __post_init__(self) -> None:
        if self.gain_db not in (20, 40):
            raise ConfigError(f"2718 gain {self.gain_db!r} dB is not a switch position",
                              key="gain_db", expected="20 or 40")
        if not (isinstance(self.attenuator_db, (int, float)) and self.attenuator_db >= 0):
            raise ConfigError(f"2718 attenuator {self.attenuator_db!r}", key="attenuator_db",
                              expected="a number of dB >= 0")
        if not (isinstance(self.current_limit_a, (int, float)) and self.current_limit_a > 0):
            raise ConfigError(f"2718 current limit {self.current_limit_a!r}", key="current_limit_a",
                              expected="a current in A > 0")
        if self.max_input_vrms is None:
            object.__setattr__(self, "max_input_vrms", 0.8 if self.gain_db == 20 else 0.08)
        elif not self.max_input_vrms > 0:
            raise ConfigError(f"max_input_vrms {self.max_input_vrms!r}", key="max_input_vrms",
                              expected="V rms > 0")

    @property
    def voltage_gain(self) -> float:
        """Output volts per input volt, attenuator included."""
        return 10 ** ((self.gain_db - self.attenuator_db) / 20.0)

    @property
    def max_input_vpp(self) -> float:
        """The input cap for a sine, in volts peak-to-peak (``2 sqrt 2 * Vrms``)."""
        return 2 * SQRT2 * self._cap_vrms

    @property
    def _cap_vrms(self) -> float:
        # max_input_vrms is None only until __post_init__ fills in the gain's default.
        assert self.max_input_vrms is not None
        return float(self.max_input_vrms)

    def check_input(self, amp_vpp: float) -> float:
        """Return ``amp_vpp`` if a sine of that size may be fed to the input, else LimitError."""
        v = float(amp_vpp)
        vrms = v / (2 * SQRT2)
        if not (v >= 0 and vrms <= self._cap_vrms * (1 + 1e-12)):
            raise LimitError(f"{v:g} Vpp ({vrms:.3g} V rms) exceeds the 2718 input cap "
                             f"{self.max_input_vrms:g} V rms at {self.gain_db:g} dB; "
                             "nothing was sent",
                             limit="amplifier input cap")
        return v

    def snapshot(self) -> dict[str, Any]:
        """The declared settings, for the run file."""
        return {"model": self.model, "declared": True, **{k: v for k, v in asdict(self).items()
                                                          if k != "model"},
                "voltage_gain": self.voltage_gain, "max_input_vpp": self.max_input_vpp}


@dataclass(frozen=True)
class Shaker4809Envelope:
    """The B&K 4809's operating envelope; :meth:`check` rejects a drive outside it."""

    freq_min_hz: float = specs.BK4809_FREQ_MIN_HZ
    freq_max_hz: float = specs.BK4809_FREQ_MAX_HZ
    force_peak_n: float = specs.BK4809_FORCE_PEAK_N
    stroke_peak_mm: float = specs.BK4809_STROKE_PEAK_MM
    velocity_peak_m_s: float = specs.BK4809_VELOCITY_PEAK_M_S
    moving_mass_kg: float = specs.BK4809_MOVING_MASS_KG
    model: str = field(default="B&K 4809", init=False)

    def check(self, freq_hz: float, disp_amp_um: float,
              payload_kg: float = 0.0) -> dict[str, float]:
        """Check a sine of displacement amplitude ``disp_amp_um`` (peak) at ``freq_hz``.

        Returns the fraction of each limit used; raises LimitError whose
        ``limit`` is ``"frequency"``, ``"stroke"``, ``"velocity"`` or ``"force"``.
        """
        f = float(freq_hz)
        x_m = float(disp_amp_um) * 1e-6
        m = self.moving_mass_kg + float(payload_kg)
        if not (math.isfinite(f) and math.isfinite(x_m) and x_m >= 0 and payload_kg >= 0):
            raise LimitError(f"bad drive: freq_hz={freq_hz!r}, disp_amp_um={disp_amp_um!r}, "
                             f"payload_kg={payload_kg!r}", limit="frequency")
        if not self.freq_min_hz <= f <= self.freq_max_hz:
            raise LimitError(f"{f:g} Hz is outside the 4809 frequency range "
                             f"{self.freq_min_hz:g}-{self.freq_max_hz:g} Hz; nothing was sent",
                             limit="frequency")
        w = 2 * math.pi * f
        used = {"stroke": x_m * 1e3 / self.stroke_peak_mm,
                "velocity": w * x_m / self.velocity_peak_m_s,
                "force": m * w * w * x_m / self.force_peak_n}
        values = {"stroke": (x_m * 1e3, self.stroke_peak_mm, "mm peak"),
                  "velocity": (w * x_m, self.velocity_peak_m_s, "m/s peak"),
                  "force": (m * w * w * x_m, self.force_peak_n,
                            f"N peak (moving mass {m * 1e3:g} g)")}
        for name in ("stroke", "velocity", "force"):
            if used[name] > 1.0 + 1e-12:
                val, lim, unit = values[name]
                short = unit.split(" (")[0]
                raise LimitError(f"{disp_amp_um:g} um at {f:g} Hz needs {val:.4g} {short}"
                                 f", over the 4809 {name} limit {lim:g} {unit}; nothing was sent",
                                 limit=name)
        return used

    def max_disp_amp_um(self, freq_hz: float, payload_kg: float = 0.0) -> float:
        """The largest displacement amplitude (um, peak) the envelope allows at ``freq_hz``."""
        w = 2 * math.pi * float(freq_hz)
        m = self.moving_mass_kg + float(payload_kg)
        return 1e6 * min(self.stroke_peak_mm * 1e-3, self.velocity_peak_m_s / w,
                         self.force_peak_n / (m * w * w))

    def snapshot(self) -> dict[str, Any]:
        return asdict(self)
