"""Modes of the robot standing on pinned feet (labkit.sim.modes, docs/model.md M13).

Checked against a hand-built reduced system (the heave of a body on six identical legs, by
symmetry), against the squeeze film's damping of that heave, and side by side with the
paper's out-of-chip spectrum (Fig. 6 / Sec. 4.3: 438 Hz, 1.2 and 1.8 kHz, body motion near
800 Hz).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import eig

from clihelpers import last_json, run_cli
from labkit.sim import RobotParams
from labkit.sim.modes import PAPER_FIG6, pinned_modes


def _heave_by_hand(p: RobotParams, c_body: float = 0.0) -> tuple[float, float]:
    """The body's heave on six pinned legs (no lateral coupling): coordinates x_1..x_3 of one leg
    (all six move alike), the body's height z = -sum Cz_i x_i (the pinned foot). Kinetic energy
    1/2 m_b z'^2 + 6 sum 1/2 M_i (z' + Cz_i x_i')^2, potential 6 sum 1/2 M_i k_i x_i^2, the
    legs' dampers 6 M_i b_i and the body film c on z. Returns (frequency Hz, damping ratio)."""
    r = np.array(p.ratio)
    cz = 1 / np.sqrt(1 + r * r)
    Mi = p.modal_participation * p.leg_mass_mg * 1e-6
    mb = p.mass_mg * 1e-6 - 18 * Mi                          # the rest of the robot's mass (model.md M2)
    k = np.array(p.k_per_s2)
    b = np.array(p.b_per_s)
    # z' = -cz . x'; the mode mass's vertical velocity z' + cz_i x_i' = (e_i - 1) cz ... per mode
    Z = -cz[None, :]                                        # dz/dx (1 x 3)
    Mm = mb * Z.T @ Z
    for i in range(3):
        u = Z.copy()
        u[0, i] += cz[i]
        Mm += 6 * Mi * u.T @ u
    Km = np.diag(6 * Mi * k)
    Dm = np.diag(6 * Mi * b) + c_body * Z.T @ Z
    A = np.block([[np.zeros((3, 3)), np.eye(3)],
                  [-np.linalg.solve(Mm, Km), -np.linalg.solve(Mm, Dm)]])
    lam = eig(A)[0]
    s = lam[np.argmin(np.where(lam.imag > 0, np.abs(lam), np.inf))]
    return s.imag / (2 * math.pi), -s.real / abs(s)


def test_heave_matches_the_reduced_system():
    p = RobotParams(cy_sign=(0, 0, 0), b_g_body_n_m2_s=0.0)
    pm = pinned_modes(p)
    heave = [m for m in pm.modes if m.kind == "body_z"]
    assert len(heave) == 1
    f, z = _heave_by_hand(p)
    assert heave[0].freq_hz == pytest.approx(f, rel=1e-6)
    assert heave[0].damping_ratio == pytest.approx(z, rel=1e-6)
    assert heave[0].body["body_z"] > 0.9


def test_the_body_film_damps_the_heave():
    """The body's film at its rest gap (c = b / u^3 / (1 + 9.638 Kn^1.159), u = 50 um + 50 nm)
    is a damper on z: the chassis-sized film (docs/model.md M7) makes the heave overdamped-ish."""
    p = RobotParams(cy_sign=(0, 0, 0), b_g_body_n_m2_s=8.9e-17)
    u = p.body_gap_um * 1e-6 + p.film_gap_nm * 1e-9
    c = 8.9e-17 / (u ** 3 * (1 + 9.638 * (68e-9 / u) ** 1.159))
    f, z = _heave_by_hand(p, c)
    heave = [m for m in pinned_modes(p).modes if m.kind == "body_z"]
    assert heave[0].freq_hz == pytest.approx(f, rel=1e-6) and heave[0].damping_ratio == pytest.approx(z, rel=1e-6)
    assert z > 0.5


def test_published_set_has_a_light_body_heave_below_the_hip_mode():
    """The finding the modes make visible (docs/model.md M13): with Table 2's frequencies as the
    legs' clamped modes and Table 1's body film, the body heaves on its legs at ~280 Hz with
    zeta ~0.03, below the hip's 438 Hz; the paper's Fig. 6 shows no such peak."""
    pm = pinned_modes(RobotParams())
    heave = next(m for m in pm.modes if m.kind == "body_z")
    assert 200 < heave.freq_hz < pm.first_leg_mode_hz() and heave.damping_ratio < 0.05
    assert heave in pm.body_modes_below_first_leg_mode()
    assert [f for f, _ in PAPER_FIG6] == [438.0, 800.0, 1200.0, 1800.0]


def test_modes_command_json_and_bad_input():
    js = last_json(run_cli("simulate", "modes", "--params", "published", "--max-hz", "2000", "--json"))
    assert js["params"] == "published" and js["leg_modes_hz"][0] == pytest.approx(437.9, abs=0.1)
    assert all(m["freq_hz"] <= 2000 for m in js["modes"]) and len(js["modes"]) >= 5
    assert {"freq_hz", "damping_ratio", "body", "legs", "kind"} <= set(js["modes"][0])
    assert [x["freq_hz"] for x in js["paper_fig6"]] == [438.0, 800.0, 1200.0, 1800.0]
    proc = run_cli("simulate", "modes", "--max-hz", "-3", check=2)
    assert "--max-hz" in proc.stderr and proc.stderr.count("\n") == 1
