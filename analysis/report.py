"""Build the model-against-measurement report: figures (PNG), one self-contained HTML page,
and ``agreement.json`` holding every number with its provenance.

Sections (paper figure numbers in brackets): FRFs per location with the fitted
model [5/6], stabilisation diagram, speed against shaker frequency [8], the
knee's vertical motion at chosen drives with contact-mode timelines [10/11],
and the agreement table. A section whose inputs were not given says so; an
input that cannot be read raises :class:`labkit.errors.InputError` naming it.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from analysis import compare, report_figures as figs, report_html as rh, report_inputs as ri
from labkit.errors import InputError


def build_report(out_dir: str | Path, *, runs: Sequence[str] = (), tracks: Sequence[str] = (),
                 fit: str | None = None, sims: Sequence[str] = (), params: str | None = None,
                 knee_drives: Sequence[tuple[float, float]] | None = None, simulate_knee: bool = True,
                 knee_duration_s: float = 0.3, leg: int = 0, band_k: float = 2.0,
                 scheduler: str | None = None, workers: int | None = None,
                 title: str = "labkit: model against measurement",
                 quiet: bool = True) -> dict[str, Any]:
    """Read the inputs, compare, draw, and write ``report.html``, PNGs and ``agreement.json``.

    Parameters
    ----------
    runs:
        Run files (``run_inchip`` and/or ``run_shaker``).
    tracks:
        Track files (``kind = "track"``).
    fit:
        A ``modal_fit`` file (``robot.fit.h5``).
    sims:
        ``sim_sweep`` files (speed against ``freq_hz``) and/or ``sim_result`` files
        (knee motion at one drive).
    params:
        Robot parameter file for simulating the knee at the chosen drives
        (default: the TOML beside the fit, else the first sweep's parameters,
        else the defaults).
    knee_drives:
        ``(freq_hz, amp_um)`` pairs; default: the drives of the measured knee records.
    simulate_knee:
        Simulate drives no ``sim_result`` covers (through :func:`labkit.executor.map_tasks`).
    leg:
        Which leg's knee (0..5) the simulated record shows.
    band_k:
        Monte Carlo band half-width in standard deviations.
    scheduler, workers:
        Passed to :func:`labkit.executor.map_tasks` for the knee simulations.

    Returns
    -------
    dict
        Paths written, per-section status and the headline agreement numbers.
    """
    from labkit.h5io import utc_now
    from labkit import __version__

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    # ---- read everything first: a bad file fails before any figure is drawn
    inchip, shaker = [], []
    for path in runs:
        kind = ri.file_kind(path)
        if kind == "run_inchip":
            inchip.append(ri.load_inchip_run(path))
        elif kind == "run_shaker":
            shaker.append(ri.load_shaker_run(path))
        else:
            raise InputError(f"this file holds {kind!r}", file=path, key="kind",
                             expected="a 'run_inchip' or 'run_shaker' run file")
    track_data = [ri.load_track(p) for p in tracks]
    fit_data = ri.load_fit(fit) if fit else None
    sim_data = [ri.load_sim(p) for p in sims]
    sweeps = [s for s in sim_data if s["kind"] == "sim_sweep"]
    results = [s for s in sim_data if s["kind"] == "sim_result"]
    inputs = {"runs": list(map(str, runs)), "tracks": list(map(str, tracks)), "fit": fit,
              "sims": list(map(str, sims)), "params": params}

    sections: list[dict[str, Any]] = []
    agreement: list[dict[str, Any]] = []
    sections.append(_frf_section(out, inchip, fit_data))
    sections.append(_stab_section(out, fit_data))
    speed_sec, speed_rows, speed_num = _speed_section(out, shaker, track_data, sweeps, band_k)
    sections.append(speed_sec)
    agreement += speed_rows
    knee_sec, knee_rows, knee_num = _knee_section(out, shaker, results, sweeps, fit, params, knee_drives,
                                                  simulate_knee, knee_duration_s, leg, scheduler, workers, quiet)
    sections.append(knee_sec)
    agreement += knee_rows
    sections.append(_agreement_section(agreement))

    meta = {"created_utc": utc_now(), "software": f"labkit {__version__}", "inputs": inputs}
    html_path = out / "report.html"
    html_path.write_text(rh.render(title, sections, meta), encoding="utf-8")
    numbers = {"speed": speed_num, "knee": knee_num}
    (out / "agreement.json").write_text(json.dumps({"meta": meta, "agreement": agreement, "details": numbers},
                                                   indent=1, default=str), encoding="utf-8")
    figures = [str(p) for s in sections for p, _ in s.get("figures", [])]
    headline = next((r for r in agreement if r["quantity"] == "speed RMS error"), None)
    return {"html": str(html_path), "figures": figures, "agreement_json": str(out / "agreement.json"),
            "sections": {s["id"]: s["status"] for s in sections},
            "missing": {s["id"]: s["message"] for s in sections if s["status"] != "ok"},
            "notes": {s["id"]: s["message"] for s in sections if s["status"] == "ok" and s.get("message")},
            "speed_rms_error_mm_s": headline["value"] if headline else None,
            "agreement": [{k: r[k] for k in ("quantity", "value", "units")} for r in agreement]}


def _missing(sid: str, title: str, message: str) -> dict[str, Any]:
    return {"id": sid, "title": title, "status": "missing", "message": message, "figures": [], "html": []}


# --------------------------------------------------------------------------- FRF and stabilisation

GROUP_TITLES = {"inchip": "tethered robot, in-chip sweep: FRF (paper Fig. 5)",
                "shaker": "released robot on the shaker: transmissibility (paper Fig. 6)"}


def _frf_section(out: Path, inchip: list[dict], fit: dict | None) -> dict[str, Any]:
    title = "Frequency responses with the fitted model (paper Fig. 5/6)"
    groups = {k: g for k, g in (fit["groups"].items() if fit else []) if g["locations"]}
    if not groups and not inchip:
        return _missing("frf", title, "No in-chip run file (--runs RUN.h5) or fit (--fit robot.fit.h5) given.")
    sec: dict[str, Any] = {"id": "frf", "title": title, "status": "ok", "figures": [], "html": []}
    if not groups:
        sec["message"] = "No fit given (--fit robot.fit.h5): measured FRFs only, no model curve."
        for k, run in enumerate(inchip):
            png = figs.frf_figure(run["locations"], [], out / f"fig_frf_run{k + 1}.png", units="(mm/s)/V",
                                  title=GROUP_TITLES["inchip"])
            sec["figures"].append((png, f"measured FRF per location from {run['file']}"))
        return sec
    for name, g in groups.items():
        png = figs.frf_figure(g["locations"], g["modes"], out / f"fig_frf_{name}.png", units=g["units"],
                              title=GROUP_TITLES.get(name, name))
        sec["figures"].append((png, f"{GROUP_TITLES.get(name, name)}: measured and fitted model "
                                    f"({g['method']}, quality {g['quality']:.3g}) from {fit['file']}"))
        if g["modes"]:
            keys = [k for k in g["modes"][0] if k != "freq_hz"]
            sec["html"].append(f"<h3>Modes ({rh._e(name)})</h3>")
            sec["html"].append(rh.table(["mode", "freq_hz"] + keys,
                                        [[i + 1, m["freq_hz"]] + [m.get(k) for k in keys]
                                         for i, m in enumerate(g["modes"])],
                                        num_cols=set(range(len(keys) + 2))))
            sec["html"].append(f'<p class="prov">from {rh._e(fit["file"])}, group {rh._e(name)}</p>')
    return sec


def _stab_section(out: Path, fit: dict | None) -> dict[str, Any]:
    title = "Stabilisation diagram"
    if fit is None:
        return _missing("stabilisation", title, "No fit given (--fit robot.fit.h5).")
    groups = {k: g for k, g in fit["groups"].items() if g.get("stabilisation")}
    if not groups:
        return _missing("stabilisation", title, f"{fit['file']} holds no stabilisation data.")
    sec: dict[str, Any] = {"id": "stabilisation", "title": title, "status": "ok", "html": [], "figures": []}
    for name, g in groups.items():
        png = figs.stabilisation_figure(g["stabilisation"], out / f"fig_stabilisation_{name}.png", g["locations"],
                                        title=f"stabilisation diagram: {name}")
        sec["figures"].append((png, f"poles by model order ({name}), from {fit['file']}"))
    return sec


# --------------------------------------------------------------------------- speed

def _sim_curves(sweeps: list[dict], band_k: float) -> list[dict[str, Any]]:
    curves = []
    for s in sweeps:
        sw = s["sweep"]
        if sw.quantity != "freq_hz":
            continue
        # measured speed is unsigned (the paper compares speed, not velocity: the robot turns),
        # the simulator's is signed along +y: compare magnitudes, draw by draw
        mean, lo, hi = compare.band_from_draws(np.abs(sw.speeds_mm_s), k=band_k)
        lo = np.maximum(lo, 0.0)                    # a speed magnitude's band stops at zero
        order = np.argsort(sw.values)
        curves.append({"file": s["file"], "label": Path(s["file"]).name, "freq_hz": sw.values[order],
                       "mean_mm_s": mean[order], "lo_mm_s": lo[order], "hi_mm_s": hi[order],
                       "nominal_mm_s": np.abs(sw.speeds_mm_s[:, 0])[order], "sweep": sw})
    return curves


def _speed_section(out: Path, shaker: list[dict], tracks: list[dict], sweeps: list[dict], band_k: float):
    title = "Speed against shaker frequency (paper Fig. 8)"
    measured = ri.measured_speeds(shaker, tracks) if (shaker or tracks) else None
    curves = _sim_curves(sweeps, band_k)
    have_meas = measured is not None and measured["freq_hz"].size > 0
    if not have_meas and not curves:
        return _missing("speed", title, "No measured speeds (--runs SHAKER_RUN.h5 / --tracks TRACK.h5) and no "
                        "simulated frequency sweep (--sim SWEEP.h5) given."), [], {}
    png = figs.speed_figure(measured if have_meas else None, curves, out / "fig_speed.png")
    sec = {"id": "speed", "title": title, "status": "ok", "html": [],
           "figures": [(png, f"measured speed with its confidence interval (by tray amplitude); simulated "
                             f"Monte Carlo mean with a +-{band_k:g} std band over draws")]}
    msgs = []
    if not have_meas:
        msgs.append("No measured speeds given: simulation only.")
    if measured is not None and measured["unmatched"]:
        msgs.append(f"Tracks with no known shaker frequency or no speed (left out): {', '.join(measured['unmatched'])}.")
    other = [f"{s['file']} (over {s['sweep'].quantity})" for s in sweeps if s["sweep"].quantity != "freq_hz"]
    if other:
        msgs.append(f"Sweeps not over freq_hz are not drawn here: {', '.join(other)}.")
    if not curves:
        msgs.append("No simulated frequency sweep (--sim SWEEP.h5): no model curve.")
    rows, numbers = [], {}
    if have_meas and curves:
        for c in curves:
            # compare only points measured at the sweep's tray amplitude (or of unknown amplitude)
            amp = float(c["sweep"].scenario.get("amp_um", np.nan))
            mask = ~np.isfinite(measured["amp_um"]) | ~np.isfinite(amp) | \
                (np.abs(measured["amp_um"] - amp) <= 0.1 * abs(amp))
            m = ri.select(measured, mask)
            if not m["freq_hz"].size:
                msgs.append(f"No measured point at the tray amplitude of {c['file']} ({amp:.3g} um).")
                continue
            p = {"measured": sorted(set(m["sources"])), "simulated": c["file"],
                 "draws": c["sweep"].draws, "band": f"mean +- {band_k:g} std (ddof=1) over draws, floored at 0",
                 "simulated_speed": "|mean forward velocity| of each draw",
                 "sim_duration_s": c["sweep"].meta.get("duration_s"), "sim_seed": c["sweep"].meta.get("seed"),
                 "uncertainty_table": c["sweep"].meta.get("uncertainty_table"),
                 "scenario": c["sweep"].scenario, "measured_amp_um_within": "10 % of the sweep's amp_um"}
            a = compare.speed_agreement(m["freq_hz"], m["speed_mm_s"], m["lo_mm_s"], m["hi_mm_s"], c["freq_hz"],
                                        c["mean_mm_s"], c["lo_mm_s"], c["hi_mm_s"], provenance=p)
            numbers[c["file"]] = a
            for q, k, u in (("speed RMS error", "rms_error_mm_s", "mm/s"),
                            ("speed bias (sim - meas)", "mean_error_mm_s", "mm/s"),
                            ("relative speed RMS error", "relative_rms_error", "1"),
                            ("speed correlation", "correlation", "1"),
                            ("fraction of measured points inside band", "fraction_inside_band", "1")):
                rows.append({"quantity": q, "value": a[k], "units": u, "n": a["n_points"], "provenance": p})
            # the nominal robot alone (draw 0): the Monte Carlo mean of speed magnitudes sits above it
            pn = dict(p, simulated_speed="|mean forward velocity| of the nominal robot (draw 0)", band="none")
            an = compare.speed_agreement(m["freq_hz"], m["speed_mm_s"], m["lo_mm_s"], m["hi_mm_s"], c["freq_hz"],
                                         c["nominal_mm_s"], c["nominal_mm_s"], c["nominal_mm_s"], provenance=pn)
            numbers[c["file"] + " (nominal)"] = an
            for q, k, u in (("speed RMS error (nominal robot)", "rms_error_mm_s", "mm/s"),
                            ("speed correlation (nominal robot)", "correlation", "1")):
                rows.append({"quantity": q, "value": an[k], "units": u, "n": an["n_points"], "provenance": pn})
            sec["html"].append(f"<h3>Measured against {rh._e(c['label'])} ({amp:.3g} um)</h3>")
            sec["html"].append(rh.table(
                ["freq_hz", "measured_mm_s", "CI lo", "CI hi", "simulated_mm_s", "band lo", "band hi", "inside band"],
                [[q["freq_hz"], q["measured_mm_s"], q["measured_lo_mm_s"], q["measured_hi_mm_s"],
                  q["simulated_mm_s"], q["band_lo_mm_s"], q["band_hi_mm_s"], q["inside_band"]] for q in a["points"]],
                num_cols=set(range(7))))
            rows += _sweep_pattern_rows(m, c)
    sec["message"] = " ".join(msgs)
    return sec, rows, numbers


def _sweep_pattern_rows(measured: dict[str, Any], c: dict[str, Any]) -> list[dict[str, Any]]:
    """Leg patterns of the measured points (labels in the run, or classified from knee records)
    against the sweep's dominant pattern at the nearest frequency (within 2 %)."""
    meas, sim, keys, files = [], [], [], []
    values = c["sweep"].values
    for fz, lab, src in zip(measured["freq_hz"], measured["patterns"], measured["sources"]):
        if lab not in compare.PATTERNS:
            continue
        i = int(np.argmin(np.abs(values - fz)))
        if abs(values[i] - fz) > 0.02 * fz:
            continue
        meas.append(lab)
        sim.append(c["sweep"].dominant_pattern(i))
        keys.append(float(fz))
        files.append(src)
    if not meas:
        return []
    a = compare.pattern_agreement(meas, sim, keys=keys,
                                  provenance={"measured": sorted(set(files)), "simulated": c["file"],
                                              "measured_label": "run file label, or classify_knee_pattern "
                                                                "on the point's knee record",
                                              "simulated_label": "dominant foot-contact pattern over draws "
                                                                 "and feet (a sweep keeps no knee records)"})
    return [{"quantity": "leg-pattern agreement (sweep)", "value": a["fraction_agree"], "units": "1",
             "n": a["n"], "provenance": a["provenance"]}]


