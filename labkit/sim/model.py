"""From (RobotParams, scenario) to the SI constants both integrators use.

Coordinates (model.md sections 3-6), all SI inside the integrators:

* body: ``y`` (forward), ``z`` = body-underside height *minus its rest value*,
  angles ``phi_x, phi_y, phi_z``, and their rates;
* legs: per leg ``j`` and mode ``i`` the modal coordinate ``xi_ij`` is the
  deviation of ``x_ij`` from its value with the robot at rest on still
  ground, and ``v_ij`` its rate.

Writing the state as deviations from the exact static equilibrium (robot
resting on its six feet: body weight ``m_b g`` shared equally, zero lateral
leg force) makes "at rest on still ground" the all-zero state, whose every
force term is an exact floating-point zero — so a resting robot does not
drift, not even by rounding. The static parts cancel analytically:
``6 F0 = m_b g``, sum of ``y_j F0`` and ``x_j F0`` = 0 (the leg layout is
symmetric), zero static lateral force per leg. What is left of gravity in
air is the constant modal acceleration ``R_i`` (``-k_i x_eq,i`` + gravity on
leg and foot), zero for the modes that are free at rest.

Choices where model.md is silent (each a RobotParams field or a constant here):

* legs: leg ``n`` (1-based) sits at ``x = +w`` for odd ``n``, ``-w`` for even
  ``n``; ``y = +p`` for legs 1-2, 0 for 3-4, ``-p`` for 5-6 (so {1, 4, 5} is a
  tripod); ``w = leg_half_width_mm``, ``p = leg_pitch_mm``, ``z = leg_z_mm``;
* masses: the legs' mass ``mass_mg - body_mass_mg`` split over six legs, a
  ``foot_mass_fraction`` of it at the foot; modal mass ``M_i =
  modal_participation x leg mass``; ``m_imp,i = m_imp_factor M_i``,
  ``m_dis,i = m_dis_factor M_i``; a PZT payload rides on the body;
* the first vertical / first lateral mode (the pinned pair and the impact
  redistribution) are the lowest-frequency modes with ratio < 1 / > 1;
* base excitation: ``-Gamma_i (Cz_i a_z + Cy_i a_y)`` with ``Gamma_i`` the
  participation of gravity (``base_participation = 0``) or a given value;
* the body touches the ground at the centre of its underside (tilt ignored
  for contact), gap ``body_gap_um`` at rest; a body impact restitutes its
  vertical velocity (``c_r_body``) and, with ``body_no_slip``, stops its
  lateral velocity;
* air drag acts on the feet in both directions (absolute velocity, still
  air), on the body vertically and laterally;
* the release test adds the foot's own inertia (``m_f a_g``) to the pull, so
  that with no adhesion a rigid robot leaves exactly when the tray's
  acceleration exceeds g;
* friction (``mu`` finite): the normal load of a pinned foot is its
  compression plus the adhesion holding it; a slipping foot stays on the
  ground vertically and feels ``mu N`` laterally.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from labkit.sim.excitation import PZT, TRIPOD_A, Shaker
from labkit.sim.params import RobotParams

AIR, ADHESION, REST = 0, 1, 2
MODE_NAMES = ("air", "adhesion", "rest")

# Layout of the flat constant vector P (the kernel cannot take Python objects).
_SCALARS = ("MB", "IX", "IY", "IZ", "G", "F0", "MF", "BGF", "BGB", "AD", "HMIN", "H0",
            "CAD", "CADT", "CR", "CRB", "MU", "KIND", "AMP", "OMEGA", "FREQ", "VOLT", "IV", "IL",
            "QSQ", "NSUB", "SQSTIFF", "GAPTOL", "MAXEV", "BNS")
_MODE_ARRAYS = ("K", "B", "CZ", "CY", "M", "MIMP", "MDIS", "R", "GACT", "KTF", "GAM", "WZ")
_LEG_ARRAYS = ("XJ", "YJ", "ZJ", "PH", "YFEQ")
IDX: dict[str, int] = {}
_n = 0
for _name in _SCALARS:
    IDX[_name] = _n
    _n += 1
for _name in _MODE_ARRAYS:
    IDX[_name] = _n
    _n += 3
for _name in _LEG_ARRAYS:
    IDX[_name] = _n
    _n += 6
IDX["PINV"] = _n        # 2x2 inverse of the pinned pair's coupling matrix, row-major
_n += 4
P_SIZE = _n


def layout_signature() -> str:
    """A text fingerprint of the array layouts (the kernel checks it: see kernel.py)."""
    return repr((sorted(IDX.items()), S_SIZE, REC_COLS, EV_COLS, CNT_SIZE))

# Layout of the flat state vector S.
S_Q = 0        # body y, z, phx, phy, phz
S_U = 5        # their rates
S_XI = 10      # 6 x 3 modal deviations (leg-major)
S_V = 28       # 6 x 3 modal rates
S_TC = 46      # time in contact per leg
S_YPIN = 52    # pinned lateral foot position (deviation part) per leg
S_SIZE = 58


@dataclass
class Model:
    """Every constant of one simulation, SI units (see the module docstring)."""

    m_b: float
    inertia: np.ndarray          # (3,) I_x, I_y, I_z
    g: float
    f0: float                    # static load per leg, N
    m_f: float                   # foot mass
    b_g_foot: float
    b_g_body: float
    a_drag: float
    h_min: float
    h0: float                    # body gap at rest
    c_ad: float
    c_ad_t: float
    c_r: float
    c_r_body: float
    body_no_slip: bool
    mu: float
    kind: int                    # 0 shaker, 1 PZT
    amp_m: float
    freq_hz: float
    volt: float
    iv: int                      # first vertical mode
    il: int                      # first lateral mode
    k: np.ndarray                # (3,)
    b: np.ndarray
    cz: np.ndarray
    cy: np.ndarray
    m_modal: np.ndarray
    m_imp: np.ndarray
    m_dis: np.ndarray
    r: np.ndarray                # residual modal acceleration in air, m/s^2
    g_act: np.ndarray            # modal acceleration per volt, m/s^2/V
    ktf: np.ndarray
    gamma: np.ndarray            # participation of the attachment's acceleration per mode
    xj: np.ndarray               # (6,)
    yj: np.ndarray
    zj: np.ndarray
    phase: np.ndarray            # +1 tripod A, -1 tripod B
    y_foot_eq: np.ndarray        # y_j + static lateral foot offset

    def pair_inverse(self) -> np.ndarray:
        """Maps foot changes (dz, dy) to (lateral, vertical) modal changes: paper eq. 8.

        Row-major 2x2; when the lateral row vanishes (``cy_sign`` 0) the
        minimum-norm solution of the vertical equation alone.
        """
        a, bb = self.cz[self.il], self.cz[self.iv]
        c, d = self.cy[self.il], self.cy[self.iv]
        det = a * d - bb * c
        if abs(det) > 1e-12:
            return np.array([d / det, -bb / det, -c / det, a / det])
        n2 = a * a + bb * bb
        return np.array([a / n2, 0.0, bb / n2, 0.0])

    @property
    def omega(self) -> float:
        return 2 * math.pi * self.freq_hz

    def pack(self) -> np.ndarray:
        """The flat float64 vector the numba kernel reads (layout :data:`IDX`)."""
        p = np.zeros(P_SIZE)
        scal = dict(MB=self.m_b, IX=self.inertia[0], IY=self.inertia[1], IZ=self.inertia[2], G=self.g,
                    F0=self.f0, MF=self.m_f, BGF=self.b_g_foot, BGB=self.b_g_body, AD=self.a_drag,
                    HMIN=self.h_min, H0=self.h0, CAD=self.c_ad, CADT=self.c_ad_t, CR=self.c_r,
                    CRB=self.c_r_body, MU=self.mu, KIND=self.kind, AMP=self.amp_m, OMEGA=self.omega,
                    FREQ=self.freq_hz, VOLT=self.volt, IV=self.iv, IL=self.il,
                    QSQ=float(np.sum(self.cz * self.cz / self.m_imp)), NSUB=SQUEEZE_SUBSTEPS,
                    SQSTIFF=SQUEEZE_STIFF, GAPTOL=GAP_TOL_M, MAXEV=MAX_EVENTS_PER_STEP,
                    BNS=1.0 if self.body_no_slip else 0.0)
        for k, v in scal.items():
            p[IDX[k]] = v
        arrays = dict(WZ=self.cz / self.m_imp, PINV=self.pair_inverse(), K=self.k, B=self.b, CZ=self.cz, CY=self.cy, M=self.m_modal, MIMP=self.m_imp,
                      MDIS=self.m_dis, R=self.r, GACT=self.g_act, KTF=self.ktf, GAM=self.gamma, XJ=self.xj, YJ=self.yj,
                      ZJ=self.zj, PH=self.phase, YFEQ=self.y_foot_eq)
        for k, v in arrays.items():
            p[IDX[k]:IDX[k] + len(v)] = v
        return p


def build_model(params: RobotParams, scenario: Shaker | PZT) -> Model:
    """The SI constants for ``params`` driven by ``scenario`` (static equilibrium included)."""
    mg = 1e-6  # mg -> kg
    g = params.g_m_s2
    leg_mass = params.leg_mass_mg * mg
    m_b = params.body_mass_mg * mg
    if isinstance(scenario, PZT) and scenario.mass_mg is not None:
        # The payload rides on the body (the legs keep their mass).
        m_b = scenario.mass_mg * mg - 6 * leg_mass
        if m_b <= 0:
            from labkit.errors import InputError
            raise InputError(f"total mass {scenario.mass_mg} mg is not above the legs' "
                             f"{6 * params.leg_mass_mg:g} mg", key="mass_mg",
                             expected=f"a number in mg, > {6 * params.leg_mass_mg:g}")
    m_f = params.foot_mass_fraction * leg_mass
    m_l = leg_mass - m_f
    L = params.body_length_mm * 1e-3
    W = params.body_width_mm * 1e-3
    # Thin plate: rotation about x (across the width) sees the length, etc.
    inertia = np.array([m_b * L * L / 12, m_b * W * W / 12, m_b * (L * L + W * W) / 12])

    k = np.array(params.k_per_s2, float)
    b = np.array(params.b_per_s, float)
    r = np.array(params.ratio, float)
    s = np.array(params.cy_sign, float)
    norm = np.sqrt(1 + r * r)
    cz = 1 / norm
    cy = s * r / norm
    m_modal = np.full(3, params.modal_participation * leg_mass)
    m_imp = m_modal * params.m_imp_factor
    m_dis = m_modal * params.m_dis_factor
    iv, il = params.vertical_mode, params.lateral_mode
    free = [i for i in range(3) if i not in (iv, il)]

    grav = cz * (-m_f * g) / m_imp + cz * (-m_l * g) / m_dis   # modal acceleration from gravity
    # Participation of the attachment's acceleration: by default the same as
    # gravity's (m_f/m_imp + m_l/m_dis), so that gravity and acceleration are
    # equivalent and a robot in free fall does not deform (see RobotParams).
    if params.base_participation > 0:
        gamma = np.full(3, params.base_participation)
    else:
        gamma = m_f / m_imp + m_l / m_dis
    x_eq = grav / k                                             # in-air equilibrium
    f0 = m_b * g / 6
    # Resting: the pinned pair carries the leg's share of the body, with zero lateral force.
    fk = m_modal * k
    rhs_y = -sum(fk[i] * x_eq[i] * cy[i] for i in free)
    rhs_z = f0 - sum(fk[i] * x_eq[i] * cz[i] for i in free)
    a11, a12 = fk[il] * cy[il], fk[iv] * cy[iv]
    a21, a22 = fk[il] * cz[il], fk[iv] * cz[iv]
    det = a11 * a22 - a12 * a21
    if abs(det) > 1e-12 * (abs(a11 * a22) + abs(a12 * a21)):
        x_eq[il] = (rhs_y * a22 - a12 * rhs_z) / det
        x_eq[iv] = (a11 * rhs_z - a21 * rhs_y) / det
    else:   # no lateral coupling (cy_sign 0): the lateral mode hangs at its in-air equilibrium
        x_eq[iv] = (rhs_z - a21 * x_eq[il]) / a22
    r_air = grav - k * x_eq
    for i in free:
        r_air[i] = 0.0          # exactly: these modes are at their own equilibrium at rest
    y_fb_eq = float(np.dot(cy, x_eq))

    w = params.leg_half_width_mm * 1e-3
    p = params.leg_pitch_mm * 1e-3
    # Leg n (1-based): odd on +x, even on -x; 1-2 front (+p), 3-4 middle, 5-6 rear (-p).
    xj = np.array([w, -w, w, -w, w, -w])
    yj = np.array([p, p, 0.0, 0.0, -p, -p])
    zj = np.full(6, params.leg_z_mm * 1e-3)
    phase = np.array([1.0 if (n + 1) in TRIPOD_A else -1.0 for n in range(6)])

    if isinstance(scenario, Shaker):
        kind, amp, freq, volt = 0, scenario.amp_um * 1e-6, scenario.freq_hz, 0.0
    else:
        kind, amp, freq, volt = 1, 0.0, scenario.freq_hz, scenario.voltage_v
    g_act = k * np.array(params.act_um_per_v) * 1e-6     # F/m_dis = k * static deflection per volt

    return Model(m_b=m_b, inertia=inertia, g=g, f0=f0, m_f=m_f,
                 b_g_foot=params.b_g_foot_n_m2_s, b_g_body=params.b_g_body_n_m2_s,
                 a_drag=params.a_drag_n_s2_m2, h_min=params.h_min_um * 1e-6, h0=params.body_gap_um * 1e-6,
                 c_ad=params.c_ad_n, c_ad_t=params.c_ad_t_n_s, c_r=params.c_r, c_r_body=params.c_r_body,
                 body_no_slip=params.body_no_slip, mu=params.mu, kind=kind, amp_m=amp, freq_hz=freq, volt=volt, iv=iv, il=il,
                 k=k, b=b, cz=cz, cy=cy, m_modal=m_modal, m_imp=m_imp, m_dis=m_dis, r=r_air, g_act=g_act,
                 ktf=np.array(params.knee_to_foot, float), gamma=gamma, xj=xj, yj=yj, zj=zj, phase=phase,
                 y_foot_eq=yj + y_fb_eq)

# Columns of the recorded trajectory (SI; converted to the result's units later).
REC_T, REC_Y, REC_Z, REC_PH, REC_ZG, REC_FZ, REC_FY, REC_KV = 0, 1, 2, 3, 6, 7, 13, 19
REC_COLS = 25
# Columns of the impact log.
EV_T, EV_LEG, EV_VPRE, EV_VPOST, EV_VYPOST, EV_STUCK = range(6)
EV_COLS = 6
# Integer counters.
CNT_BODY, CNT_EVENTS, CNT_LOST, CNT_FORCED = 6, 7, 8, 9   # 0..5: impacts per foot
CNT_SIZE = 10
#: A foot whose gap is within this of zero at the start of a step counts as touching
#: (a femtometre: the rounding level of the 1e-4 m quantities in the gap), so a
#: decision never hangs on the sign of a rounding error.
GAP_TOL_M = 1e-15
#: A foot in the air whose squeeze film is stiff over the step (dt * c * sum Cz^2/m_imp
#: above SQUEEZE_STIFF) has its modes and squeeze correction sub-cycled in
#: SQUEEZE_SUBSTEPS sub-steps: the operator splitting between the modes' exact
#: propagation and the implicit squeeze correction is first order, and the
#: constant is large when the film glues the foot (see the convergence test).
SQUEEZE_SUBSTEPS = 8
SQUEEZE_STIFF = 1.0
#: Events (impacts) handled inside one step before the step is accepted as is.
MAX_EVENTS_PER_STEP = 24


def rest_state() -> np.ndarray:
    """The robot at rest on still ground: the all-zero state (module docstring)."""
    return np.zeros(S_SIZE)
