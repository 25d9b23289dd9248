"""The Foxglove bridge's settings (:class:`VizNodeConfig`): one definition of each — name, type, default and
range — that ``nodes/viz``'s ``VizParams`` is built from (:func:`flexsheet.runtime.params.config_fields`).
Pure and light (no transport, no foxglove import); the ranges are pydantic ``Field`` constraints in the
annotations, checked when the params are. The geometry here is flat (lists of numbers, as a launch file
writes them); :class:`flexsheet.viz.scene_builder.VizConfig` is what the scene builder takes. The believed sheet's
settings are the renderer's (:data:`flexsheet.rendering.config.SHEET_PARAMS`); the WebSocket server's
address is the node's own."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

from pydantic import Field

from flexsheet.model import geometry

__all__ = ["VizNodeConfig"]


@dataclass(frozen=True)
class VizNodeConfig:
    """What the bridge serves and how often (SI units, display frame): the output and input rates, the camera
    images' source and scale, and the geometry no message carries (eye, projector, arm bases, sheet grid).
    Each field's description says what it is."""

    scene_rate: Annotated[float, Field(ge=0.0, le=100.0, description="/viz/scene, /viz/tf, /viz/metrics, Hz (5: "
                                       "under 5 % of a core in the sim with a viewer; 10 costs ~1.2 % more, "
                                       "docs/visualise.md)")] = 5.0
    camera_rate: Annotated[float, Field(ge=0.0, le=100.0, description="/camera/left, /camera/right, Hz")] = 5.0
    camera_topic: Annotated[str, Field(pattern="^/camera/(stereo|stereo_preview)$",
                                       description="where the camera images come from: the camera's decimated "
                                                   "preview (5 Hz) or the full 48 Hz stream (replays of bags "
                                                   "that only have it)")] = "/camera/stereo_preview"
    render_rate: Annotated[float, Field(ge=0.0, le=100.0, description="/render/image, Hz")] = 5.0
    input_rate: Annotated[float, Field(gt=0.0, le=1000.0, description="most messages decoded per input topic, Hz "
                                       "(camera and rendered frames: camera_rate and render_rate)")] = 5.0
    json_rate: Annotated[float, Field(ge=0.0, le=1000.0, description="cap per JSON topic, Hz (≤ input_rate)")] = 5.0
    calibration_rate: Annotated[float, Field(ge=0.0, le=10.0, description="camera calibrations resent, Hz")] = 0.5
    poll_rate: Annotated[float, Field(gt=0.0, le=200.0, description="how often due outputs are checked, Hz")] = 20.0
    camera_scale: Annotated[float, Field(gt=0.0, le=1.0, description="downscale of the camera images (0.5: a "
                                         "quarter of the pixels)")] = 0.5
    eye: Annotated[list[float], Field(description="cyclopean eye V, m")] = field(
        default_factory=lambda: geometry.EYE.tolist())
    ipd: Annotated[float, Field(ge=0.0, le=0.1, description="interpupillary distance, m")] = 0.064
    projector_position: Annotated[list[float], Field(description="m")] = field(
        default_factory=lambda: geometry.PROJECTOR.tolist())
    projector_pixel: Annotated[float, Field(gt=0.0, description="m per px on the screen")] = geometry.PIXEL_ON_SCREEN
    width: Annotated[int, Field(ge=16, description="projector width, px")] = 1024
    height: Annotated[int, Field(ge=16, description="projector height, px")] = 768
    left_base: Annotated[list[float], Field(min_length=4, max_length=4, description="left arm base (x, y, z, yaw), "
                                            "m and rad (as arm_bridge 'base')")] = field(
        default_factory=lambda: list(geometry.LEFT_BASE))
    right_base: Annotated[list[float], Field(min_length=4, max_length=4, description="right arm base (x, y, z, "
                                             "yaw), m and rad")] = field(
        default_factory=lambda: list(geometry.RIGHT_BASE))
    sheet_grid: Annotated[int, Field(ge=2, le=200, description="sheet mesh vertices per side")] = 20
