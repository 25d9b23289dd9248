"""The pushed sheet's true shape: a pre-tensioned, geometrically nonlinear membrane indented by a rounded
fingertip, solved by finite elements (pure: numpy + scipy + scikit-fem).

This is the twin's *physics* of the sheet, independent of the estimators' models: it is not the renderer's
4-triangle or "fine" correction model, nor the sine-series :class:`flexsheet.model.sheet.Membrane`. The world
twin publishes it (``/world/sheet``); estimators never call it.

**Model** (stated here; the paper gives none). The 240 × 240 × 1 mm urethane sheet in its stretched,
pre-tensioned state occupies the rectangle |u| ≤ a, |v| ≤ b of its own frame (``u`` along ``axis_u``, the
clamp-to-clamp direction; ``v`` along ``axis_v``; a = the measured clamp half span, b = half the sheet width;
the necking of the free edges is neglected). Unknowns: the in-plane displacement (u₁, u₂) and the out-of-plane
deflection w (m, positive along −normal, away from the user).

* Kinematics: Föppl–von Kármán membrane strain (moderate rotations, large deflection)
  E_αβ = ½(u_α,β + u_β,α) + ½ w,α w,β (Timoshenko & Woinowsky-Krieger, *Theory of Plates and Shells*, §96;
  Ventsel & Krauthammer, *Thin Plates and Shells*, §7). Bending is neglected (membrane limit:
  D = E t³/12(1 − ν²) ≈ 2·10⁻⁴ N·m against T·a² ≈ 1.5 N·m).
* Pre-stress: the clamps' pull N⁰ = diag(T_u, T_v), T_u = the uniaxial neo-Hookean tension of
  :func:`flexsheet.model.tension.tension` at the true stretch (clamp strain + the truth's pre-strain) with the
  truth's Young's modulus, and T_v = β·T_u with the truth's tension ratio β (free-edge contraction and clamp
  misalignment, :mod:`flexsheet.twin.truth`). It is balanced by dead tractions on the free edges, which
  cancels the N⁰ : ∇u term of the energy.
* Increment: St Venant–Kirchhoff plane stress on top of the pre-stress, N = (E t / (1 − ν²))·((1 − ν) E +
  ν tr(E) I), ν = 0.5 (incompressible rubber), E = the small-strain Young's modulus.
* Wrinkling (tension-field theory; Pipkin 1986, "The relaxed energy density for isotropic elastic membranes",
  IMA J. Appl. Math. 36; Steigmann 1990, Proc. R. Soc. A 429; FE use: Roddeman et al. 1987, J. Appl. Mech.
  54). A membrane cannot carry compression: a deep push at low stretch pulls the sheet in around the finger,
  and the hoop stress N⁰ + N there would turn compressive (down to −18 N/m against T = 24 N/m at stretch
  0.01, 60 mm). The real 1 mm sheet wrinkles instead: its bending stiffness D ≈ 2.7·10⁻⁴ N·m carries only
  ~D π²/ℓ² ≈ 1 N/m of compression over a wrinkle length ℓ ~ 5 cm (bendability T a²/D ≳ 10³), and without
  relaxation the bending-free model has no minimiser there (Newton wandered in a flat valley). So the
  energy density is Pipkin's relaxed one, in terms of the total strain E_t = E₀ + E (C:E₀ = N⁰) with
  principal values ε₁ ≥ ε₂: taut (ε₂ + ν ε₁ > 0, both principal stresses positive): the St Venant–Kirchhoff
  density above, unchanged; wrinkled (ε₁ > 0 ≥ ε₂ + ν ε₁): ½ E t ε₁², uniaxial tension along the first
  principal direction; slack (ε₁ ≤ 0): 0. The density is C¹; Newton's matrix adds 10⁻⁵·C at the non-taut
  points (tangent only: the equations solved are the relaxed ones). Where the sheet stays taut the solution
  is the unrelaxed one: the renderer's nominal tables at stretch 0.03 and 0.04 are unchanged (< 10⁻⁶ m) at
  every depth ≤ 40 mm and contact; they change only at 50–60 mm with an off-centre contact, most at (72, 72)
  mm: 0.06 / 0.67 mm at 50 / 60 mm (stretch 0.03), 0.001 / 0.10 mm (0.04).
* Boundary conditions: clamped edges u = ±a fixed (u₁ = u₂ = w = 0, the rigid clamps); free edges v = ±b
  traction-free apart from the dead pre-stress traction.
* Load: a rigid spherical fingertip of radius ``finger_radius`` (8 mm) whose apex is at depth S behind the
  flat sheet, at (u₀, v₀); frictionless unilateral contact w ≥ S − ρ + √(ρ² − r²) (r < ρ) by a penalty
  ½ k ∫ ⟨φ − w⟩₊² (k = 10¹¹ N/m³; the residual penetration is reported, ≲ 1 µm).
* Total energy Π = ∫ [½ N⁰ : (∇w ⊗ ∇w) + ½ E : 𝒞 : E + ½ k⟨φ − w⟩₊²] dA (taut; relaxed where wrinkled) is
  minimised by Newton's method with the consistent tangent and an Armijo backtracking line search on Π,
  continuing in depth (each depth starts from the previous solution scaled to the new depth: w ∝ S, u ∝ S²;
  a step that fails is retried in halves).

**Discretisation**: bilinear quadrilaterals (``skfem.ElementQuad1``) for u₁, u₂, w on a tensor-product mesh,
``h_fine`` (4 mm) over the central |u|, |v| ≤ ``fine_extent`` and ~``h_coarse`` (8 mm) outside; 3 × 3 Gauss
points (so the contact cap is sampled every ~1.3 mm). scikit-fem provides the mesh, the basis (shape
functions, gradients, quadrature weights) and the global coordinates; the element matrices of the nonlinear
forms are evaluated with numpy ``einsum`` over all elements at once (the same integrals a ``BilinearForm``
would evaluate, ~20× faster) and solved with SciPy's SuperLU.

**Table**: :mod:`flexsheet.model.sheet_table` solves this once on a grid and interpolates it at 100 Hz.

Units: m, N, N/m, Pa; frames: the sheet's (u, v) as in :mod:`flexsheet.model.sheet`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from flexsheet.model import geometry
from flexsheet.model.checks import check_positive
from flexsheet.model.sheet import clamp_half_span
from flexsheet.model.sheet_prestress import gripped_prestress, taut_floor
from flexsheet.model.tension import SheetMaterial, tension

__all__ = ["FINGER_RADIUS", "SheetPhysics", "SheetFEM", "IndentSolution", "bilinear"]

#: radius of the rigid spherical fingertip, m (an adult index fingertip pad, ~16 mm wide)
FINGER_RADIUS = 0.008


@dataclass(frozen=True)
class SheetPhysics:
    """The sheet's physical parameters for one clamp span (SI).

    ``half_span`` a (m, clamps at u = ±a), ``half_width`` b (m, free edges at v = ±b), ``thickness`` t (m),
    ``young`` E (Pa), ``poisson`` ν, ``tension_u`` T_u (N/m, pre-tension along the clamp line),
    ``tension_ratio`` β = T_v / T_u of a uniform pre-stress, or ``None``: the pre-stress of the sheet gripped
    on its clamp edges, T_u·n(u, v) (:func:`flexsheet.model.sheet_prestress.gripped_prestress`: T_v/T_u ≈
    0.035 at the centre of the square sheet, rising toward the grips), ``finger_radius`` ρ (m), ``penalty`` k
    (N/m³). Raises ``ValueError`` naming the field for a non-positive or non-finite value (ν in [0, 0.5)).
    """

    half_span: float
    half_width: float = geometry.SHEET_SIZE / 2
    thickness: float = geometry.SHEET_THICKNESS
    young: float = 2.46e6
    poisson: float = 0.5
    tension_u: float = 93.5
    tension_ratio: float | None = 1.0
    finger_radius: float = FINGER_RADIUS
    penalty: float = 1e11

    def __post_init__(self) -> None:
        for k in ("half_span", "half_width", "thickness", "young", "tension_u", "finger_radius", "penalty"):
            check_positive(k, getattr(self, k))
        if self.tension_ratio is not None:
            check_positive("tension_ratio", self.tension_ratio)
        if not (math.isfinite(self.poisson) and 0.0 <= self.poisson <= 0.5):
            raise ValueError(f"poisson must be in [0, 0.5], got {self.poisson!r}")

    @property
    def gripped(self) -> bool:
        """Whether the pre-stress is the gripped sheet's plane-stress field (``tension_ratio`` None)."""
        return self.tension_ratio is None

    @classmethod
    def from_truth(cls, truth, stretch: float, size: float = geometry.SHEET_SIZE, **kw) -> SheetPhysics:
        """Physics of the twin's true sheet (``truth``: a :class:`flexsheet.twin.truth.TwinTruth`) held at
        clamp strain ``stretch`` (≥ 0) over the unstretched side ``size`` (m): a = size(1 + stretch)/2, the
        truth's E and thickness t, T_u = :func:`flexsheet.model.tension.tension` at the strain the sheet takes
        between the jaws, stretch·(1 − grip slip) + pre-strain, and the truth's ``tension_ratio`` (None: the
        gripped pre-stress field). ``kw`` overrides fields. Raises ``ValueError`` on a bad stretch."""
        if not (math.isfinite(stretch) and stretch >= 0.0):
            raise ValueError(f"stretch must be finite and >= 0, got {stretch!r}")
        mat = SheetMaterial(young=float(truth.sheet_young), thickness=float(truth.sheet_thickness), size=size)
        strain = stretch * (1.0 - float(truth.grip_slip)) + float(truth.sheet_prestrain)
        args = {"half_span": clamp_half_span(stretch, size), "half_width": size / 2,
                "young": float(truth.sheet_young),
                "thickness": float(truth.sheet_thickness), "tension_u": tension(max(strain, 0.0), mat),
                "tension_ratio": truth.tension_ratio}
        args.update(kw)
        return cls(**args)

    def key(self) -> dict:
        """JSON-able dict of the fields, rounded (for cache keys)."""
        return {k: None if v is None else float(f"{v:.9g}") for k, v in asdict(self).items()}


