"""The FEM node's parameters (:data:`FemParams`): the ``scene`` file and every field of
:class:`flexsheet.fem.config.FemConfig`; removed params are refused with where their setting went."""

from __future__ import annotations

from pydantic import Field, field_validator, model_validator

from flexsheet.fem.config import FemConfig
from flexsheet.model.scenes import load_scene_or_paper
from flexsheet.runtime.params import build, config_fields, params_model

__all__ = ["FemParams", "REMOVED_PARAMS"]

#: params the node no longer takes, with the scene file's field that holds the setting now
REMOVED_PARAMS = {"E": "material: E", "nu": "material: nu", "finger_radius": "finger: radius"}


def _scene_file(cls, v: str | None) -> str | None:
    load_scene_or_paper(v)
    return v


def _no_removed_params(cls, data):
    """Refuse a param that was removed, naming it and where its setting went."""
    if isinstance(data, dict):
        for k, where in REMOVED_PARAMS.items():
            if k in data:
                raise ValueError(f"fem param {k!r} (= {data[k]!r}) was removed: the object, its material and "
                                 f"the finger are the scene file's; set {where!r} in the scene file (the "
                                 "launch file's scene:, default launch/scenes/cylinder.yaml)")
    return data


FemParams = params_model(
    "FemParams",
    """FEM node parameters (launch file / ``--param k=v``). SI units.

    ``scene``: the scene file (launch/scenes/*.yaml; filled by the launcher from the launch file's ``scene:``;
    none = launch/scenes/cylinder.yaml, the paper's cylinder): the object, its material (E, ν, hyperelastic
    law), support and finger radius all come from it. ``accuracy_target`` m (rendered-surface error target,
    default one projector pixel 0.7 mm); ``depth_min``/``depth_max`` m push-depth range the accuracy must hold
    over (the cylinder's mesh and model choice); ``max_depth`` m deeper input is rejected; ``strain_limit``:
    largest principal strain before linear is declared invalid; ``cache_dir`` ("" = no disk cache);
    ``mesh_h``/``mesh_h_fine``/``refine_radius`` m and ``order`` override the automatic mesh when all of h,
    h_fine are > 0 (default: the cylinder's from the accuracy table, any other scene's
    :data:`flexsheet.fem.scene_mesh.DEFAULT_SCENE_SPEC`, P2); ``arc_deg``: half-angle of the cylinder's
    working arc (deg) whose neighbourhood gets the precomputed contact region and refinement (0 = the front
    centre, the paper's push; elsewhere the full sparse solve is used; other scenes follow their stroke);
    ``nonlinear``: build the cylinder's corotational depth table (background thread); ``nonlinear_steps``:
    depth samples of that table; ``use_prediction``: use ``predicted_position``; ``model``: "auto" (the
    scene's table where stored; for the cylinder the model table decides), "linear" (no table) or "snapshots";
    ``snapshot_build``: build the cylinder's missing snapshots in a background thread (heavy: tens of minutes
    on a 2-core machine; else run ``flexsheet experiment fem --node-table``); ``snapshot_axial_max`` m:
    largest axial offset of the push served by the cylinder's snapshots (translation along the axis);
    ``table_build``: a scene with no stored nonlinear path table (a new or drawn object) is served its linear
    model while the table is built on first use in a worker process at idle priority and cached by the
    scene's key, then served (:mod:`flexsheet.fem.first_use`; needs ``cache_dir``). Every param but
    ``scene`` and ``table_build`` is a field of — defined, defaulted and range-checked in —
    :class:`flexsheet.fem.config.FemConfig`; ``fem_config()`` builds it. Removed params
    (:data:`REMOVED_PARAMS`: ``E``, ``nu``, ``finger_radius``) are refused with where their setting went.
    """,
    config_fields(FemConfig),
    validators={"_scene_file": field_validator("scene")(_scene_file),
                "_no_removed_params": model_validator(mode="before")(_no_removed_params)},
    methods={"fem_config": lambda self: build(FemConfig, self)},
    module=__name__,
    scene=(str | None, Field(default=None, description="scene file (launch/scenes/*.yaml); none: "
                                                       "launch/scenes/cylinder.yaml, the paper's cylinder")),
    table_build=(bool, Field(default=True, description="build a scene's missing nonlinear path table on "
                                                       "first use, in the background (linear meanwhile)")),
)
