"""The assembled robot's rigid-body inertia, computed independently of the model's rows.

Held rigid (modal coordinates fixed), the robot is the body plate plus point masses at the
leg attachments r_j = (x_j, y_j, z_j), each carrying its leg's modal masses sum_i M_i. Its
kinetic energy for the body velocities u = (y_b', z_b', phi_x', phi_y', phi_z') is
T = 1/2 sum_k m_k |V + w x r_k|^2 + 1/2 (I_x phi_x'^2 + I_y phi_y'^2 + I_z phi_z'^2), with
V = (0, y_b', z_b') and w = (phi_x', phi_y', phi_z'): its matrix must be the body block of
the model's mass matrix (docs/model.md M2). The leg masses' x velocity under yaw,
-phi_z' y_j, was left out before: I_zz was 0.54-0.97 of this over random robots.
"""
from __future__ import annotations

import numpy as np
import pytest

from labkit.sim import RobotParams, Shaker
from labkit.sim import model as M


def _jacobian(r: np.ndarray) -> np.ndarray:
    """3 x 5: the velocity of a point at r for unit body velocities (cross products by numpy)."""
    J = np.zeros((3, 5))
    J[1, 0] = 1.0
    J[2, 1] = 1.0
    for k in range(3):
        w = np.zeros(3)
        w[k] = 1.0
        J[:, 2 + k] = np.cross(w, r)
    return J


def _rigid_body(p: RobotParams) -> np.ndarray:
    mg = 1e-6
    m_leg = 3 * p.modal_participation * p.leg_mass_mg * mg         # three modal masses per leg
    m_b = p.mass_mg * mg - 6 * m_leg                                # the rest of the robot's mass (M2)
    L, W = p.body_length_mm * 1e-3, p.body_width_mm * 1e-3
    ref = np.zeros((5, 5))
    ref[0, 0] = ref[1, 1] = m_b
    ref[2, 2], ref[3, 3], ref[4, 4] = m_b * L * L / 12, m_b * W * W / 12, m_b * (L * L + W * W) / 12
    w, pitch, z = p.leg_half_width_mm * 1e-3, p.leg_pitch_mm * 1e-3, p.leg_z_mm * 1e-3
    for x, y in [(w, pitch), (-w, pitch), (w, 0.0), (-w, 0.0), (w, -pitch), (-w, -pitch)]:
        J = _jacobian(np.array([x, y, z]))
        ref += m_leg * J.T @ J
    return ref


@pytest.mark.parametrize("seed", range(5))
def test_the_body_block_is_the_rigid_body_inertia_of_random_robots(seed):
    rng = np.random.default_rng(seed)
    p = RobotParams().replace(leg_half_width_mm=rng.uniform(0.5, 2.0), leg_pitch_mm=rng.uniform(0.5, 2.5),
                              leg_z_mm=rng.uniform(-0.3, 0.3), body_length_mm=rng.uniform(2, 6),
                              body_width_mm=rng.uniform(1, 3), modal_participation=rng.uniform(0.2, 0.8))
    mass = M.build_model(p, Shaker()).mass[:5, :5]
    ref = _rigid_body(p)
    assert np.allclose(mass, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    assert mass[4, 4] == pytest.approx(ref[4, 4], rel=1e-12)          # yaw included
