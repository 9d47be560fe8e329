"""simulate() end to end: impacts, symmetry, convergence, kernel vs reference, outputs."""
from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from labkit.errors import InputError
from labkit.sim import ABLATIONS, PZT, RobotParams, Shaker, SimResult, simulate
from labkit.sim import model as M

# The published adhesion (50 uN, ~15 body weights) holds the feet for good at 25 um;
# with 50 nN the robot walks at 240 Hz (see the report), which exercises every mode. 100 um
# foot pads (docs/model.md M7): their film holds the lifted feet near the tray and the walk is
# periodic (the default 30 um pads let the feet fly: a chaotic walk, tests/sim/test_laws.py).
WALK = RobotParams(c_ad_n=50e-9, foot_pad_um=100.0)


@pytest.fixture(scope="module")
def walking():
    return simulate(WALK, Shaker(freq_hz=240, amp_um=25), duration_s=0.3)


def test_walking_run_shape_and_summary(walking):
    r = walking
    n = len(r.t_s)
    assert isinstance(r, SimResult) and n == pytest.approx(0.3 / r.record_dt_s + 1, abs=1)
    assert r.body_angles_rad.shape == (n, 3)
    for a in (r.foot_z_um, r.foot_y_um, r.contact, r.knee_vz_mm_s):
        assert a.shape == (n, 6)
    assert r.contact.dtype == np.int8 and set(np.unique(r.contact)) <= {0, 1, 2}
    assert r.mean_speed_mm_s > 1.0                 # it walks, forward (+y)
    assert r.impacts.min() > 0
    for fr in r.contact_fraction.values():
        assert set(fr) == {"air", "adhesion", "rest"} and sum(fr.values()) == pytest.approx(1.0)
    assert set(r.patterns) <= {"firm_contact", "partial_contact", "jumping"}
    s = json.loads(json.dumps(r.summary()))
    assert s["mean_speed_mm_s"] == r.mean_speed_mm_s and s["scenario"]["freq_hz"] == 240.0
    # the knee's velocity is what a vibrometer would integrate to the knee's motion
    assert np.abs(r.knee_vz_mm_s).max() > 10


def _check_impact_law(r):
    """Newton's law at every logged foot impact (docs/model.md M9, M11): the normal velocity
    relative to the ground reverses with c_r, unless that rebound is slower than v_stick or
    the foot's squeeze film stops it within the position tolerance (rebound m / c < POS_TOL,
    c the films' coefficient at contact, docs/model.md M7: the pad's at the asperity gap, the
    leg's at the body's gap, both rarefied; m the foot's effective mass), and then the foot is
    pinned (relative velocity 0); the lateral velocity becomes 0."""
    p = r.params
    ev = r.events
    feet = ev[ev[:, M.EV_LEG] >= 0]
    assert len(feet) == r.impacts.sum() > 0
    vpre, vpost, vy = feet[:, M.EV_VPRE], feet[:, M.EV_VPOST], feet[:, M.EV_VYPOST]
    assert np.all(vpre < 0)                          # every impact meets the ground moving into it
    stuck = feet[:, M.EV_STUCK] == 1
    mdl = M.build_model(p, Shaker(240, 0.0))
    rows = mdl.rows
    w_foot = np.array([rows[:, j] @ np.linalg.solve(mdl.mass, rows[:, j]) for j in range(6)])   # 1 / m_foot
    lam = p.mean_free_path_nm * 1e-9

    def film(b, u):
        return b / (u ** 3 * (1 + 9.638 * (lam / u) ** 1.159))         # Veijola et al. 1995
    pad = 0.4217 * 1.85e-5 * (p.foot_pad_um * 1e-6) ** 4                # Bao and Yang 2007, square plate
    c_floor = film(pad, p.film_gap_nm * 1e-9) + film(p.b_g_foot_n_m2_s, p.body_gap_um * 1e-6)
    rebound = -p.c_r * vpre
    film = rebound < M.POS_TOL_M * c_floor * w_foot[feet[:, M.EV_LEG].astype(int)]
    np.testing.assert_array_equal(stuck, (rebound < p.v_stick_mm_s * 1e-3) | film)
    np.testing.assert_allclose(vpost[~stuck], -p.c_r * vpre[~stuck], rtol=1e-9, atol=1e-15)
    assert np.abs(vpost[stuck]).max(initial=0.0) < 1e-12
    assert np.abs(vy).max() < 1e-12                  # no lateral slip, m/s
    return stuck


