"""From (RobotParams, scenario) to the matrices and constants of the coupled system.

docs/model.md (sections 3-6 and 10, equations M1-M12) is the specification this
module implements; the equation numbers below refer to it.

Generalised coordinates (M1): ``q = (y_b, z_b, phi_x, phi_y, phi_z, x_11, ..., x_63)``:
the body's forward and vertical translation and small rotations, then for
leg ``j`` and mode ``i`` the modal coordinate ``x_ij`` (foot displacement
along the mode's direction ``C_i = (Cy_i, Cz_i)`` relative to the leg's
attachment). All are *deviations from the robot at rest on still ground*
(the static equilibrium on six pinned feet), so the resting robot is q = 0.

Kinetic energy (M2): the body's, plus for every mode the modal mass ``M_i``, a
point at the attachment displaced by ``C_i x_ij``: ``T = 1/2 m_b (y_b'^2 +
z_b'^2) + 1/2 sum I phi'^2 + sum_ij 1/2 M_i |r_att,j' + C_i x_ij'|^2``. Hence one
constant symmetric positive definite mass matrix ``M = diag(m_b, m_b, I_x,
I_y, I_z, 0...) + sum_ij M_i U_ij^T U_ij`` with ``U_ij = [A_j | C_i e_ij^T]``
(``A_j`` the attachment's 2x5 kinematic matrix). The robot's rigid-body mass is
``m_b + sum M_i = mass_mg``: ``m_b`` is the rest of the robot's mass
(``RobotParams.body_coordinate_mass_mg``). The leg's base excitation by the
body's acceleration and its reaction on the body are the two off-diagonal
blocks of the same matrix, so they are consistent by construction, and with
no external force every linear and angular momentum ``M[:5] q'`` is conserved.

Potential and forces (M3, M4): modal springs and dampers ``M_i k_i``,
``M_i b_i`` on the modal coordinates; gravity ``-g (m_b e_z + sum M_i U_ij[z])``, vertical on
every mass (a falling robot does not deform, and does not drift sideways); the PZT actuator as the
generalised force ``M_i G_i V(t)`` on ``x_ij`` alone: a force pair between
leg and body, it changes no momentum.

Choices where model.md is silent (each a RobotParams field or named here):

* legs: leg ``n`` (1-based) at ``x = +w`` for odd ``n``, ``-w`` for even; ``y =
  +p`` for legs 1-2, 0 for 3-4, ``-p`` for 5-6 ({1, 4, 5} is a tripod);
  ``w = leg_half_width_mm``, ``p = leg_pitch_mm``, ``z = leg_z_mm``;
* modal mass ``M_i = modal_participation x leg mass`` (leg mass = (mass_mg -
  body_mass_mg) / 6); the body's coordinates carry the rest of ``mass_mg``; a PZT payload rides on the body;
* one mass matrix means one effective mass per mode: ``m_imp_factor`` and
  ``m_dis_factor`` must be 1 and ``base_participation`` 0 or 1 (both mean the
  mass matrix's own coupling); ``foot_mass_fraction`` no longer enters (gravity
  acts through the modal masses);
* the body touches the ground at the centre of its underside (``body_gap_um``
  at rest);
* air drag acts on the feet in air (both directions, absolute velocity) and on
  the body (y and z);
* ``impact_modes``: which leg modes take part in an impact (1) or are held
  rigid during it (0); ``v_stick_mm_s``: the sticking threshold.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from labkit.errors import InputError
from labkit.sim import scheme as K
from labkit.sim.excitation import PZT, TRIPOD_A, Shaker
from labkit.sim.params import RobotParams

AIR, ADHESION, REST = K.AIR, K.ADHESION, K.REST
MODE_NAMES = ("air", "adhesion", "rest")
NQ, NB, NR = K.NQ, K.NB, K.NR

#: Which coordinates each contact row may involve (pack checks it): the body's, and for the
#: rows of a foot (0-11: normal, then lateral) its own leg's three modes.
_ROW_SPAN = np.zeros((NQ, NR), bool)
_ROW_SPAN[:NB] = True
for _r in range(12):
    _ROW_SPAN[NB + 3 * (_r % 6):NB + 3 * (_r % 6) + 3, _r] = True

# Re-exported layouts (the scheme owns them).
S_Q, S_V, S_TC, S_YPIN, S_LAM, S_SLIP, S_SIZE = K.S_Q, K.S_V, K.S_TC, K.S_YPIN, K.S_LAM, K.S_SLIP, K.S_SIZE
REC_T, REC_Y, REC_Z, REC_PH, REC_ZG, REC_FZ, REC_FY, REC_KV = (K.REC_T, K.REC_Y, K.REC_Z, K.REC_PH, K.REC_ZG,
                                                              K.REC_FZ, K.REC_FY, K.REC_KV)
REC_COLS = K.REC_COLS
EV_T, EV_LEG, EV_VPRE, EV_VPOST, EV_VYPOST, EV_STUCK = (K.EV_T, K.EV_LEG, K.EV_VPRE, K.EV_VPOST, K.EV_VYPOST,
                                                        K.EV_STUCK)
EV_COLS = K.EV_COLS
CNT_BODY, CNT_EVENTS, CNT_LOST, CNT_FORCED, CNT_RELEASES = (K.CNT_BODY, K.CNT_EVENTS, K.CNT_LOST, K.CNT_FORCED,
                                                            K.CNT_RELEASES)
CNT_HALVED, CNT_ADV, CNT_HALVED_TRANSIENT, CNT_NEAR = K.CNT_HALVED, K.CNT_ADV, K.CNT_HALVED_TRANSIENT, K.CNT_NEAR
CNT_SIZE = K.CNT_SIZE

#: An event is located when the gap is within this of zero (m): 0.1 nm.
POS_TOL_M = 1e-10
#: Impacts handled inside one step before the step is accepted as is (counted).
MAX_EVENTS_PER_STEP = 32


def xi(j: int, i: int) -> int:
    """Index of the modal coordinate x_ij (leg j, mode i, 0-based) in q."""
    return NB + 3 * j + i


@dataclass
class Model:
    """The coupled system of one simulation (SI): matrices, rows, scalars."""

    m_b: float
    inertia: np.ndarray           # (3,)
    k: np.ndarray                 # (3,) 1/s^2
    b: np.ndarray                 # (3,) 1/s
    cz: np.ndarray
    cy: np.ndarray
    m_modal: np.ndarray           # (3,) kg
    xj: np.ndarray
    yj: np.ndarray
    zj: np.ndarray
    phase: np.ndarray             # +1 tripod A, -1 tripod B
    mass: np.ndarray              # (NQ, NQ) M
    stiff: np.ndarray             # (NQ,) diagonal of K
    damp: np.ndarray              # (NQ,) diagonal of D
    f_const: np.ndarray           # (NQ,) constant forces in deviation coordinates
    f_act: np.ndarray             # (NQ,) actuator forces per volt
    rows: np.ndarray              # (NQ, NR) contact rows (columns)
    knee: np.ndarray              # (6, NQ) knee vertical velocity rows
    held: np.ndarray              # (18,) 1 = mode held rigid in impacts
    y_foot_eq: np.ndarray         # (6,) lateral foot position at rest (body frame origin)
    x_air: np.ndarray             # (18,) modal deviations of the in-air equilibrium
    lam_rest: np.ndarray          # (NR,) contact forces at rest
    scal: dict[str, float]        # the kernel's named scalars (_scalars)

    @property
    def kind(self) -> int:
        return int(self.scal["KIND"])

    @property
    def amp_m(self) -> float:
        return float(self.scal["AMP"])

    @property
    def omega(self) -> float:
        return float(self.scal["OMEGA"])

    @property
    def h0(self) -> float:
        return float(self.scal["H0"])

    def pack(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(P, A): the flat scalar and matrix vectors the scheme reads, for step ``dt``."""
        P = np.zeros(K.P_SIZE)
        s = dict(self.scal)
        s["DT"] = dt
        for key, value in s.items():
            P[getattr(K, "P_" + key)] = value
        A = np.zeros(K.A_SIZE)
        M = self.mass
        if not np.array_equal(M, M.T):        # the scheme multiplies by M's columns as rows
            raise ValueError("the mass matrix is not exactly symmetric")
        if np.count_nonzero(M[NB:, NB:] - np.diag(np.diag(M[NB:, NB:]))):   # scheme.partial_system
            raise ValueError("the legs' modal coordinates are coupled in the mass matrix")
        # the scheme's row products visit only the body and the row's own leg (scheme.leg_of_row)
        outside = np.nonzero(np.any((self.rows != 0.0) & ~_ROW_SPAN, axis=0))[0]
        if outside.size:
            raise ValueError(f"contact row {outside[0]} involves another leg's modes")
        Minv = np.linalg.inv(M)
        Minv = 0.5 * (Minv + Minv.T)
        RI = np.zeros((NQ, K.NI))
        RI[:, :NR] = self.rows
        RI[NB + np.arange(18), NR + np.arange(18)] = 1.0
        MRI = Minv @ RI
        WI = RI.T @ MRI
        for off, arr in ((K.OFF_M, M), (K.OFF_RT, RI.T), (K.OFF_MRT, MRI.T),
                         (K.OFF_WI, WI), (K.OFF_K, self.stiff), (K.OFF_D, self.damp),
                         (K.OFF_FC, self.f_const), (K.OFF_FA, self.f_act), (K.OFF_KV, self.knee),
                         (K.OFF_YFEQ, self.y_foot_eq), (K.OFF_HELD, self.held)):
            flat = np.ascontiguousarray(arr, dtype=float).ravel()
            A[off:off + flat.size] = flat
        self._pack_levels(A, dt)
        return P, A

    def _pack_levels(self, A: np.ndarray, dt: float) -> None:
        """The step's matrices for ``dt`` and its halvings into ``A`` (exact powers of two: the
        scheme recognises a level by h == dt / 2^k), every level at once (stacked inverses):
        ``S = 2 M + h D + h^2 / 2 K`` and, for the scheme's advance, S^-1 by parts (the legs'
        diagonal, the body's Schur complement), ``(S^-1 R)^T`` and ``R^T S^-1 R``."""
        h = dt * 0.5 ** np.arange(K.NLEV)
        S = 2 * self.mass + h[:, None, None] * np.diag(self.damp) + (0.5 * h * h)[:, None, None] * np.diag(self.stiff)
        Z = np.linalg.inv(S) @ self.rows
        dli = np.zeros((K.NLEV, NQ))
        dli[:, NB:] = 1.0 / np.diagonal(S, axis1=1, axis2=2)[:, NB:]
        sc = S[:, :NB, :NB] - (S[:, :NB, NB:] * dli[:, None, NB:]) @ S[:, NB:, :NB]
        parts = ((K.LEV_DLI, dli), (K.LEV_SCI, np.linalg.inv(sc)), (K.LEV_ZT, Z.transpose(0, 2, 1)),
                 (K.LEV_Q, self.rows.T @ Z))
        lev = K.OFF_LEV + K.LEV_SIZE * np.arange(K.NLEV)[:, None]
        for off, arr in parts:
            flat = arr.reshape(K.NLEV, -1)
            A[lev + off + np.arange(flat.shape[1])] = flat

    # ---------------------------------------------------------------- invariants
    def momentum(self, state: np.ndarray) -> np.ndarray:
        """Generalised momenta of the body coordinates, ``M[:5] q'`` (M12): linear momentum
        along y and z (kg m/s) and angular momentum about x, y, z (kg m^2/s) of the whole
        robot (body and legs), small angles."""
        return self.mass[:NB] @ state[S_V:S_V + NQ]

    def energy(self, state: np.ndarray) -> float:
        """Mechanical energy (J): kinetic + modal springs - work of the constant forces (M12).

        Conserved without damping, air, drive and contact (the constant forces are
        gravity minus the static support, both conservative)."""
        q = state[S_Q:S_Q + NQ]
        v = state[S_V:S_V + NQ]
        return float(0.5 * v @ self.mass @ v + 0.5 * q @ (self.stiff * q) - self.f_const @ q)

    def foot_gap(self, state: np.ndarray) -> np.ndarray:
        """Height of each foot above the ground's rest level (m)."""
        return self.rows[:, :6].T @ state[S_Q:S_Q + NQ]


