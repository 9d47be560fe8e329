"""Calibrate the parameters the paper did not measure to the paper's observations.

The objective (:func:`objective`, :func:`cost_of`) is the sum over the observations of
``observations.toml`` of ``tanh(violation)`` (:func:`labkit.sim.paper.observations.violation`:
0 inside the observation's band, else the distance outside it in units of the
band): a smoothed count of the observations not met, each scored exactly as the
``paper-*`` scenarios score it at their ``quick`` size, except that the bands are
narrowed by :data:`OBJECTIVE_MARGIN` (5 % of a band's scale per side) so that the
search ends inside them, not on their edges.

Free parameters (:data:`FREE`), each with bounds from physics, not from the answer:

=======================  ====================  ============================================================
parameter                bounds                why these bounds
=======================  ====================  ============================================================
``c_ad_n``               0.01-50 uN (log)      50 uN is the published value (Table 1, from prior works, ~15x
                                               the robot's weight); nothing was measured on this robot
``c_ad_t_n_s``           1e-9-1e-5 N/s (log)   published 1e-7 N/s, +-2 decades (from prior works)
``c_r`` (= ``c_r_body``) 0.1-0.9               a restitution coefficient: not measured (model.md choice 0.5)
``squeeze_scale``        0.1-10 (log)          both squeeze-film coefficients x this; estimated from the
                                               geometry with the gap cubed: x10 is a gap x2.2
``act_scale``            0.5-2.0               the actuator gains x this; the default's static foot deflection,
                                               5.3 um/V vertical, x0.5-2 spans the measured 50-100 um at
                                               10-20 V (2.5-10 um/V, paper Sec. 2)
``cy_sign[1]``,          -1 or +1              signs of the vertical modes' lateral coupling (the ratios stay
``cy_sign[2]``                                 the paper's 15, 1/17, 1/15 from COMSOL; the signs are not given)
=======================  ====================  ============================================================

``modal_participation`` is no longer free: it is the uniform cantilever's tip participation
(:data:`labkit.sim.params.CANTILEVER_TIP_PARTICIPATION`, docs/model.md M13), so the legs'
stiffness at the foot follows from their mass and Table 2's frequencies. A search may still
name it in ``free`` (:data:`EXTRA_FREE`), for studies.

The ensemble objective (``SearchSettings.ensemble > 0``): every candidate is scored over its
nominal robot and ``ensemble`` robots drawn from the Monte Carlo table
(:data:`labkit.sim.uncertainty.DEFAULT_TABLE`; the same draw factors for every candidate: common
random numbers) by the project's ensemble scorer, :func:`labkit.sim.paper.ensemble.score_ensemble`
(pooled verdicts: met / not met / not applicable), turned into a cost by :func:`ensemble_score`.

The search (:func:`calibrate_paper`), all simulations through
:func:`labkit.executor.map_tasks` (common random numbers: every candidate runs
with the same seeds, so the objective does not jitter between candidates):

1. a scrambled Sobol sample of ``scan`` points over the box (log scale where
   marked, signs drawn at random), plus the start point;
2. ``rounds`` zoom rounds: a new Sobol sample of ``scan // 2`` points in a box
   ``zoom`` times narrower around the best point so far (signs fixed to the best's);
3. a Nelder-Mead polish of the continuous parameters from the best point
   (``polish`` objective evaluations at most; a hybrid, impacting model is only
   piecewise smooth, so no gradients).

It reports, for the best point: the fitted values; their spread over the
near-optimal set (every evaluated point whose objective is within ``slack`` of
the best: a set-valued uncertainty, the honest one for a piecewise objective);
the violation of every observation before (the start) and after; and, over all
evaluated points, which observations were never met together (pairs each met
by some point but never by the same one) and the rank correlation of their
violations (negative: they pull against each other).
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from labkit.errors import InputError
from labkit.sim.calibrate import Runner
from labkit.sim.paper.observations import NOT_APPLICABLE, Observation, observations, violation
from labkit.sim.paper.shaker import PAPER_SHAKER, ShakerLaw
from labkit.sim.params import RobotParams

if TYPE_CHECKING:
    from labkit.sim.paper.ensemble import EnsembleScore
    from labkit.sim.scenarios.paper import Plan
    from labkit.sim.scenarios.runs import Task


@dataclass(frozen=True)
class Free:
    """One free parameter: its bounds, scale, and how it sets a RobotParams."""

    name: str
    lo: float
    hi: float
    log: bool
    unit: str
    why: str
    kind: str = "float"          # "float" | "sign"

    def to_unit(self, v: float) -> float:
        """Value -> [0, 1] box coordinate."""
        if self.kind == "sign":
            return 1.0 if v > 0 else 0.0
        if self.log:
            return (math.log(v) - math.log(self.lo)) / (math.log(self.hi) - math.log(self.lo))
        return (v - self.lo) / (self.hi - self.lo)

    def from_unit(self, u: float) -> float:
        """[0, 1] box coordinate -> value (clipped to the bounds)."""
        u = min(max(float(u), 0.0), 1.0)
        if self.kind == "sign":
            return 1.0 if u >= 0.5 else -1.0
        if self.log:
            v = math.exp(math.log(self.lo) + u * (math.log(self.hi) - math.log(self.lo)))
        else:
            v = self.lo + u * (self.hi - self.lo)
        return min(max(v, self.lo), self.hi)


FREE: tuple[Free, ...] = (
    Free("c_ad_n", 0.01e-6, 50e-6, True, "N", "adhesion at first contact; published 50 uN from prior works"),
    Free("c_ad_t_n_s", 1e-9, 1e-5, True, "N/s", "adhesion growth; published 1e-7 N/s, +-2 decades"),
    Free("c_r", 0.1, 0.9, False, "1", "restitution of foot and body (one value); model.md choice 0.5"),
    Free("squeeze_scale", 0.1, 10.0, True, "1", "both squeeze-film coefficients x this (gap x0.46-2.2)"),
    Free("act_scale", 0.5, 2.0, True, "1", "actuator gains x this: 2.6-10.6 um/V static, measured 2.5-10"),
    Free("cy_sign[1]", -1.0, 1.0, False, "1", "sign of mode 2's lateral coupling", kind="sign"),
    Free("cy_sign[2]", -1.0, 1.0, False, "1", "sign of mode 3's lateral coupling", kind="sign"),
)


#: Parameters a search may name in ``free`` but does not fit by default.
EXTRA_FREE: tuple[Free, ...] = (
    Free("modal_participation", 0.2, 1.0, False, "1", "modal mass at the foot / leg mass; cantilever 0.25"),
)


def free_by_name() -> dict[str, Free]:
    """Every parameter a search may fit, by name (:data:`FREE` and :data:`EXTRA_FREE`)."""
    return {f.name: f for f in FREE + EXTRA_FREE}


def current(base: RobotParams, reference: RobotParams, f: Free) -> float:
    """The value of a free parameter in ``base`` (scales relative to ``reference``)."""
    if f.name == "squeeze_scale":
        return base.b_g_foot_n_m2_s / reference.b_g_foot_n_m2_s if reference.b_g_foot_n_m2_s else 1.0
    if f.name == "act_scale":
        return base.act_um_per_v[0] / reference.act_um_per_v[0] if reference.act_um_per_v[0] else 1.0
    if f.name.startswith("cy_sign["):
        return float(base.cy_sign[int(f.name[8])])
    return float(getattr(base, f.name))


def apply(base: RobotParams, values: dict[str, float], reference: RobotParams | None = None) -> RobotParams:
    """``base`` with the free parameters set; the scales (``squeeze_scale``, ``act_scale``)
    multiply the ``reference``'s values (default ``base``'s; the calibration and the
    sensitivity pass the published set, so the scales and their bounds mean the same
    whatever robot a search starts from)."""
    reference = base if reference is None else reference
    ch: dict[str, float | tuple[float, ...]] = {}
    signs = list(base.cy_sign)
    for name, v in values.items():
        if name == "squeeze_scale":
            ch["b_g_body_n_m2_s"] = reference.b_g_body_n_m2_s * v
            ch["b_g_foot_n_m2_s"] = reference.b_g_foot_n_m2_s * v
        elif name == "act_scale":
            ch["act_um_per_v"] = tuple(a * v for a in reference.act_um_per_v)
        elif name.startswith("cy_sign["):
            signs[int(name[8])] = 1.0 if v > 0 else -1.0
            ch["cy_sign"] = tuple(signs)
        elif name == "c_r":
            ch["c_r"] = v
            ch["c_r_body"] = v
        else:
            ch[name] = v
    return base.replace(**ch)


# --------------------------------------------------------------------------- batched evaluation

SCENARIO_NAMES = ("paper-fig8", "paper-patterns", "paper-ablations", "paper-payload")


def evaluate_many(param_sets: Sequence[RobotParams], *, seed: int = 0, scheduler: str | None = None,
                  workers: int | None = None, quiet: bool = True) -> list[dict[str, float]]:
    """The metrics of the four paper scenarios (quick size) for every parameter set, in one executor call."""
    from labkit.executor import map_tasks
    from labkit.sim.scenarios.base import RunOptions
    from labkit.sim.scenarios.paper import PAPER
    from labkit.sim.scenarios.runs import collect, make_tasks, run_task

    opts = RunOptions(size="quick", seed=seed)
    jobs: list[tuple[int, str, Plan, int, int]] = []
    tasks: list[Task] = []
    for k, p in enumerate(param_sets):
        for name in SCENARIO_NAMES:
            plan = PAPER[name].plan(p, opts, _law())
            t = make_tasks(plan.points, plan.draws, plan.duration_s, seed)
            jobs.append((k, name, plan, len(tasks), len(t)))
            tasks += t
    rows = map_tasks(run_task, tasks, scheduler=scheduler, workers=workers, desc="paper calibration", quiet=quiet)
    out: list[dict[str, float]] = [{} for _ in param_sets]
    for k, name, plan, start, n in jobs:
        ps = collect(plan.points, rows[start:start + n], plan.draws)
        out[k].update(PAPER[name].measure(ps))
    return out


def _law() -> ShakerLaw:
    return PAPER_SHAKER


#: The objective scores each observation against its band narrowed by this share of the band's
#: scale on each bounded side (:func:`labkit.sim.paper.observations.violation`), so the search
#: does not stop on a band's edge: the objective is flat inside a band, and the preset found
#: without it had the 240 Hz speed at 2.002 mm/s in the band 2-6, where any later change of the
#: numerics could flip the observation (issue 10). Met / not met never uses the margin.
OBJECTIVE_MARGIN = 0.05


def violations(metrics: dict[str, float], obs: Sequence[Observation] | None = None,
               margin: float = 0.0) -> dict[str, float]:
    """Observation id -> violation for one metrics dict (``margin``: see :data:`OBJECTIVE_MARGIN`)."""
    return {o.id: violation(o, metrics.get(o.metric), margin) for o in (obs or observations())}


def objective(metrics: dict[str, float], obs: Sequence[Observation] | None = None) -> float:
    """The search's objective for one metrics dict: :func:`cost_of` the violations with
    :data:`OBJECTIVE_MARGIN`."""
    return cost_of(violations(metrics, obs, OBJECTIVE_MARGIN))


def cost_of(viol: dict[str, float]) -> float:
    """The objective: ``sum tanh(violation)``.

    Each observation costs 0 inside its band and at most 1 outside, so the
    objective is a smoothed count of the observations not met: one far-off
    speed (a robot walking at 10 mm/s where the paper saw none is 100 band
    units off) cannot outweigh several observations met, as it would in a sum
    of squares.
    """
    return float(sum(math.tanh(v) for v in viol.values()))


# --------------------------------------------------------------------------- scores

#: What the ensemble objective asks of each observation beside the pooled verdict: this share of
#: the robots in the claim's regime meeting it (the paper's operating point: 2/3 of the drawn
#: robots inside the band).
ENSEMBLE_SHARE = 2.0 / 3.0
#: The objective's cost of an observation the pooled ensemble is not in the regime of (a
#: calibration must not reward leaving a claim's regime): as much as one missed by far.
NOT_APPLICABLE_COST = 1.0


@dataclass(frozen=True)
class CandidateScore:
    """One candidate scored: the objective ``cost`` and, per observation, its violation (0 when
    met, no margin; over an ensemble the pooled ensemble's, :data:`NOT_APPLICABLE_COST` outside
    the claim's regime), the metrics it was judged on (over an ensemble the pooled ones), and over
    an ensemble the share of robots in the regime meeting each observation and the nominal
    robot's violations."""

    cost: float
    violations: dict[str, float]
    metrics: dict[str, float]
    share_met: dict[str, float] | None = None
    nominal_violations: dict[str, float] | None = None

    def to_json(self) -> CandidateScoreJSON:
        out = CandidateScoreJSON(cost=self.cost, violations=self.violations, metrics=self.metrics)
        if self.share_met is not None:
            out["share_met"] = self.share_met
        if self.nominal_violations is not None:
            out["nominal_violations"] = self.nominal_violations
        return out


class _CandidateScoreJSON(TypedDict):
    cost: float
    violations: dict[str, float]
    metrics: dict[str, float]


class CandidateScoreJSON(_CandidateScoreJSON, total=False):
    """:class:`CandidateScore` as JSON (the calibration's side file)."""

    share_met: dict[str, float]
    nominal_violations: dict[str, float]


def nominal_score(metrics: dict[str, float], obs: Sequence[Observation]) -> CandidateScore:
    """The nominal robot's score: :func:`objective` (with the margin), violations without it."""
    return CandidateScore(cost=objective(metrics, obs), violations=violations(metrics, obs), metrics=dict(metrics))


def ensemble_score(score: EnsembleScore) -> CandidateScore:
    """The objective over an ensemble, on the verdicts of :mod:`labkit.sim.paper.ensemble`.

    Per observation: half the ``tanh`` of the pooled ensemble's violation (bands narrowed by
    :data:`OBJECTIVE_MARGIN`) plus half the share of the robots in the claim's regime that do not
    meet it beyond ``1 -`` :data:`ENSEMBLE_SHARE`, scaled to 1; :data:`NOT_APPLICABLE_COST` when
    the pooled ensemble is not in the claim's regime. 0 when the ensemble meets the observation
    and 2/3 of its robots do: a smoothed count of the observations the ensemble misses.
    """
    by_id = {o.id: o for o in observations()}
    cost = 0.0
    share: dict[str, float] = {}
    nominal: dict[str, float] = {}
    for s in score.scores:
        o = by_id[s.id]
        share[s.id] = 0.0 if s.met_share is None else float(s.met_share)
        nominal[s.id] = NOT_APPLICABLE_COST if s.nominal_state == NOT_APPLICABLE else violation(o, s.nominal)
        if s.violation is None:
            cost += NOT_APPLICABLE_COST
            continue
        miss = max(0.0, ENSEMBLE_SHARE - share[s.id]) / ENSEMBLE_SHARE
        cost += 0.5 * math.tanh(violation(o, s.ensemble, OBJECTIVE_MARGIN)) + 0.5 * miss
    metrics = {k: float(v) for m in score.pooled_metrics.values() for k, v in m.items()
               if isinstance(v, (int, float)) and not isinstance(v, bool)}
    return CandidateScore(cost=float(cost), violations=score.violations(NOT_APPLICABLE_COST), metrics=metrics,
                          share_met=share, nominal_violations=nominal)


# --------------------------------------------------------------------------- the search

#: The default :class:`~labkit.sim.calibrate.Runner`: local processes, quiet.
LOCAL = Runner()

@dataclass(frozen=True)
class SearchSettings:
    """How :func:`calibrate_paper` searches.

    ``scan``, ``rounds``, ``zoom``, ``polish``: Sobol points of the first scan; zoom rounds (each
    ``scan // 2`` points, a box ``zoom`` times narrower per round); Nelder-Mead evaluations.
    ``slack``: the near-optimal set, objective <= best + slack (the spread reported). ``seed``:
    of the simulations (common random numbers), of the drawn robots and of the Sobol samples.
    ``ensemble > 0``: score every candidate over its nominal robot and ``ensemble`` robots drawn
    from the Monte Carlo table, each run ``ensemble_duration_s`` (:func:`ensemble_score`); 0:
    the nominal robot alone at the scenarios' quick size (:func:`objective`). ``box``: (name, lo,
    hi) per free parameter searched over a box inside its physical bounds only (a bounded search
    around a start; the provenance's ``bounds_low``/``bounds_high`` are then the box).
    """

    scan: int = 32
    rounds: int = 2
    zoom: float = 3.0
    polish: int = 30
    slack: float = 0.25
    seed: int = 0
    ensemble: int = 0
    ensemble_duration_s: float = 1.0
    box: tuple[tuple[str, float, float], ...] = ()

    @property
    def search_box(self) -> dict[str, tuple[float, float]]:
        """``box`` as free parameter -> (lo, hi)."""
        return {n: (lo, hi) for n, lo, hi in self.box}


def score_candidates(sets: Sequence[RobotParams], settings: SearchSettings, runner: Runner) -> list[CandidateScore]:
    """Score parameter sets: over an ensemble (:func:`labkit.sim.paper.ensemble.score_ensemble`,
    seed ``settings.seed``: the same drawn robots for every set) or the nominal robot alone."""
    if settings.ensemble <= 0:
        mets = evaluate_many(sets, seed=settings.seed, scheduler=runner.scheduler, workers=runner.workers,
                             quiet=runner.quiet)
        obs = observations()
        return [nominal_score(m, obs) for m in mets]
    from labkit.sim.paper.ensemble import EnsembleSpec, score_ensemble

    spec = EnsembleSpec(draws=settings.ensemble, duration_s=settings.ensemble_duration_s, seeds=(settings.seed,))
    return [ensemble_score(score_ensemble(p, spec, scheduler=runner.scheduler, workers=runner.workers,
                                          quiet=runner.quiet)) for p in sets]


@dataclass(frozen=True)
class Evaluation:
    """One evaluated candidate of the search: its stage, free values, box coordinates and score."""

    stage: str
    values: dict[str, float]
    unit: tuple[float, ...]
    score: CandidateScore

    def to_json(self) -> EvaluationJSON:
        return EvaluationJSON(stage=self.stage, values=self.values, unit=list(self.unit), **self.score.to_json())


class EvaluationJSON(CandidateScoreJSON):
    """:class:`Evaluation` as JSON (one entry of the side file's ``history``)."""

    stage: str
    values: dict[str, float]
    unit: list[float]


class PaperCalibrationSummary(TypedDict):
    """:meth:`PaperCalibration.summary` (JSON: the command's output and side file)."""

    fitted: dict[str, float]
    start: dict[str, float]
    spread_near_optimal: dict[str, list[float]]
    before: CandidateScoreJSON
    after: CandidateScoreJSON
    met: list[str]
    not_met: list[str]
    never_met_together: list[list[str]]
    violation_rank_correlation: dict[str, dict[str, float]]
    met_by_share_of_samples: dict[str, float]
    evaluations: int
    settings: dict[str, float | int | str | None]
    bounds: dict[str, list[float | str]]


@dataclass(frozen=True)
class PaperCalibration:
    """The outcome of :func:`calibrate_paper`."""

    free: list[Free]
    start: dict[str, float]
    fitted: dict[str, float]
    spread: dict[str, tuple[float, float]]
    params: RobotParams
    before: CandidateScore
    after: CandidateScore
    never_together: list[tuple[str, str]]
    correlation: dict[str, dict[str, float]]
    met_by_share: dict[str, float]
    history: list[Evaluation] = field(default_factory=list)
    settings: SearchSettings = SearchSettings()
    runner: Runner = LOCAL
    wall_s: float = 0.0

    @property
    def met(self) -> list[str]:
        return [k for k, v in self.after.violations.items() if v == 0.0]

    @property
    def not_met(self) -> list[str]:
        return [k for k, v in self.after.violations.items() if v > 0.0]

    def settings_table(self) -> dict[str, float | int | str | None]:
        """The search's settings and where it ran, flat (JSON / TOML)."""
        box = ",".join(f"{n}={lo:g}:{hi:g}" for n, lo, hi in self.settings.box) or None
        return {**asdict(self.settings), "box": box,
                "size": "quick", "scheduler": self.runner.scheduler or "local",
                "workers": self.runner.workers, "wall_s": round(self.wall_s, 1),
                "free": ",".join(f.name for f in self.free)}

    def summary(self) -> PaperCalibrationSummary:
        return PaperCalibrationSummary(
            fitted=self.fitted, start=self.start, spread_near_optimal={k: list(v) for k, v in self.spread.items()},
            before=self.before.to_json(), after=self.after.to_json(), met=self.met, not_met=self.not_met,
            never_met_together=[list(p) for p in self.never_together], violation_rank_correlation=self.correlation,
            met_by_share_of_samples=self.met_by_share, evaluations=len(self.history),
            settings=self.settings_table(),
            bounds={f.name: [f.lo, f.hi, "log" if f.log else f.kind] for f in self.free})

    def method(self) -> str:
        """The objective in words (the preset's provenance)."""
        n = self.settings.ensemble
        what = (f"the ensemble cost of labkit.sim.paper.ensemble (nominal robot + {n} robots drawn from the Monte "
                f"Carlo table, {self.settings.ensemble_duration_s:g} s runs; per observation 0.5 tanh(violation of "
                f"the pooled ensemble) + 0.5 x the share of robots short of {ENSEMBLE_SHARE:.2f} meeting it, "
                f"{NOT_APPLICABLE_COST:g} when not applicable)" if n
                else "sum(tanh(observation violation)) of the nominal robot")
        return (f"Sobol scan + zoom rounds + Nelder-Mead on {what}, bands narrowed by {OBJECTIVE_MARGIN:g} of "
                "their scale in the objective, paper scenarios at their quick size, common random numbers")

    def provenance(self) -> dict[str, object]:
        """The ``[provenance]`` table of the ``paper`` preset (TOML)."""
        n = self.settings.ensemble
        out: dict[str, object] = {
            "preset": "paper",
            "summary": (f"calibrated to the paper's observations over {n + 1} robots: the nominal and {n} drawn"
                        if n else "calibrated to the paper's observations, nominal robot"),
            "source": "labkit.sim.paper.fit.calibrate_paper: the published set (Tables 1-2) with the unmeasured "
                      "parameters calibrated to the paper's observations (labkit/sim/paper/observations.toml) "
                      "on the paper's shaker law",
            "method": self.method(),
            "settings": {k: v for k, v in self.settings_table().items() if v is not None},
            "fitted": self.fitted,
            "near_optimal_low": {k: v[0] for k, v in self.spread.items()},
            "near_optimal_high": {k: v[1] for k, v in self.spread.items()},
            "bounds_low": {f.name: f.lo for f in self.free}, "bounds_high": {f.name: f.hi for f in self.free},
            "observations_met": self.met, "observations_not_met": self.not_met}
        if self.after.nominal_violations is not None:
            out["observations_met_by"] = "the pooled ensemble (labkit.sim.paper.ensemble)"
            out["observations_met_nominal"] = [k for k, v in self.after.nominal_violations.items() if v == 0]
        out.update(cost_before=self.before.cost, cost_after=self.after.cost,
                   never_met_together=[f"{a} / {b}" for a, b in self.never_together], evaluations=len(self.history))
        return out


def _free_params(free: Sequence[str] | None, box: Mapping[str, tuple[float, float]] | None = None) -> list[Free]:
    """The free parameters by name (all of :data:`FREE` for ``None``), each narrowed to its ``box``
    entry if any; InputError naming an unknown parameter or a box that is not a free one's."""
    names = [f.name for f in FREE] if free is None else list(free)
    known = free_by_name()
    for n in names:
        if n not in known:
            raise InputError(f"unknown free parameter {n!r}", key="--free", expected=", ".join(known))
    box = box or {}
    extra = sorted(set(box) - set(names))
    if extra:
        raise InputError(f"search box for {', '.join(extra)}, not a free parameter", key="--bound",
                         expected="NAME=LO:HI for a parameter of --free")
    return [narrowed(known[n], box[n]) if n in box else known[n] for n in names]


def narrowed(f: Free, lo_hi: tuple[float, float]) -> Free:
    """``f`` searched over ``lo_hi`` only: a box inside its physical bounds (a search around a start,
    not new bounds); InputError naming ``--bound`` otherwise."""
    lo, hi = float(lo_hi[0]), float(lo_hi[1])
    if f.kind == "sign" or not (f.lo <= lo < hi <= f.hi):
        raise InputError(f"search box {lo:g}:{hi:g} for {f.name} is not inside its bounds", key="--bound",
                         expected=f"{f.name}=LO:HI with {f.lo:g} <= LO < HI <= {f.hi:g} (signs: no box)")
    return replace(f, lo=lo, hi=hi)


class _Search:
    """The state of one search: the box, the scorer's settings and every evaluation so far."""

    def __init__(self, base: RobotParams, fr: list[Free], settings: SearchSettings, runner: Runner,
                 say: Callable[[str], None]) -> None:
        self.base, self.fr, self.s, self.runner, self.say = base, fr, settings, runner, say
        self.ref = RobotParams()
        self.history: list[Evaluation] = []

    def values_of(self, u: np.ndarray) -> dict[str, float]:
        return {f.name: f.from_unit(x) for f, x in zip(self.fr, u)}

    def run(self, us: Sequence[np.ndarray], stage: str) -> list[float]:
        """Score box points; returns their costs."""
        sets = [apply(self.base, self.values_of(u), self.ref) for u in us]
        scores = score_candidates(sets, self.s, self.runner)
        for u, sc in zip(us, scores):
            self.history.append(Evaluation(stage, self.values_of(u), tuple(float(x) for x in u), sc))
        return [sc.cost for sc in scores]

    @property
    def best(self) -> Evaluation:
        return min(self.history, key=lambda h: h.score.cost)

    def start_and_scan(self) -> None:
        u0 = np.array([f.to_unit(min(max(current(self.base, self.ref, f), f.lo), f.hi)) for f in self.fr])
        self.say(f"start: cost {self.run([u0], 'start')[0]:.3f}")
        cands = [np.asarray(c, float) for c in _sobol(len(self.fr), int(self.s.scan), self.s.seed)]
        self.run(cands, "scan")
        self.say(f"scan: {len(cands)} points, best cost {self.best.score.cost:.3f}")

    def zoom_rounds(self) -> None:
        half = 0.5
        signs = [i for i, f in enumerate(self.fr) if f.kind == "sign"]
        for r in range(int(self.s.rounds)):
            half /= self.s.zoom
            centre = np.array(self.best.unit)
            lo, hi = np.clip(centre - half, 0, 1), np.clip(centre + half, 0, 1)
            cands = [lo + s * (hi - lo) for s in _sobol(len(self.fr), int(self.s.scan) // 2, self.s.seed + 1 + r)]
            for c in cands:
                c[signs] = centre[signs]
            self.run(cands, f"zoom{r + 1}")
            self.say(f"zoom {r + 1}: best cost {self.best.score.cost:.3f}")

    def polish(self) -> None:
        """Nelder-Mead on the continuous parameters from the best point (signs fixed)."""
        from scipy.optimize import minimize

        cont = [i for i, f in enumerate(self.fr) if f.kind != "sign"]
        if self.s.polish <= 0 or self.best.score.cost <= 0 or not cont:
            return
        fixed = np.array(self.best.unit)

        def fun(x: np.ndarray) -> float:
            u = fixed.copy()
            u[cont] = np.clip(x, 0, 1)
            return self.run([u], "polish")[0]

        x0 = fixed[cont]
        step = 0.5 / self.s.zoom ** max(1, self.s.rounds)
        simplex = [x0] + [np.clip(x0 + np.eye(len(cont))[i] * step * (1 if x0[i] < 0.5 else -1), 0, 1)
                          for i in range(len(cont))]
        minimize(fun, x0, method="Nelder-Mead",
                 options={"maxfev": int(self.s.polish), "initial_simplex": np.array(simplex), "xatol": 1e-3,
                          "fatol": 1e-4})
        self.say(f"polish: best cost {self.best.score.cost:.3f}")

    def result(self, wall_s: float) -> PaperCalibration:
        """The outcome: the best point, the near-optimal spread, what was never met together."""
        best, first = self.best, self.history[0]
        near = [h for h in self.history if h.score.cost <= best.score.cost + self.s.slack]
        spread = {f.name: (float(min(h.values[f.name] for h in near)), float(max(h.values[f.name] for h in near)))
                  for f in self.fr}
        ids = list(first.score.violations)
        V = np.array([[h.score.violations[i] for i in ids] for h in self.history])
        met = V == 0
        never = [(a, b) for ia, a in enumerate(ids) for ib, b in enumerate(ids) if ia < ib
                 and met[:, ia].any() and met[:, ib].any() and not (met[:, ia] & met[:, ib]).any()]
        return PaperCalibration(
            free=self.fr, start=dict(first.values), fitted=dict(best.values), spread=spread,
            params=apply(self.base, best.values, self.ref), before=first.score, after=best.score,
            never_together=never, correlation=_rank_corr(V, ids),
            met_by_share={i: float(met[:, k].mean()) for k, i in enumerate(ids)}, history=self.history,
            settings=self.s, runner=self.runner, wall_s=wall_s)


def calibrate_paper(start: RobotParams | None = None, settings: SearchSettings = SearchSettings(), *,
                    free: Sequence[str] | None = None, runner: Runner = LOCAL,
                    log: Callable[[str], None] | None = None) -> PaperCalibration:
    """Search the free parameters for the set that best meets the paper's observations.

    Parameters
    ----------
    start:
        The robot to start from (default the published set): the search sets
        the free parameters of a copy of it. The scales (``squeeze_scale``,
        ``act_scale``) and their bounds are relative to the published set
        (Tables 1-2), whatever the start.
    settings:
        The search and its objective (:class:`SearchSettings`; ``ensemble > 0``: over drawn robots).
    free:
        Names of :data:`FREE` to fit (default all).
    runner:
        Where the simulations run (:class:`Runner`).
    log:
        Called with one line per stage.
    """
    t0 = time.perf_counter()
    search = _Search(RobotParams() if start is None else start, _free_params(free, settings.search_box), settings,
                     runner, log or (lambda _m: None))
    search.start_and_scan()
    search.zoom_rounds()
    search.polish()
    return search.result(time.perf_counter() - t0)


def _sobol(d: int, n: int, seed: int) -> np.ndarray:
    """``n`` scrambled Sobol points in [0, 1]^d (any n; a power of 2 keeps the balance properties)."""
    import warnings

    from scipy.stats import qmc

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return qmc.Sobol(d=d, scramble=True, seed=seed).random(max(1, n))


def _rank_corr(V: np.ndarray, ids: list[str]) -> dict[str, dict[str, float]]:
    """Spearman correlation of the violations of every pair of observations that vary over the samples."""
    from scipy.stats import spearmanr

    out: dict[str, dict[str, float]] = {}
    vary = [k for k in range(V.shape[1]) if np.ptp(V[:, k]) > 0]
    for a in vary:
        for b in vary:
            if a < b:
                rho = float(spearmanr(V[:, a], V[:, b]).statistic)
                if math.isfinite(rho):
                    out.setdefault(ids[a], {})[ids[b]] = round(rho, 3)
    return out


# --------------------------------------------------------------------------- sensitivity

class SensitivityRowJSON(TypedDict):
    """One step of :func:`sensitivity`: a parameter moved one way, the violations, and the
    observations lost and gained (a JSON record)."""

    parameter: str
    direction: str
    value: float
    cost: float
    violations: dict[str, float]
    lost: list[str]
    gained: list[str]


class SensitivityJSON(TypedDict, total=False):
    """:class:`Sensitivity` as JSON (the command's output file)."""

    base: dict[str, float]
    base_cost: float
    base_values: dict[str, float]
    factor: float
    rows: list[SensitivityRowJSON]
    params: str


@dataclass(frozen=True)
class Sensitivity:
    """The outcome of :func:`sensitivity`."""

    base: dict[str, float]
    base_cost: float
    base_values: dict[str, float]
    factor: float
    rows: list[SensitivityRowJSON]

    def to_json(self, params: str) -> SensitivityJSON:
        return SensitivityJSON(base=self.base, base_cost=self.base_cost, base_values=self.base_values,
                               factor=self.factor, rows=self.rows, params=params)


def sensitivity(params: RobotParams, reference: RobotParams | None = None, *, factor: float = 2.0,
                free: Sequence[str] | None = None, seed: int = 0, runner: Runner = LOCAL) -> Sensitivity:
    """One-at-a-time sensitivity of every observation's violation around ``params``.

    Each continuous free parameter is moved down and up by ``factor`` (log
    parameters: divided/multiplied; linear ones: the same relative step,
    clipped to the bounds); each sign is flipped. Returns the base violations
    and, per parameter and direction, the violations and which observations
    changed from met to not met or back.
    """
    ref = RobotParams() if reference is None else reference
    names = [f.name for f in FREE] if free is None else list(free)
    fr = [f for n, f in free_by_name().items() if n in names]
    base_vals = {f.name: current(params, ref, f) for f in fr}
    variants: list[tuple[str, str, float]] = []
    for f in fr:
        v = base_vals[f.name]
        if f.kind == "sign":
            variants.append((f.name, "flip", -v))
            continue
        variants.append((f.name, "down", max(f.lo, v / factor)))
        variants.append((f.name, "up", min(f.hi, v * factor)))
    sets = [params] + [apply(params, {**base_vals, n: x}, ref) for n, _, x in variants]
    mets = evaluate_many(sets, seed=seed, scheduler=runner.scheduler, workers=runner.workers, quiet=runner.quiet)
    obs = observations()
    base = violations(mets[0], obs)
    rows = []
    for (n, d, x), m in zip(variants, mets[1:]):
        viol = violations(m, obs)
        rows.append(SensitivityRowJSON(parameter=n, direction=d, value=x, cost=objective(m, obs), violations=viol,
                                       lost=[k for k in viol if base[k] == 0 and viol[k] > 0],
                                       gained=[k for k in viol if base[k] > 0 and viol[k] == 0]))
    return Sensitivity(base=base, base_cost=objective(mets[0], obs), base_values=base_vals, factor=factor, rows=rows)