def test_restitution_and_zero_lateral_slip_at_every_impact(walking):
    # on 100 um pads every landing sticks: the pad's film at contact stops rebounds below ~3 cm/s
    assert np.all(_check_impact_law(walking))
    # without them, another restitution and a lower sticking threshold: rebounds
    r = simulate(WALK.replace(c_r=0.8, c_ad_n=0.0, v_stick_mm_s=1e-3), Shaker(240, 25), duration_s=0.05,
                 ablation="no_squeeze_film")
    stuck = _check_impact_law(r)
    assert (~stuck).sum() > 10


def test_no_foot_below_the_ground_in_air(walking):
    r = walking
    gap = r.foot_z_um - r.ground_z_um[:, None]
    # um: no missed impact (events are located to M.POS_TOL_M = 0.1 nm)
    assert gap[r.contact == M.AIR].min() > -2 * M.POS_TOL_M * 1e6
    pinned = r.contact != M.AIR
    assert np.abs(gap[pinned]).max() < 1e-6           # pinned feet sit exactly on the ground


def test_mirror_symmetry_of_the_walk(walking):
    """Flipping every lateral coupling mirrors the walk (the same dynamics up to the order
    of floating-point operations, which the hybrid contact decisions amplify slightly)."""
    flipped = simulate(WALK.replace(cy_sign=(-1, -1, -1)), Shaker(240, 25), duration_s=0.3)
    assert flipped.mean_speed_mm_s == pytest.approx(-walking.mean_speed_mm_s, rel=1e-2)
    span = np.ptp(walking.body_y_um)
    np.testing.assert_allclose(flipped.body_y_um, -walking.body_y_um, atol=0.01 * span)
    none = simulate(WALK.replace(cy_sign=(0, 0, 0)), Shaker(240, 25), duration_s=0.3)
    assert abs(none.mean_speed_mm_s) < 1e-9 and np.abs(none.body_y_um).max() < 1e-9
    assert none.impacts.sum() > 0                    # it still hops


def _agree(a, b, t_min_s):
    """Kernel and reference give the same trajectory (to 1 nm) until their first
    differing contact decision (a threshold met within rounding: from there the
    hybrid dynamics amplify the last bit), and that comes late, if at all."""
    differs = np.any(a.contact != b.contact, axis=1)
    first = int(np.argmax(differs)) if differs.any() else len(a.t_s)
    assert a.t_s[first - 1] >= t_min_s
    for name in ("body_y_um", "body_z_um", "foot_z_um", "foot_y_um"):
        np.testing.assert_allclose(getattr(a, name)[:first], getattr(b, name)[:first], rtol=0, atol=1e-3)
    np.testing.assert_allclose(a.knee_vz_mm_s[:first], b.knee_vz_mm_s[:first], rtol=0, atol=1e-3)


@pytest.mark.parametrize("scenario, duration, t_min", [(Shaker(240, 25), 0.02, 0.003),
                                                       (PZT(1800, 20.0, mass_mg=1.0), 0.006, 0.005)])
def test_kernel_agrees_with_reference(scenario, duration, t_min):
    a = simulate(WALK, scenario, duration_s=duration, engine="numba")
    b = simulate(WALK, scenario, duration_s=duration, engine="reference")
    assert b.engine == "reference"
    _agree(a, b, t_min_s=t_min)
    # and after a divergence, the same gait: the walk is a stable periodic orbit
    assert np.abs(a.body_y_um - b.body_y_um).max() < 1.0
    assert abs(int(a.impacts.sum()) - int(b.impacts.sum())) <= 0.05 * a.impacts.sum() + 1


