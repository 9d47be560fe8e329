"""Long runs: integrated in pieces (the same to the bit as one piece), progress reported,
output decimated to a bounded number of samples with the run's end at the full rate
(the memory figure itself: bench/sim_memory_bench.py)."""
from __future__ import annotations

import numpy as np
import pytest

from labkit.sim import RobotParams, Shaker, core, simulate
from labkit.sim import model as M
from labkit.sim import scheme as S


def _start(params, drive):
    mdl = M.build_model(params, drive)
    state = M.rest_state(mdl)
    state[M.S_V + 1] = mdl.amp_m * mdl.omega
    mode = np.full(7, M.REST, np.int8)
    mode[6] = M.AIR
    return mdl, state, mode


def test_pieces_are_the_same_to_the_bit_as_one_run():
    """The ``paper`` robot at 300 Hz, 60 um (417 impacts, 3751 halved steps in 12000 steps) in
    pieces of 700 steps, and with a tail sampled at another rate: every output equal to the
    one-piece run's."""
    p, drive = RobotParams.preset("paper"), Shaker(freq_hz=300.0, amp_um=60.0)
    mdl, state, mode = _start(p, drive)
    dt = core.default_dt(p, drive)
    one = core.run_model(mdl, state, mode, 12000, dt, 7, 100)
    seen: list[tuple[int, int]] = []
    parts = core.run_model(mdl, state, mode, 12000, dt, 7, 100, piece_steps=700,
                           progress=lambda done, total: seen.append((done, total)))
    assert one["count"][S.CNT_EVENTS] > 10 and one["count"][S.CNT_HALVED] > 1000    # events across pieces
    for key in one:
        assert np.array_equal(one[key], parts[key]), key
    # the start, 18 pieces of up to 700 steps over 11998 = 1714 x 7 steps, the last 2 steps
    assert seen[0] == (0, 12000) and seen[-1] == (12000, 12000) and len(seen) == 20
    assert all(a[0] < b[0] for a, b in zip(seen, seen[1:]))
    tail = core.run_model(mdl, state, mode, 12000, dt, 7, 100, piece_steps=1000, tail_steps=3000, tail_every=2)
    t = tail["rec"][:, M.REC_T]
    head = (12000 - 3000) // 7 * 7 * dt           # the head: a whole number of 7-step intervals
    assert np.all(np.diff(t) > 0) and np.array_equal(tail["state"], one["state"])
    assert np.allclose(np.diff(t[t >= head - 1e-12]), 2 * dt)      # the tail: every 2nd step
    t1 = one["rec"][:, M.REC_T]
    assert np.array_equal(tail["rec"][t <= head + 1e-12], one["rec"][t1 <= head + 1e-12])


def test_a_long_run_keeps_a_bounded_number_of_samples(monkeypatch):
    """MAX_SAMPLES (lowered to 800 here) bounds what a run keeps; the last TAIL_PERIODS drive
    periods stay at the default interval; the statistics come from every step, the speed
    from the decimated samples agrees with the full record."""
    p, drive = RobotParams(), Shaker(freq_hz=240.0, amp_um=25.0)
    full = simulate(p, drive, duration_s=0.6, seed=1)
    monkeypatch.setattr(core, "MAX_SAMPLES", 800)
    dec = simulate(p, drive, duration_s=0.6, seed=1)
    period = 1 / 240.0
    tail = dec.t_s[dec.t_s > dec.t_s[-1] - core.TAIL_PERIODS * period + 1e-9]
    assert len(full.t_s) > 5000
    assert len(dec.t_s) <= 800 + len(tail) + 1
    assert np.allclose(np.diff(tail), full.record_dt_s)
    assert dec.contact_fraction == full.contact_fraction and list(dec.impacts) == list(full.impacts)
    assert dec.patterns == full.patterns and dec.foot_periods == full.foot_periods
    assert dec.mean_speed_mm_s == pytest.approx(full.mean_speed_mm_s, rel=0.02, abs=0.01)
