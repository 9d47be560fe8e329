"""The integration scheme of the coupled hybrid model (docs/model.md, equations M1-M12).

One source, two engines: compiled by numba (:mod:`labkit.sim.kernel`) or run as
plain Python (:mod:`labkit.sim.reference`), see :mod:`labkit.sim._jit`.
Everything is on flat float64 arrays so the compiled loop allocates nothing:

* ``P``: scalars (layout ``P_*`` below), ``A``: the constant matrices of
  :mod:`labkit.sim.model` (layout ``OFF_*``), ``S``: the state (``S_*``),
  ``mode``: contact mode of the 6 feet and the body (AIR / ADHESION / REST).

The mechanics (docs/model.md M1-M4):
generalised coordinates ``q = (y_b, z_b, phi_x, phi_y, phi_z, x_11 .. x_63)``
(23), one constant symmetric mass matrix ``M``, diagonal modal stiffness
``K`` and damping ``D``, constant forces ``f_c`` (gravity minus the static
support, the coordinates being deviations from rest), the actuator as
generalised forces on the modal coordinates only (an internal force pair),
and 14 contact rows ``R`` (foot z, foot y, body z, body y) plus 18 mode rows
used when some modes are held rigid in impacts.

One step of length h (implicit midpoint = trapezoidal rule, M5):

    (2M + hD + h^2/2 K) vbar = 2 M v0 + h (f(t + h/2) - K q0) + sum_a R_a alpha_a
    q1 = q0 + h vbar,   v1 = 2 vbar - v0

where ``alpha_a = h lambda_a`` for a pinned row (``R_a . q1`` = its target at
t + h) and ``alpha_a = -h c_a (R_a . vbar - v_g)`` for a squeeze-film row (the
film is implicit: its rate reaches 1e8 1/s near the ground; M6, M7). The small
system for ``alpha`` is symmetric positive (semi)definite once the film rows are
divided by ``h c_a``, and is solved by LDL^T (:func:`spd_solve`). Impacts (M9) and releases
(M10, with the instantaneous contact force of :func:`contact_force`) are events
located inside the step (:func:`step`). Without damping the scheme conserves
the energy of the linear system exactly and every linear momentum exactly (to
round-off; M12).
"""
from __future__ import annotations

import math

import numpy as np

from labkit.sim._jit import jit, pointer, unmanaged

NQ = 23          # generalised coordinates
NB = 5           # body coordinates
NR = 14          # contact rows: 0-5 foot z, 6-11 foot y, 12 body z, 13 body y
NI = NR + 18     # impulse rows: the contact rows, then one per leg mode (held rigid in impacts)
ROW_BZ = 12
ROW_BY = 13
AIR, ADHESION, REST = 0, 1, 2
#: Passes of the step's small system: the first takes the squeeze films' coefficients at the
#: midpoint gap predicted from the start's velocity, the later ones the mean coefficient over the
#: gaps of the last pass's solution (:func:`film_mean`), until that changes nothing
#: (FILM_PASS_SKIP). A hard landing on a film needs more than one correction: with two passes the
#: body's depth on its film at 240 Hz, 100 um was still off at the default step (9.3 against
#: 8.8 mm/s at a quarter step, issue 10); three or more agree.
FILM_PASSES = 4
#: Sub-steps (:func:`film_too_coarse`): a step is halved when a squeeze film's gap changes
#: by more than this factor over it ... (1.5 until issue 10: the body taking off from its film
#: at 400 Hz, 50 um then walked 25.5 mm/s at the default step against 27.1 at a quarter step,
#: 2 s runs; 26.6 with 1.2, for 1-2 % more trial steps in the convergence table)
FILM_RATIO = 1.2
#: ... unless the film would take less than this fraction of the row's velocity in a step.
FILM_WEAK = 0.05
#: The film passes stop when the next would change no film's effect on its row's velocity
#: by more than this fraction (weak films far from the ground: one pass).
FILM_PASS_SKIP = 1e-6
#: Sub-steps also resolve a film's transient (:func:`film_too_coarse`): a step is halved when a
#: film row is stiffer than this (x = h c / m_row; above 2 the trapezoidal rule's factor on the
#: row's deviation from the film's slow motion, (1 - x/2) / (1 + x/2), is negative: the row would
#: bounce off its film) ...
FILM_X_MAX = 2.0
#: ... while more than this fraction of the film's force goes into stopping the row (it is not
#: yet riding the film: |m_row (v1 - v0) / h| against |c vbar|; a hovering foot: ~1e-4).
FILM_TRANSIENT = 0.01
#: ... on the film rows from this one on (6: the body's film only). A foot's transient (row
#: 0-5) is taken in one step: refined too, the walk cost 1.4-2x the trial steps at 150-1260 Hz
#: for the same results; the body's is refined: taken in one step, a body bouncing on its legs
#: onto its film at ~0.1 m/s came off it at 0.48 m/s instead of 0.16 and threw the robot
#: 2.9 mm up (shaker 1278 Hz, 47 um; docs/model.md M5 "Sub-steps").
TRANSIENT_ROWS_FROM = 6
#: A point reaching the ground slower than this (m/s) touches down: it is pinned without an
#: impact being counted (round-off approach speeds of a foot that was just released).
V_TOUCH = 1e-9
#: Event location (:func:`step`): at most this many trial steps per event, and a release time
#: is located to this fraction of the step (an impact to the position tolerance P_POSTOL).
#: A release misplaced by dt changes the foot's motion by O(dt^2) (its margin is zero at the
#: release): 1e-2 and 1e-6 give the same mean speeds to 4e-3 mm/s on all 46 runs of the two
#: convergence tables, and 1e-2 takes 10 % fewer trial steps at 1-2 kHz (docs/model.md M10).
EVENT_ITERS = 12
EVENT_TIME_TOL = 1e-2
#: Releases whose crossings a trial step puts within this fraction of the default step of the
#: located one are applied together with it (:func:`step`): events simultaneous within the
#: location's tolerance, e.g. the mirrored feet of a symmetric robot.
SIMULTANEOUS = EVENT_TIME_TOL

# ---- scalars P
(P_H0, P_HR, P_BGF, P_BGB, P_AD, P_CAD, P_CADT, P_CR, P_CRB, P_VSTICK, P_MU, P_BNS, P_KIND, P_AMP,
 P_OMEGA, P_FREQ, P_VOLT, P_DT, P_GAPTOL, P_MAXEV, P_NHELD, P_POSTOL) = range(22)
# the squeeze films' law (M7): the foot pad's coefficient, the leg film's gap at contact,
# the mean free path of the gas (P_HR above: the asperity gap at contact)
P_BGP, P_HL, P_LAM = 22, 23, 24
P_SIZE = 25

#: Veijola's fit of a squeezed gas film's effective viscosity, mu_eff = mu / (1 + RAR_A Kn^RAR_N),
#: Kn = mean free path / gap (Veijola et al. 1995, Sensors and Actuators A 48: 239-248; valid
#: for Kn < 880; docs/model.md M7).
RAR_A = 9.638
RAR_N = 1.159


def layout(regions: tuple) -> tuple:
    """The offsets of ``regions`` ((name, size) pairs) laid end to end in one flat array, in
    their order, then the array's size. Every workspace below (A, a level's block of A, S, W,
    I) is one such table, unpacked into its names (``tests/sim/test_layout_tables.py`` checks
    each name against its table, that no two regions overlap and that all lie inside)."""
    offsets = []
    end = 0
    for _, size in regions:
        offsets.append(end)
        end += size
    return (*offsets, end)


#: Step levels with cached matrices: the default step dt and its halvings dt / 2^k,
#: k < NLEV (the sub-steps of :func:`integrate`); other lengths (partial steps up to
#: an event) solve their own system.
NLEV = 7
#: One level's block of A: S^-1 by parts, Z, Q (S = 2M + h D + h^2/2 K).
LEV_REGIONS = (
    ("LEV_DLI", NQ),            # 1 / S_ii of the leg coordinates (the first NB unused)
    ("LEV_SCI", NB * NB),       # the inverse of the body's Schur complement of S
    ("LEV_ZT", NR * NQ),        # (Sinv R)^T
    ("LEV_Q", NR * NR),         # R^T Sinv R
)
LEV_DLI, LEV_SCI, LEV_ZT, LEV_Q, LEV_SIZE = layout(LEV_REGIONS)
#: The constant matrices A (row-major blocks).
A_REGIONS = (
    ("OFF_M", NQ * NQ),         # the mass matrix
    ("OFF_RT", NI * NQ),        # contact rows then mode rows (R_I^T, rows contiguous)
    ("OFF_MRT", NI * NQ),       # (M^-1 R_I)^T
    ("OFF_WI", NI * NI),        # R_I^T M^-1 R_I
    ("OFF_K", NQ),              # diagonal of K
    ("OFF_D", NQ),              # diagonal of D
    ("OFF_FC", NQ),             # constant forces (deviation coordinates)
    ("OFF_FA", NQ),             # actuator forces per volt (tripod phases included)
    ("OFF_KV", 6 * NQ),         # knee vertical velocity rows
    ("OFF_YFEQ", 6),            # lateral foot position at rest
    ("OFF_HELD", 18),           # 1 = the mode is held rigid in impacts
    ("OFF_LEV", NLEV * LEV_SIZE),   # per level: LEV_REGIONS
)
(OFF_M, OFF_RT, OFF_MRT, OFF_WI, OFF_K, OFF_D, OFF_FC, OFF_FA, OFF_KV, OFF_YFEQ, OFF_HELD, OFF_LEV,
 A_SIZE) = layout(A_REGIONS)

#: The state S.
S_REGIONS = (
    ("S_Q", NQ),                # generalised coordinates
    ("S_V", NQ),                # their velocities
    ("S_TC", 6),                # time in contact per foot
    ("S_YPIN", 6),              # lateral position where a pinned foot is held
    ("S_LAM", NR),              # last contact force per row (N; + pushes the foot up)
    ("S_SLIP", 6),              # friction force of a slipping pinned foot (0: it sticks)
    ("S_FV", 7),                # per film row (feet z, body z): its mean velocity relative to the ground
    ("S_FH", 7),                # over the last step, and that step's length (0: none; M7)
)
S_Q, S_V, S_TC, S_YPIN, S_LAM, S_SLIP, S_FV, S_FH, S_SIZE = layout(S_REGIONS)

