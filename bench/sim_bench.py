"""Speed of the bundled simulator; prints ONE JSON object.

    python bench/sim_bench.py [--quick]

Measures (wall clock, and CPU time of this process where it is the better
number on a shared machine):

* microseconds per step of the numba kernel (CPU, a 1 s run) and, on the same
  stretch of the same run (its first 0.05 s), of the plain-Python reference and
  the kernel, each timed around its integration, and their ratio there (target >= 300;
  ``ratio_whole_runs``: the same with each run's set-up, the same Python for both, included);
* wall time to simulate 1 s of robot motion (kernel, warm);
* JIT cost: the first ``simulate`` call in a fresh process with an empty
  numba cache (cold: compiles) and in a second fresh process (warm: loads the
  cache, ``cache=True``);
* the wall time of the Fig. 8 sweep, 40 shaker frequencies 150..2000 Hz x 10 draws
  x 2 s with the sweep's error control, both cores (target <= 40 s), twice:
  ``sweep`` as the paper ran it (the default ``paper`` set, 25 um at 240 Hz on a
  5.8 g acceleration envelope: the shaker's amplitude falls as 1/f^2 above 240 Hz,
  paper Sec. 5.1) and ``sweep_walking_25um`` on the walking robot below at a
  constant 25 um (400 g at 2 kHz: its feet fly and land at every point, the
  expensive case); ``--quick`` runs smaller sweeps and says so; their CPU seconds as
  the pool's two workers used them (``cpu_s_workers``, from /proc: on a shared
  machine the wall time also measures the others), and every run's status
  (``status_counts``);
* per run at a few of the walking sweep's frequencies (``profile_nominal_unchecked``): steps,
  trial steps (every advance of the scheme: accepted, refused, event location), refused
  sub-steps (``refused_substeps``; of them ``refused_transient`` for a film transient, the
  rest for a film's gap ratio), event-location and other trial steps, CPU seconds; and the
  same runs checked (``profile_nominal_checked``): status, halvings, the runs the check made
  (``reruns``: at finer steps and the chaos probes; ``rerun_steps_over_run``: their steps
  over the run's own) and CPU seconds.

Cost of the scheme (issue 10): one implicit-midpoint step of the 23-coordinate
coupled system is M v0 and a solve with S = 2M + hD + h^2/2 K (through the
body's cached 5 x 5 Schur complement for the step or one of its halvings: the
legs' block is diagonal), a small solve for the contact and film rows (further
passes for the films' mean coefficient only where it matters), an impulse
through the pinned and stiff film rows, and
the instantaneous contact forces for located releases (the inverses of
R^T M^-1 R over a row set are cached, as the sets change only at events);
``kernel_us_per_step`` reports it, ``trial_steps_per_step`` the partial
steps of event location and the refused sub-steps on top, and
``cost_breakdown_us`` the parts (a full and a partial step, the contact forces,
a whole step with its checks) on a pinned and a flying robot, called as the kernel
calls them: the step's arrays as plain pointers (``labkit.sim._jit.pointer``; numba's
array arguments cost a reference count and seven words per call, and a negative-index
check per access).

The scenario is the walking robot (240 Hz, 25 um, c_ad_n = 50 nN): feet in
the air and impacts every cycle, the expensive case. With the published
adhesion (50 uN) the feet never leave and steps are cheaper.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

WALK = dict(c_ad_n=50e-9)

_CHILD = r"""
import time, json
t0 = time.perf_counter()
from labkit.sim import RobotParams, Shaker, simulate
t1 = time.perf_counter()
simulate(RobotParams(c_ad_n=50e-9), Shaker(240, 25), duration_s=0.002)
t2 = time.perf_counter()
print(json.dumps({"import_s": t1 - t0, "first_call_s": t2 - t1}))
"""


def _child_first_call(cache_dir: str) -> dict:
    env = dict(os.environ)
    if cache_dir:
        env["NUMBA_CACHE_DIR"] = cache_dir
    out = subprocess.run([sys.executable, "-c", _CHILD], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _breakdown() -> dict:
    """CPU microseconds of the scheme's parts (compiled, called in a compiled loop) on two
    states of the published robot at 240 Hz: all six feet pinned at rest, and all in the air
    20 um up on their squeeze films. ``advance_*``: one midpoint step of the default length
    (cached matrices) and of 0.37 of it (a partial step up to an event: solved through the
    body's Schur complement); ``contact_force``: the instantaneous contact forces (M10);
    ``step``: a whole default step with its event checks (no event happens)."""
    import numpy as np
    from numba import njit

    from labkit.sim import RobotParams, Shaker
    from labkit.sim import model as M
    from labkit.sim import scheme as K
    from labkit.sim._jit import pointer
    from labkit.sim.core import default_dt

    p, sc = RobotParams(), Shaker(240, 25)
    mdl = M.build_model(p, sc)
    dt = default_dt(p, sc)
    P, A = mdl.pack(dt)

    @njit
    def _loop(what, P_, A_, S0, mode0, h, n):
        W_, I_ = K.new_scratch()
        S_ = S0.copy()
        T_ = S0.copy()
        mode_ = mode0.copy()
        ev = np.zeros((8, K.EV_COLS))
        cnt = np.zeros(K.CNT_SIZE, np.int64)
        # as the kernel calls them (scheme.integrate): plain pointers
        P, A, S, T, mode, W, Iw = (pointer(P_), pointer(A_), pointer(S_), pointer(T_), pointer(mode_),
                                   pointer(W_), pointer(I_))
        for _ in range(n):
            for q in range(S0.size):
                S[q] = S0[q]
            for q in range(7):
                mode[q] = mode0[q]
            if what == 0:
                K.advance(P, A, S, mode, 0.0, h, W, Iw, T)
            elif what == 1:
                K.contact_force(P, A, S, mode, 0.0, 0.0, W, Iw, K.W_LI0)
            else:
                K.step(P, A, S, T, mode, 0.0, h, W, Iw, ev, cnt, True)

    states = {"pinned": (M.rest_state(mdl), np.array([K.ADHESION] * 6 + [K.AIR], np.int64)),
              "films": (M.air_state(mdl, 20e-6), np.array([K.AIR] * 7, np.int64))}
    out: dict = {}
    for name, (S0, mode0) in states.items():
        for label, what, h in (("advance_full", 0, dt), ("advance_partial", 0, 0.37 * dt),
                               ("contact_force", 1, dt), ("step", 2, dt)):
            _loop(what, P, A, S0, mode0, h, 10)
            n = 100_000
            c0 = time.process_time()
            _loop(what, P, A, S0, mode0, h, n)
            out[f"{name}_{label}"] = round((time.process_time() - c0) / n * 1e6, 3)
    return out


def _engines(params, sc, duration_s: float) -> dict:
    """Microseconds per step of the reference and of the kernel integrating the same stretch
    (the first ``duration_s`` of the run ``simulate`` makes: its model, step, start and
    sampling), each timed around :meth:`labkit.sim.kernel.Integration.advance` only, each
    as the best of its repeats (the kernel 20, the reference 3: the same statistic for both,
    so one slow reference run does not raise the ratio); and whether both recorded the same
    samples (to the bit)."""
    import numpy as np

    from labkit.sim import core
    from labkit.sim import model as M
    from labkit.sim import scheme as K
    from labkit.sim.kernel import Integration
    from labkit.sim.reference import scheme_python

    p = core.ablate(params, None)
    st = core._steps(sc, duration_s, core._step(p, sc, duration_s, None, None), None, None)
    mdl = M.build_model(p, sc)
    state, mode = core._start(mdl, None, None, core.JITTER_UM)   # simulate's start (seed None: at rest)
    P, A = mdl.pack(st.dt)
    mode7 = np.full(7, M.AIR, np.int8)
    mode7[:len(mode)] = np.asarray(mode)[:7]

    def once(mod):
        run = Integration(mod, P, A, state, mode7, st.dt, st.n_skip, core.EVENT_LOG_CAP)
        t0 = time.perf_counter()
        rec, _ = run.advance(st.n_steps, st.every)
        return time.perf_counter() - t0, rec

    kernel = min((once(K) for _ in range(20)), key=lambda x: x[0])
    reference = scheme_python()
    ref = min((once(reference) for _ in range(3)), key=lambda x: x[0])
    return {"reference_us_per_step": round(ref[0] / st.n_steps * 1e6, 1),
            "kernel_us_per_step_same_stretch": round(kernel[0] / st.n_steps * 1e6, 3),
            "ratio_reference_over_kernel": round(ref[0] / kernel[0], 1),
            "engines_same_samples": bool(np.array_equal(ref[1], kernel[1]))}


def _workers_cpu_s(workers: int) -> float | None:
    """CPU seconds (user + system) the local pool's worker processes have used so far, from
    /proc (they are the forkserver's children, not this process's; the pool lives as long as
    this process, so this is the sweep's CPU plus the workers' start-up). None off Linux."""
    from labkit import executor

    pool = executor._POOLS.get(workers)
    tick = os.sysconf("SC_CLK_TCK")
    total = 0.0
    try:
        for pid in list(getattr(pool, "_processes", None) or {}):
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick
    except (OSError, ValueError):
        return None
    return total if pool is not None else None


def _profile(params, sc, freqs, sdur: float) -> dict:
    """Per-run counters at a few of the sweep's frequencies (nominal robot, control off):
    steps, trial steps (every advance: accepted, refused, event location), refused sub-steps
    (of them, for a film transient), and CPU seconds."""
    from labkit.sim import Shaker, simulate

    rows = []
    for f in freqs:
        c0 = time.process_time()
        r = simulate(params, Shaker(float(f), sc.amp_um), duration_s=sdur, error_control="off")
        rows.append({"freq_hz": round(float(f), 1), "cpu_s": round(time.process_time() - c0, 3),
                     "steps": r.n_steps, "trial_steps": r.counters["trial_steps"],
                     "refused_substeps": r.counters["steps_halved"],
                     "refused_transient": r.counters["steps_halved_transient"],
                     "speed_mm_s": round(r.mean_speed_mm_s, 4)})
    return {"runs": rows, "cpu_s_per_run": round(sum(x["cpu_s"] for x in rows) / len(rows), 4),
            "trial_steps_per_run": round(sum(x["trial_steps"] for x in rows) / len(rows))}


def _profile_checked(params, sc, freqs, sdur: float) -> dict:
    """The same runs with the step's error control on: status, halvings, the runs the check
    made (the run, its reruns at finer steps, the chaos probes at each step probed, in units
    of the run's own steps: a rerun at h/2 counts 2) and CPU seconds each."""
    from labkit.sim import Shaker, core, simulate

    made: list[float] = []
    control = core.control

    def counted(r, run):           # the control's reruns, each weighed by its steps
        def run_counted(dt_s, seed):
            made.append(r.dt_s / dt_s)
            return run(dt_s, seed)
        return control(r, run_counted)

    rows = []
    core.control = counted
    try:
        for f in freqs:
            made.clear()
            c0 = time.process_time()
            r = simulate(params, Shaker(float(f), sc.amp_um), duration_s=sdur)
            cv = r.convergence
            rows.append({"freq_hz": round(float(f), 1), "cpu_s": round(time.process_time() - c0, 3),
                         "status": cv.status, "halvings": cv.halvings, "reruns": len(made),
                         "rerun_steps_over_run": round(sum(made), 2), "speed_mm_s": round(r.mean_speed_mm_s, 4)})
    finally:
        core.control = control
    return {"runs": rows, "cpu_s_per_run": round(sum(x["cpu_s"] for x in rows) / len(rows), 4)}


#: The Fig. 8 sweep's tray: 25 um at 240 Hz, the shaker's acceleration held above it (paper Sec. 5.1:
#: "maximum amplitudes achievable by the shaker become smaller" at higher frequencies).
FIG8_ACCEL_G = 5.8


def _sweep_row(params, sc, freqs, draws: int, sdur: float, accel_g: float | None, *, profile: bool) -> dict:
    """One sweep over ``freqs`` x ``draws`` x ``sdur`` on both cores, timed; with ``profile`` the
    per-run CPU of the nominal robot at a few of its frequencies, unchecked and checked."""
    from labkit.sim import sweep

    load_before = os.getloadavg()[0]
    cpu_before = _workers_cpu_s(2) or 0.0        # the pool outlives a sweep: its CPU so far
    w0 = time.perf_counter()
    s = sweep(params, sc, "freq_hz", freqs, draws=draws, duration_s=sdur, workers=2, seed=0, quiet=True,
              accel_limit_g=accel_g)
    sweep_wall = time.perf_counter() - w0
    sweep_cpu = _workers_cpu_s(2)
    conv = s.convergence
    row = {"points": len(freqs), "freq_hz": [float(freqs[0]), float(freqs[-1])], "draws": draws,
           "duration_s": sdur, "accel_limit_g": accel_g, "workers": 2, "runs": len(freqs) * draws,
           "wall_s": round(sweep_wall, 2), "full_size": len(freqs) == 40 and draws == 10 and sdur == 2.0,
           "loadavg_1min_before": round(load_before, 2),
           "cpu_s_workers": None if sweep_cpu is None else round(sweep_cpu - cpu_before, 1),
           "status_counts": {k: int((conv == k).sum()) for k in sorted(set(conv.flat))} if conv is not None else {},
           "target_wall_s": 40.0, "mean_speed_mm_s_at_first_point": round(float(s.mean_speed_mm_s[0]), 3)}
    if profile:
        # CPU the sweep needs, from nominal runs at a few of its frequencies in this process:
        # on a shared machine the wall time above also measures the others. The sweep's error
        # control: the nominal robot at every point checks its step, and the draws of the points
        # it refined are rerun at its step (docs/model.md, "Error control and validity")
        probe = freqs[:: max(1, len(freqs) // 8)]
        prof = _profile(params, sc, probe, sdur)
        checked = _profile_checked(params, sc, probe, sdur)
        runs, per, per_checked = len(freqs) * draws, prof["cpu_s_per_run"], checked["cpu_s_per_run"]
        total = per * (runs - len(freqs)) + per_checked * len(freqs)
        row.update({"cpu_s_per_run_estimate": round(per, 4), "cpu_s_per_checked_run_estimate": round(per_checked, 4),
                    "cpu_s_total_estimate": round(total, 1), "wall_s_on_2_idle_cores_estimate": round(total / 2, 1),
                    "profile_nominal_unchecked": prof, "profile_nominal_checked": checked})
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a small sweep and shorter runs (< 20 s)")
    args = ap.parse_args()

    import numpy as np

    from labkit.sim import RobotParams, Shaker, simulate

    params = RobotParams(**WALK)
    sc = Shaker(freq_hz=240, amp_um=25)
    out: dict = {"scenario": "shaker 240 Hz, 25 um, RobotParams(c_ad_n=50e-9)", "quick": args.quick}

    # --- JIT: cold (empty cache) vs warm (cache filled by the cold process).
    # --quick skips the cold compile (10-20 s) and times a warm process on the
    # project's own cache.
    if args.quick:
        warm = _child_first_call(os.environ.get("NUMBA_CACHE_DIR", ""))
        out["jit_cold_first_call_s"] = None
        out["jit_note"] = "--quick: cold compile not measured"
    else:
        with tempfile.TemporaryDirectory() as cache:
            cold = _child_first_call(cache)
            warm = _child_first_call(cache)
        out["jit_cold_first_call_s"] = round(cold["first_call_s"], 3)
    out["jit_warm_first_call_s"] = round(warm["first_call_s"], 3)
    out["import_labkit_sim_s"] = round(warm["import_s"], 3)

    # --- kernel, warm (one run: the step's error control off)
    simulate(params, sc, duration_s=0.01, error_control="off")
    dur = 0.5 if args.quick else 1.0
    c0, w0 = time.process_time(), time.perf_counter()
    r = simulate(params, sc, duration_s=dur, error_control="off")
    c1, w1 = time.process_time(), time.perf_counter()
    kernel_us = (c1 - c0) / r.n_steps * 1e6
    out["dt_s"] = r.dt_s
    out["kernel_us_per_step"] = round(kernel_us, 3)
    out["kernel_us_per_step_wall"] = round((w1 - w0) / r.n_steps * 1e6, 3)
    out["wall_s_per_simulated_s"] = round((w1 - w0) / dur, 4)
    out["cpu_s_per_simulated_s"] = round((c1 - c0) / dur, 4)
    out["speed_mm_s_check"] = round(r.mean_speed_mm_s, 4)
    out["trial_steps_per_step"] = round(r.counters["trial_steps"] / r.n_steps, 3)
    out["steps_halved"] = r.counters["steps_halved"]
    out["cost_breakdown_us"] = _breakdown()

    # --- reference against the kernel on the same stretch of the same run (the first
    # ref_dur seconds: the reference is slow), the stretch starting on six pinned feet, dearer
    # per step than the 1 s average above, so the ratio is taken here. The engines are timed
    # on their integration only (_engines: the same packed model, start and sampling, the
    # best of each engine's repeats); the run's set-up around it (packing the model, ~0.2 ms,
    # and allocating its outputs: Python and numpy, the same for both engines, ~0.4 ms in
    # all) is left out of the ratio, and shown by the ratio of whole runs (SimResult.wall_s).
    ref_dur = 0.005 if args.quick else 0.05
    eng = _engines(params, sc, ref_dur)
    out["reference_stretch_s"] = ref_dur
    out.update(eng)
    rr = simulate(params, sc, duration_s=ref_dur, engine="reference")
    whole = min(simulate(params, sc, duration_s=ref_dur, error_control="off").wall_s for _ in range(20))
    out["ratio_whole_runs"] = round(rr.wall_s / whole, 1)

    # --- the Fig. 8 sweeps with both cores: as the paper ran it (the default set on the
    # shaker's acceleration envelope), and the walking robot at a constant 25 um (400 g at 2 kHz)
    if args.quick:
        freqs, draws, sdur = np.linspace(150, 2000, 6), 2, 0.5
    else:
        freqs, draws, sdur = np.linspace(150, 2000, 40), 10, 2.0
    out["sweep"] = _sweep_row(RobotParams.preset("paper"), sc, freqs, draws, sdur, FIG8_ACCEL_G, profile=False)
    out["sweep"]["what"] = ("paper Fig. 8: the default (paper) set, 25 um at 240 Hz on a 5.8 g envelope "
                            "(labkit simulate sweep shaker --freq-hz 150:2000:40 --draws 10 --accel-limit-g 5.8)")
    out["sweep_walking_25um"] = _sweep_row(params, sc, freqs, draws, sdur, None, profile=True)
    out["sweep_walking_25um"]["what"] = ("the walking robot (c_ad_n = 50 nN) at a constant 25 um to 2 kHz (400 g): "
                                         "feet in the air and impacts every cycle at every point")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
