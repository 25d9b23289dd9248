"""Projected Newton's tangent (flexsheet/fem/reference/projected_tangent.py) against the material tangent
built another way, element by element; the batched 3 × 3 inverse and determinant (kinematics.py) against
numpy's."""

import math

import numpy as np
import pytest

from flexsheet.fem.material import Material
from flexsheet.fem.reference import hyperelastic as H
from flexsheet.fem.reference import kinematics as KIN


def _smooth_field(m, scale):
    X = m.points - m.mesh.center
    return scale * np.column_stack([X[:, 0] * X[:, 2] / 0.03, 0.5 * X[:, 1], -0.8 * X[:, 0] + 0.3 * X[:, 2]])


@pytest.mark.parametrize("Jm", [math.inf, 2.0])
def test_projected_tangent_is_the_clamped_material_tangent_element_by_element(quarter, Jm):
    """``_projection`` (batched matmuls) against a loop over one element's quadrature points built another
    way: the material tangent A = ∂P/∂F by central differences of P(F), clamped to its non-negative
    eigenvalues, and Σ_q w Bᵀ(A₊ − A)B with B the explicit 9 × 30 gradient matrix. The field compresses the
    part enough that A is indefinite somewhere; 3 × 3 inverse and determinant against numpy's. Neo-Hookean and
    a strongly stiffening Gent solid (Jm 2: the field reaches I1 − 3 ≈ 1.5, so Gent's factor g reaches ~4)."""
    m = quarter if Jm == math.inf else H.HyperelasticModel(quarter.mesh, Material(Jm=Jm), sym_y=True,
                                                           sym_z=True,
                                                           intorder=2)
    u = _smooth_field(m, 0.2)                 # indefinite at some points of 244 of the 311 elements
    F = m.deformation(u)
    Finv, J = KIN.inv_det3(F)
    np.testing.assert_allclose(J, np.linalg.det(F), rtol=1e-12)
    np.testing.assert_allclose(Finv, np.linalg.inv(F), rtol=1e-10, atol=1e-12)
    corr = m._projection(F, Finv, np.log(J), m._gent_factor(F))
    touched = np.flatnonzero(np.abs(corr).reshape(len(corr), -1).max(axis=1) > 0)
    assert len(touched) > 0, "the test field must make the tangent indefinite somewhere"
    mu, lam = m.mu, m.lam

    def piola(Fq):
        Fi = np.linalg.inv(Fq).T
        g = 1.0 if Jm == math.inf else 1.0 / (1.0 - (np.sum(Fq * Fq) - 3.0) / Jm)     # Gent: ∂W/∂I1 = μg/2
        return mu * (g * Fq - Fi) + lam * math.log(np.linalg.det(Fq)) * Fi

    def tangent(Fq):                      # A = ∂P/∂F (9 × 9, row-major (i, J)) by central differences
        A = np.zeros((9, 9))
        for c in range(9):
            dF = np.zeros(9)
            dF[c] = 1e-6
            A[:, c] = (piola(Fq + dF.reshape(3, 3)) - piola(Fq - dF.reshape(3, 3))).ravel() / 2e-6
        return 0.5 * (A + A.T)

    # an element left alone has a positive semi-definite tangent at every quadrature point
    untouched = np.setdiff1d(np.arange(len(corr)), touched)
    assert len(untouched) > 0
    for e in untouched[:2]:
        assert not np.any(corr[e])
        for q in range(F.shape[1]):
            ev = np.linalg.eigvalsh(tangent(F[e, q]))
            assert ev.min() > -1e-6 * ev.max(), (e, q, ev.min())
    for e in touched[:3]:
        K = np.zeros((30, 30))
        for q in range(F.shape[1]):
            ev, V = np.linalg.eigh(tangent(F[e, q]))
            D = V @ np.diag(np.maximum(ev, 0.0) - ev) @ V.T
            B = np.zeros((9, 30))
            for a in range(10):
                for i in range(3):
                    B[3 * i:3 * i + 3, 3 * a + i] = m.grad[e, q, a]
            K += m.w[e, q] * B.T @ D @ B
        np.testing.assert_allclose(corr[e].reshape(30, 30), K, rtol=1e-5, atol=1e-6 * np.abs(K).max())