#: Viscosity of air at 25 C (Pa s): 1.85e-5 (the value of Bao and Yang 2007, the paper's ref. 22).
AIR_VISCOSITY_PA_S = 1.85e-5


def plate_beta(aspect: float, terms: int = 50) -> float:
    """The squeeze-film shape factor of a rectangular plate, width : length = ``aspect`` <= 1:
    ``beta = 1 - (192 / pi^5) aspect sum_{n odd} tanh(n pi / (2 aspect)) / n^5`` (Reynolds'
    equation with the edges at ambient pressure; Bao and Yang 2007, eq. 13). 0.4217 for a square."""
    s = sum(math.tanh(n * math.pi / (2 * aspect)) / n ** 5 for n in range(1, 2 * terms, 2))
    return 1.0 - 192.0 / math.pi ** 5 * aspect * s


def pad_film_coefficient(side_um: float) -> float:
    """The squeeze-film coefficient (N m^2 s) of a square foot pad of this side:
    ``b = beta(1) mu_air a^4`` so that ``F = -b v / h^3`` in the continuum limit (docs/model.md M7)."""
    a = side_um * 1e-6
    return plate_beta(1.0) * AIR_VISCOSITY_PA_S * a ** 4


#: Density of silicon (kg/m^3) and the chassis thickness of the paper (Sec. 2: 30 um silicon).
SILICON_KG_M3 = 2329.0
CHASSIS_THICKNESS_UM = 30.0