# ---- recorded trajectory columns (SI)
REC_T, REC_Y, REC_Z, REC_PH, REC_ZG, REC_FZ, REC_FY, REC_KV = 0, 1, 2, 3, 6, 7, 13, 19
REC_COLS = 25
# ---- impact log columns
EV_T, EV_LEG, EV_VPRE, EV_VPOST, EV_VYPOST, EV_STUCK = range(6)
EV_COLS = 6
# ---- counters: 0..5 impacts per foot; CNT_HALVED_TRANSIENT: the refused sub-steps (of CNT_HALVED)
# refused for a film transient, the others for a film's gap ratio (film_too_coarse); CNT_NEAR: the
# contact checks (:func:`release`) that found a pinned foot within NEAR_FRACTION of letting go, a
# foot sliding, or the body resting on the ground (none: the run was *held*, docs/model.md)
CNT_BODY, CNT_EVENTS, CNT_LOST, CNT_FORCED, CNT_RELEASES, CNT_HALVED, CNT_ADV, CNT_HALVED_TRANSIENT, \
    CNT_NEAR, CNT_STOP = range(6, 16)
CNT_SIZE = 16
#: count[CNT_STOP], set by the caller: 1 = stop the run at the first step after which a foot or the
#: body is no longer held (an impact, a release, a contact check near a release); the kernel then
#: sets it to STOPPED (:func:`integrate`; a held run tried at a coarser step, docs/model.md)
STOP_WHEN_ACTIVE, STOPPED = 1, 2
#: A pinned foot is *near* letting go when the hold it has left (its hold minus its pull) is less
#: than this fraction of its hold or of the largest normal force it has borne in the run (or its
#: lateral force exceeds this fraction of what friction allows): a finer step changes the forces
#: by a few per cent of their oscillation (docs/model.md, "Held runs"), so a run whose feet all
#: kept that much at every step keeps them held at any finer step (:mod:`labkit.sim.errorcontrol`).
NEAR_FRACTION = 0.5

#: Cached inverses of R^T M^-1 R over a set of rows (the pinned rows, with or without stiff
#: film rows): NSLOT slots, direct-mapped by the set's bit mask (rows 0-12); the sets
#: change only at events, so nearly every step finds its matrix here.
NSLOT = 64
NC = 13
#: Cached LDL^T factors of the small system's leading block of pinned rows (:func:`small_solve`):
#: NFC slots, direct-mapped by the block's rows and the step level; used for blocks of at least
#: FC_MIN rows (a robot standing on its six feet: twelve, then the body's film row).
NFC = 8
FC_MIN = 4
#: The float scratch W.
W_REGIONS = (
    ("W_F", NQ),                # forces at the step's midpoint
    ("W_R", NQ),                # right-hand side
    ("W_Y0", NQ),               # Sinv r
    ("W_VB", NQ),               # vbar
    ("W_Q0", NQ),               # the step's start: positions
    ("W_V0", NQ),               # ... and velocities
    ("W_SM", NQ * NQ),          # a partial step: D_l^-1, the Schur complement, u_a (partial_system)
    ("W_B", NQ * (1 + NR)),     # its right-hand sides (also scratch of cached_inverse)
    ("W_QH", NR * NR),          # a partial step's R^T Sinv R
    ("W_AS", NI * NI),          # small system NI x NI
    ("W_BS", NI),               # small right-hand side NI
    ("W_C", NI),                # film coefficient per active row
    ("W_T", NI),                # targets per active row
    ("W_GAP0", 7),              # 7 gaps at the start
    ("W_GAP1", 7),              # 7 gaps at the end of a trial
    ("W_VREL", 7),              # per point: relative normal velocity, or where its release crosses
    ("W_FI", NQ),               # forces at a state (contact_force)
    ("W_RY", NI),               # R_a . Sinv r per active row
    ("W_LI0", NR),              # instantaneous contact forces at the start of a trial
    ("W_LI1", NR),              # ... at its end
    ("W_G0", 7),                # release margins at the start (feet, body)
    ("W_CT", 1),                # time at which W_LI1 holds the contact forces of the current state (cache)
    ("W_CV", 1),                # ... and the drive voltage they were computed with
    ("W_FX", 7),                # per film row of the last trial: x = h c / m_row
    ("W_FR", 7),                # ... and the fraction of its film force that stops the row (transient)
    ("W_GRND", 9),              # ground(): two remembered (t, zg, vg, ag), then the slot to replace next
    ("W_CACHE", NSLOT * NC * NC),   # the cached inverses (NSLOT above)
    ("W_U", NB),                # advance: the body's part of a right-hand side
    ("W_FMAX", 6),              # per foot: the largest |normal contact force| seen so far (release)
    ("W_DG", NI),               # per active film row: 1 / (h c), its term on the small system's diagonal
    ("W_FC", NFC * NC * NC),    # the cached factors of leading pinned blocks (NFC above; row stride NC)
    ("W_FHI", NFC),             # ... per slot: the block's smallest pivot
    ("W_RQ", 6),                # per foot: its z row's position at a step's start (foot_rows: free feet;
                                # advance: pinned ones)
    ("W_RV", 6),                # ... and a free foot's velocity (foot_rows)
    ("W_RB", NI),               # per active film row: R_a . vbar as the last film pass found it
)
(W_F, W_R, W_Y0, W_VB, W_Q0, W_V0, W_SM, W_B, W_QH, W_AS, W_BS, W_C, W_T, W_GAP0, W_GAP1, W_VREL, W_FI, W_RY,
 W_LI0, W_LI1, W_G0, W_CT, W_CV, W_FX, W_FR, W_GRND, W_CACHE, W_U, W_FMAX, W_DG, W_FC, W_FHI,
 W_RQ, W_RV, W_RB, W_SIZE) = layout(W_REGIONS)
#: The integer scratch I.
I_REGIONS = (
    ("I_ROWS", NI),             # active rows
    ("I_KIND", NI),             # 0 film, 1 pinned
    ("I_IMP", 7),               # impacting flags
    ("I_TAG", NSLOT),           # mask held by each cache slot (-1: empty)
    ("I_POS", NC),              # position of row r in the cached set's order
    ("I_FTAG", NFC),            # key held by each slot of the cached factors (-1: empty; small_solve)
)
I_ROWS, I_KIND, I_IMP, I_TAG, I_POS, I_FTAG, I_SIZE = layout(I_REGIONS)


@jit
def ground_at(P, t):
    """Ground height, velocity and acceleration (model.md section 7): shaker sine, else still."""
    if P[P_KIND] != 0.0:
        return 0.0, 0.0, 0.0
    w = P[P_OMEGA]
    a = P[P_AMP]
    s = math.sin(w * t)
    c = math.cos(w * t)
    return a * s, a * w * c, -a * w * w * s


@jit
def ground(P, W, t):
    """:func:`ground_at`, remembered for the last two times asked (a step asks for its start
    and end several times; the sine and cosine cost more than the rest of the lookup)."""
    for k in range(2):
        o = W_GRND + 4 * k
        if W[o] == t:
            return W[o + 1], W[o + 2], W[o + 3]
    zg, vg, ag = ground_at(P, t)
    o = W_GRND + 4 * int(W[W_GRND + 8])
    W[o] = t
    W[o + 1] = zg
    W[o + 2] = vg
    W[o + 3] = ag
    W[W_GRND + 8] = 1.0 - W[W_GRND + 8]
    return zg, vg, ag


@jit
def volts(P, t):
    """PZT square wave at time t (edges fall on step boundaries: t is a step's midpoint)."""
    if P[P_KIND] != 1.0:
        return 0.0
    ph = P[P_FREQ] * t
    return P[P_VOLT] if ph - math.floor(ph) < 0.5 else -P[P_VOLT]


@jit
def gauss(Am, oa, lda, Bm, ob, ldb, n, m):
    """Solve A X = B in place (A n x n at Am[oa], row stride lda; B n x m at Bm[ob], stride ldb).

    Gauss elimination with partial pivoting; X overwrites B, A is destroyed. A pivot
    below 1e-12 of the largest entry marks a redundant equation (e.g. the lateral rows of
    feet whose legs have no lateral compliance, cy_sign = 0): its unknown is set to 0,
    which solves a consistent system with dependent rows.
    """
    scale = 0.0
    for i in range(n):
        for c in range(n):
            v = abs(Am[oa + i * lda + c])
            if v > scale:
                scale = v
    eps = 1e-12 * scale
    for k in range(n):
        piv = k
        best = abs(Am[oa + k * lda + k])
        for i in range(k + 1, n):
            v = abs(Am[oa + i * lda + k])
            if v > best:
                best = v
                piv = i
        if piv != k:
            for c in range(n):
                tmp = Am[oa + k * lda + c]
                Am[oa + k * lda + c] = Am[oa + piv * lda + c]
                Am[oa + piv * lda + c] = tmp
            for c in range(m):
                tmp = Bm[ob + k * ldb + c]
                Bm[ob + k * ldb + c] = Bm[ob + piv * ldb + c]
                Bm[ob + piv * ldb + c] = tmp
        d = Am[oa + k * lda + k]
        if abs(d) <= eps:
            continue
        for i in range(k + 1, n):
            f = Am[oa + i * lda + k] / d
            if f != 0.0:
                for c in range(k + 1, n):
                    Am[oa + i * lda + c] -= f * Am[oa + k * lda + c]
                for c in range(m):
                    Bm[ob + i * ldb + c] -= f * Bm[ob + k * ldb + c]
    for k in range(n - 1, -1, -1):
        d = Am[oa + k * lda + k]
        if abs(d) <= eps:
            for c in range(m):
                Bm[ob + k * ldb + c] = 0.0
            continue
        for c in range(m):
            s = Bm[ob + k * ldb + c]
            for j in range(k + 1, n):
                s -= Am[oa + k * lda + j] * Bm[ob + j * ldb + c]
            Bm[ob + k * ldb + c] = s / d


@jit
def leg_of_row(r):
    """The leg whose modes a contact/impulse row involves besides the body's coordinates
    (-1: none, a body row). A foot's rows involve only the body and its own leg (M3; checked
    by :meth:`labkit.sim.model.Model.pack`), so row products skip the other legs' modes:
    the skipped terms are exact zeros, the sum's order is kept, the result is the same."""
    if r < 12:
        return r % 6
    return -1


