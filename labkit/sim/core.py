"""simulate(): run one scenario with the compiled kernel or the Python reference.

Numerics (both engines run the same scheme, :mod:`labkit.sim.scheme`; docs/model.md
M5-M11 and its section "Numerics"):

* one coupled system (23 coordinates, one mass matrix), implicit midpoint with a
  fixed step, default :func:`default_dt` (32 steps per period of the fastest mode
  or drive, >= 40 per shaker period; 1.7e-5 s for the paper's robot), halved where
  a squeeze film needs it; the PZT square wave's edges fall on step boundaries;
* squeeze films implicit, at the midpoint gap, stiff ones without ringing; impacts
  and releases are events located inside the step on the scheme's own trajectory;
* convergence (tests/sim/test_convergence.py): mean speed at the default step
  within 3 % (or 0.1 mm/s) of a quarter step for the PZT default run and shaker
  runs at 150-1500 Hz, published parameters and c_ad_n = 2e-6;
  :func:`dt_check` checks any run, and says when it is chaotic;
* the start: the robot rests on its six feet in static equilibrium and rides
  the tray (its vertical velocity is the ground's at t = 0), or, with
  ``start_height_um``, starts at rest in the air.
"""
from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from labkit.errors import InputError
from labkit.sim import model as M
from labkit.sim.errorcontrol import STEP_TOL_ABS_MM_S, STEP_TOL_REL, control, control_held, held, probe_seed, unchecked
from labkit.sim.excitation import PZT, Shaker
from labkit.sim.params import RobotParams
from labkit.sim.result import SimResult, classify_pattern, foot_period, validity

#: Default step: this many steps per period of the fastest of (highest mode, drive) ...
STEPS_PER_PERIOD = 32
#: ... and at least this many per shaker period (measured: docs/model.md M5 and "Numerics").
SHAKER_STEPS_PER_PERIOD = 40
#: Default recording interval: at most 1e-4 s, and at least 20 samples per drive period.
RECORD_DT_MAX_S = 1e-4
RECORD_PER_PERIOD = 20
#: Default start-up transient excluded from speed and contact statistics:
#: min(TRANSIENT_MAX_S, TRANSIENT_FRACTION * duration).
TRANSIENT_MAX_S = 0.2
TRANSIENT_FRACTION = 0.25
#: With a seed, the modes that are free at rest start with this RMS deviation (um).
JITTER_UM = 0.05
#: Capacity of the impact log (further impacts are counted, not logged).
EVENT_LOG_CAP = 200_000
#: A run is integrated in pieces of this many steps (progress; 1-4 s of a 2-core machine).
PIECE_STEPS = 1 << 17
#: A run keeps at most this many samples at the default recording interval (5 MB per
#: 25 columns x 25,000 samples: ~40 MB in the result) ...
MAX_SAMPLES = 200_000
#: ... and its last this many drive periods at the default interval.
TAIL_PERIODS = 20

#: Bounds of a run (:func:`check_run`). The drive: the tray's amplitude (a vibration table's
#: stroke; the paper's shaker moves 25 um) ...
MAX_AMP_UM = 1000.0
#: ... its peak acceleration (g): the random cases of the convergence checks reach 1300 g
#: (100 um at 1.8 kHz); beyond 5000 g an impact's speed is m/s on a 5-um-scale film ...
MAX_ACCEL_G = 5000.0
#: ... the drive frequency, as a multiple of the robot's highest mode (the model's modes are
#: the legs' lowest three; far above them, modes the model does not have would answer) ...
MAX_FREQ_FACTOR = 10.0
#: ... the PZT's voltage amplitude (V): the actuator law is linear, thin-film PZT depoles
#: or breaks down well before (the paper drives 20 V) ...
MAX_VOLTAGE_V = 100.0
#: ... and the work: at most this many steps (~3 h at 10 us a step).
MAX_STEPS = 1_000_000_000

#: Ablations by name (paper Fig. 12): the RobotParams fields they zero.
ABLATIONS: dict[str, dict[str, float]] = {
    "none": {},
    "no_adhesion": {"c_ad_n": 0.0, "c_ad_t_n_s": 0.0},
    "no_squeeze_film": {"b_g_body_n_m2_s": 0.0, "b_g_foot_n_m2_s": 0.0, "foot_pad_um": 0.0},
}

