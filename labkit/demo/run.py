"""``labkit demo``: the whole toolkit on the virtual lab, in one call.

Stages (each one an ordinary labkit step, called in-process through its
Python API or its command module, writing ordinary files):

1. in-chip pilot sweep: a coarse log grid at body, hip and knee of the
   tethered robot, only to see where the peaks are;
2. in-chip sweep: the pilot's grid plus lines across every peak it showed
   (a lightly damped mode is narrower than a log grid's spacing);
3. resonance fit of that run -> robot parameter file. The fitted mode
   whose response is largest at the hip (the tethered hip mode) is assigned
   explicitly to the simulator's mode 1 (lateral, hip) with ``--assign``;
   modes 2 and 3 are the *released* robot's vertical modes, which an in-chip
   sweep cannot see (the tethered robot has a tether mode and an in-chip knee
   mode instead, model.md section 9), so they keep the base values;
4. shaker run of the released robot over a frequency grid, a video per point;
5. tracking of every video -> speed with a confidence interval;
6. simulated frequency sweep with the fitted parameters, Monte Carlo draws
   over the parameters' uncertainty -> speed band;
7. report (HTML + PNG) of model against measurement.

The virtual robot
-----------------
The paper's robot (``RobotParams()``) with two changes, both stated in the
outputs: adhesion at first contact ``c_ad_n = 50 nN`` instead of 50 uN (with
the published value the feet never leave the tray and the robot does not walk;
model.md section 2 calls that magnitude the least certain), and a hip mode at
452 Hz (damping ratio 0.22) instead of 438 Hz (0.25), so that the fit has
something to find. The demo's *base* parameter file (the prior for everything
an in-chip sweep cannot measure) is the paper's robot with the same adhesion
and the paper's modes: the pipeline never reads the virtual robot's modes;
they appear only in the final comparison (``lab.truth``).

Why not the bundled ``paper`` set (``RobotParams.preset("paper")``, calibrated
to the paper's observations)? At the demo's drives it is not robust: at 240 Hz /
25 um the nominal robot walks at 2.2 mm/s but three robots drawn from the Monte
Carlo table average 15 mm/s (``python bench/paper_table.py``), and at 280 Hz
the nominal robot does not move (0.00 mm/s over 4 seeds, 2 s), so a
tracked speed and one simulation of the fitted robot (whose identified modes
differ slightly) would compare a speed with its own spread or with nothing,
not the chain the demo shows and its tests check. With 50 nN the robot walks
periodically and the chain's agreement is a test of the chain.

Both robots stand on 100 um foot pads (``foot_pad_um``, a choice the paper
does not fix; the default is 30 um, docs/model.md M7): the pads' films hold
the lifted feet and the walk is periodic, the same for every seed (9.27, 22.0,
33.6 mm/s at 200, 240, 280 Hz / 25 um). On 30 um pads the feet fly and the walk
is chaotic: seeds spread by ~1 mm/s, more than a 20 % change of the modal
participation moves it, and calibrating that participation from the tracked
speeds returned noise.
"""
from __future__ import annotations

import contextlib
import json
import shutil
import sys
import time
from collections.abc import Iterator, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from labkit.errors import InputError

if TYPE_CHECKING:
    from labkit.analysis.modal.robot import FitFiles, FitSummary
    from labkit.analysis.report.build import ReportSummary
    from labkit.demo.results import AssignmentNote, DemoFiles, DemoSummary, ShakerPoint
    from labkit.experiments.session import SessionSummary

MARKER = ".labkit-demo"

#: the virtual robot's hip mode (the rest of its modes are the paper's)
TRUE_HIP_HZ = 452.0
TRUE_HIP_DAMPING = 0.22
#: adhesion at first contact of both the virtual robot and the base file (N)
DEMO_C_AD_N = 50e-9
#: foot pads of both (um): their films hold the lifted feet, and the walk is periodic
DEMO_FOOT_PAD_UM = 100.0


