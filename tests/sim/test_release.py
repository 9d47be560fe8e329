"""The pull on the feet of a robot standing on a shaking tray (labkit.sim.paper.release), against
closed forms it does not compute (the weight, the rigid robot's inertia) and against the simulator."""
from __future__ import annotations

import math

import pytest

from labkit.sim import RobotParams, Shaker, simulate
from labkit.sim.paper.release import stuck_pull


def test_the_feet_carry_the_weight():
    """Gravity is the zero-frequency case: the six shares add up to m g (mass_mg, docs/model.md M2),
    equal by the robot's symmetry."""
    p = RobotParams.preset("paper")
    s = stuck_pull(p, 240.0, 25.0)
    assert sum(s.weight_n) == pytest.approx(p.mass_mg * 1e-6 * p.g_m_s2, rel=1e-9)
    assert max(s.weight_n) == pytest.approx(min(s.weight_n), rel=1e-9)


def test_a_rigid_robot_pulls_with_its_inertia():
    """Legs 1e6 times stiffer: every mass moves with the tray, and each foot's harmonic force is
    m w^2 A / 6 (Newton's second law for the whole robot), so T = m (w^2 A - g) / 6."""
    p = RobotParams.preset("paper")
    rigid = p.replace(k_per_s2=tuple(1e6 * k for k in p.k_per_s2))
    s = stuck_pull(rigid, 240.0, 25.0)
    m, w = p.mass_mg * 1e-6, 2 * math.pi * 240.0
    assert s.rigid_n == pytest.approx(m * w * w * 25e-6 / 6, rel=1e-9)
    assert s.amplification == pytest.approx(1.0, abs=1e-5)
    assert s.threshold_n == pytest.approx(m * (w * w * 25e-6 - p.g_m_s2) / 6, rel=1e-5)


def test_the_pull_scales_with_the_tray_amplitude():
    """Linear: the harmonic part is proportional to the amplitude, the weight is not."""
    p = RobotParams.preset("paper")
    a, b = stuck_pull(p, 240.0, 25.0), stuck_pull(p, 240.0, 6.25)
    assert b.pull_n[0] == pytest.approx(a.pull_n[0] / 4, rel=1e-9) and b.weight_n == pytest.approx(a.weight_n)


def test_the_simulated_robot_stays_down_above_the_threshold_and_leaves_well_below():
    """The simulator from rest on a 240 Hz, 25 um tray: with the adhesion 5 % above T not one foot
    leaves in 0.3 s (T bounds the pull: the body's nonlinear film only lowers it), with the
    adhesion at 0.6 T the feet leave and land (docs/simulator.md: the simulated robot stays down
    from 0.8-0.85 T)."""
    p = RobotParams.preset("paper").replace(c_ad_t_n_s=0.0)
    T = stuck_pull(p, 240.0, 25.0).threshold_n
    held = simulate(p.replace(c_ad_n=1.05 * T), Shaker(240.0, 25.0), duration_s=0.3, seed=None)
    assert held.impacts.sum() == 0 and all(v["air"] == 0.0 for v in held.contact_fraction.values())
    free = simulate(p.replace(c_ad_n=0.6 * T), Shaker(240.0, 25.0), duration_s=0.3, seed=None)
    assert free.impacts.min() > 0
