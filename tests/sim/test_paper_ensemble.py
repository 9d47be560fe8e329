"""The observations' third state, the new metrics against closed forms, and the ensemble scorer.

The closed forms: a knee velocity ``V cos(w t)`` is a displacement of amplitude ``V / w``; a
lock-in of ``A sin(w t + p)`` returns ``A``; a release with a step in the relative velocity
returns that step. The ensemble is checked against the scenario it pools (its nominal robot is
the scenario's run; a pooled mean speed is the mean of its robots')."""
from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from test_paper import _ps

from labkit.sim import RobotParams
from labkit.sim.paper.ensemble import EnsembleSpec, merge_runs, run_ensemble, score_ensemble, score_runs
from labkit.sim.paper.observations import NOT_APPLICABLE, ObservationCheck, check, observations, tally
from labkit.sim.paper.shaker import ShakerLaw
from labkit.sim.scenarios import run_scenario
from labkit.sim.scenarios.base import RunOptions
from labkit.sim.scenarios.metrics import knee_amplitude_um, lockin, release_jumps, response_gains
from labkit.sim.scenarios.paper import ablations_measure, evaluate, payload_measure, rise_onset

ABLATION_IDS = {"ablation_full_periodic", "ablation_no_adhesion_aperiodic", "ablation_no_squeeze_more_motion",
                "ablation_squeeze_slows"}


def test_third_state_is_neither_met_nor_failed():
    na = ObservationCheck("a", "m", 1.0, False, "x > 0", "src", float("nan"), state=NOT_APPLICABLE, when="w")
    assert not na.passed and not na.applicable and na.line().startswith("N/A")
    d = na.to_dict()
    assert d["state"] == "not applicable" and d["violation"] is None and d["passed"] is False
    with pytest.raises(ValueError):
        ObservationCheck("a", "m", 1.0, True, "x > 0", "src", 0.0, state=NOT_APPLICABLE)
    assert tally([na]) == {"met": 0, "not met": 0, "not applicable": 1}


def test_firm_contact_ablations_are_not_applicable_synthetic():
    """Every ablation variant in firm contact (the full model never in partial contact): the four
    Fig. 12 claims are not applicable, whatever their metrics say."""
    x = [2, 8, 4, 6, 102, 108, 104, 106, 204, 206]
    m = ablations_measure(_ps(x, [0.0] * len(x)))
    assert m["full_in_partial_contact"] == 0.0 and m["full_partial_share"] == 0.0
    states = {c.id: c.state for c in check("paper-ablations", m)}
    assert {i: states[i] for i in ABLATION_IDS} == dict.fromkeys(ABLATION_IDS, NOT_APPLICABLE)
    # partial contact at 6 V only: the ablations are scored at 6 V, not at 4 V
    part = [["partial_contact"] * 6 if v in (6, 106, 206) else ["firm_contact"] * 6 for v in x]
    speeds = [1.0 if v == 6 else 3.0 if v == 206 else 0.0 for v in x]
    m6 = ablations_measure(_ps(x, speeds, part))
    assert m6["ablation_drive_vpp"] == 6.0 and m6["full_partial_and_moving"] == 1.0
    assert m6["speed_gain_no_squeeze_mm_s"] == pytest.approx(2.0)
    assert {c.id: c.state for c in check("paper-ablations", m6)}["ablation_squeeze_slows"] == "met"


def test_firm_contact_run_gives_not_applicable():
    """A real run: the paper's shaker scaled down to 1 um at 240 Hz and 8 V (0.5 um at 4 V) keeps
    every foot on the tray, so no ablation claim can be scored there."""
    tiny = ShakerLaw(ref_amp_um=1.0)
    opts = RunOptions(size="quick", duration_s=0.2, workers=1, quiet=True)
    ps, m = evaluate("paper-ablations", RobotParams.preset("paper"), opts, tiny)
    assert m["full_partial_share"] < 0.5
    checks = {c.id: c for c in check("paper-ablations", m)}
    assert all(checks[i].state == NOT_APPLICABLE and not checks[i].passed for i in ABLATION_IDS)


