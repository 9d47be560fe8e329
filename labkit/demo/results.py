"""What ``labkit demo`` found, against the virtual lab's truth: tables for the JSON and for people."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, NotRequired, TypedDict

import numpy as np

if TYPE_CHECKING:
    from labkit.analysis.modal.robot import FitSummary, FittedModeRow
    from labkit.jsonutil import Json
    from labkit.lab.control import TetheredModes


class Resonance(TypedDict):
    """One of the virtual lab's tethered modes against the nearest fitted mode (none: not found)."""

    mode: str
    true_freq_hz: float
    true_damping_ratio: float
    fitted_index: NotRequired[int]
    freq_hz: NotRequired[float]
    freq_hz_std: NotRequired[float]
    damping_ratio: NotRequired[float]
    damping_ratio_std: NotRequired[float]
    freq_error_pct: NotRequired[float]
    damping_error_pct: NotRequired[float]
    dominant_location: NotRequired[str]


class SimulatorMode(TypedDict):
    """One of the parameter file's three modes, where it came from, and the virtual robot's."""

    mode: str
    freq_hz: float
    damping_ratio: float
    source: str
    true_freq_hz: float
    true_damping_ratio: float
    base_freq_hz: float


class ShakerPoint(TypedDict):
    """A shaker run's good point, and (once tracked) its video's headline numbers."""

    index: int
    freq_hz: float
    tray_amp_um: float
    video: str
    track: NotRequired[str]
    speed_mm_s: NotRequired[float]
    speed_ci_mm_s: NotRequired[list[float]]
    frames: NotRequired[int]
    lost_frames: NotRequired[int]
    degraded_frames: NotRequired[int]


class SpeedRow(TypedDict):
    """A tracked speed against the simulated sweep at that frequency."""

    freq_hz: float
    tray_amp_um: float
    measured_mm_s: float | None
    measured_ci_mm_s: list[float] | None
    frames: int | None
    lost_frames: int | None
    simulated_nominal_mm_s: float
    simulated_mm_s: float
    simulated_std_mm_s: float
    simulated_at_hz: float


class Headline(TypedDict):
    """The few numbers a newcomer looks at first."""

    modes_found: str
    max_freq_error_pct: float | None
    max_damping_error_pct: float | None
    speed_rms_error_vs_nominal_mm_s: float | None
    speed_rms_error_vs_mc_mean_mm_s: float | None


class AssignmentNote(TypedDict):
    """How the demo mapped the fitted modes onto the simulator's, and why."""

    assign: str
    why: str
    mode_1: str
    modes_2_3: str
    recorded_in: str


class DemoFiles(TypedDict, total=False):
    """Every file the demo wrote (paths as given, relative to where it ran)."""

    virtual_robot: str
    base_robot: str
    inchip_pilot: str
    inchip_runs: list[str]
    robot_params: str
    fit_file: str
    fit_figures: list[str]
    shaker_run: str
    configs: list[str]
    tracks: list[str]
    videos: list[str]
    sim_sweep: str
    report_html: str
    report_figures: list[str]
    agreement_json: str
    summary_json: str


class DemoSummary(TypedDict):
    """What ``labkit demo --json`` prints (and ``demo_summary.json`` holds)."""

    ok: bool
    out_dir: str
    mode: str
    seed: int
    headline: Headline
    wall_s: float
    stage_s: dict[str, float]
    files: DemoFiles
    resonances: list[Resonance]
    simulator_modes: list[SimulatorMode]
    assignment: AssignmentNote
    speeds: list[SpeedRow]
    speed_rms_error_mm_s: float | None
    report_sections: dict[str, str]
    virtual_robot: dict[str, dict[str, float]]
    settings: dict[str, Json]
    fit_warnings: list[str]
    notes: list[str]


def compare_resonances(true_modes: TetheredModes, fitted: list[FittedModeRow]) -> list[Resonance]:
    """Each of the virtual lab's tethered modes against the nearest fitted mode."""
    rows = []
    for name, f0, z0 in zip(true_modes["names"], true_modes["freq_hz"], true_modes["damping_ratio"]):
        row: Resonance = {"mode": name, "true_freq_hz": float(f0), "true_damping_ratio": float(z0)}
        if fitted:
            m = min(fitted, key=lambda m: abs(m["freq_hz"] - f0))
            row.update({"fitted_index": m["index"], "freq_hz": m["freq_hz"], "freq_hz_std": m["freq_hz_std"],
                        "damping_ratio": m["damping_ratio"], "damping_ratio_std": m["damping_ratio_std"],
                        "freq_error_pct": 100 * (m["freq_hz"] / f0 - 1),
                        "damping_error_pct": 100 * (m["damping_ratio"] / z0 - 1),
                        "dominant_location": m["dominant_location"]})
        rows.append(row)
    return rows


