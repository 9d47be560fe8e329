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
from typing import Any

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
    changes: dict[str, Any] = {}
    d = params.to_dict()
    for (n, i), v in zip(names, values):
        if i is None:
            changes[n] = float(v)
        else:
            cur = list(changes.get(n, d[n]))
            cur[i] = float(v)
            changes[n] = tuple(cur)
    return params.replace(**changes)


# --------------------------------------------------------------------------- simulation task

def speed_task(task: tuple) -> dict[str, Any]:
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
    return {"speed_mm_s": abs(float(r.mean_speed_mm_s)), "velocity_mm_s": float(r.mean_speed_mm_s),
            "foot_patterns": [str(p) for p in r.patterns], "patterns": knee_patterns}


@dataclass
class Observations:
    """What the calibration fits: speeds at shaker drives, optional pattern labels."""

    freq_hz: np.ndarray
    amp_um: np.ndarray
    speed_mm_s: np.ndarray
    speed_std_mm_s: np.ndarray
    patterns: list[str] | None = None          # one label (or "") per point
    sources: list[str] = field(default_factory=list)


@dataclass
class Calibration:
    """The outcome of :func:`calibrate`."""

    names: list[str]
    initial: np.ndarray
    fitted: np.ndarray
    std: np.ndarray
    corr: np.ndarray
    before: dict[str, Any]
    after: dict[str, Any]
    params: RobotParams
    n_sims: int
    n_iterations: int
    status: str
    settings: dict[str, Any]
    sources: list[str]

    def summary(self) -> dict[str, Any]:
        return {"parameters": {n: {"initial": float(a), "fitted": float(b), "std": float(s),
                                   "rel_change": float((b - a) / a) if a else None}
                               for n, a, b, s in zip(self.names, self.initial, self.fitted, self.std)},
                "correlation": np.round(self.corr, 4).tolist(),
                "before": self.before, "after": self.after, "n_sims": self.n_sims,
                "iterations": self.n_iterations, "status": self.status, "settings": self.settings,
                "measured": self.sources}

    def provenance(self) -> dict[str, Any]:
        """The ``[provenance]`` table of the written parameter file."""
        return {"calibration": {
            "method": "scipy.optimize.least_squares (trf) on speed residuals / speed_std"
                      + (" + pattern residuals" if self.settings.get("pattern_weight") and self.before.get(
                          "pattern_agreement") is not None else ""),
            "fitted": {n: float(v) for n, v in zip(self.names, self.fitted)},
            "std": {n: float(s) for n, s in zip(self.names, self.std)},
            "initial": {n: float(v) for n, v in zip(self.names, self.initial)},
            "rms_error_before_mm_s": self.before["rms_error_mm_s"],
            "rms_error_after_mm_s": self.after["rms_error_mm_s"],
            "measured": list(self.sources),
            "duration_s": self.settings["duration_s"], "seed": self.settings["seed"],
            "n_sims": self.n_sims, "status": self.status}}


# --------------------------------------------------------------------------- the fit

def _metrics(obs: Observations, rows: list[dict[str, Any]]) -> dict[str, Any]:
    sim = np.array([r["speed_mm_s"] for r in rows])
    err = sim - obs.speed_mm_s
    out = {"rms_error_mm_s": float(np.sqrt(np.mean(err ** 2))),
           "chi2": float(np.sum((err / obs.speed_std_mm_s) ** 2)),
           "simulated_mm_s": sim.tolist()}
    if obs.patterns and any(obs.patterns):
        pairs = [(o, _dominant(r["patterns"])) for o, r in zip(obs.patterns, rows) if o]
        out["pattern_agreement"] = float(np.mean([a == b for a, b in pairs]))
        out["simulated_patterns"] = [_dominant(r["patterns"]) for r in rows]
    return out


def _dominant(labels: Sequence[str]) -> str:
    labels = list(labels)
    return max(PATTERNS, key=lambda p: labels.count(p))


