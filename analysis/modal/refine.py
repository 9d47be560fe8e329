"""The pole-residue model: residues by linear least squares, then a joint nonlinear refinement.

Model for channel ``o`` (a measurement location) with modes ``i``::

    H_o(w) = sum_i [ R_oi / (j w - lam_i) + conj(R_oi) / (j w - conj(lam_i)) ]
             + sum_q c_oq (j w)^q                                   (residual terms)

with ``lam_i = -zeta_i wn_i + j wn_i sqrt(1 - zeta_i^2)`` shared by all channels
(common poles) and complex residues ``R_oi`` per channel.  The residual terms
(powers ``q`` in ``residual_powers``; complex coefficients) stand in for modes
outside the band: for a velocity FRF a mode far above acts like ``j w``, one
far below like ``1 / (j w)``, and the constant absorbs the ``1`` of a
base-excitation transmissibility.

The refinement runs ``scipy.optimize.least_squares`` on the parameters
``(f_i, zeta_i, Re R, Im R, Re c, Im c)`` with an analytic Jacobian; the
parameter covariance at the optimum is ``s^2 (J^T J)^-1`` with ``s^2`` the
weighted residual variance ("residual"), or the heteroscedasticity-robust
sandwich ``(J^T J)^-1 J^T diag(r^2 / (1 - h)^2) J (J^T J)^-1`` ("sandwich", HC3 with
leverages ``h``), which stays honest when the noise level varies from line to line.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from labkit.analysis.modal.lscf import modal_to_pole, pole_to_modal

__all__ = ["Channel", "Refined", "basis", "residues_ls", "model", "refine", "model_variance"]


@dataclass
class Channel:
    """One location's data: angular frequencies, FRF and per-line weights."""

    name: str
    w: np.ndarray
    H: np.ndarray
    weight: np.ndarray


def basis(w: np.ndarray, lam: np.ndarray, powers: Sequence[int]) -> np.ndarray:
    """Real-parameter basis: columns for Re R_i, Im R_i per mode, then Re c_q, Im c_q.

    Returns a complex ``(N, 2 modes + 2 len(powers))`` matrix ``B`` with ``H = B @ p``
    for real ``p``.
    """
    return _basis_ef(w, lam, powers)[0]


#: The last :func:`_basis_ef` computed: ``(w, lam, powers, (cols, E, F))``.  A refinement asks for the
#: basis of an accepted trial point again (its normal equations, the covariance, the fitted model),
#: and one basis of 7950 lines x 22 modes takes 4-5 ms; the arrays are returned read-only.
_LAST_BASIS: list[tuple] = []


