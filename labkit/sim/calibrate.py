"""Calibrate the simulator: fit chosen uncertain parameters to measured speeds (and leg patterns).

The person chooses the parameters (any scalar :class:`~labkit.sim.RobotParams`
field, or one element of a per-mode field as ``k_per_s2[1]``); the fit
minimises, by :func:`scipy.optimize.least_squares` (trust-region reflective,
with bounds),

* ``(v_sim(f_i) - v_meas,i) / sigma_i`` for every measured speed, and
* ``w * (1 - share of legs showing the observed pattern)`` for every leg-pattern
  observation (optional; the simulated legs are labelled from their knee records
  by :func:`labkit.sim.knee_patterns.classify_knee_pattern`, as the observed ones are),

where ``v_sim`` is the nominal robot's mean speed (magnitude of the mean forward
velocity: a tracked speed has no sign) from :func:`labkit.sim.simulate`
on the shaker at that point's frequency and tray amplitude. Every evaluation —
the residual and the forward-difference Jacobian, one batch of
``(parameters + 1) x points`` simulations per iteration — goes through
:func:`labkit.executor.map_tasks`, so it runs on local processes or on a Dask
cluster unchanged. All simulations use the same seed (common random numbers),
so the objective does not jitter from one evaluation to the next.

Uncertainty: the covariance ``(J^T J)^-1`` of the weighted residuals at the
solution (``sigma`` taken as absolute), inflated by the reduced chi-square
when that exceeds 1 (the model or the error bars do not explain the scatter).
The Jacobian of a hybrid (impacting) model is only piecewise smooth, so the
difference step is large on purpose (``rel_step``, default 5 %).
"""
from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TypedDict

import numpy as np

from labkit.errors import InputError
from labkit.sim.knee_patterns import PATTERNS
from labkit.sim.params import RobotParams

_NAME = re.compile(r"^([a-z_][a-z0-9_]*)(?:\[([0-2])\])?$")


# --------------------------------------------------------------------------- parameter access

def parse_names(params: RobotParams, names: Sequence[str]) -> list[tuple[str, int | None]]:
    """``"c_r"`` -> ``("c_r", None)``, ``"k_per_s2[1]"`` -> ``("k_per_s2", 1)``; InputError if unknown."""
    fields = params.to_dict()
    out = []
    for name in names:
        m = _NAME.match(name.strip())
        if not m or m.group(1) not in fields:
            raise InputError(f"unknown parameter {name!r}", key="--fit",
                             expected="RobotParams fields, e.g. c_r,c_ad_n,modal_participation,k_per_s2[1]")
        field_name, idx = m.group(1), (None if m.group(2) is None else int(m.group(2)))
        value = fields[field_name]
        if isinstance(value, list) and idx is None:
            raise InputError(f"{field_name} has one value per mode", key="--fit",
                             expected=f"{field_name}[0], {field_name}[1] or {field_name}[2]")
        if not isinstance(value, list) and idx is not None:
            raise InputError(f"{field_name} is a single number", key="--fit", expected=field_name)
        if isinstance(value, bool) or (not isinstance(value, list) and not isinstance(value, (int, float))):
            raise InputError(f"{field_name} is not a number", key="--fit")
        out.append((field_name, idx))
    if len(set(out)) != len(out):
        raise InputError("a parameter is named twice", key="--fit")
    return out


def label(name: tuple[str, int | None]) -> str:
    return name[0] if name[1] is None else f"{name[0]}[{name[1]}]"


def get_values(params: RobotParams, names: list[tuple[str, int | None]]) -> np.ndarray:
    d = params.to_dict()
    return np.array([d[n] if i is None else d[n][i] for n, i in names], float)


def set_values(params: RobotParams, names: list[tuple[str, int | None]],
               values: Sequence[float] | np.ndarray) -> RobotParams:
    scalars: dict[str, float] = {}
    vectors: dict[str, list[float]] = {}
    d = params.to_dict()
    for (n, i), v in zip(names, values):
        if i is None:
            scalars[n] = float(v)
        else:
            vectors.setdefault(n, [float(x) for x in d[n]])[i] = float(v)
    return params.replace(**scalars, **{n: tuple(v) for n, v in vectors.items()})


# --------------------------------------------------------------------------- simulation task

@dataclass(frozen=True)
class SpeedRun:
    """One simulated point: the speed (unsigned, as tracked), the signed mean velocity, the feet's
    contact patterns and the knees' patterns (labelled as measured knees are)."""

    speed_mm_s: float
    velocity_mm_s: float
    foot_patterns: tuple[str, ...]
    patterns: tuple[str, ...]