def chassis_film_coefficient(params: RobotParams) -> float:
    """The body's squeeze-film coefficient (N m^2 s) from the chassis itself: a solid silicon plate
    of the body's mass, ``CHASSIS_THICKNESS_UM`` thick, with the footprint's aspect
    (``body_width_mm : body_length_mm``): ``b = beta(W / L) mu W^3 L`` (docs/model.md M7).
    8.8e-17 for the paper's 0.28 mg body (a 1.26 x 3.16 mm plate), 590 times Table 1's value."""
    area = params.body_mass_mg * 1e-6 / (SILICON_KG_M3 * CHASSIS_THICKNESS_UM * 1e-6)
    aspect = min(params.body_width_mm, params.body_length_mm) / max(params.body_width_mm, params.body_length_mm)
    w = math.sqrt(area * aspect)
    return plate_beta(aspect) * AIR_VISCOSITY_PA_S * w ** 3 * (area / w)


def _check_single_mass(params: RobotParams) -> None:
    for key in ("m_imp_factor", "m_dis_factor"):
        if getattr(params, key) != 1.0:
            raise InputError(f"{key} = {getattr(params, key)} is not 1: the coupled model has one mass "
                             "matrix, hence one effective mass per mode (docs/model.md M2)", key=key,
                             expected="1")
    if params.base_participation not in (0.0, 1.0):
        raise InputError(f"base_participation = {params.base_participation}: the base excitation follows "
                         "from the mass matrix (docs/model.md M2)", key="base_participation",
                         expected="0 or 1")


