"""The real-time validity checks (flexsheet/fem/deformation_checks.py) against plain implementations: the
tets' strain and inversion, the folded surface faces."""

from __future__ import annotations

import numpy as np

from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.scene_mesh import scene_mesh
from flexsheet.model.scenes import SCENES_DIR, load_scene


def test_tet_checks_equal_element_checks_on_random_deformations():
    """flexsheet.fem.deformation_checks.TetChecks (sparse gradient operator + exact bounds that skip tets)
    against the plain element_checks, from small strain to many inverted tets, with and without a
    selection."""
    from flexsheet.fem.deformation_checks import TetChecks, element_checks

    sc = load_scene(SCENES_DIR / "sphere.yaml")
    m = scene_mesh(sc, MeshSpec(0.02, 0.02, 0.0)).mesh
    tc = TetChecks(m.points, m.tets)
    rng = np.random.default_rng(7)
    assert tc(np.zeros_like(m.points)) == (0.0, 0)
    for scale in (1e-5, 1e-3, 4e-3, 1e-2):
        u = scale * rng.standard_normal(m.points.shape)
        sel = rng.random(len(m.tets)) < 0.5
        for s in (None, sel):
            t = m.tets if s is None else m.tets[s]
            strain, inv = element_checks(m.points, t, u)
            got = tc(u, s)
            assert got[1] == inv and abs(got[0] - strain) <= 1e-9 * strain, (scale, got, strain, inv)
    assert inv > 0                                                  # the largest scale inverts tets
    assert tc(u, np.zeros(len(m.tets), bool)) == (0.0, 0)
    c, r = m.points[m.tets].mean(axis=1), 0.02
    assert np.array_equal(tc.near(m.center, r), np.linalg.norm(c - m.center, axis=1) <= r)


def test_fold_operator_counts_the_faces_np_cross_finds_folded():
    """flexsheet.fem.deformation_checks.fold_operator ((e1 × e2)·n0 as a sparse product) against np.cross on
    random moves of the sphere's surface, from none folded to many."""
    from flexsheet.fem.deformation_checks import fold_operator

    m = scene_mesh(load_scene(SCENES_DIR / "sphere.yaml"), MeshSpec(0.02, 0.02, 0.0)).mesh
    x0 = m.points[m.surface_nodes]
    faces = np.searchsorted(m.surface_nodes, m.faces)
    n0 = np.cross(x0[faces[:, 1]] - x0[faces[:, 0]], x0[faces[:, 2]] - x0[faces[:, 0]])
    op, rest = fold_operator(x0, faces, n0)
    rng = np.random.default_rng(3)
    counts = []
    for scale in (0.0, 1e-3, 5e-3, 2e-2):
        us = scale * rng.standard_normal(x0.shape)
        x = x0 + us
        n = np.cross(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]])
        want = np.einsum("ij,ij->i", n, n0)
        y = op @ us.ravel() + rest
        got = (y[:3 * len(faces)] * y[3 * len(faces):]).reshape(3, -1).sum(axis=0)
        assert np.allclose(got, want, rtol=1e-9, atol=1e-12 * np.abs(want).max())
        counts.append(int(np.count_nonzero(want <= 0.0)))
        assert counts[-1] == int(np.count_nonzero(got <= 0.0))
    assert counts[0] == 0 and counts[-1] > 10, counts
