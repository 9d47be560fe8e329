"""Parameter sweeps with Monte Carlo draws over parameter uncertainty.

:func:`sweep` simulates one scenario (a :class:`~labkit.sim.Shaker` or
:class:`~labkit.sim.PZT`) at every value of one quantity — any field of the
scenario (``freq_hz``, ``amp_um``, ``voltage_v``, ``mass_mg``) or of
:class:`~labkit.sim.RobotParams` — and, with ``draws > 0``, repeats every
point with robot parameters drawn from the uncertainty table of
:mod:`labkit.sim.uncertainty` (as the paper's error bars, Fig. 8 and 13).

One task per (point, draw) goes through :func:`labkit.executor.map_tasks`.
Every task carries its own seed, derived from ``(seed, draw)`` only, so

* the numbers are identical serially, in local processes or on Dask;
* draw ``d`` uses the *same* perturbed robot at every point (common random
  numbers): a curve per draw is a physically consistent robot, and the spread
  between points is not inflated by re-drawing the robot at each point.

Draw 0 is always the nominal robot; draws ``1..n-1`` are perturbed. With
``draws=0`` only the nominal robot runs (one column).
"""
from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np

from labkit.errors import InputError
from labkit.jsonutil import Json

#: Contact modes in the order of the last axis of ``contact_fraction``.
CONTACT_MODES = ("air", "adhesion", "rest")
#: A sweep's error control (:func:`sweep`): the nominal robot checked at every point, every run, none.
ERROR_CONTROL = ("sample", "every", "off")
#: Per-foot pattern labels (SimResult.patterns).
PATTERNS = ("firm_contact", "partial_contact", "jumping")

#: Units of the quantities one can sweep, by name suffix.
_SUFFIX_UNITS = {"_hz": "Hz", "_um": "um", "_v": "V", "_mg": "mg", "_s": "s", "_n": "N",
                 "_n_s": "N/s", "_kg": "kg", "_m": "m"}

if TYPE_CHECKING:
    from labkit.sim.excitation import PZT, Shaker
    from labkit.sim.params import RobotParams
    from labkit.sim.result import SimResult


def units_of(name: str) -> str:
    """The unit of a quantity from the suffix of its name (``"1"`` when it has none)."""
    for suffix in sorted(_SUFFIX_UNITS, key=len, reverse=True):
        if name.endswith(suffix):
            return _SUFFIX_UNITS[suffix]
    return "1"


def _number(value: Json) -> float:
    """A JSON number as a float (NaN for anything else: ``null`` is how JSON writes NaN)."""
    return float(value) if isinstance(value, (int, float)) else float("nan")


class SweepSummary(TypedDict):
    """:meth:`SweepResult.summary` (``labkit simulate sweep --json``, the file's ``summary_json``)."""

    quantity: str
    units: str
    draws: int
    scenario: dict[str, Json]
    duration_s: Json
    seed: Json
    step_fraction: float
    points: list[dict[str, Json]]


