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
from labkit.sim.paper.observations import MET, NOT_APPLICABLE, NOT_MET, check, observations, tally
from labkit.sim.paper.shaker import PAPER_SHAKER, ShakerLaw
from labkit.sim.params import RobotParams
from labkit.sim.scenarios.base import Outcome, RunOptions, register
from labkit.sim.scenarios.metrics import at, band, slope
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
#: Ablations at 240 Hz, at the drive where the full model is in partial contact (Fig. 12 has no
#: drive in its caption; its text is about the partial firm-contact pattern): every variant runs
#: at each of these drives and :func:`ablation_drive` picks the full model's largest
#: partial-contact share (the paper's partial drives, 4 and 6 V, at the quick size).
ABLATION_FREQ_HZ = 240.0
ABLATION_DRIVES_VPP = (3.0, 4.0, 5.0, 6.0, 7.0)
ABLATION_DRIVES_QUICK_VPP = (4.0, 6.0)
ABLATIONS_RUN = (("full model", None), ("no adhesion", "no_adhesion"), ("no squeeze film", "no_squeeze_film"))
#: Sec. 5.3, adhesion "at small locomotion amplitudes ... can prevent effective movement, and at
#: larger ... can be beneficial": full model and no adhesion at the paper's smallest and largest
#: drives (2 V firm contact, 8 V jumping).
ADHESION_DRIVES_VPP = (2.0, 8.0)
#: PZT payload drive: Fig. 13's 1.8 kHz, tripod, 20 V (**choice**: the voltage is Fig. 14's
#: "same voltage amplitude (20 V)"; Fig. 13's caption gives none).
PAYLOAD_FREQ_HZ = 1800.0
PAYLOAD_VOLTAGE_V = 20.0
PAYLOAD_MASSES_MG = (0.33, 0.6, 0.9, 1.2, 1.4, 1.6, 1.7, 1.8, 2.0, 2.2, 2.5)
PAYLOAD_MASSES_QUICK_MG = (0.33, 1.0, 1.2, 1.6, 1.7, 2.0, 2.5)
#: Fig. 14: PZT tripod at 20 V around the first lateral resonance (438 Hz), the robot's own mass.
FIG14_FREQS_HZ = (360.0, 380.0, 400.0, 420.0, 438.0, 460.0, 480.0, 500.0, 520.0)
FIG14_FREQS_QUICK_HZ = (400.0, 420.0, 438.0, 460.0, 480.0)
#: Fig. 6 (right): a stepped-sine out-of-chip run, "under small amplitude ground excitation": the
#: shaker law at 1 V p-p (3.1 um at 240 Hz, under 1 g from 150 Hz up: the feet stay on the tray).
SPECTRUM_DRIVE_VPP = 1.0
SPECTRUM_FREQS_HZ = (150.0, 200.0, 225.0, 250.0, 300.0, 350.0, 380.0, 400.0, 420.0, 438.0, 460.0, 480.0, 520.0,
                     560.0, 600.0, 700.0, 800.0, 900.0, 1000.0, 1100.0, 1150.0, 1200.0, 1250.0, 1300.0, 1400.0,
                     1500.0, 1600.0, 1700.0, 1800.0, 1900.0, 2000.0, 2200.0)
SPECTRUM_FREQS_QUICK_HZ = (150.0, 225.0, 300.0, 350.0, 400.0, 438.0, 480.0, 530.0, 600.0, 700.0, 800.0, 1000.0,
                           1100.0, 1200.0, 1300.0, 1500.0, 1650.0, 1800.0, 1950.0, 2200.0)