def test_pzt_drive_and_payload():
    r = simulate(WALK, PZT(freq_hz=1800, voltage_v=20), duration_s=0.1)
    assert r.impacts.sum() > 0 and np.isfinite(r.mean_speed_mm_s)
    heavy = simulate(WALK, PZT(freq_hz=1800, voltage_v=20, mass_mg=3.0), duration_s=0.05)
    assert not np.allclose(heavy.body_z_um, r.body_z_um[:len(heavy.t_s)])
    with pytest.raises(InputError, match="mass_mg"):
        simulate(WALK, PZT(1800, 20, mass_mg=0.04), duration_s=0.01)


def test_ablations(walking):
    assert set(ABLATIONS) == {"none", "no_adhesion", "no_squeeze_film"}
    r = simulate(WALK, Shaker(240, 25), duration_s=0.05, ablation="no_squeeze_film")
    assert r.params.b_g_foot_n_m2_s == 0.0 and r.params.b_g_body_n_m2_s == 0.0 and r.ablation == "no_squeeze_film"
    # without the film the legs swing further (paper Fig. 12, left)
    n = len(r.t_s)
    assert np.abs(r.knee_vz_mm_s).max() > np.abs(walking.knee_vz_mm_s[:n]).max()
    q = simulate(RobotParams(), Shaker(240, 25), duration_s=0.02, ablation="no-adhesion")
    assert q.params.c_ad_n == 0.0 and q.params.c_ad_t_n_s == 0.0
    with pytest.raises(InputError, match="ablation"):
        simulate(WALK, Shaker(240, 25), duration_s=0.01, ablation="no_gravity")


def test_bad_arguments():
    with pytest.raises(InputError, match="engine"):
        simulate(WALK, Shaker(240, 25), duration_s=0.01, engine="fortran")
    with pytest.raises(InputError, match="duration_s"):
        simulate(WALK, Shaker(240, 25), duration_s=-1)
    with pytest.raises(InputError, match="dt_s"):
        simulate(WALK, Shaker(240, 25), duration_s=0.01, dt_s=0.0)
    with pytest.raises(InputError, match="record_dt_s"):
        simulate(WALK, Shaker(240, 25), duration_s=0.01, record_dt_s=1.0)
    with pytest.raises(InputError, match="scenario"):
        simulate(WALK, {"freq_hz": 240}, duration_s=0.01)


def test_seed_is_reproducible():
    a = simulate(WALK, Shaker(300, 25), duration_s=0.02, seed=3)
    b = simulate(WALK, Shaker(300, 25), duration_s=0.02, seed=3)
    c = simulate(WALK, Shaker(300, 25), duration_s=0.02, seed=4)
    assert np.array_equal(a.foot_z_um, b.foot_z_um)
    assert not np.array_equal(a.foot_z_um, c.foot_z_um)


def test_to_h5(walking, tmp_path):
    path = walking.to_h5(tmp_path / "run.h5")
    with h5py.File(path, "r") as f:
        assert f.attrs["kind"] == "sim_result" and int(f.attrs["schema_version"]) >= 1
        for name, ds in f.items():
            assert "units" in ds.attrs, name
        assert f["foot_z_um"].attrs["units"] == "um" and f["knee_vz_mm_s"].attrs["units"] == "mm/s"
        assert f["t_s"].shape == walking.t_s.shape
        toml_text = f.attrs["params_toml"]
        summary = json.loads(f.attrs["summary_json"])
    (tmp_path / "p.toml").write_text(toml_text)
    assert RobotParams.from_toml(tmp_path / "p.toml") == WALK
    assert summary["patterns"] == walking.patterns


def test_coulomb_friction_option(walking):
    """mu = inf (default) is the paper's no-slip; a large mu changes nothing; a small one does."""
    big = simulate(WALK.replace(mu=1e3), Shaker(240, 25), duration_s=0.3)
    # (a foot about to be released carries almost no normal load, so even mu = 1e3 lets
    # it slip for an instant: the walk is the same to 1 %)
    assert big.mean_speed_mm_s == pytest.approx(walking.mean_speed_mm_s, rel=1e-2)
    slippery = simulate(WALK.replace(mu=0.1), Shaker(240, 25), duration_s=0.3)
    assert abs(slippery.mean_speed_mm_s - walking.mean_speed_mm_s) > 0.05
    at_rest = simulate(RobotParams(mu=0.0), Shaker(240, 0.0), duration_s=0.05)
    assert np.abs(at_rest.body_y_um).max() < 1e-9      # um: round-off of the static solve
    a = simulate(WALK.replace(mu=0.1), Shaker(240, 25), duration_s=0.02, engine="numba")
    b = simulate(WALK.replace(mu=0.1), Shaker(240, 25), duration_s=0.02, engine="reference")
    _agree(a, b, t_min_s=0.003)
    assert np.abs(a.body_y_um - b.body_y_um).max() < 1.0


