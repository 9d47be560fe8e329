"""Small input files in the layouts of interfaces.md, written by the report tests themselves.

Synthetic but physical: FRFs of a 3-mode system, a tray moving as A sin(2 pi f t),
knee records in firm contact or jumping, speeds falling with frequency.
"""
from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from labkit.h5io import put, stamp

MODES_HZ = (438.0, 1200.0, 1800.0)
ZETA = (0.25, 0.12, 0.13)


def modal_frf(f: np.ndarray, gains=(1.0, 0.5, 0.3)) -> np.ndarray:
    w = 2j * np.pi * f
    h = np.zeros_like(f, dtype=complex)
    for fn, z, g in zip(MODES_HZ, ZETA, gains):
        wn = 2 * np.pi * fn
        h += g * w * wn / (wn ** 2 + 2 * z * wn * w + w ** 2)
    return h


def write_inchip(path: Path) -> Path:
    f = np.linspace(200, 3000, 120)
    with h5py.File(path, "w") as h:
        stamp(h, "run_inchip")
        h.attrs.update(status="complete", method="stepped", config_toml="", started_utc="", ended_utc="")
        for loc, g in zip(("body", "hip", "knee"), ((0.3, 0.2, 0.1), (1.0, 0.3, 0.2), (0.2, 0.6, 1.0))):
            grp = h.create_group(f"locations/{loc}")
            put(grp, "freq_hz", f, "Hz")
            put(grp, "frf", modal_frf(f, g), "(mm/s)/V")
            put(grp, "quality", np.ones_like(f), "1")
    return path