def simulator_modes(fit: FitSummary, truth: Any, base: Any) -> list[SimulatorMode]:
    """The parameter file's three modes, where each came from, and the virtual robot's."""
    names = ("1 lateral (hip)", "2 vertical", "3 vertical")
    rows: list[SimulatorMode] = []
    for i in range(3):
        assigned = fit["assignment"].get(str(i + 1))
        rows.append({"mode": names[i], "freq_hz": fit["modal_freq_hz"][i],
                     "damping_ratio": fit["modal_damping_ratio"][i],
                     "source": f"fit #{assigned}" if assigned else "base (not measurable in-chip)",
                     "true_freq_hz": truth.modal_freq_hz[i], "true_damping_ratio": truth.modal_damping_ratio[i],
                     "base_freq_hz": base.modal_freq_hz[i]})
    return rows


def compare_speeds(points: list[ShakerPoint], sw: Any) -> list[SpeedRow]:
    """Tracked speed at each shaker point against the simulated sweep at that frequency.

    Simulated: the nominal (fitted) robot's speed, signed (+ forward), and the
    mean and standard deviation over the Monte Carlo draws of each draw's
    speed magnitude (tracking measures a speed, not a direction), as the report.
    """
    rows = []
    for p in points:
        i = int(np.argmin(np.abs(sw.values - p["freq_hz"])))
        sp = np.abs(sw.speeds_mm_s[i])
        row: SpeedRow = {"freq_hz": p["freq_hz"], "tray_amp_um": p["tray_amp_um"],
               "measured_mm_s": p.get("speed_mm_s"), "measured_ci_mm_s": p.get("speed_ci_mm_s"),
               "frames": p.get("frames"), "lost_frames": p.get("lost_frames"),
               "simulated_nominal_mm_s": float(sw.speeds_mm_s[i, 0]),
               "simulated_mm_s": float(sp.mean()),
               "simulated_std_mm_s": float(sp.std(ddof=1)) if sp.size > 1 else 0.0,
               "simulated_at_hz": float(sw.values[i])}
        rows.append(row)
    return rows


def headline(resonances: list[Resonance], speeds: list[SpeedRow], report_rms: float | None) -> Headline:
    """The few numbers a newcomer looks at first."""
    ferr = [abs(r["freq_error_pct"]) for r in resonances if "freq_error_pct" in r]
    zerr = [abs(r["damping_error_pct"]) for r in resonances if "damping_error_pct" in r]
    pairs = [(m, abs(r["simulated_nominal_mm_s"])) for r in speeds if (m := r["measured_mm_s"]) is not None]
    rms = float(np.sqrt(np.mean([(m - n) ** 2 for m, n in pairs]))) if pairs else None
    # a true mode counts as found when its nearest fitted mode is within 5 % and no other true mode's
    found = {r.get("fitted_index") for r in resonances if abs(r.get("freq_error_pct", 100.0)) < 5}
    return {"modes_found": f"{len(found)} of {len(resonances)}",
            "max_freq_error_pct": max(ferr) if ferr else None,
            "max_damping_error_pct": max(zerr) if zerr else None,
            "speed_rms_error_vs_nominal_mm_s": rms,
            "speed_rms_error_vs_mc_mean_mm_s": report_rms}


def finite(obj: Any) -> Any:
    """JSON-able, NaN and infinities as None."""
    from labkit.jsonutil import to_jsonable

    return to_jsonable(obj, finite=True)


