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
* **Quadrature**: the energy is integrated with the Gauss rule (weight 1 − β) blended with the element's 10
  P2 nodes (weight β/10 each, β = :data:`NODE_WEIGHT`; still exact for linear integrands, so the scheme stays
  consistent and the levels still converge). The Gauss points alone cannot see a P2 element fold through its
  corners and edge midpoints (det F is cubic over the element): under the fingertip such a fold let a column of
  material collapse to zero thickness and the tip jump ahead at a mesh-dependent depth (the snap-through of
  solver nh-2). With the nodes in the rule the neo-Hookean barrier (−μ ln J → ∞) keeps every node's det F > 0.
* **Finger**: rigid frictionless *capsule* (the fingertip sphere of radius r plus the finger's shaft behind
  it, along −p̂), non-penetration at the contact quadrature points of the outer surface
  (order :data:`CONTACT_INTORDER`: 25 points per facet, because the facets around the tip stretch several
  times over and the fingertip slipped between the 6 points of the order-4 rule), penalty
  E_c = Σ w φ(g_i) (gap g_i = distance to the capsule's axis segment − r; φ a C² penalty that starts
  ε = 20 µm before contact, :func:`_pen`); k = :data:`PENALTY_SCALE`·E/h, chosen by a penalty study (the
  visible surface within 0.03 mm of a 10× stiffer finger; the loaded points stand off by < ε or penetrate
  < 0.02 mm at 50 mm, reported). A real finger, not a bonded
  imposed displacement (the linear model's contact): material slides along it and wraps around it.
  Optionally (``contact="sticking"``, :func:`solve_path_capsule`) a fingertip that does not slip: points that
  touch it stick to it. It removes the frictionless snap-through under the tip but mesh-converges worse
  (docs/fem.md), so frictionless stays the default (:data:`DEFAULT_CONTACT`).
* **Support** as the linear model's: outer boundary points with x ≤ x_O fixed. Symmetry planes y = y_O
  (a push at y = y_O) and z = z_O (a push at azimuth 0) carry the normal displacement 0.
* **Newton**: minimise Π = ∫W dV + E_c; each step solves K_t δ = −r, first by PCG preconditioned with the
  last sparse Cholesky factorisation (Newton–Krylov with a lagged preconditioner, :data:`PCG_RTOL`), else by a
  fresh sparse Cholesky (CHOLMOD, :func:`_cholesky`, which also tells whether K_t is positive definite; PCG's
  negative curvature tells it too).
  Where K_t is not positive definite — far from equilibrium — the material tangent is projected to its
  positive part (Teran et al. 2005); where Newton then crawls (:data:`CRAWL_ITERS` projected steps that each
  cut the residual by less than 10 %: a limit point, where the projection stiffens the direction the material
  snaps through), the true tangent plus the smallest diagonal shift that factorises takes over for the rest of
  the load step's Newton solve (Nocedal & Wright alg. 3.3, :func:`_shifted_step`; solver nh-6). Then a
  backtracking line search keeps det F > 0 at every quadrature point and decreases Π (Armijo), with at most
  1 mm of motion per iteration so no surface point can jump across the finger. Load stepping: depth in steps
  of ``step`` m with a linear-extrapolation predictor. Converged when ‖δ‖∞ < ``tol_u`` and the free
  residual is below ``tol_r`` × the finger force scale.

Units SI: m, N, Pa. Display frame (cylinder axis along +y through ``mesh.center``).
"""

from __future__ import annotations

import math
import numbers
import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp

from flexsheet.fem.material import Material
from flexsheet.fem.mesh import TetMesh, cylinder_part_mesh

__all__ = ["unload_sweep", "stable_states", "BRANCH_MEET_TOL", "UNLOAD_VERSION", "SOLVER_VERSION", "PREVIOUS_VERSION", "CONTACT_LAWS", "DEFAULT_CONTACT", "RefSpec", "HyperelasticModel", "PathState",
           "Capsule", "capsule_at", "solve_path", "solve_path_capsule", "reference_mesh", "solver_tag"]

SOLVER_VERSION = "nh-7"     #: bump when the reference's formulation or defaults change (cache keys)
#: the version before, and where its results are the current one's: nh-7 differs from nh-6 only in a Newton call
#: that ran out of iterations (continued, :data:`RESUME_MAX`), so an nh-6 path in which no call ran out (fewer
#: than ``iters`` Newton iterations at every depth: a call that runs out counts ``iters`` by itself) is the nh-7
#: path, bit for bit — if it was computed by nh-6 as committed in 27126c8. The first nh-6 commit (4899088)
#: differed where a diagonal shift failed (it fell back to crawling); the earliest cached azimuth-0 paths
#: were computed by it, so for them "bit for bit" holds only if no shift failed (not recorded)
PREVIOUS_VERSION = "nh-6"
#: contact penalty κ = PENALTY_SCALE·E/h. Chosen by a penalty study (``flexsheet experiment fem``,
#: ``reference.penalty_study``): on the 6 mm mesh at 50 mm the old 10³ penetrated the finger by 1.2 mm, made the
#: force 10 % low and moved the visible surface by 2.2 mm against 10⁴; 10⁵ penetrates 0.004 mm and lies
#: 0.03 mm from 10⁶ (docs/fem.md). Newton needs ~2.3× the CPU of 10³ for it. Changing it needs a
#: SOLVER_VERSION bump (the snapshot tables' cache key carries the solver tag, not the penalty).
PENALTY_SCALE = 1e5
CONTACT_LAWS = ("frictionless", "sticking")   #: finger contact laws (see :func:`solve_path_capsule`)
DEFAULT_CONTACT = "frictionless"            #: the contact law the experiment and the snapshots use
CONTACT_INTORDER = 10   #: facet quadrature order of the contact points (25 per facet; see the module docstring)
NODE_WEIGHT = 0.05      #: share β of the element volume integrated at the 10 P2 nodes (see the module docstring)


def solver_tag(contact: str = DEFAULT_CONTACT, version: str = SOLVER_VERSION) -> str:
    """Cache-key tag of the reference solver ``version`` with this contact law (the version, plus the law when it
    is not frictionless, so frictionless solves cached before the option existed stay valid)."""
    if contact not in CONTACT_LAWS:
        raise ValueError(f"contact must be one of {CONTACT_LAWS}, got {contact!r}")
    return version if contact == "frictionless" else f"{version}-{contact}"


@dataclass(frozen=True)
class RefSpec:
    """Mesh of the reference: ``h`` global size (m), ``h_fine`` size (m) within ``refine_radius`` (m) of the
    contact point, or (``path_depth`` > 0, m) of the whole push path from the contact point down to that depth
    (:func:`flexsheet.fem.mesh.cylinder_part_mesh`); ``half_z`` also use the z mirror plane (azimuth-0 pushes
    only); ``skin_h`` > 0 (m): that size in the surface layer ``skin_depth`` thick within ``skin_radius`` of the
    contact point (the material that wraps the fingertip and lines the crater); ``tip_h`` > 0 (m): that size
    within ``tip_radius`` (m) of the contact point itself, graded to ``h`` over a further ``tip_radius`` (the
    material that ends up over the fingertip, stretched several times over: docs/fem.md, fold study); ``cut``: the mesh is conforming
    to the plane through the cylinder's axis and the push axis (nodes on it, as a quarter model has on its
    mirror plane), for half models (a quarter model has it: ignored). Raises ``ValueError``."""

    h: float = 0.010
    h_fine: float = 0.002
    refine_radius: float = 0.018
    half_z: bool = False
    path_depth: float = 0.0
    skin_h: float = 0.0
    skin_radius: float = 0.020
    skin_depth: float = 0.005
    cut: bool = False
    tip_h: float = 0.0
    tip_radius: float = 0.005

    def __post_init__(self):
        for name in ("h", "h_fine"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0.0005 <= v <= 0.05):
                raise ValueError(f"{name} must be in [0.0005, 0.05] m, got {v!r}")
        if self.h_fine > self.h:
            raise ValueError(f"h_fine must be <= h, got {self.h_fine!r} > {self.h!r}")
        if not (self.skin_h == 0.0 or (math.isfinite(self.skin_h) and 0.0005 <= self.skin_h <= self.h_fine)):
            raise ValueError(f"skin_h must be 0 (no skin) or in [0.0005, h_fine={self.h_fine:g}] m, got {self.skin_h!r}")
        for name in ("skin_radius", "skin_depth"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be > 0 m, got {v!r}")
        if not (self.tip_h == 0.0 or (math.isfinite(self.tip_h) and 0.0005 <= self.tip_h <= self.h_fine)):
            raise ValueError(f"tip_h must be 0 (no tip refinement) or in [0.0005, h_fine={self.h_fine:g}] m, got "
                             f"{self.tip_h!r}")
        if not (math.isfinite(self.tip_radius) and self.tip_radius >= max(self.tip_h, 1e-4)):
            raise ValueError(f"tip_radius must be >= tip_h (one element), got {self.tip_radius!r}")
        if self.skin_h > 0 and self.skin_depth < self.skin_h:
            raise ValueError(f"skin_depth must be >= skin_h = {self.skin_h:g} m (one element thick), got {self.skin_depth!r}")

    def key(self) -> str:
        """Stable text key (cache keys)."""
        k = f"h={self.h:.6g},hf={self.h_fine:.6g},rr={self.refine_radius:.6g},hz={int(self.half_z)}"
        k += f",pd={self.path_depth:.6g}" if self.path_depth > 0 else ""
        k += f",sk={self.skin_h:.6g}/{self.skin_radius:.6g}/{self.skin_depth:.6g}" if self.skin_h > 0 else ""
        k += f",tip={self.tip_h:.6g}/{self.tip_radius:.6g}" if self.tip_h > 0 else ""
        return k + (",cut" if self.cut and not self.half_z else "")      # a quarter model has the plane anyway


def reference_mesh(spec: RefSpec, angle_deg: float) -> TetMesh:
    """Half (or quarter, ``spec.half_z``) cylinder mesh refined around the push point at ``angle_deg``."""
    if spec.half_z and abs(angle_deg) > 1e-9:
        raise ValueError(f"half_z needs a push at azimuth 0, got {angle_deg!r} deg")
    return cylinder_part_mesh(spec.h, spec.h_fine, spec.refine_radius, (float(angle_deg),), half_y=True,
                              half_z=spec.half_z, path_depth=spec.path_depth,
                              skin=(spec.skin_h, spec.skin_radius, spec.skin_depth) if spec.skin_h > 0 else None,
                              tip=(spec.tip_h, spec.tip_radius) if spec.tip_h > 0 else None,
                              cut_deg=float(angle_deg) if spec.cut and not spec.half_z else None)


@dataclass(frozen=True)
class Capsule:
    """Rigid finger: the sphere (centre ``center`` (3,) m, radius ``radius`` m) swept back along −``direction``
    by ``shaft`` m (the finger's body). ``direction`` (3,) unit push direction p̂ (into the object).
    ``anchors`` (Fc, Qf, 3) m, sticking contact only: for each contact quadrature point of the
    :class:`HyperelasticModel` it is used with, the finger point it is stuck to, relative to ``center``
    (NaN where not stuck); stuck points are held there by the penalty k/2 |x − (center + anchor)|² instead of
    the normal-only one (the finger only translates, so a point on it keeps its offset from ``center``)."""

    center: np.ndarray
    direction: np.ndarray
    radius: float
    shaft: float = 0.1
    anchors: np.ndarray | None = None

    def gap(self, x: np.ndarray, curvature: bool = False):
        """Signed gaps (N,) m (< 0: inside the finger) and unit outward normals (N, 3) at points ``x`` (N, 3);
        with ``curvature`` also ∂n/∂x (N, 3, 3) (1/m): (I − nnᵀ)/ρ on the sphere, (I − nnᵀ − p̂p̂ᵀ)/ρ on the
        shaft, ρ the distance from the finger's axis point."""
        rel = np.asarray(x, float) - self.center
        s_raw = -(rel @ self.direction)
        s = np.clip(s_raw, 0.0, self.shaft)                        # position along the shaft (backward)
        q = rel + s[:, None] * self.direction                      # from the closest axis point to x
        d = np.linalg.norm(q, axis=1)
        n = q / np.maximum(d, 1e-12)[:, None]
        if not curvature:
            return d - self.radius, n
        P = np.eye(3) - n[:, :, None] * n[:, None, :]
        shaft = (s_raw > 0) & (s_raw < self.shaft)
        P[shaft] -= np.outer(self.direction, self.direction)
        return d - self.radius, n, P / np.maximum(d, 1e-12)[:, None, None]


def capsule_at(angle: float, depth: float, radius: float, cyl_radius: float, cyl_center: np.ndarray,
               axial: float = 0.0) -> Capsule:
    """Finger pushed radially at azimuth ``angle`` (rad) to ``depth`` (m; the sphere's leading point is ``depth``
    inside the undeformed surface, as :func:`flexsheet.fem.contact.finger_at`). Raises ``ValueError`` on NaN or
    negative depth."""
    for name, v in (("angle", angle), ("depth", depth), ("radius", radius), ("axial", axial)):
        if not math.isfinite(v):
            raise ValueError(f"{name} must be finite, got {v!r}")
    if depth < 0:
        raise ValueError(f"depth must be >= 0, got {depth!r}")
    if radius <= 0:
        raise ValueError(f"radius must be > 0, got {radius!r}")
    out = np.array([math.cos(angle), 0.0, math.sin(angle)])
    cp = np.asarray(cyl_center, float) + np.array([0.0, axial, 0.0]) + cyl_radius * out
    return Capsule(cp - depth * out + radius * out, -out, float(radius))


@dataclass
class PathState:
    """Converged state at one depth: ``depth`` m, ``u`` (P, 3) m displacement of every DOF point,
    ``force`` N (finger force along p̂), ``force_vec`` (3,) N, ``iterations``, ``converged``, ``min_detF``
    (smallest det F over quadrature points and element nodes), ``inverted`` (elements with det F ≤ 0 at a
    quadrature point or node), ``max_strain`` (largest principal Green–Lagrange strain), ``penetration`` m
    (deepest surface point inside the finger), ``n_contact``; ``extra["anchors"]`` (sticking contact) the
    anchors (Fc, Qf, 3) m the state was solved with (:class:`Capsule`)."""

    depth: float
    u: np.ndarray
    force: float
    force_vec: np.ndarray
    iterations: int
    converged: bool
    min_detF: float
    inverted: int
    max_strain: float
    penetration: float
    n_contact: int
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)


