"""The Foxglove bridge's settings (:class:`VizNodeConfig`): one definition of each — name, type, default and
range — that ``nodes/viz``'s ``VizParams`` is built from (:func:`flexsheet.runtime.params.config_fields`).
No transport, no foxglove import; the ranges are pydantic ``Field`` constraints in the annotations, checked
when the params are. The geometry there is flat (lists of numbers, as a launch file writes them);
:class:`VizConfig`, built from it, is what the scene builder takes. The believed sheet's
settings are the renderer's (:data:`flexsheet.rendering.config.SHEET_PARAMS`); the WebSocket server's
address is the node's own."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

import numpy as np
from pydantic import Field

from flexsheet.model import geometry
from flexsheet.model.projector import Projector
from flexsheet.model.sheet_model import SheetConfig

__all__ = ["VizNodeConfig", "VizConfig"]


@dataclass(frozen=True)
class VizNodeConfig:
    """What the bridge serves and how often (SI units, display frame): the output and input rates, the camera
    images' source and scale, and the geometry no message carries (eye, projector, arm bases, sheet grid).
    Each field's description says what it is."""

    scene_rate: Annotated[float, Field(ge=0.0, le=100.0, description="/viz/scene, /viz/tf, /viz/metrics, Hz "
                                       "(5: under 5 % of a core in the sim with a viewer; 10 costs ~1.2 % "
                                       "more, docs/visualise.md)")] = 5.0
    camera_rate: Annotated[float, Field(ge=0.0, le=100.0, description="/camera/left, /camera/right, "
                                                                      "Hz")] = 5.0
    camera_topic: Annotated[str, Field(pattern="^/camera/(stereo|stereo_preview)$",
                                       description="where the camera images come from: the camera's "
                                                   "decimated preview (5 Hz) or the full 48 Hz stream "
                                                   "(replays of bags that only have "
                                                   "it)")] = "/camera/stereo_preview"
    render_rate: Annotated[float, Field(ge=0.0, le=100.0, description="/render/image, Hz")] = 5.0
    input_rate: Annotated[float, Field(gt=0.0, le=1000.0, description="most messages decoded per input "
                                       "topic, Hz (camera and rendered frames: camera_rate and "
                                       "render_rate)")] = 5.0
    json_rate: Annotated[float, Field(ge=0.0, le=1000.0, description="cap per JSON topic, Hz (≤ "
                                                                     "input_rate)")] = 5.0
    calibration_rate: Annotated[float,
                                Field(ge=0.0, le=10.0, description="camera calibrations resent, Hz")] = 0.5
    poll_rate: Annotated[float, Field(gt=0.0, le=200.0, description="how often due outputs are checked, "
                                                                    "Hz")] = 20.0
    camera_scale: Annotated[float, Field(gt=0.0, le=1.0, description="downscale of the camera images (0.5: a "
                                         "quarter of the pixels)")] = 0.5
    eye: Annotated[list[float], Field(description="cyclopean eye V, m")] = field(
        default_factory=lambda: geometry.EYE.tolist())
    ipd: Annotated[float, Field(ge=0.0, le=0.1, description="interpupillary distance, m")] = 0.064
    projector_position: Annotated[list[float], Field(description="m")] = field(
        default_factory=lambda: geometry.PROJECTOR.tolist())
    projector_pixel: Annotated[float,
                               Field(gt=0.0, description="m per px on the screen")] = geometry.PIXEL_ON_SCREEN
    width: Annotated[int, Field(ge=16, description="projector width, px")] = 1024
    height: Annotated[int, Field(ge=16, description="projector height, px")] = 768
    left_base: Annotated[list[float],
                         Field(min_length=4, max_length=4, description="left arm base (x, y, z, yaw), "
                               "m and rad (as arm_bridge 'base')")] = field(
        default_factory=lambda: list(geometry.LEFT_BASE))
    right_base: Annotated[list[float],
                          Field(min_length=4, max_length=4, description="right arm base (x, y, z, "
                                "yaw), m and rad")] = field(
        default_factory=lambda: list(geometry.RIGHT_BASE))
    sheet_grid: Annotated[int, Field(ge=2, le=200, description="sheet mesh vertices per side")] = 20


@dataclass
class VizConfig:
    """Geometry the scene needs that no message carries (SI units, display frame).

    ``eye`` (3,) cyclopean eye V, m; ``ipd`` m; ``projector``: :class:`Projector` (default: the paper's);
    ``left_base``/``right_base``: arm bases (x, y, z, yaw) m, rad (as the arm bridges' ``base`` param);
    ``sheet``: :class:`~flexsheet.model.sheet_model.SheetConfig` of the believed sheet — give it the
    renderer's values (its params ``sheet_half_width``, ``push_threshold``, ``depth_table_step``,
    ``tension_ratio``, ``sheet_cache``, ``sheet_mesh``) and the bridge draws the dent the renderer corrects
    for; ``sheet_half_width`` (read-only) is ``sheet.half_width``; ``sheet_grid`` n (n × n sheet vertices);
    ``frustum_depth`` m of the camera frusta; ``camera_scale`` ∈ (0, 1] image downscale.
    """

    eye: np.ndarray = field(default_factory=lambda: geometry.EYE.copy())
    ipd: float = 0.064
    projector: Projector = field(default_factory=Projector.default)
    left_base: tuple = geometry.LEFT_BASE
    right_base: tuple = geometry.RIGHT_BASE
    sheet: SheetConfig = field(default_factory=SheetConfig)
    sheet_grid: int = 20
    frustum_depth: float = 0.45
    camera_scale: float = 1.0

    def __post_init__(self) -> None:
        self.eye = np.asarray(self.eye, dtype=float)
        if self.eye.shape != (3,) or not np.all(np.isfinite(self.eye)):
            raise ValueError(f"eye must be a finite (3,) vector, got {self.eye!r}")
        if not (0.0 < self.camera_scale <= 1.0):
            raise ValueError(f"camera_scale must be in (0, 1], got {self.camera_scale!r}")
        if self.sheet_grid < 2:
            raise ValueError(f"sheet_grid must be >= 2, got {self.sheet_grid!r}")
        if not (self.frustum_depth > 0):
            raise ValueError(f"frustum_depth must be > 0, got {self.frustum_depth!r}")
        if not isinstance(self.sheet, SheetConfig):
            raise ValueError(f"sheet must be a SheetConfig, got {type(self.sheet).__name__}")

    @property
    def sheet_half_width(self) -> float:
        """Half the sheet's free-edge length, m (``sheet.half_width``)."""
        return self.sheet.half_width