@jit
def spd_solve(W, oa, ob, n):
    """Solve A x = b in place for a symmetric positive (semi)definite A (n x n at W[oa],
    row stride NI, its lower triangle read; b at W[ob], overwritten by x): LDL^T without
    pivoting (:func:`ldl_factor`, :func:`ldl_solve`), A destroyed.

    A pivot below 1e-12 of the largest diagonal entry marks a redundant equation (as in
    :func:`gauss`: e.g. dependent lateral rows, cy_sign = 0): its unknown is set to 0.
    """
    ldl_factor(W, oa, n, 0, dead_pivot(W, oa, n))
    ldl_solve(W, oa, ob, n)


@jit
def dead_pivot(W, oa, n):
    """The threshold at or below which a pivot of the n x n matrix at W[oa] (row stride NI)
    is dead: 1e-12 of its largest diagonal entry."""
    scale = 0.0
    for i in range(n):
        v = W[oa + i * NI + i]
        if v > scale:
            scale = v
    return 1e-12 * scale


@jit
def ldl_factor(W, oa, n, p, eps):
    """LDL^T of the n x n matrix at W[oa] (row stride NI; lower triangle and diagonal, in
    place: L below the diagonal, D on it) by columns, without pivoting; a pivot at or below
    ``eps`` is dead (set to 0 with its column of L). The leading p x p block may already be
    factored (:func:`small_solve`'s cache): each entry below it is the same sum, in the same
    order, as when the whole matrix is factored here, so the result is the same to the bit."""
    for j in range(n):
        oj = oa + j * NI
        d = W[oj + j]
        if j >= p:
            for k in range(j):
                lk = W[oj + k]
                d -= lk * lk * W[oa + k * NI + k]
            if d <= eps:
                d = 0.0
            W[oj + j] = d
        if d == 0.0:
            for i in range(max(j + 1, p), n):
                W[oa + i * NI + j] = 0.0
            continue
        for i in range(max(j + 1, p), n):
            oi = oa + i * NI
            v = W[oi + j]
            for k in range(j):
                v -= W[oi + k] * W[oj + k] * W[oa + k * NI + k]
            W[oi + j] = v / d


@jit
def ldl_solve(W, oa, ob, n):
    """x = A^-1 b in place at W[ob] from :func:`ldl_factor`'s factors at W[oa] (L y = b,
    D z = y, L^T x = z; a dead pivot's unknown is 0)."""
    for i in range(n):
        oi = oa + i * NI
        v = W[ob + i]
        for k in range(i):
            v -= W[oi + k] * W[ob + k]
        W[ob + i] = v
    for i in range(n):
        d = W[oa + i * NI + i]
        W[ob + i] = W[ob + i] / d if d != 0.0 else 0.0
    for i in range(n - 1, -1, -1):
        if W[oa + i * NI + i] == 0.0:
            W[ob + i] = 0.0
            continue
        v = W[ob + i]
        for k in range(i + 1, n):
            v -= W[oa + k * NI + i] * W[ob + k]
        W[ob + i] = v


@jit
def row_dot(A, r, x, xo):
    """Contact/impulse row r dotted with x[xo:xo+NQ] (its nonzero span only)."""
    o = OFF_RT + r * NQ
    if r >= NR:                       # a mode row: one unit entry
        k = NB + r - NR
        return A[o + k] * x[xo + k]
    # the body's coordinates, then the row's own leg's (one sum, in ascending order)
    s = 0.0
    for i in range(NB):
        s += A[o + i] * x[xo + i]
    leg = leg_of_row(r)
    if leg >= 0:
        for i in range(NB + 3 * leg, NB + 3 * leg + 3):
            s += A[o + i] * x[xo + i]
    return s


@jit
def row_axpy(A, r, X, xo, f):
    """X[xo:xo+NQ] += f R_r (the row's nonzero span only, as :func:`row_dot`)."""
    o = OFF_RT + r * NQ
    for i in range(NB):
        X[xo + i] += A[o + i] * f
    leg = leg_of_row(r)
    if leg >= 0:
        for i in range(NB + 3 * leg, NB + 3 * leg + 3):
            X[xo + i] += A[o + i] * f


@jit
def gaps(P, A, S, t, W, o):
    """Gap of each foot (0-5) and of the body (6) above the ground at t, into W[o:o+7]."""
    zg, _, _ = ground(P, W, t)
    for j in range(6):
        W[o + j] = row_dot(A, j, S, S_Q) - zg
    W[o + 6] = P[P_H0] + S[S_Q + 1] - zg


@jit
def foot_rows(A, S, mode, W):
    """The free feet's z rows at state S, once for the functions of a step that read them:
    position into W_RQ, velocity into W_RV (the same sums as :func:`row_dot`, so the same
    values to the bit). A pinned foot's position is put there by :func:`advance`, which
    needs it for the foot's target anyway."""
    for j in range(6):
        if mode[j] == AIR:
            W[W_RQ + j] = row_dot(A, j, S, S_Q)
            W[W_RV + j] = row_dot(A, j, S, S_V)


@jit
def start_gaps(P, S, t, W):
    """:func:`gaps` of S at t into W_GAP0, the feet's rows read from W_RQ (after :func:`advance`
    from S: every foot's row is there)."""
    zg, _, _ = ground(P, W, t)
    for j in range(6):
        W[W_GAP0 + j] = W[W_RQ + j] - zg
    W[W_GAP0 + 6] = P[P_H0] + S[S_Q + 1] - zg


@jit
def forces(P, A, S, mode, t_mid, W, fo):
    """Generalised forces at state S except springs, dampers, films and contacts (M4), into
    W[fo:fo+NQ]: constant forces, the actuator at t_mid, air drag (explicit), friction of
    slipping feet. A free foot's vertical velocity is read from W_RV (:func:`foot_rows` of S)."""
    V = volts(P, t_mid)
    for i in range(NQ):
        W[fo + i] = A[OFF_FC + i] + V * A[OFF_FA + i]
    ad = P[P_AD]
    if ad > 0.0:
        for j in range(6):
            if mode[j] == AIR:
                vz = W[W_RV + j]
                vy = row_dot(A, 6 + j, S, S_V)
                fz = -ad * vz * abs(vz)
                fy = -ad * vy * abs(vy)
                # both rows of foot j span the body and leg j (:func:`leg_of_row`)
                oz = OFF_RT + j * NQ
                oy = OFF_RT + (6 + j) * NQ
                for i in range(NB):
                    W[fo + i] += A[oz + i] * fz + A[oy + i] * fy
                for i in range(NB + 3 * j, NB + 3 * j + 3):
                    W[fo + i] += A[oz + i] * fz + A[oy + i] * fy
        W[fo + 0] -= ad * S[S_V + 0] * abs(S[S_V + 0])
        W[fo + 1] -= ad * S[S_V + 1] * abs(S[S_V + 1])
    for j in range(6):
        fr = S[S_SLIP + j]
        if mode[j] != AIR and fr != 0.0:
            row_axpy(A, 6 + j, W, fo, fr)


@jit
def film_law(b, lam, u):
    """The film's coefficient (N s/m) at the mean-plane gap u (m): b / (u^3 (1 + RAR_A (lam / u)^RAR_N)),
    the squeeze film of Reynolds' equation with the gas's effective viscosity (M7)."""
    q = 1.0 + RAR_A * (lam / u) ** RAR_N if lam > 0.0 else 1.0
    return b / (u * u * u * q)


@jit
def film_law_mean(b, lam, u0, u1):
    """The mean of :func:`film_law` over the gaps from u0 to u1 (m), so that the film's impulse,
    -c (u1 - u0), is the integral of its force along the gap (M7).

    In s = 1 / u the integrand is smooth, ``c du = -b s / (1 + RAR_A (lam s)^RAR_N) ds``, and the
    mean is ``(s0 s1 / 2) sum_k w_k b s_k / q(s_k)`` by 3-point Gauss-Legendre on [s0, s1]: exact
    for the continuum law b / u^3 (linear in s) at any step, free of cancellation when u0 = u1
    (it is then the law itself), and within 1e-4 of the integral for the rarefied law over the
    gap ratios the sub-steps allow (FILM_RATIO)."""
    if u0 == u1:
        return film_law(b, lam, u0)
    s0 = 1.0 / u0
    s1 = 1.0 / u1
    sm = 0.5 * (s0 + s1)
    sh = 0.5 * (s1 - s0)
    x = 0.7745966692414834            # sqrt(3/5)
    acc = 0.0
    for k in range(3):
        sk = sm + (-x if k == 0 else (0.0 if k == 1 else x)) * sh
        wk = 0.8888888888888888 if k == 1 else 0.5555555555555556
        q = 1.0 + RAR_A * (lam * sk) ** RAR_N if lam > 0.0 else 1.0
        acc += wk * sk / q
    return b * s0 * s1 * 0.5 * acc


@jit
def film_on(P, j):
    """True when foot j (0-5) or the body (j = 6) has a squeeze film."""
    if j < 6:
        return P[P_BGP] > 0.0 or P[P_BGF] > 0.0
    return P[P_BGB] > 0.0


@jit
def film_gap0(P, j):
    """The smallest mean-plane gap of row j's films at contact (m): the asperity gap, or for a
    foot without a pad film the leg film's."""
    if j < 6 and P[P_BGP] <= 0.0:
        return P[P_HL]
    return P[P_HR]


@jit
def film_coef(P, j, g0, g1):
    """The film coefficient (N s/m) of foot j (0-5) or the body (6) over a step whose contact gap
    goes from g0 to g1 (m; equal: at that gap), M7. The gap is the distance above contact
    (negative values, within the event tolerance, count as contact). A foot has two films: its
    pad's at the pad's gap plus the asperity gap, and the leg's at the gap plus the leg's height
    above the foot tip; the body has one, at its gap plus the asperity gap."""
    a = g0 if g0 > 0.0 else 0.0
    b = g1 if g1 > 0.0 else 0.0
    lam = P[P_LAM]
    c = 0.0
    if j < 6:
        if P[P_BGP] > 0.0:
            c += film_law_mean(P[P_BGP], lam, a + P[P_HR], b + P[P_HR])
        if P[P_BGF] > 0.0:
            c += film_law_mean(P[P_BGF], lam, a + P[P_HL], b + P[P_HL])
    elif P[P_BGB] > 0.0:
        c = film_law_mean(P[P_BGB], lam, a + P[P_HR], b + P[P_HR])
    return c