def test_payload_rise_onset():
    masses = [0.33, 0.6, 0.9, 1.2, 1.4, 1.6, 1.7, 2.0]
    # flat (slow) to 1.2 mg, then rising: onset 1.2 mg
    assert rise_onset(masses, [2.0, 1.98, 2.01, 1.97, 3.0, 4.0, 5.0, 0.0], 1.7) == 1.2
    # rising from the start (the preset): onset 0.33 mg, the observation fails
    rising = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 0.0]
    assert rise_onset(masses, rising, 1.7) == 0.33
    states = {c.id: c.state for c in check("paper-payload", payload_measure(_ps(masses, rising)))}
    assert states["payload_rise_onset_1_2mg"] == "not met"
    assert states["payload_large_variation_1_7mg"] == NOT_APPLICABLE     # one robot: no spread to judge
    # an ensemble with its largest spread at 1.7 mg
    spread = np.array([[1.0, 1.1]] * 6 + [[0.0, 6.0], [0.0, 0.0]])
    m = payload_measure(_ps(masses, spread))
    assert m["speed_sd_ratio_near_1_7_mg"] == pytest.approx(np.std([0, 6], ddof=1) / np.std([1, 1.1], ddof=1))
    assert {c.id: c.state for c in check("paper-payload", m)}["payload_large_variation_1_7mg"] == "met"


def _record(f_hz=240.0, n_per=40, per=48):
    t = np.arange(n_per * per + 1) / (per * f_hz)
    return t, 2 * math.pi * f_hz


def test_knee_amplitude_is_the_integrated_velocity():
    t, w = _record()
    v_mm_s = 30.0                                     # 30 mm/s at 240 Hz: 19.9 um
    knee = np.outer(v_mm_s * np.cos(w * t), np.linspace(0.5, 1.0, 6))
    r = SimpleNamespace(t_s=t, knee_vz_mm_s=knee)
    assert knee_amplitude_um(r) == pytest.approx(v_mm_s / w * 1e3, rel=2e-3)


def test_lockin_and_gains():
    t, w = _record(1200.0)
    assert abs(lockin(t, 3.0 * np.sin(w * t + 0.7), 1200.0)) == pytest.approx(3.0, rel=1e-6)
    ground = 0.5 * np.sin(w * t)                      # um
    tray_v = 0.5 * w * np.cos(w * t) * 1e-3           # mm/s
    knee = np.repeat((2.5 * tray_v)[:, None], 6, axis=1)       # knee: 2.5 x the tray, in phase
    body = 0.5 * np.sin(w * t) + 0.25 * np.cos(w * t)          # body: tray + a quadrature part
    r = SimpleNamespace(t_s=t, ground_z_um=ground, knee_vz_mm_s=knee, body_z_um=body,
                        scenario=SimpleNamespace(freq_hz=1200.0))
    kg, bg = response_gains(r)
    assert kg == pytest.approx(1.5, rel=1e-4) and bg == pytest.approx(0.5, rel=1e-4)


def test_release_jump():
    t, w = _record()
    ground = 10.0 * np.sin(w * t)
    tray_v = 10.0 * w * np.cos(w * t) * 1e-3
    knee = np.repeat(tray_v[:, None], 6, axis=1)
    contact = np.full((len(t), 6), 2, np.int8)
    k = len(t) - 100
    contact[k:, 0] = 0                               # leg 1 lets go at sample k ...
    knee[k:, 0] += 0.5 * tray_v.max()                # ... and its knee jumps by half the tray's velocity
    r = SimpleNamespace(t_s=t, ground_z_um=ground, knee_vz_mm_s=knee, contact=contact)
    n, jump = release_jumps(r)
    assert n == 1 and jump == pytest.approx(0.5, rel=0.02)
    n0, j0 = release_jumps(SimpleNamespace(t_s=t, ground_z_um=ground, knee_vz_mm_s=knee,
                                           contact=np.full((len(t), 6), 2, np.int8)))
    assert n0 == 0 and math.isnan(j0)


