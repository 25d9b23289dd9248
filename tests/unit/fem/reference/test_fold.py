"""Self-contact and crease checks of deformed states (flexsheet/fem/reference/fold.py), on shapes whose answer
is known."""

from types import SimpleNamespace

import numpy as np
import pytest

from flexsheet.fem.material import Material
from flexsheet.fem.reference.capsule_contact import Capsule, capsule_at
from flexsheet.fem.reference.fold import (
    CREASE_STRETCH_RATIO,
    fold_report,
    outer_surface,
    surface_stretch_ratios,
    winding_numbers,
)
from flexsheet.fem.reference.hyperelastic import HyperelasticModel
from flexsheet.fem.reference.mesh import RefSpec, reference_mesh


def _slab(nx=11, ny=3, nz=3, lx=1.0, ly=0.4, lz=0.2):
    """A duck-typed P2 model of a box [0, lx] × [0, ly] × [0, lz] m (no symmetry planes, nothing fixed)."""
    from skfem import Basis, ElementTetP2, MeshTet

    sk = MeshTet.init_tensor(np.linspace(0, lx, nx), np.linspace(0, ly, ny), np.linspace(0, lz, nz))
    pts = np.ascontiguousarray(Basis(sk, ElementTetP2()).doflocs.T)
    return SimpleNamespace(skmesh=sk, mesh=SimpleNamespace(center=np.zeros(3)), sym_y=False, sym_z=False,
                           points=pts, support=np.zeros(len(pts), bool))


def _far_finger():
    """A thin finger well away from the slab: no point is in its footprint."""
    return Capsule(np.array([0.25, 0.2, 5.0]), np.array([0.0, 0.0, -1.0]), 1e-4)


@pytest.fixture(scope="module")
def quarter():
    m = HyperelasticModel(reference_mesh(RefSpec(0.016, 0.012, 0.018, True, 0.055), 0.0), Material(),
                          sym_y=True, sym_z=True)
    return m, outer_surface(m)


def test_winding_number_is_one_inside_zero_outside_and_half_on_the_quarter_cylinders_mirrored_surface(
    quarter):
    m, s = quarter
    V, T = s.closed(m.points)
    assert len(T) == 4 * len(s.tris)                      # the part and its three mirror images
    inner = np.setdiff1d(np.arange(len(m.points)), s.points)
    np.testing.assert_allclose(winding_numbers(m.points[inner], V, T), 1.0, atol=1e-9)
    out = m.points[s.points] + np.array([0.2, 0.0, 0.0])
    np.testing.assert_allclose(winding_numbers(out, V, T), 0.0, atol=1e-9)
    w = winding_numbers(m.points[s.points], V, T)
    # on the surface: 1/2 on the curved side and the end cap (a little above on a
    # chord's midpoint, a dip), 1/4 on the rim between them (a right-angled edge)
    assert w.max() < 0.53 and w.min() > 0.2
    assert np.median(w) == pytest.approx(0.5, abs=0.03)


def test_the_undeformed_quarter_model_folds_nothing(quarter):
    m, s = quarter
    caps = capsule_at(0.0, 0.01, 0.008, m.mesh.radius, m.mesh.center)
    rep = fold_report(m, s, np.zeros_like(m.points), caps, region=0.03)
    assert rep["n_penetrating"] == 0 and rep["max_penetration_m"] == 0.0
    assert rep["max_winding"] < 0.53 and rep["min_stretch_ratio"] == pytest.approx(1.0, abs=1e-9)
    assert rep["n_creased_tris"] == 0


