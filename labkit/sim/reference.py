"""The plain-Python reference integrator of the hybrid model (readable; slow).

It implements the same scheme as :mod:`labkit.sim.kernel` step for step, but
written for a reader: named constants (:class:`~labkit.sim.model.Model`),
small numpy arrays per leg, one function per physical piece. Tests check the
compiled kernel against it.

One step of length ``dt`` (model.md sections 3-6):

1. **release check** for every pinned foot: it goes back to AIR when the
   upward pull on it exceeds the adhesion ``c_ad_t * t_c + c_ad``;
2. **advance** the whole robot over the step: body accelerations from the leg
   forces (the body's squeeze film implicit), then every mode by the exact
   propagator of its damped oscillator under the step's constant forcing
   (base excitation by the attachment's acceleration, gravity, drag, PZT),
   then the foot's squeeze film as an implicit rank-one velocity correction
   (Sherman-Morrison: it is stiff, ~1e8 1/s near contact; positions get half
   of the correction, trapezoid-like), then the pinned
   pair of every foot in contact from its kinematic constraint;
3. **events**: if a foot in AIR (or the body) crosses the ground inside the
   step, the crossing instant is interpolated, the step is redone up to it,
   the impact map applied (restitution, no lateral slip, 2x2 redistribution
   onto the first vertical and first lateral mode, the foot put exactly on
   the ground), the stick-or-bounce decision taken, and the rest of the step
   integrated — repeatedly, earliest crossing first, so no impact is missed
   or applied twice.
"""
from __future__ import annotations

import math

import numpy as np

from labkit.sim import model as M
from labkit.sim.model import ADHESION, AIR, REST, Model


class RefState:
    """The integrator's state (see :mod:`labkit.sim.model` for the coordinates)."""

    def __init__(self, flat: np.ndarray, mode: np.ndarray) -> None:
        self.q = flat[M.S_Q:M.S_Q + 5].copy()
        self.u = flat[M.S_U:M.S_U + 5].copy()
        self.xi = flat[M.S_XI:M.S_XI + 18].reshape(6, 3).copy()
        self.v = flat[M.S_V:M.S_V + 18].reshape(6, 3).copy()
        self.tc = flat[M.S_TC:M.S_TC + 6].copy()
        self.ypin = flat[M.S_YPIN:M.S_YPIN + 6].copy()
        # contact modes of the 6 feet, then of the body (AIR, or REST on the ground)
        self.mode = np.zeros(7, np.int64)
        self.mode[:len(mode)] = mode[:7]

    def copy(self) -> "RefState":
        return RefState(self.flat(), self.mode)

    def flat(self) -> np.ndarray:
        return np.concatenate([self.q, self.u, self.xi.ravel(), self.v.ravel(), self.tc, self.ypin])


def ground(m: Model, t: float) -> tuple[float, float, float]:
    """Ground height, velocity, acceleration (shaker sine; still for PZT)."""
    if m.kind != 0:
        return 0.0, 0.0, 0.0
    w = m.omega
    s, c = math.sin(w * t), math.cos(w * t)
    return m.amp_m * s, m.amp_m * w * c, -m.amp_m * w * w * s


def square(m: Model, t: float) -> float:
    """PZT drive in volts at time t (square wave; 0 for the shaker)."""
    if m.kind != 1:
        return 0.0
    ph = m.freq_hz * t
    return m.volt if ph - math.floor(ph) < 0.5 else -m.volt


def propagator(k: float, b: float, tau: float) -> tuple[float, float, float, float]:
    """Exact transition of x'' + b x' + k x = 0 over tau: (p11, p12, p21, p22)."""
    sig = 0.5 * b
    disc = k - sig * sig
    e = math.exp(-sig * tau)
    if disc > 1e-9 * k:
        wd = math.sqrt(disc)
        c, s = math.cos(wd * tau), math.sin(wd * tau) / wd
    elif disc < -1e-9 * k:
        wd = math.sqrt(-disc)
        c, s = math.cosh(wd * tau), math.sinh(wd * tau) / wd
    else:
        c, s = 1.0, tau
    return e * (c + sig * s), e * s, -e * k * s, e * (c - sig * s)


def attachment(m: Model, q: np.ndarray, u: np.ndarray):
    """Vertical/lateral position and velocity of the six leg attachments."""
    az = q[1] + m.yj * q[2] - m.xj * q[3]
    ay = q[0] + m.xj * q[4]
    vz = u[1] + m.yj * u[2] - m.xj * u[3]
    vy = u[0] + m.xj * u[4]
    return az, ay, vz, vy


