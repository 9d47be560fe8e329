"""A *held* run's step error (docs/model.md, "Error control and validity"), checked against dt -> 0.

A run whose feet all stayed pinned and sticking, far from letting go at every step, is
``converged`` from a run at k times its step and its probe (``Convergence.basis == "held"``). The
claim behind it: with no event the finer steps keep the feet held as well, and the speed is the
body's elastic deflection. Checked here on drawn robots of the ``paper`` set at drives that are
not chosen to be held (the shaker on the paper's 5.8 g envelope, the PZT at small voltages): every
held run is held again at a quarter and a sixteenth of the step, from the probe's start too, and
its speed agrees with theirs; runs near a release never take the shortcut.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from labkit.sim import PZT, RobotParams, Shaker, simulate
from labkit.sim import model as M
from labkit.sim.core import default_dt, held_step_factor, run_model
from labkit.sim.errorcontrol import held, probe_seed, tolerance_mm_s
from labkit.sim.scheme import NEAR_FRACTION
from labkit.sim.sweep import limit_acceleration
from labkit.sim.uncertainty import draw_params


def _case(i: int) -> tuple[RobotParams, Shaker | PZT]:
    """Robot i drawn from the paper set (seed 7); a shaker drive on the 5.8 g envelope for even i,
    the PZT below 3 V for odd i; frequencies uniform in 300-2000 Hz; cases 6 and 7 drive the
    nominal robot at its top leg mode (1801 Hz), where a coarser step detunes most."""
    if i >= 6:
        paper = RobotParams.preset("paper")
        f = float(np.sqrt(paper.k_per_s2[2]) / (2 * np.pi))
        return paper, (limit_acceleration(Shaker(f, 25.0), 5.8) if i == 6 else PZT(f, 1.5))
    rng = np.random.default_rng(7)
    paper = RobotParams.preset("paper")
    for k in range(i + 1):
        p = draw_params(paper, rng)
        f = float(rng.uniform(300, 2000))
        sc = limit_acceleration(Shaker(f, 25.0), 5.8) if k % 2 == 0 else PZT(f, float(rng.uniform(0.2, 3.0)))
    return p, sc


@pytest.mark.parametrize("i", range(8))
def test_a_held_run_is_held_and_agrees_at_finer_steps(i):
    p, sc = _case(i)
    r = simulate(p, sc, 0.5)
    c = r.convergence
    assert c is not None
    if c.basis != "held":
        # not every drawn robot stands: those that do not are checked by halving (a walking one
        # may be chaotic), and never held
        assert c.basis == "halving" and len(c.speeds_mm_s) >= 2 and not held(r)
        return
    assert c.status == "converged"
    h = default_dt(p, sc)
    # held at twice the step (and its probe), the run at the step was never made
    assert c.speeds_mm_s == (r.mean_speed_mm_s,) and c.dt_s == r.dt_s
    # (the PZT's step is shortened so its square wave's edges fall on steps)
    k = held_step_factor(p, sc, h)
    assert k >= 2 and 0.9 * k * h <= r.dt_s <= k * h * (1 + 1e-9)
    assert c.default_dt_s == pytest.approx(h, rel=1e-6)
    for div in (4, 16):
        for seed in (r.seed, probe_seed(r.seed)):
            fine = simulate(p, sc, 0.5, seed=seed, dt_s=h / div, error_control="off")
            assert held(fine), (div, seed, fine.counters)
            assert abs(fine.mean_speed_mm_s - r.mean_speed_mm_s) <= tolerance_mm_s(fine.mean_speed_mm_s)
            assert abs(fine.mean_speed_mm_s) <= c.error_mm_s + tolerance_mm_s(0.0)


def test_most_drawn_standing_cases_are_held():
    """The shortcut is taken where it should be: at least half of the cases above (they are drawn
    where the paper robot stands: Fig. 8 shows no motion from 500 Hz)."""
    kinds = [simulate(*_case(i), 0.5).convergence.basis for i in range(6)]
    assert kinds.count("held") >= 3, kinds


def test_a_foot_near_its_release_is_not_held():
    """The walking robot (50 nN adhesion) at 240 Hz: feet pulled beyond half their hold, released,
    landing: every one of these must be counted, and the run checked by halving."""
    r = simulate(RobotParams(c_ad_n=50e-9), Shaker(240, 25), 0.2)
    assert r.counters["checks_near_release"] > 0 and r.counters["releases"] > 0
    assert not held(r)
    assert r.convergence.basis == "halving" and len(r.convergence.speeds_mm_s) >= 2


def test_near_is_counted_before_a_release():
    """The same standing robot with its adhesion lowered (c_ad_t = 0): the adhesion at which it stops
    being held is found by bisection; just below it the feet are near (counted) but never let go,
    and at half of it they let go: the near band lies between a release and a held run."""
    sc = Shaker(700.0, 5.0)
    base = dataclasses.replace(RobotParams.preset("paper"), c_ad_t_n_s=0.0)

    def at(c_ad_n):
        return simulate(dataclasses.replace(base, c_ad_n=c_ad_n), sc, 0.3, error_control="off")

    r = simulate(base, sc, 0.3, error_control="off")
    assert held(r)
    # the feet's largest pull over the run is not recorded: find the adhesion where the run
    # stops being held by bisection on c_ad_n
    lo, hi = 0.0, base.c_ad_n        # hi: held; lo: released
    for _ in range(14):
        mid = 0.5 * (lo + hi)
        rm = at(mid)
        if rm.counters["releases"] == 0 and rm.counters["checks_near_release"] == 0:
            hi = mid
        else:
            lo = mid
    # just below the held threshold the feet are near but do not let go
    just = at(0.97 * hi)
    assert just.counters["releases"] == 0 and just.counters["checks_near_release"] > 0
    assert not held(just)
    # and at half that adhesion they let go
    half = at(NEAR_FRACTION * 0.97 * hi)
    assert half.counters["releases"] > 0


def test_the_held_attempt_stops_at_the_first_sign_of_activity():
    """The coarse attempt of a robot that walks stops within its first drive periods (its cost is
    small) and the result is then the run at the default step, checked by halving."""
    p, sc = RobotParams(c_ad_n=50e-9), Shaker(240, 25)
    mdl = M.build_model(p, sc)
    state, mode = M.rest_state(mdl), np.array([M.ADHESION] * 6 + [M.AIR])
    h = default_dt(p, sc)
    n = int(round(0.2 / (2 * h)))
    out = run_model(mdl, state, mode, n, 2 * h, 1, 0, stop_when_active=True)
    assert out["stopped"][0]
    done = int(np.count_nonzero(out["rec"][1:, M.REC_T]))
    assert 0 < done < n // 4, (done, n)
    full = run_model(mdl, state, mode, n, 2 * h, 1, 0)
    assert not full["stopped"][0] and np.count_nonzero(full["rec"][1:, M.REC_T]) == n


def test_a_sweeps_sampled_draws_are_tried_held():
    """A sweep's draws at a standing point run at a multiple of the step when held (status sampled)."""
    from labkit.sim import sweep

    p = RobotParams.preset("paper")
    s = sweep(p, Shaker(240, 25), "freq_hz", [700.0], draws=3, duration_s=0.3, seed=0, workers=1, quiet=True,
              accel_limit_g=5.8)
    h = default_dt(p, limit_acceleration(Shaker(700.0, 25), 5.8))
    assert list(s.convergence[0]) == ["converged", "sampled", "sampled"]
    assert all(1.8 * h < s.dt_s[0, d] < 4.4 * h for d in (1, 2)), s.dt_s  # drawn robots: their own steps