@dataclass(frozen=True)
class DemoSettings:
    """How much the demo measures and simulates."""

    name: str
    coarse_start_hz: float
    coarse_stop_hz: float
    coarse_count: int
    refine_spacing_rel: float
    pilot_settle_s: float
    pilot_dwell_cycles: float
    settle_s: float
    dwell_cycles: float
    shaker_freqs_hz: tuple[float, ...]
    tray_amp_um: float
    video_s: float
    shaker_settle_s: float
    shaker_dwell_cycles: float
    sim_freqs_hz: tuple[float, ...]
    sim_draws: int
    sim_duration_s: float
    knee_duration_s: float


FULL = DemoSettings(
    name="full", coarse_start_hz=250.0, coarse_stop_hz=5000.0, coarse_count=40, refine_spacing_rel=0.01,
    pilot_settle_s=0.03, pilot_dwell_cycles=10, settle_s=0.05, dwell_cycles=20,
    # the paper's band (Fig. 8). The clip is short because the virtual robot walks at 20-35 mm/s
    # at 240-290 Hz (the model with the new contact physics, ~8x the paper's robot; docs/simulator.md):
    # in 0.5 s it crosses ~17 mm of the camera's 24 mm field, so it stays in view.
    shaker_freqs_hz=(150.0, 170.0, 190.0, 210.0, 230.0, 240.0, 250.0, 270.0, 290.0), tray_amp_um=25.0,
    video_s=0.5, shaker_settle_s=0.1, shaker_dwell_cycles=20,
    sim_freqs_hz=tuple(float(f) for f in np.arange(150.0, 300.0, 10.0)),
    sim_draws=20, sim_duration_s=2.0, knee_duration_s=0.2)

QUICK = DemoSettings(
    name="quick", coarse_start_hz=250.0, coarse_stop_hz=5000.0, coarse_count=24, refine_spacing_rel=0.015,
    pilot_settle_s=0.03, pilot_dwell_cycles=8, settle_s=0.03, dwell_cycles=10,
    shaker_freqs_hz=(200.0, 240.0, 280.0), tray_amp_um=25.0, video_s=0.5,
    shaker_settle_s=0.05, shaker_dwell_cycles=10,
    sim_freqs_hz=(200.0, 240.0, 280.0), sim_draws=4, sim_duration_s=0.6, knee_duration_s=0.1)


def demo_robots() -> tuple[Any, Any]:
    """``(virtual robot, base parameters)``: see the module docstring."""
    from labkit.sim import RobotParams

    paper = RobotParams()
    base = paper.replace(c_ad_n=DEMO_C_AD_N, foot_pad_um=DEMO_FOOT_PAD_UM)
    f = list(paper.modal_freq_hz)
    z = list(paper.modal_damping_ratio)
    f[0], z[0] = TRUE_HIP_HZ, TRUE_HIP_DAMPING
    return base.with_modes(freq_hz=tuple(f), damping_ratio=tuple(z)), base


# ----------------------------------------------------------------------------- plumbing

class Stages:
    """One line per stage on standard error: what starts, then how long it took."""

    def __init__(self, total: int, *, quiet: bool = False, stream: Any = None) -> None:
        self.total = total
        self.quiet = quiet
        self.stream = stream if stream is not None else sys.stderr
        self.k = 0
        self.times_s: dict[str, float] = {}
        self.t0 = time.perf_counter()

    @contextlib.contextmanager
    def stage(self, key: str, text: str) -> Iterator[None]:
        self.k += 1
        self._say(f"[{self.k}/{self.total}] {text} ...")
        t = time.perf_counter()
        yield
        self.times_s[key] = round(time.perf_counter() - t, 2)
        self._say(f"[{self.k}/{self.total}] done in {self.times_s[key]:.1f} s "
                  f"(total {time.perf_counter() - self.t0:.0f} s)")

    def say(self, text: str) -> None:
        """One line on standard error (not with ``quiet``)."""
        self._say(text)

    def _say(self, text: str) -> None:
        if not self.quiet:
            print(f"labkit demo: {text}", file=self.stream, flush=True)


