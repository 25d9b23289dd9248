"""The sheet's indentation table (flexsheet.model.sheet_table): its interpolation reproduces direct solves of
the FEM, it is cached, and at low stretch it builds for every contact."""

from __future__ import annotations

import numpy as np
import pytest
from test_sheet_fem import COARSE, COARSE_12MM, _nominal, _phys

from flexsheet.model.sheet import SheetSurface
from flexsheet.model.sheet_fem import FINGER_RADIUS, SheetFEM
from flexsheet.model.sheet_table import IndentTable


def test_table_interpolation_matches_direct_solves(tmp_path):
    ph = _phys(0)
    tab = IndentTable(ph, depths=(0.01, 0.03), positions=(0.0, 0.048), mesh=COARSE, cache_dir=str(tmp_path))
    assert not tab.built_from_cache
    again = IndentTable(ph, depths=(0.01, 0.03), positions=(0.0, 0.048), mesh=COARSE, cache_dir=str(tmp_path))
    assert again.built_from_cache and np.array_equal(again.W, tab.W)
    fem = SheetFEM(ph, **COARSE)
    for pu, pv, S in ((0.024, -0.024, 0.02), (-0.048, 0.0, 0.01)):
        sol = fem.solve_indent(S, pu, pv)
        sh = tab.shape(S, pu, pv)
        U, V = np.meshgrid(sol.x, sol.y, indexing="ij")
        err = sh.deflection(U, V) - sol.w
        far = np.hypot(U - pu, V - pv) > 2 * FINGER_RADIUS
        assert np.sqrt(np.mean(err ** 2)) < 0.02 * S                  # rms within 2 % of the depth
        assert np.abs(err[far]).max() < 0.06 * S
        assert sh.force == pytest.approx(sol.force, rel=0.15)
        assert sh.deflection(pu, pv) == pytest.approx(S, rel=0.05)    # apex on the coarse 8 mm mesh
    # a SheetSurface carries the shape like the series membrane; the grid has the SheetState layout
    sh = tab.shape(0.02, 0.01, 0.0)
    surf = SheetSurface(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), ph.half_span,
                        ph.half_width, sh)
    assert surf.pushed_point == pytest.approx([-0.02, 0.01, 0.0])
    g = sh.grid(9)
    assert g.shape == (9, 9) and np.all(g[[0, -1], :] == 0.0) and g.max() <= 0.02 + 1e-9
    # the tensor-grid evaluation (the renderer's fit grid) is
    # the point-wise one, for the table's span and another
    u, v = np.linspace(-0.15, 0.15, 41), np.linspace(-0.13, 0.13, 23)    # reaches past the edges (clamped)
    for S, pu, pv, a in ((0.02, 0.01, 0.0, None), (0.035, -0.03, 0.05, 1.01 * ph.half_span),
                         (0.004, 0.06, -0.1, None)):
        g = tab.evaluate_grid(S, pu, pv, u, v, a)
        assert g.shape == (41, 23) and g.max() > 0.5 * S
        np.testing.assert_allclose(g, tab.evaluate(S, pu, pv, u[:, None], v[None, :], a), rtol=0, atol=1e-15)
    assert np.array_equal(tab.evaluate_grid(0.0, 0.0, 0.0, u, v), np.zeros((41, 23)))
    with pytest.raises(ValueError, match="1-D"):
        tab.evaluate_grid(0.01, 0.0, 0.0, u[:, None], v)


def test_low_stretch_table_builds_for_every_contact(tmp_path):
    ph = _nominal(0.01)
    tab = IndentTable(ph, depths=(0.02, 0.06), positions=(0.0, 0.036, 0.072), mesh=COARSE_12MM,
                      cache_dir=str(tmp_path))
    assert not tab.built_from_cache and np.all(np.isfinite(tab.W))
    # every contact reaches its depths and pushes with a positive force that grows with depth
    for i, pu in enumerate(tab.positions):
        for j, pv in enumerate(tab.positions):
            assert np.all(tab.F[i, j] > 0.0) and tab.F[i, j, 1] > 3.0 * tab.F[i, j, 0]
            for S in tab.depths:
                w_apex = tab.shape(S, pu, pv).deflection(pu, pv)
                assert w_apex == pytest.approx(S, abs=0.05 * S)