def speed_task(task: tuple[RobotParams, float, float, float, int]) -> SpeedRun:
    """One simulation: ``(params, freq_hz, amp_um, duration_s, seed)`` -> speed and foot patterns."""
    from labkit.sim import Shaker, simulate
    from labkit.sim.knee_patterns import classify_knee_pattern

    params, freq_hz, amp_um, duration_s, seed = task
    r = simulate(params, Shaker(freq_hz=float(freq_hz), amp_um=float(amp_um)), duration_s=duration_s, seed=seed)
    # observed patterns come from knee records: label the simulated knees the same way
    t = np.asarray(r.t_s)
    settled = t >= t[0] + 0.5 * (t[-1] - t[0])
    tray = np.gradient(np.asarray(r.ground_z_um), t) * 1e-3
    knee = np.asarray(r.knee_vz_mm_s)
    knee_patterns = [classify_knee_pattern(t[settled], knee[settled, j], tray[settled], freq_hz)["pattern"]
                     for j in range(knee.shape[1])]
    # measured speeds are unsigned (tracked path speed; the paper compares speed, not velocity)
    return SpeedRun(speed_mm_s=abs(float(r.mean_speed_mm_s)), velocity_mm_s=float(r.mean_speed_mm_s),
                    foot_patterns=tuple(str(p) for p in r.patterns), patterns=tuple(str(p) for p in knee_patterns))


@dataclass
class Observations:
    """What the calibration fits: speeds at shaker drives, optional pattern labels."""

    freq_hz: np.ndarray
    amp_um: np.ndarray
    speed_mm_s: np.ndarray
    speed_std_mm_s: np.ndarray
    patterns: list[str] | None = None          # one label (or "") per point
    sources: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Runner:
    """Where the simulations run (:func:`labkit.executor.map_tasks`): a Dask scheduler's address or
    local processes (``workers``), and whether to show progress."""

    scheduler: str | None = None
    workers: int | None = None
    quiet: bool = True


@dataclass(frozen=True)
class FitOptions:
    """How :func:`calibrate` fits.

    ``duration_s``, ``seed``: per simulation (the same seed everywhere: common random numbers).
    ``bounds``: ``{name: (lo, hi)}``; default from 0 (exclusive) to 4x the start value, ``c_r``
    within (0, 1]. ``rel_step``: the forward-difference step, relative to each start value.
    ``pattern_weight``: the weight of a pattern residual against one speed standard deviation.
    ``max_iterations``: Jacobian evaluations allowed (each ``len(names) x points`` simulations).
    ``min_std_mm_s``: floor of the speed standard deviations (a zero error bar would dominate).
    ``scan``: a Latin-hypercube sample of the bounded box scored before the local fit, which then
    starts from the best point (0: from the start values); ``scan_rounds``: rounds of it, each in
    a box 4x narrower (per parameter) around the best point so far.
    """

    duration_s: float = 1.0
    seed: int = 0
    bounds: dict[str, tuple[float, float]] | None = None
    rel_step: float = 0.05
    pattern_weight: float = 1.0
    max_iterations: int = 10
    min_std_mm_s: float = 0.05
    scan: int = 0
    scan_rounds: int = 3


class FitMetricsJSON(TypedDict, total=False):
    """:class:`FitMetrics` as JSON."""

    rms_error_mm_s: float
    chi2: float
    simulated_mm_s: list[float]
    pattern_agreement: float
    simulated_patterns: list[str]
    chi2_reduced: float


@dataclass(frozen=True)
class FitMetrics:
    """How well a parameter set meets the observations: RMS speed error, chi-square, the simulated
    speeds; with pattern observations the share of points whose dominant simulated pattern agrees."""

    rms_error_mm_s: float
    chi2: float
    simulated_mm_s: tuple[float, ...]
    pattern_agreement: float | None = None
    simulated_patterns: tuple[str, ...] | None = None
    chi2_reduced: float | None = None

    def to_json(self) -> FitMetricsJSON:
        out = FitMetricsJSON(rms_error_mm_s=self.rms_error_mm_s, chi2=self.chi2,
                             simulated_mm_s=list(self.simulated_mm_s))
        if self.pattern_agreement is not None:
            out["pattern_agreement"] = self.pattern_agreement
        if self.simulated_patterns is not None:
            out["simulated_patterns"] = list(self.simulated_patterns)
        if self.chi2_reduced is not None:
            out["chi2_reduced"] = self.chi2_reduced
        return out