# --------------------------------------------------------------------------- knee motion

def _sim_knee_task(task: tuple) -> dict[str, Any]:
    """Simulate one shaker drive and keep what the knee figure needs (module-level: picklable)."""
    from labkit.sim import Shaker, simulate

    params, freq_hz, amp_um, duration_s, seed = task
    r = simulate(params, Shaker(freq_hz=freq_hz, amp_um=amp_um), duration_s=duration_s, seed=seed)
    return {"t_s": np.asarray(r.t_s), "knee_vz_mm_s": np.asarray(r.knee_vz_mm_s),
            "ground_z_um": np.asarray(r.ground_z_um), "contact": np.asarray(r.contact),
            "patterns": [str(p) for p in r.patterns]}


def _knee_params(fit: str | None, params: str | None, sweeps: list[dict]) -> tuple[Any, str]:
    from labkit.sim import RobotParams

    if params:
        return RobotParams.from_toml(params), params
    if fit:
        sibling = Path(fit).with_name(Path(fit).name.replace(".fit.h5", ".toml"))
        if sibling.is_file() and sibling != Path(fit):
            return RobotParams.from_toml(sibling), str(sibling)
    if sweeps and sweeps[0]["sweep"].params_toml:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            p = Path(tmp) / "robot.toml"
            p.write_text(sweeps[0]["sweep"].params_toml)
            return RobotParams.from_toml(p), f"parameters of {sweeps[0]['file']}"
    return RobotParams(), "RobotParams() defaults (paper Tables 1-2)"