def test_body_contact_restitution_and_rest():
    """Dropped from 3 mm without air films, the published robot's soft legs let the body
    hit the ground: restitution c_r_body, then it comes to rest on its feet."""
    p = RobotParams(b_g_body_n_m2_s=0.0, b_g_foot_n_m2_s=0.0, foot_pad_um=0.0, c_r_body=0.3)
    r = simulate(p, Shaker(240, 0.0), duration_s=0.15, start_height_um=3000)
    gap = r.body_z_um - r.ground_z_um
    assert r.body_impacts > 0 and gap.min() > -2 * M.POS_TOL_M * 1e6
    assert r.counters["steps_event_capped"] == 0       # no Zeno cascade of bounces
    body = r.events[r.events[:, M.EV_LEG] == -1]
    vpre, vpost = body[:, M.EV_VPRE], body[:, M.EV_VPOST]
    bounced = body[:, M.EV_STUCK] == 0
    np.testing.assert_allclose(vpost[bounced], -p.c_r_body * vpre[bounced], rtol=1e-9)
    assert bounced.any()
    assert np.abs(np.diff(r.body_z_um[-100:])).max() < 0.5   # um per sample: settled


@pytest.mark.parametrize("params", [RobotParams(), RobotParams.preset("paper"), RobotParams(cy_sign=(0.0, 0.0, 0.0))],
                         ids=["published", "paper", "cy_sign_0"])
def test_partial_step_system_equals_a_dense_solve(params):
    """The Schur-complement solve of a partial step (scheme.partial_system / partial_vbar)
    against numpy's dense solve of (2M + hD + h^2/2 K) on the same rows."""
    from labkit.sim.reference import scheme_python

    K = scheme_python()
    mdl = M.build_model(params, Shaker(240, 25))
    h = 3.7e-6
    P, A = mdl.pack(8.68e-6)
    S = np.linalg.inv(2 * mdl.mass + h * np.diag(mdl.damp) + 0.5 * h * h * np.diag(mdl.stiff))
    rng = np.random.default_rng(1)
    W = np.zeros(K.W_SIZE)
    Iw = np.zeros(K.I_SIZE, np.int64)
    rows = [0, 6, 2, 8, 5, 11, K.ROW_BZ]
    n = len(rows)
    Iw[K.I_ROWS:K.I_ROWS + n] = rows
    r = rng.normal(size=K.NQ)
    W[K.W_R:K.W_R + K.NQ] = r
    K.partial_system(A, h, W, Iw, n)
    R = mdl.rows[:, rows]
    assert np.allclose(W[K.W_Y0:K.W_Y0 + K.NQ], S @ r, rtol=1e-10, atol=1e-12 * np.abs(S @ r).max())
    Q = np.array([[W[K.W_QH + a * K.NR + b] for b in rows] for a in rows])
    assert np.allclose(Q, R.T @ S @ R, rtol=1e-10, atol=1e-12 * np.abs(R.T @ S @ R).max())
    alpha = rng.normal(size=n)
    W[K.W_BS:K.W_BS + n] = alpha
    K.partial_vbar(A, W, Iw, n)
    want = S @ (r + R @ alpha)
    assert np.allclose(W[K.W_VB:K.W_VB + K.NQ], want, rtol=1e-10, atol=1e-12 * np.abs(want).max())


