"""The neo-Hookean and Gent reference (flexsheet/fem/reference/hyperelastic.py): the residual and tangent are
the derivatives of the energy (frictionless and sticking), the small-strain limit is scikit-fem's linear
elasticity, inadmissible states have infinite energy, per-element material and support, the contact penalty.
The quarter model (fixture ``quarter``) is this folder's conftest.py's."""

import math

import numpy as np
import pytest

from flexsheet.fem.material import Material
from flexsheet.fem.reference import capsule_contact as CC
from flexsheet.fem.reference import hyperelastic as H
from flexsheet.fem.reference import path_solver as PS

MAT = Material()


def _smooth_field(m, scale):
    X = m.points - m.mesh.center
    return scale * np.column_stack([X[:, 0] * X[:, 2] / 0.03, 0.5 * X[:, 1], -0.8 * X[:, 0] + 0.3 * X[:, 2]])


@pytest.mark.parametrize("Jm, scale", [(math.inf, 0.1), (2.0, 0.2)])
def test_residual_and_tangent_are_the_derivatives_of_the_energy(quarter, Jm, scale):
    """Central differences of Π and r, with and without the finger in contact (exact tangent incl. the
    contact curvature term); neo-Hookean, and a Gent solid (Jm 2) stiffening strongly within the field
    (I1 − 3 > 1 somewhere: Gent's factor g = 1/(1 − (I1 − 3)/Jm) > 2)."""
    m = quarter if Jm == math.inf else H.HyperelasticModel(quarter.mesh, Material(Jm=Jm), sym_y=True,
                                                           sym_z=True,
                                                           intorder=2)
    rng = np.random.default_rng(0)
    u = _smooth_field(m, scale) + 1e-4 * rng.standard_normal((len(m.points), 3))
    if Jm != math.inf:
        F = m.deformation(u)
        assert ((F * F).sum(axis=(2, 3)) - 3).max() > 1.0
    v = rng.standard_normal(u.shape)
    eps = 1e-7
    for caps in (None, CC.capsule_at(0.0, 0.006, 0.008, m.mesh.radius, m.mesh.center)):
        k = m.penalty()
        r, K = m.residual_tangent(u, caps, k)
        rp, _ = m.residual_tangent(u + eps * v, caps, k, need_K=False)
        rm, _ = m.residual_tangent(u - eps * v, caps, k, need_K=False)
        fd = (rp - rm) / (2 * eps)
        assert np.linalg.norm(fd - K @ v.ravel()) < 1e-5 * np.linalg.norm(fd)
        de = (m.energy(u + eps * v, caps, k) - m.energy(u - eps * v, caps, k)) / (2 * eps)
        assert abs(de - r @ v.ravel()) < 1e-5 * abs(r @ v.ravel())


def _gauss_only(m):
    """The same mesh with the plain Gauss rule (no nodal quadrature points)."""
    return H.HyperelasticModel(m.mesh, MAT, sym_y=True, sym_z=True, intorder=2, node_weight=0.0)


@pytest.mark.parametrize("blended", [False, True])
def test_small_strain_energy_equals_scikit_fem_linear_elasticity(quarter, blended):
    """For a tiny displacement the neo-Hookean energy is ½ uᵀ K_lin u with skfem's linear_elasticity(λ, μ):
    exactly (1e-3) with the Gauss rule alone; with the default rule that also integrates β = 5 % of the volume
    at the P2 nodes, within 2 % (the blended rule is exact only for linear integrands, so it is consistent but
    not exact for this quadratic strain-energy density)."""
    from skfem import Basis, ElementTetP2, ElementVector, asm
    from skfem.models.elasticity import linear_elasticity

    m = quarter if blended else _gauss_only(quarter)
    assert m.node_weight == (H.NODE_WEIGHT if blended else 0.0)
    u = _smooth_field(m, 1e-6)
    vb = Basis(m.skmesh, ElementVector(ElementTetP2()), intorder=2)
    K = asm(linear_elasticity(*MAT.lame), vb)
    x = np.zeros(vb.N)
    x[vb.nodal_dofs.T.ravel()] = u[:m.skmesh.p.shape[1]].ravel()       # skfem's vector DOFs: node-major
    x[vb.edge_dofs.T.ravel()] = u[m.skmesh.p.shape[1]:].ravel()
    e_lin = 0.5 * x @ (K @ x)
    assert e_lin > 0
    assert abs(m.energy(u, None, 0.0) - e_lin) < (2e-2 if blended else 1e-3) * e_lin
    if blended:
        assert abs(m.energy(u, None, 0.0) - e_lin) > 1e-6 * e_lin      # the nodal points do enter the rule