@jit
def active_rows(P, A, S, mode, t, h, I, W):
    """The rows of the step's small system: pinned rows (kind 1) and film rows (kind 0).

    Returns their number. Film coefficients c (N s/m) are taken at the gap predicted for the
    step's midpoint from the start's velocity (:func:`advance` corrects them in a second
    pass when that changes a film's effect). The free feet's rows are read from W_RQ and
    W_RV (:func:`foot_rows` of S).
    """
    zg, vg, _ = ground(P, W, t)
    n = 0
    for j in range(6):
        if mode[j] == AIR:
            if film_on(P, j):
                gap = W[W_RQ + j] - zg + 0.5 * h * (W[W_RV + j] - vg)
                I[I_ROWS + n] = j
                I[I_KIND + n] = 0
                W[W_C + n] = film_coef(P, j, gap, gap)
                n += 1
        else:
            I[I_ROWS + n] = j
            I[I_KIND + n] = 1
            n += 1
            if S[S_SLIP + j] == 0.0:
                I[I_ROWS + n] = 6 + j
                I[I_KIND + n] = 1
                n += 1
    if mode[6] == REST:
        I[I_ROWS + n] = ROW_BZ
        I[I_KIND + n] = 1
        n += 1
    elif film_on(P, 6):
        gap = P[P_H0] + S[S_Q + 1] - zg + 0.5 * h * (S[S_V + 1] - vg)
        I[I_ROWS + n] = ROW_BZ
        I[I_KIND + n] = 0
        W[W_C + n] = film_coef(P, 6, gap, gap)
        n += 1
    return n


@jit
def row_target(P, S, r, zg):
    """Position a pinned row must have: the ground for z rows, the held place for y rows."""
    if r < 6:
        return zg
    if r < 12:
        return S[S_YPIN + r - 6]
    return zg - P[P_H0]


@jit
def step_level(P, h):
    """k when h is the default step halved k times (k < NLEV; its matrices are cached), else -1."""
    hk = P[P_DT]
    for k in range(NLEV):
        if h == hk:
            return k
        hk *= 0.5
    return -1


@jit
def partial_system(A, h, W, I, n):
    """The step's system for a length h without cached matrices (a partial step up to an
    event): W_Y0 = Sinv r, and R^T Sinv R over the n active rows (W_QH).

    ``S = 2M + hD + h^2/2 K`` is solved through its body block: the legs' modal coordinates
    are mutually uncoupled in M (M2; checked by :meth:`labkit.sim.model.Model.pack`), so the
    leg block is a diagonal ``D_l`` and only the body's 5 x 5 Schur complement
    ``Sc = S_bb - S_bl D_l^-1 S_lb`` is eliminated. With ``u_a = R_a,b - S_bl D_l^-1 R_a,l``
    (the row's own leg only) and ``X_a = Sc^-1 u_a`` (kept for :func:`partial_vbar`):
    ``R_a^T Sinv R_b = u_a . X_b + R_a,l . D_l^-1 R_b,l``, the last term for rows of one leg.
    """
    di = W_SM                       # D_l^-1 (leg coordinates)
    sc = W_SM + NQ                  # Sc, NB x NB
    uu = sc + NB * NB               # u_a, n x NB
    ld = 1 + NR                     # right-hand sides of Sc: r's, then u_a (then X_a)
    for i in range(NB, NQ):
        W[di + i] = 1.0 / (2.0 * A[OFF_M + i * NQ + i] + h * A[OFF_D + i] + 0.5 * h * h * A[OFF_K + i])
    for a in range(NB):
        for b in range(NB):
            W[sc + a * NB + b] = 2.0 * A[OFF_M + a * NQ + b]
        W[sc + a * NB + a] += h * A[OFF_D + a] + 0.5 * h * h * A[OFF_K + a]
        W[W_B + a * ld] = W[W_R + a]
    for i in range(NB, NQ):           # (sums over the legs outermost: independent accumulators)
        d = W[di + i]
        ri = W[W_R + i]
        for a in range(NB):
            f = 2.0 * A[OFF_M + a * NQ + i] * d
            for b in range(NB):
                W[sc + a * NB + b] -= f * 2.0 * A[OFF_M + i * NQ + b]
            W[W_B + a * ld] -= f * ri
    for c in range(n):
        ra = I[I_ROWS + c]
        o = OFF_RT + ra * NQ
        for a in range(NB):
            W[uu + c * NB + a] = A[o + a]
        leg = leg_of_row(ra)
        if leg >= 0:
            for i in range(NB + 3 * leg, NB + 3 * leg + 3):
                x = A[o + i] * W[di + i]
                for a in range(NB):
                    W[uu + c * NB + a] -= 2.0 * A[OFF_M + a * NQ + i] * x
        for a in range(NB):
            W[W_B + a * ld + 1 + c] = W[uu + c * NB + a]
    gauss(W, sc, NB, W, W_B, ld, NB, 1 + n)
    for a in range(NB):
        W[W_Y0 + a] = W[W_B + a * ld]
    for i in range(NB, NQ):
        v = W[W_R + i]
        for b in range(NB):
            v -= 2.0 * A[OFF_M + i * NQ + b] * W[W_Y0 + b]
        W[W_Y0 + i] = v * W[di + i]
    for a in range(n):
        ra = I[I_ROWS + a]
        la = leg_of_row(ra)
        oa = OFF_RT + ra * NQ
        for b in range(n):
            rb = I[I_ROWS + b]
            v = 0.0
            for k in range(NB):
                v += W[uu + a * NB + k] * W[W_B + k * ld + 1 + b]
            if la >= 0 and la == leg_of_row(rb):
                ob = OFF_RT + rb * NQ
                for i in range(NB + 3 * la, NB + 3 * la + 3):
                    v += A[oa + i] * W[di + i] * A[ob + i]
            W[W_QH + ra * NR + rb] = v


@jit
def partial_vbar(A, W, I, n):
    """vbar = Sinv r + Sinv R alpha for a partial step (:func:`partial_system`'s parts):
    with xi = sum_a X_a alpha_a, the body's part is y0_b + xi and a leg coordinate's
    ``y0_i + (sum_a R_a,i alpha_a - S_ib xi) / D_i``."""
    di = W_SM
    ld = 1 + NR
    for k in range(NB):
        x = 0.0
        for a in range(n):
            x += W[W_B + k * ld + 1 + a] * W[W_BS + a]
        W[W_VB + k] = x                           # xi, for now
    for i in range(NB, NQ):
        W[W_VB + i] = 0.0
    for a in range(n):
        ra = I[I_ROWS + a]
        leg = leg_of_row(ra)
        if leg >= 0:
            o = OFF_RT + ra * NQ
            al = W[W_BS + a]
            for i in range(NB + 3 * leg, NB + 3 * leg + 3):
                W[W_VB + i] += A[o + i] * al
    for i in range(NB, NQ):
        v = W[W_VB + i]
        for b in range(NB):
            v -= 2.0 * A[OFF_M + i * NQ + b] * W[W_VB + b]
        W[W_VB + i] = W[W_Y0 + i] + v * W[di + i]
    for k in range(NB):
        W[W_VB + k] += W[W_Y0 + k]


@jit
def pinned_block(I, n, lev):
    """(p, key) of a step's small system at the cached level ``lev`` (-1: not cached): its
    leading p rows are pinned and their factor may be cached under ``key`` (the rows and the
    level; -1 and p = 0: not at a cached level, or fewer than FC_MIN such rows)."""
    if lev < 0:
        return 0, -1
    p = 0
    mask = 0
    while p < n and I[I_KIND + p] == 1:
        mask |= 1 << I[I_ROWS + p]
        p += 1
    if p < FC_MIN:
        return 0, -1
    return p, mask | (lev << NR)


@jit
def assemble(A, W, I, n, lev):
    """The small system's matrix (lower triangle and diagonal) into W[W_AS] (row stride NI):
    Q over the active rows (the cached level's, or a partial step's W_QH with ``lev`` < 0),
    plus 1 / (h c_a) (W[W_DG + a]) on a film row's diagonal."""
    base = OFF_LEV + lev * LEV_SIZE
    for a in range(n):
        ra = I[I_ROWS + a]
        for b in range(a + 1):
            rb = I[I_ROWS + b]
            W[W_AS + a * NI + b] = A[base + LEV_Q + ra * NR + rb] if lev >= 0 else W[W_QH + ra * NR + rb]
        if I[I_KIND + a] == 0:
            W[W_AS + a * NI + a] += W[W_DG + a]


@jit
def small_solve(A, W, I, n, lev):
    """Solve the step's small system (:func:`advance`, one pass; right-hand sides in W[W_BS]),
    as :func:`spd_solve` does, to the same bits.

    Pinned row a: Q_a. alpha = t_a; film row a, divided by h c_a:
    Q_a. alpha + alpha_a / (h c_a) = -(R_a . Sinv r - v_g). Symmetric positive (semi)definite:
    Q = R^T Sinv R, plus a positive diagonal.

    At a cached level, the factor of the leading block of pinned rows (:func:`pinned_block`)
    does not change from step to step: it is kept in one of NFC slots, and a step that finds it
    factors only the rows after it (:func:`ldl_factor`), unless the test for a dead pivot (1e-12
    of the largest diagonal entry, which the film rows take part in) would now kill one of the
    block's pivots (W_FHI: the smallest of them). A block with a dead pivot is not kept."""
    assemble(A, W, I, n, lev)
    p, key = pinned_block(I, n, lev)
    if key < 0:
        spd_solve(W, W_AS, W_BS, n)
        return
    eps = dead_pivot(W, W_AS, n)
    slot = ((key * 2654435761) >> 20) % NFC
    oc = W_FC + slot * NC * NC
    if I[I_FTAG + slot] == key and eps < W[W_FHI + slot]:
        for a in range(p):
            for b in range(a + 1):
                W[W_AS + a * NI + b] = W[oc + a * NC + b]
        ldl_factor(W, W_AS, n, p, eps)
    else:
        ldl_factor(W, W_AS, n, 0, eps)
        keep_block(W, I, p, key, slot)
    ldl_solve(W, W_AS, W_BS, n)