ENGINES = ("numba", "reference")
#: simulate(error_control=...): check the step and refine (default); "held": the run tried held at
#: a multiple of the step first (kept if held, else the run at the step, unchecked: a
#: sweep's sampled draws); or not at all.
ERROR_CONTROL = ("check", "held", "off")
#: A run is first tried at k times its step (:func:`held_step_factor`, k <= HELD_MAX_FACTOR),
#: stopped at the first sign that a foot or the body is not held; held to the end (with its
#: probe, under "check"), it is the result (docs/model.md, "Held runs").
HELD_MAX_FACTOR = 4
#: ... k is the largest at which no mode of the robot on its pinned feet, nor the drive, has its
#: forced response changed by more than this fraction (its frequency's detuning by the midpoint
#: rule, over twice its damping ratio, near its resonance).
HELD_RESPONSE_CHANGE = 0.1


def ablate(params: RobotParams, ablation: str | None) -> RobotParams:
    """``params`` with the forces of a named ablation (:data:`ABLATIONS`) switched off."""
    if ablation is None:
        return params
    name = ablation.replace("-", "_")
    if name not in ABLATIONS:
        raise InputError(f"unknown ablation {ablation!r}", key="ablation", expected=", ".join(ABLATIONS))
    return params.replace(**ABLATIONS[name]) if ABLATIONS[name] else params


def default_dt(params: RobotParams, scenario: Shaker | PZT) -> float:
    """:data:`STEPS_PER_PERIOD` steps per period of the fastest mode or drive (and at least
    :data:`SHAKER_STEPS_PER_PERIOD` per shaker period); for the PZT
    rounded down so that a half period of the square wave is a whole number of steps
    (its edges fall on step boundaries)."""
    f_top = max(max(params.modal_freq_hz), scenario.freq_hz)
    dt = 1.0 / (STEPS_PER_PERIOD * f_top)
    if isinstance(scenario, Shaker):
        dt = min(dt, 1.0 / (SHAKER_STEPS_PER_PERIOD * scenario.freq_hz))
    return align_dt(dt, scenario)


def check_run(params: RobotParams, scenario: Shaker | PZT, duration_s: float, dt: float | None = None, *,
              keys: dict[str, str] | None = None) -> None:
    """Refuse a run the model or the machine cannot do, naming the bound (InputError).

    Bounds: :data:`MAX_AMP_UM`, :data:`MAX_ACCEL_G`, the drive frequency up to
    :data:`MAX_FREQ_FACTOR` times the highest mode, :data:`MAX_VOLTAGE_V`, and
    :data:`MAX_STEPS` steps of ``dt`` (default :func:`default_dt`). ``keys`` renames the
    fields in the message (``freq_hz``, ``amp_um``, ``voltage_v``, ``duration_s``)."""
    def bad(field: str, value: float, unit: str, bound: str) -> InputError:
        key = (keys or {}).get(field, field)
        return InputError(f"{value:g} {unit} is outside what the simulator can do", key=key, expected=bound)

    f_max = MAX_FREQ_FACTOR * max(params.modal_freq_hz)
    if scenario.freq_hz > f_max:
        raise bad("freq_hz", scenario.freq_hz, "Hz", f"<= {f_max:.4g} Hz ({MAX_FREQ_FACTOR:g} x the robot's "
                                                       f"highest mode, {max(params.modal_freq_hz):.4g} Hz)")
    if isinstance(scenario, Shaker):
        accel_g = scenario.amp_um * 1e-6 * (2 * math.pi * scenario.freq_hz) ** 2 / 9.81
        if scenario.amp_um > MAX_AMP_UM:
            raise bad("amp_um", scenario.amp_um, "um", f"<= {MAX_AMP_UM:g} um (a vibration table's stroke)")
        if accel_g > MAX_ACCEL_G:
            a_max = MAX_ACCEL_G * 9.81 / (2 * math.pi * scenario.freq_hz) ** 2 * 1e6
            raise bad("amp_um", scenario.amp_um, "um", f"<= {a_max:.4g} um at {scenario.freq_hz:g} Hz (peak tray "
                                                       f"acceleration <= {MAX_ACCEL_G:g} g; this is {accel_g:.3g} g)")
    elif scenario.voltage_v > MAX_VOLTAGE_V:
        raise bad("voltage_v", scenario.voltage_v, "V", f"<= {MAX_VOLTAGE_V:g} V (thin-film PZT)")
    step = default_dt(params, scenario) if dt is None else dt
    if duration_s / step > MAX_STEPS:
        raise bad("duration_s", duration_s, "s", f"<= {MAX_STEPS * step:.4g} s ({MAX_STEPS:.0e} steps of "
                                                 f"{step:.3g} s, ~3 h of computing)")


