"""The squeeze film's law, finite at contact for physical reasons (docs/model.md M7).

``F = -b v / (u^3 (1 + 9.638 Kn^1.159))``, ``Kn = lambda / u``, ``u`` = the gap above asperity
contact plus the asperity gap (Veijola et al. 1995's fit of the rarefied gas's effective
viscosity). Checked against what the simulator does not use: scipy's quadrature, its
hypergeometric function (the law's closed-form integral) and its ODE solver.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.special import hyp2f1

from labkit.sim import RobotParams, Shaker, scheme
from labkit.sim import model as M
from labkit.sim.core import run_model

A_V, N_V = 9.638, 1.159          # Veijola et al. 1995, Sensors and Actuators A 48, 239-248
LAM = 68e-9                      # m, mean free path of air at 1 atm
PAD = 60.0


def law(b, u, lam=LAM):
    """The film coefficient (N s/m) at mean-plane gap u, written here independently."""
    return b / (u ** 3 * (1 + A_V * (lam / u) ** N_V))


def impulse(b, u_from, u_to, lam=LAM):
    """Closed form of the law's integral from u_from to u_to (N s per unit of velocity's
    displacement): with s = lambda / u, int b / (u^3 q) du = (b / lambda^2) int s / (1 + a s^n) ds,
    and int_0^x s / (1 + a s^n) ds = x^2 / 2 2F1(1, 2/n; 1 + 2/n; -a x^n)."""
    def G(x):
        return x * x / 2 * hyp2f1(1.0, 2 / N_V, 1 + 2 / N_V, -A_V * x ** N_V)
    return b / lam ** 2 * (G(lam / u_from) - G(lam / u_to))


def test_the_closed_form_is_the_integral_of_the_law():
    b = 6.3e-24
    for u0, u1 in ((50e-9, 80e-9), (50e-9, 5e-6), (1e-6, 3e-6)):
        num = quad(lambda u: law(b, u), u0, u1, epsrel=1e-12, points=[2 * u0, 10 * u0])[0]
        assert impulse(b, u0, u1) == pytest.approx(num, rel=1e-8)


@pytest.mark.parametrize("u0, u1", [(50e-9, 60e-9), (60e-9, 50e-9), (50e-9, 100e-9), (1e-6, 1.2e-6),
                                    (40e-6, 30e-6), (2e-6, 2e-6), (2e-6, 2e-6 * (1 + 1e-12))])
def test_the_step_coefficient_is_the_mean_of_the_law(u0, u1):
    """scheme.film_law_mean: the film's impulse over a step is the law's integral along the gap,
    within 1e-5 for gap ratios up to 2 (the sub-steps keep them below FILM_RATIO = 1.2 where a
    film matters); the continuum law (lambda = 0) exactly, at any ratio."""
    b = 6.3e-24
    # (the closed form's difference cancels for a tiny step: there the mean is the law itself)
    want = law(b, 0.5 * (u0 + u1)) if abs(u1 - u0) < 1e-6 * u0 else impulse(b, u0, u1) / (u1 - u0)
    assert scheme.film_law_mean(b, LAM, u0, u1) == pytest.approx(want, rel=1e-5)
    exact = b * (u0 + u1) / (2 * u0 ** 2 * u1 ** 2)
    assert scheme.film_law_mean(b, 0.0, u0, u1) == pytest.approx(exact, rel=1e-12)
    assert scheme.film_law_mean(b, 0.0, 50e-9, 1e-3) == pytest.approx(b * (50e-9 + 1e-3) / (2 * 50e-9 ** 2 * 1e-6),
                                                                     rel=1e-12)


def test_the_pad_coefficient_is_the_rectangular_plate_formula():
    """b = beta mu a^4 with beta(1) = 0.42 (Bao and Yang 2007, Table 1: 0.4217), beta -> 1 for a
    long strip; a 30 um pad of air at 1.85e-5 Pa s."""
    assert M.plate_beta(1.0) == pytest.approx(0.4217, abs=1e-4)
    assert M.plate_beta(1e-3) == pytest.approx(1.0, abs=1e-3)
    assert M.pad_film_coefficient(30.0) == pytest.approx(0.4217 * 1.85e-5 * (30e-6) ** 4, rel=1e-4)


def _lone_feet(**kw):
    """Feet on a still body of 1 kg, no gravity, no air but the pad films: each foot row a free
    mass on its modes (very soft legs, 1 Hz)."""
    k = (2 * math.pi * 1.0) ** 2
    return RobotParams(mass_mg=1e6 + 0.05, body_mass_mg=1e6, g_m_s2=0.0, a_drag_n_s2_m2=0.0,
                       b_g_body_n_m2_s=0.0, b_g_foot_n_m2_s=0.0, cy_sign=(0, 0, 0),
                       k_per_s2=(k, k, k), b_per_s=(0.0, 0.0, 0.0), **kw)


def _lift_off(p, v0, dt, h_end=5e-6):
    mdl = M.build_model(p, Shaker(240, 0.0))
    s = M.rest_state()
    for j in range(6):
        s[M.S_V + M.NB + 3 * j + 1] = v0 / mdl.cz[1]       # every foot leaves contact at v0
    n = int(round(2 * h_end / v0 / dt))
    out = run_model(mdl, s, np.zeros(6, np.int8), n, dt, every=n)
    gap = mdl.foot_gap(out["state"])
    vrow = mdl.rows[:, 0] @ out["state"][M.S_V:M.S_V + M.NQ]
    w = mdl.rows[:, 0] @ np.linalg.solve(mdl.mass, mdl.rows[:, 0])     # 1 / m_row
    return gap[0], vrow, w, out


@pytest.mark.parametrize("pad_um, gap_nm", [(30.0, 50.0), (20.0, 20.0)])
def test_the_impulse_to_separate_from_contact_is_the_law_integral(pad_um, gap_nm):
    """A foot leaving contact at v0 loses J / m by the gap h: J the closed-form integral of the law
    from the asperity gap to h + asperity gap, finite at contact (1.6e-10 N s from contact to 5 um
    for a 30 um pad on 50 nm asperities: 0.12 m/s of this 1.4 ug foot's take-off speed, where the
    old law, floored at 1 um with the whole leg's coefficient, took 1.5 b / h_min^2 = 3.8e-7 N s)."""
    p = _lone_feet(foot_pad_um=pad_um, film_gap_nm=gap_nm)
    b = M.pad_film_coefficient(pad_um)
    hr = gap_nm * 1e-9
    v0 = 0.3
    h, v, w, out = _lift_off(p, v0, 2e-8)
    assert out["count"][:6].sum() == 0
    want = v0 - w * impulse(b, hr, h + hr)
    assert v0 - want > 0.02                                # the film takes a real share
    assert v == pytest.approx(want, rel=2e-4)


def test_the_impulse_does_not_depend_on_the_step():
    """The film's impulse over a step is the law's integral (film_law_mean), sub-steps keep the
    gap ratio per step below FILM_RATIO: the lift-off agrees with the closed form to 2e-5 of the
    take-off speed from 2 us (sub-stepped down to the film's scale) to 16 ns."""
    p = _lone_feet()
    b = M.pad_film_coefficient(p.foot_pad_um)
    err = []
    for dt in (2e-6, 2.5e-7, 3.125e-8, 1.5625e-8):
        h, v, w, _ = _lift_off(p, 0.3, dt)
        err.append(v - (0.3 - w * impulse(b, 50e-9, h + 50e-9)))
    assert np.abs(err).max() < 2e-5 * 0.3


def test_rarefied_settling_matches_an_independent_ode():
    """A foot pulled to contact by its spring through its pad's film: m h'' = -K h - c(h) h', c the
    rarefied law at h + the asperity gap, integrated by scipy's Radau (m, K: the vertical mode's,
    the other two modes stiff). The foot settles into the rarefied regime (Kn ~ 0.3 at the end)."""
    kv = (2 * math.pi * 1000) ** 2
    p = RobotParams(mass_mg=1e6 + 0.05, body_mass_mg=1e6, g_m_s2=0.0, a_drag_n_s2_m2=0.0,
                    b_g_body_n_m2_s=0.0, b_g_foot_n_m2_s=0.0, foot_pad_um=PAD, cy_sign=(0, 0, 0),
                    k_per_s2=((2 * math.pi * 2e4) ** 2, kv, (2 * math.pi * 3e4) ** 2), b_per_s=(0.0, 0.0, 0.0))
    mdl = M.build_model(p, Shaker(240, 0.0))
    b, hr = M.pad_film_coefficient(p.foot_pad_um), p.film_gap_nm * 1e-9
    h0 = 2e-6
    s = M.rest_state()
    for j in range(6):
        s[M.S_Q + M.NB + 3 * j + 1] = h0 / mdl.cz[1]
    dt = 2e-7
    out = run_model(mdl, s, np.zeros(6, np.int8), 40000, dt, every=400)
    t = out["rec"][:, M.REC_T]
    h = out["rec"][:, M.REC_FZ]
    m = mdl.m_modal[1] / mdl.cz[1] ** 2
    k_eff = mdl.m_modal[1] * mdl.k[1] / mdl.cz[1] ** 2

    def rhs(_, y):
        return [y[1], (-k_eff * y[0] - law(b, max(y[0], 0.0) + hr) * y[1]) / m]
    ode = solve_ivp(rhs, (0, t[-1]), [h0, 0.0], method="Radau", t_eval=t, rtol=1e-10, atol=1e-16).y[0]
    np.testing.assert_allclose(h, ode, rtol=2e-3, atol=1e-10)
    assert out["count"][:6].sum() == 0
    # it ends where rarefaction divides the viscosity by > 3 (Kn ~ 0.3), and the continuum law
    # with the same coefficient would have held it 40 % higher
    assert A_V * (LAM / (ode[-1] + hr)) ** N_V > 2.0

    def rhs_continuum(_, y):
        return [y[1], (-k_eff * y[0] - b / (max(y[0], 0.0) + hr) ** 3 * y[1]) / m]
    cont = solve_ivp(rhs_continuum, (0, t[-1]), [h0, 0.0], method="Radau", rtol=1e-10, atol=1e-16).y[0][-1]
    assert cont > 1.4 * ode[-1]