def test_element_folded_through_an_edge_midpoint_is_inadmissible(quarter):
    """Moving one edge midpoint 0.8 of the way along its edge folds the P2 element at that node (nodal det F
    −0.6) while every Gauss point still has det F ≥ 0.28: the Gauss rule alone gives a finite energy (the fold
    the nh-2 reference fell into under the fingertip); the default rule with the nodes gives +inf, so Newton's
    line search never accepts it."""
    m = quarter
    e = 0
    mid, (a, b) = m.edofs[e, 4], quarter.mesh.tets[e][:2]
    u = np.zeros((len(m.points), 3))
    u[mid] = 0.8 * (m.points[b] - m.points[a]) / 2
    g = _gauss_only(m)
    Jq = np.linalg.det(g.deformation(u))
    assert Jq.min() > 0.2
    assert g.checks(u)[1] >= 1 and g.checks(u)[0] < -0.5  # inverted at a node (every element on the edge)
    assert math.isfinite(g.energy(u, None, 0.0))
    assert m.energy(u, None, 0.0) == math.inf


def test_node_weight_is_validated(quarter):
    with pytest.raises(ValueError, match="node_weight"):
        H.HyperelasticModel(quarter.mesh, MAT, sym_y=True, sym_z=True, intorder=2, node_weight=1.0)


def test_energy_is_infinite_for_an_inverted_element(quarter):
    m = quarter
    u = np.zeros((len(m.points), 3))
    u[:, 0] = -2.5 * (m.points[:, 0] - m.mesh.center[0])        # x -> -1.5 x: det F < 0 everywhere
    assert m.energy(u, None, 0.0) == math.inf
    with pytest.raises(FloatingPointError, match="inverted"):
        m.residual_tangent(u, None, 0.0)


def test_gent_energy_of_a_homogeneous_stretch_its_limit_and_its_neo_hookean_limit(quarter):
    """A homogeneous stretch F = diag(a, b, c): Π = V·W(F) with W = −μJm/2 ln(1 − (I1 − 3)/Jm) − μ ln J +
    λ/2 ln²J written out by hand (Gent 1996 with the compressible neo-Hookean's volumetric part); +inf and a
    ``FloatingPointError`` past the limiting extensibility; Jm → ∞ gives the neo-Hookean energy."""
    X = quarter.points - quarter.mesh.center
    a, b, c = 1.6, 0.85, 0.9
    u = X * (np.array([a, b, c]) - 1.0)
    I1, lnJ = a * a + b * b + c * c, math.log(a * b * c)
    lam, mu = MAT.lame
    for Jm in (4.0, 30.0):
        m = H.HyperelasticModel(quarter.mesh, Material(Jm=Jm), sym_y=True, sym_z=True, intorder=2)
        W = -0.5 * mu * Jm * math.log(1 - (I1 - 3) / Jm) - mu * lnJ + 0.5 * lam * lnJ ** 2
        assert m.energy(u, None, 0.0) == pytest.approx(m.vol * W, rel=1e-9)
    W_nh = 0.5 * mu * (I1 - 3) - mu * lnJ + 0.5 * lam * lnJ ** 2
    assert quarter.energy(u, None, 0.0) == pytest.approx(quarter.vol * W_nh, rel=1e-9)
    near_nh = H.HyperelasticModel(quarter.mesh, Material(Jm=1e9), sym_y=True, sym_z=True, intorder=2)
    assert near_nh.energy(u, None, 0.0) == pytest.approx(quarter.energy(u, None, 0.0), rel=1e-8)
    tight = H.HyperelasticModel(quarter.mesh, Material(Jm=I1 - 3.0 - 1e-3), sym_y=True, sym_z=True,
                                intorder=2)
    assert tight.energy(u, None, 0.0) == math.inf
    with pytest.raises(FloatingPointError, match="limiting extensibility"):
        tight.residual_tangent(u, None, 0.0)


