"""The simulator's first scenarios (model.md section 8), at fixed tray laws.

=================  ==========================================================
name               what it runs (paper figure)
=================  ==========================================================
``shaker-speed``   speed vs shaker frequency at 25 um, Monte Carlo (Fig. 8)
``leg-patterns``   foot patterns as the shaker amplitude grows (Fig. 9-11)
``ablations``      full model, no adhesion, no squeeze film (Fig. 12)
``pzt-payload``    speed vs total mass, PZT 1.8 kHz tripod, 20 V (Fig. 13)
``pzt-frequency``  speed vs PZT frequency near 438 Hz at 20 V (Fig. 14)
``adhesion``       speed and patterns vs the adhesion magnitude (what the
                   behaviour hinges on; not a paper figure)
=================  ==========================================================

These drive the tray at a constant 25 um (optionally capped in acceleration)
and test coarse versions of the paper's claims (``checks``). The paper's
observations with their sources and tolerances, on the paper's shaker law,
are the ``paper-*`` scenarios of :mod:`labkit.sim.scenarios.paper`.
"""
from __future__ import annotations

from typing import TypedDict

import numpy as np

from labkit.jsonutil import Json
from labkit.sim.core import ablate
from labkit.sim.params import RobotParams
from labkit.sim.scenarios.base import Outcome, RunOptions, register
from labkit.sim.scenarios.io import write_runs, write_sweep_set
from labkit.sim.scenarios.metrics import band, fig8_checks, foot_rise_um, run_info
from labkit.sim.scenarios.plots import sweep_plot, trace_plot
from labkit.sim.sweep import SweepResult

#: The RobotParams field holding the adhesion force at first contact (N).
ADHESION_FIELD = "c_ad_n"


class Fig8Table(TypedDict):
    """A sweep judged by Fig. 8's tests (:func:`labkit.sim.scenarios.metrics.fig8_checks`) and its points."""

    checks: dict[str, bool]
    points: list[dict[str, Json]]


class Fig8Numbers(Fig8Table):
    """``shaker-speed``'s numbers per sweep: the speeds in the bands Fig. 8 speaks of."""

    peak_speed_150_300_hz_mm_s: float
    max_speed_500_1800_hz_mm_s: float
    speed_240_hz_mm_s: float


def _points(s: SweepResult) -> list[dict[str, Json]]:
    keys = (s.quantity, "mean_speed_mm_s", "std_speed_mm_s", "dominant_pattern")
    return [{k: p[k] for k in keys} for p in s.summary()["points"]]


def _fig8_table(s: SweepResult) -> Fig8Table:
    return {"checks": fig8_checks(s.values, s.mean_speed_mm_s), "points": _points(s)}


@register("shaker-speed", "speed vs shaker frequency at 25 um (paper Fig. 8)",
           "a few mm/s between 150 and 300 Hz (falling from 200 Hz, a bump near 300 Hz); "
           "no motion from 500 Hz to 1.8 kHz")