class HyperelasticModel:
    """Neo-Hookean (or Gent, ``material.Jm`` finite) P2 model of a (half/quarter) cylinder mesh with the support and symmetry planes.

    Attributes: ``points`` (P, 3) m DOF points (mesh nodes, then edge midpoints); ``n`` = 3P DOFs, DOF of
    point p component c is 3p + c; ``surface`` (P,) bool points on the outer (non-symmetry) boundary;
    ``support`` (P,) bool fixed points; ``free`` (nf,) free DOF indices. Raises ``ValueError`` on an empty mesh.
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
        self.eps = 2e-5           #: width (m) of the smooth onset of the contact penalty (see _pen)
        self.h_contact = float(np.sqrt(2.0 * np.percentile(self._cf_w.sum(axis=1), 10)))  #: fine facet size, m

    def _init_quadrature(self, intorder: int, node_weight: float) -> None:
        """The P2 basis, the DOF points and the volume quadrature (the Gauss rule blended with the 10 nodes)."""
        from skfem import Basis, ElementTetP2

        if intorder not in (2, 5, 6):
            raise ValueError(f"intorder must be 2, 5 or 6 (tetrahedral rules with positive weights), got {intorder!r}")
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
            wq = np.concatenate([(1.0 - node_weight) * b.dx, np.repeat(node_weight * vol_e / 10.0, 10, axis=1)],
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
        """Contact quadrature on the outer facets not wholly in the support (6-point rule, positive weights)."""
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

    def _init_material(self, material: Material, E_elem: np.ndarray | None, nu_elem: np.ndarray | None) -> None:
        """Lamé λ, μ (the material's, or per element from ``E_elem``/``nu_elem``), the reference modulus, Gent's Jm."""
        lam, mu = material.lame
        self.E_ref = material.E          #: modulus (Pa) that scales the contact penalty and the tolerances
        if E_elem is not None or nu_elem is not None:
            ne = len(self.mesh.tets)
            Ee = np.full(ne, material.E) if E_elem is None else np.asarray(E_elem, float)
            ve = np.full(ne, material.nu) if nu_elem is None else np.asarray(nu_elem, float)
            for name, a in (("E_elem", Ee), ("nu_elem", ve)):
                if a.shape != (ne,):
                    raise ValueError(f"{name} must have shape ({ne},) (one value per tetrahedron), got {a.shape}")
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
        self._lam4 = lam if np.isscalar(lam) else lam[..., None, None]       # broadcast against (E, Q, 3, 3)
        self._mu4 = mu if np.isscalar(mu) else mu[..., None, None]

    # ---- assembly ------------------------------------------------------------------------------------
    def _gent_factor(self, F: np.ndarray) -> np.ndarray | None:
        """Gent's stress factor g = 1/(1 − (I₁ − 3)/Jm) (E, Q) at deformation gradients ``F`` (E, Q, 3, 3), so that
        P's isochoric-free part is μ g F; None for neo-Hookean (g ≡ 1). Raises ``FloatingPointError`` at or
        beyond the limiting extensibility (the energy is +inf there; Newton's line search never goes there)."""
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
        ref = np.stack([el.lbasis(X, i)[1] for i in range(10)], axis=0)                 # (10 basis, 3, 10 nodes)
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
        else:                   # Gent: −μJm/2 ln(1 − (I1 − 3)/Jm), +inf at and beyond the limiting extensibility
            x = (I1 - 3) / self.Jm
            if np.any(x >= 1.0):
                return math.inf
            W = -0.5 * self.mu * self.Jm * np.log1p(-x) - self.mu * lnJ + 0.5 * self.lam * lnJ ** 2
        e = float(np.sum(W * self.w))
        if caps is not None:
            g, _, w = self._contact_gaps(u, caps)
            phi = _pen(g, k, self.eps)[0]
            if caps.anchors is not None:
                st = np.isfinite(caps.anchors[..., 0])
                if np.any(st):
                    dx = self._contact_x(u)[st] - caps.center - caps.anchors[st]
                    phi[st] = 0.5 * k * np.einsum("ni,ni->n", dx, dx)
            e += float(np.sum(w * phi))
        return e

    def _contact_x(self, u: np.ndarray, facets: np.ndarray | None = None) -> np.ndarray:
        """Deformed positions (Fc, Qf, 3) m of the contact quadrature points (of ``facets`` only, if given)."""
        if facets is None:
            return self._cf_X + self._cf_N @ u[self._cf_dofs]
        return self._cf_X[facets] + self._cf_N[facets] @ u[self._cf_dofs[facets]]

    def stick_anchors(self, u: np.ndarray, caps: Capsule, anchors: np.ndarray | None = None) -> np.ndarray:
        """Sticking contact: the anchors (Fc, Qf, 3) m (see :class:`Capsule`) after a converged state ``u``
        (P, 3) m with the finger ``caps``: points already stuck keep theirs, every other contact quadrature
        point in touch with the finger (gap < ε, the penalty's onset width: with a stiff penalty the points
        carrying load sit at 0 ≤ g < ε, not inside) is stuck: its anchor is placed along the finger's normal
        where the sticking spring k/2 |x − anchor|² carries the penalty's force at that gap (x − φ'(g)/k n), so
        the force is continuous when it sticks; relative to ``caps.center``."""
        x = self._contact_x(u)
        g, n = caps.gap(x.reshape(-1, 3))
        g, n = g.reshape(x.shape[:2]), n.reshape(x.shape)
        out = np.full(x.shape, np.nan) if anchors is None else np.array(anchors, float, copy=True)
        if out.shape != x.shape:
            raise ValueError(f"anchors must have shape {x.shape}, got {out.shape}")
        new = (g < self.eps) & ~np.isfinite(out[..., 0])
        d1 = _pen(g[new], self.penalty(), self.eps)[1]                  # φ'(g) ≤ 0: the push-out force
        out[new] = x[new] - (d1 / self.penalty())[:, None] * n[new] - caps.center
        return out

    def _contact_dE(self, u: np.ndarray, caps: Capsule, k: float, facets: np.ndarray, curvature: bool = True):
        """∂φ/∂x (fa, Qf, 3) N/m² and ∂²φ/∂x² (fa, Qf, 3, 3) N/m³ of the contact energy density at the contact
        quadrature points of ``facets``, and their area weights (fa, Qf) m² (``curvature``: include the
        normal's derivative, a negative term, in the frictionless part)."""
        g, nrm, w, dn = self._contact_gaps(u, caps, facets)
        _, d1, d2 = _pen(g, k, self.eps)
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
        return (-(wf[..., None] * f)).sum(axis=(0, 1)), float(max(0.0, -g.min())), int(np.sum((g < self.eps) | stuck))

    def residual_tangent(self, u: np.ndarray, caps: Capsule | None, k: float, need_K: bool = True,
                         project: bool = False):
        """Residual r (n,) N and tangent K_t (csr, n × n, N/m) of Π at ``u`` (P, 3); K_t is None when not
        ``need_K``. ``project``: replace the material tangent A (9 × 9) at every quadrature point where it is
        indefinite by its positive semi-definite projection (projected Newton, Teran, Sifakis, Irving & Fedkiw,
        SCA 2005), so K_t is positive definite. Raises ``FloatingPointError`` when an element is inverted."""
        F = self.deformation(u)
        Finv, J = inv_det3(F)
        if np.any(J <= 0):
            raise FloatingPointError("inverted element (det F <= 0)")
        lnJ = np.log(J)
        FinvT = np.swapaxes(Finv, 2, 3)
        gent = self._gent_factor(F)             # None (neo-Hookean) or g = 1/(1 − (I1 − 3)/Jm) (E, Q)
        if gent is None:
            P = self._mu4 * (F - FinvT) + (self.lam * lnJ)[..., None, None] * FinvT
        else:
            P = self._mu4 * (gent[..., None, None] * F - FinvT) + (self.lam * lnJ)[..., None, None] * FinvT
        E, Q = lnJ.shape
        G = self.grad
        Gf = G.transpose(0, 2, 1, 3).reshape(E, 10, 3 * Q)                                 # [e, a, (q, J)]
        re = Gf @ (P * self.w[..., None, None]).transpose(0, 1, 3, 2).reshape(E, 3 * Q, 3)   # Σ_qJ w ∇N_a,J P_iJ
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
                rc = _gram(Nw, f)                                                           # (fa, 10, 3)
                vd = (3 * self._cf_dofs[fa][:, :, None] + np.arange(3)).reshape(len(fa), 30)
                r += np.bincount(vd.ravel(), weights=rc.ravel(), minlength=self.n)
                NN = (Nw[..., :, None] * Nf[..., None, :]).reshape(len(fa), -1, 100)       # [f, q, (a, b)]
                Kc = _gram(NN, Hx.reshape(len(fa), -1, 9)).reshape(len(fa), 10, 10, 3, 3)   # [f, a, b, i, k]
                cdata = (vd, Kc.transpose(0, 1, 3, 2, 4).reshape(len(fa), 30, 30))
        if not need_K:
            return r, None
        H = (G @ Finv).reshape(E, Q, 30)                                                  # ∇N_a,J F⁻¹_Jm
        lw = self.lam * self.w
        c1w = (self.mu - self.lam * lnJ) * self.w
        T3 = _gram(H * lw[..., None], H)
        Y = _gram(H * c1w[..., None], H).reshape(E, 10, 3, 10, 3)
        muw = self.mu * self.w if gent is None else self.mu * gent * self.w
        T1 = (G * muw[..., None, None]).transpose(0, 2, 1, 3).reshape(E, 10, 3 * Q) @ np.swapaxes(Gf, 1, 2)
        Ke = T3.reshape(E, 10, 3, 10, 3) + Y.transpose(0, 1, 4, 3, 2)
        Ke += T1[:, :, None, :, None] * np.eye(3)[None, None, :, None, :]
        if gent is not None:    # Gent's stiffening: (2μg²/Jm) F_iJ F_kL, i.e. Σ_q w c (∇N_a·F_i)(∇N_b·F_k)
            M = (G @ np.swapaxes(F, 2, 3)).reshape(E, Q, 30)                              # ∇N_a,J F_iJ
            cw = (2.0 / self.Jm) * self.mu * gent ** 2 * self.w
            Ke += _gram(M * cw[..., None], M).reshape(E, 10, 3, 10, 3)
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
        eigenvalues to 0 (only quadrature points with a negative eigenvalue are touched). ``gent`` (E, Q): the
        Gent factor g of :meth:`_gent_factor` (None: neo-Hookean)."""
        E, Q = lnJ.shape
        S = np.einsum("eqJk,eqLi->eqiJkL", Finv, Finv).reshape(E, Q, 9, 9)
        f = np.swapaxes(Finv, 2, 3).reshape(E, Q, 9)
        A = (self._mu4 * np.eye(9) + (self.mu - self.lam * lnJ)[..., None, None] * S
             + self._lam4 * f[..., :, None] * f[..., None, :])
        if gent is not None:    # μ(g − 1) I + (2μg²/Jm) F ⊗ F on top of the neo-Hookean tangent
            fF = F.reshape(E, Q, 9)
            A = A + (self._mu4 * (gent - 1.0)[..., None, None]) * np.eye(9) \
                + ((2.0 / self.Jm) * self.mu * gent ** 2)[..., None, None] * fF[..., :, None] * fF[..., None, :]
        ev, V = np.linalg.eigh(A)
        out = np.zeros((E, 10, 3, 10, 3))
        bad = ev[..., 0] < 0
        if not np.any(bad):
            return out
        e_idx = np.flatnonzero(bad.any(axis=1))
        evb, Vb = ev[e_idx], V[e_idx]
        neg = np.minimum(evb, 0.0) * bad[e_idx][..., None]                      # A₊ − A = −V min(ev,0) Vᵀ
        ne = len(e_idx)
        D = -(Vb * neg[..., None, :]) @ np.swapaxes(Vb, -1, -2)                 # [e, q, (i, J), (k, L)]
        G = self.grad[e_idx]                                                    # [e, q, b, L]
        DG = (D.reshape(ne, Q, 27, 3) @ np.swapaxes(G, -1, -2)).reshape(ne, Q, 3, 3, 3, 10)    # [e, q, i, J, k, b]
        Gw = (G * self.w[e_idx][..., None, None]).transpose(0, 2, 1, 3).reshape(ne, 10, 3 * Q)  # [e, a, (q, J)]
        K = Gw @ DG.transpose(0, 1, 3, 2, 4, 5).reshape(ne, 3 * Q, 90)                         # [e, a, (i, k, b)]
        out[e_idx] = K.reshape(ne, 10, 3, 3, 10).transpose(0, 1, 2, 4, 3)
        return out

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
        C = _gram(F, F)
        Egl = 0.5 * (C - np.eye(3))
        return float(minJ.min()), int(np.count_nonzero(minJ <= 0)), float(np.linalg.eigvalsh(Egl).max())

    def probe_matrix(self, x: np.ndarray) -> sp.csr_matrix:
        """Interpolation matrix (k, P): values of the P2 field at points ``x`` (k, 3) m. Points just outside the
        faceted boundary use the nearest element's polynomial (a tiny extrapolation), as in
        :meth:`flexsheet.fem.solver.FemModel.probe`. Points beyond the symmetry planes must be mirrored first."""
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
        """Contact penalty per unit area, N/m³: ``penalty_scale``·E/h (default :data:`PENALTY_SCALE`), h the fine
        contact-facet size. With the smoothed onset (:func:`_pen`) a point carries pressure p at the stand-off
        g = ε − √(2εp/κ) for p < κε/2 (≈ 290·E on the 3.4 mm mesh) and penetrates (p − κε/2)/κ beyond: the
        geometric contact error is at most ε = 20 µm plus that penetration."""
        return self.penalty_scale * self.E_ref / (mesh_h or self.h_contact)

    def dof_points(self, node_mask: np.ndarray) -> np.ndarray:
        """Extend a mask over the mesh nodes (N,) bool to the DOF points (P,) bool: an edge midpoint is
        marked when both its end nodes are (e.g. a support given on the mesh nodes)."""
        node_mask = np.asarray(node_mask, bool)
        n0 = self.skmesh.p.shape[1]
        if node_mask.shape != (n0,):
            raise ValueError(f"node_mask must have shape ({n0},), got {node_mask.shape}")
        return np.concatenate([node_mask, np.all(node_mask[self.skmesh.edges], axis=0)])


def inv_det3(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse (..., 3, 3) and determinant (...) of a stack of 3 × 3 matrices ``F`` (..., 3, 3), by cofactors
    (Cramer's rule): a few times faster than ``np.linalg.inv``/``det``, which call LAPACK per matrix. The
    inverse of a singular matrix has inf/nan entries (no error); callers check the determinant."""
    a, b, c = F[..., 0, 0], F[..., 0, 1], F[..., 0, 2]
    d, e, f = F[..., 1, 0], F[..., 1, 1], F[..., 1, 2]
    g, h, i = F[..., 2, 0], F[..., 2, 1], F[..., 2, 2]
    c00, c01, c02 = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * c00 + b * c01 + c * c02
    adj = np.stack([np.stack([c00, c * h - b * i, b * f - c * e], axis=-1),
                    np.stack([c01, a * i - c * g, c * d - a * f], axis=-1),
                    np.stack([c02, b * g - a * h, a * e - b * d], axis=-1)], axis=-2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return adj / det[..., None, None], det


def _gram(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Σ_k A[..., k, x] B[..., k, y]: (..., X, Y) from (..., K, X) and (..., K, Y), as a batched BLAS matmul
    (np.einsum without ``optimize`` loops in C and is ~10× slower on these element batches)."""
    return np.swapaxes(A, -1, -2) @ B


def _pen(g: np.ndarray, k: float, eps: float):
    """Smoothed penalty φ(g) and its derivatives φ', φ'' for gaps ``g`` (m): k/(6ε)(ε − g)³ on [0, ε), the
    matching quadratic k/2 g² − kε/2 g + kε²/6 below 0 (C², so Newton sees no kink), 0 above ε."""
    g = np.asarray(g, float)
    inside = g < 0
    mid = (g >= 0) & (g < eps)
    phi = np.where(inside, 0.5 * k * g * g - 0.5 * k * eps * g + k * eps * eps / 6.0,
                   np.where(mid, k / (6 * eps) * (eps - g) ** 3, 0.0))
    d1 = np.where(inside, k * g - 0.5 * k * eps, np.where(mid, -k / (2 * eps) * (eps - g) ** 2, 0.0))
    d2 = np.where(inside, k, np.where(mid, k / eps * (eps - g), 0.0))
    return phi, d1, d2


def _cholesky(K: sp.spmatrix):
    """Sparse Cholesky of the symmetric ``K`` (:func:`flexsheet.fem.solver.factor`, CHOLMOD): the factor (with
    ``.solve(b)``) when K is positive definite, None when it is not (CHOLMOD stops at the first non-positive
    pivot). On a loaded 3.4 mm-mesh tangent (16 596 DOF): 0.69 s and 9.9 ms per solve, against
    3.8 s and 22 ms for the simplicial QDLDL used before, and 4.1 s for SuperLU in symmetric mode."""
    from flexsheet.fem.solver import NotPositiveDefinite, factor

    try:
        return factor(K, "cholmod")
    except NotPositiveDefinite:
        return None


def _pcg(A: sp.csr_matrix, b: np.ndarray, precond, rtol: float, maxiter: int) -> tuple[np.ndarray | None, int]:
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


#: inexact Newton (Newton–Krylov): the step solves K δ = −r by PCG to this relative residual, preconditioned by
#: the last Cholesky factorisation; a fresh factorisation only when PCG fails (Knoll & Keyes, J. Comput. Phys.
#: 193, 2004, "lagged" preconditioner). The step is then not exact, but the residual r is, so the converged state
#: is the same within the tolerances. A PCG iteration is two triangular solves, ~1/70 of a CHOLMOD factorisation
#: here, so PCG gives up after 20 (3.4 mm mesh, 47.5 → 50 mm step, same 22 Newton iterations: 45 s of CPU at 20,
#: 59 s at 60, 47 s never using PCG).
PCG_RTOL = 1e-4
PCG_MAXITER = 20


def _pcg_step(Kc: sp.csr_matrix, rf: np.ndarray, state: dict) -> tuple[np.ndarray | None, bool]:
    """Newton step δ (n,) from K δ = −r by PCG preconditioned with ``state["pc"]``, or None; and whether PCG
    met negative curvature (K is then not positive definite: no factorisation of it is tried)."""
    if state.get("pc_n") != Kc.shape[0]:          # a preconditioner from another model: not usable
        return None, False
    x, its = _pcg(Kc, -rf, state["pc"].solve, PCG_RTOL, PCG_MAXITER)
    if x is not None and np.all(np.isfinite(x)) and float(rf @ x) < 0:
        state["pcg"] = state.get("pcg", 0) + 1
        return x, False
    return None, its < 0


def _tangent_step(Kc: sp.csr_matrix, rf: np.ndarray, state: dict, projected: bool) -> tuple[np.ndarray | None, bool]:
    """(Newton step δ (n,) solving Kc δ = −rf, whether PCG gave it). PCG with the lagged factorisation
    (:func:`_pcg_step`) first, else a fresh factorisation that becomes the next preconditioner. On the true tangent
    (``projected`` False) returns (None, False) when Kc is not positive definite (PCG met negative curvature, or
    the Cholesky meets a non-positive pivot): the caller then takes the projected tangent. On the projected
    (semi-definite) tangent, rounding can leave it not quite positive definite: a diagonal shift, ×100 per try (at
    most 3 more factorisations; each ~1 s on 20k+ DOF); ``FloatingPointError`` if it is still not positive
    definite then (:func:`solve_path_capsule` halves the load step on it)."""
    if state.get("pc") is not None:         # lagged factorisation as preconditioner (one PCG solve)
        x, indefinite = _pcg_step(Kc, rf, state)
        if x is not None:
            return x, True
        if indefinite and not projected:
            return None, False
    state["factorisations"] = state.get("factorisations", 0) + 1
    fac = _cholesky(Kc)
    if fac is None and not projected:
        return None, False
    dmax = float(np.abs(Kc.diagonal()).max())
    shift = 1e-4 * dmax
    while fac is None and shift <= 1.0 * dmax:
        state["factorisations"] += 1
        fac = _cholesky(Kc + shift * sp.identity(Kc.shape[0], format="csr"))
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
#: direction, 3.5 % per iteration at the azimuth-10° stall, docs/fem.md); from then on :func:`_newton` takes the
#: true tangent with a diagonal shift instead (:func:`_shifted_step`).
CRAWL_ITERS = 4
CRAWL_RATIO = 0.9
#: the diagonal shift's first and largest try, × max |diag K| (Nocedal & Wright, *Numerical Optimization*, 2nd
#: ed., alg. 3.3, ×10 per try); at the azimuth-10° stall 1e-6 sufficed and 23 of 47 iterations needed none
SHIFT_MIN, SHIFT_MAX = 1e-8, 1e-3


def _shifted_step(Kc: sp.csr_matrix, rf: np.ndarray, state: dict) -> np.ndarray | None:
    """Newton step δ (n,) from (Kc + μ I) δ = −rf with the smallest μ ∈ {SHIFT_MIN, …, SHIFT_MAX}·max |diag Kc|
    (×10, starting a tenth below the last μ that worked) for which the sparse Cholesky succeeds (Nocedal &
    Wright alg. 3.3: a descent direction that keeps the true tangent's curvature, unlike the element-wise
    projection); None when even SHIFT_MAX does not make it positive definite (the caller takes the projected
    tangent). The factorisation becomes the PCG preconditioner; ``state["shifted"]`` counts these steps."""
    dmax = float(np.abs(Kc.diagonal()).max())
    mu = max(SHIFT_MIN, state.get("mu", SHIFT_MIN) / 10.0)
    eye = sp.identity(Kc.shape[0], format="csr")
    while mu <= SHIFT_MAX * (1 + 1e-9):
        state["factorisations"] = state.get("factorisations", 0) + 1
        fac = _cholesky(Kc + (mu * dmax) * eye)
        if fac is not None:
            state["pc"], state["pc_n"], state["mu"] = fac, Kc.shape[0], mu
            state["shifted"] = state.get("shifted", 0) + 1
            return -fac.solve(rf)
        mu *= 10.0
    return None


def _newton(model: HyperelasticModel, u: np.ndarray, caps: Capsule, k: float, iters: int, tol_u: float,
            tol_r: float, log, state: dict | None = None, max_step: float = 0.001,
            shifted: bool = False) -> tuple[np.ndarray, int, bool]:
    """Minimise Π from ``u``; returns (u, iterations, converged). ``state`` (dict) carries between calls the
    last positive-definite factorisation (``"pc"``, the PCG preconditioner, and ``"pc_n"``, its size), the last
    diagonal shift that factorised (``"mu"``, × max |diag K|), and counters (``"projected"``: steps on the
    projected tangent, ``"shifted"``: steps on the shifted true tangent, ``"factorisations"``, ``"pcg"``: steps
    solved by PCG). Where the true tangent is not positive definite the step is on the projected
    tangent, until Newton crawls there (:data:`CRAWL_ITERS`): then, for the rest of this call, on the true tangent
    with a diagonal shift (:func:`_shifted_step`), which crosses the limit points the projection cannot
    (``shifted=True``: from the first iteration, for a call that continues one that ended so;
    ``state["ended_shifted"]`` says how this one ended). Raises
    ``FloatingPointError`` when the line search fails or the projected tangent stays singular
    (:func:`_tangent_step`)."""
    state = {} if state is None else state
    free = model.free
    pi = model.energy(u, caps, k)
    if not math.isfinite(pi):
        raise FloatingPointError("start point has inverted elements")
    rn_prev = math.inf
    # crawl: consecutive projected iterations whose residual is above CRAWL_RATIO of the one before (counted as
    # the iteration starts, so the CRAWL_ITERS-th is still projected); shifted: true tangent plus a shift from the
    # next iteration on, for the rest of this call
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
            delta, from_pcg = _shifted_step(Kc, rf, state), False
        if delta is None:           # not positive definite (far from equilibrium): projected tangent, this step
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
            if from_pcg:            # maybe only PCG's inexactness: one exact step before calling it stagnation
                state["pc"] = None
                rn_prev = rn
                continue
            return u, it, rn < 10 * tol_r
        rn_prev = rn
    return u, iters, False


def _newton_resumed(m: HyperelasticModel, guess: np.ndarray, caps: Capsule, k: float, iters: int, tol_u: float,
                    tol_r: float, nstate: dict) -> tuple[np.ndarray | None, int, bool, np.ndarray | None]:
    """One load step's Newton solve from ``guess``; a call that runs out of ``iters`` iterations, not failed
    (e.g. a snap-through still under way), is continued from where it got to, in the mode it ended in, up to
    :data:`RESUME_MAX` more calls, rather than restarting a halved step from the last converged state (nh-7).
    Returns (u or None when the line search failed, iterations over all calls, converged, last iterate or
    None)."""
    its_total, u_last = 0, None
    try:
        u_new, its, conv = _newton(m, guess, caps, k, iters, tol_u, tol_r, None, nstate)
        u_last = u_new
        for _ in range(RESUME_MAX):
            if conv or its < iters:
                break
            its_total += its
            u_new, its, conv = _newton(m, u_new, caps, k, iters, tol_u, tol_r, None, nstate,
                                       shifted=nstate.get("ended_shifted", False))
            u_last = u_new
    except FloatingPointError:
        u_new, its, conv = None, iters, False
    return u_new, its_total + its, conv, u_last


def solve_path(model: HyperelasticModel, angle: float, depths, finger_radius: float, step: float = 0.001,
               iters: int = 30, tol_u: float = 1e-6, tol_r: float | None = None, log=None,
               substeps_max: int = 3, contact: str = DEFAULT_CONTACT) -> list[PathState]:
    """Push the capsule finger radially into the cylinder at azimuth ``angle`` (rad, :func:`capsule_at` on
    ``model.mesh``'s radius and centre) through ``depths`` (m, ascending, ≥ 0); see :func:`solve_path_capsule`
    for the load stepping, the return value and the errors raised."""
    if not math.isfinite(angle):
        raise ValueError(f"angle must be finite, got {angle!r}")
    m = model
    return solve_path_capsule(model, lambda d: capsule_at(angle, d, finger_radius, m.mesh.radius, m.mesh.center),
                              depths, step, iters, tol_u, tol_r, log, substeps_max,
                              label=f"angle {math.degrees(angle):.1f} deg", contact=contact)


def _check_path_args(depths, step: float, capsule, contact: str) -> np.ndarray:
    """``depths`` as an array, after :func:`solve_path_capsule`'s arguments are checked (``ValueError``)."""
    depths = np.asarray(depths, float)
    if depths.ndim != 1 or len(depths) == 0 or not np.all(np.isfinite(depths)) or np.any(depths < 0):
        raise ValueError(f"depths must be a non-empty 1-D array of finite values >= 0 m, got {depths!r}")
    if np.any(np.diff(depths) < 0):
        raise ValueError("depths must be ascending")
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"step must be > 0 m, got {step!r}")
    if not callable(capsule):
        raise ValueError(f"capsule must be a callable depth -> Capsule, got {type(capsule).__name__}")
    if contact not in CONTACT_LAWS:
        raise ValueError(f"contact must be one of {CONTACT_LAWS}, got {contact!r}")
    return depths


class _PathPush:
    """:func:`solve_path_capsule`'s walk along the push: the iterate ``u`` at depth ``d_cur``, the previous one
    (``u_prev`` at ``d_prev``, for the extrapolated guess), the sticking anchors, Newton's resume state and the
    current load step size."""

    def __init__(self, m: HyperelasticModel, capsule, sticking: bool, step: float, iters: int, tol_u: float,
                 tol_r: float | None, substeps_max: int, label: str, log):
        self.m, self.capsule, self.sticking = m, capsule, sticking
        self.iters, self.tol_u, self.substeps_max, self.label, self.log = iters, tol_u, substeps_max, label, log
        self.anchors = None
        self.k = m.penalty()
        self.tol_r = tol_r if tol_r is not None else 1e-6 * m.E_ref * m.h_contact ** 2 * 10
        self.u = np.zeros((len(m.points), 3))
        self.u_prev, self.d_prev = None, 0.0
        self.d_cur = 0.0
        self.nstate: dict = {}
        self.step_now = step

    def caps(self, d: float):
        """The finger at depth ``d`` (with the anchors, sticking)."""
        caps = self.capsule(d)
        if self.sticking:
            caps = replace(caps, anchors=self.anchors)
        return caps

    def load_step(self, target: float):
        """One load step toward ``target`` m, halved on a failed Newton solve (module doc of
        :func:`solve_path_capsule`): returns (Newton iterations, converged)."""
        m = self.m
        h = min(self.step_now, target - self.d_cur)
        u_last = None
        its_total = 0
        if self.sticking:                # points touching the finger at the last converged state stick to it
            self.anchors = m.stick_anchors(self.u, self.capsule(self.d_cur), self.anchors)
        for _ in range(self.substeps_max + 1):
            d_new = self.d_cur + h
            caps = self.caps(d_new)
            guess = self.u
            if self.u_prev is not None and self.d_cur > self.d_prev:
                g2 = self.u + (self.u - self.u_prev) * (h / (self.d_cur - self.d_prev))
                if math.isfinite(m.energy(g2, None, 0.0)):
                    guess = g2
            u_new, its, conv, u_try = _newton_resumed(m, guess, caps, self.k, self.iters, self.tol_u, self.tol_r,
                                                      self.nstate)
            u_last = u_try if u_try is not None else u_last
            its_total += its
            if conv:
                break
            h *= 0.5
            self.step_now = min(self.step_now, h)
        else:
            if u_last is None:
                raise RuntimeError(f"Newton failed at depth {self.d_cur * 1e3:.2f} mm -> {d_new * 1e3:.2f} mm "
                                   f"({self.label})")
            u_new = u_last          # give up on this step: keep its last iterate, flagged not converged
            if self.log:
                self.log(f"  Newton did not converge at {d_new * 1e3:.2f} mm ({self.label})")
        self.u_prev, self.d_prev = self.u, self.d_cur
        self.u, self.d_cur = u_new, d_new
        return its_total, conv

    def state(self, its_total: int, conv_all, t0: float) -> PathState:
        """The :class:`PathState` at the current depth."""
        st = _path_state(self.m, self.u, self.caps(self.d_cur), self.k, self.d_cur, its_total, conv_all, t0)
        if self.sticking:
            st.extra["anchors"] = self.anchors.copy()
        return st


def solve_path_capsule(model: HyperelasticModel, capsule, depths, step: float = 0.001, iters: int = 30,
                       tol_u: float = 1e-6, tol_r: float | None = None, log=None, substeps_max: int = 3,
                       label: str = "path", contact: str = DEFAULT_CONTACT) -> list[PathState]:
    """Push a rigid finger given by ``capsule(depth) -> Capsule`` (depth m; any object, any push direction)
    through ``depths`` (m, ascending, ≥ 0), load steps of at most ``step`` m; returns one :class:`PathState`
    per requested depth (``force`` along the capsule's direction, full-body force with the symmetry planes).
    A Newton call that runs out of ``iters`` iterations (not failed: e.g. a snap-through under way) is continued
    from its last iterate at the same depth, up to :data:`RESUME_MAX` more calls (nh-7; a step stuck for good
    thus costs (1 + RESUME_MAX)× the iterations before each halving). A load step whose Newton solve fails
    otherwise, or still has not converged then, is halved (up to ``substeps_max`` times) and the
    load steps after it keep the halved size (the path got hard: on the 3.4 mm cylinder mesh a 2.5 mm step past
    47.5 mm spent 60 iterations per try before halving, nh-5); if it still fails, its last iterate is kept and
    the state is flagged ``converged=False`` (bounded time; the caller decides).

    ``contact`` (a modelling choice, :data:`CONTACT_LAWS`): ``"frictionless"`` — non-penetration only, the
    surface slides freely on the finger; ``"sticking"`` — a fingertip that does not slip on soft tissue
    (infinite friction): a contact quadrature point that is inside the finger at a converged load step is stuck
    to the finger point nearest to it (:meth:`HyperelasticModel.stick_anchors`) and from the next load step
    on follows the finger (penalty k/2 |x − anchor|², the same k; "inside" is gap < ε, the penalty's onset,
    :meth:`HyperelasticModel.stick_anchors`); anchors are added after every load step,
    never released (a monotone push). Raises ``ValueError`` on bad depths or an unknown ``contact`` and
    ``RuntimeError`` when a step has no valid iterate at all."""
    depths = _check_path_args(depths, step, capsule, contact)
    walk = _PathPush(model, capsule, contact == "sticking", step, iters, tol_u, tol_r, substeps_max, label, log)
    out = []
    for target in depths:
        t0 = time.perf_counter()
        its_total = 0
        conv_all = True
        while walk.d_cur < target - 1e-12:
            its, conv = walk.load_step(target)
            its_total += its
            conv_all &= conv
        st = walk.state(its_total, conv_all, t0)
        out.append(st)
        if log:
            log(f"  depth {walk.d_cur * 1e3:5.1f} mm: F={st.force:.4f} N, {its_total} Newton its, "
                f"min det F={st.min_detF:.3f}, inverted={st.inverted}, pen={st.penetration * 1e3:.3f} mm, "
                f"{st.seconds:.1f} s")
    return out


def _path_state(m: HyperelasticModel, u: np.ndarray, caps: Capsule, k: float, depth: float, iterations: int,
                converged: bool, t0: float) -> PathState:
    """The :class:`PathState` of displacement ``u`` (P, 3) m under ``caps`` at ``depth`` m: the finger force
    (full body, the symmetry planes' mirror images added), the element checks; ``t0`` its start (perf_counter)."""
    fvec, pen, ncon = m.contact_force(u, caps, k)
    fvec = m.sym_factor * fvec * np.array([1.0, 0.0 if m.sym_y else 1.0, 0.0 if m.sym_z else 1.0])
    minJ, ninv, emax = m.checks(u)
    return PathState(float(depth), u.copy(), float(fvec @ caps.direction), fvec, int(iterations), bool(converged),
                     minJ, ninv, emax, pen, ncon, time.perf_counter() - t0)


def stable_states(model: HyperelasticModel, capsule, states: list[PathState], step: float = 0.0025,
                  iters: int = 30, log=None) -> tuple[list[PathState], np.ndarray, np.ndarray]:
    """Per depth the lower-energy of the loading state (``states``, :func:`solve_path_capsule`) and the
    unloaded one (:func:`unload_sweep`): where a push is bistable, the stable branch rather than the metastable
    one the loading path may stay on (both are equilibria under the same finger; the lower total potential Π
    is the one a perturbation cannot leave). The unloaded state is taken only when it converged and lies
    farther than :data:`BRANCH_MEET_TOL` from the loading one (else they are one state). Returns (states, branch
    (D,) int: 1 where the unloaded state was taken, energies (D, 2) J: Π of the loading and of the unloaded
    state at each depth). Frictionless contact only. Costs a Newton solve per load step (on the 3.4 mm half
    model at 5° and 10°, 41 min of one core each with another solve beside it, about as long as the loading path:
    the unloading steps start from the previous state with no predictor and need up to ~35 iterations at
    5–20 mm)."""
    sw = unload_sweep(model, capsule, states, step=step, iters=iters, log=log)
    out, branch = [], np.zeros(len(states), np.int64)
    energies = np.array([[un.extra["energy_loading"], un.extra["energy"]] for un in sw])
    for j, (ld, un) in enumerate(zip(states, sw, strict=True)):
        take = (un.converged and un.extra["energy"] < un.extra["energy_loading"]
                and float(np.abs(un.u - ld.u).max()) > BRANCH_MEET_TOL)
        out.append(un if take else ld)
        branch[j] = int(take)
    return out, branch, energies


#: version of :func:`stable_states`' definition (cache keys of the stable paths and the snapshot tables built
#: from them); bump when it changes
UNLOAD_VERSION = "unload-2"
#: two states of one push lie on the same branch when no DOF point is farther apart than this (m): 20× the
#: Newton tolerance on the step, far below the 0.7 mm target (:func:`stable_states`)
BRANCH_MEET_TOL = 2e-5


def unload_sweep(model: HyperelasticModel, capsule, states: list[PathState], step: float = 0.0025,
                 iters: int = 30, tol_u: float = 1e-6, tol_r: float | None = None, log=None,
                 substeps_max: int = 3) -> list[PathState]:
    """The equilibria of a frictionless push found by *unloading*: from the deepest of ``states`` (a loading
    path, :func:`solve_path_capsule`, ascending depths) the finger is withdrawn through the same depths, load
    steps of at most ``step`` m, each Newton solve started from the last unloaded state (halved on failure as in
    :func:`solve_path_capsule`). A push into a soft body can be bistable: the loading path stays on a
    metastable branch (a fold beside the finger not yet snapped) that unloading, starting past the snap, does
    not visit. Returns one :class:`PathState` per depth of ``states`` (ascending), with
    ``extra["energy"]`` (J, Π of the unloaded state) and ``extra["energy_loading"]`` (Π of the loading state
    there); the deepest state is the loading one itself (taken as stable: the push is assumed past its snaps
    there; the 50 mm states of 5°–20° on the 3.4 mm mesh are). The sweep runs to the shallowest depth: the two
    branches coincide past the snap (at 10° on the 3.4 mm mesh from 45 mm) and part only below it, so meeting
    the loading path says nothing about the depths still to come. Frictionless contact only (a sticking
    finger's anchors depend on the loading history). Raises ``ValueError`` on an empty or unsorted ``states``,
    ``RuntimeError`` when a step has no valid iterate at all."""
    if not states:
        raise ValueError("states must be a non-empty loading path")
    if any("anchors" in s.extra for s in states):
        raise ValueError("unload_sweep needs a frictionless push: these states carry a sticking finger's anchors")
    d = np.array([s.depth for s in states])
    if np.any(np.diff(d) <= 0):
        raise ValueError(f"states must have ascending depths, got {d.tolist()}")
    m = model
    k = m.penalty()
    tol_r = tol_r if tol_r is not None else 1e-6 * m.E_ref * m.h_contact ** 2 * 10
    out: list[PathState | None] = [None] * len(states)
    top = states[-1]
    e_top = m.energy(top.u, capsule(top.depth), k)
    out[-1] = replace(top, extra={**top.extra, "energy": e_top, "energy_loading": e_top})
    u, d_cur = top.u.copy(), top.depth
    nstate: dict = {}
    for j in range(len(states) - 2, -1, -1):
        t0 = time.perf_counter()
        target, its_total, conv_all = states[j].depth, 0, True
        h_max = step
        while d_cur > target + 1e-12:
            h = min(h_max, d_cur - target)
            u_last = None
            for _ in range(substeps_max + 1):
                d_new = d_cur - h
                u_new, its, conv, u_try = _newton_resumed(m, u, capsule(d_new), k, iters, tol_u, tol_r, nstate)
                u_last = u_try if u_try is not None else u_last
                its_total += its
                if conv:
                    break
                h *= 0.5
                h_max = min(h_max, h)
            else:
                if u_last is None:
                    raise RuntimeError(f"Newton failed unloading from {d_cur * 1e3:.2f} mm to {d_new * 1e3:.2f} mm")
                u_new = u_last
            conv_all &= conv
            u, d_cur = u_new, d_new
        caps = capsule(target)
        st = _path_state(m, u, caps, k, target, its_total, conv_all, t0)
        e_un, e_ld = m.energy(u, caps, k), m.energy(states[j].u, caps, k)
        st.extra.update(energy=e_un, energy_loading=e_ld)
        out[j] = st
        if log:
            gap = float(np.abs(u - states[j].u).max())
            log(f"  unloading {target * 1e3:5.2f} mm: {its_total} Newton its, Π {e_un:.6g} J against the loading "
                f"path's {e_ld:.6g} J, {gap * 1e3:.3f} mm apart, {st.seconds:.1f} s")
    return out
