"""Step-error control of a run: rerun it at half the step, halve until they agree.

Every :func:`labkit.sim.core.simulate` run (numba engine, ``error_control="check"``, the
default) goes through :func:`control` after its main run at the step ``h``
(docs/model.md, "Error control and validity"):

1. the run is repeated at ``h/2``; the step error of the run at ``h`` is estimated as
   :data:`ERROR_FACTOR` times the difference of the two mean speeds (first-order
   convergence, the safe side: the events make the scheme first order in places), and
   must be within ``max(STEP_TOL_REL |v|, STEP_TOL_ABS_MM_S)``;
2. the run is also repeated at ``h`` from a start 0.05 um apart (the leg modes jittered,
   the next seed); if that moves the speed beyond the same tolerance the run is sensitive
   at this step;
3. a failing run halves its step until the runs at ``h/2^k`` and ``h/2^(k+1)`` agree (at
   most :data:`MAX_HALVINGS` halvings) and the run at ``h/2^k`` is the result
   (``refined``); when none agrees, the finest run is the result, flagged ``not_converged``.
   A pair that agrees by more than :data:`CONFIRM_FRACTION` of the tolerance is confirmed by
   the run at the next half step (:func:`_confirmed`; two steps can agree by chance before
   the sequence converges): the run at ``h/2^k`` is kept only when it is also within the
   tolerance of the run at ``h/2^(k+2)`` (4/3 of their difference) and the finer pair agrees;
   otherwise the walk goes on from ``h/2^(k+1)``, the runs already made reused;
4. a run sensitive at :data:`CHAOS_LEVELS` successive steps (each probed once the one
   before was sensitive), or at the step that agreed with half of it, is *chaotic*: no
   single trajectory converges; it is kept at that step and flagged, never refined further.
   A coarse step can make a robot that, resolved, stands still jump and scatter (a shaker
   case at 950 Hz, 76 um: 1.98 and 3.05 mm/s at h and h/2, seeds 0.6 apart; 0.001 mm/s
   from h/4 on, seeds agreeing): one sensitive step is not enough to call it chaotic.

A run that is *held* (:func:`held`: every foot pinned and sticking at every step, far from
letting go, :data:`labkit.sim.scheme.NEAR_FRACTION`; no impact, release or slip, the body off the
ground, its speed below :data:`HELD_SPEED_FRACTION` of the tolerance) and whose probe is held too
is ``converged`` without the run at ``h/2`` (``basis = "held"``): with no event the scheme is the
midpoint rule on smooth dynamics, whose forces at a finer step differ by a few per cent of their
oscillation, far inside the hold left, so the finer run is held as well, and a held robot's speed
is its elastic deflection over the run; the error estimate is twice the sum of the two runs'
speeds. Cost: 2 runs' worth. :func:`labkit.sim.core.simulate` tries every checked run held at k
times its step first (:func:`labkit.sim.core.held_step_factor`, from the robot's pinned modes;
:func:`control_held`), so a robot that stands costs 2/k runs' worth (docs/model.md, "Held runs").

The whole run is checked, not a stretch of it: on random Monte Carlo cases a check over
the first quarter passed runs whose error grew later (bench/convergence_bench.py). Cost of a
held run: 2 runs' worth; of another run that passes: 4 runs' worth (the run, twice its steps,
the probe), 8 when the pass is marginal and confirmed (four times its steps on top); of a
chaotic one 14; of one refined k times about 2^(k+2); sweeps check a sample
(:mod:`labkit.sim.sweep`).
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from labkit.sim.result import Convergence, SimResult

#: The tolerance of the check: the estimated step error within this fraction of the speed ...
STEP_TOL_REL = 0.03
#: ... or this many mm/s (what a tracked video resolves over a few seconds; meaningful for slow runs).
STEP_TOL_ABS_MM_S = 0.02
#: The step error of the run at h, estimated from the speeds at h and h/2: this many times
#: their difference (2: first-order convergence; 4/3 would assume second order).
ERROR_FACTOR = 2.0
#: Two steps that agree, but by more than this fraction of the tolerance, are confirmed by the
#: next half step (:func:`_confirmed`): two steps can agree before the step sequence reaches
#: its asymptotic range (PZT 667 Hz, 23.6 V on a draw of the paper robot: -3.57 and -3.62 mm/s
#: at h and h/2, -3.02, -2.66, -2.50 at h/4 .. h/16).
CONFIRM_FRACTION = 0.5
#: At most this many halvings of the step (h/16).
MAX_HALVINGS = 4
#: A run is chaotic when starts 0.05 um apart differ beyond the tolerance at this many
#: successive steps (h, h/2, h/4) while the steps disagree, or at the step that agrees with
#: half of it: a coarse step can make a robot jump and scatter that, resolved, stands still.
CHAOS_LEVELS = 3

#: A held run's speed (and its probe's) must be below this fraction of the tolerance (:func:`held`).
HELD_SPEED_FRACTION = 0.25

#: ``run(dt_s, seed) -> SimResult``: the same run (robot, drive, duration, start, transient,
#: recording) at another step or from another seed, without error control.
Runner = Callable[[float, "int | None"], SimResult]


def tolerance_mm_s(v_mm_s: float) -> float:
    """The allowed step error at a mean speed ``v``: ``max(STEP_TOL_REL |v|, STEP_TOL_ABS_MM_S)``."""
    return max(STEP_TOL_REL * abs(v_mm_s), STEP_TOL_ABS_MM_S)


def probe_seed(seed: int | None) -> int:
    """The seed of the chaos probe's start: the next one (1 for a run started exactly at rest)."""
    return 1 if seed is None else int(seed) + 1


