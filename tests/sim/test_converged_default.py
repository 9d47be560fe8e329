"""Converged by default (docs/model.md, "Error control and validity"), checked against dt -> 0.

Every ``simulate`` run checks its step (rerun at half of it, halved until they agree, chaotic
runs flagged). The references here are runs at a sixteenth of the default step with the
control off: the limit the step sequence converges to, not the control's own runs. The cases
are draws of the ``paper_calibrated`` robot (the ``paper`` set until 28 November, on which the
cases below were chosen) from a random sequence (``_random_case``: seed 0, case i is the i-th
(robot, drive) pair, a shaker for even i, the PZT for odd i); 20 draws of the current default are
``python bench/convergence_bench.py``. Also: the model's masses add up to ``mass_mg``;
sweeps check a sample and carry every run's status; ``dt_check``'s allowance.
"""
from __future__ import annotations

import math

import h5py
import numpy as np
import pytest

from labkit.errors import ConfigError
from labkit.files import read_sweep_result
from labkit.sim import PZT, RobotParams, Shaker, simulate, sweep
from labkit.sim import model as M
from labkit.sim.core import default_dt, dt_check
from labkit.sim.uncertainty import draw_params


def _random_case(i: int) -> tuple[RobotParams, Shaker | PZT]:
    rng = np.random.default_rng(0)
    paper = RobotParams.preset("paper_calibrated")
    for k in range(i + 1):
        p = draw_params(paper, rng)
        if k % 2 == 0:
            sc: Shaker | PZT = Shaker(float(rng.uniform(100, 1800)), float(rng.uniform(5, 100)))
        else:
            sc = PZT(float(rng.uniform(100, 2000)), float(rng.uniform(1, 30)))
    return p, sc


#: Shaker 432 Hz / 97 um on a draw of the paper robot: -11.90 and -9.75 mm/s from starts 0.05 um apart at dt/16.
CHAOTIC_CASE = 22


def _within(v: float, ref: float) -> bool:
    return abs(v - ref) <= max(0.03 * abs(ref), 0.02)


def _limit(p: RobotParams, sc: Shaker | PZT, seed: int, duration_s: float = 0.3) -> float:
    return simulate(p, sc, duration_s, seed=seed, dt_s=default_dt(p, sc) / 16, error_control="off").mean_speed_mm_s


# --------------------------------------------------------------------------- masses (M2)

@pytest.mark.parametrize("seed", range(8))
def test_the_models_masses_add_up_to_mass_mg(seed):
    rng = np.random.default_rng(seed)
    total = rng.uniform(0.1, 2.0)
    p = RobotParams(mass_mg=total, body_mass_mg=total * rng.uniform(0.5, 0.95),
                    modal_participation=rng.uniform(0.1, 1.0))
    m_b = p.body_coordinate_mass_mg * 1e-6
    modal = 18 * p.modal_participation * p.leg_mass_mg * 1e-6
    assert m_b + modal == pytest.approx(total * 1e-6, rel=1e-14)
    mass = M.build_model(p, Shaker()).mass
    assert mass[0, 0] == pytest.approx(total * 1e-6, rel=1e-12)     # the whole robot translates
    assert mass[1, 1] == pytest.approx(total * 1e-6, rel=1e-12)
    payload = total + rng.uniform(0.0, 1.0)
    assert M.build_model(p, PZT(1000, 10, mass_mg=payload)).mass[1, 1] == pytest.approx(payload * 1e-6, rel=1e-12)


@pytest.mark.parametrize("name", ["published", "paper", "paper_calibrated"])
def test_the_bundled_robots_weigh_the_papers_0_33_mg(name):
    p = RobotParams.preset(name)
    assert p.mass_mg == 0.33
    assert M.build_model(p, Shaker()).mass[1, 1] == pytest.approx(0.33e-6, rel=1e-12)


def test_modal_masses_heavier_than_the_robot_are_refused():
    with pytest.raises(ConfigError) as e:
        RobotParams(modal_participation=3.0)
    assert e.value.key == "modal_participation"


# --------------------------------------------------------------------------- the control against dt -> 0