@dataclass
class SweepResult:
    """The outcome of :func:`sweep`.

    Attributes
    ----------
    quantity:
        The swept quantity's name (with its unit: ``freq_hz``, ``mass_mg``...).
    values:
        Its values, shape ``(points,)``.
    speeds_mm_s:
        Mean forward speed of every run, shape ``(points, draws)``; column 0
        is the nominal robot.
    contact_fraction:
        Fraction of time in each contact mode, shape ``(points, draws, 6, 3)``
        (feet x :data:`CONTACT_MODES`).
    patterns:
        Per-foot pattern label, shape ``(points, draws, 6)``.
    impacts:
        Impacts per foot, shape ``(points, draws, 6)``.
    scenario:
        The base scenario (its fields with units in their names).
    params_toml:
        The nominal robot's parameter file text.
    meta:
        Seed, duration, the uncertainty table used, the scheduler.
    flags:
        Per run, the validity flags of :class:`labkit.sim.result.Validity` joined by commas
        ("" for none), shape ``(points, draws)``; the summary counts them per point.
    convergence:
        Per run, the step control's status (:data:`labkit.sim.result.CONVERGENCE_STATUSES`, or
        ``sampled``: run at the step its point's nominal robot settled on), ``(points, draws)``.
    step_error_mm_s:
        Per run, the step-error estimate (NaN where not checked), ``(points, draws)``.
    dt_s:
        Per run, the step used, ``(points, draws)``.
    """

    quantity: str
    values: np.ndarray
    speeds_mm_s: np.ndarray
    contact_fraction: np.ndarray
    patterns: np.ndarray
    impacts: np.ndarray
    scenario: dict[str, Json] = field(default_factory=dict)
    params_toml: str = ""
    meta: dict[str, Json] = field(default_factory=dict)
    flags: np.ndarray | None = None
    convergence: np.ndarray | None = None
    step_error_mm_s: np.ndarray | None = None
    dt_s: np.ndarray | None = None

    def convergence_counts(self, point: int) -> dict[str, int]:
        """How many runs (draws) at one point ended in each step-control status."""
        labels = [] if self.convergence is None else [str(x) for x in self.convergence[point]]
        return {name: labels.count(name) for name in sorted(set(labels))}

    def flag_counts(self, point: int) -> dict[str, int]:
        """How many runs (draws) at one point left each of the model's assumptions."""
        out: dict[str, int] = {}
        if self.flags is not None:
            for text in self.flags[point]:
                for name in filter(None, str(text).split(",")):
                    out[name] = out.get(name, 0) + 1
        return out

    @property
    def draws(self) -> int:
        return int(self.speeds_mm_s.shape[1])

    @property
    def mean_speed_mm_s(self) -> np.ndarray:
        """Mean over draws at every point."""
        return self.speeds_mm_s.mean(axis=1)

    @property
    def std_speed_mm_s(self) -> np.ndarray:
        """Sample standard deviation over draws (0 with a single draw)."""
        if self.draws < 2:
            return np.zeros(len(self.values))
        return self.speeds_mm_s.std(axis=1, ddof=1)

    @property
    def nominal_speed_mm_s(self) -> np.ndarray:
        """The nominal robot's speed (draw 0) at every point."""
        return self.speeds_mm_s[:, 0]

    def pattern_counts(self, point: int) -> dict[str, int]:
        """How many (draw, foot) pairs showed each pattern at one point."""
        labels = self.patterns[point].ravel().tolist()
        return {p: labels.count(p) for p in PATTERNS}

    def dominant_pattern(self, point: int) -> str:
        """The most frequent foot pattern at one point (ties: the first in :data:`PATTERNS`)."""
        counts = self.pattern_counts(point)
        return max(PATTERNS, key=lambda p: counts[p])

    def summary(self) -> SweepSummary:
        """A JSON-able summary: one entry per point with mean and spread."""
        return {"quantity": self.quantity, "units": units_of(self.quantity),
                "draws": self.draws, "scenario": self.scenario,
                "duration_s": self.meta.get("duration_s"), "seed": self.meta.get("seed"),
                "step_fraction": _number(self.meta.get("step_fraction", 1.0)),
                "points": [self.point_summary(i) for i in range(len(self.values))]}

    def point_summary(self, i: int) -> dict[str, Json]:
        """One point of :meth:`summary`: the swept value (under the quantity's name), the speeds over the
        draws, contact fractions, patterns, flags and step control; the amplitude an acceleration limit
        left and the dt check's result when the sweep has them."""
        s = self.speeds_mm_s[i]
        frac = self.contact_fraction[i].mean(axis=(0, 1))
        err = None if self.step_error_mm_s is None else float(self.step_error_mm_s[i, 0])
        point: dict[str, Json] = {
            self.quantity: float(self.values[i]),
            "mean_speed_mm_s": float(s.mean()),
            "std_speed_mm_s": float(self.std_speed_mm_s[i]),
            "min_speed_mm_s": float(s.min()),
            "max_speed_mm_s": float(s.max()),
            "nominal_speed_mm_s": float(s[0]),
            "contact_fraction": {m: float(f) for m, f in zip(CONTACT_MODES, frac)},
            "patterns": dict(self.pattern_counts(i)),
            "dominant_pattern": self.dominant_pattern(i),
            "flags": dict(self.flag_counts(i)),
            "convergence": dict(self.convergence_counts(i)),
            "step_error_mm_s": err if err is not None and np.isfinite(err) else None,
            "dt_s": None if self.dt_s is None else [float(x) for x in self.dt_s[i]],
        }
        amp = self.meta.get("amp_um")
        if isinstance(amp, list) and self.quantity != "amp_um":
            point["amp_um"] = _number(amp[i])
        check = self.meta.get("dt_check")
        if isinstance(check, dict):
            quarter, converged = check.get("quarter_speed_mm_s"), check.get("converged")
            point["quarter_step_speed_mm_s"] = _number(quarter[i]) if isinstance(quarter, list) else float("nan")
            point["dt_converged"] = bool(converged[i]) if isinstance(converged, list) else False
        return point

    def to_h5(self, path: str | Path) -> Path:
        """Write the sweep as an HDF5 file of kind ``"sim_sweep"``; returns the path (read it back with
        :func:`labkit.files.read_sweep_result`)."""
        import h5py

        from labkit.h5io import label_dimensions, stamp

        path = Path(path)
        if path.parent and not path.parent.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
        with h5py.File(path, "w") as f:
            stamp(f, "sim_sweep")
            self.write_group(f)
            label_dimensions(f)     # the swept quantity (freq_hz, ...) as the coordinate
        return path

    def write_group(self, g: Any) -> None:
        """Write the sweep's attributes and datasets into an open HDF5 group."""
        from labkit.h5io import put, put_json

        g.attrs["quantity"] = self.quantity
        g.attrs["quantity_units"] = units_of(self.quantity)
        g.attrs["params_toml"] = self.params_toml
        put_json(g, "scenario_json", self.scenario)
        put_json(g, "meta_json", self.meta)
        put_json(g, "summary_json", self.summary())
        put(g, "values", self.values, units_of(self.quantity), quantity=self.quantity)
        put(g, "speeds_mm_s", self.speeds_mm_s, "mm/s", axes="point, draw",
            description="mean forward speed per run; axis 0 points, axis 1 draws (0 = nominal)")
        put(g, "mean_speed_mm_s", self.mean_speed_mm_s, "mm/s")
        put(g, "std_speed_mm_s", self.std_speed_mm_s, "mm/s", ddof=1)
        put(g, "contact_fraction", self.contact_fraction, "1",
            axes="point, draw, foot, mode", modes=",".join(CONTACT_MODES))
        put(g, "impacts", self.impacts, "1", axes="point, draw, foot")
        put(g, "patterns", self.patterns.astype("S16"), "label", axes="point, draw, foot",
            labels=",".join(PATTERNS))
        if self.convergence is not None and self.step_error_mm_s is not None and self.dt_s is not None:
            put(g, "convergence", self.convergence.astype("S16"), "label", axes="point, draw",
                description="step control per run: converged, refined, not_converged, chaotic, sampled, unchecked")
            put(g, "step_error_mm_s", self.step_error_mm_s, "mm/s", axes="point, draw",
                description="mean speed at the run's step minus at half of it over the check stretch (NaN: unchecked)")
            put(g, "dt_s", self.dt_s, "s", axes="point, draw")
        if self.flags is not None:
            put(g, "flags", self.flags.astype("S128"), "label", axes="point, draw",
                description="validity flags per run, comma-separated (docs/model.md, Error control and validity)")


