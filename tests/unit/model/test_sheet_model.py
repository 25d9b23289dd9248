"""The renderer's sheet models (flexsheet.model.sheet_model): the series shape evaluates the membrane's form, the
nominal FEM fit matches its table and replaces the membrane (cached), the tensor-grid evaluation is the
point-wise one."""

import numpy as np
import pytest

from flexsheet.model.sheet import Membrane, SheetSurface, clamp_half_span
from flexsheet.model.sheet_model import NominalSheetModel, table_grid

STRETCH = 0.04            # the planner's stretch for the default 30 N/m object, on a table node


# ------------------------------------------------------------------ the nominal FEM sheet model (fine shader form)
@pytest.fixture(scope="module")
def nominal_model(tmp_path_factory):
    from flexsheet.model.sheet_model import NominalSheetModel

    # centre-contact table on a coarse mesh (~2 s); the experiment and the node use the default mesh
    return NominalSheetModel(positions=(0.0,), mesh={"h_fine": 0.006, "h_coarse": 0.012},
                             cache_dir=str(tmp_path_factory.mktemp("fem")))


def test_series_shape_evaluates_the_membrane_form():
    # SeriesShape evaluates w = sum coef sin(lam (u + a)) G(v; mu, v0), the form the GLSL fine model sends:
    # given a Membrane's own arrays it must reproduce the Membrane (values and gradients)
    from flexsheet.model.sheet_model import SeriesShape

    m = Membrane(0.125, 0.12, 0.02, -0.03, 0.03, tension_ratio=0.8, modes=24)
    s = SeriesShape(m.half_span, m.half_width, m.push_u, m.push_v, m.depth, m.lam, m.mu, m.coef)
    u, v = np.meshgrid(np.linspace(-0.13, 0.13, 17), np.linspace(-0.125, 0.125, 13))
    for a, b in zip(m.deflection_grad(u, v), s.deflection_grad(u, v), strict=True):
        np.testing.assert_allclose(b, a, atol=1e-12)


def test_nominal_fit_matches_the_fem_table(nominal_model):
    a = 0.12 * 1.04
    for S in (0.01, 0.05):
        shp = nominal_model.shape(a, S, 0.0, 0.0)
        assert len(shp.coef) <= 64
        tab = nominal_model.table(0.04)
        u, v = np.meshgrid(np.linspace(-a, a, 97), np.linspace(-0.12, 0.12, 61), indexing="ij")
        err = np.abs(shp.deflection(u, v) - tab.evaluate(S, 0.0, 0.0, u, v, a))
        outline = (np.abs(v) > 0.03) | (np.abs(u) > 0.05)          # where the cylinder's outline is seen
        assert err[outline].max() < 0.01 * S, (S, err[outline].max())     # 0.1 mm at 10 mm, 0.5 mm at 50
        assert shp.fit_rms < 0.004 * S
        # clamped edges stay at zero, free edges have zero slope (the basis enforces both)
        assert np.abs(shp.deflection([-a, a], [0.0, 0.05])).max() < 1e-12
        assert np.abs(shp.deflection_grad([0.0, 0.03], [-0.12, 0.12])[2]).max() < 1e-9
        # the old sine series (tension ratio 1) is much further off at 50 mm
        m = Membrane(a, 0.12, 0.0, 0.0, S)
        if S == 0.05:
            assert np.abs(m.deflection(u, v) - tab.evaluate(S, 0.0, 0.0, u, v, a))[outline].max() > 10 * err[outline].max()


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