def shaker_speed(params: RobotParams, opts: RunOptions) -> Outcome:
    from labkit.sim import Shaker, sweep

    freqs = np.linspace(150, 2000, 40) if not opts.quick else np.array([200.0, 300.0, 800.0])
    kw = dict(draws=opts.pick(10, 2, opts.draws), duration_s=opts.pick(2.0, 0.1, opts.duration_s),
              **opts.executor_kw())
    s = sweep(params, Shaker(freq_hz=240.0, amp_um=25.0), "freq_hz", freqs.tolist(), **kw)
    capped = sweep(params, Shaker(freq_hz=240.0, amp_um=25.0), "freq_hz", freqs.tolist(),
                   accel_limit_g=ACCEL_LIMIT_G, **kw)
    out: dict[str, Fig8Numbers] = {}
    for key, sw in (("amp_25_um", s), (f"capped_{ACCEL_LIMIT_G:g}_g", capped)):
        out[key] = {"peak_speed_150_300_hz_mm_s": band(sw.values, sw.mean_speed_mm_s, 150, 300),
                    "max_speed_500_1800_hz_mm_s": band(sw.values, sw.mean_speed_mm_s, 500, 1800),
                    "speed_240_hz_mm_s": float(np.interp(240.0, sw.values, sw.mean_speed_mm_s)), **_fig8_table(sw)}
    a, c = out["amp_25_um"], out[f"capped_{ACCEL_LIMIT_G:g}_g"]
    return Outcome(
        numbers={**out, "accel_limit_g": ACCEL_LIMIT_G}, checks=a["checks"],
        finding=(f"25 um: max |speed| {a['peak_speed_150_300_hz_mm_s']:.2f} mm/s in 150-300 Hz, "
                        f"{a['max_speed_500_1800_hz_mm_s']:.2f} mm/s in 500-1800 Hz; capped at "
                        f"{ACCEL_LIMIT_G:g} g: {c['peak_speed_150_300_hz_mm_s']:.2f} and "
                 f"{c['max_speed_500_1800_hz_mm_s']:.2f} mm/s"),
        plot=sweep_plot(s, "shaker frequency (Hz)", "Shaker sweep (cf. paper Fig. 8)",
                                 [(150, 300, "mm/s expected"), (500, 1800, "no motion expected")],
                                 label="25 um", others=[(capped, f"25 um, <= {ACCEL_LIMIT_G:g} g")]),
        write_data=lambda path: write_sweep_set(path, {"amp_25_um": s, "capped": capped}))


#: The peak tray acceleration of the headline case, 25 um at 240 Hz, in g. The
#: ``shaker-speed`` and ``adhesion`` scenarios also run with the tray's
#: acceleration capped at this value (amplitude ~ 1/f^2 above 240 Hz), since
#: the paper says the shaker's amplitude falls at high frequency (**choice**:
#: the cap's value; the paper gives none).
ACCEL_LIMIT_G = round((2 * np.pi * 240.0) ** 2 * 25e-6 / 9.80665, 2)


#: Tray amplitudes standing for the paper's 2, 4, 6 and 8 Vpp shaker drive
#: (**choice**: the jumping case at 8 V is stated as 25 um, and the shaker is
#: taken as linear, so 2 V ~ 6.25 um).
PATTERN_AMPS_UM = (6.25, 12.5, 18.75, 25.0)
PATTERN_FREQ_HZ = 240.0
#: Amplitudes of the pattern map, um: the paper's range (6-25 um) and, since
#: with the published 50 uN adhesion the feet need far more, up to 400 um.
PATTERN_SWEEP_UM = (1.0, 2.0, 4.0, 6.25, 9.0, 12.5, 18.75, 25.0, 35.0, 50.0, 70.0, 100.0, 140.0, 200.0,
                    280.0, 400.0)


@register("leg-patterns", "foot patterns as the shaker amplitude grows (paper Fig. 9-11)",
           "firm contact at small amplitude, partial (adhesion-held) contact, then jumping "
           "with foot motion far above the tray's")