def format_summary(s: DemoSummary) -> str:
    """The human-readable account: where everything went and the headline figures."""
    f = s["files"]
    v = s["virtual_robot"]["changes_from_paper"]
    lines = [f"labkit demo ({s['mode']}) finished in {s['wall_s']:.0f} s; everything is in {s['out_dir']}/",
             f"Virtual robot: the paper's, with adhesion c_ad_n = {v['c_ad_n']:g} N (so it walks), "
             f"{v['foot_pad_um']:g} um foot pads (a periodic walk) and its hip mode "
             f"at {v['hip_freq_hz']:g} Hz, zeta {v['hip_damping_ratio']:g}; the pipeline starts from the paper's "
             "modes (base file) and never reads the virtual robot's.", ""]
    lines.append("Identified resonances of the tethered robot (in-chip fit) against the virtual robot's:")
    lines.append(f"  {'mode':8} {'true Hz':>9} {'fitted Hz':>16} {'error':>7}   {'true zeta':>9} "
                 f"{'fitted zeta':>16} {'error':>7}")
    for r in s["resonances"]:
        if "freq_hz" not in r:
            lines.append(f"  {r['mode']:8} {r['true_freq_hz']:9.1f}   (not found)")
            continue
        lines.append(f"  {r['mode']:8} {r['true_freq_hz']:9.1f} {r['freq_hz']:9.1f} +-{r['freq_hz_std']:5.1f} "
                     f"{r['freq_error_pct']:+6.2f}%   {r['true_damping_ratio']:9.4f} "
                     f"{r['damping_ratio']:8.4f} +-{r['damping_ratio_std']:6.4f} {r['damping_error_pct']:+6.1f}%")
    lines.append(f"  modes found: {s['headline']['modes_found']} (the tether and in-chip knee modes exist only "
                 "in-chip: the simulator does not use them)")
    lines.append("")
    lines.append(f"Robot parameter file {f['robot_params']}:")
    for m in s["simulator_modes"]:
        lines.append(f"  mode {m['mode']:16} {m['freq_hz']:7.1f} Hz, zeta {m['damping_ratio']:.3f}  <- {m['source']}"
                     f"  (virtual robot: {m['true_freq_hz']:.1f} Hz)")
    a = s["assignment"]
    lines.append(f"  assignment --assign {a['assign']}: {a['mode_1']};")
    lines.append(f"  modes 2 and 3 {a['modes_2_3']}.")
    lines.append("")
    lines.append("Walking speed on the shaker: tracked from video against simulated with the fitted parameters")
    lines.append(f"  {'freq_hz':>8} {'tray_um':>8} {'measured (95% CI)':>24} {'simulated: nominal':>19} "
                 f"{'MC mean +- std':>16}   (mm/s)")
    for sp in s["speeds"]:
        speed = sp["measured_mm_s"]
        ci = sp["measured_ci_mm_s"] or [float("nan")] * 2
        meas = "n/a" if speed is None else f"{speed:6.2f} [{ci[0]:6.2f}, {ci[1]:6.2f}]"
        lines.append(f"  {sp['freq_hz']:8.0f} {sp['tray_amp_um']:8.1f} {meas:>24} {sp['simulated_nominal_mm_s']:19.2f} "
                     f"{sp['simulated_mm_s']:8.2f} +- {sp['simulated_std_mm_s']:4.2f}")
    lines.append("  (nominal: signed, + = forward; the tracker measures speed without direction; the Monte Carlo "
                 "draws perturb the parameters by labkit.sim.uncertainty's table)")
    h = s["headline"]
    if h["speed_rms_error_vs_nominal_mm_s"] is not None:
        lines.append("  speed RMS error, measured - |nominal simulation|: "
                     f"{h['speed_rms_error_vs_nominal_mm_s']:.3g} mm/s")
    if h["speed_rms_error_vs_mc_mean_mm_s"] is not None:
        lines.append(f"  speed RMS error, measured - Monte Carlo mean (the report's): "
                     f"{h['speed_rms_error_vs_mc_mean_mm_s']:.3g} mm/s")
    lines.append("")
    lines.append("Files:")
    for key, label in (("inchip_pilot", "in-chip pilot run"), ("inchip_runs", "in-chip run file"),
                       ("shaker_run", "shaker run file"),
                       ("videos", "videos"), ("tracks", "tracks"), ("robot_params", "robot parameter file"),
                       ("fit_file", "fit file"), ("sim_sweep", "simulated sweep"), ("configs", "configs"),
                       ("report_html", "REPORT"), ("summary_json", "summary")):
        paths = f.get(key)
        if isinstance(paths, list):
            paths = f"{paths[0]} ... ({len(paths)} files)" if len(paths) > 2 else ", ".join(paths)
        lines.append(f"  {label:22} {paths}")
    lines.append(f"  {'virtual robot (truth)':22} {f['virtual_robot']}  (base: {f['base_robot']})")
    for n in s.get("notes", []):
        lines.append(f"note: {n}")
    return "\n".join(lines)
