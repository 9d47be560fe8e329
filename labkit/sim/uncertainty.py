"""Parameter uncertainty for Monte Carlo sweeps.

The paper's error bars (Fig. 8, 13) come from "the uncertainty of robot
parameters" and "the resolution of fabrication", without a table. This module
makes that table explicit: a relative standard uncertainty per uncertain
:class:`~labkit.sim.RobotParams` field. :func:`draw_params` multiplies each
listed field (each element of a per-mode tuple independently) by a
log-normal factor ``exp(sigma * N(0, 1))`` — positive, median 1, relative
standard deviation ~= sigma for small sigma. Coefficients bounded to (0, 1)
(restitution) are clipped to [0.02, 0.98].

Default relative standard uncertainties (**choices**, documented in
``docs/simulator.md``):

=================================  =====  =======================================
key                                sigma  why
=================================  =====  =======================================
``k_per_s2`` (each mode)           0.05   resonances vary ~2.5 % in frequency
                                          (f ~ sqrt(k)) from robot to robot
``b_per_s`` (each mode)            0.20   damping ratios fitted from broad peaks
``c_ad_n``                         0.50   from prior works, not measured here;
                                          the paper's least certain value
``c_ad_t_n_s``                     0.50   as above
``c_r``, ``c_r_body``              0.20   a modelling choice (model.md)
``b_g_body_n_m2_s``, ``..._foot``  0.30   estimated from geometry (gap cubed)
``a_drag_n_s2_m2``                 0.20   identified from out-of-chip ring-down
``body_mass_mg``                   0.05   fabrication tolerance, 30 um chassis
``leg_mass_mg`` (derived)          0.10   parylene feet vary more than silicon
``foot_pad_um``                    0.20   pad side not given by the paper (model.md
                                          M7); its film goes as side^4
``film_gap_nm``                    0.50   asperity gap from typical roughness,
                                          not measured on the robot or its tray
=================================  =====  =======================================

The total mass follows as body + 6 legs. Draws are independent between
keys and between the modes of a per-mode key.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from labkit.errors import ConfigError

if TYPE_CHECKING:
    from labkit.sim.params import RobotParams

#: Relative standard uncertainty per RobotParams field (see the module doc).
#: ``leg_mass_mg`` is derived (``(mass_mg - body_mass_mg) / 6``): the body and
#: the legs are drawn separately and the total follows, so a draw can never
#: make the body heavier than the robot.
DEFAULT_TABLE: dict[str, float] = {
    "k_per_s2": 0.05,
    "b_per_s": 0.20,
    "c_ad_n": 0.50,
    "c_ad_t_n_s": 0.50,
    "c_r": 0.20,
    "c_r_body": 0.20,
    "b_g_body_n_m2_s": 0.30,
    "b_g_foot_n_m2_s": 0.30,
    "a_drag_n_s2_m2": 0.20,
    "body_mass_mg": 0.05,
    "leg_mass_mg": 0.10,
    "foot_pad_um": 0.20,
    "film_gap_nm": 0.50,
}

#: Fields whose value must stay inside (0, 1).
BOUNDED = {"c_r": (0.02, 0.98), "c_r_body": (0.02, 0.98)}
#: Table keys that are not fields but derived quantities.
DERIVED = {"leg_mass_mg"}


def params_fields(params: RobotParams) -> set[str]:
    """The field names of a RobotParams (a dataclass), without ``provenance``."""
    return {f.name for f in dataclasses.fields(params)} - {"provenance"}


def check_table(params: RobotParams, table: Mapping[str, float]) -> None:
    """Raise :class:`ConfigError` naming the key when a table entry is unusable."""
    names = params_fields(params) | DERIVED
    for key, sigma in table.items():
        if key not in names:
            raise ConfigError("not a RobotParams field", key=key, expected=", ".join(sorted(names)))
        try:
            ok = float(sigma) >= 0 and np.isfinite(float(sigma))
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ConfigError(f"bad relative uncertainty {sigma!r}", key=key,
                              expected="a relative standard uncertainty >= 0 (0.1 = 10 %)")


def draw_params(params: RobotParams, rng: np.random.Generator,
                table: Mapping[str, float] | None = None) -> RobotParams:
    """One random robot: every field in ``table`` scaled by ``exp(sigma * N(0,1))``.

    Parameters
    ----------
    params:
        The nominal RobotParams.
    rng:
        The generator; the same seed gives the same robot. Keys are drawn in
        sorted order so the result does not depend on the table's insertion
        order.
    table:
        Key -> relative standard uncertainty (default :data:`DEFAULT_TABLE`).
        ``body_mass_mg`` and ``leg_mass_mg`` perturb the body and the legs;
        ``mass_mg`` (if listed instead) scales body and legs together.

    Returns
    -------
    RobotParams
        A new parameter set (``params.replace``); the nominal one is untouched.
    """
    table = dict(DEFAULT_TABLE if table is None else table)
    check_table(params, table)
    changes: dict[str, float | tuple[float, ...]] = {}
    factor: dict[str, float] = {}
    for key in sorted(table):
        sigma = float(table[key])
        value = params.leg_mass_mg if key == "leg_mass_mg" else getattr(params, key)
        if isinstance(value, (tuple, list)):
            factors = np.exp(sigma * rng.standard_normal(len(value)))
            changes[key] = tuple(float(v) * float(f) for v, f in zip(value, factors))
            continue
        f = float(np.exp(sigma * rng.standard_normal()))
        if key in ("mass_mg", "body_mass_mg", "leg_mass_mg"):
            factor[key] = f
            continue
        new = float(value) * f
        if key in BOUNDED:
            lo, hi = BOUNDED[key]
            new = float(min(max(new, lo), hi))
        changes[key] = new
    if factor:
        body = params.body_mass_mg * factor.get("body_mass_mg", 1.0) * factor.get("mass_mg", 1.0)
        legs = 6 * params.leg_mass_mg * factor.get("leg_mass_mg", 1.0) * factor.get("mass_mg", 1.0)
        changes.update(body_mass_mg=body, mass_mg=body + legs)
    return params.replace(**changes) if changes else params