def prepare_out(out: Path, force: bool) -> Path | None:
    """Create the output folder; an existing non-empty one only with ``force`` and only if a demo made it.

    With ``force`` the earlier demo's folder is moved aside (returned) rather than deleted, so a
    demo that fails leaves it in place (:func:`run_demo` moves it back, or deletes it at the end).
    """
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a folder", file=out, key="--out")
    if not out.resolve().parent.is_dir():       # the output policy (labkit.outputs): no parents made
        raise InputError("the folder that would hold it does not exist (labkit creates only the output "
                         "folder itself)", file=out, key="--out", expected=f"an existing folder {out.resolve().parent}")
    if out.is_dir() and any(out.iterdir()):
        if not force:
            raise InputError("folder exists and is not empty", file=out, key="--out",
                             expected="a new folder, or --force to replace an earlier demo's output")
        if not (out / MARKER).is_file():
            raise InputError("--force replaces only a folder an earlier `labkit demo` wrote (it has no "
                             f"{MARKER} file)", file=out, key="--out", expected="a new folder")
        import tempfile

        backup = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.resolve().parent))
        out.replace(backup / out.name)
        out.mkdir()
        (out / MARKER).write_text("written by `labkit demo`; `labkit demo --force` may delete this folder\n")
        return backup
    out.mkdir(exist_ok=True)
    (out / MARKER).write_text("written by `labkit demo`; `labkit demo --force` may delete this folder\n")
    return None


# ----------------------------------------------------------------------------- the demo

def run_demo(out: str | Path = "labkit-demo", *, quick: bool = False, seed: int = 0, quiet: bool = False,
             force: bool = False, settings: DemoSettings | None = None,
             stream: Any = None) -> DemoSummary:
    """Run the demo (:func:`_run_demo`) into ``out``; with ``force`` an earlier demo's folder is
    replaced only when the new one is complete (a failed demo puts the old folder back)."""
    out = Path(out)
    backup = prepare_out(out, force)
    from labkit.experiments.live import no_console_rows

    try:
        with no_console_rows():         # the demo prints its own stages, not every run's points
            summary = _run_demo(out, quick=quick, seed=seed, quiet=quiet, settings=settings, stream=stream)
    except BaseException:
        if backup is not None:
            shutil.rmtree(out, ignore_errors=True)
            (backup / out.name).replace(out)
            shutil.rmtree(backup, ignore_errors=True)
        raise
    if backup is not None:
        shutil.rmtree(backup, ignore_errors=True)
    return summary


@dataclass(frozen=True)
class _Run:
    """What every stage of one demo shares: where it writes, how much it does, how it reports."""

    out: Path
    settings: DemoSettings
    stages: Stages
    quiet: bool
    seed: int


@dataclass(frozen=True)
class DemoFit:
    """:func:`fit_and_assign`'s result: the files written, the fit's summary and how modes were assigned."""

    files: FitFiles
    summary: FitSummary
    assignment_note: AssignmentNote