def build_model(params: RobotParams, scenario: Shaker | PZT) -> Model:
    """The coupled system for ``params`` driven by ``scenario`` (static equilibrium included)."""
    _check_single_mass(params)
    m_b, inertia = _body(params, scenario)
    legs = _legs(params)
    rows = _contact_rows(legs)
    mass, f_grav = _mass_matrix(legs, m_b, inertia, params.g_m_s2)
    stiff, damp, f_act = _leg_forces(params, legs)
    q_eq, lam_rest = _rest_on_feet(rows, stiff, f_grav)
    # In free fall the legs are undeformed (M4: gravity and the attachment's acceleration
    # cancel in every modal equation), so a robot released in the air starts there.
    x_air = np.array([-q_eq[xi(j, i)] for j in range(6) for i in range(3)])
    y_foot_eq = legs.yj + np.array([legs.cy @ q_eq[xi(j, 0):xi(j, 0) + 3] for j in range(6)]) \
        + np.array([legs.att_y[j] @ q_eq[:NB] for j in range(6)])
    ktf = np.array(params.knee_to_foot, float)
    knee = np.zeros((6, NQ))
    for j in range(6):
        knee[j, :NB] = legs.att_z[j]
        for i in range(3):
            knee[j, xi(j, i)] = ktf[i] * legs.cz[i]
    held = np.tile([0.0 if on else 1.0 for on in params.impact_modes[:3]], 6)
    return Model(m_b=m_b, inertia=inertia, k=legs.k, b=legs.b, cz=legs.cz, cy=legs.cy, m_modal=legs.m_modal,
                 xj=legs.xj, yj=legs.yj, zj=legs.zj, phase=legs.phase, mass=mass, stiff=stiff, damp=damp,
                 f_const=f_grav - stiff * q_eq, f_act=f_act, rows=rows, knee=knee, held=held, y_foot_eq=y_foot_eq,
                 x_air=x_air, lam_rest=lam_rest, scal=_scalars(params, scenario, float(held.sum())))


