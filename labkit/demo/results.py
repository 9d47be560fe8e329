"""What ``labkit demo`` found, against the virtual lab's truth: tables for the JSON and for people."""
from __future__ import annotations

from typing import Any

import numpy as np


def compare_resonances(true_modes: dict[str, Any], fitted: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each of the virtual lab's tethered modes against the nearest fitted mode."""
    rows = []
    for name, f0, z0 in zip(true_modes["names"], true_modes["freq_hz"], true_modes["damping_ratio"]):
        row: dict[str, Any] = {"mode": name, "true_freq_hz": float(f0), "true_damping_ratio": float(z0)}
        if fitted:
            m = min(fitted, key=lambda m: abs(m["freq_hz"] - f0))
            row.update(fitted_index=m["index"], freq_hz=m["freq_hz"], freq_hz_std=m["freq_hz_std"],
                       damping_ratio=m["damping_ratio"], damping_ratio_std=m["damping_ratio_std"],
                       freq_error_pct=100 * (m["freq_hz"] / f0 - 1),
                       damping_error_pct=100 * (m["damping_ratio"] / z0 - 1),
                       dominant_location=m["dominant_location"])
        rows.append(row)
    return rows


def simulator_modes(fit: dict[str, Any], truth: Any, base: Any) -> list[dict[str, Any]]:
    """The parameter file's three modes, where each came from, and the virtual robot's."""
    names = ("1 lateral (hip)", "2 vertical", "3 vertical")
    rows = []
    for i in range(3):
        assigned = fit["assignment"].get(str(i + 1))
        rows.append({"mode": names[i], "freq_hz": fit["modal_freq_hz"][i],
                     "damping_ratio": fit["modal_damping_ratio"][i],
                     "source": f"fit #{assigned}" if assigned else "base (not measurable in-chip)",
                     "true_freq_hz": truth.modal_freq_hz[i], "true_damping_ratio": truth.modal_damping_ratio[i],
                     "base_freq_hz": base.modal_freq_hz[i]})
    return rows


def compare_speeds(points: list[dict[str, Any]], sw: Any) -> list[dict[str, Any]]:
    """Tracked speed at each shaker point against the simulated sweep at that frequency.

    Simulated: the nominal (fitted) robot's speed, signed (+ forward), and the
    mean and standard deviation over the Monte Carlo draws of each draw's
    speed magnitude (tracking measures a speed, not a direction), as the report.
    """
    rows = []
    for p in points:
        i = int(np.argmin(np.abs(sw.values - p["freq_hz"])))
        sp = np.abs(sw.speeds_mm_s[i])
        row = {"freq_hz": p["freq_hz"], "tray_amp_um": p["tray_amp_um"],
               "measured_mm_s": p.get("speed_mm_s"), "measured_ci_mm_s": p.get("speed_ci_mm_s"),
               "frames": p.get("frames"), "lost_frames": p.get("lost_frames"),
               "simulated_nominal_mm_s": float(sw.speeds_mm_s[i, 0]),
               "simulated_mm_s": float(sp.mean()),
               "simulated_std_mm_s": float(sp.std(ddof=1)) if sp.size > 1 else 0.0,
               "simulated_at_hz": float(sw.values[i])}
        rows.append(row)
    return rows


def headline(resonances: list[dict[str, Any]], speeds: list[dict[str, Any]],
             report_rms: float | None) -> dict[str, Any]:
    """The few numbers a newcomer looks at first."""
    ferr = [abs(r["freq_error_pct"]) for r in resonances if "freq_error_pct" in r]
    zerr = [abs(r["damping_error_pct"]) for r in resonances if "damping_error_pct" in r]
    pairs = [(r["measured_mm_s"], abs(r["simulated_nominal_mm_s"])) for r in speeds
             if r["measured_mm_s"] is not None]
    rms = float(np.sqrt(np.mean([(m - n) ** 2 for m, n in pairs]))) if pairs else None
    # a true mode counts as found when its nearest fitted mode is within 5 % and no other true mode's
    found = {r["fitted_index"] for r in resonances if abs(r.get("freq_error_pct", 100.0)) < 5}
    return {"modes_found": f"{len(found)} of {len(resonances)}",
            "max_freq_error_pct": max(ferr) if ferr else None,
            "max_damping_error_pct": max(zerr) if zerr else None,
            "speed_rms_error_vs_nominal_mm_s": rms,
            "speed_rms_error_vs_mc_mean_mm_s": report_rms}


def finite(obj: Any) -> Any:
    """JSON-able, NaN and infinities as None."""
    from labkit.jsonutil import to_jsonable

    return to_jsonable(obj, finite=True)


def format_summary(s: dict[str, Any]) -> str:
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
    for r in s["speeds"]:
        m = r["measured_mm_s"]
        ci = r["measured_ci_mm_s"] or [float("nan")] * 2
        meas = "n/a" if m is None else f"{m:6.2f} [{ci[0]:6.2f}, {ci[1]:6.2f}]"
        lines.append(f"  {r['freq_hz']:8.0f} {r['tray_amp_um']:8.1f} {meas:>24} {r['simulated_nominal_mm_s']:19.2f} "
                     f"{r['simulated_mm_s']:8.2f} +- {r['simulated_std_mm_s']:4.2f}")
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
        v = f.get(key)
        if isinstance(v, list):
            v = f"{v[0]} ... ({len(v)} files)" if len(v) > 2 else ", ".join(v)
        lines.append(f"  {label:22} {v}")
    lines.append(f"  {'virtual robot (truth)':22} {f['virtual_robot']}  (base: {f['base_robot']})")
    for n in s.get("notes", []):
        lines.append(f"note: {n}")
    return "\n".join(lines)