def _axis_nodes(L: float, h_fine: float, h_coarse: float, extent: float) -> np.ndarray:
    """Sorted nodes on [−L, L]: spacing ``h_fine`` on |x| ≤ extent (a multiple of h_fine, node at 0), then
    about ``h_coarse`` out to the edge."""
    n_f = max(1, int(round(min(extent, L) / h_fine)))
    ext = min(n_f * h_fine, L)
    fine = np.linspace(-ext, ext, 2 * n_f + 1)
    if L - ext < 0.25 * h_fine:
        fine[0], fine[-1] = -L, L
        return fine
    n_c = max(1, int(math.ceil((L - ext) / h_coarse)))
    coarse = np.linspace(ext, L, n_c + 1)[1:]
    return np.concatenate([-coarse[::-1], fine, coarse])


@dataclass
class IndentSolution:
    """One equilibrium. ``x`` (nx,), ``y`` (ny,) node coordinates along u and v (m); ``w`` (nx, ny) deflection
    along −normal (m); ``u1``, ``u2`` (nx, ny) in-plane displacements (m); ``depth`` S (m); ``push_u``,
    ``push_v`` (m); ``force`` contact (or pressure) force (N); ``iterations`` Newton iterations in all;
    ``residual`` final residual norm (N); ``penetration`` largest penalty penetration (m)."""

    x: np.ndarray
    y: np.ndarray
    w: np.ndarray
    u1: np.ndarray
    u2: np.ndarray
    depth: float
    push_u: float
    push_v: float
    force: float
    iterations: int
    residual: float
    penetration: float

    def deflection(self, u, v) -> np.ndarray:
        """w(u, v), m (bilinear = the Q1 interpolant); arrays broadcast; points outside are clamped in."""
        return bilinear(self.x, self.y, self.w, u, v)


