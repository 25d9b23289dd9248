"""The camera node's settings (:class:`CameraConfig`): one definition of each — name, type, default and range
— that ``nodes/camera``'s ``CameraParams`` is built from (:func:`flexsheet.runtime.params.config_fields`).
Pure: no transport, no camera driver; the ranges are pydantic ``Field`` constraints in the annotations,
checked when the params are. The registration file and the twin's truth (``display_calib``, ``twin``), and the
devices' settings (the GenICam pair's serials, trigger lines, PTP and transport; the V4L2 devices; the files
source's paths) are the node's own params (docs/camera.md)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from pydantic import Field

from flexsheet.runtime.plugins import EntryName
from flexsheet.vision.camera_port import SOURCES_GROUP

__all__ = ["CameraConfig"]


@dataclass(frozen=True)
class CameraConfig:
    """What the camera node publishes (SI units; docs/vision.md): ``source`` sim | device | files | genicam;
    ``rate_hz``; the camera model (sim) / calibration to publish (``model`` ximea | bumblebee2 | file,
    ``calib_file``, ``width``/``height`` px, ``focal_mm``, ``pixel_um``, ``baseline`` m); the twin's sensing
    (``None``: the realism's value: ``noise_dn``, ``shot_gain``, ``blur_px``, ``self_occlusion``,
    ``background_gain``, ``finger_dir``, ``drop_rate``; and ``noise_scale``, ``exposure_s``, ``blur_samples``,
    ``clutter``, ``seed``, the standalone trajectory ``traj_*``); ``link_delay_s``: the twin's link, extra
    delay from exposure to the frame in the graph, s (simulated clock only: stability sweeps);
    ``preview_rate`` Hz of the decimated pairs on ``/camera/stereo_preview`` (0: off)."""

    source: EntryName(SOURCES_GROUP, "camera source") = "sim"  # type: ignore[valid-type]
    rate_hz: Annotated[float, Field(gt=0.0, le=1000.0)] = 48.0
    # camera model (sim) / calibration to publish (all sources)
    model: Annotated[str, Field(pattern="^(ximea|bumblebee2|file)$")] = "ximea"
    calib_file: str = ""
    width: Annotated[int, Field(gt=0)] = 640
    height: Annotated[int, Field(gt=0)] = 480
    focal_mm: Annotated[float, Field(gt=0.0)] = 3.8
    pixel_um: Annotated[float, Field(gt=0.0)] = 7.4
    baseline: Annotated[float, Field(gt=0.0)] = 0.12
    # the twin's sensing (None: the realism's value)
    noise_dn: Annotated[float | None, Field(ge=0.0)] = None
    shot_gain: Annotated[float | None, Field(ge=0.0)] = None
    noise_scale: Annotated[float, Field(ge=0.0, le=100.0)] = 1.0
    blur_px: Annotated[float | None, Field(ge=0.0, le=5.0)] = None
    self_occlusion: bool | None = None
    background_gain: Annotated[float | None, Field(gt=0.0, le=2.0)] = None
    finger_dir: tuple[float, float, float] | None = None
    drop_rate: Annotated[float | None, Field(ge=0.0, lt=1.0)] = None
    exposure_s: Annotated[float, Field(ge=0.0, le=0.05)] = 0.004
    link_delay_s: Annotated[float, Field(ge=0.0, le=1.0)] = 0.0
    blur_samples: Annotated[int, Field(ge=1, le=50)] = 5
    clutter: bool = True
    seed: int = 0
    traj_amplitude_rad: float = 1.05
    traj_period_s: Annotated[float, Field(gt=0.0)] = 10.0
    traj_hover_m: float = 0.005
    # viewers: the same pairs decimated on /camera/stereo_preview, Hz (0: off)
    preview_rate: Annotated[float, Field(ge=0.0, le=1000.0)] = 5.0
