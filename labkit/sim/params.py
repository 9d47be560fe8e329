"""The robot's parameter set: defaults, TOML files with provenance, validation.

Defaults are the paper's Tables 1 and 2 (Qu, Choi, Oldham 2017) plus the
documented choices of ``docs/model.md`` (each a named field below, never a
buried constant). Per-mode quantities are 3-tuples in the order of the
paper's modes: mode 1 = hip (lateral) 438 Hz, mode 2 = foot tilt (first
vertical) 1.20 kHz, mode 3 = leg bending 1.80 kHz.

A parameter file is flat TOML: one key per field (arrays of 3 numbers for
per-mode fields, ``true``/``false`` for switches) plus an optional
``[provenance]`` table (where identified values came from). Unknown keys,
non-numbers and values out of range raise :class:`~labkit.errors.ConfigError`
naming the file, the key and the expected unit/range.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from labkit.errors import ConfigError
from labkit.jsonutil import Json

G_M_S2 = 9.81
#: A leg mode's modal mass referred to the foot, as a share of the leg's mass, for a uniform
#: clamped-free beam: every mode's mass-normalised shape is 2 / sqrt(m) at the free end, so its
#: effective mass there is m / 4 for every mode, and the modes' static contributions
#: ``4 / (m w_n^2)`` sum to the beam's tip compliance ``L^3 / (3 E I)``
#: (:func:`labkit.sim.modes.cantilever_tip_participation`, docs/model.md M13). The ``paper``
#: set's ``modal_participation``: the legs' stiffness at the foot from their mass and Table 2's
#: frequencies, not a free factor.
CANTILEVER_TIP_PARTICIPATION = 0.25


@dataclass(frozen=True)
class _Spec:
    unit: str
    lo: float | None = None          # lower bound
    lo_open: bool = False            # exclusive lower bound
    hi: float | None = None
    n: int = 1                       # 1 scalar, 3 per-mode tuple
    kind: str = "float"              # float | bool | sign | flag
    doc: str = ""


_SPECS: dict[str, _Spec] = {
    # --- paper Table 2
    "mass_mg": _Spec("mg", 0, True, doc="total robot mass (body + legs)"),
    "body_mass_mg": _Spec("mg", 0, True, doc="body (chassis) mass; legs get the rest"),
    "k_per_s2": _Spec("1/s^2 (N/m/kg)", 0, True, n=3, doc="mass-normalised modal stiffness"),
    "b_per_s": _Spec("1/s (N s/m/kg)", 0, False, n=3, doc="mass-normalised modal damping"),
    "ratio": _Spec("1 (lateral:vertical)", 0, True, n=3, doc="modal motion ratio r_i, lateral : vertical"),
    # --- paper Table 1
    "b_g_body_n_m2_s": _Spec("N m^2 s", 0, doc="squeeze-film coefficient of the body (0 = off)"),
    "b_g_foot_n_m2_s": _Spec("N m^2 s", 0, doc="squeeze-film coefficient of a foot (0 = off)"),
    "a_drag_n_s2_m2": _Spec("N s^2/m^2", 0, doc="air-drag coefficient, F = -a v|v| (feet and body)"),
    "c_ad_n": _Spec("N", 0, doc="adhesion force at first contact (0 = no adhesion)"),
    "c_ad_t_n_s": _Spec("N/s", 0, doc="adhesion growth with contact time"),
    # --- choices (model.md)
    "c_r": _Spec("1", 0, False, 1, doc="coefficient of restitution of a foot (choice)"),
    "c_r_body": _Spec("1", 0, False, 1, doc="coefficient of restitution of the body (choice)"),
    "body_no_slip": _Spec("true/false", kind="bool",
                          doc="a body-ground impact also stops the body's lateral velocity (as a foot's)"),
    "cy_sign": _Spec("1 (-1, 0 or +1)", n=3, kind="sign",
                     doc="sign s_i of Cy_i: fixes the walking direction; 0 removes lateral coupling"),
    "knee_to_foot": _Spec("1", 0, True, n=3, doc="knee : foot amplitude ratio per mode (vibrometer spot)"),
    "act_um_per_v": _Spec("um/V", 0, False, n=3,
                          doc="static modal deflection per volt of the PZT drive (actuator gain)"),
    "foot_mass_fraction": _Spec("1", 0, False, 1, doc="kept for old parameter files; does not enter the coupled "
                                "model (the modal masses carry the legs' weight, docs/model.md M2)"),
    "modal_participation": _Spec("1", 0, True, 1, doc="modal mass M_i = participation x leg mass, referred to "
                                 "the foot; it sets the legs' stiffness there, M_i k_i (a uniform cantilever: "
                                 "0.25, docs/model.md M13)"),
    "m_imp_factor": _Spec("1", 0, True, doc="m_i,imp / M_i (effective mass for foot forces); must be 1 in "
                          "the coupled model (one mass matrix, docs/model.md M2)"),
    "m_dis_factor": _Spec("1", 0, True, doc="m_i,dis / M_i (effective mass for distributed forces); must be 1 "
                          "in the coupled model"),
    "base_participation": _Spec("1", 0, doc="kept for old parameter files: 0 or 1, both mean the mass "
                                "matrix's own coupling (docs/model.md M2); other values are refused"),
    "leg_half_width_mm": _Spec("mm", 0, True, doc="|x_j| of the leg attachments"),
    "leg_pitch_mm": _Spec("mm", 0, False, doc="spacing along y of the leg attachments (y_j in -p, 0, +p)"),
    "leg_z_mm": _Spec("mm", doc="z_j of the leg attachments relative to the body's centre of mass"),
    "body_length_mm": _Spec("mm", 0, True, doc="body length along y (thin-plate inertia)"),
    "body_width_mm": _Spec("mm", 0, True, doc="body width along x (thin-plate inertia)"),
    "body_gap_um": _Spec("um", 0, True, doc="gap under the body at rest on still ground"),
    "h_min_um": _Spec("um", 0, True, doc="kept for old parameter files; does not enter: the squeeze films are "
                      "finite at contact through film_gap_nm and mean_free_path_nm (docs/model.md M7)"),
    "foot_pad_um": _Spec("um", 0, False, doc="side of a foot's square pad: its own squeeze film, "
                         "beta(1) mu_air a^4 / h^3 (0 = no pad film; docs/model.md M7)"),
    "film_gap_nm": _Spec("nm", 0, True, doc="mean-plane gap of a foot pad or the body at asperity contact "
                         "(about 3 combined RMS roughnesses; docs/model.md M7)"),
    "mean_free_path_nm": _Spec("nm", 0, False, doc="mean free path of the air: rarefied effective viscosity "
                               "mu / (1 + 9.638 Kn^1.159) in the films (0 = continuum; docs/model.md M7)"),
    "mu": _Spec("1", 0, False, doc="Coulomb friction of a pinned foot; inf = no slip (paper)"),
    "v_stick_mm_s": _Spec("mm/s", 0, False, doc="sticking threshold: an impact whose rebound (c_r times the "
                          "approach speed) is slower than this pins the foot (body) instead; ends chattering "
                          "in finitely many impacts (docs/model.md M11)"),
    "impact_modes": _Spec("1 (0 or 1)", n=3, kind="flag",
                          doc="1: the mode takes part in impacts (light-foot law, paper eq. 8 limit); "
                              "0: held rigid during an impact (stiff-leg limit: the robot rebounds as a whole)"),
    "g_m_s2": _Spec("m/s^2", 0, False, doc="gravity"),
}

#: Field name -> one-line description with unit (for docs and ``labkit info``).
FIELD_DOCS = {k: f"{s.doc} [{s.unit}]" for k, s in _SPECS.items()}
#: The unit of every parameter key (what readers of parameter files label their values with).
UNITS = {k: s.unit for k, s in _SPECS.items()}


@dataclass(frozen=True)
class RobotParams:
    """The simulator's full parameter set (frozen; use :meth:`replace`).

    Every field carries its unit in its name or in :data:`FIELD_DOCS`.
    Defaults: the paper's Tables 1-2 and the documented choices of model.md.
    """

    mass_mg: float = 0.33
    body_mass_mg: float = 0.28
    k_per_s2: tuple[float, float, float] = (7.57e6, 5.68e7, 1.28e8)
    b_per_s: tuple[float, float, float] = (1.38e3, 1.76e3, 2.97e3)
    ratio: tuple[float, float, float] = (15.0, 1.0 / 17.0, 1.0 / 15.0)
    b_g_body_n_m2_s: float = 1.5e-19
    b_g_foot_n_m2_s: float = 2.5e-19
    a_drag_n_s2_m2: float = 4.55e-6
    c_ad_n: float = 50e-6
    c_ad_t_n_s: float = 1e-7
    c_r: float = 0.5
    c_r_body: float = 0.5
    body_no_slip: bool = True
    cy_sign: tuple[float, float, float] = (1.0, 1.0, 1.0)
    knee_to_foot: tuple[float, float, float] = (0.5, 0.5, 0.5)
    act_um_per_v: tuple[float, float, float] = (5.0, 2.5, 2.5)
    foot_mass_fraction: float = 0.5
    modal_participation: float = 0.5
    m_imp_factor: float = 1.0
    m_dis_factor: float = 1.0
    base_participation: float = 0.0
    leg_half_width_mm: float = 1.0
    leg_pitch_mm: float = 1.5
    leg_z_mm: float = 0.0
    body_length_mm: float = 5.0
    body_width_mm: float = 2.0
    body_gap_um: float = 50.0
    h_min_um: float = 1.0
    foot_pad_um: float = 30.0
    film_gap_nm: float = 50.0
    mean_free_path_nm: float = 68.0
    mu: float = math.inf
    v_stick_mm_s: float = 0.01
    impact_modes: tuple[float, float, float] = (1.0, 1.0, 1.0)
    g_m_s2: float = G_M_S2
    provenance: dict[str, Json] = field(default_factory=dict, compare=False, hash=False, repr=False)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            if f.name == "provenance":
                continue
            value = _check(f.name, getattr(self, f.name), None)
            object.__setattr__(self, f.name, value)
        if self.body_mass_mg >= self.mass_mg:
            raise ConfigError(f"body mass {self.body_mass_mg} mg is not below the total {self.mass_mg} mg",
                              key="body_mass_mg", expected=f"a number in mg, < mass_mg ({self.mass_mg})")
        if self.body_coordinate_mass_mg <= 0:
            raise ConfigError(f"the 18 modal masses ({self.mass_mg - self.body_coordinate_mass_mg:.4g} mg) are not "
                              f"below the total {self.mass_mg} mg", key="modal_participation",
                              expected=f"< {self.mass_mg / (3 * (self.mass_mg - self.body_mass_mg)):.4g} "
                                       "(mass_mg / (18 x leg mass))")
        if not any(r > 1 for r in self.ratio) or not any(r < 1 for r in self.ratio):
            raise ConfigError(f"ratios {self.ratio} need one lateral (> 1) and one vertical (< 1) mode",
                              key="ratio", expected="3 numbers > 0, at least one > 1 and one < 1")

    # ------------------------------------------------------------------ derived
    @property
    def modal_freq_hz(self) -> tuple[float, float, float]:
        """Undamped natural frequencies sqrt(k_i) / 2 pi."""
        f = [math.sqrt(k) / (2 * math.pi) for k in self.k_per_s2]
        return (f[0], f[1], f[2])

    @property
    def modal_damping_ratio(self) -> tuple[float, float, float]:
        """Damping ratios b_i / (2 sqrt(k_i))."""
        z = [b / (2 * math.sqrt(k)) for k, b in zip(self.k_per_s2, self.b_per_s)]
        return (z[0], z[1], z[2])

    @property
    def lateral_mode(self) -> int:
        """Index of the first lateral mode (lowest frequency with ratio > 1)."""
        return min((i for i in range(3) if self.ratio[i] > 1), key=lambda i: self.k_per_s2[i])

    @property
    def vertical_mode(self) -> int:
        """Index of the first vertical mode (lowest frequency with ratio < 1)."""
        return min((i for i in range(3) if self.ratio[i] < 1), key=lambda i: self.k_per_s2[i])

    @property
    def body_coordinate_mass_mg(self) -> float:
        """The mass the body's coordinates carry: ``mass_mg`` minus the 18 modal masses
        (``modal_participation`` x leg mass each): the chassis plus the legs' mass that moves
        rigidly with it, so that the model's masses add up to ``mass_mg`` (docs/model.md M2)."""
        return self.mass_mg - 18.0 * self.modal_participation * self.leg_mass_mg

    @property
    def leg_mass_mg(self) -> float:
        """Mass of one leg (leg + foot): the non-body mass split over six legs."""
        return (self.mass_mg - self.body_mass_mg) / 6.0

    # ------------------------------------------------------------------ editing
    def replace(self, **changes: Any) -> RobotParams:
        """A copy with some fields changed (validated). Unknown names -> ConfigError."""
        for k in changes:
            if k not in _SPECS and k != "provenance":
                raise ConfigError("unknown parameter", key=k, expected="one of " + ", ".join(_SPECS))
        return dataclasses.replace(self, **changes)

    def with_modes(self, freq_hz=None, damping_ratio=None) -> RobotParams:
        """A copy with modal stiffness/damping from identified frequencies and damping ratios.

        ``k_i = (2 pi f_i)^2``, ``b_i = 2 zeta_i (2 pi f_i)``; a missing argument
        keeps the current value of that quantity.
        """
        f = self.modal_freq_hz if freq_hz is None else tuple(float(x) for x in freq_hz)
        z = self.modal_damping_ratio if damping_ratio is None else tuple(float(x) for x in damping_ratio)
        if len(f) != 3 or len(z) != 3:
            raise ConfigError("need 3 modes", key="freq_hz/damping_ratio", expected="3 values each")
        w = [2 * math.pi * x for x in f]
        return self.replace(k_per_s2=tuple(x * x for x in w), b_per_s=tuple(2 * zz * x for zz, x in zip(z, w)))

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict[str, Any]:
        """The fields as plain TOML-able values (tuples as lists), without provenance."""
        out = {}
        for f in dataclasses.fields(self):
            if f.name == "provenance":
                continue
            v = getattr(self, f.name)
            out[f.name] = list(v) if isinstance(v, tuple) else v
        return out

    def to_toml_text(self, provenance: Mapping[str, Json] | None = None) -> str:
        """The parameter file's text (with a ``[provenance]`` table)."""
        import tomli_w

        table: dict[str, object] = dict(self.to_dict())
        prov = dict(self.provenance)
        prov.update(provenance or {})
        if prov:
            table["provenance"] = _tomlable(prov)
        head = ("# labkit robot parameter file (labkit.sim.RobotParams); units in the key names,\n"
                "# defaults = Qu, Choi, Oldham 2017 Tables 1-2 + docs/model.md choices.\n\n")
        return head + tomli_w.dumps(table)

    def to_toml(self, path: str | Path, provenance: Mapping[str, Json] | None = None) -> Path:
        """Write the parameter file (``[provenance]`` merged from ``self.provenance`` and the argument)."""
        path = Path(path)
        path.write_text(self.to_toml_text(provenance), encoding="utf-8")
        return path

    @classmethod
    def from_dict(cls, table: Mapping[str, object], *, file: str | Path | None = None) -> RobotParams:
        """Validated parameters from a TOML-like table; missing keys keep their defaults."""
        table = dict(table)
        prov = table.pop("provenance", {})
        if not isinstance(prov, dict):
            raise ConfigError("not a table", file=file, key="provenance", expected="a [provenance] table")
        values = {}
        for key, value in table.items():
            if key not in _SPECS:
                raise ConfigError("unknown parameter", file=file, key=key,
                                  expected="one of " + ", ".join(_SPECS))
            values[key] = _check(key, value, file)
        try:
            return cls(**values, provenance=prov)
        except ConfigError as exc:
            if file is not None and exc.file is None:
                raise ConfigError(exc.message, file=file, key=exc.key, expected=exc.expected) from None
            raise

    @classmethod
    def preset(cls, name: str) -> RobotParams:
        """A bundled parameter set by name (``"published"``, ``"paper"``): :mod:`labkit.sim.presets`."""
        from labkit.sim.presets import preset

        return preset(name)

    @classmethod
    def from_toml(cls, path: str | Path) -> RobotParams:
        """Read a parameter file; errors name the file, the key and what was expected."""
        from labkit.tomlio import load_toml

        table, _ = load_toml(path)
        return cls.from_dict(table, file=path)