@jit
def keep_block(W, I, p, key, slot):
    """Keep the factor of the leading p rows (W[W_AS]) in cache slot ``slot`` under ``key``, with
    its smallest pivot; a block with a dead pivot empties the slot instead."""
    oc = W_FC + slot * NC * NC
    hi = math.inf
    for a in range(p):
        d = W[W_AS + a * NI + a]
        if d == 0.0:
            I[I_FTAG + slot] = -1
            return
        hi = min(hi, d)
        for b in range(a + 1):
            W[oc + a * NC + b] = W[W_AS + a * NI + b]
    I[I_FTAG + slot] = key
    W[W_FHI + slot] = hi


@jit
def advance(P, A, S, mode, t, h, W, I, out):
    """One midpoint step of length h from S (M5); the end state goes to ``out`` (q, v, lam).

    ``h`` equal to the default step or one of its halvings (:func:`step_level`) uses the
    cached inverse; any other length (a partial step up to an event) solves its own system.
    """
    for i in range(NQ):
        W[W_Q0 + i] = S[S_Q + i]
        W[W_V0 + i] = S[S_V + i]
    foot_rows(A, S, mode, W)
    forces(P, A, S, mode, t + 0.5 * h, W, W_F)
    # r = 2 M v0 + h (f - K q0). The matrix-vector products go by columns (M is symmetric,
    # Sinv stored transposed): each sum takes the same terms in the same order as by rows,
    # but the additions of one sum no longer wait on each other. A leg mode's column of M
    # has entries only in the body's rows and its own (the leg block is diagonal, checked
    # by Model.pack): the exact zeros are skipped, the sums stay the same to the bit.
    for i in range(NQ):
        W[W_R + i] = 0.0
    for k in range(NB):
        vk = W[W_V0 + k]
        o = OFF_M + k * NQ
        for i in range(NQ):
            W[W_R + i] += A[o + i] * vk
    for k in range(NB, NQ):
        vk = W[W_V0 + k]
        o = OFF_M + k * NQ
        for i in range(NB):
            W[W_R + i] += A[o + i] * vk
        W[W_R + k] += A[o + k] * vk
    for i in range(NQ):
        W[W_R + i] = 2.0 * W[W_R + i] + h * (W[W_F + i] - A[OFF_K + i] * W[W_Q0 + i])
    lev = step_level(P, h)
    full = lev >= 0
    base = OFF_LEV + lev * LEV_SIZE
    n = active_rows(P, A, S, mode, t, h, I, W)
    if full:
        # Sinv r through the body's Schur complement (the legs' block of S is diagonal, M2):
        # y_b = Sc^-1 (r_b - S_bl D_l^-1 r_l), y_l = D_l^-1 (r_l - S_lb y_b); S_bl = 2 M_bl.
        # About 240 products instead of the 529 of a dense inverse.
        dli = base + LEV_DLI
        for a in range(NB):
            W[W_U + a] = W[W_R + a]
        for i in range(NB, NQ):
            x = 2.0 * W[W_R + i] * A[dli + i]
            o = OFF_M + i * NQ
            for a in range(NB):
                W[W_U + a] -= A[o + a] * x
        for a in range(NB):
            v = 0.0
            o = base + LEV_SCI + a * NB
            for b in range(NB):
                v += A[o + b] * W[W_U + b]
            W[W_Y0 + a] = v
        for i in range(NB, NQ):
            v = W[W_R + i]
            o = OFF_M + i * NQ
            for a in range(NB):
                v -= 2.0 * A[o + a] * W[W_Y0 + a]
            W[W_Y0 + i] = v * A[dli + i]
    else:
        partial_system(A, h, W, I, n)
    zg1, vg1, _ = ground(P, W, t + h)
    zg0, vg0, _ = ground(P, W, t)
    # the films see the ground's mean velocity over the step (its chord), so a foot held
    # by its film follows the ground's displacement exactly and does not sink into it
    vgm = (zg1 - zg0) / h
    # per active row, what does not change between the passes: R_a . Sinv r and the
    # right-hand side of a pinned row, the position at the start of a film row (both in W_T)
    for a in range(n):
        ra = I[I_ROWS + a]
        W[W_RY + a] = row_dot(A, ra, W, W_Y0)
        if I[I_KIND + a] == 1:
            rq = row_dot(A, ra, W, W_Q0)
            if ra < 6:
                W[W_RQ + ra] = rq       # a pinned foot's row, for the start gaps (start_gaps)
            W[W_T + a] = (row_target(P, S, ra, zg1) - rq) / h - W[W_RY + a]
        else:
            W[W_T + a] = W[W_RQ + ra] if ra < 6 else row_dot(A, ra, W, W_Q0)
    settled = False             # the passes ended on one that changed no film (W_RB holds R_a . vbar)
    for it in range(FILM_PASSES):
        if it > 0:
            # the films' coefficients again, their mean over the step's gaps (M7, film_mean);
            # a pass that would change no film's effect by 1e-6 of its row's velocity is skipped
            change = 0.0
            for a in range(n):
                if I[I_KIND + a] == 0:
                    ra = I[I_ROWS + a]
                    off = P[P_H0] if ra == ROW_BZ else 0.0
                    g0 = W[W_T + a] + off - zg0
                    W[W_RB + a] = row_dot(A, ra, W, W_VB)
                    g1 = W[W_T + a] + off - zg1 + h * W[W_RB + a]
                    c = film_coef(P, 6 if ra == ROW_BZ else ra, g0, g1)
                    d = abs(c - W[W_C + a]) * h * A[OFF_WI + ra * NI + ra]
                    if d > change:
                        change = d
                    W[W_C + a] = c
            if change < FILM_PASS_SKIP:
                settled = True
                break
        for a in range(n):
            if I[I_KIND + a] == 1:
                W[W_BS + a] = W[W_T + a]
            else:
                vg = vgm if I[I_ROWS + a] != ROW_BY else 0.0
                W[W_DG + a] = 1.0 / (h * W[W_C + a])
                W[W_BS + a] = -(W[W_RY + a] - vg)
        if n > 0:
            small_solve(A, W, I, n, lev)
        if full:
            for i in range(NQ):
                W[W_VB + i] = W[W_Y0 + i]
            for a in range(n):
                al = W[W_BS + a]
                o = base + LEV_ZT + I[I_ROWS + a] * NQ
                for i in range(NQ):
                    W[W_VB + i] += A[o + i] * al
        else:
            partial_vbar(A, W, I, n)
    for r in range(NR):
        out[S_LAM + r] = 0.0
    for a in range(n):
        if I[I_KIND + a] == 1:
            out[S_LAM + I[I_ROWS + a]] = W[W_BS + a] / h
    for i in range(NQ):
        out[S_Q + i] = W[W_Q0 + i] + h * W[W_VB + i]
        out[S_V + i] = 2.0 * W[W_VB + i] - W[W_V0 + i]
    for k in range(S_TC, S_LAM):
        out[k] = S[k]
    for k in range(S_SLIP, S_SIZE):
        out[k] = S[k]
    # pinned rows: velocities exactly the ground's (an impulse through the constraints, M8).
    # Stiff film rows (M7): the midpoint's v1 = 2 vbar - v0 would carry any deviation of the
    # row's velocity from the film's quasi-static one unchanged, with its sign flipped, to
    # every later step (the trapezoidal rule does not damp infinitely stiff components). The
    # end velocity relative to the ground is instead extrapolated from the mean relative
    # velocities of this step and the last, weight (x - 2) / (x + 2), x = h c / m_row, only where
    # the rule rings (x > FILM_X_MAX: its factor (1 - x/2) / (1 + x/2) on that deviation is
    # negative). Not below: that end velocity is a linear extrapolation, off by O(h^2) in every
    # step, which sums to a first-order error where the row is not slaved to its film; the body
    # hovering on its film at x ~ 1 (240-300 Hz, 100 um) walked 3 % slower at a quarter step
    # than the limit for that reason alone (issue 10). The weight is continuous at x = 2, and the
    # deviation left after the step is at most 1/4 of the one before (x = 6).
    for j in range(7):
        out[S_FH + j] = 0.0
        W[W_FX + j] = 0.0
        W[W_FR + j] = 0.0
    m = 0
    for a in range(n):
        ra = I[I_ROWS + a]
        if I[I_KIND + a] == 1:
            I[I_ROWS + m] = ra
            W[W_T + m] = vg1 if (ra < 6 or ra == ROW_BZ) else 0.0
            m += 1
        elif ra < 6 or ra == ROW_BZ:
            j = ra if ra < 6 else 6
            rv = W[W_RB + a] if settled else row_dot(A, ra, W, W_VB)
            vrel = rv - vgm
            out[S_FV + j] = vrel
            out[S_FH + j] = h
            x = h * W[W_C + a] * A[OFF_WI + ra * NI + ra]
            hp = S[S_FH + j]
            # for film_too_coarse: x, and (where x exceeds FILM_X_MAX, the only case it reads)
            # the part of the film's force that changes the row's velocity relative to the
            # ground, 2 m_row (vbar - v0) / h, against c vbar
            W[W_FX + j] = x
            if x > FILM_X_MAX:
                u0 = row_dot(A, ra, W, W_V0) - vg0
                ub = rv - 0.5 * (vg0 + vg1)
                W[W_FR + j] = 2.0 * abs(ub - u0) / (x * abs(ub) + 1e-300)
                end = vrel
                if hp > 0.0:
                    end += h * (vrel - S[S_FV + j]) / (h + hp)
                w = (x - FILM_X_MAX) / (x + FILM_X_MAX)
                I[I_ROWS + m] = ra
                W[W_T + m] = (1.0 - w) * row_dot(A, ra, out, S_V) + w * (vg1 + end)
                m += 1
    if m > 0:
        impulse(A, out, S_V, I, W, m)


@jit
def cached_inverse(A, W, I, mask):
    """Offset in W of the inverse of R^T M^-1 R over the rows in ``mask`` (bits 0-12), rows
    in ascending order; computed by :func:`gauss` on first use (so a dependent row gets the
    same zero unknown as a direct solve). Sets I_POS[r], the position of row r."""
    m = 0
    for r in range(NC):
        if (mask >> r) & 1:
            I[I_POS + r] = m
            m += 1
    # Fibonacci hashing: the product's middle bits depend on every row of the set (the low
    # bits of mask * odd depend only on the mask's low bits, so sets that differ in their
    # lateral or body rows, bits 6-12, shared a slot and evicted each other: ~8000 inverses
    # recomputed per simulated second at 2 kHz, ~600 now)
    slot = ((mask * 2654435761) >> 20) % NSLOT
    off = W_CACHE + slot * NC * NC
    if I[I_TAG + slot] == mask:
        return off
    a = 0
    for r in range(NC):
        if (mask >> r) & 1:
            b = 0
            for c in range(NC):
                if (mask >> c) & 1:
                    W[W_AS + a * NI + b] = A[OFF_WI + r * NI + c]
                    W[W_B + a * NC + b] = 1.0 if a == b else 0.0
                    b += 1
            a += 1
    gauss(W, W_AS, NI, W, W_B, NC, m, m)
    for a in range(m):
        for b in range(m):
            W[off + a * NC + b] = W[W_B + a * NC + b]
    I[I_TAG + slot] = mask
    return off


