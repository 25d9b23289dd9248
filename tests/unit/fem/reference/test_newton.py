"""Newton's method of the reference (flexsheet/fem/reference/newton.py): PCG, the shifted true tangent past a
crawl, the lagged preconditioner, and a load step out of iterations continued (then halved past
RESUME_MAX)."""


import numpy as np
import pytest

from flexsheet.fem.reference import newton as N
from flexsheet.fem.reference import path_solver as PS


def test_pcg_solves_spd_and_reports_negative_curvature():
    """PCG reaches the requested relative residual on an SPD system (against numpy's dense solve) and returns
    (None, −i) on an indefinite one, (None, maxiter) when it runs out of iterations."""
    import scipy.sparse as sp

    rng = np.random.default_rng(3)
    B = rng.normal(size=(40, 40))
    A = sp.csr_matrix(B @ B.T + 40 * np.eye(40))
    b = rng.normal(size=40)
    x, its = N.pcg(A, b, lambda r: r / A.diagonal(), 1e-10, 200)
    assert x is not None and 0 < its <= 200
    assert np.linalg.norm(x - np.linalg.solve(A.toarray(), b)) < 1e-8 * np.linalg.norm(x)
    D = sp.diags(np.r_[np.ones(39), -1.0]).tocsr()
    e = np.zeros(40)
    e[-1] = 1.0
    x, its = N.pcg(D, e, lambda r: r, 1e-10, 50)
    assert x is None and its < 0
    x, its = N.pcg(A, b, lambda r: r, 1e-14, 2)
    assert x is None and its == 2


class _LimitPoint:
    """A 3-DOF stand-in for the model at a limit point: Π = (x0² − 1)² + x1²/2 + 10⁶ x2²/2 (the stiff x2 plays
    the contact penalty, which sets max |diag K|). From x0 = 0.05 the true tangent is indefinite (∂²Π/∂x0² < 0
    for
    |x0| < 0.577); the "projected" tangent replaces that entry by 115 (the projection stiffening the soft
    direction), so projected Newton crawls: δx0 ≈ 0.035 x0, the 3.5 % per iteration of the azimuth-10°
    stall."""

    n = 3
    free = np.arange(3)

    def energy(self, u, caps, k):
        x = u.ravel()
        return (x[0] ** 2 - 1.0) ** 2 + 0.5 * x[1] ** 2 + 0.5e6 * x[2] ** 2

    def residual_tangent(self, u, caps, k, need_K=True, project=False):
        import scipy.sparse as sp

        x = u.ravel()
        h00 = 12.0 * x[0] ** 2 - 4.0
        r = np.array([4.0 * x[0] ** 3 - 4.0 * x[0], x[1], 1e6 * x[2]])
        return r, sp.csr_matrix(np.diag([115.0 if (project and h00 < 0) else h00, 1.0, 1e6]))

    def constrained(self, K):
        return K