def test_per_element_material_and_support_override(quarter):
    """Per-element E/ν and an explicit support (the hooks other scenes use) against the defaults: the same
    values give the same residual; doubling E everywhere doubles the elastic residual (W is linear in E at
    fixed ν); a stiffer half changes it; bad shapes and values are refused naming the field."""
    m = quarter
    ne = len(m.mesh.tets)
    u = _smooth_field(m, 0.05)
    caps = CC.capsule_at(0.0, 0.004, 0.008, m.mesh.radius, m.mesh.center)
    same = H.HyperelasticModel(m.mesh, MAT, sym_y=True, sym_z=True, intorder=2, support=m.support.copy(),
                               E_elem=np.full(ne, MAT.E), nu_elem=np.full(ne, MAT.nu))
    r0, K0 = m.residual_tangent(u, caps, m.penalty())
    r1, K1 = same.residual_tangent(u, caps, same.penalty())
    assert np.allclose(r1, r0, rtol=1e-12, atol=1e-12 * np.abs(r0).max())
    assert abs(K1 - K0).max() <= 1e-12 * abs(K0).max()
    stiff = H.HyperelasticModel(m.mesh, MAT, sym_y=True, sym_z=True, intorder=2,
                                E_elem=np.full(ne, 2 * MAT.E))
    r2, _ = stiff.residual_tangent(u, None, 0.0, need_K=False)
    re, _ = m.residual_tangent(u, None, 0.0, need_K=False)
    assert np.allclose(r2, 2 * re, rtol=1e-10, atol=1e-12)
    half = np.where(m.mesh.points[m.mesh.tets].mean(axis=1)[:, 2] > m.mesh.center[2] + 0.01, 5 * MAT.E, MAT.E)
    r3, _ = H.HyperelasticModel(m.mesh, MAT, sym_y=True, sym_z=True, intorder=2,
                                E_elem=half).residual_tangent(
        u, None, 0.0, need_K=False)
    assert np.linalg.norm(r3 - re) > 0.1 * np.linalg.norm(re)
    # support from a node mask: fix the whole back half-space x <= centre - 10 mm instead of the surface only
    nodes = m.mesh.points[:, 0] <= m.mesh.center[0] - 0.01
    sup = m.dof_points(nodes)
    assert sup.shape == (len(m.points),) and np.all(m.points[sup, 0] <= m.mesh.center[0] - 0.01 + 1e-12)
    mb = H.HyperelasticModel(m.mesh, MAT, sym_y=True, sym_z=True, intorder=2, support=sup)
    assert np.all(mb.fixed_mask.reshape(-1, 3)[sup]) and not np.any(mb.support & ~sup)
    with pytest.raises(ValueError, match="support"):
        H.HyperelasticModel(m.mesh, MAT, support=np.ones(3, bool))
    with pytest.raises(ValueError, match="E_elem"):
        H.HyperelasticModel(m.mesh, MAT, E_elem=np.ones(ne - 1))
    with pytest.raises(ValueError, match="nu_elem"):
        H.HyperelasticModel(m.mesh, MAT, nu_elem=np.full(ne, 0.5))


