"""labkit.analysis.compare: metrics on arrays with known answers."""
from __future__ import annotations

import numpy as np
import pytest

from labkit.analysis import compare


def test_speed_agreement_known_errors():
    f = np.array([150.0, 200.0, 250.0, 300.0])
    meas = np.array([2.0, 4.0, 3.0, 1.0])
    sim_f = np.array([100.0, 200.0, 300.0])
    sim = np.array([1.0, 5.0, 1.0])                       # interpolates to 3, 5, 3, 1
    out = compare.speed_agreement(f, meas, meas - 0.5, meas + 0.5, sim_f, sim, sim - 0.6, sim + 0.6,
                                  provenance={"measured": ["a.h5"], "simulated": ["s.h5"]})
    err = np.array([1.0, 1.0, 0.0, 0.0])
    assert out.n_points == 4 and out.n_outside_range == 0
    assert out.rms_error_mm_s == pytest.approx(np.sqrt(np.mean(err ** 2)))
    assert out.mean_error_mm_s == pytest.approx(0.5)
    assert out.relative_rms_error == pytest.approx(np.sqrt(0.5) / np.sqrt(np.mean(meas ** 2)))
    assert out.correlation == pytest.approx(np.corrcoef(meas, [3, 5, 3, 1])[0, 1])
    # inside band (+-0.6): only the two exact points
    assert out.fraction_inside_band == pytest.approx(0.5)
    # CI (+-0.5) overlaps the band (+-0.6) when |err| <= 1.1: all four
    assert out.fraction_ci_overlaps_band == pytest.approx(1.0)
    assert out.provenance["measured"] == ["a.h5"]


def test_speed_agreement_leaves_out_points_outside_sim_range():
    out = compare.speed_agreement([50.0, 200.0, 900.0], [1.0, 2.0, 0.0], None, None,
                                  [100.0, 300.0], [2.0, 2.0], [1.5, 1.5], [2.5, 2.5])
    assert out.n_points == 1 and out.n_outside_range == 2
    assert out.rms_error_mm_s == pytest.approx(0.0)
    assert out.correlation is None                     # undefined with one point


def test_band_from_draws():
    s = np.array([[1.0, 3.0], [2.0, 2.0]])
    mean, lo, hi = compare.band_from_draws(s, k=1.0)
    assert mean.tolist() == [2.0, 2.0]
    assert lo[0] == pytest.approx(2 - np.sqrt(2)) and hi[1] == pytest.approx(2.0)


def test_pattern_agreement_and_confusion():
    out = compare.pattern_agreement(["firm_contact", "jumping", "partial_contact"],
                                    ["firm_contact", "partial_contact", "partial_contact"], keys=[2, 8, 4])
    assert out.fraction_agree == pytest.approx(2 / 3)
    assert out.confusion["jumping"]["partial_contact"] == 1
    with pytest.raises(ValueError, match="unknown pattern"):
        compare.pattern_agreement(["walking"], ["jumping"])


def test_fundamental_and_knee_agreement_phase_and_amplitude():
    f = 240.0
    tm = np.arange(0, 0.05, 1e-5) + 0.0123                 # measured record starts anywhere
    ts = np.arange(0, 0.05, 2e-5)
    tray_m = 37.7 * np.cos(2 * np.pi * f * tm)              # tray velocity of a sin displacement
    tray_s = 37.7 * np.cos(2 * np.pi * f * ts)
    knee_m = 60.0 * np.cos(2 * np.pi * f * tm - 0.5)
    knee_s = 30.0 * np.cos(2 * np.pi * f * ts - 0.8)
    out = compare.knee_motion_agreement(tm, knee_m, ts, knee_s, f, ref_meas=tray_m, ref_sim=tray_s)
    assert out.amplitude_meas_mm_s == pytest.approx(60.0, rel=1e-6)
    assert out.amplitude_ratio == pytest.approx(0.5, rel=1e-6)
    assert out.phase_meas_deg == pytest.approx(np.degrees(-0.5), abs=1e-6)
    assert out.phase_diff_deg == pytest.approx(np.degrees(-0.3), abs=1e-6)
    assert 0.9 < out.correlation < 1.0
    # anti-phase knee: correlation near -1
    out2 = compare.knee_motion_agreement(tm, -knee_m, ts, knee_s, f, ref_meas=tray_m, ref_sim=tray_s)
    assert out2.correlation < -0.9


