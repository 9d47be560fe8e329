"""The paper's four observation groups as scenarios, on the paper's shaker.

=====================  ===================================================================
name                   what it runs
=====================  ===================================================================
``paper-fig8``         speed vs shaker frequency at a constant 8 V drive: the tray
                       amplitude follows the 4809/2718 law (25 um at 240 Hz, ~1/f^2 above)
``paper-patterns``     foot patterns at 240 Hz for the paper's 2, 4, 6, 8 V drives
``paper-ablations``    full model, no adhesion, no squeeze film at 240 Hz, 4 V (12.5 um),
                       the drive of the paper's partial-contact case (Fig. 11 top right)
``paper-payload``      on-board PZT, 1.8 kHz square wave, 20 V, tripod; speed vs total mass
=====================  ===================================================================

Each returns the metrics named in ``labkit/sim/paper/observations.toml`` and one
pass/fail :class:`~labkit.sim.paper.observations.ObservationCheck` per
observation. A scenario is split into :func:`plan` (the simulations: robot,
drive, draws, duration) and :func:`measure` (the metrics from their results),
so the calibration (:mod:`labkit.sim.paper.fit`) can batch many robots'
simulations into one executor call and score them exactly as the scenario does.

Sizes: ``quick`` is the calibration's size (a few seconds per scenario on one
core; the paper preset's claims are checked at this size by
``tests/sim/test_paper_scenarios.py``); ``full`` has more points, Monte Carlo
draws and longer runs.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from labkit.sim.excitation import PZT, Shaker
from labkit.sim.paper.observations import check, observations
from labkit.sim.paper.shaker import PAPER_SHAKER, ShakerLaw
from labkit.sim.params import RobotParams
from labkit.sim.scenarios.base import Outcome, RunOptions, register
from labkit.sim.scenarios.metrics import at, band
from labkit.sim.scenarios.plots import Plot, curve_axes, trace_axes
from labkit.sim.scenarios.runs import Point, PointSet, run_points

PATTERN_ORDER = {"firm_contact": 0, "partial_contact": 1, "jumping": 2}

#: Shaker frequencies of paper-fig8, Hz (the paper's range: 150 Hz, below which its setup
#: resonates, to 1.8 kHz).
FIG8_FREQS_HZ = (150.0, 175.0, 200.0, 225.0, 240.0, 255.0, 270.0, 285.0, 300.0, 315.0, 330.0, 360.0, 400.0,
                 420.0, 440.0, 460.0, 480.0, 500.0, 550.0, 600.0, 700.0, 800.0, 1000.0, 1200.0, 1400.0,
                 1600.0, 1800.0)
FIG8_FREQS_QUICK_HZ = (200.0, 240.0, 270.0, 300.0, 320.0, 440.0, 480.0, 600.0, 1200.0)
#: The constant generator amplitude of the Fig. 8 sweep (25 um at 240 Hz on the law).
FIG8_DRIVE_VPP = 8.0
#: Pattern drives, V p-p (the paper's 2, 4, 6, 8 V), at this frequency (**choice**: the
#: paper does not give the frequency of Fig. 9-11; 240 Hz is its headline drive).
PATTERN_FREQ_HZ = 240.0
PATTERN_DRIVES_VPP = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0, 12.0)
PATTERN_DRIVES_QUICK_VPP = (2.0, 4.0, 6.0, 8.0)
#: Ablation drive: 240 Hz at 4 V, the paper's partial-contact case (**choice**: Fig. 12 has
#: no drive in its caption; its text is about the partial firm-contact pattern).
ABLATION_FREQ_HZ = 240.0
ABLATION_DRIVE_VPP = 4.0
ABLATIONS_RUN = (("full model", None), ("no adhesion", "no_adhesion"), ("no squeeze film", "no_squeeze_film"))
#: PZT payload drive: Fig. 13's 1.8 kHz, tripod, 20 V (**choice**: the voltage is Fig. 14's
#: "same voltage amplitude (20 V)"; Fig. 13's caption gives none).
PAYLOAD_FREQ_HZ = 1800.0
PAYLOAD_VOLTAGE_V = 20.0
PAYLOAD_MASSES_MG = (0.33, 0.6, 0.9, 1.2, 1.4, 1.6, 1.7, 1.8, 2.0, 2.2, 2.5)
PAYLOAD_MASSES_QUICK_MG = (0.33, 1.0, 1.2, 1.6, 1.7, 2.0, 2.5)


@dataclass(frozen=True)
class Plan:
    """The simulations of one paper scenario at one size."""

    points: list[Point]
    draws: int
    duration_s: float


@dataclass(frozen=True)
class PaperScenario:
    """How to plan and measure one paper scenario."""

    name: str
    plan: Callable[[RobotParams, RunOptions, ShakerLaw], Plan]
    measure: Callable[[PointSet], dict[str, float]]


def unsigned_speed(ps: PointSet) -> np.ndarray:
    """Mean over draws of |speed| at every point: the paper compares speeds, not velocities (a
    tracked robot has no sign), and Monte Carlo robots may walk either way."""
    return np.abs(ps.speeds_mm_s).mean(axis=1)


def _ratio(a: float, b: float, floor: float = 0.0) -> float:
    """``a / b``; NaN (a failed test) when ``b`` is not above ``floor``."""
    return a / b if b > floor and np.isfinite(a) else float("nan")


#: Below this |speed| a ratio of speeds is noise, not a trend (mm/s).
SPEED_FLOOR_MM_S = 0.05


# --------------------------------------------------------------------------- fig. 8

def fig8_plan(params: RobotParams, opts: RunOptions, law: ShakerLaw = PAPER_SHAKER) -> Plan:
    freqs = opts.pick(FIG8_FREQS_HZ, FIG8_FREQS_QUICK_HZ)
    pts = [Point(params, Shaker(freq_hz=f, amp_um=law.amp_um(f, FIG8_DRIVE_VPP)), f) for f in freqs]
    return Plan(pts, opts.pick(5, 1, opts.draws), opts.pick(1.5, 0.4, opts.duration_s))


def fig8_measure(ps: PointSet) -> dict[str, float]:
    f, v = ps.values, unsigned_speed(ps)
    return {"speed_240_hz_mm_s": at(f, v, 240.0),
            "speed_ratio_270_to_200": _ratio(at(f, v, 270.0), at(f, v, 200.0), SPEED_FLOOR_MM_S),
            "speed_rise_near_300_hz_mm_s": band(f, v, 285.0, 330.0) - at(f, v, 270.0),
            "max_speed_500_1800_hz_mm_s": band(f, v, 500.0, 1800.0),
            "max_speed_420_500_hz_mm_s": band(f, v, 420.0, 500.0)}


# --------------------------------------------------------------------------- fig. 9-11

def patterns_plan(params: RobotParams, opts: RunOptions, law: ShakerLaw = PAPER_SHAKER) -> Plan:
    volts = opts.pick(PATTERN_DRIVES_VPP, PATTERN_DRIVES_QUICK_VPP)
    pts = [Point(params, Shaker(freq_hz=PATTERN_FREQ_HZ, amp_um=law.amp_um(PATTERN_FREQ_HZ, v)), v) for v in volts]
    return Plan(pts, opts.pick(3, 1, opts.draws), opts.pick(1.0, 0.4, opts.duration_s))


def patterns_measure(ps: PointSet) -> dict[str, float]:
    idx = {float(v): i for i, v in enumerate(ps.values)}

    def share(v: float, p: str) -> float:
        return ps.share(idx[v], p) if v in idx else float("nan")

    inside = [i for i, v in enumerate(ps.values) if 2.0 <= v <= 8.0]
    ranks = [PATTERN_ORDER[ps.dominant_pattern(i)] for i in inside]
    return {"firm_share_2v": share(2.0, "firm_contact"),
            "partial_share_4_6v": float(np.nanmax([share(4.0, "partial_contact"), share(6.0, "partial_contact")])),
            "jumping_share_8v": share(8.0, "jumping"),
            "pattern_order_violations": float(sum(b < a for a, b in zip(ranks, ranks[1:]))),
            "jump_height_8v_um": float(np.mean(ps.foot_rise_um[idx[8.0]])) if 8.0 in idx else float("nan")}


# --------------------------------------------------------------------------- fig. 12

def ablations_plan(params: RobotParams, opts: RunOptions, law: ShakerLaw = PAPER_SHAKER) -> Plan:
    drive = Shaker(freq_hz=ABLATION_FREQ_HZ, amp_um=law.amp_um(ABLATION_FREQ_HZ, ABLATION_DRIVE_VPP))
    pts = [Point(params, drive, float(k), ablation) for k, (_, ablation) in enumerate(ABLATIONS_RUN)]
    return Plan(pts, opts.pick(3, 1, opts.draws), opts.pick(1.0, 0.5, opts.duration_s))


def ablations_measure(ps: PointSet) -> dict[str, float]:
    ap = np.nanmean(ps.aperiodicity, axis=1)
    lm = ps.leg_motion_um.mean(axis=1)
    v = unsigned_speed(ps)
    return {"aperiodicity_full": float(ap[0]), "aperiodicity_gain_no_adhesion": float(ap[1] - ap[0]),
            "leg_motion_ratio_no_squeeze": _ratio(float(lm[2]), float(lm[0])),
            "speed_gain_no_squeeze_mm_s": float(v[2] - v[0])}


# --------------------------------------------------------------------------- fig. 13

def payload_plan(params: RobotParams, opts: RunOptions, law: ShakerLaw = PAPER_SHAKER) -> Plan:
    masses = opts.pick(PAYLOAD_MASSES_MG, PAYLOAD_MASSES_QUICK_MG)
    pts = [Point(params, PZT(freq_hz=PAYLOAD_FREQ_HZ, voltage_v=PAYLOAD_VOLTAGE_V, mass_mg=m), m) for m in masses]
    return Plan(pts, opts.pick(5, 1, opts.draws), opts.pick(1.0, 0.4, opts.duration_s))


def payload_measure(ps: PointSet) -> dict[str, float]:
    m, v = ps.values, unsigned_speed(ps)
    low, high = v[m <= 1.6 + 1e-9], v[m >= 2.0 - 1e-9]
    return {"min_speed_to_1_6_mg_mm_s": float(low.min()) if low.size else float("nan"),
            "max_speed_from_2_0_mg_mm_s": float(high.max()) if high.size else float("nan"),
            "speed_gain_1_2_to_1_7_mg_mm_s": at(m, v, 1.7) - at(m, v, 1.2)}


#: The coordinate of each paper scenario's points.
AXIS = {"paper-fig8": "freq_hz", "paper-patterns": "drive_vpp", "paper-ablations": "run",
        "paper-payload": "mass_mg"}

PAPER: dict[str, PaperScenario] = {
    "paper-fig8": PaperScenario("paper-fig8", fig8_plan, fig8_measure),
    "paper-patterns": PaperScenario("paper-patterns", patterns_plan, patterns_measure),
    "paper-ablations": PaperScenario("paper-ablations", ablations_plan, ablations_measure),
    "paper-payload": PaperScenario("paper-payload", payload_plan, payload_measure),
}


def tray_law(opts: RunOptions) -> ShakerLaw:
    """The scenario's tray amplitude law: the options' (a table from a file) or the paper's shaker."""
    return PAPER_SHAKER if opts.tray_law is None else opts.tray_law


