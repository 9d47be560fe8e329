"""B&K 2718 declared configuration and the 4809 envelope."""
from __future__ import annotations

import json
import math

import pytest

from labkit.drivers.shaker import Amplifier2718, Shaker4809Envelope
from labkit.errors import ConfigError, LimitError


def test_amplifier_caps_follow_declared_gain():
    a20 = Amplifier2718(gain_db=20, attenuator_db=0, current_limit_a=2.0)
    a40 = Amplifier2718(gain_db=40, attenuator_db=6, current_limit_a=1.0)
    assert a20.max_input_vrms == 0.8 and a40.max_input_vrms == pytest.approx(0.08)
    assert a20.max_input_vpp == pytest.approx(0.8 * 2 * math.sqrt(2))
    assert a20.voltage_gain == pytest.approx(10.0)
    assert a40.voltage_gain == pytest.approx(10 ** (34 / 20))
    assert Amplifier2718(20, 0, 2.0, max_input_vrms=0.5).max_input_vrms == 0.5


def test_amplifier_input_check_names_limit():
    a = Amplifier2718(gain_db=40, attenuator_db=0, current_limit_a=1.0)
    assert a.check_input(0.2) == 0.2
    with pytest.raises(LimitError) as ei:
        a.check_input(0.3)            # 0.106 V rms > 0.08
    assert ei.value.limit == "amplifier input cap"


@pytest.mark.parametrize("kw, key", [
    ({"gain_db": 30, "attenuator_db": 0, "current_limit_a": 1}, "gain_db"),
    ({"gain_db": 20, "attenuator_db": -3, "current_limit_a": 1}, "attenuator_db"),
    ({"gain_db": 20, "attenuator_db": 0, "current_limit_a": 0}, "current_limit_a"),
])
def test_amplifier_knobs_are_never_guessed(kw, key):
    with pytest.raises(ConfigError) as ei:
        Amplifier2718(**kw)
    assert ei.value.key == key
    with pytest.raises(TypeError):
        Amplifier2718(gain_db=20)     # every knob must be declared


def test_amplifier_snapshot_records_knobs():
    snap = json.loads(json.dumps(Amplifier2718(20, 3, 1.5).snapshot()))
    assert snap["gain_db"] == 20 and snap["attenuator_db"] == 3 and snap["current_limit_a"] == 1.5
    assert snap["declared"] is True and snap["max_input_vrms"] == 0.8


@pytest.mark.parametrize("freq_hz, amp_um, payload_kg, limit", [
    (5.0, 10, 0, "frequency"),
    (25e3, 0.1, 0, "frequency"),
    (20.0, 4100, 0, "stroke"),            # 4 mm peak stroke
    (65.0, 4000.0 * 1.01 * 0 + 4050, 0, "stroke"),
    (68.0, 3900, 0, "velocity"),          # 2 pi 68 * 3.9 mm = 1.67 m/s; force 0.06*712=42.7 N
    (200.0, 600, 0, "force"),             # v = 0.75 m/s, F = 0.06 * 947 = 56.8 N
    (200.0, 400, 0.03, "force"),          # payload: 0.09 kg * 632 = 56.8 N
])
def test_envelope_names_the_limit(freq_hz, amp_um, payload_kg, limit):
    with pytest.raises(LimitError) as ei:
        Shaker4809Envelope().check(freq_hz, amp_um, payload_kg)
    assert ei.value.limit == limit
    assert limit in str(ei.value)


def test_envelope_accepts_inside_and_reports_use():
    env = Shaker4809Envelope()
    used = env.check(240.0, 25.0)
    w = 2 * math.pi * 240
    assert used["stroke"] == pytest.approx(0.025 / 4)
    assert used["velocity"] == pytest.approx(w * 25e-6 / 1.65)
    assert used["force"] == pytest.approx(0.06 * w * w * 25e-6 / 44.5)
    env.check(200.0, 400, payload_kg=0.0)     # same drive, no payload: fine


def test_max_displacement_crossovers():
    env = Shaker4809Envelope()
    assert env.max_disp_amp_um(30) == pytest.approx(4000)           # stroke-limited
    f = 68.0
    assert env.max_disp_amp_um(f) == pytest.approx(1.65 / (2 * math.pi * f) * 1e6)
    f = 500.0
    assert env.max_disp_amp_um(f) == pytest.approx(44.5 / (0.06 * (2 * math.pi * f) ** 2) * 1e6)
    for f in (15, 66, 71, 300, 5000):            # the max itself passes the check
        env.check(f, env.max_disp_amp_um(f) * 0.999)
