"""The planner node's params turned into its stage's configs, once: the registered display (``display_calib``:
the arm bases, the identified sheet) read here, so that the stage takes plain values and never the node's
``Params`` (:class:`flexsheet.planning.planner_stage.StageConfig`). Units: m, rad, N, s."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from flexsheet.calibration.display_calib import xyzyaw_from_pose
from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.calibration.sheet import TERMS
from flexsheet.model.motion_limits import MotionLimits
from flexsheet.model.tension import SheetMaterial
from flexsheet.planning.limits import ReachModel
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.planner_stage import StageConfig
from flexsheet.runtime.params import build

__all__ = ["MATERIAL_RENAME", "planner_config", "stage_config"]

#: launch-file name of :attr:`SheetMaterial.size`
MATERIAL_RENAME = {"size": "sheet_size"}


def _registered(p) -> tuple[ReachModel, SheetMaterial, dict | None]:
    """The reach model, the sheet and the bridges' bases: with a ``display_calib`` (the registered display),
    its arm bases (``arms.left``/``arms.right``: the reach model's (x, y, z, yaw) and the bridges' full
    T_display_base (4, 4), tilt included) and, where it has one, its identified ``sheet`` entry's terms on
    top of the sheet params; else the ``left_base``/``right_base`` and sheet params (bases None). Raises
    ``ValueError`` naming the file and entry when it is missing, unreadable or lacks an arm."""
    reach, material = build(ReachModel, p), build(SheetMaterial, p, rename=MATERIAL_RENAME)
    path = getattr(p, "display_calib", None)
    if not path:
        return reach, material, None
    dc = load_display_calib(path, require=("arms.left", "arms.right"))
    reach = replace(reach, left_base=xyzyaw_from_pose(dc.arms["left"].T_display_base),
                    right_base=xyzyaw_from_pose(dc.arms["right"].T_display_base))
    bases = {s: np.asarray(dc.arms[s].T_display_base, float) for s in ("left", "right")}
    return reach, (dc.sheet.material(material) if dc.sheet is not None else material), bases


def planner_config(p) -> PlannerConfig:
    """The :class:`PlannerConfig` that params ``p`` (the planner node's) describe; raises ``ValueError`` on
    inconsistent values or a bad ``display_calib``."""
    reach, material, _ = _registered(p)
    return build(PlannerConfig, p, material=material, limits=build(MotionLimits, p), reach=reach)


def stage_config(p) -> StageConfig:
    """The stage's :class:`StageConfig` from params ``p`` (the planner node's), the registered display read
    once; raises ``ValueError`` on inconsistent values or a bad ``display_calib``."""
    reach, material, bases = _registered(p)
    cfg = build(PlannerConfig, p, material=material, limits=build(MotionLimits, p), reach=reach)
    nominal = build(SheetMaterial, p, rename=MATERIAL_RENAME)
    return StageConfig(
        planner=cfg, bases=bases,
        sheet_identified=any(getattr(material, k) != getattr(nominal, k) for k in TERMS),
        stiffness_from_scene=p.stiffness_from_scene, min_contact_depth=p.min_contact_depth,
        head_radius=p.head_radius, keepout_margin=p.keepout_margin, pull_margin=p.pull_margin,
        arm_speed_scale=p.arm_speed_scale, arm_accel_scale=p.arm_accel_scale,
        use_fem_stiffness=p.use_fem_stiffness, fem_timeout=p.fem_timeout, fem_window=p.fem_window,
        scale_given="stiffness_scale" in p.model_fields_set)