class ParameterJSON(TypedDict):
    """One fitted parameter in :meth:`Calibration.summary`."""

    initial: float
    fitted: float
    std: float
    rel_change: float | None


class CalibrationSummary(TypedDict):
    """:meth:`Calibration.summary` (JSON: the command's output and side file)."""

    parameters: dict[str, ParameterJSON]
    correlation: list[list[float]]
    before: FitMetricsJSON
    after: FitMetricsJSON
    n_sims: int
    iterations: int
    status: str
    settings: dict[str, object]
    measured: list[str]


@dataclass(frozen=True)
class Calibration:
    """The outcome of :func:`calibrate`; ``settings`` the options used, with the start point of the
    local fit, the bounds and the scan's size (:meth:`summary`)."""

    names: list[str]
    initial: np.ndarray
    fitted: np.ndarray
    std: np.ndarray
    corr: np.ndarray
    before: FitMetrics
    after: FitMetrics
    params: RobotParams
    n_sims: int
    n_iterations: int
    status: str
    options: FitOptions
    runner: Runner
    start: dict[str, float]
    bounds: dict[str, tuple[float, float]]
    scanned: int
    use_patterns: bool
    sources: list[str]

    def settings(self) -> dict[str, object]:
        """The options as run (flat, JSON)."""
        o = self.options
        return {"duration_s": o.duration_s, "seed": o.seed, "rel_step": o.rel_step,
                "pattern_weight": o.pattern_weight if self.use_patterns else 0.0, "min_std_mm_s": o.min_std_mm_s,
                "scan": self.scanned, "scan_rounds": o.scan_rounds if o.scan else 0, "start": self.start,
                "bounds": {n: [float(a), float(b)] for n, (a, b) in self.bounds.items()},
                "scheduler": self.runner.scheduler or "local"}

    def summary(self) -> CalibrationSummary:
        return CalibrationSummary(
            parameters={n: ParameterJSON(initial=float(a), fitted=float(b), std=float(s),
                                         rel_change=float((b - a) / a) if a else None)
                        for n, a, b, s in zip(self.names, self.initial, self.fitted, self.std)},
            correlation=np.round(self.corr, 4).tolist(), before=self.before.to_json(), after=self.after.to_json(),
            n_sims=self.n_sims, iterations=self.n_iterations, status=self.status, settings=self.settings(),
            measured=list(self.sources))

    def provenance(self, start_params: str) -> dict[str, object]:
        """The ``[provenance]`` table of the written parameter file (``start_params``: where the
        start came from)."""
        used_patterns = self.use_patterns and self.before.pattern_agreement is not None
        return {"calibration": {
            "method": "scipy.optimize.least_squares (trf) on speed residuals / speed_std"
                      + (" + pattern residuals" if used_patterns else ""),
            "fitted": {n: float(v) for n, v in zip(self.names, self.fitted)},
            "std": {n: float(s) for n, s in zip(self.names, self.std)},
            "initial": {n: float(v) for n, v in zip(self.names, self.initial)},
            "rms_error_before_mm_s": self.before.rms_error_mm_s,
            "rms_error_after_mm_s": self.after.rms_error_mm_s,
            "measured": list(self.sources),
            "duration_s": self.options.duration_s, "seed": self.options.seed,
            "n_sims": self.n_sims, "status": self.status, "start_params": start_params}}


# --------------------------------------------------------------------------- the fit

def _metrics(obs: Observations, rows: Sequence[SpeedRun], chi2_reduced: float | None = None) -> FitMetrics:
    sim = np.array([r.speed_mm_s for r in rows])
    err = sim - obs.speed_mm_s
    agreement, simulated = None, None
    if obs.patterns and any(obs.patterns):
        pairs = [(o, _dominant(r.patterns)) for o, r in zip(obs.patterns, rows) if o]
        agreement = float(np.mean([a == b for a, b in pairs]))
        simulated = tuple(_dominant(r.patterns) for r in rows)
    return FitMetrics(rms_error_mm_s=float(np.sqrt(np.mean(err ** 2))),
                      chi2=float(np.sum((err / obs.speed_std_mm_s) ** 2)), simulated_mm_s=tuple(sim.tolist()),
                      pattern_agreement=agreement, simulated_patterns=simulated, chi2_reduced=chi2_reduced)


