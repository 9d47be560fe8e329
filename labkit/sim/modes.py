"""Modes of the robot standing on pinned feet (docs/model.md M13).

The coupled system of :mod:`labkit.sim.model` linearised about its rest: the twelve foot rows
(vertical and lateral) held, ``M q'' + D q' + K q = 0`` on the null space of those rows, ``D``
the legs' modal dampers plus the body's squeeze film at its rest gap. The
result is what a swept-sine measurement of the standing robot shows (the paper's out-of-chip
spectrum, Fig. 6): frequencies, damping ratios and, per mode, where its kinetic energy sits
(body translation / rotation, the legs' hip, tilt and bending modes).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.linalg import eig, null_space

from labkit.sim import model as M
from labkit.sim import scheme as K
from labkit.sim.excitation import Shaker
from labkit.sim.params import RobotParams
from labkit.sim.scheme import film_law

#: What each body coordinate is called in a mode's shape.
BODY_NAMES = ("body_y", "body_z", "body_roll_x", "body_pitch_y", "body_yaw_z")

#: The out-of-chip spectrum of the paper (Qu, Choi, Oldham 2017, Sec. 4.3-4.4 and Fig. 6):
#: the resonances of the detached robot on the tray (Hz) and what the paper attributes them to.
PAPER_FIG6 = (
    (438.0, "hip, in-plane rotation (lateral)"),
    (800.0, "body vertical motion, not modelled by the paper"),
    (1200.0, "foot tilt (vertical); body motion also near 1.2 kHz"),
    (1800.0, "leg bending through the released body (vertical)"),
)


@dataclass
class Mode:
    """One mode on pinned feet: frequency (Hz, damped), damping ratio, and its kinetic energy's
    share per part: the body's five coordinates (``body``) and the legs' three mode families."""

    freq_hz: float
    damping_ratio: float
    body: dict[str, float]
    legs: dict[str, float]
    kind: str

    @property
    def body_share(self) -> float:
        return float(sum(self.body.values()))


@dataclass
class PinnedModes:
    """The standing robot's modes, lowest first, the leg modes' clamped frequencies, and the body
    on its legs: one leg's static stiffness at the foot (lateral, vertical; N/m, the other
    direction pinned) and the heave of the rigid body on six such springs (Hz)."""

    modes: list[Mode]
    leg_modes_hz: tuple[float, float, float]
    foot_stiffness_n_m: tuple[float, float] = (0.0, 0.0)
    heave_on_springs_hz: float = 0.0

    def first_leg_mode_hz(self) -> float:
        return min(self.leg_modes_hz)

    def body_modes_below_first_leg_mode(self, share: float = 0.5) -> list[Mode]:
        """Modes whose energy is mostly the body's, below the legs' lowest clamped mode."""
        return [m for m in self.modes if m.body_share >= share and m.freq_hz < self.first_leg_mode_hz()]

    def to_dict(self) -> dict[str, object]:
        return {"leg_modes_hz": list(self.leg_modes_hz), "foot_stiffness_n_m": list(self.foot_stiffness_n_m),
                "heave_on_springs_hz": self.heave_on_springs_hz, "modes": [asdict(m) for m in self.modes],
                "paper_fig6": [{"freq_hz": f, "what": w} for f, w in PAPER_FIG6]}


def _kind(body: dict[str, float], legs: dict[str, float]) -> str:
    top = max(list(body.items()) + list(legs.items()), key=lambda kv: kv[1])[0]
    return top if top in body else f"legs_{top}"


def pinned_modes(params: RobotParams, max_hz: float = 5000.0) -> PinnedModes:
    """The modes of ``params``'s robot standing on its six pinned feet, up to ``max_hz``.

    Degenerate families (six legs vibrating in the same mode with different phase patterns)
    are listed once per eigenvalue, as the solver returns them.
    """
    mdl = M.build_model(params, Shaker(240.0, 0.0))
    R = mdl.rows[:, :12]
    N = null_space(R.T, rcond=1e-10)
    Mr = N.T @ mdl.mass @ N
    Kr = N.T @ np.diag(mdl.stiff) @ N
    # the body's squeeze film, linearised at its rest gap, damps its vertical motion (docs/model.md M7)
    c_body = film_law(mdl.scal["BGB"], mdl.scal["LAM"], mdl.h0 + mdl.scal["HR"]) if mdl.scal["BGB"] > 0 else 0.0
    rb = mdl.rows[:, K.ROW_BZ]
    Dr = N.T @ (np.diag(mdl.damp) + c_body * np.outer(rb, rb)) @ N
    n = N.shape[1]
    # first-order form: [0 I; -M^-1 K  -M^-1 D]
    Minv = np.linalg.inv(Mr)
    Amat = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ Kr, -Minv @ Dr]])
    lam, vec = eig(Amat)
    out = []
    for k in np.argsort(np.abs(lam)):
        s = lam[k]
        if s.imag <= 0:
            continue
        wn = abs(s)
        fd = s.imag / (2 * math.pi)
        if fd > max_hz:
            continue
        q = N @ vec[:n, k]
        e = np.real(np.conj(q) * (mdl.mass @ q))          # kinetic-energy density per coordinate
        tot = max(float(e.sum()), 1e-300)
        body = {BODY_NAMES[i]: float(e[i] / tot) for i in range(M.NB)}
        legs = {name: float(sum(e[M.xi(j, i)] for j in range(6)) / tot)
                for i, name in enumerate(("mode1_hip", "mode2_tilt", "mode3_bending"))}
        out.append(Mode(freq_hz=float(fd), damping_ratio=float(-s.real / wn), body=body, legs=legs,
                        kind=_kind(body, legs)))
    kf = foot_stiffness(params)
    heave = math.sqrt(6 * kf[1, 1] / mdl.m_b) / (2 * math.pi)
    return PinnedModes(modes=out, leg_modes_hz=params.modal_freq_hz,
                       foot_stiffness_n_m=(float(kf[0, 0]), float(kf[1, 1])), heave_on_springs_hz=float(heave))


def foot_stiffness(params: RobotParams) -> np.ndarray:
    """One leg's static stiffness at its foot with the body held (N/m; rows/columns lateral y, vertical z).

    The sum over the leg's modes of each mode's static compliance along its direction
    ``C_i = (Cy_i, Cz_i)``: ``C = sum_i C_i C_i^T / (M_i k_i)``, ``M_i`` the modal mass referred to
    the foot (``modal_participation`` x leg mass, docs/model.md M13); the stiffness is ``C^-1``.
    """
    leg_kg = params.leg_mass_mg * 1e-6
    r = np.array(params.ratio, float)
    norm = np.sqrt(1 + r * r)
    c = np.stack([np.array(params.cy_sign, float) * r / norm, 1 / norm], axis=1)
    comp = sum(np.outer(ci, ci) / (params.modal_participation * leg_kg * k) for ci, k in zip(c, params.k_per_s2))
    return np.linalg.pinv(np.asarray(comp))


def cantilever_roots(n: int) -> np.ndarray:
    """The first ``n`` roots ``beta_n L`` of ``1 + cos x cosh x = 0`` (uniform clamped-free beam)."""
    from scipy.optimize import brentq

    f = lambda x: 1 + math.cos(x) * math.cosh(x)  # noqa: E731
    return np.array([brentq(f, (k + 0.5) * math.pi - 0.5, (k + 0.5) * math.pi + 0.5) for k in range(n)])


def cantilever_tip_participation(mode: int, points: int = 4001) -> float:
    """A uniform clamped-free beam's mode ``mode`` (1-based): its modal mass referred to the free end,
    as a share of the beam's mass, ``int_0^1 phi^2 dx / phi(1)^2`` (the shape integrated numerically)."""
    bl = float(cantilever_roots(mode)[-1])
    x = np.linspace(0.0, 1.0, points)
    sigma = (math.cosh(bl) + math.cos(bl)) / (math.sinh(bl) + math.sin(bl))
    phi = np.cosh(bl * x) - np.cos(bl * x) - sigma * (np.sinh(bl * x) - np.sin(bl * x))
    return float(np.trapezoid(phi * phi, x) / phi[-1] ** 2)