def bilinear(x: np.ndarray, y: np.ndarray, F: np.ndarray, u, v) -> np.ndarray:
    """Bilinear interpolation of F (nx, ny) on the tensor grid (x, y) at (u, v) (broadcast; clamped)."""
    u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
    uu = np.clip(u, x[0], x[-1])
    vv = np.clip(v, y[0], y[-1])
    i = np.clip(np.searchsorted(x, uu, side="right") - 1, 0, len(x) - 2)
    j = np.clip(np.searchsorted(y, vv, side="right") - 1, 0, len(y) - 2)
    tx = (uu - x[i]) / (x[i + 1] - x[i])
    ty = (vv - y[j]) / (y[j + 1] - y[j])
    return ((1 - tx) * (1 - ty) * F[i, j] + tx * (1 - ty) * F[i + 1, j] + (1 - tx) * ty * F[i, j + 1]
            + tx * ty * F[i + 1, j + 1])


class SheetFEM:
    """Finite-element model of one :class:`SheetPhysics` (module doc).

    ``h_fine``/``h_coarse`` (m): element sizes inside/outside ``fine_extent`` (m) of the centre.
    Methods: :meth:`solve_indent` (rigid fingertip at a prescribed depth), :meth:`solve_pressure` (a uniform
    pressure patch of prescribed force, for checks against the linear theory). Raises ``ValueError`` on
    bad mesh sizes."""

    def __init__(self, physics: SheetPhysics, h_fine: float = 0.004, h_coarse: float = 0.008,
                 fine_extent: float = 0.084) -> None:
        from skfem import Basis, ElementQuad1, MeshQuad

        for k, v in (("h_fine", h_fine), ("h_coarse", h_coarse), ("fine_extent", fine_extent)):
            check_positive(k, v)
        self.phys = physics
        self.mesh_args = {"h_fine": float(h_fine), "h_coarse": float(h_coarse),
                          "fine_extent": float(fine_extent)}
        a, b = physics.half_span, physics.half_width
        self.x = _axis_nodes(a, h_fine, h_coarse, fine_extent)
        self.y = _axis_nodes(b, h_fine, h_coarse, fine_extent)
        mesh = MeshQuad.init_tensor(self.x, self.y)
        basis = Basis(mesh, ElementQuad1(), intorder=5)           # 3 x 3 Gauss points per element
        self.n_nodes = mesh.p.shape[1]
        self.ix = np.searchsorted(self.x, mesh.p[0] - 1e-12)
        self.iy = np.searchsorted(self.y, mesh.p[1] - 1e-12)
        conn = basis.element_dofs                                   # (4, nel) node indices
        self.conn = conn.T.copy()                                   # (nel, 4)
        # shape values N (nel, 4, nq) and gradients dNx, dNy (nel, 4, nq); weights dx (nel, nq)
        self.N = np.stack([np.asarray(basis.basis[i][0]) for i in range(4)], axis=1)
        g = [basis.basis[i][0].grad for i in range(4)]
        self.dNx = np.stack([gi[0] for gi in g], axis=1)
        self.dNy = np.stack([gi[1] for gi in g], axis=1)
        self.dx = basis.dx
        X = np.asarray(basis.global_coordinates())                 # (2, nel, nq)
        self.qx, self.qy = X[0], X[1]
        nel = self.conn.shape[0]
        # global dof = 3 * node + component (0: u1, 1: u2, 2: w); element dofs (nel, 12) ordered (node, comp)
        edofs = (3 * self.conn[:, :, None] + np.arange(3)[None, None, :]).reshape(nel, 12)
        self.edofs = edofs
        self.ndof = 3 * self.n_nodes
        clamped = np.flatnonzero(np.isclose(np.abs(mesh.p[0]), a, atol=1e-12))
        fixed = np.zeros(self.ndof, bool)
        fixed[(3 * clamped[:, None] + np.arange(3)).ravel()] = True
        self.free = np.flatnonzero(~fixed)
        remap = -np.ones(self.ndof, np.int64)
        remap[self.free] = np.arange(self.free.size)
        r = remap[edofs]
        rows = np.broadcast_to(r[:, :, None], (nel, 12, 12)).ravel()
        cols = np.broadcast_to(r[:, None, :], (nel, 12, 12)).ravel()
        keep = (rows >= 0) & (cols >= 0)
        self._keep = keep
        nf = self.free.size
        lin = rows[keep] * nf + cols[keep]
        uniq, self._slot = np.unique(lin, return_inverse=True)
        self._indptr = np.searchsorted(uniq // nf, np.arange(nf + 1))
        self._indices = (uniq % nf).astype(np.int32)
        self._nnz = uniq.size
        self._rfree = r
        nu = physics.poisson
        A0 = physics.young * physics.thickness / (1.0 - nu * nu)
        self.C = A0 * np.array([[1.0, nu, 0.0], [nu, 1.0, 0.0], [0.0, 0.0, 0.5 * (1.0 - nu)]])
        if physics.gripped:                                         # pre-stress, Voigt (3, nel, nq), N/m
            self._N0 = physics.tension_u * taut_floor(gripped_prestress(self.x, self.y, nu, intorder=5))
        else:
            n0 = np.array([physics.tension_u, physics.tension_ratio * physics.tension_u, 0.0])
            self._N0 = np.broadcast_to(n0[:, None, None], (3,) + self.dx.shape).copy()
        self._E0 = np.einsum("ij,jeq->ieq", np.linalg.inv(self.C), self._N0)   # its elastic strain
        #: tangent-only stiffness fraction added at wrinkled/slack points (Newton's matrix, not the equations)
        self.relax_eta = 1e-5

    # ------------------------------------------------------------------------------------------- kernels
    def _fields(self, U: np.ndarray):
        Ue = U[self.edofs].reshape(-1, 4, 3)                        # (nel, 4, 3)
        def grad(c):
            return (np.einsum("ea,eaq->eq", Ue[:, :, c], self.dNx),
                    np.einsum("ea,eaq->eq", Ue[:, :, c], self.dNy))
        u1x, u1y = grad(0)
        u2x, u2y = grad(1)
        g0, g1 = grad(2)
        w = np.einsum("ea,eaq->eq", Ue[:, :, 2], self.N)
        e = np.stack([u1x + 0.5 * g0 * g0, u2y + 0.5 * g1 * g1, u1y + u2x + g0 * g1])   # Voigt, eng. shear
        Nst = np.einsum("ij,jeq->ieq", self.C, e)
        return g0, g1, w, e, Nst, u1x, u2y

    def _relaxed(self, e: np.ndarray, Nst: np.ndarray, tangent: bool = False):
        """Tension-field relaxation (module doc) at every quadrature point: (W_rel − W₀, S, D, taut) with W
        the strain energy density of the total strain E₀ + e (J/m², less its flat-sheet value W₀), S = T_rel −
        N⁰ the relaxed total membrane stress less the pre-stress (3, nel, nq) N/m (Voigt), D (3, 3, n) =
        Newton's ∂T_rel/∂E (N/m) at the n non-taut points (only with ``tangent``, else None) and the mask of
        taut points (nel, nq), where the relaxed quantities are the plain ones, ½ e:C:e + N⁰:e, Nst and C."""
        p = self.phys
        N0 = self._N0
        Et = e + self._E0
        m = 0.5 * (Et[0] + Et[1])
        r = np.sqrt((0.5 * (Et[0] - Et[1])) ** 2 + (0.5 * Et[2]) ** 2)
        e1, e2 = m + r, m - r
        nu = p.poisson
        taut = e2 + nu * e1 > 0.0                                   # smaller principal stress > 0
        wrinkled = ~taut & (e1 > 0.0)
        # taut: the pre-stressed St Venant-Kirchhoff density (the N0 : grad u part is balanced on the edges)
        dens = 0.5 * np.einsum("ieq,ieq->eq", e, Nst) + np.einsum("ieq,ieq->eq", N0, e)
        S = Nst.copy()
        D = None
        if not np.all(taut):
            Yt = self.C[0, 0] * (1.0 - nu * nu)                     # uniaxial stiffness E·t, N/m
            W0 = 0.5 * np.einsum("ieq,ieq->eq", self._E0, N0)
            rr = np.where(wrinkled, r, 1.0)
            c, sn = (Et[0] - Et[1]) / (2.0 * rr), Et[2] / (2.0 * rr)
            a = np.stack([0.5 * (1.0 + c), 0.5 * (1.0 - c), 0.5 * sn])  # d e1 / dE (Voigt, eng. shear)
            e1p = np.maximum(e1, 0.0)
            Trel = np.where(wrinkled, Yt * e1p, 0.0) * a  # uniaxial along n1, or slack
            soft = ~taut
            dens = np.where(soft, np.where(wrinkled, 0.5 * Yt * e1p ** 2, 0.0) - W0, dens)
            S = np.where(soft[None], Trel - N0, S)
            if tangent:
                a, c, sn, k = a[:, soft], c[soft], sn[soft], np.where(wrinkled[soft], Yt, 0.0)
                bvec = np.stack([sn, -sn, -c])
                D = (k
                     * (np.einsum("in,jn->ijn", a, a)
                        + (e1p[soft] / (4.0 * rr[soft])) * np.einsum("in,jn->ijn", bvec, bvec)))
                D += self.relax_eta * self.C[:, :, None]
        return dens, S, D, taut

    def _energy(self, U: np.ndarray, phi: np.ndarray, load: np.ndarray | None) -> float:
        p = self.phys
        g0, g1, w, e, Nst, u1x, u2y = self._fields(U)
        dens, _, _, _ = self._relaxed(e, Nst)
        N0 = self._N0  # its work on the in-plane gradient: balanced
        dens = dens - N0[0] * u1x - N0[1] * u2y - N0[2] * (e[2] - g0 * g1)
        dens = dens + 0.5 * p.penalty * np.maximum(phi - w, 0.0) ** 2
        if load is not None:
            dens = dens - load * w
        return float(np.sum(dens * self.dx))

    def _assemble(self, U: np.ndarray, phi: np.ndarray, load: np.ndarray | None):
        p = self.phys
        g0, g1, w, e, Nst, _, _ = self._fields(U)
        _, Nst, D, taut = self._relaxed(e, Nst, tangent=True)        # Nst: relaxed stress less the pre-stress
        nel, nq = self.dx.shape
        # B (3, nel, nq, 12): variation of the Voigt strain; G (2, ...): gradient of w
        B = np.zeros((3, nel, nq, 4, 3))
        dNx = self.dNx.transpose(0, 2, 1)                           # (nel, nq, 4)
        dNy = self.dNy.transpose(0, 2, 1)
        Nv = self.N.transpose(0, 2, 1)
        B[0, :, :, :, 0] = dNx
        B[0, :, :, :, 2] = g0[:, :, None] * dNx
        B[1, :, :, :, 1] = dNy
        B[1, :, :, :, 2] = g1[:, :, None] * dNy
        B[2, :, :, :, 0] = dNy
        B[2, :, :, :, 1] = dNx
        B[2, :, :, :, 2] = g0[:, :, None] * dNy + g1[:, :, None] * dNx
        B = B.reshape(3, nel, nq, 12)
        gap = phi - w
        act = p.penalty * (gap > 0.0)
        pres = p.penalty * np.maximum(gap, 0.0)
        N0 = self._N0
        T11 = N0[0] + Nst[0]
        T22 = N0[1] + Nst[1]
        T12 = N0[2] + Nst[2]
        dx = self.dx
        # residual
        r = np.einsum("ieqk,ieq->ek", B, Nst * dx)
        rw = (dNx * ((N0[0] * g0 + N0[2] * g1) * dx)[:, :, None]
              + dNy * ((N0[2] * g0 + N0[1] * g1) * dx)[:, :, None]
              - Nv * (pres * dx)[:, :, None]).sum(axis=1)
        if load is not None:
            rw -= (Nv * (load * dx)[:, :, None]).sum(axis=1)
        r = r.reshape(nel, 4, 3)
        r[:, :, 2] += rw
        # tangent: material Bᵀ C B + geometric (w-w block) + penalty
        CB = np.einsum("ij,jeqk->ieqk", self.C, B)
        if D is not None:  # wrinkled/slack points: the relaxed tangent
            soft = ~taut
            CB[:, soft, :] = np.einsum("ijn,jnk->ink", D, B[:, soft, :])
        CB *= dx[None, :, :, None]
        K = np.einsum("ieqk,ieql->ekl", B, CB).reshape(nel, 4, 3, 4, 3)
        Kw = (np.einsum("eqa,eqb,eq->eab", dNx, dNx, T11 * dx)
              + np.einsum("eqa,eqb,eq->eab", dNy, dNy, T22 * dx)
              + np.einsum("eqa,eqb,eq->eab", dNx, dNy, T12 * dx)
              + np.einsum("eqa,eqb,eq->eab", dNy, dNx, T12 * dx)
              + np.einsum("eqa,eqb,eq->eab", Nv, Nv, act * dx))
        K[:, :, 2, :, 2] += Kw
        R = np.zeros(self.ndof)
        np.add.at(R, self.edofs.ravel(), r.ravel())
        data = np.bincount(self._slot, weights=K.reshape(nel, 12, 12).ravel()[self._keep],
                           minlength=self._nnz)
        nf = self.free.size
        Kf = sp.csr_matrix((data, self._indices, self._indptr), shape=(nf, nf))
        return Kf, R[self.free], pres

    def _phi(self, depth: float, u0: float, v0: float) -> np.ndarray:
        rho = self.phys.finger_radius
        r2 = (self.qx - u0) ** 2 + (self.qy - v0) ** 2
        return np.where(r2 < rho * rho, depth - rho + np.sqrt(np.maximum(rho * rho - r2, 0.0)), -1.0)

    def _newton(self, U: np.ndarray, phi: np.ndarray, load: np.ndarray | None, tol: float, max_iter: int):
        it = 0
        rn = math.inf
        for it in range(1, max_iter + 1):  # noqa: B007
            K, R, _ = self._assemble(U, phi, load)
            rn = float(np.linalg.norm(R))
            if rn <= tol:
                return U, it - 1, rn
            dUf = spla.spsolve(K.tocsc(), -R, permc_spec="MMD_AT_PLUS_A")
            if not np.all(np.isfinite(dUf)):
                raise ArithmeticError("sheet FEM: singular tangent (Newton step not finite)")
            dU = np.zeros_like(U)
            dU[self.free] = dUf
            P0 = self._energy(U, phi, load)
            slope = float(R @ dUf)
            s = 1.0
            while s > 1e-4 and self._energy(U + s * dU, phi, load) > P0 + 1e-4 * s * slope:
                s *= 0.5
            U = U + s * dU
        K, R, _ = self._assemble(U, phi, load)
        rn = float(np.linalg.norm(R))
        if rn > 1e3 * tol:
            raise ArithmeticError(f"sheet FEM: Newton did not converge in {max_iter} iterations (residual "
                                  f"{rn:.3g} N)")
        return U, it, rn

    def _solution(self, U, depth, u0, v0, force, iters, rn, pen) -> IndentSolution:
        shape = (len(self.x), len(self.y))
        out = []
        for c in range(3):
            F = np.zeros(shape)
            F[self.ix, self.iy] = U[c::3]
            out.append(F)
        return IndentSolution(self.x.copy(), self.y.copy(), out[2], out[0], out[1], float(depth), float(u0),
                              float(v0), float(force), int(iters), float(rn), float(pen))

    def _check_point(self, u0: float, v0: float) -> None:
        a, b = self.phys.half_span, self.phys.half_width
        if not (math.isfinite(u0) and math.isfinite(v0) and abs(u0) < a - self.phys.finger_radius
                and abs(v0) <= b):
            raise ValueError(f"contact (u0, v0)=({u0!r}, {v0!r}) must lie inside the sheet, |u0| < "
                             f"{a - self.phys.finger_radius:.4f} m, |v0| <= {b:.4f} m")

    def solve_indent(self, depth, u0: float = 0.0, v0: float = 0.0, *, max_step: float = 0.010,
                     tol: float = 1e-7, max_iter: int = 40, start: IndentSolution | None = None
                     ) -> IndentSolution | list[IndentSolution]:
        """Equilibrium under the rigid fingertip with its apex at ``depth`` S (m, > 0; or an increasing list
        of depths → one solution per depth, continued from each other) at contact (u0, v0) (m).

        Continuation from ``start`` (or the flat sheet) in steps ≤ ``max_step`` m; Newton until the residual
        ≤ ``tol`` N; a step whose Newton fails is retried in two halves (down to ``max_step``/64). Raises
        ``ValueError`` on a bad depth/contact, ``ArithmeticError`` if Newton still fails.
        """
        depths = [float(depth)] if np.ndim(depth) == 0 else [float(d) for d in depth]
        if (not depths or any(not (math.isfinite(d) and d > 0.0) for d in depths)
            or np.any(np.diff(depths) <= 0)):
            raise ValueError(f"depth must be > 0 m (a list: strictly increasing), got {depth!r}")
        self._check_point(u0, v0)
        U = np.zeros(self.ndof)
        S0 = 0.0
        if start is not None:
            for c, F in enumerate((start.u1, start.u2, start.w)):
                U[c::3] = F[self.ix, self.iy]
            S0 = start.depth
        out, iters = [], 0
        for S in depths:
            n = max(1, int(math.ceil((S - S0) / max_step))) if S > S0 else 1
            todo = list(np.linspace(S0, S, n + 1)[1:][::-1])            # depth steps still to take (stack)
            while todo:
                s = todo.pop()
                V = U.copy()
                if S0 > 0.0:                                            # predictor: w ∝ S, in-plane u ∝ S²
                    k = s / S0
                    V[2::3] *= k
                    V[0::3] *= k * k
                    V[1::3] *= k * k
                phi = self._phi(s, u0, v0)
                try:
                    V, it, rn = self._newton(V, phi, None, tol, max_iter)
                except ArithmeticError:
                    if s - S0 <= max_step / 64:                         # cut back six times: give up
                        raise
                    todo += [s, 0.5 * (S0 + s)]                         # retry in two half steps
                    continue
                U = V
                iters += it
                S0 = s
            _, _, pres = self._assemble(U, phi, None)
            force = float(np.sum(pres * self.dx))
            _, _, w, _, _, _, _ = self._fields(U)
            pen = float(np.max(np.maximum(phi - w, 0.0)))
            out.append(self._solution(U, S, u0, v0, force, iters, rn, pen))
        return out[0] if np.ndim(depth) == 0 else out

    def solve_pressure(self, force: float, u0: float = 0.0, v0: float = 0.0, half_side: float = 0.008, *,
                       tol: float = 1e-9, max_iter: int = 40) -> IndentSolution:
        """Equilibrium under a uniform pressure ``force``/(2·half_side)² (N, m) on the square |u − u0|,
        |v − v0| ≤ half_side (no fingertip). ``depth`` of the result = w at (u0, v0). For checks against
        :func:`linear_patch_deflection` (choose a patch on element edges). Raises ``ValueError``."""
        check_positive("force", force)
        check_positive("half_side", half_side)
        self._check_point(u0, v0)
        eps = 1e-9
        inside = (np.abs(self.qx - u0) <= half_side + eps) & (np.abs(self.qy - v0) <= half_side + eps)
        load = np.where(inside, force / (2.0 * half_side) ** 2, 0.0)
        phi = np.full_like(self.qx, -1.0)
        U, it, rn = self._newton(np.zeros(self.ndof), phi, load, tol, max_iter)
        sol = self._solution(U, 0.0, u0, v0, float(np.sum(load * self.dx)), it, rn, 0.0)
        sol.depth = float(sol.deflection(u0, v0))
        return sol