def test_the_coarse_factor_follows_the_pinned_modes_damping():
    """k shrinks as the robot's pinned modes lose damping, and is 1 (no coarse attempt) for an
    undamped one; the bound it keeps is the detuning over twice the damping ratio."""
    from labkit.sim.core import HELD_RESPONSE_CHANGE, _detuning, _pinned_modes

    p = RobotParams.preset("paper")
    sc = Shaker(2000.0, 0.3)
    h = default_dt(p, sc)
    ks = [held_step_factor(dataclasses.replace(p, b_per_s=tuple(b * s for b in p.b_per_s)), sc, h)
          for s in (1.0, 0.3, 0.1, 0.0)]
    assert ks == sorted(ks, reverse=True) and ks[0] >= 3 and ks[-1] == 1, ks
    k = ks[0]
    worst = max(_detuning(2 * np.pi * f * k * h) * (1 + 0.5 / z) for f, z in _pinned_modes(p))
    assert worst <= HELD_RESPONSE_CHANGE
    # the midpoint rule's frequency: a closed form, checked on a single oscillator's recurrence
    w, hh = 2 * np.pi * 1500.0, 5e-5
    lam = (1 - (w * hh / 2) ** 2 + 1j * w * hh) / (1 + (w * hh / 2) ** 2)    # (1 + i w h/2) / (1 - i w h/2)
    assert abs(np.angle(lam) / hh / w - (1 - _detuning(w * hh))) < 1e-12