def align_dt(dt: float, scenario: Shaker | PZT) -> float:
    """The largest step <= dt that puts the PZT square wave's edges on step boundaries."""
    if isinstance(scenario, PZT):
        half = 0.5 / scenario.freq_hz
        return half / math.ceil(half / dt - 1e-9)
    return dt


def simulate(params: RobotParams, scenario: Shaker | PZT, duration_s: float = 2.0, dt_s: float | None = None,
             record_dt_s: float | None = None, seed: int | None = None, *, engine: str = "numba",
             ablation: str | None = None, transient_s: float | None = None,
             jitter_um: float = JITTER_UM, start_height_um: float | None = None,
             progress: Callable[[int, int], None] | None = None, keys: dict[str, str] | None = None,
             error_control: str = "check") -> SimResult:
    """Simulate the robot under one excitation, its step checked (and refined where it fails).

    Parameters
    ----------
    params:
        The robot (:class:`RobotParams`).
    scenario:
        :class:`Shaker` (ground sine) or :class:`PZT` (on-board square wave, tripod gait).
    duration_s:
        Simulated time.
    dt_s:
        Step (default :func:`default_dt`); for the PZT it is shortened so the
        square wave's edges fall on step boundaries (:func:`align_dt`).
    record_dt_s:
        Sampling interval of the recorded arrays (rounded to a multiple of the step). Default:
        ``min(RECORD_DT_MAX_S, 1 / (RECORD_PER_PERIOD f))``; a run that would keep more than
        :data:`MAX_SAMPLES` samples keeps that many, evenly spaced, and the last
        :data:`TAIL_PERIODS` drive periods at the default interval (memory stays bounded).
    seed:
        ``None``: start exactly at rest. An integer: every leg mode starts with a
        small random deviation (RMS ``jitter_um``), reproducibly.
    engine:
        ``"numba"`` (compiled kernel) or ``"reference"`` (plain Python, slow).
    ablation:
        ``None``/``"none"``, ``"no_adhesion"`` or ``"no_squeeze_film"`` (:data:`ABLATIONS`).
    transient_s:
        Start-up time excluded from speed and contact statistics (default
        ``min(0.2 s, duration/4)``).
    start_height_um:
        ``None``: start resting on the six feet, riding the tray. A number H:
        start at rest in the air, the body's underside H um above its resting
        gap, the legs at their in-air equilibrium (drop tests, free flight).
    progress:
        Called as ``progress(steps_done, n_steps)`` after each piece of :data:`PIECE_STEPS` steps.
    keys:
        Names for the bounds' messages (e.g. ``{"amp_um": "--amp-um"}``), see :func:`check_run`.
    error_control:
        ``"check"`` (default): the run is first tried at a multiple of its step
        (:func:`held_step_factor`) and kept when it and its probe were *held* (every foot pinned
        far from letting go: ``convergence.basis == "held"``); otherwise it is repeated at half
        the step and the step halved until they agree, chaotic runs flagged
        (:func:`labkit.sim.errorcontrol.control`; the result's ``convergence`` carries the
        estimate; the reference engine is not checked). ``"held"``: the held attempt, else the
        run at its step unchecked (a sweep's sampled draws). ``"off"``: the run at its step only
        (``convergence.status == "unchecked"``). A ``dt_s`` given is the step used, as given:
        the control applies to the default step only.

    Raises
    ------
    InputError
        A drive, duration or step outside :func:`check_run`'s bounds, before anything runs.
    """
    _check_call(params, scenario, engine, duration_s, error_control)
    if error_control in ("check", "held") and engine == "numba" and dt_s is None:
        def held_at(sd: int | None) -> SimResult | None:
            return _held_run(_HeldRun(params, scenario, duration_s, record_dt_s, ablation, transient_s, jitter_um,
                                      start_height_um, keys, progress), sd)

        coarse = held_at(seed)
        if coarse is not None and error_control == "held":
            return coarse
        if coarse is not None:
            probe = held_at(probe_seed(seed))
            if probe is not None:
                return control_held(coarse, probe, default_dt(ablate(params, ablation), scenario))
    if error_control == "held":
        error_control = "off"
    if error_control == "check" and engine == "numba" and dt_s is None:
        def rerun(step: float, sd: int | None) -> SimResult:
            return simulate(params, scenario, duration_s, step, record_dt_s, sd, ablation=ablation,
                            transient_s=r.transient_s, jitter_um=jitter_um, start_height_um=start_height_um, keys=keys,
                            error_control="off")

        r = simulate(params, scenario, duration_s, dt_s, record_dt_s, seed, ablation=ablation, transient_s=transient_s,
                     jitter_um=jitter_um, start_height_um=start_height_um, progress=progress, keys=keys,
                     error_control="off")
        return control(r, rerun)
    p = ablate(params, ablation)
    st = _steps(scenario, duration_s, _step(p, scenario, duration_s, dt_s, keys), record_dt_s, transient_s)
    mdl = M.build_model(p, scenario)
    state, mode = _start(mdl, start_height_um, seed, jitter_um)
    t0 = time.perf_counter()
    out = run_model(mdl, state, mode, st.n_steps, st.dt, st.every, st.n_skip, engine=engine, ev_cap=EVENT_LOG_CAP,
                    tail_steps=st.tail_steps, tail_every=st.tail_every, progress=progress)
    wall = time.perf_counter() - t0
    return unchecked(_result(p, scenario, mdl, out, duration_s, st.dt, st.every, st.n_steps, st.n_skip, engine, wall,
                             seed, ablation))