def _run_demo(out: Path, *, quick: bool = False, seed: int = 0, quiet: bool = False,
              settings: DemoSettings | None = None, stream: Any = None) -> DemoSummary:
    """Run every stage on a fresh in-process virtual lab; return the summary (also in ``demo_summary.json``).

    Parameters
    ----------
    out:
        Output folder (created; see :func:`prepare_out`).
    quick:
        Fewer points and shorter records (:data:`QUICK`), for tests.
    seed:
        The virtual lab's noise seed and the Monte Carlo seed.
    quiet:
        No stage lines and no progress bars on standard error.
    settings:
        Overrides ``quick``.
    """
    from labkit.lab import VirtualLab

    s = settings or (QUICK if quick else FULL)
    t_start = time.perf_counter()
    st = Stages(7, quiet=quiet, stream=stream)
    run = _Run(out, s, st, quiet, seed)
    for sub in ("configs", "runs", "tracks", "sim"):
        (out / sub).mkdir(exist_ok=True)
    truth_robot, base = demo_robots()
    files: DemoFiles = _write_robots(out, truth_robot, base, st)
    base_file = Path(files["base_robot"])
    notes: list[str] = []

    with VirtualLab(robot=truth_robot, seed=seed) as lab:
        truth = lab.truth
        fit, shaker = _measure(lab, run, base_file, files, notes)
    files["configs"] = sorted(str(p) for p in (out / "configs").glob("*.toml"))

    points = _track_videos(run, shaker, notes)
    tracks = [p["track"] for p in points if p.get("track")]
    files["tracks"] = tracks
    files["videos"] = [str(shaker.parent / p["video"]) for p in points if p["video"]]

    sw, sim_path = _simulate(run, fit)
    files["sim_sweep"] = str(sim_path)
    with st.stage("report", "report: model against measurement"):
        rep = _report(run, files, fit, tracks, sim_path)
    files.update({"report_html": rep["html"], "report_figures": rep["figures"],
                  "agreement_json": rep["agreement_json"]})

    from labkit.demo.results import compare_resonances, compare_speeds, finite, headline, simulator_modes

    resonances = compare_resonances(truth["tethered_modes"], fit.summary["fitted_modes"])
    speeds = compare_speeds(points, sw)
    summary: DemoSummary = {
        "ok": True, "out_dir": str(out), "mode": s.name, "seed": seed,
        "headline": headline(resonances, speeds, rep.get("speed_rms_error_mm_s")),
        "wall_s": round(time.perf_counter() - t_start, 1), "stage_s": st.times_s,
        "files": files,
        "resonances": resonances,
        "simulator_modes": simulator_modes(fit.summary, truth_robot, base),
        "assignment": fit.assignment_note,
        "speeds": speeds,
        "speed_rms_error_mm_s": rep.get("speed_rms_error_mm_s"),
        "report_sections": rep.get("sections", {}),
        "virtual_robot": {"changes_from_paper": {"c_ad_n": DEMO_C_AD_N, "foot_pad_um": DEMO_FOOT_PAD_UM,
                                                 "hip_freq_hz": TRUE_HIP_HZ,
                                                 "hip_damping_ratio": TRUE_HIP_DAMPING}},
        "settings": asdict(s),
        "fit_warnings": fit.summary.get("warnings", []),
        "notes": notes,
    }
    files["summary_json"] = str(out / "demo_summary.json")
    (out / "demo_summary.json").write_text(json.dumps(finite(summary), indent=1) + "\n")
    return summary


def _write_robots(out: Path, truth_robot: Any, base: Any, st: Stages) -> DemoFiles:
    """Write the virtual robot (the truth) and the base parameters; their paths."""
    st.say(f"parameter set: demo (the published Tables 1-2 with c_ad_n = {DEMO_C_AD_N:g} N and a "
           f"{TRUE_HIP_HZ:g} Hz hip: the virtual robot; the `paper` set is not robust at the demo's drives)")
    truth_file = truth_robot.to_toml(out / "virtual_robot.toml", provenance={
        "source": "labkit demo: the virtual lab's robot (the truth; the pipeline never reads this file)",
        "changes_from_paper": f"c_ad_n = {DEMO_C_AD_N:g} N (walks), {DEMO_FOOT_PAD_UM:g} um foot pads; "
                              f"hip mode {TRUE_HIP_HZ:g} Hz, damping ratio {TRUE_HIP_DAMPING:g}"})
    base_file = base.to_toml(out / "base_robot.toml", provenance={
        "source": "labkit demo: prior for what an in-chip sweep cannot measure",
        "changes_from_paper": f"c_ad_n = {DEMO_C_AD_N:g} N (the walking robot), {DEMO_FOOT_PAD_UM:g} um foot pads; "
                              "modes are the paper's"})
    return {"virtual_robot": str(truth_file), "base_robot": str(base_file)}