#: A linear response settles in a few of the legs' decay times (~7 ms at 438 Hz, zeta 0.05).
SPECTRUM_MAX_DURATION_S = 0.3
#: A resonance of the spectrum stands this share above the median of its window (**choice**: the
#: paper's peaks in Fig. 6 stand out by several times; 20 % is far above the lock-in's round-off).
PEAK_PROMINENCE = 0.2


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
            "speed_slope_200_300_hz_mm_s_per_100_hz": slope(f, v, 200.0, 300.0) * 100.0,
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
    nan = float("nan")

    def share(v: float, p: str) -> float:
        return ps.share(idx[v], p) if v in idx else nan

    def extra(v: float, key: str, stat: Callable[[np.ndarray], float] = np.nanmean) -> float:
        vals = ps.extra.get(key)
        return float(stat(vals[idx[v]])) if v in idx and vals is not None and np.isfinite(vals[idx[v]]).any() else nan

    inside = [i for i, v in enumerate(ps.values) if 2.0 <= v <= 8.0]
    ranks = [PATTERN_ORDER[ps.dominant_pattern(i)] for i in inside]
    releases = extra(4.0, "releases", np.nansum)
    return {"firm_share_2v": share(2.0, "firm_contact"),
            "partial_share_min_4_6v": min(share(4.0, "partial_contact"), share(6.0, "partial_contact")),
            "jumping_share_8v": share(8.0, "jumping"),
            "pattern_order_violations": float(sum(b < a for a, b in zip(ranks, ranks[1:]))),
            "knee_amplitude_8v_um": extra(8.0, "knee_amp_um"),
            "foot_rise_8v_um": float(np.mean(ps.foot_rise_um[idx[8.0]])) if 8.0 in idx else nan,
            "speed_4v_mm_s": float(unsigned_speed(ps)[idx[4.0]]) if 4.0 in idx else nan,
            # 8 V is Fig. 8's 240 Hz, 25 um run (the same robots and starts): its speed, for a search
            # that runs this scenario alone (bench/paper_table.py --scenarios paper-patterns --members)
            "speed_8v_mm_s": float(unsigned_speed(ps)[idx[8.0]]) if 8.0 in idx else nan,
            "releases_4v": releases, "released_4v": float(releases > 0),
            "release_jump_4v": extra(4.0, "release_jump", np.nanmedian)}


# --------------------------------------------------------------------------- fig. 12

def ablation_x(variant: int, drive_vpp: float) -> float:
    """The coordinate of an ablation point: ``100 * variant + drive`` (variant: index in :data:`ABLATIONS_RUN`)."""
    return 100.0 * variant + float(drive_vpp)


def ablations_plan(params: RobotParams, opts: RunOptions, law: ShakerLaw = PAPER_SHAKER) -> Plan:
    pts = []
    for v in opts.pick(ABLATION_DRIVES_VPP, ABLATION_DRIVES_QUICK_VPP):
        drive = Shaker(freq_hz=ABLATION_FREQ_HZ, amp_um=law.amp_um(ABLATION_FREQ_HZ, v))
        pts += [Point(params, drive, ablation_x(k, v), ablation) for k, (_, ablation) in enumerate(ABLATIONS_RUN)]
    for v in ADHESION_DRIVES_VPP:
        drive = Shaker(freq_hz=ABLATION_FREQ_HZ, amp_um=law.amp_um(ABLATION_FREQ_HZ, v))
        pts += [Point(params, drive, ablation_x(k, v), ablation) for k, (_, ablation) in enumerate(ABLATIONS_RUN[:2])]
    return Plan(pts, opts.pick(3, 1, opts.draws), opts.pick(1.0, 0.5, opts.duration_s))


def ablation_drive(ps: PointSet) -> tuple[float, float]:
    """The drive (V p-p) of the full model's largest partial-contact share among the drives run with
    all three variants (the lowest on a tie), and that share."""
    x = ps.values
    full = {float(x[i]): i for i in range(len(x)) if x[i] < 100.0}
    cands = sorted(v for v in full if ablation_x(1, v) in x and ablation_x(2, v) in x)
    if not cands:
        return float("nan"), float("nan")
    shares = [ps.share(full[v], "partial_contact") for v in cands]
    k = int(np.argmax(shares))
    return cands[k], float(shares[k])


