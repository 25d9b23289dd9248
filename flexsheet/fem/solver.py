"""Linear (P1/P2) and corotational elasticity of the cylinder under displacement-driven fingertip contact (pure).

Three solvers share one :class:`FemModel` (stiffness assembled with scikit-fem, ``linear_elasticity``):

* :func:`solve_full` — the baseline: sparse direct solve (SuperLU) of the whole mesh with the support and the
  contact points as Dirichlet DOFs, refactored every update.
* :class:`CapacitanceSolver` — the real-time path (James & Pai, "A unified treatment of elastostatic contact
  simulation for real time haptics", Haptics-e 2001; condensation as in Bro-Nielsen & Cotin, CGF 1996).
  Precompute once the Green's-function columns G = K_FF⁻¹ E_C for the candidate contact DOFs C, keeping only
  the rows the outputs need (surface + a strain-monitor zone). Per update: G_aa f = ū_a (m × m dense Cholesky,
  m = active contact DOFs), u_out = G_out,a f, and the reaction on the finger is −Σ f.
* :func:`solve_corotational` — geometrically nonlinear mode: corotational (stiffness-warping) FEM with lagged
  element rotations from the polar decomposition of the deformation gradient (Müller et al., SCA 2002;
  Müller & Gross, GI 2004; SOFA TetrahedronFEMForceField method="polar"), solved quasi-statically.

Failure detection (:func:`element_checks`): inverted elements (det F ≤ 0) and the largest principal strain.
Units SI; displacements m, forces N, stiffness N/m; display frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg.lapack import dpotrf as _dpotrf
from scipy.linalg.lapack import dpotrs as _dpotrs
from scipy.linalg.lapack import spotrf as _spotrf
from scipy.linalg.lapack import spotrs as _spotrs

from flexsheet.fem.contact import Finger, imposed_displacement
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import TetMesh

__all__ = ["FemModel", "Solution", "NotPositiveDefinite", "solve_full", "CapacitanceSolver", "solve_corotational",
           "element_checks", "TetChecks", "fold_operator", "OutsideCandidates", "factor"]


class OutsideCandidates(ValueError):
    """The finger touches surface points outside the precomputed candidate set (use :func:`solve_full`)."""


class NotPositiveDefinite(ValueError):
    """:func:`factor` met a non-positive pivot: the matrix is not positive definite."""


class _Cholesky:
    """Sparse Cholesky of a symmetric positive-definite matrix (CHOLMOD, supernodal, through scikit-sparse; Chen,
    Davis, Hager & Rajamanickam, ACM TOMS 35, 2008); ``solve(b)`` for (n,) or (n, k). Raises
    :class:`NotPositiveDefinite` at a non-positive pivot (nothing is kept: cholespy, used before, leaked its
    factor, ~0.5 GB each time, on that path)."""

    __slots__ = ("_f",)

    def __init__(self, A: sp.spmatrix):
        from sksparse.cholmod import CholmodNotPositiveDefiniteError, cholesky

        why = None
        try:
            # supernodal always: CHOLMOD's simplicial mode (what "auto" picks for very sparse matrices) is an
            # LDLᵀ that factorises an indefinite matrix without complaint
            self._f = cholesky(sp.csc_matrix(A), mode="supernodal")
        except CholmodNotPositiveDefiniteError as exc:
            why = str(exc)      # raised below, outside the handler: no __context__ holding the failed factor
        if why is not None:
            raise NotPositiveDefinite(why)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x with A x = b; ``b`` (n,) or (n, k)."""
        return self._f(np.ascontiguousarray(b, np.float64))


def factor(A: sp.spmatrix, backend: str = "auto"):
    """Factorise a symmetric positive-definite sparse matrix; returns an object with ``.solve(b)``.

    ``backend``: "cholmod" (CHOLMOD's supernodal Cholesky via scikit-sparse, 5–10× faster here), "superlu"
    (scipy ``splu`` with a symmetric ordering) or "auto" (CHOLMOD when importable, else SuperLU). Raises
    ``ValueError`` on an unknown backend and :class:`NotPositiveDefinite` (CHOLMOD) when A is not positive
    definite."""
    if backend not in ("auto", "cholmod", "superlu"):
        raise ValueError(f"backend must be 'auto', 'cholmod' or 'superlu', got {backend!r}")
    if backend in ("auto", "cholmod"):
        try:
            return _Cholesky(A)
        except ImportError:
            if backend == "cholmod":
                raise
    return spla.splu(sp.csc_matrix(A), permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})


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
            self.points = np.vstack([self.skmesh.p.T, 0.5 * (self.skmesh.p[:, e[0]] + self.skmesh.p[:, e[1]]).T])
        bd = np.zeros(self.K.shape[0], bool)
        bd[self.basis.get_dofs().flatten()] = True
        self.boundary = bd[self.dofs[:, 0]]
        if support is None:
            self.fixed = self.boundary & (self.points[:, 0] <= mesh.center[0] + 1e-9)
        else:
            held = np.asarray(support(self.points), dtype=bool)
            if held.shape != (len(self.points),):
                raise ValueError(f"support must return a ({len(self.points)},) bool mask, got shape {held.shape}")
            self.fixed = self.boundary & held
            if not self.fixed.any():
                raise ValueError("support holds no boundary point: the object would float (singular stiffness)")
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
            self._Dinv, _ = _grad_ops(p, t)
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
    """Per-element (E (M,) Pa, ν (M,)); a missing one is the nominal ``material``'s. ``ValueError`` naming it."""
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