# --------------------------------------------------------------------------- helpers

def scenario_dict(scenario: Any) -> dict[str, Json]:
    """A scenario as a JSON-able dict with its type (``{"type": "shaker", ...}``)."""
    is_instance = dataclasses.is_dataclass(scenario) and not isinstance(scenario, type)
    fields = dataclasses.asdict(scenario) if is_instance else dict(vars(scenario))
    return {"type": type(scenario).__name__.lower(), **fields}


def apply_value(params: RobotParams, scenario: Shaker | PZT, quantity: str,
                value: float) -> tuple[RobotParams, Shaker | PZT]:
    """Set ``quantity`` to ``value`` on the scenario if it has that field, else on the params.

    ``mass_mg`` of a scenario without a payload field (a shaker run) sets the
    robot's total mass with the extra mass on the body (as the PZT payload),
    so the legs keep their mass.
    """
    from labkit.sim.uncertainty import params_fields

    if dataclasses.is_dataclass(scenario) and not isinstance(scenario, type) \
            and quantity in {f.name for f in dataclasses.fields(scenario)}:
        return params, scenario.with_value(quantity, float(value))
    if quantity == "mass_mg":
        extra = float(value) - params.mass_mg
        return params.replace(mass_mg=float(value), body_mass_mg=params.body_mass_mg + extra), scenario
    if quantity in params_fields(params):
        return params.replace(**{quantity: float(value)}), scenario
    raise InputError(f"cannot sweep {quantity!r}: neither the {type(scenario).__name__} scenario "
                     "nor the robot parameters have it", key=quantity,
                     expected="freq_hz, amp_um, voltage_v, mass_mg or a RobotParams field")


