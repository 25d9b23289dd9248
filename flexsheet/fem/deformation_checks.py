"""Failure detection of a deformed linear-model mesh (pure): inverted tetrahedra (det F ≤ 0) and the largest
principal strain of P1 tets (:func:`element_checks`, and :class:`TetChecks` precomputed for the real-time
loop), and the fold test of rendered triangles (:func:`fold_operator`). Units SI; display frame."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["element_checks", "TetChecks", "fold_operator", "grad_ops"]


def fold_operator(rest: np.ndarray, faces: np.ndarray, normals: np.ndarray):
    """Fold test of triangles as one sparse product: returns (op (6F, 3S) csr, op @ rest.ravel() (6F,)) for
    ``faces`` (F, 3) over vertices ``rest`` (S, 3) m with rest normals ``normals`` (F, 3). For vertex
    positions x (S, 3) m flattened, rows c·F + f of op @ x give e2_c = (x2 − x0)_c and rows 3F + c·F + f give
    (n0 × e1)_c = Σ_b [n0]×_cb (x1 − x0)_b of face f, so Σ_c of their product is (e1 × e2)·n0, the turned
    normal's component along the rest normal (≤ 0: the face folded over). Both are linear in x."""
    F = len(faces)
    v0, v1, v2 = (faces[:, i].astype(np.int64) for i in range(3))
    n = np.asarray(normals, float)
    skew = np.zeros((F, 3, 3))                           # [n0]× : skew[f] @ e = n0 × e
    skew[:, 0, 1], skew[:, 0, 2] = -n[:, 2], n[:, 1]
    skew[:, 1, 0], skew[:, 1, 2] = n[:, 2], -n[:, 0]
    skew[:, 2, 0], skew[:, 2, 1] = -n[:, 1], n[:, 0]
    f = np.arange(F)
    rows, cols, vals = [], [], []
    for c in range(3):
        rows += [c * F + f, c * F + f]
        cols += [3 * v2 + c, 3 * v0 + c]
        vals += [np.ones(F), -np.ones(F)]
        for b in range(3):
            if b == c:
                continue
            rows += [3 * F + c * F + f, 3 * F + c * F + f]
            cols += [3 * v1 + b, 3 * v0 + b]
            vals += [skew[:, c, b], -skew[:, c, b]]
    op = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(6 * F, 3 * len(rest)))
    return op, op @ np.asarray(rest, float).reshape(-1)