def solve_pair(m: Model, dz: float, dy: float) -> tuple[float, float]:
    """(d_lateral, d_vertical) modal changes giving foot changes (dz, dy) (paper eq. 8)."""
    a, bb = m.cz[m.il], m.cz[m.iv]
    c, d = m.cy[m.il], m.cy[m.iv]
    det = a * d - bb * c
    if abs(det) > 1e-12:
        return (dz * d - bb * dy) / det, (a * dy - c * dz) / det
    # No lateral coupling: the lateral row is empty; minimum-norm vertical solution.
    n2 = a * a + bb * bb
    return a * dz / n2, bb * dz / n2


def pin_pair(m: Model, st: RefState, j: int, zg: float, vg: float) -> None:
    """Set the pinned pair of leg j from the foot's kinematic constraint."""
    az, ay, vz, vy = attachment(m, st.q, st.u)
    il, iv = m.il, m.iv
    fz = sum(m.cz[i] * st.xi[j, i] for i in range(3) if i not in (il, iv))
    fy = sum(m.cy[i] * st.xi[j, i] for i in range(3) if i not in (il, iv))
    gz = sum(m.cz[i] * st.v[j, i] for i in range(3) if i not in (il, iv))
    gy = sum(m.cy[i] * st.v[j, i] for i in range(3) if i not in (il, iv))
    st.xi[j, il], st.xi[j, iv] = solve_pair(m, zg - az[j] - fz, st.ypin[j] - ay[j] - fy)
    st.v[j, il], st.v[j, iv] = solve_pair(m, vg - vz[j] - gz, -vy[j] - gy)


def leg_forces(m: Model, st: RefState):
    """Deviation of every leg's force on the body from its static value, (Fy, Fz) per leg."""
    f = m.m_modal * (m.k * st.xi + m.b * st.v)        # (6, 3)
    return f @ m.cy, f @ m.cz


def pull(m: Model, st: RefState, j: int, vg: float, ag: float) -> float:
    """Upward pull on foot j beyond what keeps it moving with the ground (paper eq. 10)."""
    fz = float(np.dot(m.m_modal * (m.k * st.xi[j] + m.b * st.v[j]), m.cz))
    f_foot = -m.m_f * m.g - m.a_drag * vg * abs(vg)
    return -m.f0 - fz + f_foot - m.m_f * ag


def propagate_modes(m: Model, st: RefState, j: int, h: float, a_mode: np.ndarray) -> None:
    """Exact step h of leg j's modes under constant modal accelerations a_mode."""
    for i in range(3):
        p11, p12, p21, p22 = propagator(m.k[i], m.b[i], h)
        x, v, a = st.xi[j, i], st.v[j, i], a_mode[i]
        st.xi[j, i] = p11 * x + p12 * v + (1.0 - p11) / m.k[i] * a
        st.v[j, i] = p21 * x + p22 * v + p12 * a


def squeeze(m: Model, st: RefState, j: int, h: float, v_base: float, c: float, q: float) -> None:
    """Implicit squeeze-film correction of foot j over h; v_base = attachment - ground velocity.

    ``F = -c (v_foot - v_g)`` is linear in the modal velocities for a frozen gap and
    projects onto the modes as a rank-one term (Sherman-Morrison).
    """
    w = m.cz / m.m_imp
    s = v_base + np.dot(m.cz, st.v[j])
    s_new = s / (1.0 + h * c * q)
    dv = -h * c * s_new * w
    st.v[j] += dv
    # Trapezoidal position update of the correction: without it the free
    # acceleration inside the step would leak into the position.
    st.xi[j] += 0.5 * h * dv


def friction(m: Model, st: RefState, t: float) -> np.ndarray:
    """Coulomb friction (beyond the paper; off when mu is inf): lateral friction force on
    each pinned foot that slips now (NaN for the feet that stick or are in the air)."""
    slip = np.full(6, np.nan)
    if not m.mu < math.inf:
        return slip
    _, vg, ag = ground(m, t)
    for j in range(6):
        if st.mode[j] == AIR:
            continue
        # normal load: compression plus the adhesion holding the foot (Derjaguin)
        normal = max(m.c_ad_t * st.tc[j] + m.c_ad - pull(m, st, j, vg, ag), 0.0)
        fy = float(np.dot(m.m_modal * (m.k * st.xi[j] + m.b * st.v[j]), m.cy))
        if abs(fy) > m.mu * normal:
            slip[j] = math.copysign(m.mu * normal, fy)
    return slip


