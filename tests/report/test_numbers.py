"""One way to write a value with its uncertainty: significant figures set by the uncertainty."""
from __future__ import annotations

import math

import pytest

from labkit.analysis.report.numbers import format_uncertain, format_value, uncertainty_decimals


@pytest.mark.parametrize("value, std, unit, text", [
    (452.0667, 0.3123, "Hz", "452.1 \u00b1 0.3 Hz"),          # the example
    (451.9667, 0.0407, "Hz", "451.97 \u00b1 0.04 Hz"),
    (0.220023, 6.7e-5, "", "0.22002 \u00b1 0.00007"),
    (1834.2, 14.6, "Hz", "1834 \u00b1 15 Hz"),                # leading 1: two digits
    (12345.0, 340.0, "", "12300 \u00b1 300"),                 # rounded to the hundreds
    (3.0, 0.96, "", "3.0 \u00b1 1.0"),                        # 0.96 rounds up to 1.0: one more digit
    (4.78, 0.0486, "mm/s", "4.78 \u00b1 0.05 mm/s"),
    (-2.5e-5, 3e-6, "", "(-2.5 \u00b1 0.3)e-5"),
])
def test_format_uncertain(value, std, unit, text):
    assert format_uncertain(value, std, unit) == text


def test_without_uncertainty_the_value_alone():
    assert format_uncertain(452.0667, None, "Hz") == "452.1 Hz"
    assert format_uncertain(452.0667, float("nan")) == "452.1"
    assert format_uncertain(452.0667, 0.0) == "452.1"
    assert format_uncertain(None, 0.1) == "n/a" and format_uncertain(float("inf"), 0.1) == "n/a"
    assert format_value(None) == "n/a" and format_value(3) == "3" and format_value(0.123456) == "0.1235"


def test_the_value_is_never_rounded_beyond_its_uncertainty():
    for std in (0.0011, 0.019, 0.25, 3.3, 47.0, 999.0):
        dec = uncertainty_decimals(std)
        step = 10.0 ** -dec
        # the rounding step is at most the uncertainty and more than a twentieth of it
        assert step <= std * 1.0001 or math.isclose(round(std, dec), step * round(std / step))
        assert step > std / 20