def _detuning(omega_h: float) -> float:
    """How much lower the midpoint rule's frequency of a mode is, relatively, at ``omega h``:
    ``1 - atan(omega h / 2) / (omega h / 2)``."""
    x = 0.5 * omega_h
    return 1.0 - math.atan(x) / x if x > 0 else 0.0


@functools.lru_cache(maxsize=64)
def _pinned_modes(params: RobotParams) -> tuple[tuple[float, float], ...]:
    from labkit.sim.modes import pinned_modes

    return tuple((m.freq_hz, m.damping_ratio) for m in pinned_modes(params, max_hz=math.inf).modes)


def held_step_factor(params: RobotParams, scenario: Shaker | PZT, dt: float) -> int:
    """The coarsest multiple k of the step ``dt`` (1 .. :data:`HELD_MAX_FACTOR`) a held run is tried
    at: every mode of the robot standing on its pinned, sticking feet (damping ratio zeta) and the
    drive keep their forced response within :data:`HELD_RESPONSE_CHANGE` at ``k dt``, bounded by
    ``d (1 + 1 / (2 zeta))`` with ``d`` the mode's :func:`_detuning` (first order, near resonance).
    The ``paper`` robot: 2 below 1.5 kHz (at 3 dt its top pinned mode, 1517 Hz, zeta 0.12, is
    detuned 2.0 %: a 10.04 % change), 3 for most of its drawn robots, 3-4 above 1.5 kHz."""
    modes = _pinned_modes(params)
    best = 1
    for k in range(2, HELD_MAX_FACTOR + 1):
        h = k * dt
        change = [_detuning(2 * math.pi * f * h) * (1 + 0.5 / z) if z > 0 else math.inf for f, z in modes]
        change.append(_detuning(2 * math.pi * scenario.freq_hz * h))
        if max(change) > HELD_RESPONSE_CHANGE:
            break
        best = k
    return best


@dataclass(frozen=True)
class _HeldRun:
    """What :func:`simulate` was asked, for its held attempt (:func:`_held_run`)."""

    params: RobotParams
    scenario: Shaker | PZT
    duration_s: float
    record_dt_s: float | None
    ablation: str | None
    transient_s: float | None
    jitter_um: float
    start_height_um: float | None
    keys: dict[str, str] | None
    progress: Callable[[int, int], None] | None


def _held_run(q: _HeldRun, seed: int | None) -> SimResult | None:
    """The run at :func:`held_step_factor` times the default step, stopped as soon as a foot or the
    body is not held; the result when it was held to the end (:func:`labkit.sim.errorcontrol.held`),
    else None."""
    p, sc = ablate(q.params, q.ablation), q.scenario
    h = _step(p, sc, q.duration_s, None, q.keys)       # the bounds are the default step's
    k = held_step_factor(p, sc, h)
    if k < 2 or k * h > q.duration_s / 4:
        return None
    st = _steps(sc, q.duration_s, _step(p, sc, q.duration_s, k * h, q.keys), q.record_dt_s, q.transient_s)
    mdl = M.build_model(p, sc)
    state, mode = _start(mdl, q.start_height_um, seed, q.jitter_um)
    t0 = time.perf_counter()
    out = run_model(mdl, state, mode, st.n_steps, st.dt, st.every, st.n_skip, ev_cap=EVENT_LOG_CAP,
                    tail_steps=st.tail_steps, tail_every=st.tail_every, progress=q.progress, stop_when_active=True)
    if out["stopped"][0]:
        return None
    r = unchecked(_result(p, sc, mdl, out, q.duration_s, st.dt, st.every, st.n_steps, st.n_skip, "numba",
                          time.perf_counter() - t0, seed, q.ablation))
    return r if held(r) else None


