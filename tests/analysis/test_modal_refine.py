"""labkit.analysis.modal.refine: the structured solver against scipy, the analytic Jacobian, the covariance."""
from __future__ import annotations

import numpy as np

from labkit.analysis.modal.lscf import modal_to_pole
from labkit.analysis.modal.refine import Channel, _channel_terms, _dense, refine
from labkit.analysis.modal.synth import synthetic_frf

FN = np.array([438.0, 1200.0])
ZETA = np.array([0.05, 0.02])
POWERS = (-1, 0, 1)


def _channels(seed: int = 0) -> list[Channel]:
    f = np.linspace(200, 2000, 300)
    H = synthetic_frf(f, FN, ZETA, np.array([[1.0, 0.4], [0.3, 1.0]]) * 1e7, noise=0.01, seed=seed)
    return [Channel(n, 2 * np.pi * f, h, np.full(f.size, 1 / np.sqrt(np.mean(np.abs(h) ** 2))))
            for n, h in zip("ab", H)]


def test_structured_solver_matches_scipy_least_squares():
    ch = _channels()
    lam0 = modal_to_pole(FN * np.array([1.01, 0.99]), ZETA * np.array([1.2, 0.8]))
    a = refine(ch, lam0, POWERS, band_hz=(200, 2000), solver="normal")
    b = refine(ch, lam0, POWERS, band_hz=(200, 2000), solver="scipy")
    assert a.success and b.success
    np.testing.assert_allclose(a.freq_hz, b.freq_hz, rtol=1e-8)
    np.testing.assert_allclose(a.damping_ratio, b.damping_ratio, rtol=1e-6)
    assert a.ssr <= b.ssr * (1 + 1e-9)
    np.testing.assert_allclose(np.sqrt(np.diag(a.cov))[:4], np.sqrt(np.diag(b.cov))[:4], rtol=1e-4)


def test_analytic_jacobian_and_residual_covariance():
    ch = _channels(1)
    lam0 = modal_to_pole(FN, ZETA)
    ref = refine(ch, lam0, POWERS, band_hz=(200, 2000), covariance="residual")
    m, n_lin = 2, 2 * 2 + 2 * len(POWERS)
    th = ref.theta
    r, J = _dense(_channel_terms(th, ch, m, POWERS), m, n_lin)
    # finite differences, column by column, relative steps
    for j in range(th.size):
        h = 1e-6 * max(abs(th[j]), 1e-3)
        tp, tm = th.copy(), th.copy()
        tp[j] += h
        tm[j] -= h
        num = (_dense(_channel_terms(tp, ch, m, POWERS), m, n_lin)[0]
               - _dense(_channel_terms(tm, ch, m, POWERS), m, n_lin)[0]) / (2 * h)
        np.testing.assert_allclose(J[:, j], num, rtol=1e-4, atol=1e-6 * np.max(np.abs(num)))
    # the covariance is s^2 (J^T J)^-1 of the dense problem
    dof = r.size - th.size
    cov = np.linalg.inv(J.T @ J) * (r @ r) / dof
    np.testing.assert_allclose(np.sqrt(np.diag(ref.cov)), np.sqrt(np.diag(cov)), rtol=1e-6)