@pytest.mark.parametrize("params", [RobotParams(), RobotParams.preset("paper")], ids=["published", "paper"])
def test_packed_step_matrices_of_every_level_equal_the_dense_ones(params):
    """Model.pack's matrices for dt and each halving (stacked inverses, S^-1 by parts) against
    numpy's dense inverse of S = 2M + hD + h^2/2 K at that level, assembled here."""
    from labkit.sim import scheme as K

    mdl = M.build_model(params, PZT(1746, 28.7))
    dt = 8.68e-6
    _, A = mdl.pack(dt)
    R = mdl.rows
    for lev in range(K.NLEV):
        h = dt / 2 ** lev
        S = 2 * mdl.mass + h * np.diag(mdl.damp) + 0.5 * h * h * np.diag(mdl.stiff)
        Sinv = np.linalg.inv(S)
        base = K.OFF_LEV + lev * K.LEV_SIZE
        zt = A[base + K.LEV_ZT:base + K.LEV_ZT + K.NR * K.NQ].reshape(K.NR, K.NQ)
        q = A[base + K.LEV_Q:base + K.LEV_Q + K.NR * K.NR].reshape(K.NR, K.NR)
        dli = A[base + K.LEV_DLI:base + K.LEV_DLI + K.NQ]
        assert np.allclose(zt, (Sinv @ R).T, rtol=1e-10, atol=1e-12 * np.abs(Sinv @ R).max())
        assert np.allclose(q, R.T @ Sinv @ R, rtol=1e-10, atol=1e-12 * np.abs(R.T @ Sinv @ R).max())
        assert np.array_equal(dli[K.NB:], 1.0 / np.diag(S)[K.NB:]) and not dli[:K.NB].any()
        # the body's block of S^-1 is the inverse of the Schur complement: check it through a solve
        sci = A[base + K.LEV_SCI:base + K.LEV_SCI + K.NB * K.NB].reshape(K.NB, K.NB)
        assert np.allclose(sci, Sinv[:K.NB, :K.NB], rtol=1e-9, atol=1e-12 * np.abs(Sinv[:K.NB, :K.NB]).max())


def test_small_system_solver_on_semidefinite_systems():
    """scheme.spd_solve: LDL^T of a positive definite system equals numpy's solve; with a
    dependent row (a singular, consistent system) the dependent unknown is 0 and the
    equations hold, as scheme.gauss does."""
    from labkit.sim.reference import scheme_python

    K = scheme_python()
    rng = np.random.default_rng(2)
    n, lda = 6, K.NI
    B = rng.normal(size=(n, n))
    Amat = B @ B.T + np.diag(rng.uniform(0, 3, n))
    b = rng.normal(size=n)
    W = np.zeros(lda * lda + lda)
    W[:lda * lda].reshape(lda, lda)[:n, :n] = Amat
    W[lda * lda:lda * lda + n] = b
    K.spd_solve(W, 0, lda * lda, n)
    assert np.allclose(W[lda * lda:lda * lda + n], np.linalg.solve(Amat, b), rtol=1e-10)
    # rows 0 and 1 the same constraint (like the lateral rows of legs without lateral
    # compliance): their Gram matrix is singular, the system consistent
    G = rng.normal(size=(4, n))
    G[1] = G[0]
    Q = G @ G.T
    x_true = rng.normal(size=4)
    x_true[1] = 0.0
    rhs = Q @ x_true
    W[:] = 0.0
    W[:lda * lda].reshape(lda, lda)[:4, :4] = Q
    W[lda * lda:lda * lda + 4] = rhs
    K.spd_solve(W, 0, lda * lda, 4)
    x = W[lda * lda:lda * lda + 4]
    assert x[1] == 0.0
    assert np.allclose(Q @ x, rhs, atol=1e-9 * np.abs(rhs).max())


def _lower(W, n):
    lda = int(np.sqrt(W.size - 1))
    return np.tril(W[:lda * lda].reshape(lda, lda)[:n, :n])


