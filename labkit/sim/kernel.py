"""The compiled fixed-step integrator (numba, ``cache=True``).

The same scheme as :mod:`labkit.sim.reference` (read that module for the
physics, step by step), on flat float64 arrays so the loop runs without
Python objects or allocation: the constants ``P`` (layout
:data:`labkit.sim.model.IDX`), the state ``S`` (layout ``S_*`` in
:mod:`labkit.sim.model`), the contact modes, and preallocated outputs. A
scratch vector ``W`` holds per-step temporaries.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from labkit.sim import model as _m

# numba freezes module-level ints (the layouts below) into the cached machine
# code, and its cache only watches this file. So this file carries the layout it
# was written for; a change of the layout in model.py must be copied here, which
# also refreshes the cache.
_LAYOUT = (
    "([('AD', 9), ('AMP', 18), ('B', 33), ('BGB', 8), ('BGF', 7), ('BNS', 29), ('CAD', 12), ('C"
    "ADT', 13), ('CR', 14), ('CRB', 15), ('CY', 39), ('CZ', 36), ('F0', 5), ('FREQ', 20), ('G',"
    " 4), ('GACT', 54), ('GAM', 60), ('GAPTOL', 27), ('H0', 11), ('HMIN', 10), ('IL', 23), ('IV"
    "', 22), ('IX', 1), ('IY', 2), ('IZ', 3), ('K', 30), ('KIND', 17), ('KTF', 57), ('M', 42), "
    "('MAXEV', 28), ('MB', 0), ('MDIS', 48), ('MF', 6), ('MIMP', 45), ('MU', 16), ('NSUB', 25),"
    " ('OMEGA', 19), ('PH', 84), ('PINV', 96), ('QSQ', 24), ('R', 51), ('SQSTIFF', 26), ('VOLT'"
    ", 21), ('WZ', 63), ('XJ', 66), ('YFEQ', 90), ('YJ', 72), ('ZJ', 78)], 58, 25, 6, 10)"
)
if _m.layout_signature() != _LAYOUT:
    raise ImportError("labkit.sim.kernel: the array layout in labkit/sim/model.py changed; "
                      "paste labkit.sim.model.layout_signature() into kernel._LAYOUT")

# numba sees module-level ints as compile-time constants.
MB, IX, IY, IZ, G, F0, MF = (_m.IDX[k] for k in ("MB", "IX", "IY", "IZ", "G", "F0", "MF"))
BGF, BGB, AD, HMIN, H0 = (_m.IDX[k] for k in ("BGF", "BGB", "AD", "HMIN", "H0"))
CAD, CADT, CR, CRB, MU = (_m.IDX[k] for k in ("CAD", "CADT", "CR", "CRB", "MU"))
KIND, AMP, OMEGA, FREQ, VOLT, IV, IL = (_m.IDX[k] for k in ("KIND", "AMP", "OMEGA", "FREQ", "VOLT", "IV", "IL"))
K, B, CZ, CY, MM, MIMP, MDIS, R, GACT, KTF, GAM, WZ = (_m.IDX[k] for k in (
    "K", "B", "CZ", "CY", "M", "MIMP", "MDIS", "R", "GACT", "KTF", "GAM", "WZ"))
PINV = _m.IDX["PINV"]
XJ, YJ, ZJ, PH, YFEQ = (_m.IDX[k] for k in ("XJ", "YJ", "ZJ", "PH", "YFEQ"))
SQ, SU, SXI, SV, STC, SYP, SSIZE = _m.S_Q, _m.S_U, _m.S_XI, _m.S_V, _m.S_TC, _m.S_YPIN, _m.S_SIZE
AIR, ADHESION, REST = _m.AIR, _m.ADHESION, _m.REST
REC_T, REC_Y, REC_Z, REC_PH, REC_ZG, REC_FZ, REC_FY, REC_KV = (
    _m.REC_T, _m.REC_Y, _m.REC_Z, _m.REC_PH, _m.REC_ZG, _m.REC_FZ, _m.REC_FY, _m.REC_KV)
CNT_BODY, CNT_EVENTS, CNT_LOST, CNT_FORCED = _m.CNT_BODY, _m.CNT_EVENTS, _m.CNT_LOST, _m.CNT_FORCED
QSQ, NSUB, SQSTIFF, GAPTOL, MAXEV, BNS = (_m.IDX[k] for k in ("QSQ", "NSUB", "SQSTIFF", "GAPTOL", "MAXEV", "BNS"))
# Scratch layout (W).
# A propagator is 5 numbers per mode: p11, p12, p21, p22 and (1 - p11) / k.
W_PROP = 0      # 3 x 5 propagator of the full step
W_PP = 15       # 3 x 5 propagator of a partial step
W_PSUB = 30     # 3 x 5 propagator of a squeeze sub-step of a full step
W_PPS = 45      # 3 x 5 propagator of a squeeze sub-step of a partial step
W_FY = 60       # 6 attachment lateral velocities at the start of an advance
W_FZ = 66       # 6 attachment vertical velocities at the start of an advance
W_REL = 72      # 6 contact time of feet released this step (-1 otherwise)
W_AZ = 78       # 6 attachment heights at the start of an advance
W_A = 84        # 3 modal accelerations of the leg being advanced
W_GZ = 87       # ground height at the squeeze sub-steps (up to 32)
W_GV = 120      # ground velocity at the squeeze sub-steps
W_SLIP = 153    # 6 lateral friction force on a slipping pinned foot (NaN: it sticks)
W_SIZE = 159


@njit(cache=True)
def _ground(P, t):
    if P[KIND] != 0.0:
        return 0.0, 0.0, 0.0
    w = P[OMEGA]
    s = math.sin(w * t)
    c = math.cos(w * t)
    a = P[AMP]
    return a * s, a * w * c, -a * w * w * s


@njit(cache=True)
def _square(P, t):
    if P[KIND] != 1.0:
        return 0.0
    ph = P[FREQ] * t
    return P[VOLT] if ph - math.floor(ph) < 0.5 else -P[VOLT]


@njit(cache=True)
def _propagators(P, tau, W, off):
    for i in range(3):
        k = P[K + i]
        sig = 0.5 * P[B + i]
        disc = k - sig * sig
        e = math.exp(-sig * tau)
        if disc > 1e-9 * k:
            wd = math.sqrt(disc)
            c = math.cos(wd * tau)
            s = math.sin(wd * tau) / wd
        elif disc < -1e-9 * k:
            wd = math.sqrt(-disc)
            c = math.cosh(wd * tau)
            s = math.sinh(wd * tau) / wd
        else:
            c = 1.0
            s = tau
        p11 = e * (c + sig * s)
        W[off + 5 * i] = p11
        W[off + 5 * i + 1] = e * s
        W[off + 5 * i + 2] = -e * k * s
        W[off + 5 * i + 3] = e * (c - sig * s)
        W[off + 5 * i + 4] = (1.0 - p11) / k


@njit(cache=True)
def _solve_pair(P, dz, dy):
    """(lateral, vertical) modal changes for foot changes (dz, dy): the 2x2 solve of
    paper eq. 8, by its inverse precomputed in model.py (minimum norm if singular)."""
    return P[PINV] * dz + P[PINV + 1] * dy, P[PINV + 2] * dz + P[PINV + 3] * dy


@njit(cache=True)
def _att(P, S, j):
    """Attachment z, y, vz, vy of leg j."""
    x = P[XJ + j]
    y = P[YJ + j]
    az = S[SQ + 1] + y * S[SQ + 2] - x * S[SQ + 3]
    ay = S[SQ + 0] + x * S[SQ + 4]
    vz = S[SU + 1] + y * S[SU + 2] - x * S[SU + 3]
    vy = S[SU + 0] + x * S[SU + 4]
    return az, ay, vz, vy


@njit(cache=True)
def _pin_pair(P, S, j, zg, vg):
    il = int(P[IL])
    iv = int(P[IV])
    az, ay, vz, vy = _att(P, S, j)
    fz = 0.0
    fy = 0.0
    gz = 0.0
    gy = 0.0
    for i in range(3):
        if i != il and i != iv:
            fz += P[CZ + i] * S[SXI + 3 * j + i]
            fy += P[CY + i] * S[SXI + 3 * j + i]
            gz += P[CZ + i] * S[SV + 3 * j + i]
            gy += P[CY + i] * S[SV + 3 * j + i]
    xl, xv = _solve_pair(P, zg - az - fz, S[SYP + j] - ay - fy)
    S[SXI + 3 * j + il] = xl
    S[SXI + 3 * j + iv] = xv
    vl, vv = _solve_pair(P, vg - vz - gz, -vy - gy)
    S[SV + 3 * j + il] = vl
    S[SV + 3 * j + iv] = vv


@njit(cache=True)
def _slip(P, S, W, j, zg, vg):
    """A slipping pinned foot: held vertically on the ground, free laterally (friction in W_SLIP)."""
    il = int(P[IL])
    iv = int(P[IV])
    az, ay, vz, vy = _att(P, S, j)
    hz = az - zg
    vr = vz - vg
    yf = ay
    for i in range(3):
        hz += P[CZ + i] * S[SXI + 3 * j + i]
        vr += P[CZ + i] * S[SV + 3 * j + i]
    dl, dv = _solve_pair(P, -hz, 0.0)
    S[SXI + 3 * j + il] += dl
    S[SXI + 3 * j + iv] += dv
    dl, dv = _solve_pair(P, -vr, 0.0)
    S[SV + 3 * j + il] += dl
    S[SV + 3 * j + iv] += dv
    for i in range(3):
        yf += P[CY + i] * S[SXI + 3 * j + i]
    S[SYP + j] = yf


@njit(cache=True)
def _pull(P, S, j, vg, ag):
    fz = 0.0
    for i in range(3):
        fz += P[MM + i] * (P[K + i] * S[SXI + 3 * j + i] + P[B + i] * S[SV + 3 * j + i]) * P[CZ + i]
    f_foot = -P[MF] * P[G] - P[AD] * vg * abs(vg)
    return -P[F0] - fz + f_foot - P[MF] * ag


@njit(cache=True)
def _ground_table(P, t, tau, W):
    """Ground height/velocity at t + k tau/NSUB, k = 0..NSUB (rotation recurrence: no sin/cos per point)."""
    n = int(P[NSUB])
    if P[KIND] != 0.0:
        for k in range(n + 1):
            W[W_GZ + k] = 0.0
            W[W_GV + k] = 0.0
        return
    w = P[OMEGA]
    a = P[AMP]
    s = math.sin(w * t)
    c = math.cos(w * t)
    dc = math.cos(w * tau / n)
    ds = math.sin(w * tau / n)
    for k in range(n + 1):
        W[W_GZ + k] = a * s
        W[W_GV + k] = a * w * c
        s, c = s * dc + c * ds, c * dc - s * ds


@njit(cache=True)
def _prop1(P, S, W, off, j, i):
    """Exact step of mode i of leg j under the constant modal acceleration W[W_A + i]."""
    o = off + 5 * i
    x = S[SXI + 3 * j + i]
    v = S[SV + 3 * j + i]
    a = W[W_A + i]
    S[SXI + 3 * j + i] = W[o] * x + W[o + 1] * v + W[o + 4] * a
    S[SV + 3 * j + i] = W[o + 2] * x + W[o + 3] * v + W[o + 1] * a


@njit(cache=True)
def _squeeze(P, S, W, j, h, v_base, c, q):
    """Implicit squeeze-film correction of leg j over h (v_base: attachment minus ground velocity)."""
    s = v_base
    for i in range(3):
        s += P[CZ + i] * S[SV + 3 * j + i]
    s_new = s / (1.0 + h * c * q)
    for i in range(3):
        dv = -h * c * s_new * P[WZ + i]
        S[SV + 3 * j + i] += dv
        S[SXI + 3 * j + i] += 0.5 * h * dv


@njit(cache=True)
def _advance(P, S, mode, t, tau, dt, W):
    if tau <= 0.0:
        return
    _ground_table(P, t, tau, W)
    nt = int(P[NSUB])
    zg = W[W_GZ]
    vg = W[W_GV]
    zg1 = W[W_GZ + nt]
    vg1 = W[W_GV + nt]
    volt = _square(P, t)
    if tau == dt:
        off = W_PROP
    else:
        _propagators(P, tau, W, W_PP)
        off = W_PP
    # leg forces on the body (deviation from static)
    Fy = 0.0
    Fz = 0.0
    Mx = 0.0
    My = 0.0
    Mz = 0.0
    for j in range(6):
        fy = 0.0
        fz = 0.0
        for i in range(3):
            f = P[MM + i] * (P[K + i] * S[SXI + 3 * j + i] + P[B + i] * S[SV + 3 * j + i])
            fy += f * P[CY + i]
            fz += f * P[CZ + i]
        Fy += fy
        Fz += fz
        Mx += P[YJ + j] * fz - P[ZJ + j] * fy
        My += -P[XJ + j] * fz
        Mz += P[XJ + j] * fy
    u0 = S[SU + 0]
    u1 = S[SU + 1]
    Fy -= P[AD] * u0 * abs(u0)
    Fz -= P[AD] * u1 * abs(u1)
    mb = P[MB]
    hb = P[H0] + S[SQ + 1] - zg
    hh = hb if hb > P[HMIN] else P[HMIN]
    cb = P[BGB] / (hh * hh * hh)
    if mode[6] == REST:
        vz1 = vg1                # the body rests on the ground: it moves with it
    else:
        vz1 = (u1 + tau * (Fz / mb + cb * vg1 / mb)) / (1.0 + tau * cb / mb)
    a0 = Fy / mb
    a1 = (vz1 - u1) / tau
    a2 = Mx / P[IX]
    a3 = My / P[IY]
    a4 = Mz / P[IZ]
    # attachment states at the start (for the feet in air), stored before the body moves
    for j in range(6):
        az, ay, vz, vy = _att(P, S, j)
        W[W_FY + j] = vy
        W[W_FZ + j] = vz
        W[W_AZ + j] = az
    # body update (trapezoid on positions; exact for constant acceleration)
    n0 = u0 + tau * a0
    n2 = S[SU + 2] + tau * a2
    n3 = S[SU + 3] + tau * a3
    n4 = S[SU + 4] + tau * a4
    S[SQ + 0] += 0.5 * tau * (u0 + n0)
    if mode[6] == REST:
        S[SQ + 1] = zg1 - P[H0]
    else:
        S[SQ + 1] += 0.5 * tau * (u1 + vz1)
    S[SQ + 2] += 0.5 * tau * (S[SU + 2] + n2)
    S[SQ + 3] += 0.5 * tau * (S[SU + 3] + n3)
    S[SQ + 4] += 0.5 * tau * (S[SU + 4] + n4)
    S[SU + 0] = n0
    S[SU + 1] = vz1
    S[SU + 2] = n2
    S[SU + 3] = n3
    S[SU + 4] = n4
    for j in range(6):
        xj = P[XJ + j]
        yj = P[YJ + j]
        aaz = a1 + yj * a2 - xj * a3
        aay = a0 + xj * a4
        air = mode[j] == AIR
        ffz = 0.0
        ffy = 0.0
        hf = 0.0
        if air:
            vfz = W[W_FZ + j]
            vfy = W[W_FY + j]
            for i in range(3):
                vfz += P[CZ + i] * S[SV + 3 * j + i]
                vfy += P[CY + i] * S[SV + 3 * j + i]
            ffz = -P[AD] * vfz * abs(vfz)
            ffy = -P[AD] * vfy * abs(vfy)
            hf = W[W_AZ + j] - zg
            for i in range(3):
                hf += P[CZ + i] * S[SXI + 3 * j + i]
        drive = volt * P[PH + j]
        nsub = 1
        c = 0.0
        q = 0.0
        if air:
            q = P[QSQ]
            hh = hf if hf > P[HMIN] else P[HMIN]
            c = P[BGF] / (hh * hh * hh)
            if tau * c * q > P[SQSTIFF]:
                nsub = int(P[NSUB])
        for i in range(3):
            a = P[R + i] + P[GACT + i] * drive - P[GAM + i] * (P[CZ + i] * aaz + P[CY + i] * aay)
            if air:
                a += (P[CZ + i] * ffz + P[CY + i] * ffy) / P[MIMP + i]
            elif W[W_SLIP + j] == W[W_SLIP + j]:     # not NaN: slipping
                a += P[CY + i] * W[W_SLIP + j] / P[MIMP + i]
            W[W_A + i] = a
        if nsub == 1:
            for i in range(3):
                _prop1(P, S, W, off, j, i)
        else:
            # Stiff squeeze film: sub-cycle this leg's modes and its squeeze
            # correction (the body's acceleration is constant over the step).
            h = tau / nsub
            if tau == dt:
                offs = W_PSUB
            else:
                _propagators(P, h, W, W_PPS)
                offs = W_PPS
            vzs = W[W_FZ + j]
            for k in range(1, nsub):
                for i in range(3):
                    _prop1(P, S, W, offs, j, i)
                zgk = W[W_GZ + k]
                vgk = W[W_GV + k]
                _squeeze(P, S, W, j, h, vzs + (k * h) * aaz - vgk, c, q)
                hk = W[W_AZ + j] + (k * h) * (W[W_FZ + j] + 0.5 * (k * h) * aaz) - zgk
                for i in range(3):
                    hk += P[CZ + i] * S[SXI + 3 * j + i]
                hh = hk if hk > P[HMIN] else P[HMIN]
                c = P[BGF] / (hh * hh * hh)
            for i in range(3):
                _prop1(P, S, W, offs, j, i)
        if air:
            az1, ay1, vz1a, vy1a = _att(P, S, j)
            _squeeze(P, S, W, j, tau / nsub, vz1a - vg1, c, q)
        else:
            S[STC + j] += tau
            if W[W_SLIP + j] == W[W_SLIP + j]:
                _slip(P, S, W, j, zg1, vg1)
            else:
                _pin_pair(P, S, j, zg1, vg1)


@njit(cache=True)
def _gap_vrel(P, S, j, zg, vg):
    az, ay, vz, vy = _att(P, S, j)
    h = az - zg
    vr = vz - vg
    for i in range(3):
        h += P[CZ + i] * S[SXI + 3 * j + i]
        vr += P[CZ + i] * S[SV + 3 * j + i]
    return h, vr


@njit(cache=True)
def _log(events, count, t, leg, vpre, vpost, vypost, stuck):
    n = count[CNT_EVENTS]
    if n < events.shape[0]:
        events[n, 0] = t
        events[n, 1] = leg
        events[n, 2] = vpre
        events[n, 3] = vpost
        events[n, 4] = vypost
        events[n, 5] = 1.0 if stuck else 0.0
        count[CNT_EVENTS] += 1
    else:
        count[CNT_LOST] += 1


@njit(cache=True)
def _impact(P, S, mode, j, t, events, count):
    zg, vg, ag = _ground(P, t)
    il = int(P[IL])
    iv = int(P[IV])
    az, ay, vz, vy = _att(P, S, j)
    vrel = vz - vg
    vlat = vy
    h = az - zg
    for i in range(3):
        vrel += P[CZ + i] * S[SV + 3 * j + i]
        vlat += P[CY + i] * S[SV + 3 * j + i]
        h += P[CZ + i] * S[SXI + 3 * j + i]
    dl, dv = _solve_pair(P, -(1.0 + P[CR]) * vrel, -vlat)
    S[SV + 3 * j + il] += dl
    S[SV + 3 * j + iv] += dv
    dl, dv = _solve_pair(P, -h, 0.0)
    S[SXI + 3 * j + il] += dl
    S[SXI + 3 * j + iv] += dv
    vpost = vz - vg
    vypost = vy
    ypin = ay
    for i in range(3):
        vpost += P[CZ + i] * S[SV + 3 * j + i]
        vypost += P[CY + i] * S[SV + 3 * j + i]
        ypin += P[CY + i] * S[SXI + 3 * j + i]
    f = _pull(P, S, j, vg, ag)
    stuck = vpost <= 0.0 or f <= P[CAD]
    count[j] += 1
    _log(events, count, t, j, vrel, vpost, vypost, stuck)
    if stuck:
        mode[j] = ADHESION if f > 0.0 else REST
        S[STC + j] = 0.0
        S[SYP + j] = ypin
        _pin_pair(P, S, j, zg, vg)


@njit(cache=True)
def _body_fz(P, S):
    """Vertical force on the body beyond its weight: legs (deviation) and drag."""
    fz = 0.0
    for j in range(6):
        for i in range(3):
            fz += P[MM + i] * (P[K + i] * S[SXI + 3 * j + i] + P[B + i] * S[SV + 3 * j + i]) * P[CZ + i]
    u1 = S[SU + 1]
    return fz - P[AD] * u1 * abs(u1)


@njit(cache=True)
def _friction(P, S, mode, vg, ag, W):
    """Coulomb friction (beyond the paper; off when mu is inf): which pinned feet slip now."""
    for j in range(6):
        W[W_SLIP + j] = math.nan
        if mode[j] == AIR or not P[MU] < math.inf:
            continue
        # normal load: compression plus the adhesion holding the foot (Derjaguin)
        normal = P[CADT] * S[STC + j] + P[CAD] - _pull(P, S, j, vg, ag)
        if normal < 0.0:
            normal = 0.0
        fy = 0.0
        for i in range(3):
            fy += P[MM + i] * (P[K + i] * S[SXI + 3 * j + i] + P[B + i] * S[SV + 3 * j + i]) * P[CY + i]
        if abs(fy) > P[MU] * normal:
            # the leg pushes the body by fy, so the foot by -fy; the ground resists at mu N
            W[W_SLIP + j] = (1.0 if fy > 0.0 else -1.0) * P[MU] * normal


@njit(cache=True)
def _crossing(h0, v0, h1, rem):
    """When a gap going from h0 >= 0 to h1 < 0 over rem reaches zero (linear)."""
    return rem * h0 / (h0 - h1) if h0 > 0.0 else 0.0


@njit(cache=True)
def _step(P, S, T, mode, t, dt, W, events, count):
    """One step with event location; the result is left in S."""
    zg, vg, ag = _ground(P, t)
    for j in range(6):
        W[W_REL + j] = -1.0
        if mode[j] == AIR:
            continue
        f = _pull(P, S, j, vg, ag)
        if f > P[CADT] * S[STC + j] + P[CAD]:
            W[W_REL + j] = S[STC + j]
            mode[j] = AIR
            S[STC + j] = 0.0
        else:
            mode[j] = ADHESION if f > 0.0 else REST
    _friction(P, S, mode, vg, ag, W)
    if mode[6] == REST and _body_fz(P, S) > P[MB] * ag:
        mode[6] = AIR            # the legs lift the body off faster than the ground moves
    remaining = dt
    now = t
    n_ev = 0
    while True:
        for k in range(SSIZE):
            T[k] = S[k]
        _advance(P, T, mode, now, remaining, dt, W)
        # the trial advance left the ground at now .. now + remaining in W
        nt = int(P[NSUB])
        zg0 = W[W_GZ]
        vg0 = W[W_GV]
        zg1 = W[W_GZ + nt]
        vg1 = W[W_GV + nt]
        best = math.inf
        who = -2
        for j in range(6):
            if mode[j] != AIR:
                continue
            h1, v1 = _gap_vrel(P, T, j, zg1, vg1)
            if h1 >= -P[GAPTOL]:
                continue
            h0, v0 = _gap_vrel(P, S, j, zg0, vg0)
            if h0 >= -P[GAPTOL]:
                tau = _crossing(h0, v0, h1, remaining)
            elif v0 < 0.0:
                tau = 0.0
            else:
                continue
            if tau < best:
                best = tau
                who = j
        hb0 = P[H0] + S[SQ + 1] - zg0
        hb1 = P[H0] + T[SQ + 1] - zg1
        if hb1 < 0.0 and mode[6] != REST:
            if hb0 >= -P[GAPTOL]:
                tau = _crossing(hb0, S[SU + 1] - vg0, hb1, remaining)
            elif S[SU + 1] - vg0 < 0.0:
                tau = 0.0
            else:
                tau = math.inf
            if tau < best:
                best = tau
                who = -1
        if who == -2 or n_ev >= P[MAXEV]:
            if who != -2:
                count[CNT_FORCED] += 1
            for k in range(SSIZE):
                S[k] = T[k]
            return
        n_ev += 1
        _advance(P, S, mode, now, best, dt, W)
        now += best
        remaining -= best
        if who == -1:
            zg, vg, ag = _ground(P, now)
            vpre = S[SU + 1] - vg
            S[SU + 1] = vg - P[CRB] * vpre
            if P[CRB] * abs(vpre) <= P[G] * dt or vpre >= 0.0:
                # a rebound slower than gravity adds in a step, or a body caught
                # at the step's start on its way back: it comes to rest on the
                # ground (no Zeno cascade of ever smaller bounces)
                S[SU + 1] = vg
                mode[6] = REST
            if P[BNS] != 0.0:
                S[SU + 0] = 0.0          # no lateral slip of the body either
            S[SQ + 1] = zg - P[H0]
            count[CNT_BODY] += 1
            _log(events, count, now, -1, vpre, S[SU + 1] - vg, 0.0, False)
        elif W[W_REL + who] >= 0.0:
            zg, vg, ag = _ground(P, now)
            mode[who] = ADHESION if _pull(P, S, who, vg, ag) > 0.0 else REST
            S[STC + who] = W[W_REL + who] + (now - t)
            W[W_REL + who] = -1.0
            _pin_pair(P, S, who, zg, vg)
        else:
            _impact(P, S, mode, who, now, events, count)
        if remaining <= 0.0:
            return


@njit(cache=True)
def _record(P, S, mode, t, rec, rec_contact, row):
    zg, vg, ag = _ground(P, t)
    rec[row, REC_T] = t
    rec[row, REC_Y] = S[SQ + 0]
    rec[row, REC_Z] = P[H0] + S[SQ + 1]
    rec[row, REC_PH] = S[SQ + 2]
    rec[row, REC_PH + 1] = S[SQ + 3]
    rec[row, REC_PH + 2] = S[SQ + 4]
    rec[row, REC_ZG] = zg
    for j in range(6):
        az, ay, vz, vy = _att(P, S, j)
        fz = az
        fy = P[YFEQ + j] + ay
        kv = vz
        for i in range(3):
            fz += P[CZ + i] * S[SXI + 3 * j + i]
            fy += P[CY + i] * S[SXI + 3 * j + i]
            kv += P[KTF + i] * P[CZ + i] * S[SV + 3 * j + i]
        rec[row, REC_FZ + j] = fz
        rec[row, REC_FY + j] = fy
        rec[row, REC_KV + j] = kv
        rec_contact[row, j] = mode[j]


@njit(cache=True)
def _integrate(P, S, mode, n_steps, dt, every, n_skip, rec, rec_contact, frac, max_air, count, events):
    W = np.zeros(W_SIZE)
    T = np.zeros(SSIZE)
    air_run = np.zeros(6)
    _propagators(P, dt, W, W_PROP)
    _propagators(P, dt / P[NSUB], W, W_PSUB)
    row = 0
    for n in range(n_steps + 1):
        t = n * dt
        if n % every == 0 and row < rec.shape[0]:
            _record(P, S, mode, t, rec, rec_contact, row)
            row += 1
        if n == n_steps:
            break
        _step(P, S, T, mode, t, dt, W, events, count)
        if n >= n_skip:
            for j in range(6):
                frac[j, mode[j]] += dt
                if mode[j] == AIR:
                    air_run[j] += dt
                    if air_run[j] > max_air[j]:
                        max_air[j] = air_run[j]
                else:
                    air_run[j] = 0.0


def run(P: np.ndarray, state: np.ndarray, mode: np.ndarray, n_steps: int, dt: float, every: int,
        n_skip: int, n_rec: int, ev_cap: int) -> dict:
    """Integrate with the compiled kernel; returns the output arrays (same as the reference's)."""
    S = np.ascontiguousarray(state, dtype=np.float64).copy()
    md = np.zeros(7, np.int64)          # 6 feet, then the body (AIR or REST on the ground)
    md[:6] = mode[:6]
    if len(mode) > 6:
        md[6] = mode[6]
    out = {"rec": np.zeros((n_rec, _m.REC_COLS)), "rec_contact": np.zeros((n_rec, 6), np.int8),
           "frac": np.zeros((6, 3)), "max_air": np.zeros(6), "count": np.zeros(_m.CNT_SIZE, np.int64),
           "events": np.zeros((ev_cap, _m.EV_COLS))}
    _integrate(np.ascontiguousarray(P, dtype=np.float64), S, md, int(n_steps), float(dt), int(every),
               int(n_skip), out["rec"], out["rec_contact"], out["frac"], out["max_air"], out["count"],
               out["events"])
    out["state"] = S
    out["mode"] = md.astype(np.int8)
    return out