def test_newton_that_crawls_on_the_projected_tangent_switches_to_the_shifted_true_tangent(monkeypatch):
    """Past CRAWL_ITERS crawling projected steps Newton takes the true tangent plus the smallest diagonal
    shift that factorises (Nocedal & Wright alg. 3.3) and reaches the minimum x0 = 1 in under a quarter of the
    iterations of projected Newton alone; the shift is the least of the tried ones that makes the tangent
    positive definite."""
    u0 = np.array([[0.05, 0.3, 1e-4]])
    st: dict = {}
    u, its, conv = N.newton_minimise(_LimitPoint(), u0, None, 0.0, 60, 1e-10, 1e-9, None, st, max_step=10.0)
    assert conv and abs(u[0, 0] - 1.0) < 1e-9 and abs(u[0, 1]) < 1e-9, (u, its)
    # the first projected step has no residual before it, the second still cuts it (the first
    # solved x1 and x2); the CRAWL_ITERS after them crawl, and the next step is shifted
    assert st["projected"] == N.CRAWL_ITERS + 2 and st["shifted"] >= 1, st
    # x0 ≈ 0.05·1.035⁶: −∂²Π/∂x0² ≈ 3.9 needs μ·max diag = μ·10⁶ > 3.9, so μ = 1e-5 (1e-6 gives 1.0)
    assert st["mu"] == pytest.approx(1e-5)
    monkeypatch.setattr(N, "CRAWL_ITERS", 10 ** 6)   # projected Newton alone
    st2: dict = {}
    u2, its2, conv2 = N.newton_minimise(_LimitPoint(), u0, None, 0.0, 400, 1e-10, 1e-9, None, st2,
                                        max_step=10.0)
    assert conv2 and abs(u2[0, 0] - 1.0) < 1e-9 and "shifted" not in st2
    assert its < 0.25 * its2, (its, its2)
    # where no shift makes the tangent positive definite (here at the second
    # shifted step), that step is projected and the solve stays in shifted
    # mode: one more projected step, not a second crawl (the bug it had: 10)
    real, calls = N.shifted_step, []
    monkeypatch.setattr(N, "CRAWL_ITERS", 4)
    monkeypatch.setattr(N, "shifted_step",
                        lambda *a: calls.append(1) or (None if len(calls) == 2 else real(*a)))
    st3: dict = {}
    u3, its3, conv3 = N.newton_minimise(_LimitPoint(), u0, None, 0.0, 60, 1e-10, 1e-9, None, st3,
                                        max_step=10.0)
    assert conv3 and abs(u3[0, 0] - 1.0) < 1e-9 and st3["projected"] == N.CRAWL_ITERS + 3, st3
    # a call that continues one which ended shifted (nh-7) starts shifted: no projected step, no second crawl
    monkeypatch.setattr(N, "shifted_step", real)
    st4: dict = {}
    u4, its4, conv4 = N.newton_minimise(_LimitPoint(), u0, None, 0.0, 60, 1e-10, 1e-9, None, st4,
                                        max_step=10.0,
                                shifted=True)
    assert conv4 and abs(u4[0, 0] - 1.0) < 1e-9 and "projected" not in st4, st4
    assert its4 < its, (its4, its)
    assert st["ended_shifted"] and not st2["ended_shifted"]


def test_shifted_step_gives_up_beyond_the_largest_shift():
    """A tangent whose negative eigenvalue exceeds SHIFT_MAX · max |diag| is not shifted (None: the caller
    takes the projected tangent); one within it gets a descent direction."""
    import scipy.sparse as sp

    K = sp.csr_matrix(np.diag([-5.0, 1e3]))
    assert N.shifted_step(K, np.array([1.0, 1.0]), {}) is None
    K = sp.csr_matrix(np.diag([-0.5, 1e4]))          # needs μ·10⁴ > 0.5: μ = 1e-4
    st: dict = {}
    d = N.shifted_step(K, np.array([1.0, 1.0]), st)
    assert d is not None and float(np.array([1.0, 1.0]) @ d) < 0 and st["mu"] == pytest.approx(1e-4)
    K = sp.csr_matrix(np.diag([-0.5, 1e3]))  # only the largest shift, μ = SHIFT_MAX, makes it definite
    st = {}
    assert N.shifted_step(K, np.array([1.0, 1.0]), st) is not None and st["mu"] == pytest.approx(N.SHIFT_MAX)


def test_lagged_preconditioner_newton_reaches_the_same_states_with_fewer_factorisations(quarter, monkeypatch):
    """Newton–Krylov (PCG preconditioned by the last factorisation) against exact Newton (PCG disabled, one
    factorisation per iteration) on a 20 mm push: same states to 1e-9 m, forces to 1e-7 N, at least 3× fewer
    factorisations."""
    depths = [0.005, 0.01, 0.015, 0.02]
    counts = {}

    def run(label):
        real = N.newton_minimise

        def counting(model, u, caps, k, iters, tol_u, tol_r, log, state=None, max_step=0.001, shifted=False):
            out = real(model, u, caps, k, iters, tol_u, tol_r, log, state, max_step, shifted)
            counts[label] = dict(state)
            return out

        monkeypatch.setattr(N, "newton_minimise", counting)
        st = PS.solve_path(quarter, 0.0, depths, 0.008, step=0.005)
        monkeypatch.setattr(N, "newton_minimise", real)
        return st

    nk = run("nk")
    monkeypatch.setattr(N, "PCG_MAXITER", 0)
    exact = run("exact")
    assert all(s.converged for s in nk + exact)
    for a, b in zip(nk, exact, strict=True):
        assert np.abs(a.u - b.u).max() < 1e-9
        assert abs(a.force - b.force) < 1e-7
    assert counts["nk"].get("pcg", 0) > 0 and counts["exact"].get("pcg", 0) == 0
    assert 3 * counts["nk"]["factorisations"] <= counts["exact"]["factorisations"], counts