def evaluate(name: str, params: RobotParams, opts: RunOptions,
             law: ShakerLaw | None = None) -> tuple[PointSet, dict[str, float]]:
    """Run one paper scenario's simulations and measure them (``law``: default :func:`tray_law`)."""
    sc = PAPER[name]
    plan = sc.plan(params, opts, tray_law(opts) if law is None else law)
    ps = run_points(plan.points, draws=plan.draws, duration_s=plan.duration_s, seed=opts.seed,
                    scheduler=opts.scheduler, workers=opts.workers, quiet=opts.quiet, desc=name, quantity=AXIS[name])
    return ps, sc.measure(ps)


def _outcome(name: str, ps: PointSet, metrics: dict[str, float], axis: str, plot: Plot,
             extra: dict[str, Any] | None = None, size_in: tuple[float, float] = (7.0, 4.6)) -> Outcome:
    checks = check(name, metrics)
    met = sum(c.passed for c in checks)
    finding = (f"{met}/{len(checks)} paper observations met"
               + (f"; not met: {', '.join(c.id for c in checks if not c.passed)}" if met < len(checks) else ""))
    numbers = {"metrics": metrics, "points": ps.points(axis), "draws": ps.draws,
               "duration_s": ps.meta.get("duration_s"), **(extra or {})}
    return Outcome(finding=finding, checks={c.id: c.passed for c in checks}, numbers=numbers,
                   observations=checks, plot=plot, write_data=ps.to_h5,
                   figure_size_in=size_in)