def held(r: SimResult) -> bool:
    """Was every foot held on the ground for the whole run, far from letting go (module doc)?

    True when the kernel counted no impact, release or lost event and no contact check near a
    release (``counters["checks_near_release"]``: a hold left below half the larger of the hold
    and the largest force the foot bore, a lateral force above half what friction allows, a foot
    sliding, the body resting on the ground), no foot spent measured time in the air, and the
    speed is below :data:`HELD_SPEED_FRACTION` of the tolerance."""
    c = r.counters
    if any(c.get(k, 1) != 0 for k in ("releases", "checks_near_release", "events_lost")):
        return False
    if int(np.sum(r.impacts)) or r.body_impacts:
        return False
    if any(frac.get("air", 1.0) > 0.0 for frac in r.contact_fraction.values()):
        return False
    v = r.mean_speed_mm_s
    return math.isfinite(v) and abs(v) <= HELD_SPEED_FRACTION * tolerance_mm_s(v)


def _confirmed(runs: list[SimResult], k: int, run: Runner) -> tuple[bool, float]:
    """A marginal agreement of the runs at levels k and k+1 (module doc, step 3), checked by the
    run at k+2 (appended to ``runs``): (whether it holds, the error estimate of the run at k).

    First-order convergence from level k: the run at k is off by twice its difference from k+1,
    and by 4/3 of its difference from k+2; both within the tolerance of the finest run, and the
    pair (k+1, k+2) agreeing by the same test as (k, k+1)."""
    if len(runs) < k + 3:
        runs.append(run(runs[0].dt_s / 2 ** (k + 2), runs[0].seed))
    v, w, x = (runs[i].mean_speed_mm_s for i in (k, k + 1, k + 2))
    tol = tolerance_mm_s(x)
    err = max(ERROR_FACTOR * abs(v - w), 4.0 / 3.0 * abs(v - x))
    return err <= tol and ERROR_FACTOR * abs(w - x) <= tol, err


