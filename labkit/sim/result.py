"""SimResult: one simulated run, its summary and its HDF5 file (kind ``sim_result``)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from labkit.sim.model import MODE_NAMES

#: Per-foot motion patterns (paper Fig. 9-11), defined from what the foot does
#: (docs/model.md section "Pattern labels").
PATTERNS = ("firm_contact", "partial_contact", "jumping")
#: A foot is in firm contact when it spends less than this fraction of the time in the air ...
FIRM_AIR_FRACTION = 0.01
#: ... or when it never rises more than this above the ground (um): it follows the tray.
FLIGHT_MIN_UM = 0.1
#: A foot is jumping when one of its flights lasts longer than this many drive periods.
JUMP_PERIODS = 1.0
#: Periodicity: the foot's height repeats after k drive periods (k = 1 or 2) when, over
#: the last PERIODIC_CYCLES periods, it differs from k periods before by less than
#: PERIODIC_TOL of its range (or the range is below FLIGHT_MIN_UM).
PERIODIC_TOL = 0.05
PERIODIC_CYCLES = 5

if TYPE_CHECKING:
    from labkit.sim.excitation import PZT, Shaker
    from labkit.sim.params import RobotParams


def classify_pattern(air_fraction: float, max_flight_s: float, drive_period_s: float,
                     max_height_um: float = math.inf) -> str:
    """Pattern label of one foot: firm_contact | partial_contact | jumping.

    ``firm_contact``: in the air less than :data:`FIRM_AIR_FRACTION` of the time, or
    never higher than :data:`FLIGHT_MIN_UM` above the ground (it follows the tray);
    ``jumping``: some flight longer than :data:`JUMP_PERIODS` drive periods;
    otherwise ``partial_contact`` (held part of each cycle, then it lets go and rises).
    """
    if air_fraction < FIRM_AIR_FRACTION or max_height_um < FLIGHT_MIN_UM:
        return "firm_contact"
    if max_flight_s > JUMP_PERIODS * drive_period_s:
        return "jumping"
    return "partial_contact"


def foot_period(t_s: np.ndarray, height_um: np.ndarray, drive_period_s: float, t_from_s: float = 0.0) -> int:
    """1 or 2 if a foot's height (samples at ``t_s``) repeats after that many drive periods
    over the last :data:`PERIODIC_CYCLES` periods after ``t_from_s`` (compared at 40 phases
    per period, linearly interpolated); 0 if it does not, or the run is too short."""
    n = 40
    t_end = float(t_s[-1]) if len(t_s) else 0.0
    for k in (1, 2):
        t0 = t_end - (PERIODIC_CYCLES + k) * drive_period_s
        if t0 < t_from_s or len(t_s) < 3:
            return 0
        grid = t0 + np.arange((PERIODIC_CYCLES + k) * n + 1) * (drive_period_s / n)
        x = np.interp(grid, t_s, height_um)
        rng = float(np.ptp(x))
        diff = float(np.abs(x[k * n:] - x[:-k * n]).max())
        if rng < FLIGHT_MIN_UM or diff < PERIODIC_TOL * rng:
            return k
    return 0


@dataclass
class SimResult:
    """One simulated run (arrays sampled every ``record_dt_s``).

    Attributes (units in the names): ``t_s``; ``body_y_um`` (forward),
    ``body_z_um`` (height of the body's underside above the ground's rest
    level), ``body_angles_rad`` (N, 3: phi_x, phi_y, phi_z); per foot (N, 6)
    ``foot_z_um`` (height above the ground's rest level), ``foot_y_um``,
    ``contact`` (int8: 0 AIR, 1 ADHESION, 2 REST), ``knee_vz_mm_s`` (absolute
    vertical velocity of the knee: what a vibrometer sees); ``ground_z_um``;
    ``mean_speed_mm_s`` (signed along +y, net displacement after the start-up
    transient over the time after it); ``contact_fraction`` (``"leg1"`` ..
    ``"leg6"`` -> ``{"air", "adhesion", "rest"}`` -> fraction of the time
    after the transient); ``impacts`` (6,), ``body_impacts``; ``patterns``
    (:func:`classify_pattern`), ``max_height_um`` (highest flight per foot above the
    ground after the transient), ``foot_periods`` (1 or 2: the foot's motion repeats
    after that many drive periods; 0: it does not, :func:`foot_period`); ``patterns``
    (6 labels); ``events`` (impact log: t_s, leg (0-5, -1 body), relative
    vertical velocity before/after the map in m/s, lateral velocity after,
    stuck flag).
    """

    params: RobotParams
    scenario: Shaker | PZT
    duration_s: float
    dt_s: float
    record_dt_s: float
    transient_s: float
    engine: str
    t_s: np.ndarray
    body_y_um: np.ndarray
    body_z_um: np.ndarray
    body_angles_rad: np.ndarray
    foot_z_um: np.ndarray
    foot_y_um: np.ndarray
    contact: np.ndarray
    knee_vz_mm_s: np.ndarray
    ground_z_um: np.ndarray
    mean_speed_mm_s: float
    contact_fraction: dict
    impacts: np.ndarray
    body_impacts: int
    patterns: list
    max_flight_s: np.ndarray
    events: np.ndarray
    n_steps: int
    wall_s: float
    seed: int | None = None
    ablation: str | None = None
    counters: dict = field(default_factory=dict)
    max_height_um: np.ndarray | None = None
    foot_periods: list | None = None

    def summary(self) -> dict[str, Any]:
        """JSON-able key figures."""
        return {
            "scenario": self.scenario.to_dict(),
            "engine": self.engine,
            "duration_s": self.duration_s,
            "dt_s": self.dt_s,
            "record_dt_s": self.record_dt_s,
            "transient_s": self.transient_s,
            "n_steps": int(self.n_steps),
            "wall_s": round(float(self.wall_s), 4),
            "mean_speed_mm_s": float(self.mean_speed_mm_s),
            "contact_fraction": {f: {k: round(float(v), 6) for k, v in d.items()}
                                 for f, d in self.contact_fraction.items()},
            "impacts": [int(x) for x in self.impacts],
            "body_impacts": int(self.body_impacts),
            "patterns": list(self.patterns),
            "max_flight_s": [float(x) for x in self.max_flight_s],
            "max_height_um": None if self.max_height_um is None else [float(x) for x in self.max_height_um],
            "foot_periods": None if self.foot_periods is None else [int(k) for k in self.foot_periods],
            "seed": self.seed,
            "ablation": self.ablation,
        }

    def to_h5(self, path: str | Path) -> Path:
        """Write the run (kind ``sim_result``): units on every dataset, params as TOML text."""
        import h5py

        from labkit.h5io import label_dimensions, put, put_json, stamp

        path = Path(path)
        with h5py.File(path, "w") as f:
            stamp(f, "sim_result")
            f.attrs["params_toml"] = self.params.to_toml_text()
            put_json(f, "scenario_json", self.scenario.to_dict())
            put_json(f, "summary_json", self.summary())
            f.attrs["contact_codes"] = "0 air, 1 adhesion, 2 rest"
            put(f, "t_s", self.t_s, "s")
            put(f, "body_y_um", self.body_y_um, "um")
            put(f, "body_z_um", self.body_z_um, "um")
            put(f, "body_angles_rad", self.body_angles_rad, "rad", columns="phi_x, phi_y, phi_z", axes="t_s, axis")
            put(f, "foot_z_um", self.foot_z_um, "um", axes="t_s, leg")
            put(f, "foot_y_um", self.foot_y_um, "um", axes="t_s, leg")
            put(f, "contact", self.contact, "label", codes="0 air, 1 adhesion, 2 rest", axes="t_s, leg")
            put(f, "knee_vz_mm_s", self.knee_vz_mm_s, "mm/s", axes="t_s, leg")
            put(f, "ground_z_um", self.ground_z_um, "um")
            put(f, "impacts", np.asarray(self.impacts), "1", axes="leg")
            put(f, "max_flight_s", np.asarray(self.max_flight_s), "s", axes="leg")
            frac = np.array([[self.contact_fraction[f"leg{j + 1}"][m] for m in MODE_NAMES] for j in range(6)])
            put(f, "contact_fraction", frac, "1", columns=", ".join(MODE_NAMES), axes="leg, mode")
            put(f, "events", self.events, "mixed", axes="event, field",
                columns="t_s, leg (0-5; -1 body), vrel_pre_m_s, vrel_post_m_s, vy_post_m_s, stuck")
            f.attrs["mean_speed_mm_s"] = float(self.mean_speed_mm_s)
            put_json(f, "patterns", list(self.patterns))
            label_dimensions(f)     # t_s as the coordinate (xarray, HDFView)
        return path