def slip_pair(m: Model, st: RefState, j: int, zg: float, vg: float) -> None:
    """A slipping pinned foot: put back on the ground vertically, free laterally."""
    az, ay, vz, vy = attachment(m, st.q, st.u)
    il, iv = m.il, m.iv
    dl, dv = solve_pair(m, -(az[j] + np.dot(m.cz, st.xi[j]) - zg), 0.0)
    st.xi[j, il] += dl
    st.xi[j, iv] += dv
    dl, dv = solve_pair(m, -(vz[j] + np.dot(m.cz, st.v[j]) - vg), 0.0)
    st.v[j, il] += dl
    st.v[j, iv] += dv
    st.ypin[j] = ay[j] + np.dot(m.cy, st.xi[j])


def advance(m: Model, st: RefState, t: float, tau: float, slip: np.ndarray | None = None) -> None:
    """Integrate the whole robot from t over tau (no events), in place."""
    if tau <= 0.0:
        return
    zg, vg, ag = ground(m, t)
    zg1, vg1, _ = ground(m, t + tau)
    volt = square(m, t)
    fy, fz = leg_forces(m, st)
    q, u = st.q, st.u
    # ---- body (model.md section 6): drag explicit, squeeze film implicit
    Fy = fy.sum() - m.a_drag * u[0] * abs(u[0])
    Fz = fz.sum() - m.a_drag * u[1] * abs(u[1])
    Mx = np.sum(m.yj * fz - m.zj * fy)
    My = np.sum(-m.xj * fz)
    Mz = np.sum(m.xj * fy)
    hb = m.h0 + q[1] - zg
    cb = m.b_g_body / max(hb, m.h_min) ** 3
    if st.mode[6] == REST:
        vz1 = vg1                # the body rests on the ground: it moves with it
    else:
        vz1 = (u[1] + tau * (Fz / m.m_b + cb * vg1 / m.m_b)) / (1.0 + tau * cb / m.m_b)
    acc = np.array([Fy / m.m_b, (vz1 - u[1]) / tau, Mx / m.inertia[0], My / m.inertia[1], Mz / m.inertia[2]])
    az0, ay0, vz0, vy0 = attachment(m, q, u)
    u1 = u + tau * acc
    u1[1] = vz1
    st.q = q + 0.5 * tau * (u + u1)
    st.u = u1
    if st.mode[6] == REST:
        st.q[1] = zg1 - m.h0
    a_att_z = acc[1] + m.yj * acc[2] - m.xj * acc[3]
    a_att_y = acc[0] + m.xj * acc[4]
    az1, ay1, vz1a, vy1a = attachment(m, st.q, st.u)
    # ---- legs (model.md section 3)
    for j in range(6):
        air = st.mode[j] == AIR
        a_mode = m.r + m.g_act * volt * m.phase[j] - m.gamma * (m.cz * a_att_z[j] + m.cy * a_att_y[j])
        if air:
            vfz = vz0[j] + np.dot(m.cz, st.v[j])
            vfy = vy0[j] + np.dot(m.cy, st.v[j])
            hf = az0[j] + np.dot(m.cz, st.xi[j]) - zg
            a_mode = a_mode + (m.cz * (-m.a_drag * vfz * abs(vfz)) + m.cy * (-m.a_drag * vfy * abs(vfy))) / m.m_imp
        elif slip is not None and not np.isnan(slip[j]):
            a_mode = a_mode + m.cy * slip[j] / m.m_imp
        nsub, c, qs = 1, 0.0, 0.0
        if air:
            qs = float(np.dot(m.cz, m.cz / m.m_imp))
            c = m.b_g_foot / max(hf, m.h_min) ** 3
            if tau * c * qs > M.SQUEEZE_STIFF:
                nsub = M.SQUEEZE_SUBSTEPS
        h = tau / nsub
        for k in range(1, nsub + 1):
            propagate_modes(m, st, j, h, a_mode)
            if not air:
                continue
            if k < nsub:
                # inside the step: the attachment moves with the body's constant acceleration
                zgk, vgk, _ = ground(m, t + k * h)
                squeeze(m, st, j, h, vz0[j] + k * h * a_att_z[j] - vgk, c, qs)
                hk = az0[j] + k * h * (vz0[j] + 0.5 * k * h * a_att_z[j]) - zgk + np.dot(m.cz, st.xi[j])
                c = m.b_g_foot / max(hk, m.h_min) ** 3
            else:
                squeeze(m, st, j, h, vz1a[j] - vg1, c, qs)
        if not air:
            st.tc[j] += tau
            if slip is not None and not np.isnan(slip[j]):
                slip_pair(m, st, j, zg1, vg1)
            else:
                pin_pair(m, st, j, zg1, vg1)