def _dominant(labels: Sequence[str]) -> str:
    labels = list(labels)
    return max(PATTERNS, key=lambda p: labels.count(p))


def _bounds(labels: list[str], x0: np.ndarray, given: dict[str, tuple[float, float]] | None
            ) -> dict[str, tuple[float, float]]:
    """Each parameter's bounds: given, or the defaults of :class:`FitOptions`; InputError when the
    start value lies outside."""
    out = {}
    for lab, v in zip(labels, x0):
        b = (given or {}).get(lab)
        if b is None:
            if lab in ("c_r", "c_r_body"):
                b = (0.0, 1.0)
            elif v != 0:
                b = (min(0.0, 4 * v), max(0.0, 4 * v))
            else:
                b = (-1.0, 1.0)
        if not b[0] <= v <= b[1]:
            raise InputError(f"start value {v:g} is outside the bounds {b}", key=lab)
        out[lab] = (float(b[0]), float(b[1]))
    return out


@dataclass(frozen=True)
class _Coordinates:
    """The fit's coordinates: each parameter divided by the magnitude of its start value."""

    params: RobotParams
    parsed: list[tuple[str, int | None]]
    scale: np.ndarray

    def params_at(self, x: np.ndarray) -> RobotParams:
        return set_values(self.params, self.parsed, x * self.scale)


class _Evaluator:
    """The fit's residuals: simulations batched through the executor, cached per point."""

    def __init__(self, coords: _Coordinates, obs: Observations, options: FitOptions, runner: Runner) -> None:
        self.coords, self.obs, self.o, self.runner = coords, obs, options, runner
        self.use_patterns = bool(options.pattern_weight) and any(obs.patterns or [])
        self.sims = 0
        self.jacobians = 0
        self.cache: dict[bytes, list[SpeedRun]] = {}

    def run_many(self, xs: Sequence[np.ndarray]) -> list[list[SpeedRun]]:
        from labkit.executor import map_tasks

        todo = [x for x in xs if x.tobytes() not in self.cache]
        if todo:
            tasks = []
            for x in todo:
                p = self.coords.params_at(x)
                tasks += [(p, f, a, self.o.duration_s, self.o.seed) for f, a in zip(self.obs.freq_hz, self.obs.amp_um)]
            rows = map_tasks(speed_task, tasks, scheduler=self.runner.scheduler, workers=self.runner.workers,
                             desc="calibrate", quiet=self.runner.quiet)
            self.sims += len(tasks)
            n = len(self.obs.freq_hz)
            for k, x in enumerate(todo):
                self.cache[x.tobytes()] = rows[k * n:(k + 1) * n]
        return [self.cache[x.tobytes()] for x in xs]

    def residual_of(self, rows: Sequence[SpeedRun]) -> np.ndarray:
        obs = self.obs
        r = [(row.speed_mm_s - m) / s for row, m, s in zip(rows, obs.speed_mm_s, obs.speed_std_mm_s)]
        if self.use_patterns:
            for o, row in zip(obs.patterns or [], rows):
                if o:
                    share = sum(p == o for p in row.patterns) / max(1, len(row.patterns))
                    r.append(self.o.pattern_weight * (1.0 - share))
        return np.array(r)

    def fun(self, x: np.ndarray) -> np.ndarray:
        return self.residual_of(self.run_many([np.asarray(x, float)])[0])

    def jac(self, x: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Forward differences (stepping back at an upper bound ``hi``), one batch of simulations."""
        x = np.asarray(x, float)
        self.jacobians += 1
        steps = []
        for k in range(x.size):
            h = self.o.rel_step if x[k] + self.o.rel_step <= hi[k] else -self.o.rel_step
            xk = x.copy()
            xk[k] += h
            steps.append((xk, h))
        base, *shifted = self.run_many([x] + [s[0] for s in steps])
        r0 = self.residual_of(base)
        return np.column_stack([(self.residual_of(rows) - r0) / h for rows, (_, h) in zip(shifted, steps)])

    def scan(self, x_start: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, int]:
        """A zoom search from ``x_start`` (:class:`FitOptions` ``scan``); the best point and the
        points scored. A hybrid model's speed is only piecewise smooth in its parameters: a local
        fit from the start value stalls in kinks. Score a space-filling sample of the bounded box
        (one batch of simulations), then of boxes shrinking around the best point so far."""
        from scipy.stats import qmc

        best_x = x_start
        best_cost = float(np.sum(self.residual_of(self.run_many([x_start])[0]) ** 2))
        lo_box, hi_box = lo.copy(), hi.copy()
        scanned, zoom = 0, 4.0
        for rnd in range(max(1, int(self.o.scan_rounds))):
            sample = qmc.LatinHypercube(d=x_start.size, seed=self.o.seed + rnd).random(int(self.o.scan))
            cands = [np.asarray(c, float) for c in qmc.scale(sample, lo_box, hi_box)]
            for c, rows in zip(cands, self.run_many(cands)):
                cost = float(np.sum(self.residual_of(rows) ** 2))
                if cost < best_cost:
                    best_x, best_cost = c, cost
            scanned += len(cands)
            half = (hi_box - lo_box) / (2 * zoom)
            lo_box = np.maximum(lo, best_x - half)
            hi_box = np.minimum(hi, best_x + half)
        return best_x, scanned


def _covariance(jac: np.ndarray, residual: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Standard deviations and correlation of the fitted parameters: ``(J^T J)^-1`` inflated by the
    reduced chi-square when it exceeds 1; and that chi-square."""
    dof = max(1, residual.size - n)
    chi2_red = float(np.sum(residual ** 2) / dof)
    try:
        cov = np.linalg.pinv(jac.T @ jac) * max(1.0, chi2_red)
    except np.linalg.LinAlgError:  # pragma: no cover - pinv handles singular J
        cov = np.full((n, n), np.nan)
    sd_x = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd_x, sd_x)
    return sd_x, np.nan_to_num(corr), chi2_red