def _band_text(ax: Any, checks: Sequence[Any], y: float = 0.99) -> None:
    """``PASS id`` / ``FAIL id`` lines in a corner of an axis."""
    lines = [f"{'PASS' if c.passed else 'FAIL'} {c.id}" for c in checks]
    ax.text(0.01, y, "\n".join(lines), transform=ax.transAxes, va="top", ha="left", fontsize=6,
            family="monospace", color="0.2", bbox={"facecolor": "white", "alpha": 0.8, "lw": 0})


# --------------------------------------------------------------------------- registered scenarios

@register("paper-fig8", "speed vs shaker frequency at a constant drive on the paper's shaker (paper Fig. 8)",
          "about 4 mm/s at 240 Hz / 25 um; falling from 200 Hz, a rise near 300 Hz; none from 500 Hz to 1.8 kHz")
def paper_fig8(params: RobotParams, opts: RunOptions) -> Outcome:
    ps, metrics = evaluate("paper-fig8", params, opts)
    amps = [d["amp_um"] for d in ps.drives]

    def plot(fig: Any) -> None:
        import matplotlib.ticker

        ax = fig.add_subplot(111)
        curve_axes(ax, ps, "simulated")
        ax.errorbar([240.0], [4.0], yerr=[[2.0], [2.0]], fmt="s", color="tab:red", ms=5, capsize=3,
                    label="paper: about 4 mm/s at 240 Hz (band 2-6)")
        ax.axvspan(500, 1800, color="tab:red", alpha=0.06, label="paper: no motion 500 Hz-1.8 kHz")
        ax.axvspan(420, 500, color="tab:orange", alpha=0.06, label="paper (experiment): none above 400 Hz")
        ax.axhline(0, color="0.5", lw=0.5)
        ax.set_xscale("log")
        ax.set_xlabel("shaker frequency (Hz)")
        ax.set_ylabel("mean forward speed (mm/s)")
        ax2 = ax.twinx()
        ax2.plot(ps.values, amps, ":", color="tab:blue", lw=1.0)
        ax2.set_yscale("log")
        ax2.set_ylabel(f"tray amplitude at {FIG8_DRIVE_VPP:g} V (um, dotted)", color="tab:blue", fontsize=8)
        ax2.tick_params(labelsize=7, colors="tab:blue")
        ax.set_title(f"paper-fig8: {sum(c.passed for c in check('paper-fig8', metrics))}/"
                     f"{len(observations('paper-fig8'))} observations met (cf. paper Fig. 8)", fontsize=9)
        ax.legend(fontsize=6, loc="upper right")
        _band_text(ax, check("paper-fig8", metrics))
        ax.set_xticks([150, 200, 300, 500, 1000, 1800], labels=["150", "200", "300", "500", "1000", "1800"])
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        fig.tight_layout()

    return _outcome("paper-fig8", ps, metrics, "freq_hz", plot,
                    {"drive_vpp": FIG8_DRIVE_VPP, "tray_law": tray_law(opts).describe()})


