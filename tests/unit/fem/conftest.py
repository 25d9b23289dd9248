"""Fixtures shared by the linear FEM's modules, built once per package: the coarse cylinder's mesh and its P1
and P2 models (test_mesh, test_solver, test_realtime, test_corotational: one xdist group, ``SAME_WORKER`` in
tests/conftest.py)."""

import pytest

from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec, cylinder_tet_mesh
from flexsheet.fem.solver import FemModel
from flexsheet.model.scenes import SCENES_DIR, load_scene, parse_scene

MAT = Material()


COARSE = MeshSpec(0.012, 0.006, 0.012)


@pytest.fixture(scope="package")
def mesh():
    return cylinder_tet_mesh(COARSE)


@pytest.fixture(scope="package")
def p1(mesh):
    return FemModel(mesh, MAT, order=1)


@pytest.fixture(scope="package")
def p2(mesh):
    return FemModel(mesh, MAT, order=2)


def small_push_scene(**extra):
    """The sphere scene with a 2° stroke: its refined band is a ball around the push point only."""
    sc = load_scene(SCENES_DIR / "sphere.yaml")
    data = sc.model_dump()
    data["stroke"] = {"kind": "arc", "start": [1.0, 0.0, 0.0], "toward": [0.0, 0.0, 1.0], "start_deg": 0.0,
                      "end_deg": 2.0}
    data.update(extra)
    return parse_scene(data, "<sphere, short stroke>")
