"""The renderer's settings (:class:`RendererConfig`): one definition of each — name, type, default and range —
that ``nodes/renderer``'s ``RendererParams`` is built from (:func:`flexsheet.runtime.params.config_fields`).
Pure: no transport, no GL; the ranges are pydantic ``Field`` constraints in the annotations, checked when the
params are. The projector window's settings (``output``, ``stereo``, ``monitor``, …) and the files the node
reads (``scene``, ``display_calib``) are the node's own params."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal

from pydantic import Field

from flexsheet.model import geometry as paper
from flexsheet.model.sheet_model import SheetConfig

__all__ = ["RendererConfig", "SHEET_PARAMS"]

#: the fields of :class:`RendererConfig` that describe the believed sheet; the Foxglove bridge's params take
#: them from here too (same names, defaults and ranges: give both nodes the same values)
SHEET_PARAMS = ("depth_table_step", "tension_ratio", "sheet_cache", "sheet_mesh", "push_threshold",
                "sheet_half_width")


@dataclass(frozen=True)
class RendererConfig:
    """What the renderer draws and how often (SI units, display frame): the drawing resolution, the correction
    and its error budget, the believed pushed sheet (:class:`~flexsheet.model.sheet_model.SheetConfig`'s
    values under the params' names), and the rates. Each field's description says what it is."""

    width: Annotated[int | None, Field(ge=16, le=8192, description="image width per eye, px (None: the "
                                       "calibrated projector's; otherwise its K is rescaled)")] = None
    height: Annotated[int | None, Field(ge=16, le=8192, description="image height per eye, px (as "
                                                                    "width)")] = None
    correction: Literal["auto", "none", "flat", "four_triangle", "fine"] = "auto"
    accuracy_target: Annotated[float,
                               Field(gt=0.0, description="image error budget, m")] = paper.PIXEL_ON_SCREEN
    depth_table_step: Annotated[float, Field(ge=0.0005, le=0.02, description="sample spacing of the pushed "
                                             "sheet's depth table (the fine shader's texture), "
                                             "m")] = SheetConfig.grid_step
    tension_ratio: Annotated[float | None, Field(gt=0.0, description="None: the sheet gripped on its clamp "
                                                 "edges (the display's model); a number: an ASSUMED uniform "
                                                 "T_v / T_u instead (a "
                                                 "comparison)")] = SheetConfig.tension_ratio
    sheet_cache: Annotated[str | None, Field(description="folder of the pushed-sheet FEM tables (None: "
                                             "$FLEXSHEET_CACHE/sheet_fem or "
                                             "~/.cache/flexsheet/sheet_fem)")] = None
    sheet_mesh: Annotated[dict[str, float], Field(description="FEM mesh of those tables (SheetFEM kwargs, "
                                                  "e.g. h_fine m; {}: the default 4 mm mesh)")] = field(
                                                      default_factory=dict)
    push_threshold: Annotated[float, Field(ge=0.0, description="depth behind the sheet that counts as a "
                                           "push, m")] = SheetConfig.push_threshold
    sheet_half_width: Annotated[float, Field(gt=0.0, description="half the free-edge length, "
                                             "m")] = SheetConfig.half_width
    publish_rate: Annotated[float, Field(gt=0.0, le=240.0, description="RenderedFrame rate, Hz")] = 10.0
    max_render_rate: Annotated[float, Field(gt=0.0, le=240.0, description="cap on redraws of the pair, Hz (a "
                                            "redraw follows each new fingertip or deformation; the window "
                                            "presents every vsync)")] = 60.0
    publish_scale: Annotated[float, Field(gt=0.0, le=1.0, description="downscale of the published "
                                                                      "images")] = 0.25
    samples: Annotated[int, Field(ge=0, le=16, description="MSAA samples")] = 0
