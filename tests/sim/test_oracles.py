"""The integrator against analytic oracles (model.md sections 3-6).

Most checks run the model from a prepared state with :func:`labkit.sim.core.run_model`:
a robot held in the air with gravity off and a very heavy body is six sets of
free damped oscillators; a robot with very stiff legs is a rigid block on the
table.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from labkit.sim import PZT, RobotParams, Shaker, simulate
from labkit.sim import model as M
from labkit.sim.core import run_model

# A robot whose legs are free oscillators: no gravity, no air, body 1 kg.
FREE = RobotParams(mass_mg=1e6 + 0.05, body_mass_mg=1e6, g_m_s2=0.0, a_drag_n_s2_m2=0.0,
                   b_g_body_n_m2_s=0.0, b_g_foot_n_m2_s=0.0, foot_pad_um=0.0)
LIFT_M = 1e-3   # held 1 mm above the ground


def _airborne(params, scenario, lift_m=LIFT_M):
    mdl = M.build_model(params, scenario)
    s = M.rest_state()
    s[M.S_Q + 1] = lift_m
    return mdl, s, np.zeros(6, np.int8)


@pytest.mark.parametrize("mode", [0, 1, 2])
def test_free_mode_ring_down(mode):
    mdl, s, contact = _airborne(FREE, Shaker(240, 0.0))
    x0 = 2e-6
    s[M.S_Q + M.NB + mode] = x0                       # leg 1, one mode displaced
    # implicit midpoint: frequency error (w dt)^2 / 12, 1e-5 rad per rad at this step
    dt = 1e-6
    out = run_model(mdl, s, contact, 7500, dt, every=10)
    rec = out["rec"]
    t = rec[:, M.REC_T]
    k, b = mdl.k[mode], mdl.b[mode]
    sig = b / 2
    wd = math.sqrt(k - sig * sig)
    x = x0 * np.exp(-sig * t) * (np.cos(wd * t) + sig / wd * np.sin(wd * t))
    foot_z = rec[:, M.REC_FZ] - LIFT_M
    foot_y = rec[:, M.REC_FY] - mdl.y_foot_eq[0]
    # vertical and lateral foot motion are the mode times its coupling coefficients
    np.testing.assert_allclose(foot_z, mdl.cz[mode] * x, atol=2e-3 * abs(mdl.cz[mode]) * x0)
    np.testing.assert_allclose(foot_y, mdl.cy[mode] * x, atol=2e-3 * abs(mdl.cy[mode]) * x0)
    assert out["count"][:6].sum() == 0
    # the other legs did not move
    assert np.abs(rec[:, M.REC_FZ + 1:M.REC_FZ + 6] - LIFT_M).max() < 1e-5 * x0


@pytest.mark.parametrize("freq_hz", [900.0, 1800.0, 3000.0])
def test_free_mode_frequency_response(freq_hz):
    """Steady state under the PZT square wave: the fundamental (4/pi) through H(w)."""
    params = FREE.replace(act_um_per_v=(0.0, 0.0, 1.0))
    mdl, s, contact = _airborne(params, PZT(freq_hz=freq_hz, voltage_v=2.0))
    per = 1.0 / freq_hz
    dt = per / 200
    n = int(round(40 * per / dt))
    out = run_model(mdl, s, contact, n, dt)
    t = out["rec"][:, M.REC_T]
    z = out["rec"][:, M.REC_FZ] - LIFT_M
    sel = (t >= 20 * per - 1e-12)
    tt, zz = t[sel][:-1], z[sel][:-1]            # 20 whole periods
    w = 2 * math.pi * freq_hz
    measured = 2 * np.mean(zz * np.exp(-1j * w * tt))
    g_act = mdl.k[2] * params.act_um_per_v[2] * 1e-6   # modal acceleration per volt (static 1 um/V)
    force = 4 / math.pi * g_act * 2.0             # fundamental of the square wave, sin(wt)
    h = force / (mdl.k[2] - w * w + 1j * mdl.b[2] * w)
    expected = mdl.cz[2] * h / 1j                 # Im(h e^{jwt}) seen through exp(-jwt)
    assert abs(measured) == pytest.approx(abs(expected), rel=5e-3)
    assert abs(np.angle(measured / expected)) < 5e-3


def test_pzt_tripod_gait_in_the_air():
    """Legs 1, 4, 5 are driven in phase, 2, 3, 6 in antiphase (model.md section 7)."""
    mdl, s, contact = _airborne(FREE, PZT(freq_hz=1800, voltage_v=10))
    out = run_model(mdl, s, contact, 2000, 1e-5)
    z = out["rec"][:, M.REC_FZ:M.REC_FZ + 6] - LIFT_M
    assert np.abs(z).max() > 1e-6
    for a, b in [(0, 3), (0, 4)]:
        np.testing.assert_allclose(z[:, a], z[:, b], atol=1e-4 * np.abs(z).max())
    for b in (1, 2, 5):
        np.testing.assert_allclose(z[:, 0], -z[:, b], atol=1e-4 * np.abs(z).max())


def _stiff(**kw):
    fs = 20000.0
    return RobotParams().with_modes(freq_hz=(fs, 1.3 * fs, 1.6 * fs), damping_ratio=(0.3, 0.3, 0.3)).replace(
        b_g_body_n_m2_s=0.0, b_g_foot_n_m2_s=0.0, foot_pad_um=0.0, a_drag_n_s2_m2=0.0, **kw)


def _supported_mass_kg(p):
    """Mass a foot carries on a rigid robot: a sixth of the robot's mass ``mass_mg``, which
    the body's coordinates and the 18 modal masses add up to (docs/model.md M2, M4), from
    the parameters, not from the model."""
    return p.mass_mg * 1e-6 / 6


@pytest.mark.parametrize("c_ad_n", [0.0, 2e-7])
def test_liftoff_only_above_table_acceleration_threshold(c_ad_n):
    """Stiff legs: the feet leave only when A w^2 > g + c_ad / m_foot_share."""
    p = _stiff(c_ad_n=c_ad_n, c_ad_t_n_s=0.0)
    f = 100.0
    w = 2 * math.pi * f
    threshold_um = (p.g_m_s2 + c_ad_n / _supported_mass_kg(p)) / w ** 2 * 1e6
    below = simulate(p, Shaker(f, 0.97 * threshold_um), duration_s=0.06, transient_s=0.0)
    above = simulate(p, Shaker(f, 1.05 * threshold_um), duration_s=0.06, transient_s=0.0)
    def hop_um(r):   # how far the body rises above its resting height on the moving table
        return float(np.max(r.body_z_um - r.ground_z_um - p.body_gap_um))

    assert below.impacts.sum() == 0
    assert all(below.contact_fraction[f"leg{j}"]["air"] == 0.0 for j in range(1, 7))
    assert hop_um(below) < 0.03                      # the stiff legs' static give
    assert above.impacts.min() > 0 and hop_um(above) > 0.1


def test_release_time_under_adhesion_matches_formula():
    """First release when m (A w^2 sin wt - g) exceeds c_ad_t t + c_ad (paper eq. 9)."""
    c_ad, c_ad_t = 1e-7, 2e-5
    p = _stiff(c_ad_n=c_ad, c_ad_t_n_s=c_ad_t)
    f = 100.0
    w = 2 * math.pi * f
    m = _supported_mass_kg(p)
    amp = 1.5 * (p.g_m_s2 + c_ad / m) / w ** 2
    r = simulate(p, Shaker(f, amp * 1e6), duration_s=0.004, record_dt_s=1e-9, transient_s=0.0)
    first = r.t_s[np.argmax(r.contact[:, 0] == M.AIR)]
    predicted = brentq(lambda t: m * (amp * w * w * math.sin(w * t) - p.g_m_s2) - (c_ad + c_ad_t * t), 0, 0.25 / f)
    # the release is located in time; what is left is the rigid-robot idealisation of the
    # 20 kHz legs (their response time 1/(2 pi 20 kHz) = 8 us)
    assert abs(first - predicted) <= 5e-6
    # and the label before release: ADHESION once the ground pulls (tension), REST before
    before = r.contact[r.t_s < predicted - 3 * r.dt_s, 0]
    assert set(np.unique(before)) == {M.ADHESION, M.REST}


def test_squeeze_film_settling_matches_closed_form():
    """A foot pushed to the ground by its spring through the film: h^-3 = h0^-3 + 3 K t / b
    (the continuum law: the pad's film without rarefaction, on a negligible asperity gap; the
    rarefied law: tests/sim/test_film_law.py)."""
    p = RobotParams(mass_mg=1e6 + 0.05, body_mass_mg=1e6, g_m_s2=0.0, a_drag_n_s2_m2=0.0,
                    b_g_body_n_m2_s=0.0, b_g_foot_n_m2_s=0.0, foot_pad_um=423.0, mean_free_path_nm=0.0,
                    film_gap_nm=1e-3, cy_sign=(0, 0, 0),
                    k_per_s2=((2 * math.pi * 2e4) ** 2, (2 * math.pi * 1000) ** 2, (2 * math.pi * 3e4) ** 2),
                    b_per_s=(1e-3, 1e-3, 1e-3))
    mdl = M.build_model(p, Shaker(240, 0.0))
    b_g = M.pad_film_coefficient(p.foot_pad_um)          # 2.5e-19 N m^2 s, the paper's leg value
    h0 = 5e-6
    s = M.rest_state()
    for j in range(6):
        s[M.S_Q + M.NB + 3 * j + 1] = h0 / mdl.cz[1]   # every foot 5 um up, its spring pulls it down
    dt = 1e-6
    out = run_model(mdl, s, np.zeros(6, np.int8), 20000, dt, every=500)
    t = out["rec"][:, M.REC_T]
    h = out["rec"][:, M.REC_FZ]
    k_eff = mdl.m_modal[1] * mdl.k[1] / mdl.cz[1] ** 2
    closed = (h0 ** -3 + 3 * k_eff * t / b_g) ** (-1 / 3)
    np.testing.assert_allclose(h, closed, rtol=3e-3)
    assert h[-1] < 0.6 * h0


def test_air_drag_terminal_velocity():
    """A robot falling in still air reaches v^2 = m g / (7 a), m = mass_mg the robot's mass:
    gravity acts on the body and the modal masses, which add up to it (M2, M4), drag on the
    body and the six feet, which fall with it (the legs keep their free-fall shape)."""
    p = RobotParams(b_g_body_n_m2_s=0.0, b_g_foot_n_m2_s=0.0, foot_pad_um=0.0, cy_sign=(0, 0, 0))
    mdl = M.build_model(p, Shaker(240, 0.0))
    s = M.air_state(mdl, 0.5)
    dt = 2e-5
    out = run_model(mdl, s, np.zeros(6, np.int8), int(0.4 / dt), dt, every=50)
    v_end = out["state"][M.S_V + 1]
    v_t = math.sqrt(p.mass_mg * 1e-6 * p.g_m_s2 / (7 * p.a_drag_n_s2_m2))
    assert v_end == pytest.approx(-v_t, rel=1e-3)
    assert out["count"][:6].sum() == 0


@pytest.mark.parametrize("scenario", [Shaker(240, 0.0), PZT(1800, 0.0), PZT(1800, 0.0, mass_mg=1.2)])
def test_robot_on_still_ground_stays_at_rest_to_round_off(scenario):
    """The static equilibrium (a linear solve) is a fixed point of the scheme to round-off:
    nothing moves by more than 1e-9 um (the solve's residual) in 0.2 s."""
    r = simulate(RobotParams(), scenario, duration_s=0.2)
    assert np.abs(r.body_y_um).max() < 1e-9 and np.abs(r.body_angles_rad).max() < 1e-12
    assert np.abs(r.body_z_um - r.body_z_um[0]).max() < 1e-9
    assert np.abs(r.foot_z_um).max() < 1e-9 and np.abs(r.knee_vz_mm_s).max() < 1e-9
    assert np.abs(r.foot_y_um - r.foot_y_um[0]).max() < 1e-9
    assert np.all(r.contact == M.REST) and r.impacts.sum() == 0
    assert abs(r.mean_speed_mm_s) < 1e-9
    assert r.patterns == ["firm_contact"] * 6