def ablations_measure(ps: PointSet) -> dict[str, float]:
    idx = {float(x): i for i, x in enumerate(ps.values)}
    ap = np.nanmean(ps.aperiodicity, axis=1)
    lm = ps.leg_motion_um.mean(axis=1)
    v = unsigned_speed(ps)
    nan = float("nan")

    def get(arr: np.ndarray, variant: int, drive: float) -> float:
        i = idx.get(ablation_x(variant, drive))
        return float(arr[i]) if i is not None else nan

    d, share = ablation_drive(ps)
    moving = get(v, 0, d) >= SPEED_FLOOR_MM_S
    partial = share > 0.5
    small, large = ADHESION_DRIVES_VPP
    return {"ablation_drive_vpp": d, "full_partial_share": share, "full_in_partial_contact": float(partial),
            "full_partial_and_moving": float(partial and moving),
            "aperiodicity_full": get(ap, 0, d), "aperiodicity_gain_no_adhesion": get(ap, 1, d) - get(ap, 0, d),
            "leg_motion_ratio_no_squeeze": _ratio(get(lm, 2, d), get(lm, 0, d)),
            "speed_gain_no_squeeze_mm_s": get(v, 2, d) - get(v, 0, d),
            "speed_gain_no_adhesion_small_mm_s": get(v, 1, small) - get(v, 0, small),
            "no_adhesion_moves_small": float(get(v, 1, small) >= SPEED_FLOOR_MM_S),
            "speed_gain_adhesion_large_mm_s": get(v, 0, large) - get(v, 1, large),
            "moves_large": float(max(get(v, 0, large), get(v, 1, large)) >= SPEED_FLOOR_MM_S)}


# --------------------------------------------------------------------------- fig. 13

def payload_plan(params: RobotParams, opts: RunOptions, law: ShakerLaw = PAPER_SHAKER) -> Plan:
    masses = opts.pick(PAYLOAD_MASSES_MG, PAYLOAD_MASSES_QUICK_MG)
    pts = [Point(params, PZT(freq_hz=PAYLOAD_FREQ_HZ, voltage_v=PAYLOAD_VOLTAGE_V, mass_mg=m), m) for m in masses]
    return Plan(pts, opts.pick(5, 1, opts.draws), opts.pick(1.0, 0.4, opts.duration_s))


def payload_measure(ps: PointSet) -> dict[str, float]:
    m, v = ps.values, unsigned_speed(ps)
    low, high = v[m <= 1.6 + 1e-9], v[m >= 2.0 - 1e-9]
    sd = np.abs(ps.speeds_mm_s).std(axis=1, ddof=1) if ps.draws > 1 else np.full(len(m), np.nan)
    near, rest = sd[(m >= 1.6 - 1e-9) & (m <= 1.8 + 1e-9)], sd[m <= 1.4 + 1e-9]
    return {"min_speed_to_1_6_mg_mm_s": float(low.min()) if low.size else float("nan"),
            "max_speed_from_2_0_mg_mm_s": float(high.max()) if high.size else float("nan"),
            "speed_gain_1_2_to_1_7_mg_mm_s": at(m, v, 1.7) - at(m, v, 1.2),
            "payload_rise_onset_mg": rise_onset(m, v, 1.7),
            "speed_sd_ratio_near_1_7_mg": _ratio(float(np.max(near)) if near.size else float("nan"),
                                                 float(np.max(rest)) if rest.size else float("nan")),
            "payload_ensemble": float(ps.draws > 1)}


def rise_onset(masses: np.ndarray, speeds: np.ndarray, upto: float) -> float:
    """Where the speed's rise towards ``upto`` begins: the largest mass (<= ``upto``) whose speed is
    within :data:`SPEED_FLOOR_MM_S` of the curve's minimum there (NaN for no points)."""
    m, v = np.asarray(masses, float), np.asarray(speeds, float)
    keep = m <= upto + 1e-9
    if not keep.any():
        return float("nan")
    m, v = m[keep], v[keep]
    return float(m[v <= v.min() + SPEED_FLOOR_MM_S].max())


# --------------------------------------------------------------------------- fig. 14

def fig14_plan(params: RobotParams, opts: RunOptions, law: ShakerLaw = PAPER_SHAKER) -> Plan:
    freqs = opts.pick(FIG14_FREQS_HZ, FIG14_FREQS_QUICK_HZ)
    pts = [Point(params, PZT(freq_hz=f, voltage_v=PAYLOAD_VOLTAGE_V), f) for f in freqs]
    return Plan(pts, opts.pick(5, 1, opts.draws), opts.pick(1.0, 0.4, opts.duration_s))


def fig14_measure(ps: PointSet) -> dict[str, float]:
    f, v = ps.values, unsigned_speed(ps)
    return {"max_speed_400_480_hz_mm_s": band(f, v, 400.0, 480.0),
            "speed_438_hz_mm_s": at(f, v, 438.0)}