def _check_call(params: RobotParams, scenario: Shaker | PZT, engine: str, duration_s: float,
                error_control: str) -> None:
    """InputError naming the first of :func:`simulate`'s arguments of the wrong type or out of range."""
    if not isinstance(params, RobotParams):
        raise InputError(f"params must be a RobotParams, not {type(params).__name__}", key="params")
    if not isinstance(scenario, (Shaker, PZT)):
        raise InputError(f"scenario must be a Shaker or a PZT, not {type(scenario).__name__}", key="scenario")
    if engine not in ENGINES:
        raise InputError(f"unknown engine {engine!r}", key="engine", expected=" or ".join(ENGINES))
    if not (duration_s > 0 and math.isfinite(duration_s)):
        raise InputError(f"out of range: {duration_s!r}", key="duration_s", expected="a number in s, > 0")
    if error_control not in ERROR_CONTROL:
        raise InputError(f"unknown error control {error_control!r}", key="error_control",
                         expected=" or ".join(ERROR_CONTROL))


@dataclass(frozen=True)
class Steps:
    """How a run is stepped and sampled (:func:`simulate`'s plan, from its arguments).

    ``dt``: the step (s); ``n_steps`` of it; a sample kept every ``every`` steps, and every
    ``tail_every`` over the last ``tail_steps`` (a long run's end at the full rate); the first
    ``n_skip`` steps are the start-up transient (left out of speed and contact statistics).
    """

    dt: float
    n_steps: int
    every: int
    n_skip: int
    tail_steps: int = 0
    tail_every: int = 1


def _step(p: RobotParams, scenario: Shaker | PZT, duration_s: float, dt_s: float | None,
          keys: dict[str, str] | None) -> float:
    """A run's step: ``dt_s`` or :func:`default_dt`, aligned (:func:`align_dt`) and within
    :func:`check_run`'s bounds (InputError naming the bound)."""
    dt = default_dt(p, scenario) if dt_s is None else float(dt_s)
    if not (dt > 0 and dt <= duration_s):
        raise InputError(f"out of range: {dt_s!r}", key="dt_s", expected=f"a number in s, > 0, <= {duration_s}")
    dt = align_dt(dt, scenario)
    check_run(p, scenario, duration_s, dt, keys=keys)
    return dt


def _steps(scenario: Shaker | PZT, duration_s: float, dt: float, record_dt_s: float | None,
           transient_s: float | None) -> Steps:
    """The sampling and transient of a run at step ``dt`` (InputError naming one out of range)."""
    decimate = record_dt_s is None
    if record_dt_s is None:
        record_dt_s = min(RECORD_DT_MAX_S, 1.0 / (RECORD_PER_PERIOD * scenario.freq_hz))
    if not (record_dt_s > 0 and record_dt_s <= duration_s / 2):
        raise InputError(f"out of range: {record_dt_s!r}", key="record_dt_s",
                         expected=f"a number in s, > 0, <= duration_s / 2 ({duration_s / 2:g})")
    every = max(1, int(round(record_dt_s / dt)))
    n_steps = int(round(duration_s / dt))
    tail_steps, tail_every = 0, every
    if decimate and n_steps // every > MAX_SAMPLES:
        # a long run: MAX_SAMPLES samples over the run, the last TAIL_PERIODS drive periods at
        # the full rate (the foot patterns and periodicity read them)
        tail_steps = min(n_steps, int(math.ceil(TAIL_PERIODS / scenario.freq_hz / dt)))
        every = int(math.ceil(n_steps / MAX_SAMPLES))
    if transient_s is None:
        transient_s = min(TRANSIENT_MAX_S, TRANSIENT_FRACTION * duration_s)
    n_skip = min(int(round(transient_s / dt)), n_steps - 1)
    return Steps(dt, n_steps, every, n_skip, tail_steps, tail_every)