def write_fit(path: Path) -> Path:
    """A modal_fit file in the layout of labkit.analysis.modal.io (groups inchip and shaker)."""
    f = np.linspace(200, 3000, 120)
    rng = np.random.default_rng(1)
    with h5py.File(path, "w") as h:
        stamp(h, "modal_fit")
        h.attrs["summary_json"] = json.dumps({"modes_hz": list(MODES_HZ)})
        for group, units in (("inchip", "(mm/s)/V"), ("shaker", "1")):
            g = h.create_group(f"groups/{group}")
            g.attrs.update(method="lscf+refine", frf_kind=group, quality=0.97)
            for loc in ("body", "hip", "knee"):
                lg = g.create_group(f"locations/{loc}")
                lg.attrs["name"] = loc
                model = modal_frf(f)
                put(lg, "freq_hz", f, "Hz")
                put(lg, "frf", model * (1 + 0.05 * rng.standard_normal(f.size)), units)
                put(lg, "model", model, units)
            m = g.create_group("modes")
            put(m, "freq_hz", np.array(MODES_HZ), "Hz")
            put(m, "freq_hz_std", np.array([3.0, 8.0, 12.0]), "Hz")
            put(m, "damping_ratio", np.array(ZETA), "1")
            put(m, "damping_ratio_std", np.array([0.01, 0.01, 0.02]), "1")
            put(m, "amplitude", np.ones((3, 3), complex), "x")
            m.create_dataset("dominant_location", data=["hip", "knee", "knee"], dtype=h5py.string_dtype())
            s = g.create_group("stabilisation")
            orders = np.repeat(np.arange(2, 12, 2), 3)
            put(s, "order", orders, "1")
            put(s, "freq_hz", np.tile(MODES_HZ, 5) * (1 + 0.01 * rng.standard_normal(15)), "Hz")
            put(s, "damping_ratio", np.tile(ZETA, 5), "1")
            put(s, "status", np.clip(orders // 3 - 1, 0, 2), "label")
            put(s, "chosen_hz", np.array(MODES_HZ), "Hz")
    return path


SHAKER_F = np.array([150.0, 200.0, 250.0, 300.0, 600.0])
SHAKER_SPEED = np.array([3.0, 4.2, 2.5, 2.9, 0.0])


def knee_record(freq_hz: float, amp_um: float, pattern: str, duration_s: float = 0.05, fs: float = 50e3):
    t = np.arange(0, duration_s, 1 / fs) + 0.00731                   # any start time
    tray_v = 2 * np.pi * freq_hz * amp_um * 1e-3 * np.cos(2 * np.pi * freq_hz * t)   # mm/s
    if pattern == "firm_contact":
        knee = 1.05 * tray_v
    else:                                                         # jumping: slow large excursions
        knee = tray_v + 6 * np.abs(tray_v).max() * np.sin(2 * np.pi * freq_hz / 3 * t)
    return t, knee, tray_v


def write_shaker(path: Path, videos: bool = True, knee: bool = True) -> Path:
    """A run_shaker file as labkit.experiments.runfile lays it out: a /points table (one
    interlocked point, left out by readers) and /records/p<index>/ velocity records."""
    freq = np.append(SHAKER_F, 350.0)
    status = ["ok"] * SHAKER_F.size + ["interlock"]
    with h5py.File(path, "w") as h:
        stamp(h, "run_shaker")
        h.attrs.update(status="complete", robot_spot="knee" if knee else "body", amplitude_kind="tray_amp_um")
        pts = h.create_group("points")
        put(pts, "freq_hz", freq, "Hz")
        put(pts, "tray_amp_um", np.where(np.array(status) == "ok", 25.0, np.nan), "um")
        put(pts, "tray_amp_request_um", np.full(freq.size, 25.0), "um")
        put(pts, "transmissibility", np.ones(freq.size, complex), "1")
        pts.create_dataset("status", data=status, dtype=h5py.string_dtype()).attrs["units"] = "label"
        names = [f"videos/p{i}.mp4" if videos and s == "ok" else "" for i, s in enumerate(status)]
        pts.create_dataset("video", data=names, dtype=h5py.string_dtype()).attrs["units"] = "path"
        put(pts, "index", np.arange(1, freq.size + 1), "1")
        if knee:
            for i, pat in ((1, "firm_contact"), (3, "jumping")):
                t, k, tr = knee_record(SHAKER_F[i], 25.0, pat)
                g = h.create_group(f"records/p{i + 1:05d}")
                g.attrs["dt_s"] = t[1] - t[0]
                put(g, "robot_velocity_mm_s", k.astype(np.float32), "mm/s")
                put(g, "tray_velocity_mm_s", tr.astype(np.float32), "mm/s")
    return path


def write_track(path: Path, speed: float, ci: tuple[float, float], video: str | None = None,
                freq_hz: float | None = None) -> Path:
    with h5py.File(path, "w") as h:
        stamp(h, "track")
        t = np.linspace(0, 2, 61)
        put(h, "t_s", t, "s")
        put(h, "x_mm", np.zeros_like(t), "mm")
        put(h, "y_mm", speed * t, "mm")
        put(h, "heading_rad", np.zeros_like(t), "rad")
        put(h, "quality", np.ones_like(t), "1")
        h.attrs["mean_speed_mm_s"] = speed
        h.attrs["speed_ci_mm_s"] = np.array(ci)
        h.attrs["mm_per_px"] = 0.01
        h.attrs["mm_per_px_std"] = 0.0001
        if video is not None:
            h.attrs["source_video"] = video      # as labkit.analysis.tracking.output writes it
        if freq_hz is not None:
            h.attrs["freq_hz"] = freq_hz
    return path


def write_sweep(path: Path) -> Path:
    from labkit.sim.sweep import SweepResult

    f = np.array([100.0, 150.0, 200.0, 250.0, 300.0, 400.0, 800.0])
    base = np.array([2.0, 3.5, 5.0, 3.0, 3.5, 0.5, 0.0])
    draws = base[:, None] * (1 + 0.1 * np.linspace(-1, 1, 5))[None, :]
    pats = np.full((7, 5, 6), "partial_contact", dtype=object)
    pats[1] = "firm_contact"
    SweepResult(quantity="freq_hz", values=f, speeds_mm_s=draws, contact_fraction=np.zeros((7, 5, 6, 3)),
                patterns=pats.astype(str), impacts=np.zeros((7, 5, 6), int),
                scenario={"type": "shaker", "freq_hz": 240.0, "amp_um": 25.0}, params_toml="",
                meta={"seed": 0, "duration_s": 1.0}).to_h5(path)
    return path


def write_sim_result(path: Path, freq_hz: float, amp_um: float, pattern: str) -> Path:
    """A sim_result in the layout SimResult.to_h5 writes (datasets at the root)."""
    t = np.arange(0, 0.06, 2e-5)
    zg = amp_um * np.sin(2 * np.pi * freq_hz * t)
    tray_v = 2 * np.pi * freq_hz * amp_um * 1e-3 * np.cos(2 * np.pi * freq_hz * t)
    if pattern == "firm_contact":
        knee1 = 1.1 * tray_v
    else:                            # jumping: large excursions repeating only every third period
        knee1 = tray_v + 6 * np.abs(tray_v).max() * np.sin(2 * np.pi * freq_hz / 3 * t)
    knee = np.repeat(knee1[:, None], 6, axis=1)
    contact = np.full((t.size, 6), 2 if pattern == "firm_contact" else 0, dtype=np.int8)
    with h5py.File(path, "w") as h:
        stamp(h, "sim_result")
        h.attrs["scenario_json"] = json.dumps({"type": "shaker", "freq_hz": freq_hz, "amp_um": amp_um})
        put(h, "t_s", t, "s")
        put(h, "ground_z_um", zg, "um")
        put(h, "knee_vz_mm_s", knee, "mm/s")
        put(h, "contact", contact, "label")
        h.attrs["patterns"] = json.dumps([pattern] * 6)
    return path


KNEE_DRIVES_HZ = (150.0, 170.0, 190.0, 210.0, 230.0, 250.0, 270.0, 290.0, 310.0)


def write_shaker_knees(path: Path, freqs_hz=KNEE_DRIVES_HZ, amp_um: float = 25.0) -> Path:
    """A knee-spot run_shaker file with a knee record at every one of ``freqs_hz`` (no video)."""
    freq = np.asarray(freqs_hz, float)
    with h5py.File(path, "w") as h:
        stamp(h, "run_shaker")
        h.attrs.update(status="complete", robot_spot="knee", amplitude_kind="tray_amp_um")
        pts = h.create_group("points")
        put(pts, "freq_hz", freq, "Hz")
        put(pts, "tray_amp_um", np.full(freq.size, amp_um), "um")
        pts.create_dataset("status", data=["ok"] * freq.size, dtype=h5py.string_dtype()).attrs["units"] = "label"
        put(pts, "index", np.arange(1, freq.size + 1), "1")
        for i, f in enumerate(freq):
            t, k, tr = knee_record(f, amp_um, "firm_contact")
            g = h.create_group(f"records/p{i + 1:05d}")
            g.attrs["dt_s"] = t[1] - t[0]
            put(g, "robot_velocity_mm_s", k.astype(np.float32), "mm/s")
            put(g, "tray_velocity_mm_s", tr.astype(np.float32), "mm/s")
    return path


def write_real_fit(path: Path, lines: int = 60):
    """A modal_fit file written by labkit's own fit (fit_modes + write_fit_h5) on the FRFs of a
    two-mode structure whose body location has an anti-resonance between the modes, measured on
    a grid too coarse to resolve it. Returns ``(path, fit)``."""
    from labkit.analysis.modal.fit import fit_modes
    from labkit.analysis.modal.io import write_fit_h5
    from labkit.analysis.modal.synth import synthetic_frf

    f = np.geomspace(200.0, 3000.0, lines)
    wn = 2 * np.pi * np.array([450.0, 1500.0])
    # body: residues of the same sign -> a zero between the modes; hip: opposite signs -> none
    shapes = np.array([[1.0, 1.0], [1.0, -0.6]]) * wn[None, :] ** 2
    h = synthetic_frf(f, [450.0, 1500.0], [0.03, 0.02], shapes, noise=0.002, seed=3)
    fit = fit_modes(f, {"body": h[0], "hip": h[1]}, n_modes=2, kind="mobility")
    write_fit_h5(path, {"inchip": fit}, {"inchip": []}, {}, {"inchip": fit.summary()})
    return path, fit
