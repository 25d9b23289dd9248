"""Fixtures shared by the linear FEM's modules, built once per package: the coarse cylinder's mesh and its P1 and
P2 models (test_mesh, test_solver, test_realtime, test_corotational: one xdist group, ``SAME_WORKER`` in
tests/conftest.py)."""

import pytest

from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec, cylinder_tet_mesh
from flexsheet.fem.solver import FemModel

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