def _start(mdl: M.Model, start_height_um: float | None, seed: int | None,
           jitter_um: float) -> tuple[np.ndarray, np.ndarray]:
    """The initial state and contact modes: resting on the feet and riding the tray, or at rest in
    the air ``start_height_um`` above the resting gap; with a seed, the leg modes jittered."""
    if start_height_um is None:
        state = M.rest_state(mdl)
        # The robot starts riding the tray: resting on its feet and moving with the
        # ground (z_g' at t = 0), so a shaker run does not begin with a jolt.
        state[M.S_V + 1] = mdl.amp_m * mdl.omega if mdl.kind == 0 else 0.0
        mode = np.full(7, M.REST, np.int8)
        mode[6] = M.AIR
    else:
        h = float(start_height_um)
        drop_um = M.lowest_foot_drop_m(mdl) * 1e6
        amp_um = mdl.amp_m * 1e6
        if not (math.isfinite(h) and h > drop_um + amp_um):
            raise InputError(f"out of range: {start_height_um!r}", key="start_height_um",
                             expected=f"a number in um, > {drop_um + amp_um:.3g} (the unloaded legs hang "
                                      f"{drop_um:.3g} um lower; tray amplitude {amp_um:g} um)")
        state = M.air_state(mdl, h * 1e-6)
        mode = np.full(7, M.AIR, np.int8)
    if seed is not None and jitter_um > 0:
        rng = np.random.default_rng(seed)
        for k in range(18):
            state[M.S_Q + M.NB + k] += jitter_um * 1e-6 * rng.standard_normal()
    return state, mode


def run_model(mdl: M.Model, state: np.ndarray, mode: np.ndarray, n_steps: int, dt: float, every: int = 1,
              n_skip: int = 0, *, engine: str = "numba", ev_cap: int = EVENT_LOG_CAP, tail_steps: int = 0,
              tail_every: int | None = None, piece_steps: int | None = None,
              progress: Callable[[int, int], None] | None = None,
              stop_when_active: bool = False) -> dict[str, np.ndarray]:
    """Low level: integrate a built model from any state (layouts in :mod:`labkit.sim.scheme`).

    ``mode``: contact mode of the 6 feet and (7th, optional) the body. Returns
    the raw output arrays (SI): ``rec`` (samples x ``REC_COLS``),
    ``rec_contact``, ``frac`` (time per foot and contact mode after ``n_skip``
    steps), ``max_air``, ``max_h`` (highest flight per foot), ``count``,
    ``events``, and the final ``state`` and ``mode``.

    The run is integrated in pieces of ``piece_steps`` (default :data:`PIECE_STEPS`),
    the same to the bit as one piece; ``progress(done, n_steps)`` is called after each.
    A sample is kept every ``every`` steps, and every ``tail_every`` steps over the
    last ``tail_steps`` steps (a long run's output decimated, its end at full rate).
    With ``stop_when_active`` the run stops at the first step after which a foot or the body
    is not held (:class:`labkit.sim.kernel.Integration`): ``stopped`` (one bool) says so, and
    the other outputs are then those of the stretch run.
    """
    from labkit.sim.kernel import Integration

    P, A = mdl.pack(dt)
    mode7 = np.full(7, M.AIR, np.int8)
    mode7[:min(7, len(mode))] = np.asarray(mode)[:7]
    if engine == "numba":
        from labkit.sim import scheme as mod
    else:
        from labkit.sim.reference import scheme_python

        mod = scheme_python()
    run = Integration(mod, P, A, state, mode7, dt, n_skip, ev_cap, stop_when_active)
    recs, contacts = [], []
    pieces = _pieces(n_steps, every, tail_steps, tail_every or every, piece_steps or PIECE_STEPS)
    if progress is not None and len(pieces) > 1:
        progress(0, n_steps)
    for k, (n, ev) in enumerate(pieces):
        rec, rc = run.advance(n, ev)
        if run.stopped:
            return {"rec": rec, "rec_contact": rc, **run.outputs()}
        last = k == len(pieces) - 1
        if not last and n % ev == 0:     # its last sample is the next piece's first
            rec, rc = rec[:-1], rc[:-1]
        recs.append(rec)
        contacts.append(rc)
        if progress is not None:
            progress(run.n0, n_steps)
    one = len(recs) == 1
    # the pieces joined column-major, as each is (Integration.advance)
    return {"rec": recs[0] if one else np.concatenate([r.T for r in recs], axis=1).T,
            "rec_contact": contacts[0] if one else
            np.concatenate(contacts), **run.outputs()}