def _newton_calls(monkeypatch, budget):
    """Patch ``N.newton_minimise`` so that call i may take only ``budget(i)`` iterations (reporting the full
    ``iters`` when it runs out, as the real one does; a call that stagnates exactly at its budget reads as run
    out too); returns the list of calls (start u, finger centre, returned u, iterations, converged,
    shifted)."""
    real, calls = N.newton_minimise, []

    def limited(model, u, caps, k, iters, tol_u, tol_r, log, state=None, max_step=0.001, shifted=False):
        n = min(iters, budget(len(calls)))
        un, its, conv = real(model, u, caps, k, n, tol_u, tol_r, log, state, max_step, shifted)
        its = iters if (not conv and its == n) else its
        calls.append((u.copy(), caps.center.copy(), un.copy(), its, conv, shifted))
        return un, its, conv

    monkeypatch.setattr(N, "newton_minimise", limited)
    return calls


def test_a_load_step_out_of_iterations_is_continued_from_where_it_got_not_halved(quarter, monkeypatch):
    """nh-7: a Newton call that runs out of iterations (a snap-through still descending) is continued from its
    last iterate at the same depth; the load step is not halved and the path ends where the plain solve
    does."""
    plain = PS.solve_path(quarter, 0.0, [0.005, 0.01], 0.008, step=0.005, iters=30)
    # the second load step runs out at 2
    calls = _newton_calls(monkeypatch, lambda i: 2 if i == 1 else 10 ** 6)
    cont = PS.solve_path(quarter, 0.0, [0.005, 0.01], 0.008, step=0.005, iters=30)
    assert all(s.converged for s in plain + cont)
    assert len(calls) == 3, [(c[3], c[4]) for c in calls]         # step 1; step 2 runs out; its continuation
    assert not calls[1][4] and calls[1][3] == 30 and calls[2][4]
    assert np.array_equal(calls[2][0], calls[1][2])               # continued from the last iterate ...
    assert np.array_equal(calls[2][1], calls[1][1])  # ... at the same finger position (no halving)
    for a, b in zip(plain, cont, strict=True):
        assert np.abs(a.u - b.u).max() < 1e-7 and abs(a.force - b.force) < 1e-5
    assert cont[1].iterations == calls[1][3] + calls[2][3]        # both calls counted


def test_a_load_step_that_keeps_running_out_is_halved_after_resume_max_continuations(quarter, monkeypatch):
    """After RESUME_MAX continuations that also run out, the load step is halved as before (from the last
    converged state, not from the stuck iterate)."""
    plain = PS.solve_path(quarter, 0.0, [0.005, 0.01], 0.008, step=0.005, iters=30)
    calls = _newton_calls(monkeypatch, lambda i: 1 if 1 <= i <= 1 + N.RESUME_MAX else 10 ** 6)
    st = PS.solve_path(quarter, 0.0, [0.005, 0.01], 0.008, step=0.005, iters=30)
    assert all(s.converged for s in st)
    stuck = calls[1:2 + N.RESUME_MAX]                            # the first call and RESUME_MAX continuations
    assert all(not c[4] for c in stuck) and all(np.array_equal(c[1], calls[1][1]) for c in stuck)
    # from its last iterate
    assert all(np.array_equal(b[0], a[2]) for a, b in zip(stuck[:-1], stuck[1:], strict=True))
    halved = calls[2 + N.RESUME_MAX]
    assert np.linalg.norm(halved[1] - calls[0][1]) == pytest.approx(0.0025, abs=1e-12)   # 2.5 mm past 5 mm
    assert not np.array_equal(halved[0], stuck[-1][2])           # the halved step restarts from converged
    assert np.abs(st[1].u - plain[1].u).max() < 1e-7 and abs(st[1].force - plain[1].force) < 1e-5