def leg_patterns(params: RobotParams, opts: RunOptions) -> Outcome:
    from labkit.sim import Shaker, simulate, sweep

    dur = opts.pick(0.5, 0.1, opts.duration_s)
    amps = np.array(PATTERN_SWEEP_UM) if not opts.quick else np.array([2.0, 25.0])
    s = sweep(params, Shaker(freq_hz=PATTERN_FREQ_HZ, amp_um=amps[0]), "amp_um", amps.tolist(),
              draws=opts.pick(0, 0, opts.draws), duration_s=dur, **opts.executor_kw())
    order = {"firm_contact": 0, "partial_contact": 1, "jumping": 2}
    dominant = [s.dominant_pattern(i) for i in range(len(amps))]
    # Traces: the paper's headline 25 um and, for each pattern the map found,
    # the middle amplitude showing it, so every pattern present is drawn.
    picks = {25.0}
    for p in order:
        hits = [a for a, d in zip(amps, dominant) if d == p]
        if hits:
            picks.add(float(hits[len(hits) // 2]))
    trace_amps = sorted(picks)
    runs = [(f"{a:g} um", simulate(params, Shaker(freq_hz=PATTERN_FREQ_HZ, amp_um=a), duration_s=dur, seed=opts.seed))
            for a in trace_amps]
    frac = {p: [s.pattern_counts(i)[p] / (6 * s.draws) for i in range(len(amps))] for p in order}
    seen = [p for p in order if p in dominant]
    ranks = [order[d] for d in dominant]
    # Paper: jumping legs reach ~200 um over a 25 um tray; ask for more than twice the tray's amplitude.
    rise = {a: foot_rise_um(r) for a, (_, r) in zip(trace_amps, runs)}
    jumpers = [a for a, (_, r) in zip(trace_amps, runs) if "jumping" in r.patterns]
    checks = {"all_three_patterns": len(seen) == 3,
              "ordered_with_amplitude": bool(all(b >= a for a, b in zip(ranks, ranks[1:]))),
              "jumping_far_above_tray": bool(jumpers and all(rise[a] > 2 * a for a in jumpers))}

    def extra(fig, ax):
        for p, c in zip(frac, ("tab:green", "tab:orange", "tab:purple")):
            ax.plot(amps, frac[p], "o-", ms=3, color=c, label=p.replace("_", " "))
        ax.axvspan(min(PATTERN_AMPS_UM), max(PATTERN_AMPS_UM), color="0.9", zorder=0)
        ax.set_xscale("log")
        ax.set_xlabel(f"tray amplitude (um) at {PATTERN_FREQ_HZ:g} Hz; grey: the paper's 2-8 V", fontsize=7)
        ax.set_ylabel("share of feet", fontsize=7)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6)

    return Outcome(
        numbers={"freq_hz": PATTERN_FREQ_HZ, "amps_um": amps.tolist(), "dominant_pattern": dominant,
                 "foot_rise_um": {f"{a:g}": v for a, v in rise.items()},
                 "pattern_share": frac, "traces": {lab: run_info(r, PATTERN_FREQ_HZ) for lab, r in runs}},
        checks=checks,
        finding="dominant pattern vs amplitude: "
                + ", ".join(f"{a:g} um {d.split('_')[0]}" for a, d in zip(amps, dominant)),
        plot=trace_plot(runs, PATTERN_FREQ_HZ, extra=extra), write_data=s.to_h5)


#: The drive for the ablations: the headline case of the paper.
ABLATION_SHAKER = {"freq_hz": 240.0, "amp_um": 25.0}
#: An ablation "makes the motion less periodic" when its aperiodicity exceeds
#: the full model's by this much (0 = periodic, ~1.4 = unrelated cycles).
APERIODIC_MARGIN = 0.05
#: ... and "makes the legs move more" when their peak-to-peak motion grows by this factor.
LEG_MOTION_RATIO = 1.2


@register("ablations", "full model vs no adhesion vs no squeeze film (paper Fig. 12)",
           "without adhesion the partial-contact motion is no longer periodic; "
           "without squeeze-film damping the leg motion grows")
def ablations(params: RobotParams, opts: RunOptions) -> Outcome:
    from labkit.sim import Shaker, simulate

    dur = opts.pick(1.0, 0.1, opts.duration_s)
    sc = Shaker(**ABLATION_SHAKER)
    runs = [(label, simulate(ablate(params, what), sc, duration_s=dur, seed=opts.seed))
            for label, what in (("full model", "none"), ("no adhesion", "no_adhesion"),
                                ("no squeeze film", "no_squeeze_film"))]
    info = {label: run_info(r, sc.freq_hz) for label, r in runs}
    full, noad, nosq = info["full model"], info["no adhesion"], info["no squeeze film"]
    # Margins so that rounding-level differences do not count as an effect.
    checks = {"no_adhesion_less_periodic": bool(noad["aperiodicity"] > full["aperiodicity"] + APERIODIC_MARGIN),
              "no_squeeze_film_more_leg_motion": bool(nosq["leg_motion_um"] > LEG_MOTION_RATIO * full["leg_motion_um"])}
    _, full_r = runs[0]
    return Outcome(
        numbers={**ABLATION_SHAKER, "runs": info}, checks=checks,
        finding=(f"aperiodicity full {full['aperiodicity']:.3f} / no adhesion {noad['aperiodicity']:.3f}; "
                        f"leg motion full {full['leg_motion_um']:.1f} um / no squeeze film "
                 f"{nosq['leg_motion_um']:.1f} um"),
        plot=trace_plot(runs, sc.freq_hz),
        write_data=lambda path: write_runs(path, "sim_ablations", runs, info))


@register("pzt-payload", "speed vs total mass, on-board PZT at 1.8 kHz, tripod, 20 V (paper Fig. 13)",
           "more than 1 mm/s up to about 1.7 mg total mass, stopping above; speed rising between 1.2 and 1.7 mg")
def pzt_payload(params: RobotParams, opts: RunOptions) -> Outcome:
    from labkit.sim import PZT, sweep

    masses = np.round(np.linspace(0.33, 2.5, 14), 3) if not opts.quick else np.array([0.33, 2.5])
    s = sweep(params, PZT(freq_hz=1800.0, voltage_v=20.0, mass_mg=0.33), "mass_mg", masses.tolist(),
              draws=opts.pick(10, 2, opts.draws), duration_s=opts.pick(1.0, 0.05, opts.duration_s),
              **opts.executor_kw())
    mean = s.mean_speed_mm_s
    moving = masses[np.abs(mean) > 1.0]
    limit = float(moving.max()) if moving.size else float("nan")
    above = np.abs(mean[masses > 1.9])
    checks = {"over_1_mm_s_up_to_about_1_7_mg": bool(moving.size and 1.4 <= limit <= 2.0
                                                     and np.all(np.abs(mean[masses <= 1.4]) > 1.0)),
              "stops_above_about_1_7_mg": bool(above.size and above.max() < 0.3)}
    return Outcome(
        numbers={"freq_hz": 1800.0, "voltage_v": 20.0, "largest_mass_over_1_mm_s_mg": limit,
                 "points": _points(s)},
        checks=checks,
        finding=f"|speed| > 1 mm/s up to {limit:g} mg; max |speed| above 1.9 mg: "
                f"{(above.max() if above.size else float('nan')):.3f} mm/s",
        plot=sweep_plot(s, "total robot mass (mg)", "PZT 1.8 kHz tripod, 20 V (cf. paper Fig. 13)"),
        write_data=s.to_h5)


@register("pzt-frequency", "speed vs PZT frequency near the 438 Hz lateral resonance, 20 V (paper Fig. 14)",
           "a speed trend with frequency around the first lateral resonance")
def pzt_frequency(params: RobotParams, opts: RunOptions) -> Outcome:
    from labkit.sim import PZT, sweep

    freqs = np.linspace(250, 650, 17) if not opts.quick else np.array([400.0, 450.0])
    s = sweep(params, PZT(freq_hz=438.0, voltage_v=20.0), "freq_hz", freqs.tolist(),
              draws=opts.pick(5, 2, opts.draws), duration_s=opts.pick(1.0, 0.05, opts.duration_s),
              **opts.executor_kw())
    i = int(np.argmax(np.abs(s.mean_speed_mm_s)))
    peak_f = float(s.values[i])
    checks = {"speed_varies_with_frequency": bool(np.ptp(s.mean_speed_mm_s) > 2 * float(np.mean(s.std_speed_mm_s)))}
    return Outcome(
        numbers={"voltage_v": 20.0, "peak_freq_hz": peak_f, "peak_speed_mm_s": float(s.mean_speed_mm_s[i]),
                 "points": _points(s)},
        checks=checks, finding=f"fastest at {peak_f:g} Hz: {s.mean_speed_mm_s[i]:.2f} mm/s",
        plot=sweep_plot(s, "PZT drive frequency (Hz)", "PZT 20 V tripod near 438 Hz (cf. paper Fig. 14)",
                        [(430, 446, "438 Hz")]),
        write_data=s.to_h5)


#: Adhesion magnitudes tried by the ``adhesion`` scenario, N (the paper's is 50e-6).
ADHESION_VALUES_N = (0.0, 0.5e-6, 1e-6, 2e-6, 5e-6, 10e-6, 20e-6, 50e-6)
#: Shaker frequencies of the ``adhesion`` scenario, Hz (Fig. 8's range, coarser).
ADHESION_FREQS_HZ = (150.0, 200.0, 240.0, 300.0, 400.0, 500.0, 600.0, 800.0, 1000.0, 1400.0, 1800.0)


@register("adhesion", "speed vs shaker frequency for adhesion magnitudes 0-50 uN (25 um; and capped at 5.8 g)",
           "not a paper figure: which adhesion magnitude (if any) gives Fig. 8's behaviour")
def adhesion(params: RobotParams, opts: RunOptions) -> Outcome:
    from labkit.sim import Shaker, sweep

    name = ADHESION_FIELD
    values = ADHESION_VALUES_N if not opts.quick else (0.0, 50e-6)
    freqs = np.array(ADHESION_FREQS_HZ if not opts.quick else (240.0, 800.0))
    dur = opts.pick(1.0, 0.05, opts.duration_s)
    nd = opts.pick(0, 0, opts.draws)
    laws = {"25 um": None, f"<= {ACCEL_LIMIT_G:g} g": ACCEL_LIMIT_G}
    sweeps = {(law, v): sweep(params.replace(**{name: v}), Shaker(freq_hz=240.0, amp_um=25.0), "freq_hz",
                              freqs.tolist(), draws=nd, duration_s=dur, **opts.executor_kw(), accel_limit_g=cap)
              for law, cap in laws.items() for v in values}

    def plot(fig):
        import matplotlib
        import matplotlib.ticker

        cmap = matplotlib.colormaps["viridis"]
        for k, law in enumerate(laws):
            ax = fig.add_subplot(1, 2, k + 1)
            for n, v in enumerate(values):
                s = sweeps[(law, v)]
                ax.plot(s.values, s.mean_speed_mm_s, "o-", ms=2, lw=0.9, color=cmap(n / max(1, len(values) - 1)),
                        label=f"{v * 1e6:g} uN")
            ax.axvspan(150, 300, color="tab:blue", alpha=0.08)
            ax.axvspan(500, 1800, color="tab:red", alpha=0.05)
            ax.set_xscale("log")
            ax.set_xticks([150, 300, 500, 1000, 1800], labels=["150", "300", "500", "1000", "1800"])
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            ax.set_xlabel(f"shaker frequency (Hz), tray {law}", fontsize=8)
            ax.set_ylabel("mean forward speed (mm/s)", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.set_title(f"adhesion {name} (paper: 50 uN)", fontsize=8)
            if k == 0:
                ax.legend(fontsize=6, ncol=2, title="adhesion", title_fontsize=6)
        fig.tight_layout()

    table: dict[str, dict[str, Fig8Table]] = {
        law: {f"{v * 1e6:g}": _fig8_table(sweeps[(law, v)]) for v in values} for law in laws}
    good = {law: [k for k, t in rows.items() if all(t["checks"].values())] for law, rows in table.items()}
    return Outcome(
        numbers={"field": name, "by_law_and_adhesion_un": table, "values_reproducing_fig8_un": good},
        checks={"published_value_reproduces_fig8": "50" in good["25 um"]},
        finding="adhesion values (uN) meeting both Fig. 8 tests: "
                + "; ".join(f"tray {law}: {', '.join(g) or 'none'}" for law, g in good.items()),
        plot=plot,
        write_data=lambda path: write_sweep_set(path, {f"{'amp_25_um' if cap is None else 'capped'}/"
                                                       f"{v * 1e6:g}_uN": sweeps[(law, v)]
                                                       for law, cap in laws.items() for v in values}))


