"""The renderer's sheet model (flexsheet.model.sheet_model): the depth table is the FEM table at its samples
and bilinear between them, the gripped model is not the uniform one, the identified strain offset blends the
neighbouring strain nodes, the model is cached and replaces the membrane, the tensor-grid evaluation is the
point-wise one."""

import numpy as np
import pytest

from flexsheet.model.sheet import Membrane, SheetSurface, clamp_half_span
from flexsheet.model.sheet_model import NominalSheetModel, SampledShape, grid_size, table_grid

STRETCH = 0.04            # the planner's stretch for the default 30 N/m object, on a table node
COARSE = {"h_fine": 0.006, "h_coarse": 0.012}


# ------------------------------------------------------------------ the gripped sheet's FEM, as a depth table
@pytest.fixture(scope="module")
def nominal_model(tmp_path_factory):
    # centre-contact tables on a coarse mesh (~3 s each); the experiment and the node use the default mesh
    return NominalSheetModel(positions=(0.0,), mesh=COARSE, cache_dir=str(tmp_path_factory.mktemp("fem")))


def test_sampled_shape_is_bilinear_between_its_samples():
    # the depth table returns its samples exactly and a bilinear surface (here w = 3u + 2v + uv) everywhere
    a, b = 0.125, 0.12
    nu, nv = grid_size(a, b, 0.004)
    assert (nu, nv) == (64, 61)
    u, v = np.linspace(-a, a, nu), np.linspace(-b, b, nv)
    f = lambda uu, vv: 0.003 * uu + 0.002 * vv + 0.1 * uu * vv            # noqa: E731
    s = SampledShape(a, b, 0.0, 0.0, 0.01, f(u[:, None], v[None, :]))
    assert s.w.dtype == np.float32 and s.w.shape == (nu, nv)
    np.testing.assert_allclose(s.deflection(u[:, None], v[None, :]), s.w, atol=0)
    q = np.random.default_rng(0).uniform([-a, -b], [a, b], (200, 2))
    w, wu, wv = s.deflection_grad(q[:, 0], q[:, 1])
    # within a cell of a bilinear function the interpolant is the function (float32 samples: 1e-9 m)
    np.testing.assert_allclose(w, f(q[:, 0], q[:, 1]), atol=2e-9)
    np.testing.assert_allclose(wu, 0.003 + 0.1 * q[:, 1], atol=1e-5)
    np.testing.assert_allclose(wv, 0.002 + 0.1 * q[:, 0], atol=1e-5)
    assert s.deflection(2 * a, 0.0) == pytest.approx(s.deflection(a, 0.0))      # clamped onto the sheet
    for bad in (np.zeros((1, 5)), np.full((3, 3), np.nan), np.zeros(4)):
        with pytest.raises(ValueError, match="w must be"):
            SampledShape(a, b, 0.0, 0.0, 0.01, bad)


def test_depth_table_matches_the_gripped_fem_table(nominal_model):
    a = clamp_half_span(STRETCH)
    tab = nominal_model.table(STRETCH)
    assert tab.physics.gripped                                           # not the old uniform T_v = T_u
    u, v = np.meshgrid(np.linspace(-a, a, 97), np.linspace(-0.12, 0.12, 61), indexing="ij")
    outline = (np.abs(v) > 0.03) | (np.abs(u) > 0.05)          # where the cylinder's outline is seen
    for S in (0.01, 0.05):
        shp = nominal_model.shape(a, S, 0.0, 0.0)
        nu, nv = nominal_model.grid_of(a, 0.12)
        assert shp.w.shape == (nu, nv)
        su, sv = np.linspace(-a, a, nu), np.linspace(-0.12, 0.12, nv)
        # at its samples the table is the FEM table (float32)
        np.testing.assert_allclose(shp.w, tab.evaluate(S, 0.0, 0.0, su[:, None], sv[None, :], a), atol=1e-7)
        err = np.abs(shp.deflection(u, v) - tab.evaluate(S, 0.0, 0.0, u, v, a))
        assert err[outline].max() < 0.004 * S, (S, err[outline].max())   # 0.2 mm at 50 mm between samples
        # the uniform-tension series the renderer drew before is far off the gripped sheet
        m = Membrane(a, 0.12, 0.0, 0.0, S)
        assert (np.abs(m.deflection(u, v) - tab.evaluate(S, 0.0, 0.0, u, v, a))[outline].max() > 10
                * err[outline].max())


def test_strain_offset_blends_the_neighbouring_strain_nodes(tmp_path):
    m = NominalSheetModel(positions=(0.0,), mesh=COARSE, cache_dir=str(tmp_path), strain_offset=0.0025)
    assert m.node_of(0.04) == 0.04 and m.node_of(0.0476) == 0.05
    assert m.blend_of(0.0425) == [(0.04, pytest.approx(0.75)), (0.05, pytest.approx(0.25))]
    assert m.blend_of(0.04001) == [(0.04, 1.0)]  # < 1 % of the other node: one table
    a = clamp_half_span(STRETCH)
    assert m.shape(a, 0.03, 0.0, 0.0, build=False) is None and m.missing(a) == 0.04
    shp = m.shape(a, 0.03, 0.0, 0.0)                                        # builds both nodes
    nu, nv = m.grid_of(a, 0.12)
    u, v = np.linspace(-a, a, nu), np.linspace(-0.12, 0.12, nv)           # the depth table's samples
    want = 0.75 * table_grid(m.table(0.04), 0.03, 0.0, 0.0, u, v, a) + 0.25 * table_grid(m.table(0.05), 0.03,
                                                                                         0.0,
                                                                                         0.0, u, v, a)
    np.testing.assert_allclose(shp.w, want, atol=1e-7)
    # the offset counts
    assert np.abs(shp.w - table_grid(m.table(0.04), 0.03, 0.0, 0.0, u, v, a)).max() > 1e-5
    assert "identified offset +0.0025" in shp.source and m.missing(a) is None
    for bad in (0.2, float("nan")):
        with pytest.raises(ValueError, match="strain_offset"):
            NominalSheetModel(strain_offset=bad)


def test_nominal_model_is_cached_and_replaces_the_membrane(nominal_model):
    a = 0.12 * 1.04
    sheet = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0], a,
                         membrane=Membrane(a, 0.12, 0.001, -0.002, 0.03, modes=16))
    s2 = nominal_model.surface(sheet)
    assert s2.membrane is not sheet.membrane and s2.membrane.depth == 0.03
    assert (s2.membrane.push_u, s2.membrane.push_v) == (0.001, -0.002)
    assert nominal_model.surface(sheet).membrane is s2.membrane            # LRU hit
    flat = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0], a)
    assert nominal_model.surface(flat) is flat
    with pytest.raises(ValueError, match="depth"):
        nominal_model.shape(a, 0.0, 0.0, 0.0)


def test_table_grid_equals_pointwise_evaluation():
    m = NominalSheetModel()
    tab = m.table(STRETCH)
    a = clamp_half_span(STRETCH) * 1.002
    u, v = np.linspace(-a, a, 37), np.linspace(-0.12, 0.12, 29)
    for S, pu, pv in ((0.03, 0.0, 0.0), (0.045, 0.011, -0.02), (0.004, -0.05, 0.08), (0.065, 0.08, 0.0)):
        g = table_grid(tab, S, pu, pv, u, v, a)
        np.testing.assert_allclose(g, tab.evaluate(S, pu, pv, u[:, None], v[None, :], a), atol=1e-12)
