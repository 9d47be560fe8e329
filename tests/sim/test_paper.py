"""The paper as data: the observations table, its tests, the shaker law, presets, the calibration's parts.

No simulation here (fast): laws and closed forms. The scenarios themselves run in
tests/sim/test_paper_scenarios.py.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from clihelpers import run_cli
from labkit.errors import ConfigError, InputError
from labkit.sim import RobotParams
from labkit.sim.paper import fit
from labkit.sim.paper.observations import Observation, check, observations, parse, violation
from labkit.sim.paper.shaker import PAPER_SHAKER, ShakerLaw
from labkit.sim.scenarios import SCENARIOS
from labkit.sim.scenarios.paper import PAPER, fig8_measure, patterns_measure, payload_measure
from labkit.sim.scenarios.runs import PointSet

# --------------------------------------------------------------------------- the table


def test_table_covers_the_issue_and_names_real_scenarios():
    obs = observations()
    assert len({o.id for o in obs}) == len(obs) >= 15
    assert {o.scenario for o in obs} == set(PAPER) <= set(SCENARIOS)
    assert all(o.when is None or o.when != o.metric for o in obs)
    for o in obs:
        assert o.source and o.quote and o.tolerance
        # a number from the paper is inside its own pass band
        if o.paper_value is not None and o.basis == "number":
            assert o.passes(o.paper_value), o.id
    assert observations("paper-fig8")[0].id == "fig8_speed_240hz"
    # the weakest honest form: observations without a paper number are signs, orders or ranges
    assert all(o.basis in ("sign", "order", "range") for o in obs if o.paper_value is None)


def _ps(values, speeds, patterns=None, rise=None, extra=None):
    n = len(values)
    sp = np.asarray(speeds, float).reshape(n, -1)
    d = sp.shape[1]
    pats = np.array(patterns if patterns is not None else [["firm_contact"] * 6] * n).reshape(n, 1, 6)
    pats = np.repeat(pats, d, axis=1)
    r = np.asarray(rise if rise is not None else np.zeros(n), float).reshape(n, 1).repeat(d, axis=1)
    ex = {k: np.asarray(v, float).reshape(n, -1) for k, v in (extra or {}).items()}
    return PointSet(quantity="x", values=np.asarray(values, float), speeds_mm_s=sp, patterns=pats,
                    contact_fraction=np.zeros((n, d, 6, 3)), impacts=np.zeros((n, d, 6)), foot_rise_um=r,
                    leg_motion_um=np.ones((n, d)), aperiodicity=np.zeros((n, d)), extra=ex)


def test_every_metric_of_the_table_is_measured_by_its_scenario():
    abl = [2, 8, 4, 6, 102, 108, 104, 106, 204, 206]
    produced = {"paper-fig8": fig8_measure(_ps([200, 240, 270, 300, 450, 1000], [1, 1, 1, 1, 1, 1])),
                "paper-patterns": patterns_measure(_ps([2, 4, 6, 8], [0, 0, 0, 0])),
                "paper-payload": payload_measure(_ps([0.33, 1.2, 1.7, 2.0], [1, 1, 1, 1])),
                "paper-ablations": PAPER["paper-ablations"].measure(_ps(abl, [1] * len(abl))),
                "paper-fig14": PAPER["paper-fig14"].measure(_ps([400, 438, 480], [1, 1, 1])),
                "paper-spectrum": PAPER["paper-spectrum"].measure(
                    _ps([300, 438, 1200, 1800], [0] * 4, extra={"knee_gain": [1] * 4, "body_gain": [1] * 4}))}
    for o in observations():
        assert o.metric in produced[o.scenario], o.id
        assert o.when is None or o.when in produced[o.scenario], o.id


def test_fig8_metrics_on_a_paper_shaped_curve():
    # falling from 200 Hz, a bump at 300, nothing from 420 Hz
    f = [200, 240, 270, 300, 320, 440, 480, 600, 1000, 1600]
    v = [6.0, 4.0, 1.0, 2.5, 1.5, 0.0, 0.0, 0.0, 0.0, 0.0]
    m = fig8_measure(_ps(f, v))
    assert m["speed_240_hz_mm_s"] == 4.0
    assert m["speed_slope_200_300_hz_mm_s_per_100_hz"] == pytest.approx(
        100 * np.polyfit([200, 240, 270, 300], [6.0, 4.0, 1.0, 2.5], 1)[0])
    assert m["speed_rise_near_300_hz_mm_s"] == pytest.approx(1.5)
    assert all(c.passed for c in check("paper-fig8", m))
    # a peak near the hip resonance instead fails the two 'no motion' observations and the fall
    v2 = [1.0, 2.0, 3.0, 4.0, 5.0, 8.0, 3.0, 0.0, 0.0, 0.0]
    failed = {c.id for c in check("paper-fig8", fig8_measure(_ps(f, v2))) if not c.passed}
    assert {"fig8_falls_from_200hz", "fig8_none_400_500hz"} <= failed
    # no motion at all: slope 0, not a decline
    still = {c.id: c for c in check("paper-fig8", fig8_measure(_ps(f, [0.0] * 10)))}
    assert still["fig8_falls_from_200hz"].state == "not met"


def test_fig8_decline_is_a_fitted_slope_over_200_300_hz():
    """'a fast decline in speed from 200 Hz': the least-squares slope over every point of 200-300 Hz,
    not the ratio of two points; a straight decline gives its own slope back."""
    f = [200, 225, 240, 255, 270, 285, 300, 600]
    line = [6.0 - 0.04 * (x - 200) if x <= 300 else 0.0 for x in f]
    m = fig8_measure(_ps(f, line))
    assert m["speed_slope_200_300_hz_mm_s_per_100_hz"] == pytest.approx(-4.0, rel=1e-9)
    # a peak at 255 Hz over a slow 200 Hz: the speed at 270 is still above 200's, the old ratio test's
    # opposite case; the fitted slope is positive and the claim fails
    peaked = [1.0, 3.0, 5.0, 8.0, 4.0, 2.5, 1.5, 0.0]
    got = {c.id: c for c in check("paper-fig8", fig8_measure(_ps(f, peaked)))}
    assert got["fig8_falls_from_200hz"].value > 0 and got["fig8_falls_from_200hz"].state == "not met"


def test_pattern_metrics_count_order_violations():
    firm, part, jump = (["firm_contact"] * 6, ["partial_contact"] * 6, ["jumping"] * 6)
    extra = {"knee_amp_um": [20, 25, 60, 210], "releases": [0, 12, 30, 40], "release_jump": [np.nan, 0.4, 1, 2]}
    m = patterns_measure(_ps([2, 4, 6, 8], [0] * 4, [firm, part, part, jump], rise=[0, 1, 5, 300], extra=extra))
    assert m == {"firm_share_2v": 1.0, "partial_share_min_4_6v": 1.0, "jumping_share_8v": 1.0,
                 "pattern_order_violations": 0.0, "knee_amplitude_8v_um": 210.0, "foot_rise_8v_um": 300.0,
                 "speed_4v_mm_s": 0.0, "speed_8v_mm_s": 0.0, "releases_4v": 12.0, "released_4v": 1.0,
                 "release_jump_4v": 0.4}
    assert all(c.passed for c in check("paper-patterns", m))
    # partial contact at 4 V only: the smaller of the two shares decides (not the better one)
    one = patterns_measure(_ps([2, 4, 6, 8], [0] * 4, [firm, part, firm, jump], extra=extra))
    assert one["partial_share_min_4_6v"] == 0.0
    assert {c.id: c.state for c in check("paper-patterns", one)}["patterns_partial_at_4_6v"] == "not met"
    # no release at 4 V: the release jump is not applicable, not passed
    calm = patterns_measure(_ps([2, 4, 6, 8], [0] * 4, [firm, firm, part, jump],
                                extra={**extra, "releases": [0, 0, 3, 9], "release_jump": [np.nan] * 4}))
    assert {c.id: c.state for c in check("paper-patterns", calm)}["patterns_release_jump_4v"] == "not applicable"
    back = patterns_measure(_ps([2, 4, 6, 8], [0] * 4, [part, firm, jump, part]))
    assert back["pattern_order_violations"] == 2.0


def test_violation_is_the_distance_outside_the_band():
    two = Observation("x", "s", "m", "src", "q", "number", "t", "both", low=2.0, high=6.0)
    assert violation(two, 4.0) == 0.0 and violation(two, 2.0) == 0.0
    assert violation(two, 1.0) == pytest.approx(0.25)          # 1 below, band width 4
    assert violation(two, 10.0) == pytest.approx(1.0)
    below = Observation("y", "s", "m", "src", "q", "range", "t", "both", high=0.1)
    assert violation(below, 0.05) == 0.0 and violation(below, 0.1) > 0      # strict
    assert violation(below, 0.3) == pytest.approx(2.0)
    assert violation(below, float("nan")) == 3.0 and violation(below, None) == 3.0
    sign = Observation("z", "s", "m", "src", "q", "sign", "t", "both", low=0.0)
    assert violation(sign, 0.0) > 0 and violation(sign, 1e-9) == 0.0


def test_objective_margin_scores_the_edge_of_a_band_but_never_decides_met():
    """The calibration's objective narrows each band by a margin (fit.OBJECTIVE_MARGIN) so its
    search ends inside the band; the observation itself is met on the band as written."""
    two = Observation("x", "s", "m", "src", "q", "number", "t", "both", low=2.0, high=6.0)
    m = 0.05                                                     # 0.2 of the width 4
    assert violation(two, 2.002, m) == pytest.approx(0.198 / 4) and two.passes(2.002)
    assert violation(two, 5.9, m) == pytest.approx(0.1 / 4) and violation(two, 4.0, m) == 0.0
    assert violation(two, 1.0, m) == pytest.approx(1.2 / 4)     # outside: measured from the narrowed edge
    below = Observation("y", "s", "m", "src", "q", "range", "t", "both", high=0.1)
    assert violation(below, 0.099, m) == pytest.approx(0.004 / 0.1) and below.passes(0.099)
    assert violation(below, 0.2, m) == pytest.approx(0.105 / 0.1)
    metrics = {"speed_240_hz_mm_s": 2.002}
    obs = [o for o in observations() if o.metric == "speed_240_hz_mm_s"]
    assert fit.violations(metrics, obs) == {obs[0].id: 0.0}
    assert fit.objective(metrics, obs) == pytest.approx(math.tanh((2.0 + 0.05 * 4 - 2.002) / 4))


@pytest.mark.parametrize("row, key", [
    ({"low": 1.0, "high": 1.0}, "observation[0]"),
    ({"basis": "vibes", "low": 1.0}, "observation[0].basis"),
    ({}, "observation[0]"),
    ({"low": "1", "high": 2.0}, "observation[0].low"),
    ({"low": 1.0, "colour": "red"}, "observation[0]"),
])
def test_bad_table_names_the_key(row, key):
    base = {"id": "a", "scenario": "paper-fig8", "metric": "m", "source": "s", "quote": "q", "basis": "sign",
            "tolerance": "t", "who": "both"}
    with pytest.raises(ConfigError) as e:
        parse({"observation": [{**base, **row}]}, file="obs.toml")
    assert e.value.key == key and "obs.toml" in str(e.value)


# --------------------------------------------------------------------------- the shaker law


def test_shaker_law_reference_point_and_linearity():
    law = PAPER_SHAKER
    assert law.amp_um(240.0) == pytest.approx(25.0, rel=1e-12)
    assert law.amp_um(240.0, 2.0) == pytest.approx(6.25, rel=1e-12)      # linear in the drive
    assert law.accel_g(240.0) == pytest.approx((2 * math.pi * 240) ** 2 * 25e-6 / 9.80665)
    assert law.limited_by(240.0) == "drive"


def test_shaker_law_is_mass_controlled_above_the_suspension():
    law = PAPER_SHAKER
    # the 4809 manual: constant acceleration at constant voltage from 700 Hz (to 5 kHz)
    acc = [law.accel_g(f) for f in (700.0, 1000.0, 2000.0, 5000.0)]
    assert max(acc) / min(acc) < 1.03
    assert law.amp_um(1000.0) / law.amp_um(2000.0) == pytest.approx(4.0, rel=0.01)   # 1/f^2
    # at the suspension resonance the 2nd-order shape is 1/(2 zeta)
    assert law.shape(law.suspension_hz) == pytest.approx(1 / (2 * law.suspension_damping_ratio))
    # the paper's "amplitude falls with frequency": 25 um at 240 Hz, < 2 um at 1 kHz, not 25 um (100 g)
    assert law.amp_um(1000.0) < 2.0
    assert ShakerLaw(suspension_hz=0.0).amp_um(480.0) == pytest.approx(25.0 / 4)


def test_shaker_envelope_caps_large_drives():
    law = PAPER_SHAKER
    f = 1000.0
    w = 2 * math.pi * f
    assert law.amp_um(f, 1e4) == pytest.approx(44.5 / (0.060 * w * w) * 1e6)          # force limit
    assert law.limited_by(f, 1e4) == "force"
    assert law.amp_um(5.0, 8.0) <= 4000.0 and law.limited_by(5.0, 1e4) == "stroke"
    heavy = ShakerLaw(tray_mass_kg=0.060)
    assert heavy.envelope_um(f) == pytest.approx(law.envelope_um(f) / 2)
    with pytest.raises(InputError, match="freq_hz"):
        law.amp_um(-1.0)
    with pytest.raises(InputError, match="suspension_damping_ratio"):
        ShakerLaw(suspension_damping_ratio=0.0)


# --------------------------------------------------------------------------- presets and the calibration's parts


def test_presets():
    from labkit.sim.presets import preset_names

    assert RobotParams.preset("published") == RobotParams()
    assert "published" in preset_names()
    with pytest.raises(ConfigError) as e:
        RobotParams.preset("nonesuch")
    assert e.value.key == "preset" and "published" in e.value.expected


def test_free_parameters_round_trip():
    from labkit.sim.paper.fit import FREE, apply, current

    ref = RobotParams()
    values = {f.name: f.from_unit(0.3) for f in FREE}
    p = apply(ref, values)
    for f in FREE:
        assert current(p, ref, f) == pytest.approx(values[f.name]), f.name
        assert f.from_unit(f.to_unit(values[f.name])) == pytest.approx(values[f.name])
        assert f.lo <= f.from_unit(-1.0) <= f.from_unit(2.0) <= f.hi
    assert p.c_r == p.c_r_body
    assert p.b_g_body_n_m2_s / ref.b_g_body_n_m2_s == pytest.approx(values["squeeze_scale"])


def test_cli_bad_params_and_calibrate_modes(tmp_path):
    proc = run_cli("simulate", "shaker", "--params", "nonesuch", "--duration-s", "0.01", check=2)
    assert "nonesuch" in proc.stderr and "published" in proc.stderr and proc.stderr.count("\n") == 1
    proc = run_cli("calibrate", "--out", str(tmp_path / "x.toml"), check=2)
    assert "MEASURED" in proc.stderr
    proc = run_cli("calibrate", "--paper", "--fit", "c_r", "--out", str(tmp_path / "x.toml"), check=2)
    assert "--paper" in proc.stderr
    proc = run_cli("calibrate", "--paper", "--free", "gravity", "--out", str(tmp_path / "x.toml"), check=2)
    assert "gravity" in proc.stderr and "c_ad_n" in proc.stderr
    proc = run_cli("calibrate", "--paper", "--paper-ensemble", "2", "--paper-duration-s", "0", "--out",
                   str(tmp_path / "x.toml"), check=2)
    assert "--paper-duration-s" in proc.stderr and proc.stderr.count("\n") == 1
    assert not (tmp_path / "x.toml").exists()


def test_search_box_narrows_a_free_parameter_inside_its_bounds(tmp_path):
    """A bounded search around a start (``--bound`` with ``--paper``): the box maps [0, 1] onto
    itself, and a box outside the physical bounds, on a sign or on a parameter not free is one
    line naming --bound, nothing written."""
    from labkit.sim.paper.fit import _free_params

    ad, sq = _free_params(["c_ad_n", "squeeze_scale"], {"c_ad_n": (2e-6, 6e-6)})
    assert (ad.lo, ad.hi, ad.log) == (2e-6, 6e-6, True)
    assert ad.from_unit(0.0) == pytest.approx(2e-6) and ad.from_unit(1.0) == pytest.approx(6e-6)
    assert ad.from_unit(0.5) == pytest.approx((2e-6 * 6e-6) ** 0.5)         # log scale: the geometric mean
    assert (sq.lo, sq.hi) == (0.1, 10.0)                                     # no box: its physical bounds
    for box in ({"c_ad_n": (1e-9, 6e-6)}, {"c_ad_n": (6e-6, 2e-6)}, {"c_r": (0.2, 0.5)}):
        with pytest.raises(InputError) as e:
            _free_params(["c_ad_n", "squeeze_scale"], box)
        assert e.value.key == "--bound"
    with pytest.raises(InputError, match="signs"):
        _free_params(["cy_sign[1]"], {"cy_sign[1]": (-1.0, 1.0)})
    proc = run_cli("calibrate", "--paper", "--free", "c_ad_n", "--bound", "c_ad_n=1e-3:2e-3", "--out",
                   str(tmp_path / "x.toml"), check=2)
    assert "--bound" in proc.stderr and "c_ad_n" in proc.stderr and proc.stderr.count("\n") == 1
    assert not (tmp_path / "x.toml").exists()


def test_scales_are_relative_to_the_published_set_whatever_the_start():
    """A search started from another robot (the ``paper`` preset, a user's file) sets the free
    parameters of that robot, with the films' and the actuator's scales (and so their bounds)
    relative to Tables 1-2: squeeze_scale 1 is the published film, from any start."""
    from labkit.sim.paper.fit import FREE, apply, current

    published = RobotParams()
    start = RobotParams.preset("paper").replace(k_per_s2=(8e6, 6e7, 1.3e8))
    p = apply(start, {"squeeze_scale": 1.0, "act_scale": 2.0}, published)
    assert p.b_g_foot_n_m2_s == published.b_g_foot_n_m2_s and p.b_g_body_n_m2_s == published.b_g_body_n_m2_s
    assert p.act_um_per_v == tuple(2.0 * a for a in published.act_um_per_v)
    assert p.k_per_s2 == (8e6, 6e7, 1.3e8) and p.c_ad_n == start.c_ad_n      # the rest is the start's
    squeeze = next(f for f in FREE if f.name == "squeeze_scale")
    assert current(start, published, squeeze) == pytest.approx(start.b_g_foot_n_m2_s / published.b_g_foot_n_m2_s)
