"""How the report writes numbers: one function for a value with its uncertainty, one for a bare value.

Figures, tables and the command line all go through :func:`format_uncertain`, so a mode
reads ``452.0 ± 0.04 Hz`` everywhere and never carries seven significant figures.
"""
from __future__ import annotations

import math

PLUS_MINUS = "\u00b1"


def _finite(x: float | None) -> bool:
    return x is not None and isinstance(x, (int, float)) and math.isfinite(x)


def uncertainty_decimals(std: float) -> int:
    """Decimal places at which a value with standard uncertainty ``std`` is rounded.

    The uncertainty keeps one significant digit, two when that digit would be a 1
    (0.14 rounded to 0.1 would understate it by 30 %; the Particle Data Group rounds
    similarly). Negative results mean tens, hundreds, ...
    """
    exp = math.floor(math.log10(abs(std)))
    lead = int(abs(std) / 10 ** exp + 1e-9)
    digits = 2 if lead == 1 else 1
    dec = digits - 1 - exp
    # rounding can carry into the next digit (0.96 -> 1.0): recompute on the rounded value
    rounded = round(abs(std), dec)
    if rounded > 0 and math.floor(math.log10(rounded)) != exp:
        exp2 = math.floor(math.log10(rounded))
        lead2 = int(rounded / 10 ** exp2 + 1e-9)
        dec = (2 if lead2 == 1 else 1) - 1 - exp2
    return dec


def format_value(value: float | int | None, digits: int = 4) -> str:
    """A bare number with ``digits`` significant figures ("n/a" for None/NaN)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    if isinstance(value, bool) or isinstance(value, int):
        return str(value)
    return f"{value:.{digits}g}"


def format_uncertain(value: float | None, std: float | None, unit: str = "", *, digits: int = 4) -> str:
    """``value ± std unit`` with the significant figures set by the uncertainty.

    >>> format_uncertain(452.0667, 0.3123, "Hz")
    '452.1 ± 0.3 Hz'
    >>> format_uncertain(0.220023, 6.7e-5)
    '0.22002 ± 0.00007'
    >>> format_uncertain(1834.2, 14.6, "Hz")
    '1834 ± 15 Hz'
    >>> format_uncertain(12345.0, 340.0)
    '12300 ± 300'

    Without a usable uncertainty (None, NaN, zero) the value alone, with ``digits``
    significant figures. Very small or large values are written as ``(m ± s)e±k``.
    """
    tail = f" {unit}" if unit else ""
    if not _finite(value):
        return "n/a"
    assert value is not None
    if not _finite(std) or std == 0:
        return format_value(float(value), digits) + tail
    assert std is not None
    std = abs(float(std))
    big = max(abs(value), std)
    if big >= 1e6 or big < 1e-3:
        k = math.floor(math.log10(big))
        inner = format_uncertain(value / 10 ** k, std / 10 ** k)
        return f"({inner})e{k:+d}{tail}"
    dec = uncertainty_decimals(std)
    if dec > 0:
        return f"{value:.{dec}f} {PLUS_MINUS} {std:.{dec}f}{tail}"
    step = 10 ** (-dec)
    v = int(round(value / step) * step)
    s = int(round(std / step) * step)
    return f"{v} {PLUS_MINUS} {s}{tail}"