@jit
def impulse(A, X, xo, I, W, m):
    """Change X[xo:xo+NQ] (velocities, or positions) by M^-1 R_a P so that rows I_ROWS[:m]
    take the values W[W_T:W_T+m] (the impact law M9 with the mass matrix); returns nothing."""
    mask = 0
    for a in range(m):
        r = I[I_ROWS + a]
        if r >= NC or (mask >> r) & 1:
            mask = -1
            break
        mask |= 1 << r
    if mask > 0:
        off = cached_inverse(A, W, I, mask)
        for a in range(m):
            r = I[I_ROWS + a]
            W[W_BS + I[I_POS + r]] = W[W_T + a] - row_dot(A, r, X, xo)
        for a in range(m):
            W[W_AS + a] = 0.0
        for b in range(m):                  # side by side, as in contact_force
            x = W[W_BS + b]
            for a in range(m):
                W[W_AS + a] += W[off + a * NC + b] * x
        for r in range(NC):
            if (mask >> r) & 1:
                mo = OFF_MRT + r * NQ
                p = W[W_AS + I[I_POS + r]]
                for i in range(NQ):
                    X[xo + i] += A[mo + i] * p
        return
    for a in range(m):
        ra = I[I_ROWS + a]
        for b in range(m):
            W[W_AS + a * NI + b] = A[OFF_WI + ra * NI + I[I_ROWS + b]]
        W[W_BS + a] = W[W_T + a] - row_dot(A, ra, X, xo)
    gauss(W, W_AS, NI, W, W_BS, 1, m, 1)
    for a in range(m):
        o = OFF_MRT + I[I_ROWS + a] * NQ
        p = W[W_BS + a]
        for i in range(NQ):
            X[xo + i] += A[o + i] * p


@jit
def pinned_rows(S, mode, I, m):
    """Append the rows of every pinned foot (and a resting body) to I_ROWS from index m."""
    for j in range(6):
        if mode[j] != AIR:
            I[I_ROWS + m] = j
            m += 1
            if S[S_SLIP + j] == 0.0:
                I[I_ROWS + m] = 6 + j
                m += 1
    if mode[6] == REST:
        I[I_ROWS + m] = ROW_BZ
        m += 1
    return m


@jit
def pinned_targets(P, S, I, W, m0, m, vg):
    for a in range(m0, m):
        r = I[I_ROWS + a]
        W[W_T + a] = vg if (r < 6 or r == ROW_BZ) else 0.0


@jit
def held_rows(P, A, S, I, W, m):
    """Rows of the modes held rigid in impacts (target: their current velocity)."""
    if P[P_NHELD] == 0.0:
        return m
    for k in range(18):
        if A[OFF_HELD + k] != 0.0:
            I[I_ROWS + m] = NR + k
            W[W_T + m] = S[S_V + NB + k]
            m += 1
    return m


@jit
def log_event(events, count, t, leg, vpre, vpost, vypost, stuck):
    n = count[CNT_EVENTS]
    if n < events.shape[0]:
        events[n, EV_T] = t
        events[n, EV_LEG] = leg
        events[n, EV_VPRE] = vpre
        events[n, EV_VPOST] = vpost
        events[n, EV_VYPOST] = vypost
        events[n, EV_STUCK] = 1.0 if stuck else 0.0
        count[CNT_EVENTS] = n + 1
    else:
        count[CNT_LOST] += 1


@jit
def impact(P, A, S, mode, t, W, I, events, count):
    """Impacts at t of every foot (and the body) flagged in I_IMP (M9, M11).

    One impulse on the whole system through all contact points at once: an
    impacting foot's normal velocity relative to the ground reverses with c_r
    and its lateral velocity becomes zero; pinned feet stay pinned; held modes
    keep their velocity. A rebound slower than v_stick ends the bouncing: the
    foot (body) is pinned instead (perfectly plastic), so chattering ends after
    finitely many impacts.
    """
    zg, vg, _ = ground(P, W, t)
    vstick = P[P_VSTICK]
    # relative normal velocities before
    for j in range(7):
        if I[I_IMP + j] != 0:
            r = j if j < 6 else ROW_BZ
            W[W_VREL + j] = row_dot(A, r, S, S_V) - vg
    m = 0
    for j in range(7):
        if I[I_IMP + j] != 0:
            cr = P[P_CR] if j < 6 else P[P_CRB]
            vpre = W[W_VREL + j]
            rebound = -cr * vpre
            # M11: a rebound slower than v_stick ends the bouncing; so does one that the squeeze
            # film stops within the position tolerance (rebound m_row / c, c the film's at contact,
            # M7): the foot would be back at once and bounce again, a Zeno sequence whose limit
            # is contact (unresolved, the feet chattered once per step at a step-dependent rate)
            r = j if j < 6 else ROW_BZ
            stuck = rebound < vstick or rebound < P[P_POSTOL] * film_coef(P, j, 0.0, 0.0) * A[OFF_WI + r * NI + r]
            if j < 6:
                I[I_ROWS + m] = j
                W[W_T + m] = vg + (0.0 if stuck else rebound)
                m += 1
                I[I_ROWS + m] = 6 + j
                W[W_T + m] = 0.0
                m += 1
            else:
                I[I_ROWS + m] = ROW_BZ
                W[W_T + m] = vg + (0.0 if stuck else rebound)
                m += 1
                if P[P_BNS] != 0.0:
                    I[I_ROWS + m] = ROW_BY
                    W[W_T + m] = 0.0
                    m += 1
            W[W_GAP1 + j] = 1.0 if stuck else 0.0
    m0 = m
    m = pinned_rows(S, mode, I, m)
    pinned_targets(P, S, I, W, m0, m, vg)
    m = held_rows(P, A, S, I, W, m)
    # keep the rows for the position projection below
    impulse(A, S, S_V, I, W, m)
    # put the impacting points exactly on the ground (M-orthogonal position projection)
    for a in range(m):
        r = I[I_ROWS + a]
        if r < NR:
            if r < 6:
                W[W_T + a] = zg
            elif r < 12:
                # lateral rows keep their place: a pinned foot its held place, an impacting one where it is
                if mode[r - 6] != AIR:
                    W[W_T + a] = S[S_YPIN + r - 6]
                else:
                    W[W_T + a] = row_dot(A, r, S, S_Q)
            elif r == ROW_BZ:
                W[W_T + a] = zg - P[P_H0]
            else:
                W[W_T + a] = S[S_Q + 0]
        else:
            W[W_T + a] = S[S_Q + NB + r - NR]
    impulse(A, S, S_Q, I, W, m)
    for j in range(7):
        if I[I_IMP + j] == 0:
            continue
        stuck = W[W_GAP1 + j] != 0.0
        r = j if j < 6 else ROW_BZ
        # back on the ground without approaching it (to round-off): no impact
        touch = W[W_VREL + j] >= -V_TOUCH
        if not touch:
            vpost = row_dot(A, r, S, S_V) - vg
            vy = row_dot(A, 6 + j, S, S_V) if j < 6 else S[S_V + 0]
            if j < 6:
                count[j] += 1
                # a new contact begins: F_ad grows with the time since this landing (M10).
                # (Only a stuck impact reset it before: with the films on, feet land with a
                # rebound and then touch, so t_c summed every contact of the run.)
                S[S_TC + j] = 0.0
            else:
                count[CNT_BODY] += 1
            log_event(events, count, t, j if j < 6 else -1, W[W_VREL + j], vpost, vy, stuck)
        if stuck:
            mode[j] = REST
            if j < 6:
                S[S_YPIN + j] = row_dot(A, 6 + j, S, S_Q)
                S[S_SLIP + j] = 0.0


@jit
def contact_force(P, A, S, mode, t, tv, W, I, o):
    """Instantaneous contact force of every pinned row at state S and time t (M10), into
    W[o:o+NR] (N; + pushes the foot up / forward; 0 for free rows); the drive is taken at tv.

    The force balance of the whole coupled system: with F every other force (springs,
    dampers, gravity, actuator, films of the free feet and the body, drag, friction),
    ``R_p^T M^-1 (F + R_p lam) = a_target`` (the ground's acceleration for z rows, 0 for
    y rows). So the pull on a foot counts the actuator, the leg's weight, the films and
    the body's motion, as the paper's force balance (eq. 10) does.
    """
    for r in range(NR):
        W[o + r] = 0.0
    m = pinned_rows(S, mode, I, 0)
    if m == 0:
        return
    foot_rows(A, S, mode, W)
    forces(P, A, S, mode, tv, W, W_FI)
    zg, vg, ag = ground(P, W, t)
    for i in range(NQ):
        W[W_FI + i] -= A[OFF_K + i] * S[S_Q + i] + A[OFF_D + i] * S[S_V + i]
    for j in range(6):
        if mode[j] == AIR and film_on(P, j):
            gap = W[W_RQ + j] - zg
            fz = -film_coef(P, j, gap, gap) * (W[W_RV + j] - vg)
            row_axpy(A, j, W, W_FI, fz)
    if mode[6] != REST and film_on(P, 6):
        gap = P[P_H0] + S[S_Q + 1] - zg
        W[W_FI + 1] -= film_coef(P, 6, gap, gap) * (S[S_V + 1] - vg)
    mask = 0
    for a in range(m):
        mask |= 1 << I[I_ROWS + a]
    off = cached_inverse(A, W, I, mask)
    # R_a^T M^-1 F for every pinned row a (rows of (M^-1 R)^T); the sums run side by side
    # (i outermost), each in its own order, so none waits on another's additions
    for a in range(m):
        W[W_AS + a] = 0.0
    for i in range(NQ):
        f = W[W_FI + i]
        for a in range(m):
            W[W_AS + a] += A[OFF_MRT + I[I_ROWS + a] * NQ + i] * f
    for a in range(m):
        ra = I[I_ROWS + a]
        acc = ag if (ra < 6 or ra == ROW_BZ) else 0.0
        W[W_BS + I[I_POS + ra]] = acc - W[W_AS + a]
    for k in range(m):
        W[W_AS + k] = 0.0
    for b in range(m):
        x = W[W_BS + b]
        for k in range(m):
            W[W_AS + k] += W[off + k * NC + b] * x
    for a in range(m):
        ra = I[I_ROWS + a]
        W[o + ra] = W[W_AS + I[I_POS + ra]]