#: Standard gravity, for accelerations given in g.
G0_M_S2 = 9.80665


def limit_acceleration(scenario: Any, accel_limit_g: float | None) -> Any:
    """A shaker scenario with its amplitude cut to a peak-acceleration limit.

    ``amp_um = min(amp_um, a_max / (2 pi f)^2)``: what a force-limited
    shaker does (its amplitude falls as 1/f^2 above some frequency; the
    paper: "maximum amplitudes achievable by the shaker become smaller" at
    high frequency). ``None`` or a scenario without ``amp_um``: unchanged.
    """
    if accel_limit_g is None or not hasattr(scenario, "amp_um"):
        return scenario
    amp_max_um = accel_limit_g * G0_M_S2 / (2 * np.pi * scenario.freq_hz) ** 2 * 1e6
    if scenario.amp_um <= amp_max_um:
        return scenario
    return dataclasses.replace(scenario, amp_um=float(amp_max_um))


def check_points(params: RobotParams, scenario: Shaker | PZT, quantity: str, grid: np.ndarray, duration_s: float,
                 accel_limit_g: float | None, fraction: float, *, keys: dict[str, str] | None = None) -> None:
    """Every point of a sweep (the nominal robot) within :func:`labkit.sim.core.check_run`'s
    bounds, before any process starts (InputError naming the bound)."""
    from labkit.sim.core import check_run, default_dt

    for v in grid:
        p, sc = apply_value(params, scenario, quantity, float(v))
        sc = limit_acceleration(sc, accel_limit_g)
        check_run(p, sc, duration_s, default_dt(p, sc) * fraction, keys=keys)


def _task_seed(seed: int, draw: int) -> int:
    """One integer seed per draw, the same at every point (common random numbers)."""
    return int(np.random.SeedSequence([int(seed), int(draw)]).generate_state(1)[0])


@dataclass(frozen=True)
class PointTask:
    """One (point, draw) run of a sweep (picklable): the nominal robot and base scenario, the swept
    ``quantity`` set to ``value``, the ``draw`` (0: nominal) and how the run is made. ``quarter``: the
    dt check's run at a quarter of the step; ``fraction``: of the default step; ``control``:
    :func:`labkit.sim.simulate`'s ``error_control`` (``"check"`` or ``"off"``)."""

    params: RobotParams
    scenario: Shaker | PZT
    quantity: str
    value: float
    draw: int
    seed: int
    duration_s: float
    table: dict[str, float]
    accel_limit_g: float | None = None
    quarter: bool = False
    fraction: float = 1.0
    control: str = "check"


def run_point(task: PointTask) -> RunRow:
    """Run one (point, draw) task: draw the parameters, apply the value, simulate.

    A module-level function so the executor can pickle it by reference.
    """
    from labkit.sim import simulate
    from labkit.sim.uncertainty import draw_params

    params, scenario = task.params, task.scenario
    task_seed = _task_seed(task.seed, task.draw)
    if task.draw > 0:
        params = draw_params(params, np.random.default_rng(task_seed), task.table)
    params, scenario = apply_value(params, scenario, task.quantity, task.value)
    scenario = limit_acceleration(scenario, task.accel_limit_g)
    dt_s = None
    if task.quarter or task.fraction != 1.0:   # the dt check: the same run at a quarter of the sweep's step
        from labkit.sim.core import align_dt, default_dt

        dt_s = align_dt(default_dt(params, scenario) * task.fraction * (0.25 if task.quarter else 1.0), scenario)
    r = simulate(params, scenario, duration_s=task.duration_s, seed=task_seed, dt_s=dt_s, error_control=task.control)
    return result_row(r)


@dataclass(frozen=True)
class RunRow:
    """The small, picklable part of a :class:`~labkit.sim.result.SimResult` a sweep keeps.

    ``contact_fraction``: feet x :data:`CONTACT_MODES`; ``patterns``, ``impacts``: per foot;
    ``flags``: the validity flags joined by commas; ``convergence``, ``step_error_mm_s``,
    ``halvings``: what the step control did; ``dt_s``: the step used.
    """

    speed_mm_s: float
    contact_fraction: np.ndarray
    patterns: tuple[str, ...]
    impacts: np.ndarray
    flags: str = ""
    convergence: str = "unchecked"
    step_error_mm_s: float = float("nan")
    halvings: int = 0
    dt_s: float = float("nan")


