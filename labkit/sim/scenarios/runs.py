"""Run a list of (robot, drive) points with Monte Carlo draws through the executor.

:func:`labkit.sim.sweep` varies one quantity over a fixed base scenario; the
paper scenarios need a drive that changes with the point (the shaker's
amplitude falls with frequency, :mod:`labkit.sim.paper.shaker`) and per-run
measures beyond the speed (foot clearance, leg motion, aperiodicity). A
:class:`Point` is one robot and one fully specified drive; :func:`run_points`
runs every (point, draw) as one task of :func:`labkit.executor.map_tasks`
and returns a :class:`PointSet`, which has the curve attributes of a
:class:`~labkit.sim.sweep.SweepResult` (so the same plots draw it).

Seeding is the sweep's: draw ``d`` uses ``SeedSequence([seed, d])`` for both
its parameter draw and its start, the same at every point (common random
numbers); draw 0 is the nominal robot.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from labkit.jsonutil import Json
from labkit.sim.excitation import PZT, Shaker
from labkit.sim.params import RobotParams
from labkit.sim.sweep import RunRow, SweepResult


@dataclass(frozen=True)
class Point:
    """One robot and one drive; ``x`` is the point's coordinate on the scenario's axis."""

    params: RobotParams
    drive: Shaker | PZT
    x: float
    ablation: str | None = None


@dataclass(frozen=True)
class Task:
    """One simulation of :func:`run_task` (picklable)."""

    point: Point
    draw: int
    seed: int
    duration_s: float
    table: dict[str, float] | None = None


def task_seed(seed: int, draw: int) -> int:
    """One integer seed per draw, the same at every point (common random numbers)."""
    return int(np.random.SeedSequence([int(seed), int(draw)]).generate_state(1)[0])


@dataclass(frozen=True)
class ScenarioRow:
    """What :func:`run_task` keeps of one run: the sweep's row (:class:`~labkit.sim.sweep.RunRow`), the
    paper scenarios' measures (:mod:`labkit.sim.scenarios.metrics`; ``measures`` by the names of
    ``RUN_MEASURES``) and the CPU time it took."""

    run: RunRow
    foot_rise_um: float
    leg_motion_um: float
    aperiodicity: float
    measures: dict[str, float] = field(default_factory=dict)
    cpu_s: float = 0.0


def run_task(task: Task) -> ScenarioRow:
    """Simulate one task and keep its small measures (a module-level function: pickled by reference)."""
    import time

    from labkit.sim.core import simulate
    from labkit.sim.scenarios.metrics import foot_rise_um, leg_aperiodicity, leg_motion_um, run_measures
    from labkit.sim.sweep import result_row
    from labkit.sim.uncertainty import draw_params

    t0 = time.process_time()
    seed = task_seed(task.seed, task.draw)
    params = task.point.params
    if task.draw > 0:
        params = draw_params(params, np.random.default_rng(seed), task.table)
    r = simulate(params, task.point.drive, duration_s=task.duration_s, seed=seed, ablation=task.point.ablation)
    return ScenarioRow(result_row(r), foot_rise_um(r), leg_motion_um(r), leg_aperiodicity(r), run_measures(r),
                       time.process_time() - t0)


@dataclass
class PointSet(SweepResult):
    """The runs of :func:`run_points`: a :class:`~labkit.sim.sweep.SweepResult` (axis 0 the
    points, axis 1 the draws; its curve statistics, pattern counts and summary) with the
    per-run measures the paper scenarios need and the drive of every point."""

    foot_rise_um: np.ndarray = field(default_factory=lambda: np.zeros((0, 1)))
    leg_motion_um: np.ndarray = field(default_factory=lambda: np.zeros((0, 1)))
    aperiodicity: np.ndarray = field(default_factory=lambda: np.zeros((0, 1)))
    drives: list[dict[str, Json]] = field(default_factory=list)
    #: Further per-run measures (point x draw) by name (labkit.sim.scenarios.metrics.RUN_MEASURES).
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    def share(self, point: int, pattern: str) -> float:
        """Share of (draw, foot) pairs at one point that show ``pattern``."""
        counts = self.pattern_counts(point)
        total = sum(counts.values())
        return counts.get(pattern, 0) / total if total else float("nan")

    def points(self, name: str) -> list[dict[str, Json]]:
        """One JSON-able row per point: the coordinate (as ``name``), speeds, pattern, drive."""
        rows: list[dict[str, Json]] = []
        for i, x in enumerate(self.values):
            rows.append({name: float(x), "mean_speed_mm_s": float(self.mean_speed_mm_s[i]),
                         "std_speed_mm_s": float(self.std_speed_mm_s[i]),
                         "nominal_speed_mm_s": float(self.nominal_speed_mm_s[i]),
                         "dominant_pattern": self.dominant_pattern(i),
                         "foot_rise_um": float(np.mean(self.foot_rise_um[i])),
                         **({"drive": self.drives[i]} if i < len(self.drives) else {})})
        return rows

    def to_h5(self, path: str | Path) -> Path:
        """Write the set (kind ``sim_points``): the sweep's datasets plus the per-run measures."""
        import h5py

        from labkit.h5io import put, put_json, stamp

        path = Path(path)
        with h5py.File(path, "w") as f:
            stamp(f, "sim_points")
            self.write_group(f)
            put_json(f, "drives_json", self.drives)
            put(f, "foot_rise_um", self.foot_rise_um, "um", axes="point, draw")
            put(f, "leg_motion_um", self.leg_motion_um, "um", axes="point, draw")
            put(f, "aperiodicity", self.aperiodicity, "1", axes="point, draw")
            for name, values in self.extra.items():
                put(f, f"run_{name}", values, "um" if name.endswith("_um") else "1", axes="point, draw")
        return path