def _contact_dofs(model: FemModel, finger: Finger, candidates: np.ndarray | None = None):
    pts_idx = np.flatnonzero(model.boundary & ~model.fixed)
    inside, ubar = imposed_displacement(model.points[pts_idx], finger)
    return pts_idx[inside], ubar[inside]


def solve_full(model: FemModel, finger: Finger) -> Solution:
    """Baseline: sparse direct solve with Dirichlet DOFs = support ∪ contact points; refactors every call.

    Returns a :class:`Solution` whose ``u`` covers every DOF point (P, 3). Stiffness is dF/dd with the
    contact set held (a second right-hand side on the same factorisation)."""
    cpts, ubar = _contact_dofs(model, finger)
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
    """Real-time linear contact by the capacitance matrix (James & Pai 2001) over precomputed Green's functions.

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
        self._all_points = np.ascontiguousarray(np.vstack([self._cand_points, self._noncand_points.reshape(-1, 3)]))
        self._G_flat = np.ascontiguousarray(self.G_cc).reshape(-1)

    def arrays(self) -> dict:
        """The precomputed state as plain arrays (see :meth:`from_arrays`)."""
        return {"G_cc": self.G_cc, "G_co": self.G_co, "cand_pts": self.cand_pts, "out_pts": self.out_pts,
                "cand_points": self._cand_points, "noncand_points": self._noncand_points}

    @classmethod
    def from_arrays(cls, z, dtype=np.float64) -> CapacitanceSolver:
        """Rebuild a solver from :meth:`arrays` (no model needed); raises ``ValueError`` on inconsistent shapes
        or a ``dtype`` other than float64/float32. ``dtype`` float32 keeps ``G_cc`` and ``G_co`` in single
        precision and runs the per-update Cholesky in it (LAPACK ``spotrf``/``spotrs``): half the memory and
        memory traffic. The capacitance blocks are well conditioned (cond(G_aa) ≈ 200 on the shipped scenes),
        so the displacements move by < 0.05 µm at a 50 mm push (tests/unit/fem/test_fem_scene.py checks < 1 µm
        against a float64 dense solve); force and stiffness are summed in float64."""
        dtype = np.dtype(dtype)
        if dtype not in (np.dtype(np.float64), np.dtype(np.float32)):
            raise ValueError(f"dtype must be float64 or float32, got {dtype}")
        self = cls.__new__(cls)
        self.model = None
        self.cand_pts, self.out_pts = np.asarray(z["cand_pts"]), np.asarray(z["out_pts"])
        self.G_cc = np.ascontiguousarray(z["G_cc"], dtype=dtype)
        self.G_co = np.ascontiguousarray(z["G_co"], dtype=dtype)
        self._cand_points, self._noncand_points = np.asarray(z["cand_points"]), np.asarray(z["noncand_points"])
        nc = 3 * len(self.cand_pts)
        if (self.G_cc.shape != (nc, nc) or self.G_co.shape != (nc, 3 * len(self.out_pts))
                or self._cand_points.shape != (len(self.cand_pts), 3)):
            raise ValueError(f"precomputed matrices have inconsistent shapes {self.G_cc.shape}, {self.G_co.shape}")
        self._prepare()
        return self

    @property
    def nbytes(self) -> int:
        """Bytes held by the precomputed matrices."""
        return self.G_cc.nbytes + self.G_co.nbytes

    def solve(self, finger: Finger) -> Solution:
        """One update: returns a :class:`Solution` with ``u`` (#outputs, 3) m at the output points.

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
        nout = len(self.out_pts)
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
        u = (f[:, 0] @ np.take(self.G_co, a, axis=0)).astype(np.float64).reshape(nout, 3)
        f = f.astype(np.float64)
        fvec = f[:, 0].reshape(-1, 3).sum(axis=0)
        force = float(fvec @ finger.direction)
        stiff = float(f[:, 1].reshape(-1, 3).sum(axis=0) @ finger.direction)
        return Solution(u, max(force, 0.0), fvec, max(stiff, 0.0), len(k), "condensed")


def fold_operator(rest: np.ndarray, faces: np.ndarray, normals: np.ndarray):
    """Fold test of triangles as one sparse product: returns (op (6F, 3S) csr, op @ rest.ravel() (6F,)) for
    ``faces`` (F, 3) over vertices ``rest`` (S, 3) m with rest normals ``normals`` (F, 3). For vertex positions
    x (S, 3) m flattened, rows c·F + f of op @ x give e2_c = (x2 − x0)_c and rows 3F + c·F + f give
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


def _grad_ops(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-tet inverse edge matrices Dm⁻¹ (M, 3, 3) and volumes (M,), for F = I + Du·Dm⁻¹."""
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
        Dm_inv, _ = _grad_ops(points, tets)
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
        Dm_inv = _grad_ops(points, tets)[0] if M else np.zeros((0, 3, 3))
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
        """Displacement gradients H (3, 3, M), H[i, j] = ∂u_i/∂x_j per tet, of node displacements ``u`` (N, 3)."""
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


def _element_stiffness(points, tets, material: Material):
    """P1 element stiffness matrices (M, 12, 12), DOF order (node, component). Zienkiewicz, FEM vol. 1 §6."""
    Dm_inv, vol = _grad_ops(points, tets)
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


def solve_corotational(model: FemModel, finger: Finger, iters: int = 30, tol: float = 1e-6,
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
    cpts, ubar = _contact_dofs(model, finger)
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