def result_row(r: SimResult) -> RunRow:
    """The small, picklable part of a SimResult a sweep keeps."""
    frac = np.zeros((6, len(CONTACT_MODES)))
    cf = r.contact_fraction
    for j, foot in enumerate(list(cf)[:6]):
        modes = cf[foot]
        for m, name in enumerate(CONTACT_MODES):
            frac[j, m] = float(modes.get(name, modes.get(name.upper(), 0.0)))
    conv = r.convergence
    return RunRow(speed_mm_s=float(r.mean_speed_mm_s), contact_fraction=frac,
                  patterns=tuple(str(p) for p in r.patterns), impacts=np.asarray(r.impacts, dtype=int),
                  flags=",".join(r.validity.flags) if r.validity is not None else "",
                  convergence=conv.status if conv is not None else "unchecked",
                  step_error_mm_s=float(conv.error_mm_s) if conv is not None else float("nan"),
                  halvings=int(conv.halvings) if conv is not None else 0, dt_s=float(r.dt_s))


@dataclass(frozen=True)
class RunTable:
    """Runs stacked over (points, draws): the arrays of a :class:`SweepResult`."""

    speeds_mm_s: np.ndarray
    contact_fraction: np.ndarray
    patterns: np.ndarray
    impacts: np.ndarray
    flags: np.ndarray
    convergence: np.ndarray
    step_error_mm_s: np.ndarray
    dt_s: np.ndarray

    @classmethod
    def of(cls, rows: Sequence[RunRow], points: int, draws: int) -> RunTable:
        """The rows of ``points x draws`` runs, point-major, as arrays."""
        shape = (points, draws)

        def labels(values: Sequence[object], extra: tuple[int, ...] = ()) -> np.ndarray:
            return np.array(values, dtype=object).reshape(shape + extra).astype(str)

        return cls(speeds_mm_s=np.array([r.speed_mm_s for r in rows], float).reshape(shape),
                   contact_fraction=np.array([r.contact_fraction for r in rows]).reshape(
                       shape + (6, len(CONTACT_MODES))),
                   patterns=labels([list(r.patterns) for r in rows], (6,)),
                   impacts=np.array([r.impacts for r in rows]).reshape(shape + (6,)),
                   flags=labels([r.flags for r in rows]), convergence=labels([r.convergence for r in rows]),
                   step_error_mm_s=np.array([r.step_error_mm_s for r in rows], float).reshape(shape),
                   dt_s=np.array([r.dt_s for r in rows], float).reshape(shape))


# --------------------------------------------------------------------------- sweep

