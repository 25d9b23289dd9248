"""The renderer node's params (:data:`RendererParams`): the files it reads and the projector window's device
settings are the node's own; every other param is a field of
:class:`flexsheet.rendering.config.RendererConfig`. SI units, display frame."""

from __future__ import annotations

import importlib.util
from typing import Literal

from pydantic import Field, field_validator

from flexsheet.model.scenes import load_scene
from flexsheet.rendering.config import RendererConfig
from flexsheet.runtime.params import build, config_fields, params_model

__all__ = ["RendererParams"]


def _scene_file(cls, v: str | None) -> str | None:
    if v:                        # validated in full, so `flexsheet launch --check` names a bad key

        load_scene(v)
    return v


def _window_lib(cls, v: str) -> str:
    if v == "window" and importlib.util.find_spec("glfw") is None:
        raise ValueError("output='window' (the projector window) needs the 'glfw' package, which is not "
                         "installed (pip install glfw); use output='offscreen'")
    return v


def _monitor(cls, v: int | str) -> int | str:
    if isinstance(v, int) and v < 0 or isinstance(v, str) and not v.strip():
        raise ValueError(f"monitor must be an index >= 0 or part of a monitor's name, got {v!r}")
    return v


#: the files the node reads (filled by the launcher from the launch file's top-level sections)
_FILES = {
    "scene": (str | None, Field(None, description="scene file (launch/scenes/*.yaml) whose object is drawn "
                                                  "until the FEM publishes; None: the paper's cylinder")),
    "display_calib": (str | None, Field(None, description="display.yaml: the projector (K_p, D, pose) and "
                                                          "the eye (V, ipd); None: the nominal geometry "
                                                          "(logged)")),
}

#: the projector window (``output: window``): device settings, the node's own
_WINDOW = {
    "output": (Literal["offscreen", "window"], Field(
        "offscreen", description="offscreen: headless EGL; window: the projector window (glfw)")),
    "stereo": (Literal["frame_sequential", "side_by_side", "top_bottom", "mono"], Field(
        "frame_sequential", description="window format: eyes on alternate vsyncs (active shutter glasses), "
                                        "the halves of one frame, or one image from the cyclopean eye")),
    "monitor": (int | str, Field(0, description="window: monitor index (0 = primary) or part of its name")),
    "fullscreen": (bool, Field(True, description="window: take the whole monitor (false: a window, "
                                                 "debugging)")),
    "mirror_x": (bool, Field(False, description="window: flip each eye's image left-right")),
    "refresh_hz": (float | None, Field(None, gt=0.0, le=500.0,
                                       description="window: refresh rate to ask for, Hz (None: the "
                                                   "monitor's)")),
    "quad_buffer": (bool, Field(True, description="window, frame_sequential: use a quad-buffered stereo "
                                                  "context where the driver offers one")),
    "swap_eyes": (bool, Field(False, description="window, frame_sequential: right eye on even vsyncs")),
}

RendererParams = params_model(
    "RendererParams",
    """Renderer parameters (SI units, display frame).

    The files (``scene``, ``display_calib``) and the projector window (``output`` … ``swap_eyes``) are the
    node's own; every other param is a field of — defined, defaulted and range-checked in —
    :class:`flexsheet.rendering.config.RendererConfig`; ``renderer_config()`` builds it.
    """,
    _FILES,
    config_fields(RendererConfig),
    _WINDOW,
    validators={"_scene_file": field_validator("scene")(_scene_file),
                "_window_lib": field_validator("output")(_window_lib),
                "_monitor": field_validator("monitor")(_monitor)},
    methods={"renderer_config": lambda self: build(RendererConfig, self)},
    module=__name__,
)
