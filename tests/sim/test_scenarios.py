"""Named scenarios (labkit.sim.scenarios): short runs produce their labelled outputs.

The classic scenarios run here at their quick size; the paper scenarios (slower: real
observation metrics) in tests/sim/test_paper_scenarios.py."""
from __future__ import annotations

import h5py
import numpy as np
import pytest

from labkit.errors import InputError
from labkit.sim import RobotParams
from labkit.sim.scenarios import SCENARIOS, ScenarioResult, ablate, aperiodicity, run_scenario
from labkit.sim.scenarios.classic import ADHESION_FIELD

CLASSIC = [n for n in SCENARIOS if not n.startswith("paper-")]


def test_aperiodicity_oracles():
    t = np.arange(0, 0.1, 1e-5)
    f = 240.0
    assert aperiodicity(t, np.sin(2 * np.pi * f * t), f) < 1e-3
    # a period-2 subharmonic is periodic too
    assert aperiodicity(t, np.sin(np.pi * f * t) + np.sin(2 * np.pi * f * t), f) < 1e-3
    noise = np.random.default_rng(0).standard_normal(t.size)
    assert aperiodicity(t, noise, f) > 1.0
    assert np.isnan(aperiodicity(t[:500], np.sin(2 * np.pi * f * t[:500]), f))


def test_ablate_zeroes_the_forces():
    p = RobotParams()
    noad = ablate(p, "no_adhesion")
    assert getattr(noad, ADHESION_FIELD) == 0.0
    assert getattr(p, ADHESION_FIELD) > 0
    nosq = ablate(p, "no-squeeze-film")
    zeroed = [f for f in vars(p) if getattr(nosq, f) != getattr(p, f)]
    # the body's film, the leg's and the foot pad's (docs/model.md M7)
    assert sorted(zeroed) == ["b_g_body_n_m2_s", "b_g_foot_n_m2_s", "foot_pad_um"]
    assert all(getattr(nosq, f) == 0.0 for f in zeroed)
    assert ablate(p, "none") is p
    with pytest.raises(InputError, match="ablation"):
        ablate(p, "no_gravity")


def test_one_ablate():
    import labkit.sim.core
    import labkit.sim.scenarios

    assert labkit.sim.scenarios.ablate is labkit.sim.core.ablate


@pytest.mark.parametrize("name", CLASSIC)
def test_quick_scenario_outputs(name, tmp_path):
    res = run_scenario(name, out_dir=tmp_path, quick=True, workers=1, quiet=True)
    assert isinstance(res, ScenarioResult)
    s = res.summary()
    assert s["name"] == name and s["quick"] is True
    assert s["finding"] and isinstance(s["checks"], dict)
    assert all(isinstance(v, bool) for v in s["checks"].values())
    png = tmp_path / f"sim_{name}.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size < 150_000
    with h5py.File(s["data"]) as f:
        assert str(f.attrs["kind"]).startswith("sim_")


def test_leg_patterns_labels_per_amplitude(tmp_path):
    s = run_scenario("leg-patterns", out_dir=None, quick=True, workers=1, quiet=True).summary()
    assert len(s["dominant_pattern"]) == len(s["amps_um"])
    assert set(s["dominant_pattern"]) <= {"firm_contact", "partial_contact", "jumping"}
    for share in zip(*s["pattern_share"].values()):
        assert sum(share) == pytest.approx(1.0)


def test_unknown_scenario():
    with pytest.raises(InputError, match="scenario"):
        run_scenario("moonwalk", out_dir=None)


def test_fig8_checks_on_synthetic_curves():
    from labkit.sim.scenarios import fig8_checks

    f = np.array([150.0, 240.0, 300.0, 600.0, 1200.0, 1800.0])
    assert fig8_checks(f, [1.0, 4.0, 2.0, 0.0, 0.01, 0.0]) == {
        "mm_s_between_150_and_300_hz": True, "none_from_500_hz_to_1800_hz": True}
    assert fig8_checks(f, [0.0, 0.01, 0.0, 0.0, 0.0, 0.0])["mm_s_between_150_and_300_hz"] is False
    assert fig8_checks(f, [1.0, 4.0, 2.0, 0.0, 3.0, 0.0])["none_from_500_hz_to_1800_hz"] is False
