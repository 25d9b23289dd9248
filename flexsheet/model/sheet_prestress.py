"""The pre-stress of a sheet gripped on two opposite edges and pulled apart: a plane-stress solve.

The clamps grip the sheet along its whole edges u = ±a and pull them apart; the other two edges v = ±b are
free. Near the grips the rubber cannot contract sideways, so a transverse tension builds up there and fades
toward the middle of a long span; at the centre of the 240 × 240 mm sheet the transverse-to-axial tension
ratio is a few per cent, and the axial tension is a little above the uniaxial value. A uniform
T_v = T_u (a sheet pulled equally both ways) is 2–3 × too stiff under a fingertip
(``../shared/design/compliance_notes.md``, "How a sheet gripped on two edges carries tension").

**Model** (linear plane stress on the stretched rectangle |u| ≤ a, |v| ≤ b; Timoshenko & Goodier, *Theory
of Elasticity*, §7–§16): the in-plane displacement minimises ∫ ½ ε : C : ε dA with C the plane-stress
stiffness of a unit uniaxial stiffness E·t = 1 and Poisson's ratio ν; Dirichlet BC u₁ = ±a, u₂ = 0 on the
grips (a unit clamp strain, no slip across the jaws), traction-free edges v = ±b. The returned field is
n = C : ε(u): the membrane stress resultant per unit uniaxial tension, so the pre-stress of a sheet whose
uniaxial tension at the clamp strain is T (N/m, :func:`flexsheet.model.tension.tension`) is N⁰ = T·n. The
shape of n depends on a/b and ν only. Closed-form limits (tested): a long strip (a ≫ b) is uniaxial at its
centre, n = (1, 0, 0); a short wide one (a ≪ b) is in plane strain there, n = (1/(1 − ν²), ν/(1 − ν²), 0).

Solved with scikit-fem (``ElementVector(ElementQuad1())``, ``linear_elasticity`` with the plane-stress Lamé
constants) on the tensor mesh and quadrature the sheet FEM uses, so the field is in discrete equilibrium
with the FEM's own in-plane equations.
"""

from __future__ import annotations

import math

import numpy as np

from flexsheet.model.checks import check_positive

__all__ = ["TAUT_FLOOR", "gripped_prestress", "taut_floor"]


def gripped_prestress(x: np.ndarray, y: np.ndarray, poisson: float = 0.5, intorder: int = 5) -> np.ndarray:
    """Pre-stress per unit uniaxial tension of the gripped sheet (module doc), at the quadrature points of
    ``MeshQuad.init_tensor(x, y)`` with ``intorder``: (3, nel, nq) Voigt (n_uu, n_vv, n_uv), dimensionless.

    ``x`` (nx,) m: increasing node coordinates along u, grips at x[0] = −a and x[-1] = a (symmetric);
    ``y`` (ny,) m along v, free edges at the ends. Raises ``ValueError`` on fewer than 2 nodes, unsorted
    nodes or ν outside [0, 0.5]."""
    from skfem import Basis, ElementQuad1, ElementVector, MeshQuad, asm, condense, solve
    from skfem.models.elasticity import linear_elasticity

    x, y = np.asarray(x, float), np.asarray(y, float)
    for name, v in (("x", x), ("y", y)):
        if v.ndim != 1 or v.size < 2 or not np.all(np.isfinite(v)) or np.any(np.diff(v) <= 0):
            raise ValueError(f"{name} must be >= 2 increasing finite node coordinates, got shape {v.shape}")
    if not (math.isfinite(poisson) and 0.0 <= poisson <= 0.5):
        raise ValueError(f"poisson must be in [0, 0.5], got {poisson!r}")
    a = float(x[-1])
    check_positive("half span x[-1]", a)
    mesh = MeshQuad.init_tensor(x, y)
    basis = Basis(mesh, ElementVector(ElementQuad1()), intorder=intorder)
    nu = float(poisson)
    lam, mu = nu / (1.0 - nu * nu), 0.5 / (1.0 + nu)      # plane-stress Lamé constants for E·t = 1
    K = asm(linear_elasticity(lam, mu), basis)
    u = np.zeros(basis.N)
    dofs = basis.nodal_dofs                                 # (2, n_nodes): u1, u2 of each node
    grip = np.flatnonzero(np.isclose(np.abs(mesh.p[0]), a, atol=1e-12))
    u[dofs[0, grip]] = mesh.p[0, grip]                      # u1 = ±a: unit clamp strain
    fixed = np.concatenate([dofs[0, grip], dofs[1, grip]])
    u = solve(*condense(K, np.zeros(basis.N), x=u, D=fixed))
    g = basis.interpolate(u).grad                           # (2, 2, nel, nq): d u_i / d x_j
    e = np.stack([g[0, 0], g[1, 1], g[0, 1] + g[1, 0]])   # Voigt strain, engineering shear
    C = np.array([[1.0, nu, 0.0], [nu, 1.0, 0.0], [0.0, 0.0, 0.5 * (1.0 - nu)]]) / (1.0 - nu * nu)
    return np.einsum("ij,jeq->ieq", C, e)


#: smallest principal pre-stress kept, per unit T_u: the gripped field is ~0 across the free
#: edges and slightly compressive at the grips' corners; the 1 mm sheet's bending carries ~1
#: N/m there without wrinkling (:mod:`flexsheet.model.sheet_fem`), so the flat sheet is taut
#: everywhere and the sheet FEM's wrinkling relaxation acts on what the finger does
TAUT_FLOOR = 0.01


def taut_floor(n: np.ndarray, floor: float = TAUT_FLOOR) -> np.ndarray:
    """Pre-stress field ``n`` (3, ...) Voigt with each point's principal values raised to at least ``floor``
    (same principal directions)."""
    m = 0.5 * (n[0] + n[1])
    d, s = 0.5 * (n[0] - n[1]), n[2]
    r = np.sqrt(d * d + s * s)
    rr = np.where(r > 0.0, r, 1.0)
    c2, s2 = np.where(r > 0.0, d / rr, 1.0), np.where(r > 0.0, s / rr, 0.0)     # cos 2θ, sin 2θ
    l1, l2 = np.maximum(m + r, floor), np.maximum(m - r, floor)
    mm, rn = 0.5 * (l1 + l2), 0.5 * (l1 - l2)
    return np.stack([mm + rn * c2, mm - rn * c2, rn * s2])