# --------------------------------------------------------------------------- fig. 6 (right)

def spectrum_plan(params: RobotParams, opts: RunOptions, law: ShakerLaw = PAPER_SHAKER) -> Plan:
    freqs = opts.pick(SPECTRUM_FREQS_HZ, SPECTRUM_FREQS_QUICK_HZ)
    pts = [Point(params, Shaker(freq_hz=f, amp_um=law.amp_um(f, SPECTRUM_DRIVE_VPP)), f) for f in freqs]
    dur = min(opts.pick(0.3, 0.15, opts.duration_s), SPECTRUM_MAX_DURATION_S)
    return Plan(pts, opts.pick(3, 1, opts.draws), dur)


def spectrum_measure(ps: PointSet) -> dict[str, float]:
    f = ps.values
    knee = np.nanmean(ps.extra["knee_gain"], axis=1) if "knee_gain" in ps.extra else np.full(len(f), np.nan)
    body = np.nanmean(ps.extra["body_gain"], axis=1) if "body_gain" in ps.extra else np.full(len(f), np.nan)
    return {"knee_peak_hz_350_600": peak_at(f, knee, 350.0, 600.0),
            "knee_peak_hz_1000_1500": peak_at(f, knee, 1000.0, 1500.0),
            "knee_peak_hz_1500_2200": peak_at(f, knee, 1500.0, 2200.0),
            "body_peak_hz_150_1500": peak_at(f, body, 150.0, 1500.0)}


def peak_at(freqs: np.ndarray, gain: np.ndarray, lo: float, hi: float,
            prominence: float = PEAK_PROMINENCE) -> float:
    """Frequency of the largest ``gain`` over ``lo <= f <= hi``; NaN when none is finite or when the
    largest does not stand ``prominence`` (a share) above the window's median: a flat response has
    no resonance, whichever point is highest by round-off."""
    f, g = np.asarray(freqs, float), np.asarray(gain, float)
    m = (f >= lo) & (f <= hi) & np.isfinite(g)
    if not m.any():
        return float("nan")
    k = int(np.argmax(g[m]))
    return float(f[m][k]) if g[m][k] >= (1.0 + prominence) * float(np.median(g[m])) else float("nan")


#: The coordinate of each paper scenario's points.
AXIS = {"paper-fig8": "freq_hz", "paper-patterns": "drive_vpp", "paper-ablations": "run",
        "paper-payload": "mass_mg", "paper-fig14": "freq_hz", "paper-spectrum": "freq_hz"}

PAPER: dict[str, PaperScenario] = {
    "paper-fig8": PaperScenario("paper-fig8", fig8_plan, fig8_measure),
    "paper-patterns": PaperScenario("paper-patterns", patterns_plan, patterns_measure),
    "paper-ablations": PaperScenario("paper-ablations", ablations_plan, ablations_measure),
    "paper-payload": PaperScenario("paper-payload", payload_plan, payload_measure),
    "paper-fig14": PaperScenario("paper-fig14", fig14_plan, fig14_measure),
    "paper-spectrum": PaperScenario("paper-spectrum", spectrum_plan, spectrum_measure),
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
             extra: dict[str, object] | None = None, size_in: tuple[float, float] = (7.0, 4.6)) -> Outcome:
    checks = check(name, metrics)
    n = tally(checks)
    finding = (f"{n[MET]}/{len(checks)} paper observations met"
               + (f", {n[NOT_APPLICABLE]} not applicable (not in the claim's regime: "
                  f"{', '.join(c.id for c in checks if not c.applicable)})" if n[NOT_APPLICABLE] else "")
               + (f"; not met: {', '.join(c.id for c in checks if c.state == NOT_MET)}" if n[NOT_MET] else ""))
    numbers: dict[str, object] = {"metrics": metrics, "points": ps.points(axis), "draws": ps.draws,
               "duration_s": ps.meta.get("duration_s"), **(extra or {})}
    return Outcome(finding=finding, checks={c.id: c.passed for c in checks}, numbers=numbers,
                   observations=checks, plot=plot, write_data=ps.to_h5,
                   figure_size_in=size_in)


def _band_text(ax: Any, checks: Sequence[Any], y: float = 0.99) -> None:
    """``PASS id`` / ``FAIL id`` lines in a corner of an axis."""
    lines = [f"{c.line().split()[0]} {c.id}" for c in checks]
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