def test_ensemble_pools_the_scenarios_robots(tmp_path):
    """Two seeds x one drawn robot on the Fig. 14 scenario: the nominal value is the scenario's own
    run, the pooled mean speed is the mean of the robots', and each robot is a different draw."""
    p = RobotParams.preset("paper")
    e = score_ensemble(p, EnsembleSpec(draws=1, seeds=(0, 1), duration_s=0.2, scenarios=["paper-fig14"]), workers=1)
    # the same ensemble run one seed at a time and merged scores the same
    parts = [run_ensemble(p, EnsembleSpec(draws=1, seeds=[s], duration_s=0.2, scenarios=["paper-fig14"]), workers=1)
             for s in (0, 1)]
    merged = score_runs(merge_runs(parts))
    assert [x.to_dict() for x in merged.scores] == [x.to_dict() for x in e.scores]
    assert merged.member_metrics == e.member_metrics and merged.settings.seeds == (0, 1)
    s = e.by_id()["fig14_moves_near_438hz"]
    direct = run_scenario("paper-fig14", p, None, quick=True, draws=1, duration_s=0.2, seed=0, workers=1,
                          quiet=True)
    assert s.nominal == pytest.approx(direct.observations[0].value, rel=1e-12)
    members = [m["speed_438_hz_mm_s"] for m in e.member_metrics["paper-fig14"]]
    assert len(members) == 2 and members[0] != members[1]
    assert e.pooled_metrics["paper-fig14"]["speed_438_hz_mm_s"] == pytest.approx(np.mean(members), rel=1e-12)
    assert s.per_seed == pytest.approx([e.member_metrics["paper-fig14"][k]["max_speed_400_480_hz_mm_s"]
                                        for k in range(2)])
    assert e.runs == 3 * 5 and e.cpu_s > 0 and s.robots == 2
    assert sum(e.count().values()) == len(observations("paper-fig14"))
    d = e.to_dict()
    assert d["observations"][0]["state"] in ("met", "not met", "not applicable") and len(d["seed_met"]) == 2


def test_ensemble_score_counts_not_applicable_robots_out():
    """Robots outside the claim's regime neither meet nor fail it: the robots' mean and share met
    are over the robots in the regime; a pooled ensemble outside it is not applicable, not met."""
    from labkit.sim.paper.ensemble import Measured, _score

    o = next(o for o in observations("paper-ablations") if o.id == "ablation_squeeze_slows")

    def m(gain, regime):
        return {o.metric: gain, o.when: float(regime)}

    got = Measured(nominal=m(1.0, 0), pooled=m(0.2, 1), seeds=[m(0.2, 1), m(-1.0, 0)],
                   members=[m(0.5, 1), m(-0.5, 1), m(9.0, 0), m(0.3, 1)])
    s = _score(o, got)
    assert s.nominal_state == NOT_APPLICABLE and s.state == "met"
    assert s.per_seed_states == ["met", NOT_APPLICABLE]
    assert s.robots == 3 and s.mean == pytest.approx(0.1) and s.met_share == pytest.approx(2 / 3)
    assert s.median == pytest.approx(0.3)
    assert s.violation == 0.0
    from labkit.sim.paper.ensemble import EnsembleScore, EnsembleSettings

    out = replace(_score(o, replace(got, pooled=m(1.0, 0))), id="outside")
    assert out.state == NOT_APPLICABLE and out.violation is None
    settings = EnsembleSettings(draws=2, duration_s=1.0, seeds=(0, 1))
    e = EnsembleScore(scores=[s, out], settings=settings, cpu_s=0.0, wall_s=0.0, runs=0)
    assert list(e.violations(not_applicable=0.7).values()) == [0.0, 0.7]
    assert e.count() == {"met": 1, "not met": 0, "not applicable": 1} and e.seed_counts() == [2, 0]


def test_spectrum_peak_needs_a_resonance():
    """A resonance at 440 Hz in a flat background is found; a flat response (the highest point set
    by round-off) has no peak, so the observation is not met rather than met by accident."""
    from labkit.sim.scenarios.paper import peak_at, spectrum_measure

    f = np.array([300, 350, 400, 438, 480, 530, 600, 1000, 1200, 1500, 1650, 1800, 1950, 2200], float)
    w0, zeta = 440.0, 0.05
    reso = 1.0 / np.sqrt((1 - (f / w0) ** 2) ** 2 + (2 * zeta * f / w0) ** 2)
    assert peak_at(f, reso, 350, 600) == 438.0
    flat = 0.52 + 1e-3 * np.sin(f)
    assert math.isnan(peak_at(f, flat, 1500, 2200))
    m = spectrum_measure(_ps(f, [0] * len(f), extra={"knee_gain": flat, "body_gain": reso}))
    states = {c.id: c.state for c in check("paper-spectrum", m)}
    assert states["spectrum_peak_1800hz"] == "not met" and states["spectrum_body_800_1200hz"] == "not met"
