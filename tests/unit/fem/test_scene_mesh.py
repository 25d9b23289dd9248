"""Any scene meshed (flexsheet/fem/scene_mesh.py): gmsh meshes every shipped scene into valid tets with its support
and material, and the sphere's mesh volume converges to the analytic one."""

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
