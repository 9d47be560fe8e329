"""The paper's observations scored over a Monte Carlo ensemble of robots, not one robot.

A robot set (a :class:`~labkit.sim.params.RobotParams`) is judged by the robots
fabrication makes of it: ``draws`` robots drawn from the Monte Carlo table
(:func:`labkit.sim.uncertainty.draw_params`) for each seed of ``seeds``, every
one run through the points of every paper scenario
(:data:`labkit.sim.scenarios.paper.PAPER`) for ``duration_s``. All runs go
through one :func:`labkit.executor.map_tasks` call (local processes or a Dask
scheduler). Robot ``(seed, draw)`` uses ``SeedSequence([seed, draw])`` for its
draw and its start, the same at every point (common random numbers), so draw
``d`` of seed ``s`` is one physical robot across all scenarios.

Per observation (:class:`ObservationScore`):

* ``nominal``: the metric of the nominal robot (draw 0, seed ``seeds[0]``);
* ``ensemble``: the metric of the whole ensemble pooled (every drawn robot of
  every seed is one draw of the scenario's :class:`~labkit.sim.scenarios.runs.PointSet`:
  mean curves over robots, pattern shares over robots and feet), and its
  ``state``: met / not met / not applicable (:mod:`labkit.sim.paper.observations`);
  this is the verdict;
* ``mean`` +- ``spread``: mean and standard deviation of the metric over the
  individual robots in the claim's regime (``robots`` of them, NaN-free), with
  ``median`` and ``met_share`` (share of the robots in the regime that meet it);
* ``per_seed``: the metric of each seed's ensemble of ``draws`` robots (how much
  the verdict depends on which robots were drawn).

Entry point: :func:`score_ensemble`. It is small on purpose: the calibration
(:mod:`labkit.sim.paper.fit`) can call it as its objective.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING, TypedDict, cast

import numpy as np

from labkit.errors import InputError
from labkit.jsonutil import Json
from labkit.sim.paper.observations import (
    MET,
    NOT_APPLICABLE,
    STATES,
    ObservationCheck,
    check_one,
    observations,
)
from labkit.sim.params import RobotParams

if TYPE_CHECKING:
    from labkit.sim.paper.observations import Observation
    from labkit.sim.paper.shaker import ShakerLaw, TableLaw
    from labkit.sim.scenarios.paper import Plan
    from labkit.sim.scenarios.runs import Point, PointSet, ScenarioRow

#: A scenario's measure: its runs -> its metrics (:data:`labkit.sim.scenarios.paper.PAPER`).
Measure = Callable[["PointSet"], dict[str, float]]

#: The default ensemble: 6 drawn robots x 2 s x seeds 0, 1, 2 (18 robots).
DEFAULT_DRAWS = 6
DEFAULT_DURATION_S = 2.0
DEFAULT_SEEDS = (0, 1, 2)


@dataclass(frozen=True)
class ObservationScore:
    """One observation over the ensemble (see the module's docstring)."""

    id: str
    scenario: str
    metric: str
    band: str
    source: str
    paper_value: float | None
    nominal: float | None
    nominal_state: str
    ensemble: float | None
    state: str
    mean: float | None
    spread: float | None
    median: float | None
    robots: int
    met_share: float | None
    per_seed: list[float | None]
    per_seed_states: list[str]
    #: The pooled ensemble's distance outside the band (:func:`~labkit.sim.paper.observations.violation`);
    #: None when not applicable.
    violation: float | None = None

    @property
    def met(self) -> bool:
        return self.state == MET

    def to_dict(self) -> dict[str, Json]:
        """The score as JSON: every field, in the order above."""
        return cast("dict[str, Json]", asdict(self))


@dataclass(frozen=True)
class EnsembleSettings:
    """What an ensemble ran: drawn robots per seed, seconds per run, the seeds, the scenarios'
    point grids and names, the drawn robots in all, the tray law, where it ran; ``params``: the
    set's name or file, when the caller records it."""

    draws: int
    duration_s: float
    seeds: tuple[int, ...]
    size: str = "quick"
    scenarios: tuple[str, ...] = ()
    robots: int = 0
    tray_law: str = ""
    scheduler: str = "local"
    workers: int | None = None
    params: str | None = None

    def to_dict(self) -> EnsembleSettingsJSON:
        return EnsembleSettingsJSON(draws=self.draws, duration_s=self.duration_s, seeds=list(self.seeds),
                                    size=self.size, scenarios=list(self.scenarios), robots=self.robots,
                                    tray_law=self.tray_law, scheduler=self.scheduler, workers=self.workers,
                                    params=self.params)


class EnsembleSettingsJSON(TypedDict):
    """:class:`EnsembleSettings` as JSON."""

    draws: int
    duration_s: float
    seeds: list[int]
    size: str
    scenarios: list[str]
    robots: int
    tray_law: str
    scheduler: str
    workers: int | None
    params: str | None


class EnsembleScoreJSON(TypedDict):
    """:meth:`EnsembleScore.to_dict` (the bench's JSON)."""

    settings: EnsembleSettingsJSON
    cpu_s: float
    wall_s: float
    runs: int
    met: dict[str, int]
    nominal_met: dict[str, int]
    seed_met: list[int]
    observations: list[dict[str, Json]]


@dataclass(frozen=True)
class EnsembleScore:
    """The result of :func:`score_ensemble`: one :class:`ObservationScore` per observation."""

    scores: list[ObservationScore]
    settings: EnsembleSettings
    cpu_s: float
    wall_s: float
    runs: int
    #: Per scenario: the metrics of each drawn robot, and of the pooled ensemble.
    member_metrics: dict[str, list[dict[str, float]]] = field(default_factory=dict)
    pooled_metrics: dict[str, dict[str, float]] = field(default_factory=dict)

    def count(self, which: str = "ensemble") -> dict[str, int]:
        """Observations per state for the ``"ensemble"`` verdict or the ``"nominal"`` robot."""
        states = [s.state if which == "ensemble" else s.nominal_state for s in self.scores]
        return {st: states.count(st) for st in STATES}

    def seed_counts(self) -> list[int]:
        """Observations met by each seed's ensemble of ``draws`` robots."""
        n = len(self.settings.seeds)
        return [sum(s.per_seed_states[k] == MET for s in self.scores) for k in range(n)]

    def by_id(self) -> dict[str, ObservationScore]:
        return {s.id: s for s in self.scores}

    def violations(self, not_applicable: float = 1.0) -> dict[str, float]:
        """Observation id -> the pooled ensemble's violation (0 when met), ``not_applicable`` for an
        observation outside its regime (a calibration objective must not reward leaving a regime)."""
        return {s.id: not_applicable if s.violation is None else s.violation for s in self.scores}

    def to_dict(self) -> EnsembleScoreJSON:
        return EnsembleScoreJSON(settings=self.settings.to_dict(), cpu_s=round(self.cpu_s, 1),
                                 wall_s=round(self.wall_s, 1), runs=self.runs, met=self.count("ensemble"),
                                 nominal_met=self.count("nominal"), seed_met=self.seed_counts(),
                                 observations=[s.to_dict() for s in self.scores])


def _finite(x: float | None) -> float | None:
    return float(x) if x is not None and math.isfinite(float(x)) else None


@dataclass(frozen=True)
class EnsembleRuns:
    """The simulations of an ensemble (:func:`run_ensemble`), before scoring: the plan of every
    scenario and one result row per (point, robot), robots ordered nominal first, then seed-major."""

    plans: dict[str, Plan]
    #: :func:`labkit.sim.scenarios.runs.run_task`'s rows, per scenario.
    rows: dict[str, list[ScenarioRow]]
    robots: list[tuple[int, int]]
    settings: EnsembleSettings
    wall_s: float


@dataclass(frozen=True)
class EnsembleSpec:
    """Which robots, runs and scenarios an ensemble holds.

    ``draws``, ``duration_s``, ``seeds``: drawn robots per seed, seconds per run (a scenario may
    cap it: the spectrum's runs are short), the seeds; default 6 x 2 s x (0, 1, 2). ``size``: the
    scenarios' point grids, ``"quick"`` (the calibration's) or ``"full"``. ``scenarios``: paper
    scenario names (default all of :data:`labkit.sim.scenarios.paper.PAPER`). ``tray_law``: the
    shaker scenarios' tray amplitude law (default the paper's shaker). ``table``: Monte Carlo
    spreads (default :data:`labkit.sim.uncertainty`'s table).
    """

    draws: int = DEFAULT_DRAWS
    duration_s: float = DEFAULT_DURATION_S
    seeds: Sequence[int] = DEFAULT_SEEDS
    size: str = "quick"
    scenarios: Sequence[str] | None = None
    tray_law: ShakerLaw | TableLaw | None = None
    table: dict[str, float] | None = None


def score_ensemble(params: RobotParams, spec: EnsembleSpec = EnsembleSpec(), *, scheduler: str | None = None,
                   workers: int | None = None, quiet: bool = True) -> EnsembleScore:
    """Score every paper observation over ``spec.draws`` drawn robots for each of ``spec.seeds``.

    Parameters
    ----------
    params:
        The robot set the robots are drawn around (its nominal robot is scored too).
    spec:
        The ensemble (:class:`EnsembleSpec`).
    scheduler, workers, quiet:
        As for :func:`labkit.executor.map_tasks`.

    Returns
    -------
    EnsembleScore
        One :class:`ObservationScore` per observation; ``cpu_s`` is the simulations' CPU time.
    """
    return score_runs(run_ensemble(params, spec, scheduler=scheduler, workers=workers, quiet=quiet))


def run_ensemble(params: RobotParams, spec: EnsembleSpec = EnsembleSpec(), *, scheduler: str | None = None,
                 workers: int | None = None, quiet: bool = True) -> EnsembleRuns:
    """The simulations of :func:`score_ensemble` (same parameters), in one executor call."""
    draws, duration_s, seeds, size = spec.draws, spec.duration_s, spec.seeds, spec.size
    scenarios, tray_law, table = spec.scenarios, spec.tray_law, spec.table
    from labkit.executor import map_tasks
    from labkit.sim.scenarios.base import RunOptions
    from labkit.sim.scenarios.paper import PAPER
    from labkit.sim.scenarios.paper import tray_law as default_law
    from labkit.sim.scenarios.runs import Task, run_task

    names = list(PAPER) if scenarios is None else [str(n) for n in scenarios]
    bad = [n for n in names if n not in PAPER]
    if bad or not names:
        raise InputError(f"unknown paper scenario(s) {bad}", key="scenarios", expected=", ".join(PAPER))
    if int(draws) < 1 or not seeds or not (math.isfinite(duration_s) and duration_s > 0):
        raise InputError(f"ensemble of {draws} draws x {list(seeds)} seeds x {duration_s} s", key="draws/seeds",
                         expected="draws >= 1, one or more seeds, duration > 0 s")
    t0 = time.perf_counter()
    opts = RunOptions(size=size, duration_s=float(duration_s), seed=int(seeds[0]), tray_law=tray_law)
    law = default_law(opts)
    robots = [(int(seeds[0]), 0)] + [(int(s), d) for s in seeds for d in range(1, int(draws) + 1)]
    plans = {name: PAPER[name].plan(params, opts, law) for name in names}
    tasks = [Task(p, d, s, plans[name].duration_s, table) for name in names for p in plans[name].points
             for s, d in robots]
    rows = map_tasks(run_task, tasks, scheduler=scheduler, workers=workers, desc="paper ensemble", quiet=quiet)
    out, start = {}, 0
    for name in names:
        n = len(plans[name].points) * len(robots)
        out[name], start = rows[start:start + n], start + n
    settings = EnsembleSettings(draws=int(draws), duration_s=float(duration_s), seeds=tuple(int(s) for s in seeds),
                                size=size, scenarios=tuple(names), robots=len(robots) - 1,
                                tray_law=law.describe()["law"], scheduler=scheduler or "local", workers=workers)
    return EnsembleRuns(plans=plans, rows=out, robots=robots, settings=settings, wall_s=time.perf_counter() - t0)


def merge_runs(parts: Sequence[EnsembleRuns]) -> EnsembleRuns:
    """One ensemble from runs of the same set, grid and duration over other seeds (e.g. one seed per
    call, saved as each ends): the first part's nominal robot, every part's drawn robots."""
    if not parts:
        raise InputError("no runs to merge", key="runs", expected="one or more EnsembleRuns")
    first = parts[0]
    same = ("draws", "duration_s", "size", "scenarios")
    for p in parts[1:]:
        differ = [k for k in same if getattr(p.settings, k) != getattr(first.settings, k)]
        if differ:
            raise InputError(f"runs differ in {differ}",
                             key="runs", expected="runs of one ensemble (same draws, duration, size, scenarios)")
    robots = [first.robots[0]] + [r for p in parts for r in p.robots[1:]]
    rows = {}
    for name, plan in first.plans.items():
        merged = []
        for i in range(len(plan.points)):
            merged.append(first.rows[name][i * len(first.robots)])
            for p in parts:
                m = len(p.robots)
                merged += p.rows[name][i * m + 1:(i + 1) * m]
        rows[name] = merged
    seeds = tuple(s for p in parts for s in p.settings.seeds)
    settings = replace(first.settings, seeds=seeds, robots=len(robots) - 1)
    return EnsembleRuns(plans=first.plans, rows=rows, robots=robots, settings=settings,
                        wall_s=sum(p.wall_s for p in parts))


def score_runs(runs: EnsembleRuns) -> EnsembleScore:
    """Score the simulations of :func:`run_ensemble` (cheap: no simulation; re-scores saved runs)."""
    from labkit.sim.scenarios.paper import PAPER

    scores, members, pooled = [], {}, {}
    n_seeds, draws = len(runs.settings.seeds), runs.settings.draws
    for name, plan in runs.plans.items():
        got = _measure(PAPER[name].measure, plan.points, runs.rows[name], (len(runs.robots), n_seeds, draws))
        members[name], pooled[name] = got.members, got.pooled
        scores += [_score(o, got) for o in observations(name)]
    cpu = sum(r.cpu_s for rows in runs.rows.values() for r in rows)
    return EnsembleScore(scores=scores, settings=runs.settings, cpu_s=cpu, wall_s=runs.wall_s,
                         runs=sum(len(r) for r in runs.rows.values()), member_metrics=members,
                         pooled_metrics=pooled)


@dataclass(frozen=True)
class Measured:
    """One scenario's metrics over an ensemble: the nominal robot's, the pooled drawn robots', each
    seed's ensemble's and each drawn robot's."""

    nominal: dict[str, float]
    pooled: dict[str, float]
    seeds: list[dict[str, float]]
    members: list[dict[str, float]]


def _measure(measure: Measure, points: Sequence[Point], rows: Sequence[ScenarioRow],
             shape: tuple[int, int, int]) -> Measured:
    """Metrics of the nominal robot, each seed's ensemble, the pooled ensemble and each drawn robot
    (``shape``: robots in all, seeds, drawn robots per seed)."""
    from labkit.sim.scenarios.runs import collect

    n_robots, n_seeds, draws = shape

    by_robot = [[rows[i * n_robots + k] for i in range(len(points))] for k in range(n_robots)]

    def metrics_of(robots: Sequence[int]) -> dict[str, float]:
        picked = [by_robot[k][i] for i in range(len(points)) for k in robots]
        return measure(collect(points, picked, len(robots)))

    drawn = list(range(1, n_robots))
    return Measured(nominal=metrics_of([0]), pooled=metrics_of(drawn),
                    seeds=[metrics_of(drawn[s * draws:(s + 1) * draws]) for s in range(n_seeds)],
                    members=[metrics_of([k]) for k in drawn])


def _score(o: Observation, got: Measured) -> ObservationScore:
    nominal, pooled = check_one(o, got.nominal), check_one(o, got.pooled)
    seeds: list[ObservationCheck] = [check_one(o, m) for m in got.seeds]
    robots = [check_one(o, m) for m in got.members]
    applicable = [c for c in robots if c.state != NOT_APPLICABLE]
    vals = np.array([c.value for c in applicable if c.value is not None and math.isfinite(c.value)], float)
    return ObservationScore(
        id=o.id, scenario=o.scenario, metric=o.metric, band=o.band, source=o.source, paper_value=o.paper_value,
        nominal=_finite(nominal.value), nominal_state=nominal.state, ensemble=_finite(pooled.value),
        state=pooled.state, mean=float(vals.mean()) if vals.size else None,
        spread=float(vals.std(ddof=1)) if vals.size > 1 else None,
        median=float(np.median(vals)) if vals.size else None, robots=int(vals.size),
        met_share=(sum(c.passed for c in applicable) / len(applicable)) if applicable else None,
        per_seed=[_finite(c.value) for c in seeds], per_seed_states=[c.state for c in seeds],
        violation=_finite(pooled.violation))
