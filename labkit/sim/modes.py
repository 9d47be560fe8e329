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
    """The standing robot's modes, lowest first, and the leg modes' clamped frequencies."""

    modes: list[Mode]
    leg_modes_hz: tuple[float, float, float]

    def first_leg_mode_hz(self) -> float:
        return min(self.leg_modes_hz)

    def body_modes_below_first_leg_mode(self, share: float = 0.5) -> list[Mode]:
        """Modes whose energy is mostly the body's, below the legs' lowest clamped mode."""
        return [m for m in self.modes if m.body_share >= share and m.freq_hz < self.first_leg_mode_hz()]

    def to_dict(self) -> dict:
        return {"leg_modes_hz": list(self.leg_modes_hz), "modes": [asdict(m) for m in self.modes],
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
    return PinnedModes(modes=out, leg_modes_hz=params.modal_freq_hz)
