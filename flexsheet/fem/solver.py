"""Linear (P1/P2) and corotational elasticity of the cylinder under displacement-driven fingertip contact
(pure).

Three solvers share one :class:`FemModel` (stiffness assembled with scikit-fem, ``linear_elasticity``):

* :func:`solve_full` — the baseline: sparse direct solve (SuperLU) of the whole mesh with the support and the
  contact points as Dirichlet DOFs, refactored every update.
* :class:`CapacitanceSolver` — the real-time path (James & Pai, "A unified treatment of elastostatic contact
  simulation for real time haptics", Haptics-e 2001; condensation as in Bro-Nielsen & Cotin, CGF 1996).
  Precompute once the Green's-function columns G = K_FF⁻¹ E_C for the candidate contact DOFs C, keeping only
  the rows the outputs need (surface + a strain-monitor zone). Per update: G_aa f = ū_a (m × m dense Cholesky,
  m = active contact DOFs), u_out = G_out,a f, and the reaction on the finger is −Σ f.
* :func:`flexsheet.fem.corotational.solve_corotational` — geometrically nonlinear mode: corotational
  (stiffness-warping) FEM with lagged element rotations (its own module).

Failure detection (inverted elements, the largest principal strain, folded faces):
:mod:`flexsheet.fem.deformation_checks`; the sparse factorisation: :mod:`flexsheet.fem.sparse_factor`.
Units SI; displacements m, forces N, stiffness N/m; display frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.linalg.lapack import dpotrf as _dpotrf
from scipy.linalg.lapack import dpotrs as _dpotrs
from scipy.linalg.lapack import spotrf as _spotrf
from scipy.linalg.lapack import spotrs as _spotrs

from flexsheet.fem.contact import ContactFinger, imposed_displacement
from flexsheet.fem.deformation_checks import grad_ops
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import TetMesh
from flexsheet.fem.sparse_factor import factor

__all__ = ["FemModel", "Solution", "solve_full", "CapacitanceSolver", "OutsideCandidates", "contact_dofs"]


class OutsideCandidates(ValueError):
    """The finger touches surface points outside the precomputed candidate set (use :func:`solve_full`)."""


class FemModel:
    """Linear elasticity on a :class:`TetMesh` with P1 (``order=1``) or P2 (``order=2``) vector elements.

    Attributes: ``K`` (n, n) csr stiffness (N/m); ``dofs`` (P, 3) int DOF indices of each *DOF point* (mesh
    nodes, then edge midpoints for P2); ``points`` (P, 3) m their positions; ``boundary`` (P,) bool;
    ``fixed`` (P,) bool support points (boundary with x ≤ x_O, or ``support``'s); ``free`` (nf,) free DOF
    indices.

    Any object: ``support`` optional callable(points (P, 3) m) → (P,) bool that marks which
    *boundary* DOF points are held (e.g. :meth:`flexsheet.model.scenes.Scene.fixed_mask`; default the
    cylinder's back half, x ≤ x_O); ``E_elem``/``nu_elem`` optional per-element Young's modulus (M,) Pa and
    Poisson's ratio (M,) (e.g. :meth:`~flexsheet.model.scenes.Scene.material_at` at the element centroids:
    stiff inclusions), piecewise constant; ``material`` is then only the nominal one. Without them the
    assembly is exactly the scalar-material one. Raises ``ValueError`` naming the argument on a wrong shape,
    a non-finite or out-of-range value.
    Source: scikit-fem ``ElementVector(ElementTetP1/P2)``, ``linear_elasticity(λ, μ)`` (per element: the same
    weak form 2μ ε(u):ε(v) + λ div u div v with λ, μ as ``ElementTetP0`` fields).
    """

    def __init__(self, mesh: TetMesh, material: Material, order: int = 1, support=None,
                 E_elem: np.ndarray | None = None, nu_elem: np.ndarray | None = None):
        from skfem import Basis, ElementTetP1, ElementTetP2, ElementVector, MeshTet, asm
        from skfem.models.elasticity import linear_elasticity

        if order not in (1, 2):
            raise ValueError(f"order must be 1 or 2, got {order!r}")
        self.mesh, self.material, self.order = mesh, material, order
        self.skmesh = MeshTet(np.ascontiguousarray(mesh.points.T), np.ascontiguousarray(mesh.tets.T))
        elem = ElementVector(ElementTetP1() if order == 1 else ElementTetP2())
        self.basis = Basis(self.skmesh, elem)
        if E_elem is None and nu_elem is None:
            lam, mu = material.lame
            self.K = asm(linear_elasticity(lam, mu), self.basis).tocsr()
            self.E_elem = self.nu_elem = None
        else:
            self.E_elem, self.nu_elem = _element_material(len(mesh.tets), material, E_elem, nu_elem)
            self.K = _assemble_varying(self.basis, self.E_elem, self.nu_elem)
        nd = self.basis.nodal_dofs.T
        if order == 1:
            self.dofs = np.ascontiguousarray(nd)
            self.points = self.skmesh.p.T.copy()
        else:
            self.dofs = np.ascontiguousarray(np.vstack([nd, self.basis.edge_dofs.T]))
            e = self.skmesh.edges
            self.points = np.vstack([self.skmesh.p.T,
                                     0.5 * (self.skmesh.p[:, e[0]] + self.skmesh.p[:, e[1]]).T])
        bd = np.zeros(self.K.shape[0], bool)
        bd[self.basis.get_dofs().flatten()] = True
        self.boundary = bd[self.dofs[:, 0]]
        if support is None:
            self.fixed = self.boundary & (self.points[:, 0] <= mesh.center[0] + 1e-9)
        else:
            held = np.asarray(support(self.points), dtype=bool)
            if held.shape != (len(self.points),):
                raise ValueError(f"support must return a ({len(self.points)},) bool mask, got shape "
                                 f"{held.shape}")
            self.fixed = self.boundary & held
            if not self.fixed.any():
                raise ValueError("support holds no boundary point: the object would float (singular "
                                 "stiffness)")
        fixed_dofs = self.dofs[self.fixed].ravel()
        mask = np.ones(self.K.shape[0], bool)
        mask[fixed_dofs] = False
        self.free = np.flatnonzero(mask)
        self.fixed_dofs = np.sort(fixed_dofs)

    @property
    def n_dofs(self) -> int:
        """Total number of DOFs."""
        return self.K.shape[0]

    def probe(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Displacement field ``u`` (n,) evaluated at points ``x`` (k, 3) m → (k, 3) m.

        Each point is located in the tet that contains it, or — for points just outside the faceted boundary
        (curved surface of a coarser mesh) — the nearby tet it is least outside of, and the element
        polynomial is evaluated there (a tiny extrapolation). Follows scikit-fem ``CellBasis.probes``."""
        from scipy.sparse import coo_matrix
        from scipy.spatial import cKDTree

        x = np.asarray(x, float)
        p, t = self.mesh.points, self.mesh.tets
        if not hasattr(self, "_tree"):
            self._tree = cKDTree(p[t].mean(axis=1))
            self._Dinv, _ = grad_ops(p, t)
        k = min(24, len(t))
        _, cand = self._tree.query(x, k=k)
        cand = np.atleast_2d(cand)
        rel = x[:, None, :] - p[t[cand, 0]]                                   # (q, k, 3)
        lam = np.einsum("qkij,qkj->qki", self._Dinv[cand], rel)               # barycentric 1..3
        bary = np.concatenate([1 - lam.sum(axis=2, keepdims=True), lam], axis=2)
        best = np.argmax(bary.min(axis=2), axis=1)
        cells = cand[np.arange(len(x)), best]
        xx = np.ascontiguousarray(x.T)
        pts = self.basis.mapping.invF(xx[:, :, np.newaxis], tind=cells)
        phis = np.array([self.basis.elem.gbasis(self.basis.mapping, pts, j, tind=cells)[0]
                         for j in range(self.basis.Nbfun)]).flatten()
        q = len(x)
        rows = np.tile(np.arange(3 * q, dtype=np.int64), self.basis.Nbfun)
        cols = self.basis.element_dofs[:, np.tile(cells, 3)].flatten()
        P = coo_matrix((phis, (rows, cols)), shape=(3 * q, self.basis.N)).tocsr()
        return (P @ u).reshape(3, q).T


def _element_material(n_tets: int, material: Material, E_elem, nu_elem) -> tuple[np.ndarray, np.ndarray]:
    """Per-element (E (M,) Pa, ν (M,)); a missing one is the nominal ``material``'s. ``ValueError`` naming
    it."""
    out = []
    for name, v, default in (("E_elem", E_elem, material.E), ("nu_elem", nu_elem, material.nu)):
        a = np.full(n_tets, float(default)) if v is None else np.asarray(v, dtype=float)
        if a.shape != (n_tets,):
            raise ValueError(f"{name} must have shape ({n_tets},) (one value per tetrahedron), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite, got {a[~np.isfinite(a)][:3].tolist()}")
        out.append(a)
    E, nu = out
    if E.min() <= 0.0:
        raise ValueError(f"E_elem must be > 0 Pa, got {float(E.min())!r}")
    if nu.min() < 0.0 or nu.max() >= 0.5:
        raise ValueError(f"nu_elem must be in [0, 0.5), got range [{float(nu.min())!r}, {float(nu.max())!r}]")
    return E, nu


def _assemble_varying(basis, E: np.ndarray, nu: np.ndarray) -> sp.csr_matrix:
    """Stiffness (n, n) csr of 2μ ε(u):ε(v) + λ div u div v with λ, μ constant per element (scikit-fem)."""
    from skfem import BilinearForm, ElementTetP0, asm
    from skfem.helpers import ddot, div, sym_grad

    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    b0 = basis.with_element(ElementTetP0())

    @BilinearForm
    def form(u, v, w):
        return 2.0 * w.mu * ddot(sym_grad(u), sym_grad(v)) + w.lam * div(u) * div(v)

    return asm(form, basis, lam=b0.interpolate(lam), mu=b0.interpolate(mu)).tocsr()


@dataclass
class Solution:
    """Result of one update.

    ``u`` (P', 3) m displacements at the solver's output points (all DOF points for the full solver, the
    output points for the capacitance solver); ``force`` N magnitude of the reaction along p̂ (≥ 0 in
    compression); ``force_vec`` (3,) N total force the finger applies to the object; ``stiffness`` N/m,
    dF/dd with the contact set held; ``n_contact`` number of contact points; ``method`` name."""

    u: np.ndarray
    force: float
    force_vec: np.ndarray
    stiffness: float
    n_contact: int
    method: str
    u_full: np.ndarray | None = None     #: (n_dofs,) DOF vector (full solver only), for probing


def contact_dofs(model: FemModel, finger: ContactFinger, candidates: np.ndarray | None = None):
    """(contact points (c,) int indices of the free surface DOF points inside ``finger``, their imposed
    displacements (c, 3) m): the Dirichlet contact of :func:`solve_full` and the corotational solve."""
    pts_idx = np.flatnonzero(model.boundary & ~model.fixed)
    inside, ubar = imposed_displacement(model.points[pts_idx], finger)
    return pts_idx[inside], ubar[inside]


def solve_full(model: FemModel, finger: ContactFinger) -> Solution:
    """Baseline: sparse direct solve with Dirichlet DOFs = support ∪ contact points; refactors every call.

    Returns a :class:`Solution` whose ``u`` covers every DOF point (P, 3). Stiffness is dF/dd with the
    contact set held (a second right-hand side on the same factorisation)."""
    cpts, ubar = contact_dofs(model, finger)
    n = model.n_dofs
    x = np.zeros(n)
    dx = np.zeros(n)
    cd = model.dofs[cpts]
    x[cd.ravel()] = ubar.ravel()
    dx[cd.ravel()] = np.tile(finger.direction, len(cpts))
    D = np.union1d(model.fixed_dofs, cd.ravel())
    mask = np.ones(n, bool)
    mask[D] = False
    interior = np.flatnonzero(mask)
    K = model.K
    if len(cpts):
        lu = factor(K[interior][:, interior])
        KID = K[interior][:, D]
        sol = lu.solve(-np.column_stack([KID @ x[D], KID @ dx[D]]))
        x[interior] = sol[:, 0]
        dx[interior] = sol[:, 1]
    r = K @ x
    dr = K @ dx
    fvec = r[cd].sum(axis=0) if len(cpts) else np.zeros(3)
    force = float(fvec @ finger.direction)
    stiff = float(dr[cd].sum(axis=0) @ finger.direction) if len(cpts) else 0.0
    return Solution(x[model.dofs], max(force, 0.0), fvec, max(stiff, 0.0), len(cpts), "sparse", x)


class CapacitanceSolver:
    """Real-time linear contact by the capacitance matrix (James & Pai 2001) over precomputed Green's
    functions.

    ``candidates`` (P,) bool: surface DOF points the finger may touch (must be free, not support);
    ``outputs`` (P,) bool: DOF points whose displacement each update returns (e.g. free surface + monitor
    zone). Precompute: one sparse factorisation of K_FF and |C| = 3·#candidates solves. Memory
    8·|C|·(|C| + 3·#outputs) bytes. Raises ``ValueError`` if a candidate is a support point.
    """

    def __init__(self, model: FemModel, candidates: np.ndarray, outputs: np.ndarray, block: int = 256):
        if np.any(candidates & model.fixed):
            raise ValueError("candidates must not include support (fixed) points")
        self.model = model
        self.cand_pts = np.flatnonzero(candidates)
        self.out_pts = np.flatnonzero(outputs)
        pos_in_free = np.full(model.n_dofs, -1, np.int64)
        pos_in_free[model.free] = np.arange(len(model.free))
        cdofs = model.dofs[self.cand_pts].ravel()
        odofs = model.dofs[self.out_pts].ravel()
        out_fixed = pos_in_free[odofs] < 0
        Kff = model.K[model.free][:, model.free]
        lu = factor(Kff)
        nc = len(cdofs)
        ci = pos_in_free[cdofs]
        oi = np.where(out_fixed, 0, pos_in_free[odofs])
        self.G_cc = np.empty((nc, nc))
        self.G_co = np.empty((nc, len(odofs)))        # row j: output response to a unit force on cdof j
        for s in range(0, nc, block):
            cols = np.arange(s, min(nc, s + block))
            E = np.zeros((len(model.free), len(cols)))
            E[ci[cols], np.arange(len(cols))] = 1.0
            Z = lu.solve(E)
            self.G_cc[:, cols] = Z[ci]
            zo = Z[oi].T
            zo[:, out_fixed] = 0.0
            self.G_co[cols] = zo
        self.G_cc = 0.5 * (self.G_cc + self.G_cc.T)
        self._finish()

    def _finish(self) -> None:
        model = self.model
        self._cand_points = model.points[self.cand_pts]
        free_surface = np.flatnonzero(model.boundary & ~model.fixed)
        self._noncand_points = model.points[np.setdiff1d(free_surface, self.cand_pts)]
        self._prepare()

    def _prepare(self) -> None:
        """Per-update helpers: every free surface point in one array (candidates first: one contact test per
        update) and ``G_cc`` flattened for a one-index gather of the active block."""
        self._all_points = np.ascontiguousarray(
            np.vstack([self._cand_points, self._noncand_points.reshape(-1, 3)]))
        self._G_flat = np.ascontiguousarray(self.G_cc).reshape(-1)

    def arrays(self) -> dict:
        """The precomputed state as plain arrays (see :meth:`from_arrays`)."""
        return {"G_cc": self.G_cc, "G_co": self.G_co, "cand_pts": self.cand_pts, "out_pts": self.out_pts,
                "cand_points": self._cand_points, "noncand_points": self._noncand_points}

    @classmethod
    def from_arrays(cls, z, dtype=np.float64) -> CapacitanceSolver:
        """Rebuild a solver from :meth:`arrays` (no model needed); raises ``ValueError`` on inconsistent
        shapes or a ``dtype`` other than float64/float32. ``dtype`` float32 keeps ``G_cc`` and ``G_co`` in
        single precision and runs the per-update Cholesky in it (LAPACK ``spotrf``/``spotrs``): half the
        memory and memory traffic. The capacitance blocks are well conditioned (cond(G_aa) ≈ 200 on the
        shipped scenes), so the displacements move by < 0.05 µm at a 50 mm push
        (tests/unit/fem/test_scene_model.py checks < 1 µm against a float64 dense solve); force and stiffness
        are summed in float64."""
        dtype = np.dtype(dtype)
        if dtype not in (np.dtype(np.float64), np.dtype(np.float32)):
            raise ValueError(f"dtype must be float64 or float32, got {dtype}")
        self = cls.__new__(cls)
        self.model = None
        self.cand_pts, self.out_pts = np.asarray(z["cand_pts"]), np.asarray(z["out_pts"])
        self.G_cc = np.ascontiguousarray(z["G_cc"], dtype=dtype)
        self.G_co = np.ascontiguousarray(z["G_co"], dtype=dtype)
        self._cand_points, self._noncand_points = np.asarray(z["cand_points"]), np.asarray(
            z["noncand_points"])
        nc = 3 * len(self.cand_pts)
        if (self.G_cc.shape != (nc, nc) or self.G_co.shape != (nc, 3 * len(self.out_pts))
                or self._cand_points.shape != (len(self.cand_pts), 3)):
            raise ValueError(f"precomputed matrices have inconsistent shapes {self.G_cc.shape}, "
                             f"{self.G_co.shape}")
        self._prepare()
        return self

    @property
    def nbytes(self) -> int:
        """Bytes held by the precomputed matrices."""
        return self.G_cc.nbytes + self.G_co.nbytes

    def solve(self, finger: ContactFinger, outputs: bool = True) -> Solution:
        """One update: returns a :class:`Solution` with ``u`` (#outputs, 3) m at the output points
        (``outputs`` False: ``u`` is (0, 3), for a caller that needs only the force and dF/dd, which skips the
        largest product).

        Raises :class:`OutsideCandidates` when a non-candidate surface point is inside the finger, and
        ``numpy.linalg.LinAlgError`` if the active block is not positive definite (a corrupt precompute).
        The active block G_aa is gathered with one flat index, factored in place by LAPACK ``?potrf`` and
        solved for both right-hand sides (ū_a and the unit push, for dF/dd) by ``?potrs`` (d: float64, s: a
        float32 solver, see :meth:`from_arrays`): the arithmetic of ``scipy.linalg.cho_factor``/``cho_solve``
        without their copies and checks."""
        inside, ubar = imposed_displacement(self._all_points, finger)
        ncp = len(self._cand_points)
        if inside[ncp:].any():
            raise OutsideCandidates("finger touches surface points outside the precomputed contact region")
        k = np.flatnonzero(inside[:ncp])
        nout = len(self.out_pts) if outputs else 0
        if len(k) == 0:
            return Solution(np.zeros((nout, 3)), 0.0, np.zeros(3), 0.0, 0, "condensed")
        a = (3 * k[:, None] + np.arange(3)[None, :]).ravel()
        m = len(a)
        # G_aa (m, m) in C order; symmetric, so its transpose view is the same matrix in Fortran order
        Gaa = np.take(self._G_flat, ((a * self.G_cc.shape[0])[:, None] + a[None, :]).ravel()).reshape(m, m)
        single = Gaa.dtype == np.float32
        potrf, potrs = (_spotrf, _spotrs) if single else (_dpotrf, _dpotrs)
        c, info = potrf(Gaa.T, lower=0, clean=0, overwrite_a=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"capacitance block not positive definite (potrf info {info})")
        rhs = np.empty((2, m), Gaa.dtype)
        rhs[0] = ubar[k].ravel()
        rhs[1] = np.tile(finger.direction, len(k))
        f, info = potrs(c, rhs.T, lower=0, overwrite_b=1)
        if info != 0:                                   # pragma: no cover - only for invalid arguments
            raise np.linalg.LinAlgError(f"potrs failed (info {info})")
        u = ((f[:, 0] @ np.take(self.G_co, a, axis=0)).astype(np.float64).reshape(nout, 3) if outputs
             else np.zeros((0, 3)))
        f = f.astype(np.float64)
        fvec = f[:, 0].reshape(-1, 3).sum(axis=0)
        force = float(fvec @ finger.direction)
        stiff = float(f[:, 1].reshape(-1, 3).sum(axis=0) @ finger.direction)
        return Solution(u, max(force, 0.0), fvec, max(stiff, 0.0), len(k), "condensed")