def _knee_section(out, shaker, results, sweeps, fit, params, knee_drives, simulate_knee, duration_s, leg,
                  scheduler, workers, quiet):
    title = "Knee vertical motion, measured against simulated (paper Fig. 10/11)"
    records = [dict(r, file=run["file"]) for run in shaker for r in run["knee"]]
    drives = list(knee_drives) if knee_drives else [(r["freq_hz"], r["tray_amp_um"]) for r in records][:4]
    drives += [(float(s["scenario"].get("freq_hz", np.nan)), float(s["scenario"].get("amp_um", np.nan)))
               for s in results if not any(_same_drive(d, s["scenario"]) for d in drives)]
    drives = [d for d in drives if np.isfinite(d[0])]
    if not drives:
        return _missing("knee", title, "No measured knee records (shaker run files with waveforms), no "
                        "sim_result files (--sim) and no --knee-drive given."), [], {}
    sims: dict[int, dict[str, Any]] = {}
    for i, d in enumerate(drives):
        hit = next((s for s in results if _same_drive(d, s["scenario"])), None)
        if hit is not None:
            sims[i] = dict(hit, source=hit["file"])
    todo = [i for i, d in enumerate(drives) if i not in sims and np.isfinite(d[1])]
    param_src = None
    if simulate_knee and todo:
        from labkit.executor import map_tasks

        p, param_src = _knee_params(fit, params, sweeps)
        outs = map_tasks(_sim_knee_task, [(p, drives[i][0], drives[i][1], duration_s, 0) for i in todo],
                         scheduler=scheduler, workers=workers, desc="knee sims", quiet=quiet)
        for i, o in zip(todo, outs):
            sims[i] = dict(o, source=f"simulate({param_src}, Shaker({drives[i][0]:g} Hz, {drives[i][1]:g} um), "
                                     f"duration_s={duration_s:g}, seed=0)")
    sec = {"id": "knee", "title": title, "status": "ok", "figures": [], "html": []}
    rows, numbers, table_rows, msgs = [], {}, [], []
    pat_meas, pat_sim, pat_keys, pat_files = [], [], [], []
    for i, (freq, amp) in enumerate(drives):
        meas = next((r for r in records if abs(r["freq_hz"] - freq) <= 0.01 * freq
                     and (not np.isfinite(amp) or not np.isfinite(r["tray_amp_um"])
                          or abs(r["tray_amp_um"] - amp) <= 0.1 * abs(amp) + 1e-9)), None)
        sim = sims.get(i)
        case: dict[str, Any] = {"freq_hz": freq, "tray_amp_um": amp}
        if meas is not None:
            meas = dict(meas, **compare.classify_knee_pattern(meas["t_s"], meas["knee_vz_mm_s"],
                                                              meas.get("tray_vz_mm_s"), freq))
            case["measured"] = meas
        if sim is not None:
            t = np.asarray(sim["t_s"])
            tray_v = np.gradient(np.asarray(sim["ground_z_um"]), t) * 1e-3        # um/s -> mm/s
            knee = np.asarray(sim["knee_vz_mm_s"])
            knee = knee[:, leg] if knee.ndim == 2 else knee
            pats = sim.get("patterns") or []
            # the settled second half of the run is what gets compared with the measured record
            settle = t >= t[0] + 0.5 * (t[-1] - t[0])
            # label the simulated knee record with the same classifier as the measured one: the
            # same observable on both sides (the simulator's own per-foot label is shown beside it)
            knee_label = compare.classify_knee_pattern(t[settle], knee[settle], tray_v[settle], freq)["pattern"]
            case["simulated"] = {"t_s": t, "knee_vz_mm_s": knee, "tray_vz_mm_s": tray_v, "contact": sim["contact"],
                                 "pattern": f"{knee_label} (foot contact: "
                                            f"{pats[leg] if len(pats) > leg else '?'})",
                                 "knee_pattern": knee_label, "foot_pattern": pats[leg] if len(pats) > leg else "?",
                                 "source": sim["source"]}
        png = figs.knee_figure(case, out / f"fig_knee_{i + 1}.png")
        sec["figures"].append((png, f"drive {freq:.4g} Hz, {amp:.3g} um: measured "
                                    f"{meas['file'] if meas else '(none)'}; simulated "
                                    f"{sim['source'] if sim else '(none)'}, leg {leg + 1}"))
        if meas is not None and sim is not None:
            s = case["simulated"]
            p = {"measured": meas["file"], "measured_point": meas["point"], "simulated": s["source"], "leg": leg + 1}
            a = compare.knee_motion_agreement(meas["t_s"], meas["knee_vz_mm_s"], t[settle], s["knee_vz_mm_s"][settle],
                                              freq, ref_meas=meas.get("tray_vz_mm_s"), ref_sim=tray_v[settle],
                                              provenance=p)
            numbers[f"{freq:.4g}Hz_{amp:.3g}um"] = a
            for q, k, u in (("knee amplitude ratio (sim/meas)", "amplitude_ratio", "1"),
                            ("knee phase difference (sim - meas)", "phase_diff_deg", "deg"),
                            ("knee waveform correlation", "correlation", "1")):
                rows.append({"quantity": f"{q} @ {freq:.4g} Hz, {amp:.3g} um", "value": a[k], "units": u, "n": 1,
                             "provenance": p})
            table_rows.append([freq, amp, a["amplitude_meas_mm_s"], a["amplitude_sim_mm_s"], a["phase_diff_deg"],
                               a["correlation"], meas.get("pattern", "?"), s["knee_pattern"], s["foot_pattern"]])
            if meas.get("pattern") in compare.PATTERNS:
                pat_meas.append(meas["pattern"])
                pat_sim.append(s["knee_pattern"])
                pat_keys.append(f"{freq:.4g} Hz, {amp:.3g} um")
                pat_files.append(meas["file"])
        elif meas is None:
            msgs.append(f"No measured knee record at {freq:.4g} Hz, {amp:.3g} um.")
        else:
            msgs.append(f"No simulation at {freq:.4g} Hz, {amp:.3g} um (give --sim SIM_RESULT.h5 or allow simulation).")
    if pat_meas:
        a = compare.pattern_agreement(pat_meas, pat_sim, keys=pat_keys,
                                      provenance={"measured": sorted(set(pat_files)),
                                                  "measured_label": "classify_knee_pattern on the knee record",
                                                  "simulated_label": f"classify_knee_pattern on leg {leg + 1}'s "
                                                                     "simulated knee record (settled half)",
                                                  "params": param_src})
        numbers["patterns"] = a
        rows.append({"quantity": "leg-pattern agreement (knee records)", "value": a["fraction_agree"], "units": "1",
                     "n": a["n"], "provenance": a["provenance"]})
    if table_rows:
        sec["html"].append(rh.table(["freq_hz", "tray_amp_um", "measured amp (mm/s)", "simulated amp (mm/s)",
                                     "phase diff (deg)", "correlation", "measured pattern (knee)",
                                     "simulated pattern (knee)", f"simulated foot contact (leg {leg + 1})"],
                                    table_rows, num_cols={0, 1, 2, 3, 4, 5}))
    if param_src:
        sec["html"].append(f'<p class="prov">simulated with {rh._e(param_src)}</p>')
    sec["message"] = " ".join(msgs)
    return sec, rows, numbers


def _same_drive(d: tuple[float, float], scenario: dict[str, Any]) -> bool:
    f, a = d
    sf, sa = float(scenario.get("freq_hz", np.nan)), float(scenario.get("amp_um", np.nan))
    return bool(abs(sf - f) <= 0.01 * abs(f) and (not np.isfinite(a) or abs(sa - a) <= 0.1 * abs(a) + 1e-9))


# --------------------------------------------------------------------------- agreement table

def _agreement_section(rows: list[dict[str, Any]]) -> dict[str, Any]:
    title = "Agreement between model and measurement"
    if not rows:
        return _missing("agreement", title, "Nothing to compare: needs measured and simulated data of the same "
                        "kind (speeds and a frequency sweep, or knee records and simulations).")
    table = rh.table(["quantity", "value", "units", "n", "provenance"],
                     [[r["quantity"], r["value"], r["units"], r["n"], rh.prov(r["provenance"])] for r in rows],
                     num_cols={1, 3})
    return {"id": "agreement", "title": title, "status": "ok", "figures": [],
            "html": [table, "<p>Every number is also in <code>agreement.json</code> beside this page.</p>"]}