def foot_gap(m: Model, st: RefState, zg: float) -> np.ndarray:
    az, _, _, _ = attachment(m, st.q, st.u)
    return az + st.xi @ m.cz - zg


def foot_vrel(m: Model, st: RefState, vg: float) -> np.ndarray:
    _, _, vz, _ = attachment(m, st.q, st.u)
    return vz + st.v @ m.cz - vg


def impact(m: Model, st: RefState, j: int, t: float, out) -> None:
    """Impact map of foot j at time t (model.md section 5), then stick or bounce."""
    zg, vg, ag = ground(m, t)
    az, ay, vz, vy = attachment(m, st.q, st.u)
    il, iv = m.il, m.iv
    vrel = vz[j] + np.dot(m.cz, st.v[j]) - vg
    vlat = vy[j] + np.dot(m.cy, st.v[j])
    h = az[j] + np.dot(m.cz, st.xi[j]) - zg
    dl, dv = solve_pair(m, -(1.0 + m.c_r) * vrel, -vlat)
    st.v[j, il] += dl
    st.v[j, iv] += dv
    dl, dv = solve_pair(m, -h, 0.0)
    st.xi[j, il] += dl
    st.xi[j, iv] += dv
    vpost = vz[j] + np.dot(m.cz, st.v[j]) - vg
    vypost = vy[j] + np.dot(m.cy, st.v[j])
    f = pull(m, st, j, vg, ag)
    stuck = vpost <= 0.0 or f <= m.c_ad
    out.count[j] += 1
    out.log(t, j, vrel, vpost, vypost, stuck)
    if stuck:
        st.mode[j] = ADHESION if f > 0 else REST
        st.tc[j] = 0.0
        st.ypin[j] = ay[j] + np.dot(m.cy, st.xi[j])
        pin_pair(m, st, j, zg, vg)


def body_impact(m: Model, st: RefState, t: float, dt: float, out) -> None:
    """Restitution of the body's vertical velocity against the ground.

    A rebound slower than what gravity adds in one step ends the bouncing: the
    body rests on the ground (moves with it) until the legs lift it off;
    otherwise it would bounce ever smaller (Zeno).
    """
    zg, vg, _ = ground(m, t)
    vpre = st.u[1] - vg
    st.u[1] = vg - m.c_r_body * vpre
    if m.c_r_body * abs(vpre) <= m.g * dt or vpre >= 0.0:
        st.u[1] = vg
        st.mode[6] = REST
    if m.body_no_slip:
        st.u[0] = 0.0          # no lateral slip of the body either
    st.q[1] = zg - m.h0
    out.count[M.CNT_BODY] += 1
    out.log(t, -1, vpre, st.u[1] - vg, 0.0, False)


def release(m: Model, st: RefState, t: float) -> np.ndarray:
    """Start-of-step check of every pinned foot: release, or relabel ADHESION/REST.

    Returns the contact time of each foot released now (-1 for the others).
    """
    _, vg, ag = ground(m, t)
    released = np.full(6, -1.0)
    for j in range(6):
        if st.mode[j] == AIR:
            continue
        f = pull(m, st, j, vg, ag)
        if f > m.c_ad_t * st.tc[j] + m.c_ad:
            released[j] = st.tc[j]
            st.mode[j] = AIR
            st.tc[j] = 0.0
        else:
            st.mode[j] = ADHESION if f > 0 else REST
    return released


def crossing(h0: float, v0: float, h1: float, rem: float) -> float:
    """When a gap going from h0 >= 0 to h1 < 0 over rem reaches zero (linear)."""
    return rem * h0 / (h0 - h1) if h0 > 0.0 else 0.0


