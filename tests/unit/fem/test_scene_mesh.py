"""Any scene meshed (flexsheet/fem/scene_mesh.py): gmsh meshes every shipped scene into valid tets with its
support and material, and the sphere's mesh volume converges to the analytic one."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.scene_mesh import scene_mesh
from flexsheet.model.scenes import SCENES_DIR, load_scene


def _volumes(points, tets):
    p = points[tets]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6.0


@pytest.mark.parametrize("name", ["sphere", "rounded_box", "organ"])
def test_every_shipped_scene_meshes_into_valid_tets_with_its_support_and_material(name):
    sc = load_scene(SCENES_DIR / f"{name}.yaml")
    sm = scene_mesh(sc)
    m = sm.mesh
    vol = _volumes(m.points, m.tets)
    assert vol.min() > 0.0                                    # positively oriented, none degenerate
    # the volume of the body's own surface (trimesh, a closed triangle mesh) within 4 %: a coarse mesh's
    # chords cut the curved surface (h = 12 mm away from the stroke)
    assert abs(vol.sum() / sc.trimesh().volume - 1.0) < 0.04, (vol.sum(), sc.trimesh().volume)
    # every node lies in or on the body (gmsh's surface nodes are on it: |signed distance| < 0.5 mm)
    sd = sc.signed_distance(m.points[m.surface_nodes])
    assert np.abs(sd).max() < 5e-4
    # support = the scene's fixed_mask on boundary nodes, and only there
    surf = m.surface_nodes
    assert m.fixed.any() and not m.fixed[np.setdiff1d(np.arange(len(m.points)), surf)].any()
    assert np.array_equal(m.fixed[surf], sc.fixed_mask(m.points[surf]))
    assert np.allclose(m.center, sc.center)
    # per-element material: the inclusions' E exactly on the elements whose centroid lies inside them
    cen = m.points[m.tets].mean(axis=1)
    inside = np.zeros(len(cen), bool)
    for inc in sc.inclusions:
        inside |= np.linalg.norm(cen - np.asarray(inc.center), axis=1) <= inc.radius
    assert np.all(sm.E[~inside] == sc.material.E) and np.all(sm.nu == sc.material.nu)
    if sc.inclusions:
        assert inside.sum() >= 20 and np.all(sm.E[inside] == sc.inclusions[0].E)
        inc = sc.inclusions[0]
        v_inc = vol[inside].sum()                            # the tumour's volume, resolved within 40 %
        assert abs(v_inc / (4 / 3 * math.pi * inc.radius ** 3) - 1.0) < 0.4, v_inc


def test_sphere_mesh_volume_converges_to_the_analytic_volume():
    sc = load_scene(SCENES_DIR / "sphere.yaml")
    R = sc.object.radius
    exact = 4.0 / 3.0 * math.pi * R ** 3
    errs = [abs(scene_mesh(sc, MeshSpec(h, h, 0.0)).volume / exact - 1.0) for h in (0.012, 0.006)]
    assert errs[1] < 0.012 and errs[1] < errs[0] / 2.5, errs      # chord error ∝ h²
    stl = scene_mesh(sc, MeshSpec(0.012, 0.012, 0.0), force_stl=True)   # the STL route meshes it too
    assert stl.how == "stl" and abs(stl.volume / exact - 1.0) < 0.05


@pytest.mark.parametrize("name", ["sphere", "cylinder", "rounded_box"])
def test_the_support_rim_is_a_mesh_line_when_asked(name):
    """rim=True (the references): every held surface node that shares a triangle with a free one lies on the
    support's plane, refined to h_fine along it; without it a back-half's held-to-free step falls between
    nodes."""
    from flexsheet.fem.mesh import surface_faces
    from flexsheet.fem.scene_mesh import support_plane

    sc = load_scene(SCENES_DIR / f"{name}.yaml")
    spec = MeshSpec(0.012, 0.006, 0.012)
    p0, n = support_plane(sc)

    def rim_offsets(m):
        f = surface_faces(m.points, m.tets)
        mixed = f[m.fixed[f].any(axis=1) & ~m.fixed[f].all(axis=1)]
        rim = np.unique(mixed[m.fixed[mixed]])
        return np.abs((m.points[rim] - p0) @ n), m.points[rim]

    d_on, pts = rim_offsets(scene_mesh(sc, spec, rim=True).mesh)
    assert d_on.max() < 1e-7 and len(d_on) >= 20
    # the rim's nodes are h_fine apart along it (neighbours within 1.5 h_fine)
    from scipy.spatial import cKDTree

    gap = cKDTree(pts).query(pts, k=2)[0][:, 1]
    assert np.median(gap) < 1.5 * spec.h_fine, np.median(gap)
    d_off, _ = rim_offsets(scene_mesh(sc, spec).mesh)
    if sc.support.kind == "back_half":                 # node selection: the step lies up to an element away
        assert d_off.max() > 1e-3
    else:  # the box's held back face: its edges, within the tolerance
        assert d_off.max() <= sc.support.tolerance + 1e-9