def test_block_covariance_equals_the_dense_one(monkeypatch):
    """The covariance by blocks (Schur complement; linear in the locations) is the dense formula's."""
    import labkit.analysis.modal.refine as modal_refine
    from labkit.analysis.modal.refine import _cost, _covariance, _normal, _stacked

    monkeypatch.setattr(modal_refine, "BLOCK_COVARIANCE_ABOVE", 0)          # blocks even for this small case

    ch = _channels(2) + _channels(3)[:1]
    m, n_lin = 2, 2 * 2 + 2 * len(POWERS)
    for fixed in (None, np.array([True, False])):
        for kind in ("residual", "sandwich"):
            ref = refine(ch, modal_to_pole(FN, ZETA), POWERS, band_hz=(200, 2000), covariance=kind, fixed_freq=fixed)
            terms = _channel_terms(ref.theta, ch, m, POWERS)
            A, _ = _normal(terms, m, n_lin)
            free = np.ones(ref.theta.size, bool)
            if fixed is not None:
                free[0:2 * m:2] = ~fixed
            stacks = [(J, None, rs) for J, rs in (_stacked(Jp, B, r) for r, Jp, B in terms)]
            dense = _covariance(A * np.outer(free, free), stacks, _cost(terms), m, n_lin, ref.dof, kind)
            np.testing.assert_allclose(ref.cov, dense, rtol=0, atol=1e-10 * np.max(np.abs(dense)))
            np.testing.assert_allclose(np.sqrt(np.diag(ref.cov))[free], np.sqrt(np.diag(dense))[free], rtol=1e-8)


def test_gram_normal_equations_equal_the_explicit_ones():
    """The normal equations from one shared Gram matrix (common lines, constant weights), and the
    Jacobians built from shared real arrays, are those of each channel's explicit Jacobian."""
    from labkit.analysis.modal.refine import _explicit_normals, _explicit_shared, _gram_normals, _gram_ok, _stacked

    ch = _channels(2) + _channels(3)[:1]
    assert _gram_ok(ch)
    m = 2
    ref = refine(ch, modal_to_pole(FN * 1.001, ZETA), POWERS, band_hz=(200, 2000))
    th = ref.theta * (1 + 1e-4 * np.sin(np.arange(ref.theta.size)))       # off the optimum: a gradient
    got = _gram_normals(th, ch, m, POWERS)
    want = _explicit_normals(_channel_terms(th, ch, m, POWERS))
    for (r1, G1, g1), (r2, G2, g2) in zip(got, want):
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_allclose(G1, G2, rtol=1e-9, atol=1e-12 * np.max(np.abs(G2)))
        np.testing.assert_allclose(g1, g2, rtol=1e-8, atol=1e-10 * np.max(np.abs(g2)))
    _, stacks, normals = _explicit_shared(th, ch, m, POWERS)
    for (_, G1, g1), (X1, M1, rs1), (r2, Jp, B), (_, G2, g2) in zip(normals, stacks,
                                                                     _channel_terms(th, ch, m, POWERS), want):
        J1, (J2, rs2) = X1 @ M1, _stacked(Jp, B, r2)                        # J = WB M, WB shared
        np.testing.assert_array_equal(rs1, rs2)
        np.testing.assert_allclose(J1, J2, rtol=1e-12, atol=1e-13 * np.max(np.abs(J2)))
        np.testing.assert_allclose(G1, G2, rtol=1e-9, atol=1e-12 * np.max(np.abs(G2)))
        np.testing.assert_allclose(g1, g2, rtol=1e-8, atol=1e-10 * np.max(np.abs(g2)))
    uneven = [Channel(c.name, c.w, c.H, c.weight * np.linspace(1, 2, c.w.size)) for c in ch]
    assert not _gram_ok(uneven)


def test_leverages_by_cholesky_equal_the_quadratic_form():
    """diag(J S J^T) by the Cholesky factor of S equals the direct form, and S singular (a direction
    the pseudo-inverse cut, a held parameter) falls back to it; the leverages of the full normal
    matrix sum to the number of parameters."""
    from labkit.analysis.modal.refine import _leverages

    rng = np.random.default_rng(0)
    J = np.asfortranarray(rng.standard_normal((400, 12)) * np.logspace(-3, 3, 12))
    S = np.linalg.inv(J.T @ J)
    direct = np.einsum("ij,ij->i", J @ S, J)
    np.testing.assert_allclose(_leverages(J, S), direct, rtol=1e-9, atol=1e-15)
    assert abs(_leverages(J, S).sum() - 12) < 1e-9
    S[0, :] = S[:, 0] = 0.0
    np.testing.assert_allclose(_leverages(np.ascontiguousarray(J), S), np.einsum("ij,ij->i", J @ S, J), rtol=1e-12)