@jit
def release_margin(P, S, mode, W, o, j, extra):
    """How far the pull on pinned foot j (or the resting body, j = 6) exceeds what holds
    it, with the forces W[o:o+NR] and contact time S_TC + extra (M10): > 0 releases.
    A foot is held by F_ad(t_c) = c_ad_t t_c + c_ad (paper eq. 9), the body by nothing."""
    if j == 6:
        return -W[o + ROW_BZ]
    return -W[o + j] - (P[P_CADT] * (S[S_TC + j] + extra) + P[P_CAD])


@jit
def release(P, A, S, mode, count, W, o):
    """Check of every pinned foot with the instantaneous contact forces W[o:o+NR] (M10): it
    goes back to AIR when the tension exceeds F_ad(t_c) = c_ad_t t_c + c_ad; else it is
    labelled ADHESION (tension) or REST (compression). A resting body leaves when the
    ground would have to pull it. Coulomb friction (mu finite) decides stick or slip.
    Returns the number of releases. (Inside a step, releases are located in time by
    :func:`step`; this check catches jumps of the force, e.g. at a drive edge.)"""
    n = 0
    near = mode[6] == REST
    for j in range(6):
        if mode[j] == AIR:
            continue
        lam_z = W[o + j]
        fad = P[P_CADT] * S[S_TC + j] + P[P_CAD]
        if abs(lam_z) > W[W_FMAX + j]:
            W[W_FMAX + j] = abs(lam_z)
        # near: the hold left is less than NEAR_FRACTION of the hold or of the largest force
        # the foot has borne (where the weight it carries dwarfs its adhesion, the pull that
        # releases it is a change of that force, not of the hold)
        if fad + lam_z < NEAR_FRACTION * max(fad, W[W_FMAX + j]):
            near = True
        if -lam_z > fad:
            # t_c is kept: should the foot not leave within the step, it keeps its contact time
            mode[j] = AIR
            S[S_SLIP + j] = 0.0
            count[CNT_RELEASES] += 1
            n += 1
            continue
        mode[j] = ADHESION if lam_z < 0.0 else REST
        if P[P_MU] < 1e300:
            normal = lam_z + fad
            if normal < 0.0:
                normal = 0.0
            cap = P[P_MU] * normal
            if S[S_SLIP + j] == 0.0:
                lam_y = W[o + 6 + j]
                if abs(lam_y) > NEAR_FRACTION * cap:
                    near = True
                if abs(lam_y) > cap:
                    S[S_SLIP + j] = cap if lam_y > 0.0 else -cap
                    if cap == 0.0:
                        S[S_SLIP + j] = 1e-300 if lam_y > 0.0 else -1e-300
            else:
                near = True
                vy = row_dot(A, 6 + j, S, S_V)
                if vy * S[S_SLIP + j] < 0.0 or cap == 0.0:   # still sliding (or nothing can hold it)
                    S[S_SLIP + j] = cap if S[S_SLIP + j] > 0.0 else -cap
                    if cap == 0.0:
                        S[S_SLIP + j] = 1e-300 if vy < 0.0 else -1e-300
                else:                              # it stopped: stick where it is
                    S[S_SLIP + j] = 0.0
                    S[S_YPIN + j] = row_dot(A, 6 + j, S, S_Q)
    if mode[6] == REST and W[o + ROW_BZ] < 0.0:
        mode[6] = AIR
        n += 1
    if near:
        count[CNT_NEAR] += 1
    return n


@jit
def event_value(P, A, S, T, mode, now, tau, tv, W, I, who, rel):
    """Advance a trial to now + tau (into T) and return the event function of ``who``:
    its gap for an impact, minus its release margin for a release (> 0 before the event)."""
    advance(P, A, S, mode, now, tau, W, I, T)
    if rel:
        contact_force(P, A, T, mode, now + tau, tv, W, I, W_LI1)
        return -release_margin(P, S, mode, W, W_LI1, who, tau)
    gaps(P, A, T, now + tau, W, W_GAP1)
    return W[W_GAP1 + who]


@jit
def film_too_coarse(P, A, mode, h, W):
    """Nonzero when a squeeze film changes too much over a trial step of length h (M7):
    1 for a transient, 2 for a gap ratio (below); 0 when the step resolves every film.

    The film's coefficient goes as gap^-3; the step resolves it when the gap (from the film's
    plane: the asperity gap added) changes by less than the factor FILM_RATIO over the step, or when the film
    is too weak to matter: it would take less than FILM_WEAK of the row's relative
    velocity in one step (h c / m_row, with 1 / m_row = R^T M^-1 R). Uses the gaps at the
    trial's start and end in W_GAP0, W_GAP1.

    Also too coarse: a film in a transient (more than FILM_TRANSIENT of its force stops the
    row instead of balancing the other forces) that is stiffer than FILM_X_MAX over the step,
    x = h c / m_row > 2, where the trapezoidal rule turns the row's approach into a rebound:
    a body landing on its film at 300 Hz bounced off it at 32 steps per mode period
    (W_FX, W_FR: x and that fraction per film row, from the trial's :func:`advance`). Only the
    body's film row is refined for a transient (TRANSIENT_ROWS_FROM).
    """
    for j in range(7):
        if mode[j] != AIR:
            continue
        # a film transient the step does not resolve, but the finest sub-step would (a film
        # too stiff even for that, e.g. a body's at contact, is left to the stiff limit, M7),
        # on the body's film row only: a foot's row rebounding on its film in one step moves
        # little, the body's rebound throws the robot (M7 "Sub-steps"; TRANSIENT_ROWS_FROM)
        x = W[W_FX + j]
        if j >= TRANSIENT_ROWS_FROM and x > FILM_X_MAX and W[W_FR + j] > FILM_TRANSIENT \
                and x * P[P_DT] <= FILM_X_MAX * h * (1 << (NLEV - 1)):
            return 1
        if not film_on(P, j):
            continue
        # the gaps measured from the film's own plane (the asperity gap added), where the law
        # goes as u^-3 (u^-1.84 in the rarefied limit)
        u0 = film_gap0(P, j)
        g0 = (W[W_GAP0 + j] if W[W_GAP0 + j] > 0.0 else 0.0) + u0
        g1 = (W[W_GAP1 + j] if W[W_GAP1 + j] > 0.0 else 0.0) + u0
        lo = g0 if g0 < g1 else g1
        hi = g1 if g0 < g1 else g0
        if hi > FILM_RATIO * lo:
            r = j if j < 6 else ROW_BZ
            if h * film_coef(P, j, lo - u0, lo - u0) * A[OFF_WI + r * NI + r] > FILM_WEAK:
                return 2
    return 0


@jit
def bracket_root(lo, glo, hi, ghi, side, x, g):
    """One iteration of the event location: the bracket [lo, hi] of a root of a function that
    is > 0 at lo (value glo) and <= 0 at hi (ghi), its value g at x inside it; returns the new
    bracket, ``side`` and the next point.

    Regula falsi with the Anderson-Bjoerck rule: when the same end moves twice in a row, the
    value at the other end is scaled by 1 - g_new / g_old (0.5 if that is not positive), so the
    bracket closes from both sides. Plain regula falsi keeps one end for good wherever the
    function is curved, e.g. the contact force of a foot next to a squeeze film's 25 ns
    transient after an event; a release then took 6-10 trial steps to locate (issue 10).
    ``side``: +1 when the last iteration moved lo, -1 when it moved hi, 0 at the start.
    """
    if g > 0.0:
        if side == 1:
            f = 1.0 - g / glo
            ghi *= f if f > 0.0 else 0.5
        lo = x
        glo = g
        side = 1
    else:
        if side == -1:
            f = 1.0 - g / ghi if ghi != 0.0 else 0.5
            glo *= f if f > 0.0 else 0.5
        hi = x
        ghi = g
        side = -1
    nxt = lo + (hi - lo) * glo / (glo - ghi) if glo > 0.0 else lo
    return lo, glo, hi, ghi, side, nxt