def _pieces(n_steps: int, every: int, tail_steps: int, tail_every: int, piece: int) -> list[tuple[int, int]]:
    """(steps, sampling interval) of each piece: the head (a whole number of ``every``) in
    pieces of about ``piece`` steps, then the tail at ``tail_every``."""
    head = max(0, n_steps - tail_steps) // every * every
    out: list[tuple[int, int]] = []
    for n_part, ev in ((head, every), (n_steps - head, tail_every)):
        size = max(ev, piece // ev * ev)
        while n_part > 0:
            n = min(size, n_part)
            out.append((n, ev))
            n_part -= n
    return out or [(0, every)]


def mean_speed_mm_s(t: np.ndarray, y: np.ndarray, t_from: float) -> float:
    """Mean forward speed (mm/s) after ``t_from``: the least-squares slope of y(t) (m).

    Not the end-to-end displacement: the body rides its legs like a sprung mass
    (docs/model.md M2: on pinned feet the body bounces and sways at a few hundred
    Hz by tens of um), and the end points would sample that oscillation; the
    slope of a fit averages it out (error ~ amplitude / (omega T^2)).
    """
    sel = t >= t_from
    if sel.sum() < 2:
        sel = np.ones_like(t, bool)
    tt, yy = t[sel], y[sel]
    if len(tt) < 2 or tt[-1] <= tt[0]:
        return 0.0
    tc = tt - tt.mean()
    # sums, not ``tc @ tc``: a dot product of this length (10^4-10^5 samples) wakes OpenBLAS's
    # threads, which then spin for ~0.1 s of CPU on the other core; in a sweep on both cores
    # that was 15-20 % of the time (issue 10, bench/sim_bench.py)
    den = float(np.sum(tc * tc))
    return float(np.sum(tc * (yy - yy.mean())) / den * 1e3) if den > 0 else 0.0


def _result(p, scenario, mdl, out, duration_s, dt, every, n_steps, n_skip, engine, wall, seed, ablation):
    rec, cnt = out["rec"], out["count"]
    t = rec[:, M.REC_T]
    y = rec[:, M.REC_Y]
    t_skip = n_skip * dt
    speed = mean_speed_mm_s(t, y, t_skip - 0.5 * dt)
    tot = out["frac"].sum(axis=1, keepdims=True)
    frac = np.divide(out["frac"], tot, out=np.zeros_like(out["frac"]), where=tot > 0)
    cf = {f"leg{j + 1}": {name: float(frac[j, m]) for m, name in enumerate(M.MODE_NAMES)} for j in range(6)}
    period = 1.0 / scenario.freq_hz
    max_h_um = out["max_h"] * 1e6
    patterns = [classify_pattern(frac[j, M.AIR], float(out["max_air"][j]), period, float(max_h_um[j]))
                for j in range(6)]
    height = (rec[:, M.REC_FZ:M.REC_FZ + 6] - rec[:, [M.REC_ZG]]) * 1e6
    periods = [foot_period(t, height[:, j], period, t_skip) for j in range(6)]
    n_ev = int(cnt[M.CNT_EVENTS])
    counters = {"events_lost": int(cnt[M.CNT_LOST]), "steps_event_capped": int(cnt[M.CNT_FORCED]),
                "steps_halved": int(cnt[M.CNT_HALVED]), "trial_steps": int(cnt[M.CNT_ADV]),
                "steps_halved_transient": int(cnt[M.CNT_HALVED_TRANSIENT]), "releases": int(cnt[M.CNT_RELEASES]),
                "checks_near_release": int(cnt[M.CNT_NEAR])}
    valid = validity(p, (rec[:, M.REC_Z] - rec[:, M.REC_ZG]) * 1e6, rec[:, M.REC_PH:M.REC_PH + 3],
                     out["rec_contact"], counters)
    return SimResult(
        params=p, scenario=scenario, duration_s=float(duration_s), dt_s=float(dt), record_dt_s=float(dt * every),
        transient_s=float(t_skip), engine=engine, t_s=t.copy(), body_y_um=y * 1e6, body_z_um=rec[:, M.REC_Z] * 1e6,
        body_angles_rad=rec[:, M.REC_PH:M.REC_PH + 3].copy(), foot_z_um=rec[:, M.REC_FZ:M.REC_FZ + 6] * 1e6,
        foot_y_um=rec[:, M.REC_FY:M.REC_FY + 6] * 1e6, contact=out["rec_contact"].copy(),
        knee_vz_mm_s=rec[:, M.REC_KV:M.REC_KV + 6] * 1e3, ground_z_um=rec[:, M.REC_ZG] * 1e6,
        mean_speed_mm_s=speed, contact_fraction=cf, impacts=cnt[:6].astype(int).copy(),
        body_impacts=int(cnt[M.CNT_BODY]), patterns=patterns, max_flight_s=out["max_air"].copy(),
        events=out["events"][:n_ev].copy(), n_steps=n_steps, wall_s=wall, seed=seed, ablation=ablation,
        counters=counters, max_height_um=max_h_um.copy(), foot_periods=periods, validity=valid)


#: dt_check: the default step and the quarter step agree when the mean speeds differ by
#: less than this fraction, or by less than DT_CHECK_ABS_MM_S, plus the seeds' spread (two
#: standard errors of the difference of the means); the same tolerance as the per-run
#: error control (:mod:`labkit.sim.errorcontrol`).
DT_CHECK_REL = STEP_TOL_REL
DT_CHECK_ABS_MM_S = STEP_TOL_ABS_MM_S
#: dt_check: seeds of the chaos probe (runs from slightly different starts, jitter_um).
DT_CHECK_SEEDS = 4


class StepSpeeds(TypedDict):
    """The speeds of :func:`dt_check`'s starts at one step, their mean, standard error and deviation (mm/s)."""

    speeds_mm_s: list[float]
    mean_mm_s: float
    sem_mm_s: float
    std_mm_s: float


class DtCheck(TypedDict):
    """:func:`dt_check`: the two steps, the seeds, the speeds at each, and the verdict."""

    dt_s: float
    quarter_dt_s: float
    seeds: list[int]
    default: StepSpeeds
    quarter: StepSpeeds
    chaotic: bool
    difference_mm_s: float
    tolerance_mm_s: float
    allowance_mm_s: float
    converged: bool


def dt_check(params: RobotParams, scenario: Shaker | PZT, duration_s: float = 2.0, *, seeds: int = DT_CHECK_SEEDS,
             seed: int = 0, ablation: str | None = None, engine: str = "numba",
             start_height_um: float | None = None) -> DtCheck:
    """Is the default step converged for this run? Rerun at a quarter of it and compare.

    Runs ``seeds`` starts (seeds ``seed .. seed+seeds-1``, each leg mode jittered by
    :data:`JITTER_UM`) at the default step and at a quarter step. A run is *chaotic*
    when the speeds of the starts at one step spread by more than the agreement
    tolerance (their standard deviation > max(DT_CHECK_REL |mean|, DT_CHECK_ABS_MM_S)):
    then single trajectories cannot converge and only the ensemble means are compared.
    The allowance: ``max(3 % of the quarter step's mean, 0.02 mm/s) + 2 sqrt(se_a^2 + se_b^2)``
    (se: the standard errors of the two means over the seeds; ~0 for a run that is not chaotic).
    Every run is checked anyway (``simulate``'s error control); this is the explicit, fuller
    check over several starts and the whole run. Returns a JSON-able dict: per step the
    speeds, mean and standard error, the difference, ``tolerance_mm_s``, ``allowance_mm_s``,
    ``converged`` and ``chaotic``.
    """
    if seeds < 2:
        raise InputError(f"need at least 2 seeds, got {seeds}", key="seeds", expected="an integer >= 2")
    p = ablate(params, ablation)
    dt = default_dt(p, scenario)
    starts = list(range(seed, seed + seeds))

    def speeds(step: float) -> StepSpeeds:
        v = np.array([simulate(p, scenario, duration_s, dt_s=step, seed=s, engine=engine, error_control="off",
                               start_height_um=start_height_um).mean_speed_mm_s for s in starts])
        return {"speeds_mm_s": [float(x) for x in v], "mean_mm_s": float(v.mean()),
                "sem_mm_s": float(v.std(ddof=1) / math.sqrt(len(v))), "std_mm_s": float(v.std(ddof=1))}

    a, b = speeds(dt), speeds(dt / 4)
    tol = max(DT_CHECK_REL * abs(b["mean_mm_s"]), DT_CHECK_ABS_MM_S)
    diff = a["mean_mm_s"] - b["mean_mm_s"]
    # the means must agree within the tolerance plus two standard errors of their difference
    allow = tol + 2 * math.hypot(a["sem_mm_s"], b["sem_mm_s"])
    return {"dt_s": dt, "quarter_dt_s": align_dt(dt / 4, scenario), "seeds": starts, "default": a, "quarter": b,
            "chaotic": bool(max(a["std_mm_s"], b["std_mm_s"]) > tol), "difference_mm_s": float(diff),
            "tolerance_mm_s": float(tol), "allowance_mm_s": float(allow), "converged": bool(abs(diff) <= allow)}