@register("paper-ablations", "full model vs no adhesion vs no squeeze film at 240 Hz where the full model is "
          "in partial contact; adhesion at 2 and 8 V (paper Fig. 12, Sec. 5.3)",
          "without adhesion the partial-contact motion is no longer periodic; without the squeeze film the "
          "legs move more and the robot is faster; adhesion blocks motion at 2 V and helps at 8 V")
def paper_ablations(params: RobotParams, opts: RunOptions) -> Outcome:
    ps, metrics = evaluate("paper-ablations", params, opts)
    plan = ablations_plan(params, opts, tray_law(opts))
    volts = metrics["ablation_drive_vpp"]
    volts = volts if np.isfinite(volts) else opts.pick(ABLATION_DRIVES_VPP, ABLATION_DRIVES_QUICK_VPP)[0]
    drive = Shaker(freq_hz=ABLATION_FREQ_HZ, amp_um=tray_law(opts).amp_um(ABLATION_FREQ_HZ, volts))

    def plot(fig: Any) -> None:
        order = [("no squeeze film", drive, "no_squeeze_film"), ("no adhesion", drive, "no_adhesion"),
                 ("full model", drive, None)]
        runs = _trace_runs(params, order, plan.duration_s, opts.seed)
        for i, (label, r) in enumerate(runs):
            ax = fig.add_subplot(1, 3, i + 1)
            trace_axes(ax, label, r, ABLATION_FREQ_HZ, legend=i == 0)
            ax.set_xlabel("t (ms)", fontsize=7)
        fig.suptitle(f"paper-ablations (cf. paper Fig. 12), {ABLATION_FREQ_HZ:g} Hz, {volts:g} V, "
                     f"{drive.amp_um:.3g} um: {metrics_line(metrics, 'paper-ablations')}", fontsize=8)
        fig.tight_layout()

    idx = {float(x): i for i, x in enumerate(ps.values)}
    runs = {f"{label}, {v:g} V": {"mean_speed_mm_s": float(ps.mean_speed_mm_s[i]),
                                  "aperiodicity": float(np.nanmean(ps.aperiodicity[i])),
                                  "leg_motion_um": float(ps.leg_motion_um[i].mean()),
                                  "partial_share": ps.share(i, "partial_contact"),
                                  "contact_fraction": dict(zip(("air", "adhesion", "rest"),
                                                               ps.contact_fraction[i].mean(axis=(0, 1)).tolist())),
                                  "dominant_pattern": ps.dominant_pattern(i)}
            for k, (label, _) in enumerate(ABLATIONS_RUN) for v in sorted({x % 100 for x in idx})
            if (i := idx.get(ablation_x(k, v))) is not None}
    return _outcome("paper-ablations", ps, metrics, "run", plot,
                    {"freq_hz": ABLATION_FREQ_HZ, "drive_vpp": volts, "amp_um": drive.amp_um,
                     "runs": runs, "tray_law": tray_law(opts).describe()}, size_in=(9.0, 3.4))


@register("paper-payload", "speed vs total mass, on-board PZT 1.8 kHz tripod at 20 V (paper Fig. 13)",
          "more than 1 mm/s up to about 1.7 mg total mass, no motion above; speed rising from 1.2 to 1.7 mg")
def paper_payload(params: RobotParams, opts: RunOptions) -> Outcome:
    ps, metrics = evaluate("paper-payload", params, opts)

    def mark(ax: Any) -> None:
        ax.axhline(1.0, color="tab:red", lw=0.8, ls="--", label="paper: > 1 mm/s up to about 1.7 mg")
        ax.axvspan(1.7, max(2.5, float(ps.values.max())), color="tab:red", alpha=0.06,
                   label="paper: stops above 1.7 mg")

    plot = _speed_plot("paper-payload", ps, metrics, ("total robot mass (mg)",
                       f"paper-payload, PZT {PAYLOAD_FREQ_HZ:g} Hz tripod {PAYLOAD_VOLTAGE_V:g} V (cf. paper Fig. 13)"),
                       mark)
    return _outcome("paper-payload", ps, metrics, "mass_mg", plot,
                    {"freq_hz": PAYLOAD_FREQ_HZ, "voltage_v": PAYLOAD_VOLTAGE_V})


