"""The live renderer's pushed-sheet correction, measured against the twin's TRUE sheet.

:class:`flexsheet.experiments.correction.LivePath` builds the renderer side exactly as ``RendererNode.setup``
does: :func:`flexsheet.model.sheet_model.sheet_model_for` of the node's default :class:`SheetConfig` (the nominal FEM:
nominal E, no pre-strain, assumed tension ratio 1), :class:`RendererState` fed the clamp poses and the fingertip,
:class:`ErrorTable` + :func:`pick_model` ``auto``, and the picked model's correction (the numpy twin of the
shader, equal to 2e-6 m: tests/unit/rendering/test_correction_twin.py).

The truth side never shares the renderer's model: the true sheet is the FEM at the truth's E, pre-strain and
tension ratio (:meth:`SheetPhysics.from_truth` of a realistic :class:`TwinTruth`, not the values the renderer
assumes), and the light is traced onto it by the measurement camera's bisection tracer on a 241×241 grid
(:func:`flexsheet.experiments.measurement.trace_to_sheet`), not the renderer's Newton solver. Eye, projector and
clamps are the same on both sides, so what is measured is the sheet model (the registration's share is in the
correction experiment, docs/renderer.md). The first run on a clean machine builds FEM tables (~1–2 min).
"""

import numpy as np
import pytest

from flexsheet.experiments.correction.live_path import LivePath
from flexsheet.experiments.correction.twin_world import TwinWorld
from flexsheet.model import geometry
from flexsheet.model.sheet import clamp_half_span, clamp_poses
from flexsheet.model.sheet_model import NominalSheetModel, PendingPush, SheetConfig, table_grid
from flexsheet.rendering.state import RendererState, pick_model
from flexsheet.twin.truth import TwinTruth

STRETCH = 0.04            # the planner's stretch for the default 30 N/m object, on a table node
TARGET = geometry.PIXEL_ON_SCREEN
EYE, PROJ = geometry.EYE, geometry.PROJECTOR


@pytest.fixture(scope="module")
def live():
    return LivePath(STRETCH)


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("depth", [0.030, 0.050])
def test_live_correction_on_the_true_sheet_within_a_pixel(live, seed, depth):
    truth = TwinTruth.draw(seed, "realistic")
    assert truth.tension_ratio != 1.0 and truth.sheet_prestrain > 0.0       # not the renderer's assumptions
    r = live.measure(TwinWorld(truth), depth)
    assert r["model"] == "fine" and r["terms"] == 64                         # the nominal FEM fit, not the series
    assert r["max_mm"] < TARGET * 1e3, r
    assert r["uncorrected_max_mm"] > 5 * TARGET * 1e3                        # the measurement is sensitive
    assert r["series_max_mm"] > 2 * TARGET * 1e3                             # and sees the old model's miss


def test_unpushed_sheet_is_flat_and_exact(live):
    r = live.measure(TwinWorld(TwinTruth.draw(0, "realistic")), 0.0)
    assert r["model"] == "flat" and r["max_mm"] < 1e-3


def test_missing_table_is_not_built_in_the_drawing_thread(tmp_path):
    """With build=False (the node's drawing thread) a push at a stretch without a table is a PendingPush, the
    node is asked for it, and auto draws it with the 4-triangle model (stretch 0.12: beyond the shipped tables,
    0.01–0.11: the bridges' span band, clamp strain 0.01–0.10, and one step past it)."""
    asked = []
    cfg = SheetConfig(cache_dir=str(tmp_path))
    st = RendererState(EYE, PROJ, cfg, build=False, on_missing=asked.append)
    Tl, Tr = clamp_poses(np.zeros(3), [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.12)
    st.set_arm_pose("left", Tl)
    st.set_arm_pose("right", Tr)
    st.set_fingertip(np.array([-0.03, 0.01, 0.0]), 0.0)
    sheet, _ = st.sheet_for_frame()
    assert isinstance(sheet.membrane, PendingPush) and asked == [0.12]
    assert sheet.pushed_point == pytest.approx([-0.03, 0.01, 0.0], abs=1e-12)
    assert pick_model("auto", sheet, None, TARGET) == "four_triangle"
    assert pick_model("fine", sheet, None, TARGET) == "four_triangle"
    assert not list(tmp_path.iterdir())                                   # nothing was built
    assert NominalSheetModel(cache_dir=str(tmp_path)).nearest_on_disk(0.12) == 0.11     # the nearest shipped one


def test_table_grid_equals_pointwise_evaluation():
    m = NominalSheetModel()
    tab = m.table(STRETCH)
    a = clamp_half_span(STRETCH) * 1.002
    u, v = np.linspace(-a, a, 37), np.linspace(-0.12, 0.12, 29)
    for S, pu, pv in ((0.03, 0.0, 0.0), (0.045, 0.011, -0.02), (0.004, -0.05, 0.08), (0.065, 0.08, 0.0)):
        g = table_grid(tab, S, pu, pv, u, v, a)
        np.testing.assert_allclose(g, tab.evaluate(S, pu, pv, u[:, None], v[None, :], a), atol=1e-12)
