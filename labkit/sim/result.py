"""SimResult: one simulated run, its summary and its HDF5 file (kind ``sim_result``)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

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

#: Validity (:class:`Validity`): the model is written for small body angles (sin phi = phi,
#: cos phi = 1: 0.17 % and 0.5 % off at this bound, rad) ...
SMALL_ANGLE_RAD = 0.1
#: ... a body "on its film" is closer to the ground than this fraction of its resting gap ...
ON_FILM_FRACTION = 0.1
#: ... and a jump is "beyond the legs' reach" when the body's underside rises more than this
#: many body lengths above the ground (the robot tumbles; nothing in the model can land it).
JUMP_BODY_LENGTHS = 1.0


class ValiditySummary(TypedDict):
    """:meth:`Validity.summary`."""

    flags: list[str]
    max_tilt_rad: float
    small_angle_bound_rad: float
    body_edge_gap_um: float
    edge_tolerance_um: float
    body_on_film_feet_up_fraction: float
    max_jump_um: float
    jump_limit_um: float
    events_lost: int
    steps_event_capped: int
    chaotic: bool | None
    not_converged: bool


class ConvergenceSummary(TypedDict):
    """:meth:`Convergence.summary` (NaN written as None)."""

    status: str
    dt_s: float
    default_dt_s: float
    step_error_mm_s: float | None
    tolerance_mm_s: float | None
    seed_spread_mm_s: float | None
    measured_s: list[float]
    halvings: int
    speeds_per_step_mm_s: list[float]
    wall_s: float
    basis: str


class SimResultSummary(TypedDict):
    """:meth:`SimResult.summary`: a run's key figures (a ``sim_result`` file's ``summary_json``)."""

    scenario: dict[str, float | str]
    engine: str
    duration_s: float
    dt_s: float
    record_dt_s: float
    transient_s: float
    n_steps: int
    wall_s: float
    mean_speed_mm_s: float
    contact_fraction: dict[str, dict[str, float]]
    impacts: list[int]
    body_impacts: int
    patterns: list[str]
    max_flight_s: list[float]
    max_height_um: list[float] | None
    foot_periods: list[int] | None
    seed: int | None
    ablation: str | None
    validity: ValiditySummary | None
    convergence: ConvergenceSummary | None


@dataclass
class Validity:
    """Where a run left what the model assumes (docs/model.md, "Error control and validity").

    ``max_tilt_rad``: the largest |phi_x| or |phi_y| (flag ``small_angle`` beyond
    :data:`SMALL_ANGLE_RAD`); ``body_edge_gap_um``: the lowest gap under the body's edge
    (centre gap minus half the width times |phi_y| and half the length times |phi_x|; the
    body's film and impacts act at its centre only: flag ``body_edge_contact`` below minus
    ``edge_tolerance_um``, the film's floor h_min, under which the film law does not resolve gaps);
    ``body_on_film_feet_up_fraction``: the time the body lies on its film (gap below
    :data:`ON_FILM_FRACTION` of its resting gap) with all six feet in the air (flag
    ``body_on_film_feet_up``); ``max_jump_um``: the body's highest gap (flag ``high_jump`` above
    :data:`JUMP_BODY_LENGTHS` body lengths); ``events_lost``: impacts beyond the event log's
    capacity (counted, not logged; flag ``event_log_full``); ``steps_event_capped``: steps
    that met more events than a step may locate (flag ``event_cap``); ``chaotic``: runs from
    slightly different starts spread beyond the agreement tolerance (``None``: not probed;
    :func:`labkit.sim.core.dt_check`, sweeps' checks)."""

    max_tilt_rad: float
    body_edge_gap_um: float
    body_on_film_feet_up_fraction: float
    max_jump_um: float
    jump_limit_um: float
    edge_tolerance_um: float = 0.0
    events_lost: int = 0
    steps_event_capped: int = 0
    chaotic: bool | None = None
    not_converged: bool = False

    @property
    def flags(self) -> list[str]:
        """The names of the assumptions the run left (empty: none)."""
        out = []
        if self.max_tilt_rad > SMALL_ANGLE_RAD:
            out.append("small_angle")
        if self.body_edge_gap_um < -self.edge_tolerance_um:
            out.append("body_edge_contact")
        if self.body_on_film_feet_up_fraction > 0:
            out.append("body_on_film_feet_up")
        if self.max_jump_um > self.jump_limit_um:
            out.append("high_jump")
        if self.events_lost:
            out.append("event_log_full")
        if self.steps_event_capped:
            out.append("event_cap")
        if self.chaotic:
            out.append("chaotic")
        if self.not_converged:
            out.append("not_converged")
        return out

    def summary(self) -> ValiditySummary:
        """JSON-able: every figure and ``flags``."""
        return {"flags": self.flags, "max_tilt_rad": float(self.max_tilt_rad),
                "small_angle_bound_rad": SMALL_ANGLE_RAD, "body_edge_gap_um": float(self.body_edge_gap_um),
                "edge_tolerance_um": float(self.edge_tolerance_um),
                "body_on_film_feet_up_fraction": float(self.body_on_film_feet_up_fraction),
                "max_jump_um": float(self.max_jump_um), "jump_limit_um": float(self.jump_limit_um),
                "events_lost": int(self.events_lost), "steps_event_capped": int(self.steps_event_capped),
                "chaotic": self.chaotic, "not_converged": bool(self.not_converged)}


#: Convergence statuses (:class:`Convergence`): the default step passed its check; a smaller
#: step passed and the run was redone there; no step down to the limit passed; the run is
#: chaotic (runs from starts 0.05 um apart differ beyond the tolerance: no single trajectory converges);
#: no check was made (error control off, or the reference engine).
CONVERGENCE_STATUSES = ("converged", "refined", "not_converged", "chaotic", "unchecked")


@dataclass
class Convergence:
    """The step-error estimate a run carries (docs/model.md, "Error control and validity").

    ``status``: one of :data:`CONVERGENCE_STATUSES`; ``dt_s``: the step of the result;
    ``default_dt_s``: the step the control started from; ``error_mm_s``: the estimated step
    error of the result's mean speed (twice its difference from the run at half its step;
    NaN: unchecked); ``tolerance_mm_s``: ``max(rel |v|, abs)`` it was held to;
    ``seed_spread_mm_s``: the speed of the run at the default step from a start 0.05 um apart
    minus its own (the chaos probe); ``measured_s``: the time the speeds are measured over
    (``(t_from, t_to)``: after the transient); ``halvings``: how often the step was halved;
    ``speeds_mm_s``: the speed per step tried (default, half, quarter ...);
    ``wall_s``: what the checks and refinements took; ``basis``: how the error was estimated,
    ``"halving"`` (the runs at smaller steps) or ``"held"`` (every foot held far from letting go
    in the run and its probe: :func:`labkit.sim.errorcontrol.held`), empty when unchecked."""

    status: str
    dt_s: float
    default_dt_s: float
    error_mm_s: float = math.nan
    tolerance_mm_s: float = math.nan
    seed_spread_mm_s: float = math.nan
    measured_s: tuple[float, float] = (0.0, 0.0)
    halvings: int = 0
    speeds_mm_s: tuple[float, ...] = ()
    wall_s: float = 0.0
    basis: str = ""

    def summary(self) -> ConvergenceSummary:
        """JSON-able: every figure (NaN as None)."""
        def num(x: float) -> float | None:
            return None if not math.isfinite(x) else float(x)

        return {"status": self.status, "dt_s": float(self.dt_s), "default_dt_s": float(self.default_dt_s),
                "step_error_mm_s": num(self.error_mm_s), "tolerance_mm_s": num(self.tolerance_mm_s),
                "seed_spread_mm_s": num(self.seed_spread_mm_s), "measured_s": [float(x) for x in self.measured_s],
                "halvings": int(self.halvings), "speeds_per_step_mm_s": [float(x) for x in self.speeds_mm_s],
                "wall_s": round(float(self.wall_s), 4), "basis": self.basis}


def validity(params: RobotParams, body_gap_um: np.ndarray, angles_rad: np.ndarray, contact: np.ndarray,
             counters: dict[str, int]) -> Validity:
    """:class:`Validity` of a run from its samples (gap under the body's centre, um; angles
    phi_x, phi_y, phi_z; contact modes, 0 = air) and the kernel's counters."""
    tilt_x = np.abs(angles_rad[:, 0])
    tilt_y = np.abs(angles_rad[:, 1])
    edge = body_gap_um - 0.5e3 * (params.body_width_mm * tilt_y + params.body_length_mm * tilt_x)
    feet_up = np.all(contact == 0, axis=1)
    on_film = body_gap_um < ON_FILM_FRACTION * params.body_gap_um
    n = max(1, len(body_gap_um))
    return Validity(
        max_tilt_rad=float(max(tilt_x.max(initial=0.0), tilt_y.max(initial=0.0))),
        body_edge_gap_um=float(edge.min(initial=np.inf)),
        body_on_film_feet_up_fraction=float(np.count_nonzero(feet_up & on_film) / n),
        max_jump_um=float(body_gap_um.max(initial=0.0)), jump_limit_um=JUMP_BODY_LENGTHS * params.body_length_mm * 1e3,
        edge_tolerance_um=float(params.h_min_um),
        events_lost=int(counters.get("events_lost", 0)), steps_event_capped=int(counters.get("steps_event_capped", 0)))


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
    stuck flag); ``validity`` (:class:`Validity`: where the run left the model's assumptions);
    ``convergence`` (:class:`Convergence`: the step-error estimate and what the control did).
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
    contact_fraction: dict[str, dict[str, float]]
    impacts: np.ndarray
    body_impacts: int
    patterns: list[str]
    max_flight_s: np.ndarray
    events: np.ndarray
    n_steps: int
    wall_s: float
    seed: int | None = None
    ablation: str | None = None
    counters: dict[str, int] = field(default_factory=dict)
    max_height_um: np.ndarray | None = None
    foot_periods: list[int] | None = None
    validity: Validity | None = None
    convergence: Convergence | None = None

    def summary(self) -> SimResultSummary:
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
            "validity": None if self.validity is None else self.validity.summary(),
            "convergence": None if self.convergence is None else self.convergence.summary(),
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
            if self.convergence is not None:
                f.attrs["convergence"] = self.convergence.status
                f.attrs["step_error_mm_s"] = float(self.convergence.error_mm_s)
            put_json(f, "patterns", list(self.patterns))
            label_dimensions(f)     # t_s as the coordinate (xarray, HDFView)
        return path
