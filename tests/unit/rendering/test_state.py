"""The renderer's state (flexsheet.rendering.state): in the node's drawing thread a missing table is not
built; the push is drawn with the 4-triangle model meanwhile."""

import numpy as np
import pytest

from flexsheet.model import geometry
from flexsheet.model.sheet import clamp_poses
from flexsheet.model.sheet_model import NominalSheetModel, PendingPush, SheetConfig
from flexsheet.rendering.state import RendererState, pick_model

TARGET = geometry.PIXEL_ON_SCREEN
EYE, PROJ = geometry.EYE, geometry.PROJECTOR


def test_missing_table_is_not_built_in_the_drawing_thread(tmp_path):
    """With build=False (the node's drawing thread) a push at a stretch without a table is a PendingPush, the
    node is asked for it, and auto draws it with the 4-triangle model (stretch 0.12: beyond the shipped
    tables, 0.01–0.11: the bridges' span band, clamp strain 0.01–0.10, and one step past it)."""
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
    assert NominalSheetModel(cache_dir=str(tmp_path)).nearest_on_disk(0.12) == 0.11  # the nearest shipped one