def calibrate(params: RobotParams, names: Sequence[str], obs: Observations, *, duration_s: float = 1.0, seed: int = 0,
              bounds: dict[str, tuple[float, float]] | None = None, rel_step: float = 0.05,
              pattern_weight: float = 1.0, max_iterations: int = 10, min_std_mm_s: float = 0.05, scan: int = 0,
              scan_rounds: int = 3,
              scheduler: str | None = None, workers: int | None = None, quiet: bool = False) -> Calibration:
    """Fit ``names`` of ``params`` to the observed speeds (and patterns).

    Parameters
    ----------
    params:
        Starting :class:`~labkit.sim.RobotParams`.
    names:
        Parameters to fit (``c_r``, ``c_ad_n``, ``k_per_s2[1]`` ...).
    obs:
        The measurements.
    duration_s, seed:
        Per simulation (the same seed everywhere: common random numbers).
    bounds:
        ``{name: (lo, hi)}``; default: from 0 (exclusive) to 4x the start
        value, and ``c_r`` within (0, 1].
    rel_step:
        Forward-difference step, relative to each start value.
    pattern_weight:
        Weight of a pattern residual against one speed standard deviation.
    max_iterations:
        Jacobian evaluations allowed (each is ``len(names) x points`` simulations).
    min_std_mm_s:
        Floor of the speed standard deviations (a zero error bar would dominate).
    scan:
        Size of a Latin-hypercube sample of the bounded box scored before the
        local fit, which then starts from the best point (0: start from ``params``).
    scan_rounds:
        Rounds of that sampling; each round after the first samples a box 4x
        narrower (per parameter) around the best point so far.
    """
    from scipy.optimize import least_squares

    from labkit.executor import map_tasks

    parsed = parse_names(params, names)
    labels = [label(n) for n in parsed]
    x0 = get_values(params, parsed)
    scale = np.where(x0 != 0, np.abs(x0), 1.0)
    lo, hi = [], []
    for lab, v in zip(labels, x0):
        b = (bounds or {}).get(lab)
        if b is None:
            if lab in ("c_r", "c_r_body"):
                b = (0.0, 1.0)
            elif v != 0:
                b = (min(0.0, 4 * v), max(0.0, 4 * v))
            else:
                b = (-1.0, 1.0)
        if not b[0] <= v <= b[1]:
            raise InputError(f"start value {v:g} is outside the bounds {b}", key=lab)
        lo.append(b[0] / scale[labels.index(lab)])
        hi.append(b[1] / scale[labels.index(lab)])
    lo_a = np.array(lo) + 1e-9
    hi_a = np.array(hi) - 1e-9
    std = np.maximum(np.asarray(obs.speed_std_mm_s, float), min_std_mm_s)
    obs = Observations(np.asarray(obs.freq_hz, float), np.asarray(obs.amp_um, float),
                       np.asarray(obs.speed_mm_s, float), std, obs.patterns, obs.sources)
    patterns = obs.patterns or []
    use_patterns = bool(pattern_weight) and any(patterns)
    counter = {"sims": 0, "jac": 0}
    cache: dict[bytes, list[dict[str, Any]]] = {}

    def tasks_for(x: np.ndarray) -> list[tuple]:
        p = set_values(params, parsed, x * scale)
        return [(p, f, a, duration_s, seed) for f, a in zip(obs.freq_hz, obs.amp_um)]

    def run_many(xs: list[np.ndarray]) -> list[list[dict[str, Any]]]:
        todo = [x for x in xs if x.tobytes() not in cache]
        if todo:
            tasks = [t for x in todo for t in tasks_for(x)]
            rows = map_tasks(speed_task, tasks, scheduler=scheduler, workers=workers, desc="calibrate", quiet=quiet)
            counter["sims"] += len(tasks)
            n = len(obs.freq_hz)
            for k, x in enumerate(todo):
                cache[x.tobytes()] = rows[k * n:(k + 1) * n]
        return [cache[x.tobytes()] for x in xs]

    def residual_of(rows: list[dict[str, Any]]) -> np.ndarray:
        r = [(row["speed_mm_s"] - m) / s for row, m, s in zip(rows, obs.speed_mm_s, obs.speed_std_mm_s)]
        if use_patterns:
            for o, row in zip(patterns, rows):
                if o:
                    share = sum(p == o for p in row["patterns"]) / max(1, len(row["patterns"]))
                    r.append(pattern_weight * (1.0 - share))
        return np.array(r)

    def fun(x: np.ndarray) -> np.ndarray:
        return residual_of(run_many([np.asarray(x, float)])[0])

    def jac(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)
        counter["jac"] += 1
        steps = []
        for k in range(x.size):
            h = rel_step if x[k] + rel_step <= hi_a[k] else -rel_step      # step back at an upper bound
            xk = x.copy()
            xk[k] += h
            steps.append((xk, h))
        base, *shifted = run_many([x] + [s[0] for s in steps])
        r0 = residual_of(base)
        return np.column_stack([(residual_of(rows) - r0) / h for rows, (_, h) in zip(shifted, steps)])

    x_start = np.clip(x0 / scale, lo_a, hi_a)
    before_rows = run_many([x_start])[0]
    scanned = 0
    zoom = 4.0
    if scan > 0:
        # A hybrid model's speed is only piecewise smooth in its parameters: a local fit from
        # the start value stalls in kinks. Score a space-filling sample of the bounded box (one
        # batch of simulations), then of boxes shrinking around the best point so far (a zoom
        # search), and start the local fit from the best point found.
        from scipy.stats import qmc

        best_x, best_cost = x_start, float(np.sum(residual_of(before_rows) ** 2))
        lo_box, hi_box = lo_a.copy(), hi_a.copy()
        for rnd in range(max(1, int(scan_rounds))):
            sample = qmc.LatinHypercube(d=x0.size, seed=seed + rnd).random(int(scan))
            cands = [np.asarray(c, float) for c in qmc.scale(sample, lo_box, hi_box)]
            for c, rows in zip(cands, run_many(cands)):
                cost = float(np.sum(residual_of(rows) ** 2))
                if cost < best_cost:
                    best_x, best_cost = c, cost
            scanned += len(cands)
            half = (hi_box - lo_box) / (2 * zoom)
            lo_box = np.maximum(lo_a, best_x - half)
            hi_box = np.minimum(hi_a, best_x + half)
        x_start = best_x
    sol = least_squares(fun, x_start, jac=jac, bounds=(lo_a, hi_a), method="trf", x_scale=1.0,
                        max_nfev=max_iterations + 1, diff_step=None)
    after_rows = run_many([np.asarray(sol.x, float)])[0]
    J = np.asarray(sol.jac, float)          # the Jacobian at the solution (linear loss: unmodified)
    m_res = sol.fun.size
    dof = max(1, m_res - x0.size)
    chi2_red = float(np.sum(sol.fun ** 2) / dof)
    try:
        cov = np.linalg.pinv(J.T @ J) * max(1.0, chi2_red)
    except np.linalg.LinAlgError:  # pragma: no cover - pinv handles singular J
        cov = np.full((x0.size, x0.size), np.nan)
    sd_x = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd_x, sd_x)
    fitted = sol.x * scale
    return Calibration(names=labels, initial=x0, fitted=fitted, std=sd_x * scale, corr=np.nan_to_num(corr),
                       before=_metrics(obs, before_rows), after=dict(_metrics(obs, after_rows), chi2_reduced=chi2_red),
                       params=set_values(params, parsed, fitted), n_sims=counter["sims"],
                       n_iterations=counter["jac"], status=str(sol.message),
                       settings={"duration_s": duration_s, "seed": seed, "rel_step": rel_step,
                                 "pattern_weight": pattern_weight if use_patterns else 0.0,
                                 "min_std_mm_s": min_std_mm_s, "scan": scanned,
                                 "scan_rounds": scan_rounds if scan else 0,
                                 "start": dict(zip(labels, (x_start * scale).tolist())),
                                 "bounds": {n: [float(a), float(b)]
                                            for n, a, b in zip(labels, lo_a * scale, hi_a * scale)},
                                 "scheduler": scheduler or "local"},
                       sources=list(obs.sources))