def _measure(lab: Any, run: _Run, base_file: Path, files: DemoFiles, notes: list[str]) -> tuple[DemoFit, Path]:
    """Stages 1-4 on ``lab``: the in-chip pilot and sweep, the fit, the shaker run; ``(fit, shaker run)``."""
    from labkit.demo.configs import coarse_grid, write_shaker_config
    from labkit.experiments.session import run_session

    out, s, st, quiet, seed = run.out, run.settings, run.stages, run.quiet, run.seed
    # 1. pilot: a coarse log grid, only to see where the peaks are
    grid = coarse_grid(s.coarse_start_hz, s.coarse_stop_hz, s.coarse_count)
    pilot = out / "runs" / "inchip_pilot.h5"
    with st.stage("inchip_pilot", f"in-chip pilot sweep: {len(grid)} lines "
                                  f"{s.coarse_start_hz:g}-{s.coarse_stop_hz:g} Hz x body, hip, knee"):
        inchip_run(lab, out / "configs" / "inchip_pilot.toml", pilot, grid, settle_s=s.pilot_settle_s,
                   dwell_cycles=s.pilot_dwell_cycles, note="pilot: coarse log grid", quiet=quiet, seed=seed)
    # 2. the measurement: the pilot's grid plus lines across every peak it showed
    lines, extra, peaks = refined_grid(pilot, grid, s.refine_spacing_rel)
    if not len(extra):
        notes.append("the pilot sweep showed no peak: the measurement repeats its grid")
    inchip = out / "runs" / "inchip.h5"
    with st.stage("inchip", f"in-chip sweep: {len(lines)} lines, {len(extra)} of them across the peaks at "
                            + (", ".join(f"{p:.0f}" for p in peaks) or "-") + " Hz"):
        inchip_run(lab, out / "configs" / "inchip.toml", inchip, lines, settle_s=s.settle_s,
                   dwell_cycles=s.dwell_cycles, note="the pilot's grid plus lines across its peaks",
                   quiet=quiet, seed=seed)
    inchip_runs = [str(inchip)]
    files["inchip_pilot"] = str(pilot)
    # 3. fit, with the hip mode assigned explicitly to simulator mode 1
    with st.stage("fit", "resonance fit of the in-chip run -> robot parameter file"):
        fit = fit_and_assign(inchip_runs, out / "robot.toml", base_file, notes)
    files.update({"robot_params": fit.files["out"], "fit_file": fit.files["fit_file"],
                  "fit_figures": fit.files["figures"], "inchip_runs": inchip_runs})
    # 4. shaker run with video
    with st.stage("shaker", f"shaker run: {len(s.shaker_freqs_hz)} frequencies at {s.tray_amp_um:g} um, "
                            f"{s.video_s:g} s of video each"):
        cfg = write_shaker_config(out / "configs" / "shaker.toml", s.shaker_freqs_hz, s.tray_amp_um,
                                  video_s=s.video_s, settle_s=s.shaker_settle_s,
                                  dwell_cycles=s.shaker_dwell_cycles)
        shaker = out / "runs" / "shaker.h5"
        _check_run(run_session("shaker", cfg, shaker, lab=lab, quiet=quiet, seed=seed), shaker)
    files["shaker_run"] = str(shaker)
    return fit, shaker