# ---- sticking contact (the fingertip does not slip on the tissue) ------------------------------------------
def test_sticking_residual_and_tangent_are_the_derivatives_of_the_energy(quarter):
    """With some contact points stuck (anchors perturbed off the finger) the residual and tangent are still
    the exact derivatives of Π; the anchors lie on the finger's surface; points already stuck keep their
    anchor."""
    from dataclasses import replace

    m = quarter
    rng = np.random.default_rng(1)
    u = _smooth_field(m, 0.1) + 1e-4 * rng.standard_normal((len(m.points), 3))
    caps = CC.capsule_at(0.0, 0.006, 0.008, m.mesh.radius, m.mesh.center)
    a = m.stick_anchors(u, caps)
    stuck = np.isfinite(a[..., 0])
    assert 5 < stuck.sum() < stuck.size
    # anchored along the finger's normal where the sticking spring carries the penalty's force at that gap
    # (continuous force when a point sticks): |x − anchor|·k = −φ'(g), so the anchor lies ε/2 … ε outside
    x = m._contact_x(u)[stuck]
    gx, _ = caps.gap(x)
    d1 = CC.smooth_penalty(gx, m.penalty(), m.eps)[1]
    assert np.allclose(m.penalty() * np.linalg.norm(x - caps.center - a[stuck], axis=1), -d1, rtol=1e-9,
                       atol=1e-9)
    g, _ = caps.gap(caps.center + a[stuck])
    assert np.all((g > 0.5 * m.eps - 1e-12) & (g < m.eps + 1e-12)), (g.min(), g.max())
    deeper = CC.capsule_at(0.0, 0.009, 0.008, m.mesh.radius, m.mesh.center)
    a2 = m.stick_anchors(u, deeper, a)                                 # deeper: more points stick
    assert np.isfinite(a2[..., 0]).sum() > stuck.sum() and np.array_equal(a2[stuck], a[stuck])
    caps = replace(caps, anchors=a + np.where(stuck[..., None], 2e-4 * rng.standard_normal(a.shape), np.nan))
    k, eps = m.penalty(), 1e-7
    v = rng.standard_normal(u.shape)
    r, K = m.residual_tangent(u, caps, k)
    fd = (m.residual_tangent(u + eps * v, caps, k, need_K=False)[0]
          - m.residual_tangent(u - eps * v, caps, k, need_K=False)[0]) / (2 * eps)
    assert np.linalg.norm(fd - K @ v.ravel()) < 1e-5 * np.linalg.norm(fd)
    de = (m.energy(u + eps * v, caps, k) - m.energy(u - eps * v, caps, k)) / (2 * eps)
    assert abs(de - r @ v.ravel()) < 1e-5 * abs(r @ v.ravel())
    # the finger's force on the body is −∂Π_contact/∂x summed: equals the contact part of the residual
    f, _, n = m.contact_force(u, caps, k)
    r_el = m.residual_tangent(u, None, k, need_K=False)[0]
    assert np.allclose(f, -(r - r_el).reshape(-1, 3).sum(axis=0), rtol=1e-9, atol=1e-9)
    assert n >= stuck.sum()


def test_stiffer_penalty_penetrates_less_and_is_validated(quarter):
    """κ = scale·E/h: at a 10 mm push a 100× softer finger penetrates ~100× deeper; bad scales are refused."""
    soft = H.HyperelasticModel(quarter.mesh, MAT, sym_y=True, sym_z=True, intorder=2,
                               penalty_scale=CC.PENALTY_SCALE / 100)
    assert soft.penalty() == pytest.approx(quarter.penalty() / 100)
    a = PS.solve_path(quarter, 0.0, [0.01], 0.008, step=0.005)[-1]
    b = PS.solve_path(soft, 0.0, [0.01], 0.008, step=0.005)[-1]
    assert a.converged and b.converged
    assert b.penetration > 20 * max(a.penetration, 1e-9) and b.penetration > 1e-5
    assert b.force < a.force                                       # the soft finger sinks in: less push-back
    for bad in (0.0, -1.0, float("nan"), "1e5"):
        with pytest.raises(ValueError, match="penalty_scale"):
            H.HyperelasticModel(quarter.mesh, MAT, penalty_scale=bad)
