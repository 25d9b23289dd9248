"""The organ's mesh (flexsheet.model.organ_mesh): the shipped kidney.obj is closed, small and what the code
makes."""

from __future__ import annotations

import numpy as np
import trimesh

from flexsheet.model.scenes import SCENES_DIR


def test_organ_mesh_is_closed_small_and_reproducible():
    path = SCENES_DIR / "kidney.obj"
    assert path.stat().st_size <= 200_000
    m = trimesh.load(str(path), force="mesh")
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0 and not m.is_convex   # the hilum
    ext = m.bounds[1] - m.bounds[0]
    assert 0.05 < ext[0] < 0.07 and 0.10 < ext[1] < 0.13 and 0.05 < ext[2] < 0.08   # kidney-like, m
    from flexsheet.model.organ_mesh import kidney_mesh

    g = kidney_mesh()
    assert (len(g.vertices) == len(m.vertices)
            and np.abs(np.sort(g.vertices, 0) - np.sort(m.vertices, 0)).max() < 1e-5)