def _track_videos(run: _Run, shaker: Path, notes: list[str]) -> list[ShakerPoint]:
    """Stage 5: track every video of the shaker run; its good points with their tracked speeds."""
    from labkit.analysis.tracking import Scale, track_file

    out, st = run.out, run.stages
    points = shaker_points(shaker)
    with st.stage("track", f"tracking {sum(1 for p in points if p['video'])} videos"):
        # Each video is scaled by the robot's length in it (a slow or still robot included: the
        # tracker tells it from dust by its motion or its outline). A video that still fails is
        # tracked again with the scale the other videos of the same run found (one camera, one
        # zoom), as a user at the bench would calibrate once per session, and noted if it fails again.
        scales: list[tuple[float, float]] = []
        unscaled: list[tuple[ShakerPoint, Path, Path, InputError]] = []
        for p in points:
            if not p["video"]:
                continue
            video = (shaker.parent / p["video"]).resolve()     # absolute: the track names its video
            track_path = out / "tracks" / f"{video.stem}.h5"
            try:
                summ = track_file(video, out=track_path, quiet=True).summary
            except InputError as exc:
                unscaled.append((p, video, track_path, exc))
                continue
            scales.append((float(summ["mm_per_px"]), float(summ["mm_per_px_std"])))
            _record_track(p, track_path, summ)
        if unscaled and not scales:
            raise unscaled[0][3]
        if unscaled:
            mm = np.array([m for m, _ in scales])
            run_scale = Scale(float(np.mean(mm)), float(max(np.std(mm), np.mean([d for _, d in scales]))),
                              "other videos of the run", {"videos": len(scales)})
            for p, video, track_path, _exc in unscaled:
                try:
                    summ = track_file(video, out=track_path, quiet=True, scale=run_scale).summary
                except InputError as exc:
                    # a robot that never moved is set aside like dust: no track, and the point is left
                    # out of the speed comparison (its video and run point stay)
                    notes.append(f"{video.name}: not tracked, the robot did not move in it ({exc.message})")
                    continue
                _record_track(p, track_path, summ)
                notes.append(f"{video.name}: scaled by the other videos of the run "
                             f"({run_scale.mm_per_px:.5f} mm/px; the robot did not walk enough to measure it)")
    return points


def _simulate(run: _Run, fit: DemoFit) -> tuple[Any, Path]:
    """Stage 6: the simulated sweep with the fitted parameters; ``(sweep, its file)``."""
    from labkit.sim import RobotParams, Shaker, sweep

    s = run.settings
    fitted = RobotParams.from_toml(fit.files["out"])
    sim_freqs = sorted(set(s.sim_freqs_hz) | set(s.shaker_freqs_hz))
    with run.stages.stage("simulate", f"simulated sweep: {len(sim_freqs)} frequencies x {s.sim_draws} Monte Carlo "
                                      f"draws x {s.sim_duration_s:g} s"):
        sw = sweep(fitted, Shaker(freq_hz=sim_freqs[0], amp_um=s.tray_amp_um), "freq_hz", sim_freqs,
                   draws=s.sim_draws, duration_s=s.sim_duration_s, seed=run.seed, quiet=run.quiet)
        sim_path = sw.to_h5(run.out / "sim" / "sim_sweep.h5")
    return sw, sim_path


def _report(run: _Run, files: DemoFiles, fit: DemoFit, tracks: list[str], sim_path: Path) -> ReportSummary:
    """Stage 7: the report of model against measurement."""
    from labkit.analysis.report.build import build_report

    return build_report(run.out / "report", runs=[*files["inchip_runs"], files["shaker_run"]], tracks=tracks,
                        fit=fit.files["fit_file"], sims=[str(sim_path)], params=fit.files["out"],
                        knee_duration_s=run.settings.knee_duration_s, title="labkit demo: virtual lab", quiet=True)


def inchip_run(lab: Any, cfg_path: Path, run_path: Path, freqs_hz: Any, *, note: str, quiet: bool, seed: int,
               settle_s: float | None = None, dwell_cycles: float | None = None,
               base: dict | None = None, header: str | None = None) -> Path:
    """Write an in-chip config over ``freqs_hz`` and run it on ``lab``; the run must complete."""
    from labkit.demo.configs import write_inchip_config
    from labkit.experiments.session import run_session

    cfg = write_inchip_config(cfg_path, freqs_hz, settle_s=settle_s, dwell_cycles=dwell_cycles, note=note,
                              base=base, header=header)
    _check_run(run_session("inchip", cfg, run_path, lab=lab, quiet=quiet, seed=seed), run_path)
    return run_path