def _basis_ef(w: np.ndarray, lam: np.ndarray, powers: Sequence[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`basis` and its pole terms ``E = 1 / (j w - lam)``, ``F = 1 / (j w - conj(lam))`` (read-only;
    the last one is remembered, see :data:`_LAST_BASIS`)."""
    last = _LAST_BASIS[0] if _LAST_BASIS else None
    if (last is not None and last[0] is w and last[2] == tuple(powers) and last[1].shape == lam.shape
            and np.array_equal(last[1], lam)):
        return last[3]
    out = _basis_ef_new(w, lam, powers)
    for a in out:
        a.flags.writeable = False
    _LAST_BASIS[:] = [(w, lam.copy(), tuple(powers), out)]
    return out


def _basis_ef_new(w: np.ndarray, lam: np.ndarray, powers: Sequence[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    # Built as (columns, lines) rows and returned transposed (column-major): each column is contiguous,
    # which is what the Gram matrices (BLAS) and WB (:func:`_wb_gram`) want; a third less time.
    jw = 1j * w[None, :]
    E = 1.0 / (jw - lam[:, None])
    F = 1.0 / (jw - np.conj(lam)[:, None])
    cols = np.empty((2 * lam.size + 2 * len(powers), w.size), dtype=complex)
    np.add(E, F, out=cols[0:2 * lam.size:2])
    cols[1:2 * lam.size:2] = 1j * (E - F)
    for k, q in enumerate(powers):
        t = (1j ** (q % 4)) * w ** float(q)                 # (j w)^q without a complex power (slow)
        cols[2 * lam.size + 2 * k] = t
        cols[2 * lam.size + 2 * k + 1] = 1j * t
    return cols.T, E.T, F.T


def _ri(a: np.ndarray) -> np.ndarray:
    return np.concatenate([a.real, a.imag])


def _same_grid(channels: Sequence[Channel]) -> bool:
    """True when every channel has the first one's lines (then the pole terms are computed once)."""
    if not channels:
        return False
    w0 = channels[0].w
    return all(c.w is w0 or (c.w.shape == w0.shape and np.array_equal(c.w, w0)) for c in channels)


def residues_ls(channels: Sequence[Channel], lam: np.ndarray, powers: Sequence[int]) -> list[np.ndarray]:
    """Linear least-squares residues and residual terms per channel for fixed poles."""
    out = []
    shared = basis(channels[0].w, lam, powers) if channels and _same_grid(channels) else None
    if shared is not None and all(np.all(c.weight == c.weight[0]) for c in channels):
        # A weight constant over the lines scales both sides: one solve for all channels.
        rhs = np.column_stack([_ri(c.H) for c in channels])
        p, *_ = np.linalg.lstsq(np.vstack([shared.real, shared.imag]), rhs, rcond=None)
        return [p[:, k].copy() for k in range(len(channels))]
    for ch in channels:
        B = (basis(ch.w, lam, powers) if shared is None else shared) * ch.weight[:, None]
        p, *_ = np.linalg.lstsq(np.vstack([B.real, B.imag]), _ri(ch.H * ch.weight), rcond=None)
        out.append(p)
    return out


def _start_residues(channels: Sequence[Channel], lam: np.ndarray, powers: Sequence[int]) -> list[np.ndarray]:
    """Residues to start the refinement from: :func:`residues_ls` by the scaled normal equations
    (a fifth of the time; the iteration polishes them) where those are well conditioned."""
    if not _gram_ok(channels):
        return residues_ls(channels, lam, powers)
    from scipy.linalg import LinAlgError, cho_factor, cho_solve

    _, WB, G_all = _wb_gram(channels[0].w, lam, powers)         # the first normal equations' too
    X = WB[:, 2 * lam.size:]                                      # [Re B; Im B]
    G = G_all[2 * lam.size:, 2 * lam.size:]
    d = np.sqrt(np.diag(G))
    d[d == 0] = 1.0
    try:
        L = cho_factor(G / np.outer(d, d))
    except LinAlgError:
        return residues_ls(channels, lam, powers)
    if np.min(np.abs(np.diag(L[0]))) < 1e-5:            # cond(X) above ~1e5: least squares proper
        return residues_ls(channels, lam, powers)
    rhs = X.T @ np.column_stack([_ri(c.H) for c in channels])
    p = cho_solve(L, rhs / d[:, None]) / d[:, None]
    return [p[:, k].copy() for k in range(len(channels))]


def model(w: np.ndarray, lam: np.ndarray, p: np.ndarray, powers: Sequence[int]) -> np.ndarray:
    """Evaluate the model of one channel with real parameter vector ``p`` (see :func:`basis`)."""
    return basis(np.asarray(w, dtype=float), lam, powers) @ p


@dataclass
class Refined:
    """Result of :func:`refine`."""

    freq_hz: np.ndarray
    damping_ratio: np.ndarray
    lin: list[np.ndarray]          # per channel: [Re R_1, Im R_1, ..., Re c_q, Im c_q]
    cov: np.ndarray                # covariance of the full parameter vector
    theta: np.ndarray              # full parameter vector (f_1, z_1, ..., channel 0 lin, channel 1 lin, ...)
    ssr: float                     # weighted sum of squared residuals (real + imag parts)
    dof: int
    success: bool
    nfev: int
    misfit: np.ndarray | None = None   # per channel, misfit to noise before any scaling of cov (set by the fit)


def _unpack(theta: np.ndarray, m: int, n_lin: int, n_ch: int):
    fz = theta[:2 * m].reshape(m, 2)
    lins = [theta[2 * m + k * n_lin: 2 * m + (k + 1) * n_lin] for k in range(n_ch)]
    return fz[:, 0], fz[:, 1], lins


def _poles_and_derivatives(f: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """Poles of ``(f, zeta)`` (damping clipped into (0, 1)) and ``(d lam / d f, d lam / d zeta)``."""
    z = np.clip(z, 1e-13, 0.999)
    sq = np.sqrt(np.clip(1 - z ** 2, 1e-12, None))
    return modal_to_pole(f, z), (2 * np.pi * (-z + 1j * sq), 2 * np.pi * f * (-1 - 1j * z / sq))


def _channel_terms(theta, channels, m, powers, want_jac=True):
    """Per channel: weighted complex residual and complex Jacobian blocks (poles, own linear part)."""
    n_lin = 2 * m + 2 * len(powers)
    f, z, lins = _unpack(theta, m, n_lin, len(channels))
    lam, (dlam_df, dlam_dz) = _poles_and_derivatives(f, z)
    out = []
    shared = _same_grid(channels)             # common lines: the pole terms once, not per channel
    for k, ch in enumerate(channels):
        if k == 0 or not shared:
            B, E, F = _basis_ef(ch.w, lam, powers)
            E2, F2 = (E * E, F * F) if want_jac else (E, F)
        p = lins[k]
        r = (B @ p - ch.H) * ch.weight
        if not want_jac:
            out.append((r, None, None))
            continue
        R = p[0:2 * m:2] + 1j * p[1:2 * m:2]
        # dH/df = E^2 R dlam/df + F^2 conj(R dlam/df) (likewise for zeta); a weight constant over the
        # lines is folded into the m coefficients instead of multiplying the N x m blocks
        wt = ch.weight
        c = float(wt[0]) if np.all(wt == wt[0]) else 1.0
        Jp = np.empty((ch.w.size, 2 * m), dtype=complex)
        for col, dlam in ((0, dlam_df), (1, dlam_dz)):
            a = c * R * dlam
            Jp[:, col::2] = E2 * a + F2 * np.conj(a)
        if c == 1.0 and not np.all(wt == 1.0):
            Jp *= wt[:, None]
        out.append((r, Jp, B * wt[:, None]))
    return out


def _normal(terms, m: int, n_lin: int):
    """Normal matrix ``J^T J`` and gradient ``J^T r`` of the real-stacked problem.

    For real parameters and residuals stacked as ``[Re; Im]``, ``J^T J = Re(J^H J)``;
    the Jacobian is block-arrow shaped (poles shared, linear parts per channel),
    so only the small blocks are formed.
    """
    return _assemble_normal(_explicit_normals(terms), m, n_lin)


def _explicit_normals(terms) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per channel ``(r, G, g)``: the residual, ``X^T X`` and ``X^T r`` of ``X = [Jp, B]`` real-stacked."""
    out = []
    for r, Jp, B in terms:
        J, rs = _stacked(Jp, B, r)                            # real-stacked: half the work of Re(J^H J)
        out.append((r, J.T @ J, J.T @ rs))
    return out


def _assemble_normal(normals, m: int, n_lin: int) -> tuple[np.ndarray, np.ndarray]:
    """The full normal matrix and gradient from the per-channel blocks of :func:`_explicit_normals`."""
    P = 2 * m + n_lin * len(normals)
    A = np.zeros((P, P))
    g = np.zeros(P)
    for k, (_, G, gk) in enumerate(normals):
        sl = slice(2 * m + k * n_lin, 2 * m + (k + 1) * n_lin)
        A[:2 * m, :2 * m] += G[:2 * m, :2 * m]
        A[:2 * m, sl] = G[:2 * m, 2 * m:]
        A[sl, :2 * m] = G[2 * m:, :2 * m]
        A[sl, sl] = G[2 * m:, 2 * m:]
        g[:2 * m] += gk[:2 * m]
        g[sl] = gk[2 * m:]
    return A, g


def _gram_ok(channels: Sequence[Channel]) -> bool:
    """Common lines and a weight constant over the lines of each channel: :func:`_gram_normals` applies."""
    return _same_grid(channels) and all(np.all(c.weight == c.weight[0]) for c in channels)


def _gram_normals(theta, channels, m, powers) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """:func:`_explicit_normals` without forming any channel's Jacobian (common lines, constant weights).

    Every channel's real-stacked Jacobian is ``J_k = WB M_k`` with ``WB`` shared by the channels and a
    small ``M_k`` (:func:`_shared_parts`), so ``J_k^T J_k = M_k^T (WB^T WB) M_k`` from one Gram matrix and
    ``J_k^T r_k = M_k^T (WB^T r_k)``: the gradients use the residuals themselves, so the fixed point is
    that of the explicit form.
    """
    WB, G, per = _shared_parts(theta, channels, m, powers)
    return [(r, M.T @ G @ M, M.T @ (WB.T @ rs)) for r, rs, M in per]


def _shared_parts(theta, channels, m, powers):
    """``(WB, WB^T WB, [(r_k, rs_k, M_k)])`` for channels with common lines and constant weights.

    With ``P = E^2 + F^2`` and ``Q = E^2 - F^2``, a channel's pole column ``E^2 a + F^2 conj(a)``
    stacks as ``W [Re a; Im a]`` with ``W = [[Re P, -Im Q], [Im P, Re Q]]``, and its basis block is
    the shared ``Bs = [Re B; Im B]`` times its weight ``c``.  So ``J_k = [W, Bs] M_k = WB M_k`` with a
    small ``M_k``; ``rs_k`` is the real-stacked weighted residual ``r_k``.  The Gram matrix is one
    symmetric rank-k update (``dsyrk``: half the work of a general product).
    """
    n_lin = 2 * m + 2 * len(powers)
    f, z, lins = _unpack(theta, m, n_lin, len(channels))
    lam, dlams = _poles_and_derivatives(f, z)
    B, WB, G = _wb_gram(channels[0].w, lam, powers)
    i = np.arange(m)
    per = []
    for ch, p in zip(channels, lins):
        c = float(ch.weight[0])
        r = (B @ p - ch.H) * c
        R = p[0:2 * m:2] + 1j * p[1:2 * m:2]
        M = np.zeros((2 * m + n_lin, 2 * m + n_lin))
        for col, dlam in enumerate(dlams):
            a = c * R * dlam
            M[i, 2 * i + col], M[m + i, 2 * i + col] = a.real, a.imag
        M[2 * m:, 2 * m:] = c * np.eye(n_lin)
        per.append((r, np.concatenate([r.real, r.imag]), M))
    return WB, G, per


#: The last :func:`_wb_gram`: ``(basis arrays, (WB, G))``, valid while :data:`_LAST_BASIS` holds that basis.
_LAST_WB: list[tuple] = []


def _wb_gram(w: np.ndarray, lam: np.ndarray, powers: Sequence[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The basis ``B`` of poles ``lam``, the shared ``WB`` of :func:`_shared_parts` and its Gram matrix
    ``WB^T WB`` (one ``dsyrk``), remembered for the last basis (the starting residues and the first
    normal equations use the same)."""
    from scipy.linalg.blas import dsyrk

    basis_ef = _basis_ef(w, lam, powers)
    if _LAST_WB and _LAST_WB[0][0] is basis_ef:
        return basis_ef[0], *_LAST_WB[0][1]
    B, E, F = basis_ef
    m = lam.size
    Et, Ft, Bt = E.T, F.T, B.T                          # (columns, lines), contiguous rows (_basis_ef_new)
    E2, F2 = Et * Et, Ft * Ft
    n = E.shape[0]
    WBt = np.empty((2 * m + B.shape[1], 2 * n))         # WB^T by rows: WB column-major
    P = E2 + F2
    WBt[:m, :n], WBt[:m, n:] = P.real, P.imag
    P = E2 - F2
    np.negative(P.imag, out=WBt[m:2 * m, :n])
    WBt[m:2 * m, n:] = P.real
    WBt[2 * m:, :n], WBt[2 * m:, n:] = Bt.real, Bt.imag
    WB = WBt.T
    G = dsyrk(1.0, WB, trans=1)                         # upper triangle of WB^T WB
    G = G + np.triu(G, 1).T
    WB.flags.writeable = False
    _LAST_WB[:] = [(basis_ef, (WB, G))]
    return B, WB, G


def _normals(theta, channels, m, powers) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per channel ``(r, J^T J, J^T r)`` (real-stacked), by the cheapest exact route."""
    if _gram_ok(channels):
        return _gram_normals(theta, channels, m, powers)
    return _explicit_normals(_channel_terms(theta, channels, m, powers))


def _stacked(Jp: np.ndarray, B: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``[[Re Jp, Re B], [Im Jp, Im B]]`` as one contiguous real array (filled in place) and ``[Re r; Im r]``."""
    n, a, b = r.size, Jp.shape[1], B.shape[1]
    X = np.empty((2 * n, a + b))
    X[:n, :a], X[n:, :a] = Jp.real, Jp.imag
    X[:n, a:], X[n:, a:] = B.real, B.imag
    return X, np.concatenate([r.real, r.imag])


def _blocks(normals, free_p: np.ndarray):
    """The normal equations in blocks, scaled to unit diagonal: the shared (free) pole parameters
    ``(G_pp, g_p, d_p)`` and per channel ``(G_pl, G_ll, g_l, d_l)`` (see :func:`_lm_step`), from the
    per-channel ``(r, G, g)`` of :func:`_normals`."""
    chans = []
    P = int(np.sum(free_p))
    G_pp = np.zeros((P, P))
    g_p = np.zeros(P)
    sel = np.concatenate([free_p, np.ones(normals[0][1].shape[0] - free_p.size, bool)]) if normals else free_p
    for _, Gf, gf in normals:
        G, gk = Gf[np.ix_(sel, sel)], gf[sel]
        G_pp += G[:P, :P]
        g_p += gk[:P]
        chans.append((G[:P, P:], G[P:, P:], gk[P:]))
    d_p = np.sqrt(np.diag(G_pp))
    d_p[d_p == 0] = 1.0
    out = []
    for G_pl, G_ll, g_l in chans:
        d_l = np.sqrt(np.diag(G_ll))
        d_l[d_l == 0] = 1.0
        out.append((G_pl / np.outer(d_p, d_l), G_ll / np.outer(d_l, d_l), g_l / d_l, d_l))
    return G_pp / np.outer(d_p, d_p), g_p / d_p, d_p, out


def _lm_step(blocks, mu: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """The Levenberg-Marquardt step ``-(A + mu I)^-1 g`` (scaled) of the block-arrow normal matrix.

    The per-channel linear parameters are eliminated (Schur complement), so
    the cost grows linearly with the number of channels instead of with the
    cube of the parameter count.
    """
    G_pp, g_p, d_p, chans = blocks
    S = G_pp + mu * np.eye(G_pp.shape[0])
    rhs = g_p.copy()
    solved = []
    for G_pl, G_ll, g_l, _ in chans:
        L = G_ll + mu * np.eye(G_ll.shape[0])
        X = np.linalg.solve(L, np.column_stack([G_pl.T, g_l]))       # L^-1 [G_lp, g_l]
        S -= G_pl @ X[:, :-1]
        rhs -= G_pl @ X[:, -1]
        solved.append((L, X))
    x_p = np.linalg.solve(S, rhs) if S.size else np.zeros(0)
    steps_l = []
    for (_, X), (_, _, _, d_l) in zip(solved, chans):
        x_l = X[:, -1] - X[:, :-1] @ x_p                                 # L^-1 (g_l - G_lp x_p)
        steps_l.append(-x_l / d_l)
    return -x_p / d_p, steps_l


def _cost(terms) -> float:
    return float(sum(np.sum(r.real ** 2 + r.imag ** 2) for r, _, _ in terms))


def _dense(terms, m: int, n_lin: int) -> tuple[np.ndarray, np.ndarray]:
    """The full real-stacked residual vector and Jacobian (for scipy's solver and checks)."""
    P = 2 * m + n_lin * len(terms)
    rows_r, rows_j = [], []
    for k, (r, Jp, B) in enumerate(terms):
        J = np.zeros((r.size, P), dtype=complex)
        J[:, :2 * m] = Jp
        J[:, 2 * m + k * n_lin: 2 * m + (k + 1) * n_lin] = B
        rows_r.append(np.concatenate([r.real, r.imag]))
        rows_j.append(np.vstack([J.real, J.imag]))
    return np.concatenate(rows_r), np.vstack(rows_j)


def refine(channels: Sequence[Channel], lam0: np.ndarray, powers: Sequence[int], *,
           band_hz: tuple[float, float], covariance: str = "residual", max_iter: int = 100,
           tol: float = 1e-10, solver: str = "normal", fixed_freq: np.ndarray | None = None,
           fixed_damping: np.ndarray | None = None) -> Refined:
    """Refine poles, residues and residual terms together by nonlinear least squares.

    ``solver="normal"`` (default): a Levenberg-Marquardt iteration on the
    normal equations, which exploits the block structure (a few shared pole
    parameters, many per-channel linear ones); ``scipy.optimize.least_squares``
    factors the full ``(2 lines) x (parameters)`` Jacobian at every step and is
    5-10 times slower here.  ``solver="scipy"`` runs ``least_squares`` (method
    ``"lm"``, analytic Jacobian) instead, as a cross-check.  Damping ratios
    are kept in (0, 1) by clipping.

    ``fixed_freq`` / ``fixed_damping`` (boolean per mode) hold those values at
    their starting values (poles chosen by hand); their variances are zero.

    Channels that share their lines with weights constant over them get their
    normal equations from one Gram matrix (:func:`_gram_normals`).  Once a step
    lowers the cost by less than the noise variance, the next is taken from the
    explicit Jacobian, which the covariance then reuses: when that step converges
    (cost changed by less than ``tol``), the covariance is the last iterate but one's.
    """
    m = lam0.size
    n_lin = 2 * m + 2 * len(powers)
    f0, z0 = pole_to_modal(lam0)
    z0 = np.clip(z0, 1e-10, 0.95)
    # the residues of the poles the iteration starts from, bit for bit (its first basis is then this one)
    lins = _start_residues(channels, _poles_and_derivatives(f0, z0)[0], powers)
    theta = np.concatenate([np.column_stack([f0, z0]).ravel(), *lins])
    free = np.ones(theta.size, dtype=bool)
    if fixed_freq is not None:
        free[0:2 * m:2] = ~np.asarray(fixed_freq, dtype=bool)
    if fixed_damping is not None:
        free[1:2 * m:2] = ~np.asarray(fixed_damping, dtype=bool)
    if solver == "scipy" and not free.all():
        raise ValueError("solver 'scipy' does not hold parameters fixed")
    if solver == "scipy":
        from scipy.optimize import least_squares

        def fun(th):
            return _dense(_channel_terms(th, channels, m, powers), m, n_lin)[0]

        def jac(th):
            return _dense(_channel_terms(th, channels, m, powers), m, n_lin)[1]

        sol = least_squares(fun, theta, jac=jac,
                            method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=2000)
        theta = sol.x
        return _finish(theta, channels, m, n_lin, powers, covariance, bool(sol.success), int(sol.nfev), free)
    elif solver != "normal":
        raise ValueError(f"solver must be 'normal' or 'scipy', not {solver!r}")
    normals = _normals(theta, channels, m, powers)
    cost = _cost(normals)
    mu = 1e-3
    success = False
    n_iter = 0
    free_p = free[:2 * m]
    small = theta.size <= BLOCK_COVARIANCE_ABOVE
    dof = max(sum(2 * c.w.size for c in channels) - theta.size, 1)
    at = None                                           # the explicit terms the covariance will use
    for n_iter in range(1, max_iter + 1):  # noqa: B007 -- the count is reported after the loop
        blocks = _blocks(normals, free_p)
        improved = False
        while mu < 1e12:
            step = np.zeros(theta.size)
            try:
                step_p, step_l = _lm_step(blocks, mu)
            except np.linalg.LinAlgError:
                mu *= 10
                continue
            step[:2 * m][free_p] = step_p
            step[2 * m:] = np.concatenate(step_l)
            trial = theta + step
            trial[1:2 * m:2] = np.clip(trial[1:2 * m:2], 1e-12, 0.98)
            trial[0:2 * m:2] = np.clip(trial[0:2 * m:2], 0.25 * band_hz[0], 2.0 * band_hz[1])
            t_terms = _channel_terms(trial, channels, m, powers, want_jac=False)
            t_cost = _cost(t_terms)
            if t_cost < cost:
                improved = True
                break
            mu *= 10
        if not improved:
            success = True                              # no downhill step left: at the minimum
            break
        rel = (cost - t_cost) / max(cost, 1e-300)
        near = cost - t_cost < t_cost / dof
        small_step = np.all(np.abs(step) <= tol * 100 * (np.abs(theta) + 1e-12))
        theta, cost = trial, t_cost
        mu = max(mu / 10, 1e-12)
        if rel < tol or small_step:
            success = True
            break
        # A step that lowered the cost by less than the noise variance moved the estimate by about its
        # standard uncertainty or less: the next one is then typically the last, and the explicit
        # Jacobian the covariance needs gives its normal equations too (one evaluation, not two).
        at = _explicit(theta, channels, m, powers) if near and small else None
        normals = _normals(theta, channels, m, powers) if at is None else at[2]
    return _finish(theta, channels, m, n_lin, powers, covariance, success, n_iter, free, at, cost)


#: Above this many parameters the covariance is computed by blocks (many locations: a scan).  Below,
#: the dense pseudo-inverse, whose cut-off of near-singular directions (nearly collinear residual
#: terms over a narrow band) acts on the whole problem at once.
BLOCK_COVARIANCE_ABOVE = 300


def _explicit(theta, channels, m, powers):
    """Each channel's terms (:func:`_channel_terms`), its real-stacked Jacobian and residual as
    ``(X, M, rs)`` with ``J = X M`` (``M`` None: ``J = X``; see :func:`_stacked`), and normal equations
    from them: the normal matrix and the sandwich both use ``J``."""
    if _gram_ok(channels):
        return _explicit_shared(theta, channels, m, powers)
    terms = _channel_terms(theta, channels, m, powers)
    stacks = [_stacked(Jp, B, r) for r, Jp, B in terms]
    return (terms, [(J, None, rs) for J, rs in stacks],
            [(r, J.T @ J, J.T @ rs) for (r, _, _), (J, rs) in zip(terms, stacks)])


def _explicit_shared(theta, channels, m, powers):
    """:func:`_explicit` for common lines and constant weights (:func:`_gram_ok`): every channel's
    Jacobian is the shared ``WB`` times its own small ``M`` (:func:`_shared_parts`), never formed."""
    WB, G, per = _shared_parts(theta, channels, m, powers)
    terms = [(r, None, None) for r, _, _ in per]
    stacks = [(WB, M, rs) for _, rs, M in per]
    normals = [(r, M.T @ G @ M, M.T @ (WB.T @ rs)) for r, rs, M in per]
    return terms, stacks, normals


def _finish(theta, channels, m, n_lin, powers, covariance, success, n_iter, free=None, at=None,
            cost=None) -> Refined:
    """The result at ``theta``, its covariance from ``at`` (:func:`_explicit`, possibly of the last
    iterate but one, whose step changed the cost by under ``tol``: the same to that order) or
    computed here; ``cost``: the cost at ``theta`` when known."""
    small = theta.size <= BLOCK_COVARIANCE_ABOVE
    n_obs = sum(2 * c.w.size for c in channels)
    dof = max(n_obs - int(np.sum(free)) if free is not None else n_obs - theta.size, 1)
    if small:
        terms, stacks, normals = _explicit(theta, channels, m, powers) if at is None else at
        ssr = _cost(terms) if cost is None else float(cost)
        A, _ = _assemble_normal(normals, m, n_lin)
        if free is not None and not free.all():
            # Held parameters: no variance, and no part in the others' (rows and columns zeroed).
            A = A * np.outer(free, free)
        cov = _covariance(A, stacks, ssr, m, n_lin, dof, covariance)
    else:
        terms = _channel_terms(theta, channels, m, powers)
        ssr = _cost(terms)
        free_p = np.ones(2 * m, bool) if free is None else np.asarray(free[:2 * m], bool)
        cov = _covariance_blocks(terms, m, n_lin, free_p, dof, covariance)
    f, z, lin = _unpack(theta, m, n_lin, len(channels))
    return Refined(f.copy(), z.copy(), [np.array(x) for x in lin], cov, theta, ssr, dof, success, n_iter)


def _pinv_sym(A: np.ndarray) -> np.ndarray:
    # Scaling to unit diagonal keeps the inverse accurate when parameters differ
    # by many orders of magnitude (Hz against damping ratios against residues).
    d = np.sqrt(np.abs(np.diag(A)))              # a Schur complement's diagonal can round below 0
    d[~(d > 0) | ~np.isfinite(d)] = 1.0
    inv = _inv_well_conditioned(A / np.outer(d, d))
    if inv is not None:
        return inv / np.outer(d, d)
    ev, V = np.linalg.eigh(A / np.outer(d, d))
    keep = ev > ev.max() * 1e-14
    return ((V[:, keep] / ev[keep]) @ V[:, keep].T) / np.outer(d, d)


def _inv_well_conditioned(A: np.ndarray) -> np.ndarray | None:
    """``A^-1`` of a symmetric positive definite ``A`` by Cholesky (a sixth of an eigendecomposition's
    time) when LAPACK's condition estimate shows that :func:`_pinv_sym`'s cut-off (eigenvalues below
    ``1e-14`` of the largest) would cut nothing; otherwise None."""
    from scipy.linalg.lapack import dpocon, dpotrf, dpotri

    if A.size == 0 or not np.all(np.isfinite(A)):
        return None
    L, info = dpotrf(A, lower=1, clean=1)
    if info != 0:
        return None
    rcond, info = dpocon(L, float(np.max(np.sum(np.abs(A), axis=0))), uplo="L")
    if info != 0 or not rcond > 1e-11:          # the 1-norm estimate is within a factor n of the 2-norm's
        return None
    inv, info = dpotri(L, lower=1)
    if info != 0:
        return None
    return np.tril(inv) + np.tril(inv, -1).T


def _covariance_blocks(terms, m: int, n_lin: int, free_p: np.ndarray, dof: int, kind: str) -> np.ndarray:
    """The parameter covariance of :func:`_covariance`, by blocks: O(P^2 m) instead of O(P^3).

    The normal matrix is block-arrow shaped (shared pole parameters ``p``,
    per-channel linear parameters ``l_k``).  With ``T_k = A_kk^-1 A_kp`` and the
    Schur complement's (pseudo-)inverse ``Sig = (A_pp - sum A_pk T_k)^+``, the
    inverse is ``U Sig U^T + blockdiag(0, A_kk^-1)`` with ``U = [I; -T_1; ...]``,
    and the sandwich ``inv M inv`` (``M`` block-arrow too) is
    ``U Sig Q Sig U^T + C Sig U^T + U Sig C^T + blockdiag(0, W_k M_k W_k^T)`` with
    ``V_k = [I, -T_k^T]``, ``W_k = [0, A_kk^-1]``, ``Q = sum V_k M_k V_k^T`` and
    ``C`` stacking ``W_k M_k V_k^T``.  Held pole parameters (``~free_p``) have
    zero rows and columns.
    """
    fp = np.flatnonzero(free_p)
    pf = fp.size
    K = len(terms)
    P = 2 * m + K * n_lin
    A_pp = np.zeros((pf, pf))
    per = []
    for r, Jp, B in terms:
        J = Jp[:, fp]
        A_pp += (J.conj().T @ J).real
        A_pl = (J.conj().T @ B).real
        inv_ll = _pinv_sym((B.conj().T @ B).real)
        per.append((J, B, r, A_pl, inv_ll, inv_ll @ A_pl.T))           # T_k = A_ll^-1 A_lp
    S = A_pp - sum(A_pl @ T for _, _, _, A_pl, _, T in per) if per else A_pp
    Sig = _pinv_sym(S) if pf else np.zeros((0, 0))
    U = np.zeros((P, pf))
    U[fp, np.arange(pf)] = 1.0
    for k, (*_, T) in enumerate(per):
        U[2 * m + k * n_lin: 2 * m + (k + 1) * n_lin] = -T
    if kind != "sandwich":
        cov = U @ Sig @ U.T
        for k, (*_, inv_ll, _) in enumerate(per):
            sl = slice(2 * m + k * n_lin, 2 * m + (k + 1) * n_lin)
            cov[sl, sl] += inv_ll
        return cov * _cost(terms) / dof
    Q = np.zeros((pf, pf))
    C = np.zeros((P, pf))
    diag_blocks = []
    for k, (J, B, r, _, inv_ll, T) in enumerate(per):
        # The inverse restricted to (p, l_k), for the leverages (HC3, as in _covariance).
        STt = Sig @ T.T
        sub = np.block([[Sig, -STt], [-STt.T, inv_ll + T @ STt]])
        Jk = np.hstack([J, B])
        M = np.zeros((pf + n_lin, pf + n_lin))
        for part, res in ((Jk.real, r.real), (Jk.imag, r.imag)):
            lev = np.clip(np.sum((part @ sub) * part, axis=1), 0.0, 0.99)
            Jr = part * (res / (1.0 - lev))[:, None]
            M += Jr.T @ Jr
        V = np.hstack([np.eye(pf), -T.T])                                  # (pf, pf + n_lin)
        W = np.hstack([np.zeros((n_lin, pf)), inv_ll])                     # (n_lin, pf + n_lin)
        Q += V @ M @ V.T
        C[2 * m + k * n_lin: 2 * m + (k + 1) * n_lin] = W @ M @ V.T
        diag_blocks.append(W @ M @ W.T)
    USig = U @ Sig
    CSig = C @ Sig
    cov = USig @ Q @ USig.T + CSig @ U.T + U @ CSig.T
    for k, blk in enumerate(diag_blocks):
        sl = slice(2 * m + k * n_lin, 2 * m + (k + 1) * n_lin)
        cov[sl, sl] += blk
    return cov


def _covariance(A: np.ndarray, stacks: list[tuple[np.ndarray, np.ndarray | None, np.ndarray]], cost: float,
                m: int, n_lin: int, dof: int, kind: str) -> np.ndarray:
    """The parameter covariance from the normal matrix ``A``; for the sandwich each channel's
    real-stacked Jacobian ``J = X M`` and residual ``rs`` as ``(X, M, rs)`` (``M`` None: ``J = X``,
    which is then overwritten; otherwise ``X`` may be shared by the channels and is left alone)."""
    from scipy.linalg.blas import dsyrk

    inv = _pinv_sym(A)
    if kind != "sandwich":
        return inv * cost / dof
    # HC3: each residual inflated by 1 / (1 - leverage); plain HC0 under-covers
    # when the few lines near a sharp peak carry most of the information.
    P = A.shape[0]
    meat = np.zeros((P, P))
    buf = None
    for k, (X, M, res) in enumerate(stacks):         # real and imaginary rows together
        idx = np.r_[np.arange(2 * m), 2 * m + k * n_lin + np.arange(n_lin)]
        S = inv[np.ix_(idx, idx)]
        if M is not None and buf is None:
            buf = np.empty(X.shape, order="F")       # one work array for every channel's leverages and meat
        lev = np.clip(_leverages(X, S if M is None else M @ S @ M.T, buf), 0.0, 0.99)
        u = (res / (1.0 - lev))[:, None]
        if M is None:
            Xu = np.multiply(X, u, out=X)            # in place: the rows weighted for the meat
        else:
            assert buf is not None
            Xu = np.multiply(X, u, out=buf)
        G = dsyrk(1.0, Xu, trans=1) if Xu.flags.f_contiguous else dsyrk(1.0, Xu.T, trans=0)
        G = G + np.triu(G, 1).T                      # X_u^T X_u from its upper triangle
        meat[np.ix_(idx, idx)] += G if M is None else M.T @ G @ M
    return inv @ meat @ inv


def _leverages(J: np.ndarray, S: np.ndarray, work: np.ndarray | None = None) -> np.ndarray:
    """``diag(J S J^T)`` for a symmetric positive semi-definite ``S``: ``|J L|^2`` by rows with the
    Cholesky factor ``S = L L^T`` (a triangular product, half the work of ``J S``), or ``J S`` itself
    where ``S`` is singular (a direction the pseudo-inverse cut).  ``work``: a column-major array of
    ``J``'s shape to compute in (overwritten), instead of a new one."""
    from scipy.linalg import LinAlgError, cholesky
    from scipy.linalg.blas import dtrmm

    d = np.sqrt(np.abs(np.diag(S)))
    d[d == 0] = 1.0
    try:
        L = cholesky(S / np.outer(d, d), lower=True) * d[:, None]
    except LinAlgError:
        return np.einsum("ij,ij->i", J @ S, J)
    if work is not None and work.shape == J.shape and work.flags.f_contiguous:
        np.copyto(work, J)
        X = dtrmm(1.0, L, work, side=1, lower=1, overwrite_b=1)   # J L in place, column-major for BLAS
    else:
        X = dtrmm(1.0, L, np.asfortranarray(J), side=1, lower=1)
    X *= X
    return X @ np.ones(X.shape[1])                                   # row sums (a BLAS product)


def model_variance(channels: Sequence[Channel], ref: Refined, powers: Sequence[int],
                   noise_var: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Per channel, the variance ``E|model - E model|^2`` of the fitted model at each line caused by
    noise of variance ``noise_var`` (per channel and line, in the units of the FRF): the parameter
    covariance ``A^-1 J^T diag(noise) J A^-1`` carried to each line (first order).

    Where the noise differs from line to line (relative noise, a sharp peak), the parameters carry
    the noise of the loud lines to the quiet ones: there the residual is this, not the local noise.
    The noise, not the residual, is the meat, so a wrong model is not excused by its own misfit.
    Above :data:`BLOCK_COVARIANCE_ABOVE` parameters (many locations, whose common poles are well
    determined) each channel's own residues and residual terms only, with the poles held.
    """
    m = ref.freq_hz.size
    n_lin = 2 * m + 2 * len(powers)
    terms = _channel_terms(ref.theta, channels, m, powers)
    if ref.theta.size > BLOCK_COVARIANCE_ABOVE:
        return [_linear_model_variance(B, c.weight, v) for (_, _, B), c, v in zip(terms, channels, noise_var)]
    A, _ = _normal(terms, m, n_lin)
    inv = _pinv_sym(A)
    meat = np.zeros_like(A)
    parts = []
    for k, ((_, Jp, B), c, v) in enumerate(zip(terms, channels, noise_var)):
        idx = np.r_[np.arange(2 * m), 2 * m + k * n_lin + np.arange(n_lin)]
        J = np.hstack([Jp, B])
        half = 0.5 * np.asarray(v, dtype=float) * c.weight ** 2          # per real component
        meat[np.ix_(idx, idx)] += J.real.T @ (J.real * half[:, None]) + J.imag.T @ (J.imag * half[:, None])
        parts.append((idx, J))
    C = inv @ meat @ inv
    out = []
    for (idx, J), c in zip(parts, channels):
        Ck = C[np.ix_(idx, idx)]
        var = np.sum((J.real @ Ck) * J.real, axis=1) + np.sum((J.imag @ Ck) * J.imag, axis=1)
        out.append(np.clip(var, 0.0, None) / np.maximum(c.weight, 1e-300) ** 2)
    return out


def _linear_model_variance(B: np.ndarray, weight: np.ndarray, noise_var: np.ndarray) -> np.ndarray:
    """:func:`model_variance` of one channel with its poles held (weighted basis ``B``)."""
    half = 0.5 * np.asarray(noise_var, dtype=float) * weight ** 2
    X = np.vstack([B.real, B.imag])
    inv = _pinv_sym(X.T @ X)
    C = inv @ (B.real.T @ (B.real * half[:, None]) + B.imag.T @ (B.imag * half[:, None])) @ inv
    var = np.sum((B.real @ C) * B.real, axis=1) + np.sum((B.imag @ C) * B.imag, axis=1)
    return np.clip(var, 0.0, None) / np.maximum(weight, 1e-300) ** 2
