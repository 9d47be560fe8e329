"""When a foot can leave a shaking tray: the pull on the feet of a robot that stands on it.

A pinned foot leaves when its pull exceeds the adhesion ``F_ad`` (docs/model.md M10). While all
six feet are pinned, the robot is linear: the body on its legs (the system of
:func:`labkit.sim.modes.pinned_modes`: mass matrix, the legs' modal springs and dampers, the body's
squeeze film at its rest gap) driven by the tray's acceleration. Its steady response to a tray
``z_g = A sin(2 pi f t)`` gives every foot's contact force: its share of the weight ``W_j``
(compressive) and a harmonic part of amplitude ``P_j``. The largest pull over a period,

    T = max_j (P_j - W_j),

is the adhesion above which no foot ever leaves: a robot whose adhesion at first contact exceeds
``T`` stays down for good once its feet are down, whatever its other parameters (a force
threshold against a bounded periodic pull). Below ``T`` a foot can leave each period (necessary
for a walk, not sufficient). At the paper's 240 Hz the body heaves on its legs a little below
the drive (docs/model.md M13), so ``P_j`` is the rigid robot's ``m w^2 A / 6`` amplified by that
resonance (:attr:`StuckPull.amplification`), and ``T`` varies between drawn robots as their heave
moves against the drive.

Gravity is the same problem at zero frequency (a uniform acceleration ``g``), so the weight
shares come from the same solve.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from labkit.sim.params import RobotParams


@dataclass(frozen=True)
class StuckPull:
    """The contact forces of a robot standing on its six pinned feet on a shaking tray (N).

    ``weight_n``: each foot's share of the weight (compressive, positive); ``pull_n``: the
    amplitude of the harmonic part of each foot's vertical contact force; ``rigid_n``: that
    amplitude for a rigid robot, ``m w^2 A / 6``.
    """

    freq_hz: float
    amp_um: float
    weight_n: tuple[float, ...]
    pull_n: tuple[float, ...]
    rigid_n: float

    @property
    def threshold_n(self) -> float:
        """``T``: the largest pull on any foot over a period; adhesion above it holds every foot."""
        return max(p - w for p, w in zip(self.pull_n, self.weight_n))

    @property
    def amplification(self) -> float:
        """The largest harmonic foot force over the rigid robot's."""
        return max(self.pull_n) / self.rigid_n if self.rigid_n > 0 else math.nan

    def holds(self, adhesion_n: float) -> bool:
        """Whether an adhesion at first contact of ``adhesion_n`` keeps every foot down."""
        return adhesion_n >= self.threshold_n


def stuck_pull(params: RobotParams, freq_hz: float, amp_um: float) -> StuckPull:
    """The feet's contact forces of ``params``'s robot pinned on a tray shaking at ``freq_hz``,
    ``amp_um`` (steady state; see the module's docstring)."""
    from scipy.linalg import null_space

    from labkit.sim import model as M
    from labkit.sim import scheme as K
    from labkit.sim.excitation import Shaker

    mdl = M.build_model(params, Shaker(float(freq_hz), float(amp_um)))
    R = mdl.rows[:, :12]
    N = null_space(R.T, rcond=1e-10)
    c_body = (K.film_law(mdl.scal["BGB"], mdl.scal["LAM"], mdl.h0 + mdl.scal["HR"])
              if mdl.scal["BGB"] > 0 else 0.0)
    rb = mdl.rows[:, K.ROW_BZ]
    D = np.diag(mdl.damp) + c_body * np.outer(rb, rb)
    Kq = np.diag(mdl.stiff)
    uz = np.zeros(mdl.mass.shape[0])
    uz[1] = 1.0                     # the body's z: with the legs' modal coordinates at 0, every point up by 1

    def contact(w: float, accel: float) -> np.ndarray:
        """Pinned rows' forces (complex amplitudes) for a tray acceleration ``accel e^{iwt}``:
        in the tray's frame every mass feels ``-M u_z accel``."""
        Z = N.T @ (-w * w * mdl.mass + 1j * w * D + Kq) @ N
        q = N @ np.linalg.solve(Z, -N.T @ mdl.mass @ uz * accel)
        lam, *_ = np.linalg.lstsq(R, (-w * w * mdl.mass + 1j * w * D + Kq) @ q + mdl.mass @ uz * accel, rcond=None)
        return lam

    w = 2 * math.pi * float(freq_hz)
    weight = np.real(contact(0.0, params.g_m_s2))[:6]
    pull = np.abs(contact(w, w * w * float(amp_um) * 1e-6))[:6]
    rigid = float(uz @ mdl.mass @ uz) * w * w * float(amp_um) * 1e-6 / 6
    return StuckPull(freq_hz=float(freq_hz), amp_um=float(amp_um), weight_n=tuple(float(x) for x in weight),
                     pull_n=tuple(float(x) for x in pull), rigid_n=rigid)
