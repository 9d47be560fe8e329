"""The body on its legs (docs/model.md M13): the legs' stiffness at the foot from their modes,
checked against the Euler-Bernoulli cantilever (its characteristic equation and the static tip
compliance L^3 / (3 E I), closed forms labkit does not compute), and the ensemble scorer of the
paper calibration (labkit.sim.paper.fit.ensemble_cost) on hand-made metrics."""
from __future__ import annotations

import math

import numpy as np
import pytest

from labkit.sim import RobotParams
from labkit.sim.modes import cantilever_roots, cantilever_tip_participation, foot_stiffness, pinned_modes
from labkit.sim.params import CANTILEVER_TIP_PARTICIPATION

#: beta_n L of a clamped-free beam, from the literature (Blevins, Formulas for natural frequency
#: and mode shape, table 8-1): 1.87510407, 4.69409113, 7.85475744.
BLEVINS = (1.87510407, 4.69409113, 7.85475744)


def test_cantilever_roots_are_the_tabulated_ones():
    assert cantilever_roots(3) == pytest.approx(BLEVINS, abs=1e-7)


def test_every_cantilever_mode_has_a_quarter_of_the_beam_mass_at_its_tip():
    for n in (1, 2, 3, 4):
        assert cantilever_tip_participation(n) == pytest.approx(0.25, rel=1e-5)
    assert CANTILEVER_TIP_PARTICIPATION == 0.25


def test_the_modes_static_contributions_sum_to_the_beam_formula():
    """sum_n 1 / (m_eff,n w_n^2) = L^3 / (3 E I), w_n^2 = (beta_n L)^4 E I / (m L^3): in units of
    L^3 / (E I), sum_n 1 / (p_n (beta_n L)^4) = 1/3 (p_n the tip participation)."""
    roots = cantilever_roots(12)
    terms = [1 / (cantilever_tip_participation(n + 1, points=8001) * r ** 4) for n, r in enumerate(roots)]
    assert sum(terms) == pytest.approx(1 / 3, rel=1e-4)
    assert terms[0] / sum(terms) == pytest.approx(0.9707, abs=1e-3)      # the first mode carries 97 %


def test_foot_stiffness_is_the_modes_springs_in_series():
    """Without lateral coupling (cy_sign 0) every mode moves the foot vertically by Cz_i x_i: the
    foot's vertical stiffness is the three modal springs M_i k_i / Cz_i^2 in series. With the
    coupling, pinning the foot laterally can only stiffen it vertically."""
    p = RobotParams(cy_sign=(0.0, 0.0, 0.0))
    m = p.modal_participation * p.leg_mass_mg * 1e-6
    cz2 = [1 / (1 + r * r) for r in p.ratio]
    series = 1 / sum(c / (m * k) for c, k in zip(cz2, p.k_per_s2))
    assert foot_stiffness(p)[1, 1] == pytest.approx(series, rel=1e-9)
    assert foot_stiffness(RobotParams())[1, 1] >= series


def test_the_heave_on_six_springs_is_the_coupled_heave_for_light_legs():
    """The rigid body on six massless springs of the foot stiffness against the coupled model's heave
    on pinned feet: equal in the limit of light legs (a heavy body: 100 x the paper's)."""
    p = RobotParams.preset("paper")
    heavy = p.replace(mass_mg=p.mass_mg + 99 * p.body_mass_mg, body_mass_mg=100 * p.body_mass_mg)
    pm = pinned_modes(heavy)
    heave = next(m for m in pm.modes if m.kind == "body_z")
    assert heave.freq_hz == pytest.approx(pm.heave_on_springs_hz, rel=0.02)


def test_the_paper_set_stands_on_cantilever_legs_and_its_heave_is_below_the_hip():
    """The documented finding (model.md M13): with the legs' stiffness from their mass and Table 2's
    frequencies, the body's heave on pinned feet lies below the first leg mode (438 Hz)."""
    p = RobotParams.preset("paper")
    assert p.modal_participation == CANTILEVER_TIP_PARTICIPATION
    pm = pinned_modes(p)
    heave = next(m for m in pm.modes if m.kind == "body_z")
    assert 180.0 < heave.freq_hz < pm.first_leg_mode_hz()
    assert heave.damping_ratio < 0.05
    assert math.isclose(pm.first_leg_mode_hz(), 437.9, abs_tol=0.5)


def test_participation_is_no_longer_a_free_parameter_of_the_paper_fit():
    from labkit.sim.paper.fit import FREE, free_by_name

    assert "modal_participation" not in {f.name for f in FREE}
    assert "modal_participation" in free_by_name()


def _obs():
    from labkit.sim.paper.observations import observations

    return [o for o in observations() if o.id == "fig8_speed_240hz"]


def test_ensemble_cost_counts_the_median_and_the_share_of_robots():
    """Band 2-6 mm/s at 240 Hz (Fig. 8): robots at 3, 4, 5 -> met, cost 0; 3 of 6 inside with the
    median inside -> half the share term; all at 0 -> the whole share term and the median's."""
    from labkit.sim.paper.fit import OBJECTIVE_MARGIN, ensemble_cost
    from labkit.sim.paper.observations import violation

    obs = _obs()
    metric = obs[0].metric
    ok = ensemble_cost([{metric: v} for v in (3.0, 4.0, 5.0)], obs)
    assert ok.cost == 0.0 and ok.violations[obs[0].id] == 0.0 and ok.share_met[obs[0].id] == 1.0
    half = ensemble_cost([{metric: v} for v in (0.0, 0.0, 3.5, 3.5, 3.5, 9.0)], obs)
    assert half.violations[obs[0].id] == 0.0 and half.share_met[obs[0].id] == 0.5
    assert half.cost == pytest.approx(0.5 * (2 / 3 - 0.5) / (2 / 3))
    none = ensemble_cost([{metric: 0.0}] * 4, obs)
    assert none.violations[obs[0].id] == pytest.approx(0.5)            # 2 mm/s below, in units of 4 mm/s
    assert none.cost == pytest.approx(0.5 + 0.5 * math.tanh(violation(obs[0], 0.0, OBJECTIVE_MARGIN)))


def test_ensemble_members_share_their_draws_between_candidates():
    """Common random numbers: two candidates that differ in adhesion get robots drawn with the same
    factors (each member's body mass ratio to its nominal is the same)."""
    from labkit.sim.paper.fit import ensemble_members

    a = ensemble_members(RobotParams.preset("paper"), 3, seed=0)
    b = ensemble_members(RobotParams.preset("paper").replace(c_ad_n=1e-6), 3, seed=0)
    assert len(a) == 4 and a[0] == RobotParams.preset("paper")
    ra = np.array([m.body_mass_mg for m in a]) / a[0].body_mass_mg
    rb = np.array([m.body_mass_mg for m in b]) / b[0].body_mass_mg
    assert ra == pytest.approx(rb) and np.ptp(ra) > 0


def test_simulate_runs_the_paper_set_by_default_and_says_so_first():
    from clihelpers import last_json, run_cli

    out = run_cli("simulate", "shaker", "--freq-hz", "240", "--amp-um", "25", "--duration-s", "0.01").stdout
    assert out.splitlines()[0].startswith("parameter set: paper (calibrated to the paper's observations over")
    js = last_json(run_cli("simulate", "shaker", "--duration-s", "0.01", "--params", "published", "--json"))
    assert js["params"] == "published" and js["parameter_set"].startswith("parameter set: published (")