def calibrate(params: RobotParams, names: Sequence[str], obs: Observations, options: FitOptions = FitOptions(),
              runner: Runner = Runner(quiet=False)) -> Calibration:
    """Fit ``names`` of ``params`` to the observed speeds (and patterns).

    Parameters
    ----------
    params:
        Starting :class:`~labkit.sim.RobotParams`.
    names:
        Parameters to fit (``c_r``, ``c_ad_n``, ``k_per_s2[1]`` ...).
    obs:
        The measurements.
    options:
        The fit's settings (:class:`FitOptions`: duration, seed, bounds, steps, scan).
    runner:
        Where the simulations run (:class:`Runner`).
    """
    from scipy.optimize import least_squares

    parsed = parse_names(params, names)
    labels = [label(n) for n in parsed]
    x0 = get_values(params, parsed)
    scale = np.where(x0 != 0, np.abs(x0), 1.0)
    bounds = _bounds(labels, x0, options.bounds)
    lo_a = np.array([bounds[lab][0] for lab in labels]) / scale + 1e-9
    hi_a = np.array([bounds[lab][1] for lab in labels]) / scale - 1e-9
    std = np.maximum(np.asarray(obs.speed_std_mm_s, float), options.min_std_mm_s)
    obs = Observations(np.asarray(obs.freq_hz, float), np.asarray(obs.amp_um, float),
                       np.asarray(obs.speed_mm_s, float), std, obs.patterns, obs.sources)
    ev = _Evaluator(_Coordinates(params, parsed, scale), obs, options, runner)
    x_start = np.clip(x0 / scale, lo_a, hi_a)
    before_rows = ev.run_many([x_start])[0]
    scanned = 0
    if options.scan > 0:
        x_start, scanned = ev.scan(x_start, lo_a, hi_a)
    sol = least_squares(ev.fun, x_start, jac=lambda x: ev.jac(x, hi_a), bounds=(lo_a, hi_a), method="trf",
                        x_scale=1.0, max_nfev=options.max_iterations + 1, diff_step=None)
    after_rows = ev.run_many([np.asarray(sol.x, float)])[0]
    sd_x, corr, chi2_red = _covariance(np.asarray(sol.jac, float), sol.fun, x0.size)
    fitted = sol.x * scale
    return Calibration(names=labels, initial=x0, fitted=fitted, std=sd_x * scale, corr=corr,
                       before=_metrics(obs, before_rows), after=_metrics(obs, after_rows, chi2_red),
                       params=set_values(params, parsed, fitted), n_sims=ev.sims, n_iterations=ev.jacobians,
                       status=str(sol.message), options=options, runner=runner,
                       start=dict(zip(labels, (x_start * scale).tolist())),
                       bounds={lab: (float(a), float(b)) for lab, a, b in zip(labels, lo_a * scale, hi_a * scale)},
                       scanned=scanned, use_patterns=ev.use_patterns, sources=list(obs.sources))