def _expected(spec: _Spec) -> str:
    if spec.kind == "bool":
        return "true or false"
    if spec.kind == "sign":
        return "3 numbers, each -1, 0 or +1"
    if spec.kind == "flag":
        return "3 numbers, each 0 or 1"
    text = ("3 numbers" if spec.n == 3 else "a number") + f" in {spec.unit}"
    rng = []
    if spec.lo is not None:
        rng.append(f"{'>' if spec.lo_open else '>='} {spec.lo:g}")
    if spec.hi is not None:
        rng.append(f"<= {spec.hi:g}")
    return text + (", " + " and ".join(rng) if rng else "")


def _check(key: str, value: Any, file) -> Any:
    spec = _SPECS[key]
    exp = _expected(spec)
    if spec.kind == "bool":
        if not isinstance(value, bool):
            raise ConfigError(f"not a boolean: {value!r}", file=file, key=key, expected=exp)
        return value
    if spec.n == 3:
        if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 3:
            raise ConfigError(f"not 3 values: {value!r}", file=file, key=key, expected=exp)
        return tuple(_num(f"{key}[{i}]", v, spec, file, exp) for i, v in enumerate(value))
    return _num(key, value, spec, file, exp)


def _num(key: str, value: Any, spec: _Spec, file, exp: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) and not hasattr(value, "__float__"):
        raise ConfigError(f"not a number: {value!r}", file=file, key=key, expected=exp)
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"not a number: {value!r}", file=file, key=key, expected=exp) from None
    if spec.kind == "sign":
        if v not in (-1.0, 0.0, 1.0):
            raise ConfigError(f"out of range: {v!r}", file=file, key=key, expected=exp)
        return v
    if spec.kind == "flag":
        if v not in (0.0, 1.0):
            raise ConfigError(f"out of range: {v!r}", file=file, key=key, expected=exp)
        return v
    bad = v != v or (spec.lo is not None and (v <= spec.lo if spec.lo_open else v < spec.lo)) \
        or (spec.hi is not None and v > spec.hi) or (math.isinf(v) and key != "mu")
    if bad:
        raise ConfigError(f"out of range: {v!r}", file=file, key=key, expected=exp)
    return v


def _tomlable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _tomlable(v) for k, v in obj.items() if v is not None}
    if isinstance(obj, (list, tuple)):
        return [_tomlable(v) for v in obj]
    if isinstance(obj, (str, bool, int, float)):
        return obj
    if hasattr(obj, "item"):
        return obj.item()
    return str(obj)