def test_a_slab_folded_back_onto_itself_penetrates_by_the_overlap():
    """Rotate the slab's right half 180° about the line x = 0.5, z = 0.15: it lands on z ∈ [0.1, 0.3] over the
    left half (z ∈ [0, 0.2]); its top face lies 0.1 m inside the left half, the left half's top face 0.1 m
    inside it."""
    m = _slab()
    s = outer_surface(m)
    X = m.points
    u = np.zeros_like(X)
    right = X[:, 0] > 0.5 + 1e-9
    rel = X[right] - np.array([0.5, 0.0, 0.15])
    u[right] = np.array([0.5, 0.0, 0.15]) + rel * np.array([-1.0, 1.0, -1.0]) - X[right]
    rep = fold_report(m, s, u, _far_finger(), region=10.0)
    assert rep["max_winding"] > 1.4                      # inside the other half: 1.5 on its surface
    assert rep["n_penetrating"] > 20
    assert rep["max_penetration_m"] == pytest.approx(0.1, abs=0.005)
    flat = fold_report(m, s, np.zeros_like(X), _far_finger(), region=10.0)
    assert flat["n_penetrating"] == 0 and flat["max_winding"] < 0.51


def test_a_creased_slab_reads_the_valleys_angle():
    """Fold the right half up about the top edge line x = 0.5, z = 0.2 by 150°: a sharp valley on the top face
    with 30° of air and 330° of material around it, no overlap. The valley's points read 330 / 360; the left
    half's top face away from it reads ½. (The rigid rotation tears the elements just below the hinge line, so
    the side faces there are not checked.)"""
    m = _slab()
    s = outer_surface(m)
    X = m.points
    a = np.radians(150.0)
    R = np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]])
    u = np.zeros_like(X)
    right = X[:, 0] > 0.5 + 1e-9
    piv = np.array([0.5, 0.0, 0.2])
    u[right] = piv + (X[right] - piv) @ R.T - X[right]
    V, T = s.closed(X + u)
    top = (np.abs(X[:, 2] - 0.2) < 1e-9) & (X[:, 1] > 0.05) & (X[:, 1] < 0.35)
    hinge = top & (np.abs(X[:, 0] - 0.5) < 1e-9)
    away = top & (X[:, 0] > 0.05) & (X[:, 0] < 0.4)
    np.testing.assert_allclose(winding_numbers((X + u)[hinge], V, T), 330.0 / 360.0, atol=0.005)
    w = winding_numbers((X + u)[away], V, T)
    assert np.all(np.abs(w - 0.5) < 0.02)


def test_surface_stretch_reads_a_uniform_compression():
    m = _slab()
    s = outer_surface(m)
    x = m.points * np.array([0.5, 1.0, 1.0])
    st = surface_stretch_ratios(s, m.points, x)
    top = np.all(np.abs(m.points[s.tris][:, :, 2] - 0.2) < 1e-9, axis=1)
    np.testing.assert_allclose(st[top, 0], 0.5, atol=1e-12)
    np.testing.assert_allclose(st[top, 1], 1.0, atol=1e-12)
    rep = fold_report(m, s, x - m.points, _far_finger(), region=10.0)
    assert rep["min_stretch_ratio"] == pytest.approx(0.5, abs=1e-12) and 0.5 < CREASE_STRETCH_RATIO
    assert rep["n_creased_tris"] > 0


def test_outer_surface_refuses_a_p1_model(quarter):
    m, _ = quarter
    bad = SimpleNamespace(**{k: getattr(m, k) for k in ("skmesh", "mesh", "sym_y", "sym_z", "support")},
                          points=np.ascontiguousarray(m.skmesh.p.T))
    with pytest.raises(ValueError, match="edge midpoint"):
        outer_surface(bad)


def test_a_quarter_model_moved_through_its_mirror_plane_penetrates_its_mirror_image(quarter):
    """Shift the quarter model 5 mm across its z mirror plane: its surface near the plane now lies inside its
    own mirror image (the closed surface is the part and its mirrors), and the depth is measured, not left at
    0."""
    m, s = quarter
    caps = capsule_at(0.0, 0.01, 0.008, m.mesh.radius, m.mesh.center)
    u = np.zeros_like(m.points)
    u[:, 2] = -0.005
    rep = fold_report(m, s, u, caps, region=0.05)
    assert rep["n_penetrating"] > 0 and rep["max_winding"] > 1.0
    assert 0.001 < rep["max_penetration_m"] < 0.05