@pytest.mark.parametrize("i", [1, 8, 10])
def test_runs_off_at_the_default_step_are_refined_to_the_limit(i):
    """Draws of the paper robot whose default step is off its dt/16 value: PZT 1023 Hz / 26.8 V
    (50.74 mm/s against 53.83, 5.7 %), and two shaker drives where the robot hops (0.3 s runs).
    At the default settings, refined, all within 3 % or 0.02 mm/s of dt/16."""
    p, sc = _random_case(i)
    limit = _limit(p, sc, i)
    plain = simulate(p, sc, 0.3, seed=i, error_control="off").mean_speed_mm_s
    assert not _within(plain, limit)                 # the default step alone is off
    r = simulate(p, sc, 0.3, seed=i)
    c = r.convergence
    assert c.status == "refined" and c.halvings >= 1 and r.dt_s == pytest.approx(c.default_dt_s / 2 ** c.halvings)
    assert _within(r.mean_speed_mm_s, limit)
    assert c.error_mm_s <= c.tolerance_mm_s and not {"chaotic", "not_converged"} & set(r.validity.flags)


def test_a_chaotic_run_is_flagged_not_refined():
    """CHAOTIC_CASE on a draw of the paper robot: at a sixteenth of the step, two starts
    0.05 um apart end at speeds further apart than the tolerance: no single trajectory
    converges. The default run is flagged chaotic, never called converged."""
    p, sc = _random_case(CHAOTIC_CASE)
    a, b = _limit(p, sc, CHAOTIC_CASE), _limit(p, sc, CHAOTIC_CASE + 1)
    assert not _within(a, b)
    r = simulate(p, sc, 0.3, seed=CHAOTIC_CASE)
    assert r.convergence.status == "chaotic" and "chaotic" in r.validity.flags and r.validity.chaotic


def test_a_converged_run_carries_its_estimate_everywhere(tmp_path):
    p = RobotParams()
    sc = Shaker(240, 25)
    r = simulate(p, sc, 0.1, seed=0)
    half = simulate(p, sc, 0.1, seed=0, dt_s=r.dt_s / 2, error_control="off")
    c = r.convergence
    assert c.status == "converged" and r.dt_s == default_dt(p, sc)
    assert c.error_mm_s == pytest.approx(2 * abs(r.mean_speed_mm_s - half.mean_speed_mm_s), rel=1e-9, abs=1e-15)
    s = r.summary()["convergence"]
    assert s["status"] == "converged" and s["tolerance_mm_s"] == pytest.approx(max(0.03 * abs(half.mean_speed_mm_s),
                                                                                   0.02))
    path = r.to_h5(tmp_path / "run.h5")
    with h5py.File(path) as f:
        assert f.attrs["convergence"] == "converged" and math.isfinite(f.attrs["step_error_mm_s"])
    off = simulate(p, sc, 0.1, seed=0, error_control="off")
    assert off.convergence.status == "unchecked" and off.mean_speed_mm_s == r.mean_speed_mm_s


# --------------------------------------------------------------------------- sweeps: a sample checked

def test_a_sweep_checks_its_nominal_robot_and_reruns_the_draws_where_it_refined(tmp_path):
    p, sc = _random_case(1)
    s = sweep(p, sc, "voltage_v", [sc.voltage_v, 2.0], draws=2, duration_s=0.3, scheduler="serial", quiet=True)
    assert s.convergence.shape == (2, 2) and s.convergence[0, 0] == "refined"
    assert list(s.convergence[:, 1]) == ["sampled", "sampled"]
    # the draw at the refined point ran at the nominal robot's step fraction
    assert s.dt_s[0, 0] < s.dt_s[1, 0] and s.dt_s[0, 1] < 0.6 * default_dt(p, sc)
    assert np.isfinite(s.step_error_mm_s[:, 0]).all() and np.isnan(s.step_error_mm_s[:, 1]).all()
    point = s.summary()["points"][0]
    assert point["convergence"] == {"refined": 1, "sampled": 1} and point["step_error_mm_s"] > 0
    back = read_sweep_result(s.to_h5(tmp_path / "sweep.h5"))
    assert (back.convergence == s.convergence).all() and np.array_equal(back.dt_s, s.dt_s)


# --------------------------------------------------------------------------- dt_check's allowance

def test_dt_check_allowance_is_meaningful_for_slow_runs():
    """The published robot barely moves at 240 Hz / 25 um (~1e-3 mm/s): the allowance is
    0.02 mm/s plus two standard errors of the seeds' means, not 0.1 mm/s."""
    c = dt_check(RobotParams(), Shaker(240, 25.0), 0.1, seeds=2)
    assert c["tolerance_mm_s"] == pytest.approx(0.02)
    se = math.hypot(c["default"]["sem_mm_s"], c["quarter"]["sem_mm_s"])
    assert c["allowance_mm_s"] == pytest.approx(0.02 + 2 * se)
    assert c["converged"] and not c["chaotic"]