def refined_grid(pilot: Path, grid: Any, spacing_rel: float) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """``(lines, extra, peaks_hz)``: the pilot's grid plus fine lines across its narrow peaks."""
    from labkit.analysis.modal.io import read_run
    from labkit.demo.configs import refine_lines

    rp = read_run(pilot)
    extra, peaks = refine_lines(rp.freq_hz[0], [np.abs(h) for h in rp.frf], spacing_rel)
    return np.union1d(np.round(np.asarray(grid, float), 3), extra), extra, peaks


def _check_run(summary: SessionSummary, path: Path) -> None:
    if summary.get("status") != "complete" or summary.get("points_ok") != summary.get("points_planned"):
        raise InputError(f"the run did not complete cleanly: {summary.get('status')}, "
                         f"{summary.get('points_ok')} of {summary.get('points_planned')} points",
                         file=path)


def fit_and_assign(runs: list[str], out: Path, base_file: Path, notes: list[str], *,
                   figures: bool = True) -> DemoFit:
    """Fit the in-chip runs, then assign the tethered hip mode to simulator mode 1 and write.

    :func:`labkit.analysis.modal.fit_robot` fits once with ``assign="none"``
    and lists the fitted modes with the location where each responds most;
    the lowest hip-dominant mode is the tethered hip mode. The same fits are
    then re-assigned explicitly, ``1=#K,2=keep,3=keep`` (no refit), which the
    parameter file's ``[provenance]`` records. Returns the files written, what
    ``labkit fit --json`` prints of the fit, and how the modes were assigned.
    """
    from labkit.analysis.modal import fit_robot

    probe = fit_robot(runs, base=base_file, assign="none")
    modes = probe.listing
    hip = [m for m in modes if str(m["dominant_location"]).split(":")[-1] == "hip"]
    if hip:
        chosen = min(hip, key=lambda m: m["freq_hz"])
        why = "the lowest fitted mode whose response is largest at the hip"
    elif modes:
        chosen = min(modes, key=lambda m: m["freq_hz"])
        why = "no mode is largest at the hip: the lowest fitted mode (the hip mode is the robot's first)"
        notes.append(why)
    else:
        raise InputError("the fit found no mode", file=", ".join(runs))
    spec = f"1=#{chosen['index']},2=keep,3=keep"
    rf = probe.reassign(spec)
    written = rf.write(out, figures=figures)
    return DemoFit(written, rf.summary(), {
        "assign": spec, "why": why,
        "mode_1": f"fitted #{chosen['index']} ({chosen['freq_hz']:.1f} Hz, tethered hip mode) -> simulator "
                  "mode 1 (lateral, hip)",
        "modes_2_3": "kept from the base file: the released robot's vertical modes cannot be measured in-chip "
                     "(the tethered robot shows a tether mode and an in-chip knee mode instead)",
        "recorded_in": str(out) + " [provenance] assignment_rule / assignment"})


def _record_track(p: ShakerPoint, track_path: Path, summ: Mapping[str, Any]) -> None:
    """Put a track's headline numbers (``summ``: the tracker's summary) on its shaker point."""
    p.update({"track": str(track_path), "speed_mm_s": float(summ["mean_speed_mm_s"]),
              "speed_ci_mm_s": [float(v) for v in summ["speed_ci_mm_s"]],
              "frames": int(summ["frames"]), "lost_frames": int(summ["lost_frames"]),
              "degraded_frames": int(summ.get("degraded_frames", 0))})


def shaker_points(path: Path) -> list[ShakerPoint]:
    """The shaker run's ok points: frequency, measured tray amplitude, video (relative to the run file)."""
    from labkit.files.runs import ShakerRun, read_run_file

    run = read_run_file(path)
    if not isinstance(run, ShakerRun):
        raise InputError(f"this file holds {run.kind!r}", file=path, key="kind", expected="a 'run_shaker' file")
    pts, ok = run.points, run.ok
    video = pts["video"] if "video" in pts else [""] * ok.size
    return [{"index": int(pts["index"][k]), "freq_hz": float(pts["freq_hz"][k]),
             "tray_amp_um": float(pts["tray_amp_um"][k]), "video": str(video[k])} for k in np.flatnonzero(ok)]