def _trace_runs(params: RobotParams, drives: Sequence[tuple[str, Shaker, str | None]], duration_s: float,
                seed: int) -> list[tuple[str, Any]]:
    from labkit.sim.core import simulate

    return [(label, simulate(params, d, duration_s=duration_s, seed=seed, ablation=ab)) for label, d, ab in drives]


@register("paper-patterns", "foot patterns for the paper's 2-8 V shaker drives at 240 Hz (paper Fig. 9-11)",
          "firm contact at 2 V, partial contact at 4-6 V, jumping at 8 V with feet ~200 um above a 25 um tray")
def paper_patterns(params: RobotParams, opts: RunOptions) -> Outcome:
    ps, metrics = evaluate("paper-patterns", params, opts)
    plan = patterns_plan(params, opts)

    def plot(fig: Any) -> None:
        drives = [(f"{v:g} V ({tray_law(opts).amp_um(PATTERN_FREQ_HZ, v):.3g} um)",
                   Shaker(freq_hz=PATTERN_FREQ_HZ, amp_um=tray_law(opts).amp_um(PATTERN_FREQ_HZ, v)), None)
                  for v in PATTERN_DRIVES_QUICK_VPP]
        runs = _trace_runs(params, drives, plan.duration_s, opts.seed)
        for i, (label, r) in enumerate(runs):
            ax = fig.add_subplot(2, 2, i + 1)
            trace_axes(ax, label, r, PATTERN_FREQ_HZ, legend=i == 0)
            ax.set_xlabel("t (ms)", fontsize=7)
        fig.suptitle(f"paper-patterns (cf. paper Fig. 11): {metrics_line(metrics, 'paper-patterns')}", fontsize=8)
        fig.tight_layout()

    dom = [ps.dominant_pattern(i) for i in range(len(ps.values))]
    return _outcome("paper-patterns", ps, metrics, "drive_vpp", plot,
                    {"freq_hz": PATTERN_FREQ_HZ, "dominant_pattern": dict(zip((f"{v:g}" for v in ps.values), dom)),
                     "tray_law": tray_law(opts).describe()},
                    size_in=(7.0, 5.2))