def make_tasks(points: Sequence[Point], draws: int, duration_s: float, seed: int,
               table: dict[str, float] | None = None) -> list[Task]:
    """One task per (point, draw); ``draws = 0`` or 1 runs the nominal robot only."""
    n = max(1, int(draws))
    return [Task(p, d, int(seed), float(duration_s), table) for p in points for d in range(n)]


def collect(points: Sequence[Point], rows: Sequence[ScenarioRow], draws: int,
            meta: dict[str, Json] | None = None, quantity: str = "x") -> PointSet:
    """Assemble the rows of :func:`make_tasks`'s tasks (in order) into a :class:`PointSet`."""
    from labkit.sim.scenarios.metrics import RUN_MEASURES
    from labkit.sim.sweep import RunTable, scenario_dict

    shape = (len(points), max(1, int(draws)))
    t = RunTable.of([r.run for r in rows], *shape)

    def arr(values: list[float]) -> np.ndarray:
        return np.array(values, dtype=float).reshape(shape)

    return PointSet(quantity=quantity, values=np.array([p.x for p in points], float), speeds_mm_s=t.speeds_mm_s,
                    contact_fraction=t.contact_fraction, patterns=t.patterns, impacts=t.impacts,
                    params_toml=points[0].params.to_toml_text() if points else "", meta=dict(meta or {}),
                    foot_rise_um=arr([r.foot_rise_um for r in rows]),
                    leg_motion_um=arr([r.leg_motion_um for r in rows]),
                    aperiodicity=arr([r.aperiodicity for r in rows]),
                    convergence=t.convergence, step_error_mm_s=t.step_error_mm_s, dt_s=t.dt_s,
                    extra={k: arr([r.measures[k] for r in rows]) for k in RUN_MEASURES
                           if rows and all(k in r.measures for r in rows)},
                    drives=[scenario_dict(p.drive) | ({"ablation": p.ablation} if p.ablation else {})
                            for p in points])


def run_points(points: Sequence[Point], *, draws: int = 0, duration_s: float = 1.0, seed: int = 0,
               scheduler: str | None = None, workers: int | None = None, quiet: bool = False,
               desc: str = "scenario", quantity: str = "x") -> PointSet:
    """Run every point (``draws`` Monte Carlo robots each) and collect the measures."""
    from labkit.executor import map_tasks

    tasks = make_tasks(points, draws, duration_s, seed)
    rows = map_tasks(run_task, tasks, scheduler=scheduler, workers=workers, desc=desc, quiet=quiet)
    return collect(points, rows, draws, {"draws": max(1, int(draws)), "duration_s": float(duration_s),
                                         "seed": int(seed), "seeding": "SeedSequence([seed, draw]) per draw"},
                   quantity)