def step(m: Model, st: RefState, t: float, dt: float, out) -> RefState:
    """One full step with event location; returns the new state."""
    released = release(m, st, t)
    slip = friction(m, st, t)
    _, _, ag = ground(m, t)
    if st.mode[6] == REST:
        fy, fz = leg_forces(m, st)
        if fz.sum() - m.a_drag * st.u[1] * abs(st.u[1]) > m.m_b * ag:
            st.mode[6] = AIR     # the legs lift the body off faster than the ground moves
    remaining, now, n_ev = dt, t, 0
    while True:
        trial = st.copy()
        advance(m, trial, now, remaining, slip)
        zg0, vg0, _ = ground(m, now)
        zg1, _, _ = ground(m, now + remaining)
        h0 = foot_gap(m, st, zg0)
        h1 = foot_gap(m, trial, zg1)
        v0 = foot_vrel(m, st, vg0)
        best, who = math.inf, -2
        for j in range(6):
            if st.mode[j] != AIR or trial.mode[j] != AIR or h1[j] >= -M.GAP_TOL_M:
                continue
            if h0[j] >= -M.GAP_TOL_M:
                tau = crossing(h0[j], v0[j], h1[j], remaining)
            elif v0[j] < 0.0:
                tau = 0.0
            else:
                continue
            if tau < best:
                best, who = tau, j
        hb0 = m.h0 + st.q[1] - zg0
        hb1 = m.h0 + trial.q[1] - zg1
        if hb1 < 0.0 and st.mode[6] != REST:
            if hb0 >= -M.GAP_TOL_M:
                tau = crossing(hb0, st.u[1] - vg0, hb1, remaining)
            elif st.u[1] - vg0 < 0.0:
                tau = 0.0
            else:
                tau = math.inf
            if tau < best:
                best, who = tau, -1
        if who == -2:
            return trial
        if n_ev >= M.MAX_EVENTS_PER_STEP:
            out.count[M.CNT_FORCED] += 1
            return trial
        n_ev += 1
        advance(m, st, now, best, slip)
        now += best
        remaining -= best
        if who == -1:
            body_impact(m, st, now, dt, out)
        elif released[who] >= 0.0:
            # Released at the start of this step but back on the ground within it:
            # the foot did not actually leave (the "would move away" test), no impact.
            _, vg, ag = ground(m, now)
            st.mode[who] = ADHESION if pull(m, st, who, vg, ag) > 0 else REST
            st.tc[who] = released[who] + (now - t)
            released[who] = -1.0
            pin_pair(m, st, who, ground(m, now)[0], vg)
        else:
            impact(m, st, who, now, out)
        if remaining <= 0.0:
            return st


class RefOutputs:
    """The arrays both engines fill (same layout as the kernel's)."""

    def __init__(self, n_rec: int, ev_cap: int) -> None:
        self.rec = np.zeros((n_rec, M.REC_COLS))
        self.rec_contact = np.zeros((n_rec, 6), np.int8)
        self.frac = np.zeros((6, 3))
        self.max_air = np.zeros(6)
        self.count = np.zeros(M.CNT_SIZE, np.int64)
        self.events = np.zeros((ev_cap, M.EV_COLS))

    def log(self, t, leg, vpre, vpost, vypost, stuck) -> None:
        n = self.count[M.CNT_EVENTS]
        if n < len(self.events):
            self.events[n] = (t, leg, vpre, vpost, vypost, 1.0 if stuck else 0.0)
            self.count[M.CNT_EVENTS] += 1
        else:
            self.count[M.CNT_LOST] += 1


def record(m: Model, st: RefState, t: float, out: RefOutputs, row: int) -> None:
    zg, vg, _ = ground(m, t)
    az, ay, vz, vy = attachment(m, st.q, st.u)
    r = out.rec[row]
    r[M.REC_T] = t
    r[M.REC_Y] = st.q[0]
    r[M.REC_Z] = m.h0 + st.q[1]
    r[M.REC_PH:M.REC_PH + 3] = st.q[2:5]
    r[M.REC_ZG] = zg
    r[M.REC_FZ:M.REC_FZ + 6] = az + st.xi @ m.cz
    r[M.REC_FY:M.REC_FY + 6] = m.y_foot_eq + ay + st.xi @ m.cy
    r[M.REC_KV:M.REC_KV + 6] = vz + st.v @ (m.ktf * m.cz)
    out.rec_contact[row] = st.mode[:6]


def integrate(m: Model, flat: np.ndarray, mode: np.ndarray, n_steps: int, dt: float, n_rec_every: int,
              n_skip: int, out: RefOutputs) -> tuple[np.ndarray, np.ndarray]:
    """Run n_steps steps of dt from the state (flat, mode); fill ``out``; return the final state."""
    st = RefState(flat, mode)
    air_run = np.zeros(6)
    row = 0
    for n in range(n_steps + 1):
        t = n * dt
        if n % n_rec_every == 0 and row < len(out.rec):
            record(m, st, t, out, row)
            row += 1
        if n == n_steps:
            break
        st = step(m, st, t, dt, out)
        if n >= n_skip:
            for j in range(6):
                out.frac[j, st.mode[j]] += dt
                if st.mode[j] == AIR:
                    air_run[j] += dt
                    out.max_air[j] = max(out.max_air[j], air_run[j])
                else:
                    air_run[j] = 0.0
    return st.flat(), st.mode.astype(np.int8)