@jit
def step(P, A, S, T, mode, t, dt, W, I, events, count, refine):
    """One full step with event location (M9, M10); the new state is left in S.

    Events inside the step: a free foot (or the body) reaching the ground, and a
    pinned foot (or the resting body) whose pull exceeds what holds it. The
    earliest is located on the scheme's own trajectory (bracket_root), the step is
    advanced to it, the event applied, and the rest of the step integrated.

    With ``refine``, a step whose trial shows a squeeze film it does not resolve
    (:func:`film_too_coarse`) is refused before anything is integrated: it returns True
    and the caller halves it (:func:`substeps`). Returns False when the step was taken.
    """
    now = t
    rem = dt
    tv = t + 0.5 * dt          # the drive is constant over a step (edges on step boundaries)
    n_ev = 0
    tol = P[P_POSTOL]
    first = True
    exempt = 0                 # bit j: point j was re-pinned at the instant of its release
    while True:
        if first and abs(W[W_CT] - now) <= 1e-9 * dt and W[W_CV] == volts(P, tv):
            # the last step ended without events: its end-of-step forces are this state's
            for r in range(NR):
                W[W_LI0 + r] = W[W_LI1 + r]
        else:
            contact_force(P, A, S, mode, now, tv, W, I, W_LI0)
        first = False
        W[W_CT] = -1.0
        if release(P, A, S, mode, count, W, W_LI0) > 0:
            contact_force(P, A, S, mode, now, tv, W, I, W_LI0)
        for j in range(7):
            if (j < 6 and mode[j] != AIR) or (j == 6 and mode[6] == REST):
                W[W_G0 + j] = release_margin(P, S, mode, W, W_LI0, j, 0.0)
        count[CNT_ADV] += 1
        advance(P, A, S, mode, now, rem, W, I, T)
        start_gaps(P, S, now, W)
        gaps(P, A, T, now + rem, W, W_GAP1)
        if refine and n_ev == 0:
            why = film_too_coarse(P, A, mode, rem, W)
            if why > 0:
                if why == 1:
                    count[CNT_HALVED_TRANSIENT] += 1
                return True
        contact_force(P, A, T, mode, now + rem, tv, W, I, W_LI1)
        who = -1
        rel = False
        best = 2.0
        for j in range(7):
            W[W_VREL + j] = 2.0     # here: where in the trial point j's release crosses (linearly)
            pinned = (j < 6 and mode[j] != AIR) or (j == 6 and mode[6] == REST)
            if pinned:
                g1 = release_margin(P, S, mode, W, W_LI1, j, rem)
                if g1 <= 0.0:
                    continue
                g0 = W[W_G0 + j]
                frac = g0 / (g0 - g1) if g0 < 0.0 else 0.0
                W[W_VREL + j] = frac
                if frac < best:
                    best = frac
                    who = j
                    rel = True
                continue
            g1 = W[W_GAP1 + j]
            g0 = W[W_GAP0 + j]
            # every sink below the ground is an impact event (a sink let be, within the position
            # tolerance, would be lifted back at the next step's start: m g d of energy fed into
            # every rebound, and a drop never came to rest), except for a point re-pinned in this
            # step at the instant it was released: released again, it would loop there; its sink
            # is then let be within the tolerance
            if g1 >= 0.0 or ((exempt >> j) & 1 and g1 >= -tol):
                continue
            frac = g0 / (g0 - g1) if g0 > 0.0 else 0.0
            if frac < best:
                best = frac
                who = j
                rel = False
        if who < 0:
            W[W_CT] = now + rem
            W[W_CV] = volts(P, tv)
            break
        if n_ev >= P[P_MAXEV]:
            count[CNT_FORCED] += 1
            break
        n_ev += 1
        # locate the event of `who` inside [0, rem] (bracket_root on the scheme's own trajectory)
        lo = 0.0
        glo = -W[W_G0 + who] if rel else W[W_GAP0 + who]
        hi = rem
        ghi = -release_margin(P, S, mode, W, W_LI1, who, rem) if rel else W[W_GAP1 + who]
        tau = best * rem
        fresh = False           # T holds the trial advanced to tau
        side = 0                # which end of the bracket the last iteration moved (bracket_root)
        tp = hi                 # the last point evaluated (the trial's end, at first)
        gp = ghi
        for _ in range(EVENT_ITERS):
            if tau <= 0.0:
                tau = 0.0
                break
            count[CNT_ADV] += 1
            g = event_value(P, A, S, T, mode, now, tau, tv, W, I, who, rel)
            # an impact: the gap within the position tolerance; a release: the secant's next
            # correction (from the last two points) below EVENT_TIME_TOL of the step
            if (not rel and 0.0 <= g <= tol) or hi - lo <= 1e-9 * rem \
                    or (rel and g != gp and abs(g * (tau - tp)) <= EVENT_TIME_TOL * rem * abs(g - gp)):
                fresh = True
                break
            tp = tau
            gp = g
            lo, glo, hi, ghi, side, tau = bracket_root(lo, glo, hi, ghi, side, tau, g)
        if not rel and not fresh:
            # an impact is applied where the point is still above the ground (the bracket's
            # upper end): lifting a point that sank back onto the ground would add energy
            tau = lo
        if tau > 0.0:
            if not fresh:
                count[CNT_ADV] += 1
                advance(P, A, S, mode, now, tau, W, I, T)
            for k in range(S_SIZE):
                S[k] = T[k]
            for j in range(6):
                if mode[j] != AIR:
                    S[S_TC + j] += tau
            now += tau
            rem -= tau
        if rel:
            # the pull now exceeds the hold: the foot (body) leaves the ground (M10); so does
            # every pinned point whose release the trial puts within EVENT_TIME_TOL of the step
            # of this one's (the location's own tolerance: mirrored feet cross together, to
            # round-off, and released one at a time a symmetric robot turned)
            for j in range(7):
                if j == who or (W[W_VREL + j] <= 1.0 and (W[W_VREL + j] - best) * (rem + tau)
                                <= SIMULTANEOUS * P[P_DT]):
                    mode[j] = AIR
                    if j < 6:
                        S[S_SLIP + j] = 0.0
                        count[CNT_RELEASES] += 1
            if rem <= 0.0:
                return False
            continue
        if tau <= 0.0 and W[W_GAP0 + who] <= 0.0:
            exempt |= 1 << who
        # every free point at or below the ground and approaching it impacts now
        gaps(P, A, S, now, W, W_GAP0)
        _, vg, _ = ground(P, W, now)
        for j in range(7):
            I[I_IMP + j] = 0
            free = mode[j] == AIR
            if free and (W[W_GAP0 + j] <= tol or j == who):
                r = j if j < 6 else ROW_BZ
                # `who` is handled even when it is not approaching: a foot released at the
                # step's start that comes back did not leave (impact() pins it, no impact)
                if row_dot(A, r, S, S_V) - vg < 0.0 or j == who:
                    I[I_IMP + j] = 1
        impact(P, A, S, mode, now, W, I, events, count)
        if rem <= 0.0:
            return False
    for k in range(S_SIZE):
        S[k] = T[k]
    for j in range(6):
        if mode[j] != AIR:
            S[S_TC + j] += rem
    return False


@jit
def substeps(P, A, S, T, mode, t, dt, W, I, events, count):
    """One default step dt from t, halved where a squeeze film needs it (M7, "Numerics").

    A step refused by :func:`step` is halved (down to dt / 2^(NLEV-1), whose matrices are
    cached like dt's); after each accepted sub-step that ends on the grid of the next
    coarser level, that level is tried again. The drive is constant over dt (its edges
    fall on default-step boundaries), so every sub-step sees the same voltage.
    """
    top = NLEV - 1
    units = 1 << top
    unit = dt / units
    pos = 0
    k = 0
    h = dt
    while pos < units:
        if step(P, A, S, T, mode, t + pos * unit, h, W, I, events, count, k < top):
            count[CNT_HALVED] += 1
            k += 1
            h *= 0.5
            continue
        pos += 1 << (top - k)
        if k > 0 and pos % (1 << (top - k + 1)) == 0:
            k -= 1
            h *= 2.0


@jit
def record(P, A, S, mode, t, rec, rec_contact, row):
    zg, _, _ = ground_at(P, t)
    rec[REC_T, row] = t
    rec[REC_Y, row] = S[S_Q + 0]
    rec[REC_Z, row] = P[P_H0] + S[S_Q + 1]
    for k in range(3):
        rec[REC_PH + k, row] = S[S_Q + 2 + k]
    rec[REC_ZG, row] = zg
    for j in range(6):
        rec[REC_FZ + j, row] = row_dot(A, j, S, S_Q)
        rec[REC_FY + j, row] = A[OFF_YFEQ + j] + row_dot(A, 6 + j, S, S_Q)
        s = 0.0
        for i in range(NQ):
            s += A[OFF_KV + j * NQ + i] * S[S_V + i]
        rec[REC_KV + j, row] = s
        rec_contact[row, j] = mode[j]


@jit
def new_scratch():
    """The scratch arrays (W, I) of a run, empty: no contact forces, ground values or
    inverses cached yet."""
    W = np.zeros(W_SIZE)
    W[W_CT] = -1.0
    W[W_GRND] = math.nan
    W[W_GRND + 4] = math.nan
    I = np.zeros(I_SIZE, np.int64)
    for k in range(NSLOT):
        I[I_TAG + k] = -1
    for k in range(NFC):
        I[I_FTAG + k] = -1
    return W, I


@jit
def integrate(P_, A_, S_, mode_, n0, n_steps, dt, every, n_skip, rec, rec_contact, frac, max_air, max_h, count,
              events, W_, I_, T_, air_run):
    """Run steps n0 .. n0 + n_steps - 1 of dt (time n dt); fill the outputs (statistics from step
    n_skip on). A long run is integrated in pieces (:class:`labkit.sim.kernel.Integration`): the
    state, the scratch and every accumulated output carry over, ``rec`` is the piece's own
    (a sample every ``every`` steps from the piece's first step, its last step included; one
    row per column REC_*, so that each recorded quantity is contiguous).

    ``W_, I_`` (:func:`new_scratch`), ``T_`` (S_SIZE) and ``air_run`` (6, zeros) are scratch,
    allocated by the caller, which keeps every array alive for the call.

    The step's arrays go down as plain pointers (:func:`labkit.sim._jit.pointer`) and the
    outputs as arrays without reference counting (:func:`labkit.sim._jit.unmanaged`). An
    array argument costs numba seven words on the stack and an atomic increment and decrement
    of its reference count in every call it is not inlined into, and each index a check for a
    negative value: a step makes dozens of such calls, and the pointers made it 1.45x faster
    than arrays (same results to the bit). Plain Python indexes the arrays themselves."""
    P, A, S, mode = pointer(P_), pointer(A_), pointer(S_), pointer(mode_)
    W, I, T = pointer(W_), pointer(I_), pointer(T_)
    rec, rec_contact, frac, max_air, max_h = unmanaged(rec), unmanaged(rec_contact), unmanaged(frac), \
        unmanaged(max_air), unmanaged(max_h)
    count, events, air_run = unmanaged(count), unmanaged(events), unmanaged(air_run)
    row = 0
    for n in range(n_steps + 1):
        t = (n0 + n) * dt
        if n % every == 0 and row < rec.shape[1]:
            record(P, A, S, mode, t, rec, rec_contact, row)
            row += 1
        if n == n_steps:
            break
        substeps(P, A, S, T, mode, t, dt, W, I, events, count)
        if count[CNT_STOP] == STOP_WHEN_ACTIVE and (count[CNT_NEAR] > 0 or count[CNT_RELEASES] > 0
                                                    or count[CNT_EVENTS] + count[CNT_LOST] + count[CNT_BODY] > 0):
            count[CNT_STOP] = STOPPED
            break
        if n0 + n >= n_skip:
            zg, _, _ = ground(P, W, t + dt)
            for j in range(6):
                frac[j, mode[j]] += dt
                if mode[j] == AIR:
                    air_run[j] += dt
                    if air_run[j] > max_air[j]:
                        max_air[j] = air_run[j]
                    hgt = row_dot(A, j, S, S_Q) - zg
                    if hgt > max_h[j]:
                        max_h[j] = hgt
                else:
                    air_run[j] = 0.0
