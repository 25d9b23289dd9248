"""The corotational solve (flexsheet/fem/corotational.py) equals the linear one at a small depth."""

import numpy as np

from flexsheet.fem.contact import finger_at
from flexsheet.fem.corotational import solve_corotational
from flexsheet.fem.solver import solve_full


def test_corotational_matches_linear_at_small_depth(p1):
    fg = finger_at(0.0, 0.001, 0.008, p1.mesh.radius, p1.mesh.center)
    lin = solve_full(p1, fg)
    co, it, conv = solve_corotational(p1, fg)
    assert conv and it < 30
    assert abs(co.force - lin.force) < 0.03 * lin.force
    assert np.abs(co.u - lin.u).max() < 0.03 * np.abs(lin.u).max()
