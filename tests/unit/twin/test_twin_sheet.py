"""The twin's independent sheet physics (flexsheet.model.sheet_fem): the nonlinear membrane FEM converges, agrees
with the linear membrane's closed-form series at small load, stiffens at 50 mm depth, and its interpolation table
reproduces direct solves. Three truth seeds (the sheet's E, pre-strain and tension ratio differ per seed)."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.model.sheet import SheetSurface
from flexsheet.model.sheet_fem import FINGER_RADIUS, SheetFEM, SheetPhysics
from flexsheet.model.sheet_linear import linear_patch_deflection
from flexsheet.model.sheet_table import IndentTable
from flexsheet.twin.truth import TwinTruth

COARSE = {"h_fine": 0.008, "h_coarse": 0.012}


def _phys(seed: int, stretch: float = 0.04) -> SheetPhysics:
    return SheetPhysics.from_truth(TwinTruth.draw(seed, "realistic"), stretch)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_small_load_matches_the_linear_membrane_and_converges_with_the_mesh(seed):
    ph = _phys(seed)
    ref = linear_patch_deflection(ph, 0.01, 0.008, 0.0, 0.0)          # 10 mN on a 16 mm square: w ≈ 50 µm
    errs = []
    for h in (0.008, 0.004):
        sol = SheetFEM(ph, h_fine=h).solve_pressure(0.01, 0.0, 0.0, 0.008)
        assert sol.residual < 1e-9 and sol.iterations <= 4             # Newton: quadratic from the flat sheet
        errs.append(abs(sol.depth / ref - 1.0))
    assert 20e-6 < ref < 200e-6
    assert errs[1] < 0.02                                              # within 2 % at the default 4 mm mesh
    assert errs[1] < errs[0] / 2.5                                     # and O(h²): ~4× smaller for h/2


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_indentation_converges_and_stiffens_at_50mm(seed):
    ph = _phys(seed)
    fem = SheetFEM(ph, **COARSE)
    small, deep = fem.solve_indent([0.003, 0.050], 0.0, 0.0)
    for s in (small, deep):
        assert s.residual < 1e-6 and s.penetration < 1e-4
        assert s.w.max() == pytest.approx(s.depth, abs=0.02 * s.depth + 1e-4)   # the finger is the deepest point
        assert np.all(s.w[[0, -1], :] == 0.0)                          # clamped edges u = ±a do not move
    k_lin = small.force / small.depth                                  # N/m at 3 mm (linear regime)
    assert 30.0 < k_lin < 400.0
    assert deep.force / deep.depth > 1.8 * k_lin                       # geometric stiffening (stretching)
    # the deflection is positive everywhere behind the sheet and the free edges sag less than the middle
    assert deep.w.min() >= -1e-6
    mid = deep.w[len(deep.x) // 2]
    assert mid[len(deep.y) // 2] > mid[0] and mid[len(deep.y) // 2] > mid[-1]


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
    # the tensor-grid evaluation (the renderer's fit grid) is the point-wise one, for the table's span and another
    u, v = np.linspace(-0.15, 0.15, 41), np.linspace(-0.13, 0.13, 23)    # reaches past the edges (clamped)
    for S, pu, pv, a in ((0.02, 0.01, 0.0, None), (0.035, -0.03, 0.05, 1.01 * ph.half_span), (0.004, 0.06, -0.1, None)):
        g = tab.evaluate_grid(S, pu, pv, u, v, a)
        assert g.shape == (41, 23) and g.max() > 0.5 * S
        np.testing.assert_allclose(g, tab.evaluate(S, pu, pv, u[:, None], v[None, :], a), rtol=0, atol=1e-15)
    assert np.array_equal(tab.evaluate_grid(0.0, 0.0, 0.0, u, v), np.zeros((41, 23)))
    with pytest.raises(ValueError, match="1-D"):
        tab.evaluate_grid(0.01, 0.0, 0.0, u[:, None], v)


def test_bad_inputs_are_refused_with_the_field_named():
    ph = _phys(0)
    with pytest.raises(ValueError, match="tension_ratio"):
        SheetPhysics(half_span=0.12, tension_ratio=0.0)
    with pytest.raises(ValueError, match="poisson"):
        SheetPhysics(half_span=0.12, poisson=0.7)
    fem = SheetFEM(ph, h_fine=0.02, h_coarse=0.03)
    with pytest.raises(ValueError, match="depth"):
        fem.solve_indent(-0.01)
    with pytest.raises(ValueError, match="depth"):
        fem.solve_indent([0.02, 0.01])
    with pytest.raises(ValueError, match="inside the sheet"):
        fem.solve_indent(0.01, ph.half_span - 0.001, 0.0)
    with pytest.raises(ValueError, match="stretch"):
        SheetPhysics.from_truth(TwinTruth.draw(0), -0.1)
    with pytest.raises(ValueError, match="positions"):
        IndentTable(ph, positions=(0.01, 0.02))