def _body(params: RobotParams, scenario: Shaker | PZT) -> tuple[float, np.ndarray]:
    """The body coordinates' mass (kg; a PZT payload rides on it) and its inertia about x, y, z."""
    mg = 1e-6  # mg -> kg
    m_b = params.body_coordinate_mass_mg * mg         # M2: the model's masses add up to mass_mg
    if isinstance(scenario, PZT) and scenario.mass_mg is not None:
        # The payload rides on the body (the legs keep their mass).
        m_b += (scenario.mass_mg - params.mass_mg) * mg
        if m_b <= 0:
            modal = params.mass_mg - params.body_coordinate_mass_mg
            raise InputError(f"total mass {scenario.mass_mg} mg is not above the legs' modal masses "
                             f"({modal:.4g} mg)", key="mass_mg", expected=f"a number in mg, > {modal:.4g}")
    L = params.body_length_mm * 1e-3
    W = params.body_width_mm * 1e-3
    # Thin plate: rotation about x (across the width) sees the length, etc.
    return m_b, np.array([m_b * L * L / 12, m_b * W * W / 12, m_b * (L * L + W * W) / 12])


@dataclass(frozen=True)
class _Legs:
    """The legs' modes and where they stand: per mode (3,) ``k``, ``b``, the direction ``cz``, ``cy``
    and the modal mass; per leg (6,) the attachment ``xj``, ``yj``, ``zj``, the tripod ``phase``, and
    the attachment's kinematic rows ``att_z``, ``att_y`` (6 x NB, M1)."""

    k: np.ndarray
    b: np.ndarray
    cz: np.ndarray
    cy: np.ndarray
    m_modal: np.ndarray
    xj: np.ndarray
    yj: np.ndarray
    zj: np.ndarray
    phase: np.ndarray
    att_z: np.ndarray
    att_y: np.ndarray


def _legs(params: RobotParams) -> _Legs:
    r = np.array(params.ratio, float)
    norm = np.sqrt(1 + r * r)
    w = params.leg_half_width_mm * 1e-3
    p = params.leg_pitch_mm * 1e-3
    xj = np.array([w, -w, w, -w, w, -w])
    yj = np.array([p, p, 0.0, 0.0, -p, -p])
    zj = np.full(6, params.leg_z_mm * 1e-3)
    # Attachment kinematics (M1): z_att = z_b + y_j phx - x_j phy, y_att = y_b - z_j phx + x_j phz.
    att_z = np.array([(0.0, 1.0, yj[j], -xj[j], 0.0) for j in range(6)])
    att_y = np.array([(1.0, 0.0, -zj[j], 0.0, xj[j]) for j in range(6)])
    return _Legs(k=np.array(params.k_per_s2, float), b=np.array(params.b_per_s, float),
                 cz=1 / norm, cy=np.array(params.cy_sign, float) * r / norm,       # model.md section 2
                 m_modal=np.full(3, params.modal_participation * (params.leg_mass_mg * 1e-6)), xj=xj, yj=yj, zj=zj,
                 phase=np.array([1.0 if (n + 1) in TRIPOD_A else -1.0 for n in range(6)]), att_z=att_z, att_y=att_y)


def _contact_rows(legs: _Legs) -> np.ndarray:
    """The contact rows as columns (NQ x NR): foot z, foot y, body z, body y (M1)."""
    rows = np.zeros((NQ, NR))
    for j in range(6):
        rows[:NB, j] = legs.att_z[j]
        rows[:NB, 6 + j] = legs.att_y[j]
        for i in range(3):
            rows[xi(j, i), j] = legs.cz[i]
            rows[xi(j, i), 6 + j] = legs.cy[i]
    rows[1, K.ROW_BZ] = 1.0
    rows[0, K.ROW_BY] = 1.0
    return rows


def _mass_matrix(legs: _Legs, m_b: float, inertia: np.ndarray, g: float) -> tuple[np.ndarray, np.ndarray]:
    """The mass matrix (M2) and the weights (M4) of the body and the modal masses."""
    mass = np.zeros((NQ, NQ))
    mass[0, 0] = mass[1, 1] = m_b
    mass[2, 2], mass[3, 3], mass[4, 4] = inertia
    f_grav = np.zeros(NQ)
    f_grav[1] = -m_b * g
    for j in range(6):
        for i in range(3):
            # M2: the modal mass is a point at the attachment displaced by C_i x_ij:
            # velocity U q' with U's rows y and z (2 x NQ)
            U = np.zeros((3, NQ))
            U[0, :NB] = legs.att_y[j]
            U[1, :NB] = legs.att_z[j]
            U[0, xi(j, i)] = legs.cy[i]
            U[1, xi(j, i)] = legs.cz[i]
            # ... and along x: x_att = z_j phy - y_j phz (the leg masses' share of the yaw and
            # roll inertia; x itself is no coordinate, M1)
            U[2, :NB] = (0.0, 0.0, 0.0, legs.zj[j], -legs.yj[j])
            mass += legs.m_modal[i] * U.T @ U
            f_grav += -g * legs.m_modal[i] * U[1]                  # M4: its weight, vertical
    return 0.5 * (mass + mass.T), f_grav