def test_ldl_factor_resumed_after_a_factored_block_is_the_same_to_the_bit():
    """scheme.ldl_factor: factoring an n x n system whose leading p x p block is already
    factored gives the bits of factoring it whole (each entry the same sum in the same
    order), with live pivots and with a dead one (two equal rows) inside the block."""
    from labkit.sim.reference import scheme_python

    K = scheme_python()
    rng = np.random.default_rng(7)
    n, p, lda = 13, 12, K.NI
    for dead in (False, True):
        G = rng.normal(size=(n, n + 3))
        if dead:
            G[4] = G[3]
        Q = G @ G.T
        eps = 1e-12 * np.diag(Q).max()
        W = np.zeros(lda * lda + 1)
        W[:lda * lda].reshape(lda, lda)[:n, :n] = Q
        whole = W.copy()
        K.ldl_factor(whole, 0, n, 0, eps)
        resumed = W.copy()
        resumed[:lda * lda].reshape(lda, lda)[:p, :p] = whole[:lda * lda].reshape(lda, lda)[:p, :p]
        K.ldl_factor(resumed, 0, n, p, eps)
        assert np.array_equal(_lower(resumed, n), _lower(whole, n))
        assert (_lower(whole, n)[4:, 4] == 0).all() == dead


def test_cached_factor_of_the_pinned_rows_gives_the_uncached_solution_to_the_bit():
    """scheme.small_solve: the system of twelve pinned rows and the body's film row solved with
    the pinned block's factor cached (its first step, the next steps, a film coefficient that
    moves the dead-pivot threshold past one of the block's pivots, and back) equals the
    solution without the cache (scheme.spd_solve), bit for bit, and solves the system."""
    from labkit.sim.reference import scheme_python

    K = scheme_python()
    rng = np.random.default_rng(11)
    A = np.zeros(K.A_SIZE)
    G = rng.normal(size=(K.NR, K.NR + 2))
    G[5] = G[4] + 1e-5 * G[5]              # a pivot ~1e-10 of the largest: live or dead by eps
    Q = G @ G.T
    A[K.OFF_LEV + K.LEV_Q:K.OFF_LEV + K.LEV_Q + K.NR * K.NR] = Q.ravel()
    rows = list(range(12)) + [K.ROW_BZ]
    n, h = len(rows), 1e-5

    rhs = np.r_[np.arange(1.0, n), -0.4]

    def pose(W, Iw, c):                      # the rows, the right-hand sides, the film row's 1 / (h c)
        for a, r in enumerate(rows):
            Iw[K.I_ROWS + a] = r
            Iw[K.I_KIND + a] = 0 if r == K.ROW_BZ else 1
        W[K.W_BS:K.W_BS + n] = rhs
        W[K.W_DG + n - 1] = 1.0 / (h * c)

    Wc, Ic = K.new_scratch()                 # one scratch over the steps: the cache lives there
    pose(Wc, Ic, 1e3)
    key = K.pinned_block(Ic, n, 0)[1]
    assert key >= 0
    for c in (1e3, 1e3, 1e3, 1e-3, 1e-3, 1e3):   # 1 / (h c) = 100 or 1e8: eps crosses the small pivot
        W, Iw = K.new_scratch()
        pose(W, Iw, c)
        K.assemble(A, W, Iw, n, 0)
        K.spd_solve(W, K.W_AS, K.W_BS, n)
        pose(Wc, Ic, c)
        K.small_solve(A, Wc, Ic, n, 0)
        assert np.array_equal(Wc[K.W_BS:K.W_BS + n], W[K.W_BS:K.W_BS + n])
        assert (key in Ic[K.I_FTAG:K.I_FTAG + K.NFC]) == (c > 1.0)   # a dead pivot is not kept
        if c > 1.0:
            x = Wc[K.W_BS:K.W_BS + n].copy()
    Qs = Q[np.ix_(rows, rows)].copy()
    Qs[-1, -1] += 1.0 / (h * 1e3)
    assert x[5] != 0.0
    assert np.all(np.abs(Qs @ x - rhs) <= 1e-9 * (np.abs(Qs) @ np.abs(x)))


def _state_after(K, p, sc, steps):
    """The reference scheme's run (p, sc) after ``steps`` steps: (P, A, run, dt)."""
    from labkit.sim import core
    from labkit.sim.kernel import Integration

    dt = core._step(p, sc, 0.05, None, None)
    mdl = M.build_model(p, sc)
    state, mode = core._start(mdl, None, None, core.JITTER_UM)
    P, A = mdl.pack(dt)
    run = Integration(K, P, A, state, np.asarray(mode), dt, 0, 100)
    run.advance(steps, steps)
    return P, A, run, dt