def _status(runs: list[SimResult], spreads: list[float], run: Runner) -> tuple[str, int, float, float]:
    """Walk down the steps (module doc): (status, level of the result, error, tolerance)."""
    h, seed, sensitive_levels = runs[0].dt_s, runs[0].seed, 0
    for k in range(MAX_HALVINGS):
        v = runs[k].mean_speed_mm_s
        if len(spreads) == k:                     # probe a finer level only after a sensitive one
            spreads.append(run(runs[k].dt_s, probe_seed(seed)).mean_speed_mm_s - v
                           if sensitive_levels else 0.0)
        sensitive = abs(spreads[k]) > tolerance_mm_s(v)
        sensitive_levels = sensitive_levels + 1 if sensitive else 0
        if sensitive_levels >= CHAOS_LEVELS:
            return "chaotic", k, math.nan, tolerance_mm_s(v)
        if len(runs) < k + 2:
            runs.append(run(h / 2 ** (k + 1), seed))
        w = runs[k + 1].mean_speed_mm_s
        err, tol = ERROR_FACTOR * abs(v - w), tolerance_mm_s(w)
        if err <= tol and not sensitive and err > CONFIRM_FRACTION * tol and k + 2 <= MAX_HALVINGS:
            ok, err3 = _confirmed(runs, k, run)
            if not ok:
                continue
            err, tol = err3, tolerance_mm_s(runs[k + 2].mean_speed_mm_s)
        if err <= tol:
            return ("chaotic" if sensitive else "converged" if k == 0 else "refined"), k, err, tol
    return "not_converged", MAX_HALVINGS, err, tol


def control(r: SimResult, run: Runner) -> SimResult:
    """Check the step of the run ``r``, refine or flag it (module doc); returns the result to
    keep, with :attr:`SimResult.convergence` and its validity flags set."""
    t0 = time.perf_counter()
    runs = [r]
    probe = run(r.dt_s, probe_seed(r.seed))
    if held(r) and held(probe):
        return control_held(r, probe, r.dt_s)
    spreads = [probe.mean_speed_mm_s - r.mean_speed_mm_s]
    status, k, err, tol = _status(runs, spreads, run)
    out = runs[k]
    if out.validity is not None:
        out.validity.chaotic = status == "chaotic"
        out.validity.not_converged = status == "not_converged"
    out.convergence = Convergence(status=status, dt_s=out.dt_s, default_dt_s=r.dt_s, error_mm_s=float(err),
                                  tolerance_mm_s=float(tol), seed_spread_mm_s=float(spreads[min(k, len(spreads) - 1)]),
                                  measured_s=(float(r.transient_s), float(r.duration_s)), halvings=k,
                                  speeds_mm_s=tuple(float(x.mean_speed_mm_s) for x in runs),
                                  wall_s=time.perf_counter() - t0, basis="halving")
    return out


def control_held(r: SimResult, probe: SimResult, default_dt_s: float) -> SimResult:
    """The result of a run held to the end, at the default step ``default_dt_s`` or a multiple of
    it, its probe held too (:func:`held`; module doc): ``converged`` on the ``"held"`` basis, at its
    own step; the check's cost (``wall_s``) is the probe's."""
    v, vp = r.mean_speed_mm_s, probe.mean_speed_mm_s
    if r.validity is not None:
        r.validity.chaotic = False
        r.validity.not_converged = False
    r.convergence = Convergence(status="converged", dt_s=r.dt_s, default_dt_s=default_dt_s,
                                error_mm_s=float(ERROR_FACTOR * (abs(v) + abs(vp))),
                                tolerance_mm_s=float(tolerance_mm_s(v)), seed_spread_mm_s=float(vp - v),
                                measured_s=(float(r.transient_s), float(r.duration_s)), halvings=0,
                                speeds_mm_s=(float(v),), wall_s=float(probe.wall_s), basis="held")
    return r


def unchecked(r: SimResult) -> SimResult:
    """Mark a run whose step was not checked (error control off, reference engine)."""
    r.convergence = Convergence(status="unchecked", dt_s=r.dt_s, default_dt_s=r.dt_s)
    return r


def agree(a_mm_s: np.ndarray, b_mm_s: np.ndarray) -> np.ndarray:
    """Element-wise: do two speeds agree within :func:`tolerance_mm_s` of the second?"""
    b = np.asarray(b_mm_s, float)
    return np.abs(np.asarray(a_mm_s, float) - b) <= np.maximum(STEP_TOL_REL * np.abs(b), STEP_TOL_ABS_MM_S)