def test_classify_knee_pattern():
    f = 200.0
    t = np.arange(0, 0.1, 1e-5)
    tray = np.cos(2 * np.pi * f * t)
    assert compare.classify_knee_pattern(t, tray * 1.05, tray, f)["pattern"] == "firm_contact"
    noisy = 1.5 * np.cos(2 * np.pi * f * t - 0.3) + 0.015 * np.random.default_rng(0).standard_normal(t.size)
    assert compare.classify_knee_pattern(t, noisy, tray, f)["pattern"] == "firm_contact"   # 1.4 % noise
    clipped = np.minimum(1.5 * tray, 1.0)                  # flattened tops: leaves the ground each cycle
    assert compare.classify_knee_pattern(t, clipped, tray, f)["pattern"] == "partial_contact"
    partial = tray.copy()
    partial[np.mod(t * f, 1.0) > 0.6] += 1.0               # lets go for 40 % of every cycle
    assert compare.classify_knee_pattern(t, partial, tray, f)["pattern"] == "partial_contact"
    jump = tray + 5.0 * np.sin(2 * np.pi * f / 3 * t)      # slow, large excursions: > 1 period away
    assert compare.classify_knee_pattern(t, jump, tray, f)["pattern"] == "jumping"
    assert compare.dominant_pattern(np.array([["jumping", "firm_contact"], ["jumping", "x"]])) == "jumping"


def test_draw_percentiles_and_coverage():
    # 4 draws at two frequencies, linear in between
    sim_f = np.array([100.0, 200.0])
    draws = np.array([[1.0, 2.0, 3.0, 4.0], [3.0, 4.0, 5.0, 6.0]])
    pct = compare.draw_percentiles([100.0, 150.0, 200.0, 250.0], [2.5, 0.0, 6.0, 5.0], sim_f, draws)
    # 2.5 beats two of four draws; 0 beats none; 6 ties the largest (mid-rank 3.5 of 4); 250 Hz is outside
    assert pct[:3].tolist() == [50.0, 0.0, 87.5] and np.isnan(pct[3])
    cov = compare.coverage(pct, [True, False, True], (10.0, 90.0))
    assert cov.fraction_inside == pytest.approx(2 / 3) and cov.expected_fraction == pytest.approx(0.8)
    assert cov.median_percentile == pytest.approx(50.0)
    lo, hi = compare.percentile_band(draws, (10.0, 90.0))
    assert lo.tolist() == pytest.approx([1.3, 3.3]) and hi.tolist() == pytest.approx([3.7, 5.7])


def test_tolerances_and_verdicts():
    t = compare.Tolerances.from_mapping({"knee_phase_deg_max": 15})
    assert t.knee_phase_deg_max == 15.0 and t.speed_relative_rms_max == 0.30
    with pytest.raises(ValueError, match="unknown tolerance nope"):
        compare.Tolerances.from_mapping({"nope": 1})
    with pytest.raises(ValueError, match="band_lo_pct"):
        compare.Tolerances.from_mapping({"band_lo_pct": 95})
    assert compare.verdict(0.2, at_most=0.3) == "pass" and compare.verdict(0.4, at_most=0.3) == "fail"
    assert compare.verdict(1.0, at_least=0.75, at_most=1.33) == "pass"
    assert compare.verdict(None, at_most=1) == "n/a" and compare.verdict(float("nan"), at_least=0) == "n/a"


def test_results_to_dict_json_in_field_order():
    """agreement.json holds each result's to_dict(): fields in order, tuples as lists, nested results as dicts."""
    import json

    out = compare.pattern_agreement(["jumping", "firm_contact"], ["jumping", "partial_contact"],
                                    keys=[240.0, "8 V"], provenance={"measured": ["a.h5"]})
    d = out.to_dict()
    assert list(d) == ["n", "fraction_agree", "confusion", "pairs", "provenance"]
    assert d["pairs"] == [{"key": 240.0, "measured": "jumping", "simulated": "jumping", "agree": True},
                          {"key": "8 V", "measured": "firm_contact", "simulated": "partial_contact", "agree": False}]
    assert json.loads(json.dumps(d)) == d
    speed = compare.speed_agreement([150.0], [2.0], None, None, [100.0, 200.0], [2.0, 2.0], [1.0, 1.0], [3.0, 3.0])
    sd = speed.to_dict()
    assert isinstance(sd["points"], list) and sd["points"][0]["inside_band"] is True
    assert list(sd)[-3:] == ["points", "method", "provenance"]