_WALK_50NN = (RobotParams(c_ad_n=50e-9), Shaker(freq_hz=240, amp_um=25))
_TRIPODS = (RobotParams.preset("paper"), PZT(freq_hz=438, voltage_v=8))


@pytest.mark.parametrize(("case", "steps", "feet_in_air"),
                         [(_WALK_50NN, 200, 6), (_WALK_50NN, 500, 0), (_TRIPODS, 75, 2), (_TRIPODS, 150, 3)],
                         ids=["flying", "resting", "tripods-a", "tripods-b"])
def test_a_step_reads_the_feet_rows_only_of_its_own_state(case, steps, feet_in_air):
    """scheme.foot_rows keeps the feet's rows of a state for the functions of a step that read
    them (forces, active_rows, advance, contact_force, the start gaps): a step's result must
    be the same to the bit whatever the scratch held there before (NaN, or another state's
    rows), at states with every foot in the air (films), every foot resting (pinned), and
    one tripod pinned while the other flies (both at once: contact_force with free feet);
    and the contact forces it leaves for the next step are those of its end state."""
    from labkit.sim.reference import scheme_python

    K = scheme_python()
    P, A, run, dt = _state_after(K, *case, steps)
    assert int((run.md[:6] == K.AIR).sum()) == feet_in_air
    results = []
    Wf, If = K.new_scratch()
    K.gaps(P, A, run.S, steps * dt, Wf, K.W_GAP0)        # the start state's gaps, nothing cached
    start_gaps = Wf[K.W_GAP0:K.W_GAP0 + 7].copy()
    for fill in (np.nan, 1e-3, -7.0):
        S, T, md = run.S.copy(), np.zeros(K.S_SIZE), run.md.copy()
        W, Iw = run.W.copy(), run.I.copy()
        for o, size in ((K.W_RQ, 6), (K.W_RV, 6), (K.W_RB, K.NI)):
            W[o:o + size] = fill
        count, events = np.zeros(K.CNT_SIZE, np.int64), np.zeros((100, K.EV_COLS))
        assert not K.step(P, A, S, T, md, steps * dt, dt, W, Iw, events, count, False)
        assert np.all(np.isfinite(S))
        results.append((S, md))
        # a step without events (so the checks below are not skipped): the gaps it found at its
        # start (every foot's, pinned ones too) and the contact forces it left for the next step
        # are those of its start and end states (contact_force on a fresh scratch: nothing cached)
        assert count[K.CNT_EVENTS] == 0
        assert np.array_equal(W[K.W_GAP0:K.W_GAP0 + 7], start_gaps)
        Wf, If = K.new_scratch()
        K.contact_force(P, A, S, md, (steps + 1) * dt, (steps + 0.5) * dt, Wf, If, K.W_LI1)
        assert np.array_equal(W[K.W_LI1:K.W_LI1 + K.NR], Wf[K.W_LI1:K.W_LI1 + K.NR])
    for S, md in results[1:]:
        assert np.array_equal(S, results[0][0]) and np.array_equal(md, results[0][1])


@pytest.mark.parametrize("every_pass", [False, True], ids=["passes-skipped", "every-pass"])
def test_a_film_rows_recorded_velocity_is_that_of_the_steps_last_pass(every_pass, monkeypatch):
    """After a step (scheme.advance) a film row's recorded mean velocity relative to the ground
    (S_FV) is R_j . vbar - the ground's mean velocity, vbar the step's mean velocity as its end
    positions give it, (q1 - q0) / h: whether the film passes stopped early (no film's effect
    changed) or all ran (advance reuses the last pass's R_j . vbar only in the first case; in
    the second, at this state, the last pass moves it by 0.3 %)."""
    from labkit.sim.reference import scheme_python

    K = scheme_python()
    if every_pass:
        monkeypatch.setattr(K, "FILM_PASS_SKIP", -1.0)
    P, A, run, dt = _state_after(K, *_TRIPODS, 200)     # every foot flies, near the ground
    S, out, md = run.S.copy(), np.zeros(K.S_SIZE), run.md.copy()
    W, Iw = run.W.copy(), run.I.copy()
    t = 200 * dt
    K.advance(P, A, S, md, t, dt, W, Iw, out)
    vbar = (out[K.S_Q:K.S_Q + K.NQ] - S[K.S_Q:K.S_Q + K.NQ]) / dt
    vgm = (K.ground_at(P, t + dt)[0] - K.ground_at(P, t)[0]) / dt
    R = A[K.OFF_RT:K.OFF_RT + 6 * K.NQ].reshape(6, K.NQ)
    want = R @ vbar - vgm
    assert np.all(out[K.S_FH:K.S_FH + 6] == dt)            # six film rows (every foot flies)
    got = out[K.S_FV:K.S_FV + 6]
    assert np.allclose(got, want, rtol=1e-9, atol=1e-9 * np.abs(want).max())


