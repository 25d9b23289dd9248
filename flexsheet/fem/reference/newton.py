"""Newton's method of the geometrically nonlinear reference (pure): one load step's minimisation of the total
potential Π of a :class:`flexsheet.fem.reference.hyperelastic.HyperelasticModel` under a finger: the step from
the true tangent by PCG with a lagged Cholesky preconditioner or a fresh sparse Cholesky, else from the
projected tangent or the diagonally shifted true tangent, a backtracking line search with a trust region, and
the continuation of a call that ran out of iterations.

Minimise Π = ∫W dV + E_c; each step solves K_t δ = −r, first by PCG preconditioned with the last sparse
Cholesky factorisation (Newton–Krylov with a lagged preconditioner, :data:`PCG_RTOL`), else by a fresh sparse
Cholesky (CHOLMOD, :func:`cholesky_or_none`, which also tells whether K_t is positive definite; PCG's negative
curvature tells it too). Where K_t is not positive definite — far from equilibrium — the material tangent is
projected to its positive part (Teran et al. 2005); where Newton then crawls (:data:`CRAWL_ITERS` projected
steps that each cut the residual by less than 10 %: a limit point, where the projection stiffens the direction
the material snaps through), the true tangent plus the smallest diagonal shift that factorises takes over for
the rest of the load step's Newton solve (Nocedal & Wright alg. 3.3, :func:`shifted_step`; solver nh-6). Then
a backtracking line search keeps det F > 0 at every quadrature point and decreases Π (Armijo), with at most 1
mm of motion per iteration so no surface point can jump across the finger. Load stepping: depth in steps of
``step`` m with a linear-extrapolation predictor. Converged when ‖δ‖∞ < ``tol_u`` and the free residual is
below ``tol_r`` × the finger force scale.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from flexsheet.fem.reference.capsule_contact import Capsule

if TYPE_CHECKING:
    from flexsheet.fem.reference.hyperelastic import HyperelasticModel
from flexsheet.fem.sparse_factor import NotPositiveDefinite, factor

__all__ = ["PCG_RTOL", "PCG_MAXITER", "RESUME_MAX", "CRAWL_ITERS", "CRAWL_RATIO", "SHIFT_MIN", "SHIFT_MAX",
           "cholesky_or_none", "pcg", "shifted_step", "newton_minimise", "newton_resumed"]


def cholesky_or_none(K: sp.spmatrix):
    """Sparse Cholesky of the symmetric ``K`` (:func:`flexsheet.fem.sparse_factor.factor`, CHOLMOD): the
    factor (with ``.solve(b)``) when K is positive definite, None when it is not (CHOLMOD stops at the first
    non-positive pivot). On a loaded 3.4 mm-mesh tangent (16 596 DOF): 0.69 s and 9.9 ms per solve, against
    3.8 s and 22 ms for the simplicial QDLDL used before, and 4.1 s for SuperLU in symmetric mode."""
    try:
        return factor(K, "cholmod")
    except NotPositiveDefinite:
        return None


def pcg(A: sp.csr_matrix, b: np.ndarray, precond, rtol: float, maxiter: int) -> tuple[np.ndarray | None, int]:
    """Preconditioned conjugate gradients for A x = b (A symmetric; ``precond(r)`` applies M⁻¹). Returns
    (x, iterations), (None, −iterations) on negative curvature (pᵀAp ≤ 0: A is not positive definite), or
    (None, maxiter) when ‖r‖ ≤ ``rtol``·‖b‖ is not reached in ``maxiter`` iterations (Saad, *Iterative
    Methods for Sparse Linear Systems*, 2nd ed., alg. 9.1)."""
    x = np.zeros_like(b)
    if not np.any(b):
        return x, 0
    r = b.copy()
    z = precond(r)
    p = z.copy()
    rz = float(r @ z)
    stop = rtol * float(np.linalg.norm(b))
    for i in range(1, maxiter + 1):
        Ap = A @ p
        pAp = float(p @ Ap)
        if not pAp > 0:
            return None, -i
        a = rz / pAp
        x += a * p
        r -= a * Ap
        if float(np.linalg.norm(r)) <= stop:
            return x, i
        z = precond(r)
        rz_new = float(r @ z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return None, maxiter


#: inexact Newton (Newton–Krylov): the step solves K δ = −r by PCG to this relative residual,
#: preconditioned by the last Cholesky factorisation; a fresh factorisation only when PCG fails (Knoll
#: & Keyes, J. Comput. Phys. 193, 2004, "lagged" preconditioner). The step is then not exact, but the
#: residual r is, so the converged state is the same within the tolerances. A PCG iteration is two
#: triangular solves, ~1/70 of a CHOLMOD factorisation here, so PCG gives up after 20 (3.4 mm mesh,
#: 47.5 → 50 mm step, same 22 Newton iterations: 45 s of CPU at 20, 59 s at 60, 47 s never using PCG).
PCG_RTOL = 1e-4
PCG_MAXITER = 20


def _pcg_step(Kc: sp.csr_matrix, rf: np.ndarray, state: dict) -> tuple[np.ndarray | None, bool]:
    """Newton step δ (n,) from K δ = −r by PCG preconditioned with ``state["pc"]``, or None; and whether PCG
    met negative curvature (K is then not positive definite: no factorisation of it is tried)."""
    if state.get("pc_n") != Kc.shape[0]:          # a preconditioner from another model: not usable
        return None, False
    x, its = pcg(Kc, -rf, state["pc"].solve, PCG_RTOL, PCG_MAXITER)
    if x is not None and np.all(np.isfinite(x)) and float(rf @ x) < 0:
        state["pcg"] = state.get("pcg", 0) + 1
        return x, False
    return None, its < 0


def _tangent_step(Kc: sp.csr_matrix, rf: np.ndarray, state: dict, projected: bool) -> tuple[np.ndarray | None,
                                                                                            bool]:
    """(Newton step δ (n,) solving Kc δ = −rf, whether PCG gave it). PCG with the lagged factorisation
    (:func:`_pcg_step`) first, else a fresh factorisation that becomes the next preconditioner. On the true
    tangent (``projected`` False) returns (None, False) when Kc is not positive definite (PCG met negative
    curvature, or the Cholesky meets a non-positive pivot): the caller then takes the projected tangent. On
    the projected (semi-definite) tangent, rounding can leave it not quite positive definite: a diagonal
    shift, ×100 per try (at most 3 more factorisations; each ~1 s on 20k+ DOF); ``FloatingPointError`` if it
    is still not positive definite then (:func:`~flexsheet.fem.reference.path_solver.solve_path_capsule`
    halves the load step on it)."""
    if state.get("pc") is not None:         # lagged factorisation as preconditioner (one PCG solve)
        x, indefinite = _pcg_step(Kc, rf, state)
        if x is not None:
            return x, True
        if indefinite and not projected:
            return None, False
    state["factorisations"] = state.get("factorisations", 0) + 1
    fac = cholesky_or_none(Kc)
    if fac is None and not projected:
        return None, False
    dmax = float(np.abs(Kc.diagonal()).max())
    shift = 1e-4 * dmax
    while fac is None and shift <= 1.0 * dmax:
        state["factorisations"] += 1
        fac = cholesky_or_none(Kc + shift * sp.identity(Kc.shape[0], format="csr"))
        shift *= 100.0
    state["pc"], state["pc_n"] = fac, Kc.shape[0]
    if fac is None:
        raise FloatingPointError("the projected tangent stays singular after diagonal shifts")
    return -fac.solve(rf), False


#: a load step whose Newton call ran out of iterations (not failed: e.g. a snap-through still under way) is
#: continued from its last iterate up to this many more calls before the step is halved (nh-7). The price: a
#: step that is stuck for good spends (1 + RESUME_MAX)× the iterations of nh-6 before each halving
RESUME_MAX = 3

#: Newton "crawls" on the projected tangent when this many consecutive projected steps each left the residual
#: above CRAWL_RATIO of the one before (linear convergence: at a limit point the projection stiffens the soft
#: direction, 3.5 % per iteration at the azimuth-10° stall, docs/fem.md); from then on
#: :func:`newton_minimise` takes the true tangent with a diagonal shift instead (:func:`shifted_step`).
CRAWL_ITERS = 4
CRAWL_RATIO = 0.9
#: the diagonal shift's first and largest try, × max |diag K| (Nocedal & Wright, *Numerical Optimization*, 2nd
#: ed., alg. 3.3, ×10 per try); at the azimuth-10° stall 1e-6 sufficed and 23 of 47 iterations needed none
SHIFT_MIN, SHIFT_MAX = 1e-8, 1e-3


def shifted_step(Kc: sp.csr_matrix, rf: np.ndarray, state: dict) -> np.ndarray | None:
    """Newton step δ (n,) from (Kc + μ I) δ = −rf with the smallest μ ∈ {SHIFT_MIN, …, SHIFT_MAX}·max |diag
    Kc| (×10, starting a tenth below the last μ that worked) for which the sparse Cholesky succeeds (Nocedal &
    Wright alg. 3.3: a descent direction that keeps the true tangent's curvature, unlike the element-wise
    projection); None when even SHIFT_MAX does not make it positive definite (the caller takes the projected
    tangent). The factorisation becomes the PCG preconditioner; ``state["shifted"]`` counts these steps."""
    dmax = float(np.abs(Kc.diagonal()).max())
    mu = max(SHIFT_MIN, state.get("mu", SHIFT_MIN) / 10.0)
    eye = sp.identity(Kc.shape[0], format="csr")
    while mu <= SHIFT_MAX * (1 + 1e-9):
        state["factorisations"] = state.get("factorisations", 0) + 1
        fac = cholesky_or_none(Kc + (mu * dmax) * eye)
        if fac is not None:
            state["pc"], state["pc_n"], state["mu"] = fac, Kc.shape[0], mu
            state["shifted"] = state.get("shifted", 0) + 1
            return -fac.solve(rf)
        mu *= 10.0
    return None


def newton_minimise(model: HyperelasticModel, u: np.ndarray, caps: Capsule, k: float, iters: int,
                    tol_u: float,
            tol_r: float, log, state: dict | None = None, max_step: float = 0.001,
            shifted: bool = False) -> tuple[np.ndarray, int, bool]:
    """Minimise Π from ``u``; returns (u, iterations, converged). ``state`` (dict) carries between calls the
    last positive-definite factorisation (``"pc"``, the PCG preconditioner, and ``"pc_n"``, its size), the
    last diagonal shift that factorised (``"mu"``, × max |diag K|), and counters (``"projected"``: steps on
    the projected tangent, ``"shifted"``: steps on the shifted true tangent, ``"factorisations"``, ``"pcg"``:
    steps solved by PCG). Where the true tangent is not positive definite the step is on the projected
    tangent, until Newton crawls there (:data:`CRAWL_ITERS`): then, for the rest of this call, on the true
    tangent with a diagonal shift (:func:`shifted_step`), which crosses the limit points the projection cannot
    (``shifted=True``: from the first iteration, for a call that continues one that ended so;
    ``state["ended_shifted"]`` says how this one ended). Raises ``FloatingPointError`` when the line search
    fails or the projected tangent stays singular (:func:`_tangent_step`)."""
    state = {} if state is None else state
    free = model.free
    pi = model.energy(u, caps, k)
    if not math.isfinite(pi):
        raise FloatingPointError("start point has inverted elements")
    rn_prev = math.inf
    # crawl: consecutive projected iterations whose residual is above CRAWL_RATIO of the one
    # before (counted as the iteration starts, so the CRAWL_ITERS-th is still projected);
    # shifted: true tangent plus a shift from the next iteration on, for the rest of this call
    crawl = 0
    state["ended_shifted"] = shifted
    for it in range(1, iters + 1):
        r, K = model.residual_tangent(u, caps, k)
        rf = np.zeros(model.n)
        rf[free] = r[free]
        rn = float(np.linalg.norm(rf))
        Kc = model.constrained(K)
        delta, from_pcg = _tangent_step(Kc, rf, state, projected=False)
        if delta is None and shifted:
            delta, from_pcg = shifted_step(Kc, rf, state), False
        if delta is None:  # not positive definite (far from equilibrium): projected tangent, this step
            state["projected"] = state.get("projected", 0) + 1
            crawl = crawl + 1 if rn > CRAWL_RATIO * rn_prev else 0
            shifted = shifted or crawl >= CRAWL_ITERS   # (a projected step after a failed shift stays in it)
            state["ended_shifted"] = shifted
            _, K = model.residual_tangent(u, caps, k, project=True)
            delta, from_pcg = _tangent_step(model.constrained(K), rf, state, projected=True)
        else:
            crawl = 0
        if not np.all(np.isfinite(delta)):
            raise FloatingPointError(f"non-finite Newton step at iteration {it}")
        d3 = delta.reshape(-1, 3)
        slope = float(rf @ delta)
        # trust region: no point moves more than max_step per iteration, so no surface point can jump
        # across the finger between two energy evaluations (the penalty is only seen where it is sampled)
        alpha, ok = min(1.0, max_step / max(float(np.abs(delta).max()), 1e-300)), False
        for _ in range(30):
            cand = u + alpha * d3
            pi_c = model.energy(cand, caps, k)
            if math.isfinite(pi_c) and pi_c <= pi + 1e-4 * alpha * min(slope, 0.0) + 1e-12 * abs(pi):
                ok = True
                break
            alpha *= 0.5
        if not ok:
            if from_pcg:            # the inexact step was no use: factorise afresh next iteration
                state["pc"] = None
                continue
            raise FloatingPointError(f"line search failed at iteration {it}")
        u, pi = cand, pi_c
        step = alpha * float(np.abs(delta).max())
        if log:
            log(f"    newton {it}: |r|={rn:.3e} N, |du|={step * 1e3:.4f} mm, alpha={alpha:.3g}")
        if step < tol_u and rn < max(tol_r, 1e-12):
            return u, it, True
        # stagnation: a tiny step that the line search had to cut, or a residual (taken before this step) that
        # the previous step did not halve (round-off floor). A tiny *full* Newton step with a falling residual
        # is not stagnation: the stiff contact penalty makes the step tiny long before the residual is (3.4 mm
        # mesh at 50 mm: |du| < 1e-8 m at |r| = 1.4e-4 N, one iteration before quadratic convergence)
        if step < 0.01 * tol_u and (alpha < 1.0 or rn > 0.5 * rn_prev):
            if from_pcg:  # maybe only PCG's inexactness: one exact step before calling it stagnation
                state["pc"] = None
                rn_prev = rn
                continue
            return u, it, rn < 10 * tol_r
        rn_prev = rn
    return u, iters, False


def newton_resumed(m: HyperelasticModel, guess: np.ndarray, caps: Capsule, k: float, iters: int, tol_u: float,
                    tol_r: float, nstate: dict) -> tuple[np.ndarray | None, int, bool, np.ndarray | None]:
    """One load step's Newton solve from ``guess``; a call that runs out of ``iters`` iterations, not failed
    (e.g. a snap-through still under way), is continued from where it got to, in the mode it ended in, up to
    :data:`RESUME_MAX` more calls, rather than restarting a halved step from the last converged state (nh-7).
    Returns (u or None when the line search failed, iterations over all calls, converged, last iterate or
    None)."""
    its_total, u_last = 0, None
    try:
        u_new, its, conv = newton_minimise(m, guess, caps, k, iters, tol_u, tol_r, None, nstate)
        u_last = u_new
        for _ in range(RESUME_MAX):
            if conv or its < iters:
                break
            its_total += its
            u_new, its, conv = newton_minimise(m, u_new, caps, k, iters, tol_u, tol_r, None, nstate,
                                       shifted=nstate.get("ended_shifted", False))
            u_last = u_new
    except FloatingPointError:
        u_new, its, conv = None, iters, False
    return u_new, its_total + its, conv, u_last
