"""The gripped sheet's pre-stress (flexsheet.model.sheet_prestress): the plane-stress solve against its
closed-form limits (a long strip is uniaxial at its centre, a short wide one is in plane strain there), its
equilibrium (the same pull crosses every section between the grips; the free edges carry no normal stress) and
the square sheet's transverse tension, small at the centre and growing toward the grips."""

from __future__ import annotations

import numpy as np
import pytest
from skfem import Basis, ElementQuad1, MeshQuad

from flexsheet.model.sheet_prestress import gripped_prestress, taut_floor


def _at(x, y, n, u, v):
    """The field's value at the quadrature point nearest (u, v)."""
    X = np.asarray(Basis(MeshQuad.init_tensor(x, y), ElementQuad1(), intorder=5).global_coordinates())
    d = (X[0] - u) ** 2 + (X[1] - v) ** 2
    i = np.unravel_index(np.argmin(d), d.shape)
    return n[:, i[0], i[1]]


@pytest.mark.parametrize("nu", [0.3, 0.45, 0.5])
def test_long_strip_is_uniaxial_and_short_wide_one_in_plane_strain(nu):
    x, y = np.linspace(-1.0, 1.0, 201), np.linspace(-0.05, 0.05, 11)
    np.testing.assert_allclose(_at(x, y, gripped_prestress(x, y, nu), 0.0, 0.0), [1.0, 0.0, 0.0], atol=0.005)
    x, y = np.linspace(-0.01, 0.01, 11), np.linspace(-0.5, 0.5, 201)
    plane_strain = np.array([1.0, nu, 0.0]) / (1.0 - nu * nu)
    np.testing.assert_allclose(_at(x, y, gripped_prestress(x, y, nu), 0.0, 0.0), plane_strain, atol=0.005)


def test_square_sheet_pull_crosses_every_section_and_free_edges_are_unloaded():
    x = np.linspace(-0.124, 0.124, 63)
    y = np.linspace(-0.12, 0.12, 61)
    n = gripped_prestress(x, y)
    B = Basis(MeshQuad.init_tensor(x, y), ElementQuad1(), intorder=5)
    X = np.asarray(B.global_coordinates())
    # resultant of n_uu over a band of elements around each section u = const, per unit length of the band
    resultants = []
    h = x[1] - x[0]
    for k in (2, 15, 31, 45, 58):  # one column of elements, x[k] to x[k + 1]
        band = np.abs(X[0] - (x[k] + h / 2)) < h / 2
        resultants.append(np.sum((n[0] * B.dx)[band]) / h)
    np.testing.assert_allclose(resultants, resultants[2], rtol=0.02)
    assert 0.24 * 1.0 < resultants[2] < 0.24 * 1.2                    # ≈ the uniaxial pull, a little above
    centre, mid, near = (_at(x, y, n, u, 0.0) for u in (0.0, 0.06, 0.09))
    assert 0.02 < centre[1] / centre[0] < 0.06                         # the notes' ~0.04 at the centre
    assert centre[1] / centre[0] < mid[1] / mid[0] < near[1] / near[0] < 0.5
    # next to a free edge, off the grips
    edge = (np.abs(np.abs(X[1]) - 0.12) < 0.0012) & (np.abs(X[0]) < 0.08)
    assert np.max(np.abs(n[1][edge])) < 0.05 and np.max(np.abs(n[2][edge])) < 0.08


def test_taut_floor_raises_only_the_slack_principal_values():
    rng = np.random.default_rng(5)
    n = rng.uniform(-0.3, 1.3, (3, 200))
    f = taut_floor(n, 0.01)

    def principal(x):
        m, r = 0.5 * (x[0] + x[1]), np.hypot(0.5 * (x[0] - x[1]), x[2])
        return m + r, m - r

    (a1, a2), (b1, b2) = principal(n), principal(f)
    np.testing.assert_allclose(b1, np.maximum(a1, 0.01), atol=1e-12)
    np.testing.assert_allclose(b2, np.maximum(a2, 0.01), atol=1e-12)
    taut = a2 >= 0.01
    np.testing.assert_allclose(f[:, taut], n[:, taut], atol=1e-12)          # taut points are untouched
    # the principal direction is kept where the larger value is not floored
    keep = a1 > 0.02
    np.testing.assert_allclose(np.arctan2(f[2], f[0] - f[1])[keep], np.arctan2(n[2], n[0] - n[1])[keep],
                               atol=1e-9)


def test_bad_nodes_and_poisson_are_refused_with_the_field_named():
    y = np.linspace(-0.1, 0.1, 5)
    with pytest.raises(ValueError, match="x must"):
        gripped_prestress(np.array([0.1, -0.1]), y)
    with pytest.raises(ValueError, match="poisson"):
        gripped_prestress(y, y, 0.7)
