"""The quarter cylinder's reference model, built once per package (test_hyperelastic, test_projected_tangent,
test_path_solver, test_newton: one xdist group, ``SAME_WORKER`` in tests/conftest.py); test_fold.py's quarter
model (other sizes, with its outer surface) is that module's own."""

import pytest

from flexsheet.fem.material import Material
from flexsheet.fem.reference import hyperelastic as H
from flexsheet.fem.reference import mesh as RM

MAT = Material()


@pytest.fixture(scope="package")
def quarter():
    mesh = RM.reference_mesh(RM.RefSpec(0.016, 0.008, 0.018, half_z=True), 0.0)
    return H.HyperelasticModel(mesh, MAT, sym_y=True, sym_z=True, intorder=2)