def sweep(params: RobotParams, base_scenario: Shaker | PZT, quantity: str = "freq_hz",
          values: Sequence[float] = (), draws: int = 0, duration_s: float = 2.0,
          scheduler: str | None = None, workers: int | None = None, seed: int = 0,
          quiet: bool = False, table: dict[str, float] | None = None,
          accel_limit_g: float | None = None, dt_check: bool = False,
          step_fraction: float = 1.0, keys: dict[str, str] | None = None,
          error_control: str = "sample") -> SweepResult:
    """Simulate ``base_scenario`` at every value of ``quantity``, with Monte Carlo draws.

    Parameters
    ----------
    params:
        The nominal :class:`~labkit.sim.RobotParams`.
    base_scenario:
        A :class:`~labkit.sim.Shaker` or :class:`~labkit.sim.PZT`; every field
        but the swept one is kept.
    quantity:
        The scenario field (``freq_hz``, ``amp_um``, ``voltage_v``,
        ``mass_mg``) or RobotParams field to sweep; ``mass_mg`` on a shaker
        run sets the robot's total mass.
    values:
        The values, in the quantity's unit.
    draws:
        Monte Carlo draws per point: 0 runs the nominal robot only; ``n >= 1``
        runs the nominal robot (draw 0) plus ``n - 1`` robots drawn from
        ``table``.
    duration_s:
        Simulated time per run.
    scheduler, workers:
        Passed to :func:`labkit.executor.map_tasks` (local processes by
        default, ``"serial"``, or ``"tcp://host:port"`` for Dask).
    seed:
        Seeds every draw; the same seed gives the same numbers on any backend.
    quiet:
        Hide the progress bar.
    table:
        Relative standard uncertainties (default
        :data:`labkit.sim.uncertainty.DEFAULT_TABLE`).
    accel_limit_g:
        Shaker runs only: cap the tray's peak acceleration (in g) by cutting
        the amplitude (:func:`limit_acceleration`); the amplitude used at
        each point is in ``meta["amp_um"]``. ``None``: the amplitude is kept.
    dt_check:
        Also run the nominal robot at every point at a quarter of the default
        step; ``meta["dt_check"]`` gets its speeds, the differences and whether
        each point is converged (within 3 % or 0.1 mm/s,
        :data:`labkit.sim.core.DT_CHECK_REL`, :data:`~labkit.sim.core.DT_CHECK_ABS_MM_S`).
    step_fraction:
        Every run at this fraction of its default step (0 < f <= 1; PZT runs
        rounded down to whole steps per half drive period), for the runs the
        default step does not converge (docs/model.md, "Numerics"); the dt
        check then compares with a quarter of that. ``meta["step_fraction"]``.
    keys:
        Names of the fields in the bounds' messages (:func:`labkit.sim.core.check_run`).
    error_control:
        ``"sample"`` (default): the nominal robot (draw 0) at every point checks its step
        (:func:`labkit.sim.errorcontrol.control`), first; where it had to halve the step, the
        other draws of that point then run at the step it settled on (their status ``sampled``).
        ``"every"``: every run checks itself. ``"off"``: no check (``unchecked``).
        ``convergence``, ``step_error_mm_s`` and ``dt_s`` of the result hold what each run did.

    Returns
    -------
    SweepResult
    """
    from labkit.sim.uncertainty import DEFAULT_TABLE, check_table

    grid = np.asarray([float(v) for v in values], dtype=float)
    if grid.size == 0:
        raise InputError("no values to sweep", key=quantity, expected="at least one value")
    _check_options(int(draws), duration_s, step_fraction, accel_limit_g, error_control)
    table = dict(DEFAULT_TABLE if table is None else table)
    check_table(params, table)
    n_draws = max(1, int(draws))
    proto = PointTask(params, base_scenario, quantity, float(grid[0]), 0, int(seed), float(duration_s), table,
                      accel_limit_g, False, float(step_fraction))
    apply_value(params, base_scenario, quantity, grid[0])       # a bad quantity fails before any process starts
    check_points(params, base_scenario, quantity, grid, duration_s, accel_limit_g, float(step_fraction), keys=keys)
    tasks = [dataclasses.replace(proto, value=float(v), draw=d, control=_control(error_control, d))
             for v in grid for d in range(n_draws)]
    checks = [dataclasses.replace(proto, value=float(v), quarter=True, control="off") for v in grid] if dt_check else []
    run = functools.partial(_run_batch, scheduler=scheduler, workers=workers, quiet=quiet)
    if error_control == "sample" and n_draws > 1:
        rows = _run_sampled(tasks + checks, len(tasks), n_draws, run, f"sweep {quantity}")
    else:
        rows = run(tasks + checks, f"sweep {quantity}")
    quarter_rows, rows = rows[len(tasks):], rows[:len(tasks)]
    t = RunTable.of(rows, len(grid), n_draws)
    meta = _sweep_meta(proto, n_draws, scheduler, error_control)
    if dt_check:
        meta["dt_check"] = _dt_check_meta(t.speeds_mm_s[:, 0], quarter_rows)
    if accel_limit_g is not None and hasattr(base_scenario, "amp_um"):
        meta["accel_limit_g"] = float(accel_limit_g)
        meta["amp_um"] = [float(limit_acceleration(apply_value(params, base_scenario, quantity, v)[1],
                                                   accel_limit_g).amp_um) for v in grid]
    return SweepResult(quantity=quantity, values=grid, speeds_mm_s=t.speeds_mm_s, contact_fraction=t.contact_fraction,
                       patterns=t.patterns, impacts=t.impacts, scenario=scenario_dict(base_scenario),
                       params_toml=params.to_toml_text(), meta=meta, flags=t.flags, convergence=t.convergence,
                       step_error_mm_s=t.step_error_mm_s, dt_s=t.dt_s)


def _run_batch(batch: list[PointTask], desc: str, *, scheduler: str | None, workers: int | None,
               quiet: bool) -> list[RunRow]:
    """Run tasks through :func:`labkit.executor.map_tasks` (local processes, serial or Dask)."""
    from labkit.executor import map_tasks

    return map_tasks(run_point, batch, scheduler=scheduler, workers=workers, desc=desc, quiet=quiet)


