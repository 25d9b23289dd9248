"""The cylinder's tetrahedral mesh (flexsheet/fem/mesh.py): closed, outward, supported on its back half; its
spec refuses bad values; it round-trips through meshio."""

import math

import numpy as np
import pytest

from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec


def test_mesh_is_closed_outward_and_supported_on_back_half(mesh):
    p = mesh.points[mesh.faces]
    vol = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0
    exact = math.pi * mesh.radius ** 2 * mesh.length
    assert 0.97 * exact < vol < exact          # outward winding gives the (faceted) volume, positive
    assert np.all(mesh.points[mesh.fixed, 0] <= mesh.center[0] + 1e-9)
    assert mesh.fixed.sum() > 20
    # every edge of a closed surface is shared by exactly two triangles
    e = np.sort(np.concatenate([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]], mesh.faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    assert np.all(counts == 2)


def test_mesh_spec_rejects_bad_values():
    with pytest.raises(ValueError, match="h_fine"):
        MeshSpec(0.005, 0.01, 0.01)
    with pytest.raises(ValueError, match="^h must"):
        MeshSpec(float("nan"), 0.001, 0.0)
    with pytest.raises(ValueError, match="nu"):
        Material(1e4, 0.5)


def test_mesh_round_trips_through_meshio(mesh, tmp_path):
    import meshio

    from flexsheet.fem.mesh import write_mesh

    path = str(tmp_path / "cyl.vtu")
    write_mesh(mesh, path)
    back = meshio.read(path)
    assert np.allclose(back.points, mesh.points)
    assert np.array_equal(back.cells_dict["tetra"], mesh.tets)
    assert np.array_equal(back.point_data["fixed"].astype(bool), mesh.fixed)
