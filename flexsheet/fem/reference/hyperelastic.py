"""Geometrically nonlinear reference: compressible neo-Hookean cylinder pushed by a rigid finger (pure).

Total Lagrangian, quadratic (P2) tetrahedra, Newton's method with load stepping in the push depth. This is
the accuracy reference the real-time models are judged against (docs/fem.md, "Physically right deformation").

* **Material**: compressible neo-Hookean, W = μ/2 (tr C − 3) − μ ln J + λ/2 (ln J)², first Piola–Kirchhoff
  stress P = μ (F − F⁻ᵀ) + λ ln J F⁻ᵀ, tangent A_iJkL = μ δ_ik δ_JL + (μ − λ ln J) F⁻¹_Jk F⁻¹_Li
  + λ F⁻¹_Ji F⁻¹_Lk (Bonet & Wood, *Nonlinear Continuum Mechanics for FEA*, 2nd ed., §6.4.3; the same energy
  as scikit-fem's hyperelasticity examples). λ, μ from the small-strain E, ν, so it agrees with linear
  elasticity for small strains.
  Or (``material.Jm`` finite) a **Gent** solid: μ/2 (tr C − 3) becomes −μJm/2 ln(1 − (tr C − 3)/Jm) (Gent,
  Rubber Chem. Technol. 69, 1996; limiting chain extensibility, neo-Hookean as Jm → ∞), so P's first term is
  μ g F with g = 1/(1 − (I₁ − 3)/Jm) and the tangent gains μ(g − 1) δ_ik δ_JL + (2μg²/Jm) F_iJ F_kL; the
  energy is +inf at I₁ − 3 ≥ Jm (the line search's barrier, as det F ≤ 0). A neo-Hookean solid never
  stiffens, and under the frictionless finger its apex thins without a mesh-converged limit past ~35–40 mm
  (docs/fem.md, fold and material studies).
* **Discretisation**: scikit-fem ``ElementTetP2`` on straight-sided tetrahedra (shape-function gradients and
  the 4-point quadrature, ``intorder=2``, positive weights); element matrices and residuals are vectorised
  numpy here (the tangent split into μ(∇N·∇N)⊗I + two rank-structured terms in h = ∇N·F⁻¹).
* **Quadrature**: the energy is integrated with the Gauss rule (weight 1 − β) blended with the element's 10 P2
  nodes (weight β/10 each, β = :data:`NODE_WEIGHT`; still exact for linear integrands, so the scheme stays
  consistent and the levels still converge). The Gauss points alone cannot see a P2 element fold through its
  corners and edge midpoints (det F is cubic over the element: a column under the fingertip collapsed); with
  the nodes in the rule the neo-Hookean barrier (−μ ln J → ∞) keeps every node's det F > 0.
* **Finger**: a rigid capsule pressed onto the contact quadrature points of the outer surface (order
  :data:`CONTACT_INTORDER`: 25 points per facet) through a smoothed penalty, frictionless or sticking
  (:mod:`flexsheet.fem.reference.capsule_contact`, whose docstring gives the law and its choices).
* **Support** as the linear model's: outer boundary points with x ≤ x_O fixed. Symmetry planes y = y_O
  (a push at y = y_O) and z = z_O (a push at azimuth 0) carry the normal displacement 0.
* **Newton**: minimise Π = ∫W dV + E_c with load stepping in the depth (:mod:`flexsheet.fem.reference.newton`:
  the steps, the tangent's projection, the line search, the convergence test).

Units SI: m, N, Pa. Display frame (cylinder axis along +y through ``mesh.center``).

Files: this module is the model (:class:`HyperelasticModel`: quadrature, energy, residual and tangent,
contact forces); the mesh, the finger, the 3 × 3 algebra, the projected tangent, the version tags, Newton and
the push along a path are their own modules of :mod:`flexsheet.fem.reference`.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
import scipy.sparse as sp

from flexsheet.fem.material import Material
from flexsheet.fem.mesh import TetMesh
from flexsheet.fem.reference.capsule_contact import PENALTY_SCALE, Capsule, smooth_penalty
from flexsheet.fem.reference.kinematics import gram, inv_det3
from flexsheet.fem.reference.projected_tangent import projection_correction

__all__ = ["HyperelasticModel", "NODE_WEIGHT", "CONTACT_INTORDER"]

#: facet quadrature order of the contact points (25 per facet; see the module docstring)
CONTACT_INTORDER = 10
#: share β of the element volume integrated at the 10 P2 nodes (see the module docstring)
NODE_WEIGHT = 0.05


class HyperelasticModel:
    """Neo-Hookean (or Gent, ``material.Jm`` finite) P2 model of a (half/quarter) cylinder mesh with the
    support and symmetry planes.

    Attributes: ``points`` (P, 3) m DOF points (mesh nodes, then edge midpoints); ``n`` = 3P DOFs, DOF of
    point p component c is 3p + c; ``surface`` (P,) bool points on the outer (non-symmetry) boundary;
    ``support`` (P,) bool fixed points; ``free`` (nf,) free DOFs. Raises ``ValueError`` on an empty mesh.
    """

    def __init__(self, mesh: TetMesh, material: Material, sym_y: bool = True, sym_z: bool = False,
                 intorder: int = 5, support: np.ndarray | None = None, E_elem: np.ndarray | None = None,
                 nu_elem: np.ndarray | None = None, node_weight: float = NODE_WEIGHT,
                 penalty_scale: float = PENALTY_SCALE):
        """``support`` (P,) bool over the DOF points (mesh nodes first, then edge midpoints, i.e.
        ``self.points``; build it from a node mask with :meth:`dof_points` first): fixed points, replacing the
        default rule (outer-boundary points with x ≤ ``mesh.center`` x). ``E_elem`` (E,) Pa and ``nu_elem``
        (E,) per-tetrahedron Young's modulus and Poisson's ratio (either may be given; the other comes from
        ``material``): λ, μ per element (inclusions, layered bodies). Raises ``ValueError`` on a wrong shape
        or an out-of-range value, naming the field. ``penalty_scale``: the contact penalty κ = scale·E/h
        (:meth:`penalty`; > 0)."""
        from skfem import MeshTet

        if isinstance(penalty_scale, bool) or not isinstance(penalty_scale, numbers.Real) \
                or not (math.isfinite(penalty_scale) and penalty_scale > 0):
            raise ValueError(f"penalty_scale must be finite and > 0, got {penalty_scale!r}")
        self.penalty_scale = float(penalty_scale)

        if len(mesh.tets) == 0:
            raise ValueError("mesh has no tetrahedra")
        self.mesh, self.material = mesh, material
        sk = MeshTet(np.ascontiguousarray(mesh.points.T), np.ascontiguousarray(mesh.tets.T))
        self.skmesh = sk
        self._init_quadrature(intorder, node_weight)
        outer = self._init_boundary(sym_y, sym_z, support)
        self._init_contact_quadrature(outer, support is None)
        self._init_material(material, E_elem, nu_elem)
        self._pattern()
        self.eps = 2e-5           #: width (m) of the smooth onset of the contact penalty (see smooth_penalty)
        #: fine facet size, m
        self.h_contact = float(np.sqrt(2.0 * np.percentile(self._cf_w.sum(axis=1), 10)))

    def _init_quadrature(self, intorder: int, node_weight: float) -> None:
        """The P2 basis, the DOF points and the volume quadrature (Gauss rule blended with the 10 nodes)."""
        from skfem import Basis, ElementTetP2

        if intorder not in (2, 5, 6):
            raise ValueError("intorder must be 2, 5 or 6 (tetrahedral rules with positive weights), got "
                             f"{intorder!r}")
        self.basis = Basis(self.skmesh, ElementTetP2(), intorder=intorder)
        b = self.basis
        self.points = np.ascontiguousarray(b.doflocs.T)
        self.n = 3 * len(self.points)
        self.edofs = np.ascontiguousarray(b.element_dofs.T)                             # (E, 10) points
        gq = np.stack([bf[0].grad for bf in b.basis], axis=0).transpose(2, 3, 0, 1)       # (E, Q, 10, 3)
        # nodal gradients for det F at the 10 element nodes (inversion check, and the nodal quadrature points)
        self._node_grad = self._nodal_gradients()
        if not (math.isfinite(node_weight) and 0.0 <= node_weight < 1.0):
            raise ValueError(f"node_weight must be in [0, 1), got {node_weight!r}")
        self.node_weight = float(node_weight)
        if node_weight > 0:         # blended rule: (1 − β) × the Gauss rule + β × the 10 nodes, equal weights
            vol_e = b.dx.sum(axis=1, keepdims=True)
            gq = np.concatenate([gq, self._node_grad], axis=1)
            wq = np.concatenate([(1.0 - node_weight) * b.dx,
                                 np.repeat(node_weight * vol_e / 10.0, 10, axis=1)],
                                axis=1)
        else:
            wq = b.dx
        self.grad = np.ascontiguousarray(gq)                                              # (E, Q', 10, 3)
        self.w = np.ascontiguousarray(wq)                                                 # (E, Q')
        self.vol = float(self.w.sum())

    def _init_boundary(self, sym_y: bool, sym_z: bool, support: np.ndarray | None) -> np.ndarray:
        """The outer surface, the support and the fixed DOFs (support and symmetry planes); returns the outer
        (non-symmetry) boundary facets."""
        sk, b, c = self.skmesh, self.basis, self.mesh.center
        P = len(self.points)
        tol = 1e-9
        facets = sk.boundary_facets()
        fp = sk.p[:, sk.facets[:, facets]]                                                # (3, 3, nf)
        on_y = np.all(np.abs(fp[1] - c[1]) < tol, axis=0) if sym_y else np.zeros(len(facets), bool)
        on_z = np.all(np.abs(fp[2] - c[2]) < tol, axis=0) if sym_z else np.zeros(len(facets), bool)
        outer = facets[~(on_y | on_z)]
        surf = np.zeros(P, bool)
        surf[b.get_dofs(facets=outer).flatten()] = True
        self.surface = surf
        if support is None:
            self.support = surf & (self.points[:, 0] <= c[0] + tol)
        else:
            support = np.asarray(support)
            if support.shape != (P,) or support.dtype != np.bool_:
                raise ValueError(f"support must be a ({P},) bool array over the DOF points, got "
                                 f"{support.dtype} {support.shape}")
            self.support = support.copy()
        fixed = np.zeros((P, 3), bool)
        fixed[self.support] = True
        if sym_y:
            fixed[np.abs(self.points[:, 1] - c[1]) < tol, 1] = True
        if sym_z:
            fixed[np.abs(self.points[:, 2] - c[2]) < tol, 2] = True
        self.fixed_mask = fixed.ravel()
        self.sym_y, self.sym_z = sym_y, sym_z
        self.sym_factor = 2 ** (int(sym_y) + int(sym_z))       #: full-body force = factor × this part's
        self.free = np.flatnonzero(~self.fixed_mask)
        self.contact_pts = np.flatnonzero(surf & ~self.support)
        return outer

    def _init_contact_quadrature(self, outer: np.ndarray, default_support: bool) -> None:
        """Contact quadrature on the outer facets not wholly in the support (6-point rule)."""
        from skfem import ElementTetP2, FacetBasis

        sk, c, tol = self.skmesh, self.mesh.center, 1e-9
        if default_support:
            sup_facet = np.all(self.points[sk.facets[:, outer], 0] <= c[0] + tol, axis=0)
        else:
            sup_facet = np.all(self.support[sk.facets[:, outer]], axis=0)
        fb = FacetBasis(sk, ElementTetP2(), facets=outer[~sup_facet], intorder=CONTACT_INTORDER)
        self._cf_dofs = np.ascontiguousarray(fb.element_dofs.T)                         # (Fc, 10)
        self._cf_N = np.ascontiguousarray(np.stack([bf[0].value for bf in fb.basis], axis=2))  # (Fc, Qf, 10)
        self._cf_X = np.ascontiguousarray(fb.global_coordinates().value.transpose(1, 2, 0))    # (Fc, Qf, 3)
        self._cf_w = np.ascontiguousarray(fb.dx)                                         # (Fc, Qf) m²

    def _init_material(self, material: Material, E_elem: np.ndarray | None,
                       nu_elem: np.ndarray | None) -> None:
        """Lamé λ, μ (the material's, or per element from ``E_elem``/``nu_elem``), reference modulus, Jm."""
        lam, mu = material.lame
        self.E_ref = material.E          #: modulus (Pa) that scales the contact penalty and the tolerances
        if E_elem is not None or nu_elem is not None:
            ne = len(self.mesh.tets)
            Ee = np.full(ne, material.E) if E_elem is None else np.asarray(E_elem, float)
            ve = np.full(ne, material.nu) if nu_elem is None else np.asarray(nu_elem, float)
            for name, a in (("E_elem", Ee), ("nu_elem", ve)):
                if a.shape != (ne,):
                    raise ValueError(f"{name} must have shape ({ne},) (one value per tetrahedron), got "
                                     f"{a.shape}")
            if not np.all(np.isfinite(Ee) & (Ee > 0)):
                raise ValueError(f"E_elem must be finite and > 0 Pa, got min {float(np.min(Ee))!r}")
            if not np.all(np.isfinite(ve) & (ve >= 0) & (ve < 0.5)):
                raise ValueError(f"nu_elem must be in [0, 0.5), got range [{float(np.min(ve))!r}, "
                                 f"{float(np.max(ve))!r}]")
            lam = (Ee * ve / ((1 + ve) * (1 - 2 * ve)))[:, None]                           # (E, 1) Pa
            mu = (Ee / (2 * (1 + ve)))[:, None]
            self.E_ref = float(np.max(Ee))
        self.lam, self.mu = lam, mu      #: Lamé λ, μ (Pa): floats, or (E, 1) arrays per element
        self.Jm = float(material.Jm) if material.gent else None     #: Gent limiting I1 − 3, None: neo-Hookean
        self.lam4 = lam if np.isscalar(lam) else lam[..., None, None]   #: λ broadcast against (E, Q, 3, 3)
        self.mu4 = mu if np.isscalar(mu) else mu[..., None, None]       #: μ likewise

    # ---- assembly ------------------------------------------------------------------------------------
    def _gent_factor(self, F: np.ndarray) -> np.ndarray | None:
        """Gent's stress factor g = 1/(1 − (I₁ − 3)/Jm) (E, Q) at deformation gradients ``F`` (E, Q, 3, 3), so
        that P's isochoric-free part is μ g F; None for neo-Hookean (g ≡ 1). Raises ``FloatingPointError`` at
        or beyond the limiting extensibility (the energy is +inf there; Newton's line search stops short)."""
        if self.Jm is None:
            return None
        x = ((F * F).sum(axis=(2, 3)) - 3.0) / self.Jm
        if np.any(x >= 1.0):
            raise FloatingPointError("Gent limiting extensibility reached (I1 - 3 >= Jm)")
        return 1.0 / (1.0 - x)

    def _nodal_gradients(self) -> np.ndarray:
        """∇N_a at the 10 reference nodes of each element, (E, 10, 10, 3) [elem, node, basis, dim]."""
        from skfem import ElementTetP2

        el = ElementTetP2()
        X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1],
                      [.5, 0, 0], [.5, .5, 0], [0, .5, 0], [0, 0, .5], [.5, 0, .5], [0, .5, .5]]).T
        ref = np.stack([el.lbasis(X, i)[1] for i in range(10)], axis=0)  # (10 basis, 3, 10 nodes)
        p = self.mesh.points[self.mesh.tets]                                              # (E, 4, 3)
        Jm = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)  # dX/dxi (E, 3, 3)
        Jinv = np.linalg.inv(Jm)
        return np.einsum("akn,ekJ->enaJ", ref, Jinv)

    def _pattern(self) -> None:
        E = len(self.edofs)
        vd = (3 * self.edofs[:, :, None] + np.arange(3)).reshape(E, 30)
        self._vd = vd
        rows = np.repeat(vd, 30, axis=1).ravel()
        cols = np.tile(vd, (1, 30)).ravel()
        key = rows * self.n + cols
        uniq, inv = np.unique(key, return_inverse=True)
        self._scatter = inv
        r, c = uniq // self.n, uniq % self.n
        self._nnz = len(uniq)
        A = sp.csr_matrix((np.arange(self._nnz, dtype=float), (r, c)), shape=(self.n, self.n))
        self._csr_order = A.data.astype(np.int64)        # csr position -> unique index
        self._indptr, self._indices = A.indptr, A.indices
        self._csr_row = np.repeat(np.arange(self.n), np.diff(A.indptr))
        fm = self.fixed_mask
        self._csr_fixed = fm[self._csr_row] | fm[self._indices]
        self._csr_diag_fixed = (self._csr_row == self._indices) & fm[self._csr_row]

    def deformation(self, u: np.ndarray):
        """F (E, Q, 3, 3) at the quadrature points for DOF-point displacements ``u`` (P, 3) m."""
        ue = u[self.edofs]                                                                # (E, 10, 3)
        return np.eye(3) + np.swapaxes(ue, 1, 2)[:, None] @ self.grad

    def nodal_deformation(self, u: np.ndarray) -> np.ndarray:
        """F (E, 10, 3, 3) at the 10 P2 nodes of each element for displacements ``u`` (P, 3) m."""
        return np.eye(3) + np.swapaxes(u[self.edofs], 1, 2)[:, None] @ self._node_grad

    def energy(self, u: np.ndarray, caps: Capsule | None, k: float) -> float:
        """Π (J) = elastic energy + contact penalty; +inf if det F ≤ 0 at any quadrature point."""
        F = self.deformation(u)
        J = inv_det3(F)[1]
        if np.any(J <= 0):
            return math.inf
        lnJ = np.log(J)
        I1 = (F * F).sum(axis=(2, 3))
        if self.Jm is None:
            W = 0.5 * self.mu * (I1 - 3) - self.mu * lnJ + 0.5 * self.lam * lnJ ** 2
        else:  # Gent: −μJm/2 ln(1 − (I1 − 3)/Jm), +inf at and beyond the limiting extensibility
            x = (I1 - 3) / self.Jm
            if np.any(x >= 1.0):
                return math.inf
            W = -0.5 * self.mu * self.Jm * np.log1p(-x) - self.mu * lnJ + 0.5 * self.lam * lnJ ** 2
        e = float(np.sum(W * self.w))
        if caps is not None:
            g, _, w = self._contact_gaps(u, caps)
            phi = smooth_penalty(g, k, self.eps)[0]
            if caps.anchors is not None:
                st = np.isfinite(caps.anchors[..., 0])
                if np.any(st):
                    dx = self._contact_x(u)[st] - caps.center - caps.anchors[st]
                    phi[st] = 0.5 * k * np.einsum("ni,ni->n", dx, dx)
            e += float(np.sum(w * phi))
        return e

    def _contact_x(self, u: np.ndarray, facets: np.ndarray | None = None) -> np.ndarray:
        """Deformed positions (Fc, Qf, 3) m of the contact quadrature points (``facets`` only, if given)."""
        if facets is None:
            return self._cf_X + self._cf_N @ u[self._cf_dofs]
        return self._cf_X[facets] + self._cf_N[facets] @ u[self._cf_dofs[facets]]

    def stick_anchors(self, u: np.ndarray, caps: Capsule, anchors: np.ndarray | None = None) -> np.ndarray:
        """Sticking contact: the anchors (Fc, Qf, 3) m (see :class:`Capsule`) after a converged state ``u``
        (P, 3) m with the finger ``caps``: points already stuck keep theirs, every other contact quadrature
        point in touch with the finger (gap < ε, the penalty's onset width: with a stiff penalty the points
        carrying load sit at 0 ≤ g < ε, not inside) is stuck: its anchor is placed along the finger's normal
        where the sticking spring k/2 |x − anchor|² carries the penalty's force at that gap (x − φ'(g)/k n),
        so the force is continuous when it sticks; relative to ``caps.center``."""
        x = self._contact_x(u)
        g, n = caps.gap(x.reshape(-1, 3))
        g, n = g.reshape(x.shape[:2]), n.reshape(x.shape)
        out = np.full(x.shape, np.nan) if anchors is None else np.array(anchors, float, copy=True)
        if out.shape != x.shape:
            raise ValueError(f"anchors must have shape {x.shape}, got {out.shape}")
        new = (g < self.eps) & ~np.isfinite(out[..., 0])
        d1 = smooth_penalty(g[new], self.penalty(), self.eps)[1]  # φ'(g) ≤ 0: the push-out force
        out[new] = x[new] - (d1 / self.penalty())[:, None] * n[new] - caps.center
        return out

    def _contact_dE(self, u: np.ndarray, caps: Capsule, k: float, facets: np.ndarray, curvature: bool = True):
        """∂φ/∂x (fa, Qf, 3) N/m² and ∂²φ/∂x² (fa, Qf, 3, 3) N/m³ of the contact energy density at the contact
        quadrature points of ``facets``, and their area weights (fa, Qf) m² (``curvature``: include the
        normal's derivative, a negative term, in the frictionless part)."""
        g, nrm, w, dn = self._contact_gaps(u, caps, facets)
        _, d1, d2 = smooth_penalty(g, k, self.eps)
        f = d1[..., None] * nrm
        Hx = d2[..., None, None] * nrm[..., :, None] * nrm[..., None, :]
        if curvature:
            Hx = Hx + d1[..., None, None] * dn
        if caps.anchors is not None:
            a = caps.anchors[facets]
            st = np.isfinite(a[..., 0])
            if np.any(st):
                f[st] = k * (self._contact_x(u, facets)[st] - caps.center - a[st])
                Hx[st] = k * np.eye(3)
        return f, Hx, w

    def _contact_gaps(self, u: np.ndarray, caps: Capsule, facets: np.ndarray | None = None):
        """Gaps (Fc, Qf) m, outward finger normals (Fc, Qf, 3) and area weights (Fc, Qf) m² at the contact
        quadrature points of the deformed outer surface (with ``facets``: those contact facets only, and
        also ∂n/∂x (Fc, Qf, 3, 3))."""
        if facets is None:
            x = self._contact_x(u)
            g, n = caps.gap(x.reshape(-1, 3))
            return g.reshape(x.shape[:2]), n.reshape(x.shape), self._cf_w
        x = self._contact_x(u, facets)
        g, n, dn = caps.gap(x.reshape(-1, 3), curvature=True)
        return g.reshape(x.shape[:2]), n.reshape(x.shape), self._cf_w[facets], dn.reshape(x.shape + (3,))

    def contact_force(self, u: np.ndarray, caps: Capsule, k: float) -> tuple[np.ndarray, float, int]:
        """(force the finger applies to this part (3,) N, deepest penetration m, contact points in touch (gap
        below the penalty's onset ε) or stuck)."""
        g, n, w = self._contact_gaps(u, caps)
        stuck = np.isfinite(caps.anchors[..., 0]) if caps.anchors is not None else np.zeros(g.shape, bool)
        fa = np.flatnonzero(np.any((g < self.eps) | stuck, axis=1))
        if not len(fa):
            return np.zeros(3), 0.0, 0
        f, _, wf = self._contact_dE(u, caps, k, fa, curvature=False)
        return (-(wf[..., None] * f)).sum(axis=(0, 1)), float(max(0.0,
                                                                  -g.min())), int(np.sum((g < self.eps)
                                                                                         | stuck))

    def residual_tangent(self, u: np.ndarray, caps: Capsule | None, k: float, need_K: bool = True,
                         project: bool = False):
        """Residual r (n,) N and tangent K_t (csr, n × n, N/m) of Π at ``u`` (P, 3); K_t is None when not
        ``need_K``. ``project``: replace the material tangent A (9 × 9) at every quadrature point where it is
        indefinite by its positive semi-definite projection (projected Newton, Teran, Sifakis, Irving &
        Fedkiw, SCA 2005), so K_t is positive definite. Raises ``FloatingPointError`` when an element is
        inverted."""
        F = self.deformation(u)
        Finv, J = inv_det3(F)
        if np.any(J <= 0):
            raise FloatingPointError("inverted element (det F <= 0)")
        lnJ = np.log(J)
        FinvT = np.swapaxes(Finv, 2, 3)
        gent = self._gent_factor(F)             # None (neo-Hookean) or g = 1/(1 − (I1 − 3)/Jm) (E, Q)
        if gent is None:
            P = self.mu4 * (F - FinvT) + (self.lam * lnJ)[..., None, None] * FinvT
        else:
            P = self.mu4 * (gent[..., None, None] * F - FinvT) + (self.lam * lnJ)[..., None, None] * FinvT
        E, Q = lnJ.shape
        G = self.grad
        Gf = G.transpose(0, 2, 1, 3).reshape(E, 10, 3 * Q)                                 # [e, a, (q, J)]
        # Σ_qJ w ∇N_a,J P_iJ
        re = Gf @ (P * self.w[..., None, None]).transpose(0, 1, 3, 2).reshape(E, 3 * Q, 3)
        r = np.bincount(self._vd.ravel(), weights=re.ravel(), minlength=self.n)
        cdata = None
        if caps is not None:
            g0, _, _ = self._contact_gaps(u, caps)
            act = g0 < self.eps
            if caps.anchors is not None:
                act |= np.isfinite(caps.anchors[..., 0])
            fa = np.flatnonzero(np.any(act, axis=1))
            if len(fa):
                # the curvature term is negative: dropped when projecting
                f, Hx, w = self._contact_dE(u, caps, k, fa, curvature=not project)
                Nf = self._cf_N[fa]                                                         # (fa, Qf, 10)
                Nw = Nf * w[..., None]                                                      # (fa, Qf, 10)
                rc = gram(Nw, f)                                                           # (fa, 10, 3)
                vd = (3 * self._cf_dofs[fa][:, :, None] + np.arange(3)).reshape(len(fa), 30)
                r += np.bincount(vd.ravel(), weights=rc.ravel(), minlength=self.n)
                NN = (Nw[..., :, None] * Nf[..., None, :]).reshape(len(fa), -1, 100)       # [f, q, (a, b)]
                Kc = gram(NN, Hx.reshape(len(fa), -1, 9)).reshape(len(fa), 10, 10, 3, 3)   # [f, a, b, i, k]
                cdata = (vd, Kc.transpose(0, 1, 3, 2, 4).reshape(len(fa), 30, 30))
        if not need_K:
            return r, None
        H = (G @ Finv).reshape(E, Q, 30)                                                  # ∇N_a,J F⁻¹_Jm
        lw = self.lam * self.w
        c1w = (self.mu - self.lam * lnJ) * self.w
        T3 = gram(H * lw[..., None], H)
        Y = gram(H * c1w[..., None], H).reshape(E, 10, 3, 10, 3)
        muw = self.mu * self.w if gent is None else self.mu * gent * self.w
        T1 = (G * muw[..., None, None]).transpose(0, 2, 1, 3).reshape(E, 10, 3 * Q) @ np.swapaxes(Gf, 1, 2)
        Ke = T3.reshape(E, 10, 3, 10, 3) + Y.transpose(0, 1, 4, 3, 2)
        Ke += T1[:, :, None, :, None] * np.eye(3)[None, None, :, None, :]
        if gent is not None:    # Gent's stiffening: (2μg²/Jm) F_iJ F_kL, i.e. Σ_q w c (∇N_a·F_i)(∇N_b·F_k)
            M = (G @ np.swapaxes(F, 2, 3)).reshape(E, Q, 30)                              # ∇N_a,J F_iJ
            cw = (2.0 / self.Jm) * self.mu * gent ** 2 * self.w
            Ke += gram(M * cw[..., None], M).reshape(E, 10, 3, 10, 3)
        if project:
            Ke += self._projection(F, Finv, lnJ, gent)
        data = np.bincount(self._scatter, weights=Ke.ravel(), minlength=self._nnz)[self._csr_order]
        K = sp.csr_matrix((data, self._indices, self._indptr), shape=(self.n, self.n))
        if cdata is not None:
            vd, Kc = cdata
            rr = np.repeat(vd, 30, axis=1).ravel()
            cc = np.tile(vd, (1, 30)).ravel()
            K = K + sp.csr_matrix((Kc.ravel(), (rr, cc)), shape=(self.n, self.n))
        return r, K

    def _projection(self, F: np.ndarray, Finv: np.ndarray, lnJ: np.ndarray, gent: np.ndarray | None = None
                    ) -> np.ndarray:
        """Element-matrix correction Σ_q w Bᵀ(A₊ − A)B (E, 10, 3, 10, 3) where A₊ clamps A's negative
        eigenvalues to 0 (:func:`flexsheet.fem.reference.projected_tangent.projection_correction`)."""
        return projection_correction(self, F, Finv, lnJ, gent)

    def constrained(self, K: sp.csr_matrix) -> sp.csr_matrix:
        """K with fixed rows/columns replaced by the identity (same size; fixed DOFs then get δ = 0)."""
        K = K.tocsr(copy=True)
        K.sort_indices()
        fm = self.fixed_mask
        row = np.repeat(np.arange(self.n), np.diff(K.indptr))
        d = K.data
        d[fm[row] | fm[K.indices]] = 0.0
        d[(row == K.indices) & fm[row]] = 1.0
        return K

    # ---- checks --------------------------------------------------------------------------------------
    def checks(self, u: np.ndarray) -> tuple[float, int, float]:
        """(min det F over quadrature points and element nodes, inverted element count, largest principal
        Green–Lagrange strain over quadrature points) for displacements ``u`` (P, 3) m."""
        F = self.deformation(u)
        Jq = inv_det3(F)[1]
        Jn = inv_det3(self.nodal_deformation(u))[1]
        minJ = np.minimum(Jq.min(axis=1), Jn.min(axis=1))
        C = gram(F, F)
        Egl = 0.5 * (C - np.eye(3))
        return float(minJ.min()), int(np.count_nonzero(minJ <= 0)), float(np.linalg.eigvalsh(Egl).max())

    def probe_matrix(self, x: np.ndarray) -> sp.csr_matrix:
        """Interpolation matrix (k, P): values of the P2 field at points ``x`` (k, 3) m. Points just outside
        the faceted boundary use the nearest element's polynomial (a tiny extrapolation), as in
        :meth:`flexsheet.fem.solver.FemModel.probe`. Points beyond the symmetry planes must be mirrored
        first."""
        from scipy.spatial import cKDTree

        x = np.asarray(x, float)
        p, t = self.mesh.points, self.mesh.tets
        if not hasattr(self, "_tree"):
            self._tree = cKDTree(p[t].mean(axis=1))
            Dm = np.stack([p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]], p[t[:, 3]] - p[t[:, 0]]], axis=2)
            self._Dinv = np.linalg.inv(Dm)
        kk = min(24, len(t))
        _, cand = self._tree.query(x, k=kk)
        cand = np.atleast_2d(cand)
        rel = x[:, None, :] - p[t[cand, 0]]
        lam = np.einsum("qkij,qkj->qki", self._Dinv[cand], rel)
        bary = np.concatenate([1 - lam.sum(axis=2, keepdims=True), lam], axis=2)
        best = np.argmax(bary.min(axis=2), axis=1)
        cells = cand[np.arange(len(x)), best]
        pts = self.basis.mapping.invF(np.ascontiguousarray(x.T)[:, :, None], tind=cells)
        phis = np.array([self.basis.elem.gbasis(self.basis.mapping, pts, j, tind=cells)[0]
                         for j in range(self.basis.Nbfun)]).reshape(self.basis.Nbfun, len(x))
        rows = np.tile(np.arange(len(x)), self.basis.Nbfun)
        cols = self.basis.element_dofs[:, cells].ravel()
        return sp.csr_matrix((phis.ravel(), (rows, cols)), shape=(len(x), len(self.points)))

    def penalty(self, mesh_h: float | None = None) -> float:
        """Contact penalty per unit area, N/m³: ``penalty_scale``·E/h (default :data:`PENALTY_SCALE`), h the
        fine contact-facet size. With the smoothed onset
        (:func:`~flexsheet.fem.reference.capsule_contact.smooth_penalty`) a point carries pressure p at the
        stand-off g = ε − √(2εp/κ) for p < κε/2 (≈ 290·E on the 3.4 mm mesh) and penetrates (p − κε/2)/κ
        beyond: the geometric contact error is at most ε = 20 µm plus that penetration."""
        return self.penalty_scale * self.E_ref / (mesh_h or self.h_contact)

    def dof_points(self, node_mask: np.ndarray) -> np.ndarray:
        """Extend a mask over the mesh nodes (N,) bool to the DOF points (P,) bool: an edge midpoint is
        marked when both its end nodes are (e.g. a support given on the mesh nodes)."""
        node_mask = np.asarray(node_mask, bool)
        n0 = self.skmesh.p.shape[1]
        if node_mask.shape != (n0,):
            raise ValueError(f"node_mask must have shape ({n0},), got {node_mask.shape}")
        return np.concatenate([node_mask, np.all(node_mask[self.skmesh.edges], axis=0)])

