"""Which fitted mode becomes which of the simulator's three modes.

The tethered robot's in-chip modes are not the released robot's (model.md
section 9: the tether mode ~830 Hz and the in-chip knee mode ~3.4 kHz exist
only in-chip), so the person decides, and the parameter file records it.

``--assign`` syntax: comma-separated ``SIM=WHAT`` items, ``SIM`` in 1, 2, 3:

* ``1=438``    the fitted mode nearest 438 Hz (it must lie within 10 %),
* ``2=#3``     fitted mode number 3 of the listing (1-based, as printed),
* ``3=keep``   keep the base parameter file's mode 3;

sim modes not named keep the base values.  ``--assign none`` keeps all three.

Default (no ``--assign``): each sim mode takes the fitted mode nearest its
base frequency if one lies within :data:`DEFAULT_TOLERANCE` (15 %), released
robot (shaker) fits before tethered (in-chip) ones, closest pairs first, each
fitted mode used once; any other sim mode keeps its base value.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from labkit.errors import InputError

__all__ = ["FittedMode", "parse_assign", "assign", "DEFAULT_TOLERANCE", "RULE_DEFAULT"]

DEFAULT_TOLERANCE = 0.15
NAMED_TOLERANCE = 0.10
RULE_DEFAULT = ("default: each simulator mode takes the fitted mode nearest its base frequency within "
                f"{DEFAULT_TOLERANCE:.0%} (shaker/released fits first, closest first, each used once); "
                "others keep the base values")
_GROUP_RANK = {"shaker": 0, "inchip": 1}


@dataclass
class FittedMode:
    index: int                 # 1-based, as listed
    group: str                 # inchip | shaker
    freq_hz: float
    damping_ratio: float


def parse_assign(spec: str | None) -> dict[int, tuple[str, float]] | None:
    """``{sim_mode: ("hz", f) | ("index", k) | ("keep", 0)}``; ``None`` for the default rule."""
    if spec is None:
        return None
    text = spec.strip()
    if text.lower() in ("none", "keep"):
        return {1: ("keep", 0.0), 2: ("keep", 0.0), 3: ("keep", 0.0)}
    out: dict[int, tuple[str, float]] = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        if "=" not in item:
            raise InputError(f"bad item {item!r}", key="--assign", expected="SIM=HZ, SIM=#INDEX or SIM=keep")
        left, right = (s.strip() for s in item.split("=", 1))
        if left not in ("1", "2", "3"):
            raise InputError(f"bad simulator mode {left!r}", key="--assign", expected="1, 2 or 3")
        sim = int(left)
        if sim in out:
            raise InputError(f"simulator mode {sim} named twice", key="--assign", expected="each at most once")
        low = right.lower()
        try:
            if low == "keep":
                out[sim] = ("keep", 0.0)
            elif low.startswith("#"):
                out[sim] = ("index", float(int(low[1:])))
            else:
                hz = float(low[:-2] if low.endswith("hz") else low)
                if not hz > 0:
                    raise ValueError
                out[sim] = ("hz", hz)
        except ValueError:
            raise InputError(f"bad value {right!r} for mode {sim}", key="--assign",
                             expected="a frequency in Hz (438), a fitted mode number (#2) or keep") from None
    return out


def assign(fitted: Sequence[FittedMode], base_freq_hz: Sequence[float],
           spec: dict[int, tuple[str, float]] | None) -> dict[int, FittedMode | None]:
    """Map simulator modes 1-3 to fitted modes (``None``: keep the base value)."""
    result: dict[int, FittedMode | None] = {1: None, 2: None, 3: None}
    if spec is None:
        pairs = []
        for sim in (1, 2, 3):
            fb = base_freq_hz[sim - 1]
            for fm in fitted:
                rel = abs(fm.freq_hz - fb) / fb
                if rel <= DEFAULT_TOLERANCE:
                    pairs.append((_GROUP_RANK.get(fm.group, 2), rel, sim, fm))
        used: set[int] = set()
        for _, _, sim, fm in sorted(pairs, key=lambda t: (t[0], t[1])):
            if result[sim] is None and fm.index not in used:
                result[sim] = fm
                used.add(fm.index)
        return result
    by_index = {fm.index: fm for fm in fitted}
    taken: dict[int, int] = {}
    for sim, (how, val) in sorted(spec.items()):
        if how == "keep":
            continue
        if how == "index":
            found = by_index.get(int(val))
            if found is None:
                raise InputError(f"no fitted mode #{int(val)} for simulator mode {sim}", key="--assign",
                                 expected=f"a number from 1 to {len(fitted)}")
            fm = found
        else:
            if not fitted:
                raise InputError("no fitted modes to assign", key="--assign")
            fm = min(fitted, key=lambda m: abs(m.freq_hz - val))
            if abs(fm.freq_hz - val) / val > NAMED_TOLERANCE:
                raise InputError(f"no fitted mode within {NAMED_TOLERANCE:.0%} of {val:g} Hz for simulator "
                                 f"mode {sim} (nearest {fm.freq_hz:.4g} Hz)", key="--assign",
                                 expected="a fitted frequency (see the listing) or #INDEX")
        if fm.index in taken:
            raise InputError(f"fitted mode #{fm.index} assigned to modes {taken[fm.index]} and {sim}",
                             key="--assign", expected="each fitted mode used once")
        taken[fm.index] = sim
        result[sim] = fm
    return result


def describe(spec_text: str | None) -> str:
    return RULE_DEFAULT if spec_text is None else f"--assign {spec_text}"


def as_dict(result: dict[int, FittedMode | None]) -> dict[str, Any]:
    return {str(k): (None if v is None else v.index) for k, v in result.items()}