def _speed_plot(name: str, ps: PointSet, metrics: dict[str, float], labels: tuple[str, str],
                mark: Callable[[Any], None]) -> Plot:
    """A speed curve with the paper's marks (``mark(ax)``) and the observations' verdicts;
    ``labels``: the x axis's label and the title."""
    xlabel, title = labels
    def plot(fig: Any) -> None:
        ax = fig.add_subplot(111)
        curve_axes(ax, ps, "simulated")
        mark(ax)
        ax.axhline(0, color="0.5", lw=0.5)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("mean forward speed (mm/s)")
        ax.set_title(f"{title}: {metrics_line(metrics, name)}", fontsize=8)
        ax.legend(fontsize=6, loc="upper right")
        _band_text(ax, check(name, metrics), y=0.8)
        fig.tight_layout()

    return plot


def metrics_line(metrics: dict[str, float], name: str) -> str:
    """``"n/m met"`` (and how many not applicable) for a figure title."""
    checks = check(name, metrics)
    n = tally(checks)
    return f"{n[MET]}/{len(checks)} observations met" + (f", {n[NOT_APPLICABLE]} n/a" if n[NOT_APPLICABLE] else "")


@register("paper-fig14", "speed vs PZT frequency near the first lateral resonance, 20 V tripod (paper Fig. 14)",
          "the robot walks when its PZTs drive it around 438 Hz")
def paper_fig14(params: RobotParams, opts: RunOptions) -> Outcome:
    ps, metrics = evaluate("paper-fig14", params, opts)

    def mark(ax: Any) -> None:
        ax.axvline(438.0, color="tab:red", lw=0.8, ls="--", label="paper: first lateral resonance 438 Hz")

    plot = _speed_plot("paper-fig14", ps, metrics, ("PZT frequency (Hz)",
                       f"paper-fig14, PZT tripod {PAYLOAD_VOLTAGE_V:g} V (cf. paper Fig. 14)"), mark)
    return _outcome("paper-fig14", ps, metrics, "freq_hz", plot, {"voltage_v": PAYLOAD_VOLTAGE_V})


@register("paper-spectrum", "out-of-chip response: knee and body velocity relative to the tray, stepped sine "
          "at small amplitude (paper Fig. 6 right)",
          "resonances near 438 Hz, 1.2 kHz and 1.8 kHz; body motion near 800 Hz and 1.2 kHz")
def paper_spectrum(params: RobotParams, opts: RunOptions) -> Outcome:
    ps, metrics = evaluate("paper-spectrum", params, opts)
    knee = np.nanmean(ps.extra["knee_gain"], axis=1)
    body = np.nanmean(ps.extra["body_gain"], axis=1)

    def plot(fig: Any) -> None:
        ax = fig.add_subplot(111)
        ax.loglog(ps.values, knee, "k-", marker=".", label="knee (mean of legs) / tray")
        ax.loglog(ps.values, body, ":", color="tab:pink", marker=".", label="body / tray")
        for f in (438.0, 1200.0, 1800.0):
            ax.axvline(f, color="tab:red", lw=0.6, ls="--")
        ax.axvspan(800.0, 1200.0, color="tab:pink", alpha=0.08, label="paper: body motion 800 Hz-1.2 kHz")
        ax.set_xlabel("shaker frequency (Hz)")
        ax.set_ylabel("relative velocity / tray velocity")
        ax.set_title(f"paper-spectrum at {SPECTRUM_DRIVE_VPP:g} V (cf. paper Fig. 6 right; dashed: 438 Hz, 1.2, "
                     f"1.8 kHz): {metrics_line(metrics, 'paper-spectrum')}", fontsize=8)
        ax.legend(fontsize=6, loc="lower right")
        _band_text(ax, check("paper-spectrum", metrics))
        fig.tight_layout()

    gains = [{"freq_hz": float(f), "knee_gain": float(k), "body_gain": float(b)}
             for f, k, b in zip(ps.values, knee, body)]
    return _outcome("paper-spectrum", ps, metrics, "freq_hz", plot,
                    {"drive_vpp": SPECTRUM_DRIVE_VPP, "gains": gains, "tray_law": tray_law(opts).describe()})
