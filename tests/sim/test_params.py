"""RobotParams: paper defaults, derived modal quantities, TOML files, validation."""
from __future__ import annotations

import math

import pytest

from labkit.errors import ConfigError, InputError
from labkit.sim import PZT, RobotParams, Shaker


def test_defaults_are_the_papers_tables():
    p = RobotParams()
    assert p.mass_mg == 0.33 and p.body_mass_mg == 0.28
    assert p.k_per_s2 == (7.57e6, 5.68e7, 1.28e8)
    assert p.b_per_s == (1.38e3, 1.76e3, 2.97e3)
    assert p.ratio == pytest.approx((15, 1 / 17, 1 / 15))
    assert (p.b_g_body_n_m2_s, p.b_g_foot_n_m2_s) == (1.5e-19, 2.5e-19)
    assert (p.a_drag_n_s2_m2, p.c_ad_n, p.c_ad_t_n_s) == (4.55e-6, 50e-6, 1e-7)
    # model.md: 438 Hz, 1.20 kHz, 1.80 kHz; damping ratios 0.25, 0.12, 0.13
    assert p.modal_freq_hz == pytest.approx((438, 1200, 1800), rel=2e-3)
    assert p.modal_damping_ratio == pytest.approx((0.25, 0.12, 0.13), abs=0.012)
    assert (p.lateral_mode, p.vertical_mode) == (0, 1)


def test_with_modes_maps_frequency_and_damping():
    p = RobotParams().with_modes(freq_hz=(400.0, 1100.0, 2000.0), damping_ratio=(0.1, 0.2, 0.05))
    assert p.k_per_s2[2] == pytest.approx((2 * math.pi * 2000) ** 2)
    assert p.b_per_s[1] == pytest.approx(2 * 0.2 * 2 * math.pi * 1100)
    assert p.modal_freq_hz == pytest.approx((400, 1100, 2000))
    assert p.modal_damping_ratio == pytest.approx((0.1, 0.2, 0.05))
    # one argument keeps the other quantity
    q = RobotParams().with_modes(freq_hz=(400.0, 1100.0, 2000.0))
    assert q.modal_damping_ratio == pytest.approx(RobotParams().modal_damping_ratio)


def test_replace_validates():
    p = RobotParams().replace(c_r=0.3, c_ad_n=20e-6)
    assert (p.c_r, p.c_ad_n) == (0.3, 20e-6)
    with pytest.raises(ConfigError, match="c_r"):
        RobotParams().replace(c_r=1.5)
    with pytest.raises(ConfigError, match="unknown"):
        RobotParams().replace(c_rr=0.3)
    with pytest.raises(ConfigError, match="body_mass_mg"):
        RobotParams().replace(body_mass_mg=0.4)


def test_toml_round_trip_with_provenance(tmp_path):
    p = RobotParams().with_modes(freq_hz=(438.0, 1200.0, 1800.0), damping_ratio=(0.25, 0.12, 0.13))
    path = p.to_toml(tmp_path / "robot.toml", provenance={"run": "runs/a.h5", "fit": "rfp", "quality": 0.97})
    text = path.read_text()
    assert "[provenance]" in text and "k_per_s2" in text
    q = RobotParams.from_toml(path)
    assert q == p
    assert q.provenance == {"run": "runs/a.h5", "fit": "rfp", "quality": 0.97}
    # provenance travels on: a copy written again keeps it
    q.to_toml(tmp_path / "again.toml")
    assert RobotParams.from_toml(tmp_path / "again.toml").provenance["fit"] == "rfp"


def test_partial_file_keeps_defaults(tmp_path):
    f = tmp_path / "r.toml"
    f.write_text("c_ad_n = 5e-8\nmu = inf\n")
    p = RobotParams.from_toml(f)
    assert p.c_ad_n == 5e-8 and p.k_per_s2 == RobotParams().k_per_s2 and math.isinf(p.mu)


@pytest.mark.parametrize("line, key, expected", [
    ("bogus_mm = 1", "bogus_mm", "one of"),
    ("mass_mg = -0.3", "mass_mg", "in mg, > 0"),
    ("body_mass_mg = 0", "body_mass_mg", "in mg, > 0"),
    ("ratio = [15, 0, 0.0667]", "ratio[1]", "> 0"),
    ("c_r = \"half\"", "c_r", "a number in 1"),
    ("k_per_s2 = [1e6, 2e6]", "k_per_s2", "3 numbers"),
    ("c_ad_n = true", "c_ad_n", "a number in N"),
    ("cy_sign = [1, 0.5, 1]", "cy_sign[1]", "-1, 0 or +1"),
    ("provenance = 3", "provenance", "[provenance] table"),
])
def test_bad_files_name_file_key_and_expectation(tmp_path, line, key, expected):
    f = tmp_path / "bad.toml"
    f.write_text(line + "\n")
    with pytest.raises(ConfigError) as info:
        RobotParams.from_toml(f)
    msg = str(info.value)
    assert str(f) in msg and f"'{key}'" in msg and expected in msg
    assert isinstance(info.value, InputError)   # -> CLI exit 2


def test_missing_and_invalid_toml_files(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        RobotParams.from_toml(tmp_path / "nope.toml")
    f = tmp_path / "broken.toml"
    f.write_text("mass_mg = = 1\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        RobotParams.from_toml(f)


def test_scenarios_validate():
    assert Shaker(freq_hz=240, amp_um=25).to_dict() == {"kind": "shaker", "freq_hz": 240.0, "amp_um": 25.0}
    assert PZT(freq_hz=1800, voltage_v=20, mass_mg=1.2).mass_mg == 1.2
    with pytest.raises(InputError, match="freq_hz"):
        Shaker(freq_hz=0, amp_um=25)
    with pytest.raises(InputError, match="amp_um"):
        Shaker(freq_hz=240, amp_um=-1)
    with pytest.raises(InputError, match="voltage_v"):
        PZT(freq_hz=1800, voltage_v="x")