def test_pack_refuses_a_model_outside_the_kernels_structure():
    """The kernel's row products and partial-step solve rely on the model's structure (a
    foot's rows involve the body and its own leg only; the legs' modal coordinates are
    uncoupled in M; M exactly symmetric); pack() checks it instead of computing wrong."""
    base = M.build_model(RobotParams(), Shaker(240, 25))
    base.pack(8.68e-6)
    for what, message in (("rows", "another leg"), ("legs", "coupled"), ("symmetry", "symmetric")):
        mdl = M.build_model(RobotParams(), Shaker(240, 25))
        if what == "rows":
            mdl.rows[M.NB + 3, 0] = 0.1          # foot 0's z row touching leg 1's first mode
        elif what == "legs":
            mdl.mass[M.NB, M.NB + 3] = mdl.mass[M.NB + 3, M.NB] = 1e-9
        else:
            mdl.mass[0, 1] += 1e-12
        with pytest.raises(ValueError, match=message):
            mdl.pack(8.68e-6)


def test_unmanaged_views_write_through_and_leave_the_owner_alone():
    """The kernel's views without reference counting (labkit.sim._jit.unmanaged): reads and
    writes reach the caller's array; the array's own reference count is untouched; plain
    Python gets the array itself (the reference engine)."""
    import sys

    from numba import njit

    from labkit.sim._jit import unmanaged

    @njit
    def fill(a, b):
        u, v = unmanaged(a), unmanaged(b)
        for i in range(u.shape[0]):
            u[i] = 2.0 * i
        v[1, 2] = u[3] + 1.0
        return u.sum()

    a, b = np.zeros(5), np.zeros((2, 3))
    before = sys.getrefcount(a)
    assert fill(a, b) == 20.0
    assert a.tolist() == [0.0, 2.0, 4.0, 6.0, 8.0] and b[1, 2] == 7.0
    assert sys.getrefcount(a) == before
    assert unmanaged(a) is a


def test_pointer_reads_and_writes_the_array_in_compiled_code_and_is_the_array_in_python():
    """labkit.sim._jit.pointer: in compiled code a typed pointer to the array's data (the
    kernel's step functions take these), indexed like the array, writes reaching the caller's
    array; in plain Python (the reference engine) the array itself."""
    import sys

    from numba import njit

    from labkit.sim._jit import pointer

    @njit
    def bump(w, n):                     # compiled once for a pointer, once for an array
        for i in range(n):
            w[i + 1] += 2.0 * w[i]
        return w[n]

    @njit
    def through_pointer(a, ints):
        p, q = pointer(a), pointer(ints)
        return bump(p, 3) + q[2]

    a, ints = np.ones(5), np.arange(4, dtype=np.int64)
    before = sys.getrefcount(a)
    assert through_pointer(a, ints) == 15.0 + 2
    assert a.tolist() == [1.0, 3.0, 7.0, 15.0, 1.0]
    assert sys.getrefcount(a) == before
    assert pointer(a) is a
    b = np.ones(5)
    assert bump(b, 3) == 15.0 and b.tolist() == a.tolist()

    @njit
    def strided(a):
        return pointer(a)[1]

    from numba.core.errors import TypingError

    with pytest.raises(TypingError):        # element i of a strided array is not at data + i
        strided(np.arange(6.0)[::2])
