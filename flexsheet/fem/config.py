"""The FEM node's settings (:class:`FemConfig`): one definition of each — name, type, default and range — that
``nodes/fem``'s ``FemParams`` is built from (:func:`flexsheet.runtime.params.config_fields`). Pure: no
transport; the ranges are pydantic ``Field`` constraints in the annotations, checked when the params are."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from pydantic import Field

from flexsheet.fem.cache import DEFAULT_CACHE_DIR

__all__ = ["FemConfig"]


@dataclass(frozen=True)
class FemConfig:
    """How the FEM node chooses, builds and serves its scene's model (SI units; the meaning of each field is
    in ``nodes/fem``'s ``FemParams`` docstring). The object, its material and the finger are the scene file's.

    ``accuracy_target`` m; ``depth_min``/``depth_max`` m (the range the accuracy must hold over);
    ``max_depth`` m (deeper input is rejected); ``strain_limit``; ``cache_dir`` ("" = no disk cache);
    ``mesh_h``/``mesh_h_fine``/``refine_radius`` m and ``order`` (override the automatic mesh when h, h_fine >
    0); ``arc_deg`` deg (the cylinder's working arc); ``nonlinear``, ``nonlinear_steps`` (the corotational
    depth table); ``use_prediction``; ``model`` auto | linear | snapshots; ``snapshot_build``;
    ``snapshot_axial_max`` m.
    """

    accuracy_target: Annotated[float, Field(gt=0.0)] = 0.0007
    depth_min: Annotated[float, Field(ge=0.0)] = 0.005
    depth_max: Annotated[float, Field(gt=0.0)] = 0.03
    max_depth: Annotated[float, Field(gt=0.0, le=0.07)] = 0.06
    strain_limit: Annotated[float, Field(gt=0.0)] = 1.0
    cache_dir: str = DEFAULT_CACHE_DIR
    mesh_h: Annotated[float, Field(ge=0.0)] = 0.0
    mesh_h_fine: Annotated[float, Field(ge=0.0)] = 0.0
    refine_radius: Annotated[float, Field(ge=0.0)] = 0.012
    order: Annotated[int, Field(ge=1, le=2)] = 2
    arc_deg: Annotated[float, Field(ge=0.0, le=90.0)] = 0.0
    nonlinear: bool = False
    nonlinear_steps: Annotated[int, Field(ge=2, le=101)] = 11
    use_prediction: bool = False
    model: Annotated[str, Field(pattern="^(auto|linear|snapshots)$")] = "auto"
    snapshot_build: bool = False
    snapshot_axial_max: Annotated[float, Field(ge=0.0, le=0.06)] = 0.01