def _leg_forces(params: RobotParams, legs: _Legs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Diagonals of the modal springs and dampers, and the actuator's force per volt (M3, M4)."""
    stiff = np.zeros(NQ)
    damp = np.zeros(NQ)
    f_act = np.zeros(NQ)
    g_act = legs.k * np.array(params.act_um_per_v) * 1e-6       # static modal deflection per volt
    for j in range(6):
        for i in range(3):
            stiff[xi(j, i)] = legs.m_modal[i] * legs.k[i]
            damp[xi(j, i)] = legs.m_modal[i] * legs.b[i]
            f_act[xi(j, i)] = legs.m_modal[i] * g_act[i] * legs.phase[j]   # M4: internal force pair
    return stiff, damp, f_act


def _rest_on_feet(rows: np.ndarray, stiff: np.ndarray, f_grav: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Static equilibrium on six pinned feet (absolute coordinates, legs unstretched at 0):
    ``K q = f_grav + R12 lam``, ``R12^T q = 0``; returns q and the contact forces (NR,)."""
    R12 = rows[:, :12]
    kkt = np.zeros((NQ + 12, NQ + 12))
    kkt[:NQ, :NQ] = np.diag(stiff)
    kkt[:NQ, NQ:] = -R12
    kkt[NQ:, :NQ] = R12.T
    # least squares: with cy_sign = 0 the lateral rows are dependent (their forces are then
    # the minimum-norm ones; the coordinates are unique)
    sol = np.linalg.lstsq(kkt, np.concatenate([f_grav, np.zeros(12)]), rcond=None)[0]
    lam_rest = np.zeros(NR)
    lam_rest[:12] = sol[NQ:]
    return sol[:NQ], lam_rest


def _scalars(params: RobotParams, scenario: Shaker | PZT, n_held: float) -> dict[str, float]:
    """The kernel's named scalars (films, contact, drive, tolerances; :meth:`Model.pack`)."""
    if isinstance(scenario, Shaker):
        kind, amp, freq, volt = 0, scenario.amp_um * 1e-6, scenario.freq_hz, 0.0
    else:
        kind, amp, freq, volt = 1, 0.0, scenario.freq_hz, scenario.voltage_v
    return dict(H0=params.body_gap_um * 1e-6, HR=params.film_gap_nm * 1e-9, BGF=params.b_g_foot_n_m2_s,
                BGP=pad_film_coefficient(params.foot_pad_um), HL=params.body_gap_um * 1e-6,
                LAM=params.mean_free_path_nm * 1e-9,
                BGB=params.b_g_body_n_m2_s, AD=params.a_drag_n_s2_m2, CAD=params.c_ad_n, CADT=params.c_ad_t_n_s,
                CR=params.c_r, CRB=params.c_r_body, VSTICK=params.v_stick_mm_s * 1e-3,
                MU=params.mu if math.isfinite(params.mu) else 1e308, BNS=1.0 if params.body_no_slip else 0.0,
                KIND=kind, AMP=amp, OMEGA=2 * math.pi * freq, FREQ=freq, VOLT=volt, GAPTOL=0.0,
                MAXEV=MAX_EVENTS_PER_STEP, NHELD=n_held, POSTOL=POS_TOL_M)


def rest_state(mdl: Model | None = None) -> np.ndarray:
    """The robot at rest on still ground: all-zero coordinates, the static contact forces."""
    s = np.zeros(S_SIZE)
    if mdl is not None:
        s[S_LAM:S_LAM + NR] = mdl.lam_rest
    return s


def air_state(mdl: Model, height_m: float) -> np.ndarray:
    """At rest in the air: body underside ``height_m`` above its resting height, legs at
    their in-air equilibrium (so nothing moves relative to the body in free fall)."""
    s = np.zeros(S_SIZE)
    s[S_Q + 1] = height_m
    s[S_Q + NB:S_Q + NQ] = mdl.x_air
    return s


def lowest_foot_drop_m(mdl: Model) -> float:
    """How far below its resting height the lowest foot hangs when the legs are unloaded (m)."""
    s = air_state(mdl, 0.0)
    return float(max(0.0, -mdl.foot_gap(s).min()))
