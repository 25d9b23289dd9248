"""What the surface planner answers (:mod:`flexsheet.planning.surface_planner`): a :class:`Plan` per fingertip
sample, or a held copy of the last one with a :class:`Hold` reason. Display frame, SI."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from flexsheet.model import geometry
from flexsheet.model.sheet import clamp_poses
from flexsheet.model.vec import Vec

__all__ = ["Hold", "INPUT_REJECTIONS", "Plan"]


class Hold(StrEnum):
    """Why the planner holds its last safe plan (a :class:`Plan` ``status``; compares equal to its string)."""

    MARKER_LOST = "hold:marker_lost"
    INVALID_FINGERTIP = "hold:invalid_fingertip"
    INVALID_STAMP = "hold:invalid_stamp"
    INVALID_STIFFNESS = "hold:invalid_stiffness"
    STALE_FINGERTIP = "hold:stale_fingertip"
    FUTURE_STAMP = "hold:future_stamp"
    SINGULAR = "hold:singular"
    HEAD_LOST = "hold:head_lost"
    KEEP_OUT = "hold:keep_out"


#: the holds caused by a refused input (the node reports them as rejected input)
INPUT_REJECTIONS = frozenset({Hold.INVALID_FINGERTIP, Hold.INVALID_STAMP, Hold.STALE_FINGERTIP,
                              Hold.FUTURE_STAMP, Hold.INVALID_STIFFNESS})


@dataclass(frozen=True, slots=True)
class Plan:
    """One planner output (display frame, SI).

    ``contact`` (3,) m: contact point on the virtual surface (desired); ``normal``, ``axis_u``, ``axis_v``
    (3,) unit: commanded sheet frame; ``origin`` (3,) m: commanded sheet centre; ``offset`` (s_u, s_v) m:
    contact position on the sheet relative to its centre; ``stretch``, ``tension`` N/m, ``stiffness`` N/m,
    ``object_stiffness`` N/m; ``depth`` m: push depth (≥ 0 when the fingertip is inside); ``touching``;
    ``status``: "ok" or ';'-joined reasons; ``left``/``right`` (3,) m: clamp points
    (:func:`flexsheet.model.sheet.clamp_points`); ``reach_margin`` m; ``t`` s: time of the fingertip sample
    planned from; ``sheet_size`` m: the unstretched sheet side between the clamps; ``k_source``: where
    ``object_stiffness`` came from — "given" (passed to
    :meth:`flexsheet.planning.surface_planner.SurfacePlanner.update`, e.g. the FEM's dF/dd), "scene" (the
    compliance model at the contact), "param" (``object_stiffness`` of the config) or "table" (the object's
    force–depth table, :meth:`flexsheet.planning.surface_planner.SurfacePlanner.set_force_depth`); it is
    already mapped by ``stiffness_scale``.
    """

    t: float
    contact: Vec
    normal: Vec
    axis_u: Vec
    axis_v: Vec
    origin: Vec
    offset: tuple[float, float]
    stretch: float
    tension: float
    stiffness: float
    object_stiffness: float
    depth: float
    touching: bool
    status: str
    left: Vec
    right: Vec
    reach_margin: float
    sheet_size: float = geometry.SHEET_SIZE
    k_source: str = "param"

    def rotation(self) -> np.ndarray:
        """(3, 3) rotation with columns (normal, axis_u, axis_v)."""
        return np.column_stack([self.normal, self.axis_u, self.axis_v])

    def clamp_matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """Left and right clamp poses T_display_clamp (4, 4): :func:`flexsheet.model.sheet.clamp_poses` of
        this plan's sheet (origin, normal, axis_u, stretch, sheet_size)."""
        return clamp_poses(self.origin, self.normal, self.axis_u, self.stretch, self.sheet_size)
