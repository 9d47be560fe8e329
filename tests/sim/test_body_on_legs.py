"""The body on its legs (docs/model.md M13): the legs' stiffness at the foot from their modes,
checked against the Euler-Bernoulli cantilever (its characteristic equation and the static tip
compliance L^3 / (3 E I), closed forms labkit does not compute), and the ensemble scorer of the
paper calibration (labkit.sim.paper.fit.ensemble_score) on hand-made ensemble verdicts."""
from __future__ import annotations

import math

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


def _scored(o, pooled, share, state="met"):
    """An ObservationScore of ``o`` as labkit.sim.paper.ensemble makes it (pooled value, share of
    the robots in the regime meeting it, the pooled verdict)."""
    from labkit.sim.paper.ensemble import ObservationScore
    from labkit.sim.paper.observations import NOT_APPLICABLE, violation

    viol = None if state == NOT_APPLICABLE else violation(o, pooled)
    return ObservationScore(id=o.id, scenario=o.scenario, metric=o.metric, band=o.band, source=o.source,
                            paper_value=o.paper_value, nominal=pooled, nominal_state=state, ensemble=pooled,
                            state=state, mean=pooled, spread=0.0, median=pooled, robots=12, met_share=share,
                            per_seed=[pooled], per_seed_states=[state], violation=viol)


def test_ensemble_score_counts_the_pooled_verdict_and_the_share_of_robots():
    """The calibration's cost over an ensemble, on labkit.sim.paper.ensemble's verdicts. Band 2-6
    mm/s at 240 Hz (Fig. 8): pooled 4 with every robot inside -> 0; pooled 3.5 with half of them
    inside -> half the share term, (2/3 - 1/2) / (2/3) / 2; pooled 0 with none inside -> the
    whole share term and half the tanh of the violation (2 mm/s below, in units of 4 mm/s, plus
    the margin); an observation outside its regime costs NOT_APPLICABLE_COST, never 0."""
    from labkit.sim.paper.ensemble import EnsembleScore, EnsembleSettings
    from labkit.sim.paper.fit import NOT_APPLICABLE_COST, OBJECTIVE_MARGIN, ensemble_score
    from labkit.sim.paper.observations import NOT_APPLICABLE, observations, violation

    o = _obs()[0]
    ablation = next(x for x in observations() if x.when is not None)

    def cost(*scores):
        settings = EnsembleSettings(draws=12, duration_s=1.0, seeds=(0,))
        return ensemble_score(EnsembleScore(scores=list(scores), settings=settings, cpu_s=0.0, wall_s=0.0, runs=0))

    ok = cost(_scored(o, 4.0, 1.0))
    assert ok.cost == 0.0 and ok.violations == {o.id: 0.0} and ok.share_met == {o.id: 1.0}
    half = cost(_scored(o, 3.5, 0.5))
    assert half.violations[o.id] == 0.0 and half.cost == pytest.approx(0.5 * (2 / 3 - 0.5) / (2 / 3))
    none = cost(_scored(o, 0.0, 0.0, "not met"))
    assert none.violations[o.id] == pytest.approx(0.5)
    assert none.cost == pytest.approx(0.5 + 0.5 * math.tanh(violation(o, 0.0, OBJECTIVE_MARGIN)))
    outside = _scored(ablation, 0.2, None, NOT_APPLICABLE)
    both = cost(_scored(o, 4.0, 1.0), outside)
    assert both.cost == NOT_APPLICABLE_COST and both.violations[ablation.id] == NOT_APPLICABLE_COST
    assert both.nominal_violations == {o.id: 0.0, ablation.id: NOT_APPLICABLE_COST}


def test_simulate_runs_the_paper_set_by_default_and_says_so_first():
    from clihelpers import last_json, run_cli

    out = run_cli("simulate", "shaker", "--freq-hz", "240", "--amp-um", "25", "--duration-s", "0.01").stdout
    assert out.splitlines()[0].startswith("parameter set: paper (calibrated to the paper's observations over")
    js = last_json(run_cli("simulate", "shaker", "--duration-s", "0.01", "--params", "published", "--json"))
    assert js["params"] == "published" and js["parameter_set"].startswith("parameter set: published (")