def grad_ops(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-tet inverse edge matrices Dm⁻¹ (M, 3, 3) 1/m and volumes (M,) m³ of P1 tets ``tets`` (M, 4) over
    ``points`` (N, 3) m, for F = I + Du·Dm⁻¹."""
    p = points[tets]
    Dm = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)
    vol = np.linalg.det(Dm) / 6.0
    return np.linalg.inv(Dm), vol


def element_checks(points: np.ndarray, tets: np.ndarray, u: np.ndarray, Dm_inv: np.ndarray | None = None):
    """Deformation checks of P1 tets: returns (max principal |strain| (small-strain ε = sym ∇u), number of
    inverted tets (det F ≤ 0)). ``points`` (N, 3) m, ``tets`` (M, 4), ``u`` (N, 3) m node displacements."""
    if len(tets) == 0:
        return 0.0, 0
    if Dm_inv is None:
        Dm_inv, _ = grad_ops(points, tets)
    ue = u[tets]
    Du = np.stack([ue[:, 1] - ue[:, 0], ue[:, 2] - ue[:, 0], ue[:, 3] - ue[:, 0]], axis=2)
    H = Du @ Dm_inv
    F = H + np.eye(3)
    detF = (F[:, 0, 0] * (F[:, 1, 1] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 1])
            - F[:, 0, 1] * (F[:, 1, 0] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 0])
            + F[:, 0, 2] * (F[:, 1, 0] * F[:, 2, 1] - F[:, 1, 1] * F[:, 2, 0]))
    inv = int(np.count_nonzero(detF <= 0.0))
    return _max_abs_sym_eig(0.5 * (H + np.transpose(H, (0, 2, 1)))), inv


class TetChecks:
    """:func:`element_checks` of a fixed set of P1 tets, precomputed for the real-time loop (same results to
    rounding).

    ``points`` (N, 3) m, ``tets`` (M, 4) indices into them. The displacement gradient of every tet,
    H = ∇u = Σ_a u_a ⊗ ∇N_a, is one sparse product ``B @ u.ravel()`` (B (9M, 3N), 4 entries a row, stored
    component-major: row (3i + j)·M + m holds H_ij of tet m, so each H_ij is a contiguous (M,) array).
    Exact bounds then skip most of the eigenvalue work: the largest |principal strain| of a tet lies in
    [‖ε‖_F/√3, ‖ε‖_F] (ε = sym H), so only tets with ‖ε‖_F ≥ max‖ε‖_F/√3, and then only those with ‖ε‖_F ≥
    the exact |λ|max of the tet with the largest ‖ε‖_F, can hold the maximum; they get LAPACK's symmetric
    eigenvalues (``numpy.linalg.eigvalsh``). Likewise det(I + H) ≤ 0 needs ‖H‖_2 ≥ 1, so only tets with
    ‖H‖_F ≥ 1 get the determinant. ``centroids`` (M, 3) m.
    """

    _T = np.array([0, 3, 6, 1, 4, 7, 2, 5, 8])          # row 3i + j -> row 3j + i (transpose)

    def __init__(self, points: np.ndarray, tets: np.ndarray):
        points = np.asarray(points, float)
        tets = np.asarray(tets, np.int64).reshape(-1, 4)
        M, N = len(tets), len(points)
        self.n_points, self.n_tets = N, M
        Dm_inv = grad_ops(points, tets)[0] if M else np.zeros((0, 3, 3))
        g = np.concatenate([-Dm_inv.sum(axis=1, keepdims=True), Dm_inv], axis=1)      # (M, 4, 3) ∇N_a
        i, j, a = np.meshgrid(np.arange(3), np.arange(3), np.arange(4), indexing="ij")  # (3, 3, 4)
        rows = ((3 * i + j)[..., None] * M + np.arange(M)).ravel()                     # row (3i+j)·M + m
        cols = (3 * tets.T[a] + i[..., None]).ravel()                                  # u_a[i] of tet m
        vals = np.transpose(g, (1, 2, 0))[a, j].ravel()                                # ∂N_a/∂x_j of tet m
        self.B = sp.csr_matrix((vals, (rows, cols)), shape=(9 * M, 3 * N))
        self.B.sum_duplicates()
        self.centroids = points[tets].mean(axis=1) if M else np.zeros((0, 3))
        self._c2 = np.einsum("ij,ij->i", self.centroids, self.centroids)

    def gradients(self, u: np.ndarray) -> np.ndarray:
        """Displacement gradients H (3, 3, M), H[i, j] = ∂u_i/∂x_j per tet, of node displacements ``u`` (N,
        3)."""
        return (self.B @ np.ascontiguousarray(u, float).reshape(-1)).reshape(3, 3, self.n_tets)

    def near(self, point: np.ndarray, radius: float) -> np.ndarray:
        """(M,) bool: tets whose centroid lies within ``radius`` m of ``point`` (3,) m."""
        p = np.asarray(point, float)
        return self._c2 - 2.0 * (self.centroids @ p) <= radius * radius - float(p @ p)

    def __call__(self, u: np.ndarray, select: np.ndarray | None = None) -> tuple[float, int]:
        """(max principal |strain|, number of inverted tets) as :func:`element_checks` over the tets where
        ``select`` (M,) bool is True (None: all). ``u`` (N, 3) m."""
        if self.n_tets == 0 or (select is not None and not select.any()):
            return 0.0, 0
        H = (self.B @ np.ascontiguousarray(u, float).reshape(-1)).reshape(9, self.n_tets)
        fro_h = np.einsum("cm,cm->m", H, H)                                           # ‖H‖_F²
        fro_e = 0.5 * (fro_h + np.einsum("cm,cm->m", H, H[self._T]))                  # ‖sym H‖_F²
        if select is not None:
            fro_e[~select] = 0.0
            fro_h[~select] = 0.0
        top = float(fro_e.max())
        strain = 0.0
        if top > 0.0:
            k = np.flatnonzero(fro_e >= top * (1.0 / 3.0) * (1.0 - 1e-9))
            Hk = H[:, k]
            E = (0.5 * (Hk + Hk[self._T])).T.reshape(-1, 3, 3)
            if len(k) > 8:          # sharper lower bound: the exact |λ|max of the tet with the largest ‖ε‖_F
                fk = fro_e[k]
                lam0 = float(np.abs(np.linalg.eigvalsh(E[int(np.argmax(fk))])).max())
                E = E[fk >= lam0 * lam0 * (1.0 - 1e-9)]
            strain = float(np.abs(np.linalg.eigvalsh(E)).max())
        k = np.flatnonzero(fro_h >= 1.0 - 1e-9)
        if len(k) == 0:
            return strain, 0
        F = H[:, k]
        F[[0, 4, 8]] += 1.0
        detF = (F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6])
                + F[2] * (F[3] * F[7] - F[4] * F[6]))
        return strain, int(np.count_nonzero(detF <= 0.0))


def _max_abs_sym_eig(e: np.ndarray) -> float:
    """Largest |eigenvalue| over a stack (M, 3, 3) of symmetric matrices, closed form (Smith, CACM 1961)."""
    q = (e[:, 0, 0] + e[:, 1, 1] + e[:, 2, 2]) / 3.0
    p1 = e[:, 0, 1] ** 2 + e[:, 0, 2] ** 2 + e[:, 1, 2] ** 2
    d0, d1, d2 = e[:, 0, 0] - q, e[:, 1, 1] - q, e[:, 2, 2] - q
    p = np.sqrt((d0 * d0 + d1 * d1 + d2 * d2 + 2 * p1) / 6.0)
    ps = np.where(p > 0, p, 1.0)
    b00, b11, b22 = d0 / ps, d1 / ps, d2 / ps
    b01, b02, b12 = e[:, 0, 1] / ps, e[:, 0, 2] / ps, e[:, 1, 2] / ps
    r = 0.5 * (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02))
    phi = np.arccos(np.clip(r, -1.0, 1.0)) / 3.0
    l1 = q + 2 * p * np.cos(phi)
    l3 = q + 2 * p * np.cos(phi + 2 * np.pi / 3)
    return float(max(np.max(np.abs(l1)), np.max(np.abs(l3))))