@register("paper-ablations", "full model vs no adhesion vs no squeeze film at 240 Hz, 4 V (paper Fig. 12)",
          "without adhesion the partial-contact motion is no longer periodic; without the squeeze film the "
          "legs move more and the robot is faster")
def paper_ablations(params: RobotParams, opts: RunOptions) -> Outcome:
    ps, metrics = evaluate("paper-ablations", params, opts)
    plan = ablations_plan(params, opts, tray_law(opts))
    drive = plan.points[0].drive

    def plot(fig: Any) -> None:
        assert isinstance(drive, Shaker)
        order = [("no squeeze film", drive, "no_squeeze_film"), ("no adhesion", drive, "no_adhesion"),
                 ("full model", drive, None)]
        runs = _trace_runs(params, order, plan.duration_s, opts.seed)
        for i, (label, r) in enumerate(runs):
            ax = fig.add_subplot(1, 3, i + 1)
            trace_axes(ax, label, r, ABLATION_FREQ_HZ, legend=i == 0)
            ax.set_xlabel("t (ms)", fontsize=7)
        fig.suptitle(f"paper-ablations (cf. paper Fig. 12), {ABLATION_FREQ_HZ:g} Hz, {drive.amp_um:.3g} um: "
                     f"{metrics_line(metrics, 'paper-ablations')}", fontsize=8)
        fig.tight_layout()

    runs = {label: {"mean_speed_mm_s": float(ps.mean_speed_mm_s[k]),
                    "aperiodicity": float(np.nanmean(ps.aperiodicity[k])),
                    "leg_motion_um": float(ps.leg_motion_um[k].mean()), "dominant_pattern": ps.dominant_pattern(k)}
            for k, (label, _) in enumerate(ABLATIONS_RUN)}
    return _outcome("paper-ablations", ps, metrics, "run", plot,
                    {"freq_hz": ABLATION_FREQ_HZ, "amp_um": drive.amp_um if isinstance(drive, Shaker) else None,
                     "runs": runs, "tray_law": tray_law(opts).describe()}, size_in=(9.0, 3.4))


@register("paper-payload", "speed vs total mass, on-board PZT 1.8 kHz tripod at 20 V (paper Fig. 13)",
          "more than 1 mm/s up to about 1.7 mg total mass, no motion above; speed rising from 1.2 to 1.7 mg")
def paper_payload(params: RobotParams, opts: RunOptions) -> Outcome:
    ps, metrics = evaluate("paper-payload", params, opts)

    def plot(fig: Any) -> None:
        ax = fig.add_subplot(111)
        curve_axes(ax, ps, "simulated")
        ax.axhline(1.0, color="tab:red", lw=0.8, ls="--", label="paper: > 1 mm/s up to about 1.7 mg")
        ax.axvspan(1.7, max(2.5, float(ps.values.max())), color="tab:red", alpha=0.06,
                   label="paper: stops above 1.7 mg")
        ax.axhline(0, color="0.5", lw=0.5)
        ax.set_xlabel("total robot mass (mg)")
        ax.set_ylabel("mean forward speed (mm/s)")
        ax.set_title(f"paper-payload, PZT {PAYLOAD_FREQ_HZ:g} Hz tripod {PAYLOAD_VOLTAGE_V:g} V (cf. paper Fig. 13): "
                     f"{metrics_line(metrics, 'paper-payload')}", fontsize=8)
        ax.legend(fontsize=6, loc="upper right")
        _band_text(ax, check("paper-payload", metrics), y=0.8)
        fig.tight_layout()

    return _outcome("paper-payload", ps, metrics, "mass_mg", plot,
                    {"freq_hz": PAYLOAD_FREQ_HZ, "voltage_v": PAYLOAD_VOLTAGE_V})


def metrics_line(metrics: dict[str, float], name: str) -> str:
    """``"n/m met"`` for a figure title."""
    checks = check(name, metrics)
    return f"{sum(c.passed for c in checks)}/{len(checks)} observations met"
