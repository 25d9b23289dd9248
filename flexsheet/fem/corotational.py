"""Corotational (stiffness-warping) FEM of the cylinder under displacement-driven fingertip contact (pure):
the geometrically nonlinear mode of the linear P1 model (:func:`solve_corotational`), with lagged element
rotations from the polar decomposition of the deformation gradient (Müller et al., SCA 2002; Müller & Gross,
GI 2004; SOFA TetrahedronFEMForceField method="polar"), solved quasi-statically. Units SI; display frame."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from flexsheet.fem.contact import ContactFinger
from flexsheet.fem.deformation_checks import grad_ops
from flexsheet.fem.material import Material
from flexsheet.fem.solver import FemModel, Solution, contact_dofs
from flexsheet.fem.sparse_factor import factor

__all__ = ["solve_corotational"]


def _element_stiffness(points, tets, material: Material):
    """P1 element stiffness matrices (M, 12, 12), DOF order (node, component). Zienkiewicz, FEM vol. 1 §6."""
    Dm_inv, vol = grad_ops(points, tets)
    # gradients of barycentric functions: rows of Dm_inv give grad of N1..N3, N0 = -sum
    g = np.concatenate([-Dm_inv.sum(axis=1, keepdims=True), Dm_inv], axis=1)   # (M, 4, 3)
    lam, mu = material.lame
    M = len(tets)
    B = np.zeros((M, 6, 12))
    for a in range(4):
        gx, gy, gz = g[:, a, 0], g[:, a, 1], g[:, a, 2]
        c = 3 * a
        B[:, 0, c], B[:, 1, c + 1], B[:, 2, c + 2] = gx, gy, gz
        B[:, 3, c], B[:, 3, c + 1] = gy, gx
        B[:, 4, c + 1], B[:, 4, c + 2] = gz, gy
        B[:, 5, c], B[:, 5, c + 2] = gz, gx
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[np.arange(3), np.arange(3)] += 2 * mu
    D[3:, 3:] = np.eye(3) * mu
    return np.einsum("mki,kl,mlj->mij", B, D, B) * vol[:, None, None], Dm_inv


def _polar_rotations(F: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(F)
    R = U @ Vt
    neg = np.linalg.det(R) < 0
    if np.any(neg):
        U[neg, :, 2] *= -1
        R[neg] = U[neg] @ Vt[neg]
    return R


def solve_corotational(model: FemModel, finger: ContactFinger, iters: int = 30, tol: float = 1e-6,
                       u0: np.ndarray | None = None):
    """Corotational (polar) FEM, P1 only, quasi-static, contact as :func:`solve_full`.

    Internal force f_e = R_e K_e (R_eᵀ x_e − X_e) with R_e from the polar decomposition of F_e; Newton-like
    iterations with the warped stiffness Σ R_e K_e R_eᵀ (Müller & Gross 2004) until the largest displacement
    increment is below ``tol``·(depth + 1 mm). ``u0`` (N, 3) m optional warm start. Returns
    (:class:`Solution` with ``u`` (N, 3), iterations used, converged flag). Raises ``ValueError`` for P2.
    """
    if model.order != 1:
        raise ValueError(f"corotational solver needs order 1, got {model.order}")
    mesh = model.mesh
    X = model.points
    tets = mesh.tets
    Ke, Dm_inv = _element_stiffness(X, tets, model.material)
    M = len(tets)
    edofs = model.dofs[tets].reshape(M, 12)
    rows = np.repeat(edofs, 12, axis=1).ravel()
    cols = np.tile(edofs, (1, 12)).ravel()
    n = model.n_dofs
    cpts, ubar = contact_dofs(model, finger)
    cd = model.dofs[cpts].ravel()
    D = np.union1d(model.fixed_dofs, cd)
    mask = np.ones(n, bool)
    mask[D] = False
    interior = np.flatnonzero(mask)
    x = np.zeros(n)
    if u0 is not None:
        x[model.dofs] = u0
    x[model.fixed_dofs] = 0.0
    x[cd] = ubar.ravel()
    Xe = X[tets].reshape(M, 12)
    scale = tol * (finger.depth + 1e-3)
    converged, it = False, 0
    for it in range(1, iters + 1):  # noqa: B007 - it is returned
        ue = x[edofs].reshape(M, 4, 3)
        Du = np.stack([ue[:, 1] - ue[:, 0], ue[:, 2] - ue[:, 0], ue[:, 3] - ue[:, 0]], axis=2)
        F = np.eye(3) + Du @ Dm_inv
        R = _polar_rotations(F)
        Rb = np.zeros((M, 12, 12))
        for a in range(4):
            Rb[:, 3 * a:3 * a + 3, 3 * a:3 * a + 3] = R
        RK = Rb @ Ke
        KR = RK @ np.transpose(Rb, (0, 2, 1))
        xe = Xe + x[edofs]
        local = np.einsum("mji,mj->mi", Rb, xe) - Xe          # R^T x - X
        fe = np.einsum("mij,mj->mi", RK, local)
        fint = np.bincount(edofs.ravel(), weights=fe.ravel(), minlength=n)
        Kt = sp.csr_matrix((KR.ravel(), (rows, cols)), shape=(n, n))
        if len(interior) == 0:
            converged = True
            break
        dx = factor(Kt[interior][:, interior]).solve(-fint[interior])
        x[interior] += dx
        if np.max(np.abs(dx)) < scale:
            converged = True
            break
    # reaction: recompute internal force at the final state
    ue = x[edofs].reshape(M, 4, 3)
    Du = np.stack([ue[:, 1] - ue[:, 0], ue[:, 2] - ue[:, 0], ue[:, 3] - ue[:, 0]], axis=2)
    R = _polar_rotations(np.eye(3) + Du @ Dm_inv)
    Rb = np.zeros((M, 12, 12))
    for a in range(4):
        Rb[:, 3 * a:3 * a + 3, 3 * a:3 * a + 3] = R
    local = np.einsum("mji,mj->mi", Rb, Xe + x[edofs]) - Xe
    fe = np.einsum("mij,mjk,mk->mi", Rb, Ke, local)
    fint = np.bincount(edofs.ravel(), weights=fe.ravel(), minlength=n)
    fvec = fint[model.dofs[cpts]].sum(axis=0) if len(cpts) else np.zeros(3)
    force = float(fvec @ finger.direction)
    return Solution(x[model.dofs], max(force, 0.0), fvec, 0.0, len(cpts), "corotational"), it, converged
