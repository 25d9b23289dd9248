"""The scene's one stiffness scale for the sheet (pure): the object's force–depth mapped into what the sheet
can present between its least and its largest stretch (:func:`flexsheet.model.force_depth.scene_scale`),
over the depths a scene is used at. Units m, N."""

from __future__ import annotations

from flexsheet.model.force_depth import scene_scale
from flexsheet.model.tension import SheetMaterial, press_force
from flexsheet.planning.surface_planner import FORCE_DEPTH

__all__ = ["scale_depths", "sheet_scene_scale"]


def scale_depths(stroke_depth: float) -> tuple[float, float]:
    """(lo, hi) m: the depths a scene's one scale is fitted over, :data:`FORCE_DEPTH` to twice its stroke
    depth."""
    return FORCE_DEPTH, 2.0 * float(stroke_depth)


def sheet_scene_scale(table, mat: SheetMaterial, max_stretch: float, stroke_depth: float, gain: float = 1.0):
    """The scene's one scale (:func:`flexsheet.model.force_depth.scene_scale`) for the sheet ``mat`` at its
    centre: its force at ``mat.min_stretch`` and at ``max_stretch`` bound every mapped force of ``table`` over
    :func:`scale_depths` of ``stroke_depth`` m, with contrast gain ``gain``. Raises ``ValueError`` as
    ``scene_scale``."""
    lo, hi = scale_depths(stroke_depth)
    return scene_scale(table, lambda d: press_force(mat.min_stretch, mat, 0.0, d),
                       lambda d: press_force(max_stretch, mat, 0.0, d), lo, hi, gain)