def _dt_check_meta(nominal_mm_s: np.ndarray, quarter_rows: list[RunRow]) -> dict[str, Json]:
    """The dt check of a sweep's ``meta``: the nominal robot's speed at a quarter step, the difference,
    and whether they agree (:func:`labkit.sim.errorcontrol.agree`) at every point."""
    from labkit.sim.errorcontrol import agree

    q = np.array([r.speed_mm_s for r in quarter_rows])
    return {"quarter_speed_mm_s": [float(x) for x in q], "difference_mm_s": [float(x) for x in nominal_mm_s - q],
            "converged": [bool(x) for x in agree(nominal_mm_s, q)]}


def _sweep_meta(proto: PointTask, n_draws: int, scheduler: str | None, error_control: str) -> dict[str, Json]:
    """A sweep's ``meta``: seeding, duration, uncertainty table, scheduler, error control, step fraction."""
    meta: dict[str, Json] = {
        "seed": proto.seed, "draws": n_draws, "duration_s": proto.duration_s,
        "uncertainty_table": {k: float(v) for k, v in proto.table.items()}, "scheduler": scheduler or "local",
        "draw_0": "nominal", "seeding": "SeedSequence([seed, draw]) per draw, same at every point",
        "task_seeds": [_task_seed(proto.seed, d) for d in range(n_draws)], "error_control": error_control}
    if proto.fraction != 1.0:
        meta["step_fraction"] = proto.fraction
    return meta


def _control(mode: str, draw: int) -> str:
    """``simulate``'s error control for one draw under a sweep's mode (:data:`ERROR_CONTROL`): the
    sampled draws are tried held at a coarser step first (``"held"``, docs/model.md)."""
    if mode == "every" or (mode == "sample" and draw == 0):
        return "check"
    return "held" if mode == "sample" else "off"


def _check_options(draws: int, duration_s: float, step_fraction: float, accel_limit_g: float | None,
                   error_control: str) -> None:
    """InputError naming the first of a sweep's options that is out of range (before any run)."""
    if draws < 0:
        raise InputError(f"draws must be >= 0, got {draws}", key="draws", expected="an integer >= 0")
    if not duration_s > 0:
        raise InputError(f"duration must be > 0 s, got {duration_s}", key="duration_s",
                         expected="a duration in s, > 0")
    if not 0.0 < step_fraction <= 1.0:
        raise InputError(f"step fraction must be in (0, 1], got {step_fraction}", key="step_fraction",
                         expected="a fraction of the default step, 0 < f <= 1")
    if accel_limit_g is not None and not accel_limit_g > 0:
        raise InputError(f"acceleration limit must be > 0 g, got {accel_limit_g}", key="accel_limit_g",
                         expected="a peak acceleration in g, > 0")
    if error_control not in ERROR_CONTROL:
        raise InputError(f"unknown error control {error_control!r}", key="error_control",
                         expected=", ".join(ERROR_CONTROL))


def _run_sampled(tasks: list[PointTask], n_main: int, n_draws: int,
                 run: Callable[[list[PointTask], str], list[RunRow]], desc: str) -> list[RunRow]:
    """Sampled error control: the nominal robot (draw 0) of every point first, with the control;
    then the other draws (and the tasks after ``n_main``, the dt check's), each at the step its
    point's nominal robot settled on where it refined it (halved the step and then agreed with
    half of it), else at the default step; their status ``sampled``. Returns every task's row,
    in the order of ``tasks``. (Run after the nominal robots, a refined point's draws are not
    first run at the default step and thrown away.)"""
    nominal = run(tasks[0:n_main:n_draws], desc + ": nominal robots, checked")
    rest: list[PointTask] = []
    for i in range(n_main):
        if i % n_draws:
            row = nominal[i // n_draws]
            halve = 2 ** row.halvings if row.convergence == "refined" else 1
            rest.append(dataclasses.replace(tasks[i], fraction=tasks[i].fraction / halve))
    rest += tasks[n_main:]
    done = iter(run(rest, desc + ": draws"))
    rows = [nominal[i // n_draws] if i % n_draws == 0 else dataclasses.replace(next(done), convergence="sampled")
            for i in range(n_main)]
    return rows + list(done)
