"""Planner node: fingertip in, sheet target and the two clamp (arm) targets out. A thin shell around
:class:`flexsheet.planning.surface_planner.SurfacePlanner`.

The object is the ``scene`` file's (:mod:`flexsheet.model.scenes`; the launcher fills ``scene`` from the
launch file's top-level ``scene:``; none = the paper's cylinder): its shape
(:func:`flexsheet.planning.shape.planner_shape`) and its compliance.

Subscribes ``/fingertip`` (QoS LATEST; ``predicted_position`` when ``use_prediction``),
``/object/deformation`` (QoS LATEST) and the latched ``/object/force_depth``. The sheet's tension is set so
that the finger feels the object: once the FEM node's force–depth table of this scene has arrived, its force
at the contact and depth, mapped by ``stiffness_scale`` (unless set, the scene's one scale,
:func:`flexsheet.model.force_depth.scene_scale`, logged) and ``contrast_gain``
(:meth:`SurfacePlanner.set_force_depth`); before it, the FEM's dF/dd (``ObjectDeformation.stiffness``, and
from 2 mm deep its contact force, matched in force) while fresh and *about this scene*, else the scene's
estimate at the contact (:mod:`flexsheet.planning.compliance`: Hertz contact with the scene's material,
stiffer over inclusions) when ``stiffness_from_scene``, else ``object_stiffness``; times ``stiffness_scale``.
The sheet model is ``display_calib``'s identified ``sheet`` entry where it has one. The clamp force is capped
at ``pull_margin`` × the pull the arms' joint torques allow at the targets it sends them
(:mod:`flexsheet.planning.pull_guard`) and at ``max_force``. Every ``/sheet/target`` carries the tension, the
presented and the requested stiffness; the heartbeat's message says which source is in use. The FEM's
stiffness counts as about this scene when the message's ``scene_key`` (the FEM's
:meth:`~flexsheet.model.scenes.Scene.key`: the FEM meshes and solves any scene) equals this scene's; a message
without one (a bag recorded before the FEM read scenes) counts only on the paper's cylinder, the one object
that FEM solved. Publishes ``/sheet/target``, ``/arm/left/target``, ``/arm/right/target`` with
``source_stamp`` = the fingertip's ``exposure_stamp``. The viewer's head (``/eye/pose``) bounds the sheet's
motion: reduced speed near it, hold and back off before the sheet would enter its keep-out (``head_radius`` +
``keepout_margin``), hold while the glasses are lost (:mod:`flexsheet.planning.head_guard`); without a head
camera this is inactive. With the application's target mark (``/task/mark``, optional) the sheet waits for
the finger where it predicts the landing (:mod:`flexsheet.planning.landing`). A lost marker (``valid=False``)
or an input the planner refuses republishes the last safe pose with status ``hold:<reason>``; an unreachable
target holds the arms and says ``unreachable``.
Malformed or NaN messages are rejected by the codec and counted in diagnostics.
Time: a fingertip stamped ahead of the node's clock or not newer than the last is handled as
:meth:`~flexsheet.planning.surface_planner.SurfacePlanner.update` says (``hold:future_stamp``; a backward
clock step restarts the time base). The work is :class:`flexsheet.planning.planner_stage.PlannerStage`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from pydantic import Field

from flexsheet.model.force_depth import ForceDepth
from flexsheet.model.motion_limits import MotionLimits
from flexsheet.model.scenes import load_scene_or_paper
from flexsheet.model.tension import SheetMaterial
from flexsheet.model.timing import LAB
from flexsheet.planning.arm_command import ACCEL_SCALE, SPEED_SCALE
from flexsheet.planning.limits import ReachModel
from flexsheet.planning.plan import INPUT_REJECTIONS, Plan
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.planner_stage import HEAD_WORDS, PlannerStage, held_sheet
from flexsheet.runtime.node import InputRejected, Node
from flexsheet.runtime.params import config_fields, params_model
from flexsheet.runtime.qos import QoS
from messages import ArmTarget, EyePose, Fingertip, ObjectDeformation, ObjectForceDepth, SheetTarget, topics
from nodes.planner.config import MATERIAL_RENAME, planner_config, stage_config

__all__ = ["PlannerParams", "PlannerNode"]


def _check(p) -> PlannerConfig:
    """Params check: the config, and the scene file (read once more in setup)."""
    if p.scene:
        load_scene_or_paper(p.scene)
    return planner_config(p)


PlannerParams = params_model(
    "PlannerParams",
    """Planner parameters (launch file / ``--param k=v``). SI units, display frame.

    Node-only: ``scene``: the scene file (launch/scenes/*.yaml; filled by the launcher from the launch file's
    ``scene:``; none = the paper's cylinder) — its shape and material (every shape a scene names:
    launch/scenes/*.yaml, e.g. ``rounded_box``). ``use_prediction``: plan on ``Fingertip.predicted_position``;
    ``use_fem_stiffness``: use the FEM's stiffness while fresher than ``fem_timeout`` s and about this scene —
    with ``fem_window`` > 0 the median of its messages of the last ``fem_window`` s (default 0: the latest
    only; a median steadies a scene whose FEM dF/dd jumps with the few surface nodes a light touch moves, such
    as the sphere, but lags the tension on the cylinder); ``stiffness_from_scene``: else the scene's
    compliance estimate at the contact (:mod:`flexsheet.planning.compliance`), else ``object_stiffness``;
    ``min_contact_depth`` m: the depth below which the estimate takes that depth (light touch);
    ``display_calib``: the display registration (``display.yaml``, filled by the launcher from the launch
    file's ``display_calib:``) whose arm bases replace ``left_base``/``right_base`` in the reach check (the
    planner never reads the twin's truth). Every other param is a field of — defined, defaulted and checked in
    — :class:`PlannerConfig` (``touch_distance`` … ``max_dt``), :class:`SheetMaterial` (``young`` …
    ``max_force``; its ``size`` is ``sheet_size``), :class:`MotionLimits` and :class:`ReachModel`;
    ``planner_config()`` builds the config.
    """,
    config_fields(PlannerConfig, exclude=("material", "limits", "reach")),
    config_fields(SheetMaterial, rename=MATERIAL_RENAME),
    config_fields(MotionLimits),
    config_fields(ReachModel),
    check=_check,
    methods={"planner_config": planner_config},
    module=__name__,
    scene=(str | None, Field(default=None, description="scene file (launch/scenes/*.yaml); none: the "
                                                       "paper's")),
    use_prediction=(bool, False),
    use_fem_stiffness=(bool, True),
    stiffness_from_scene=(bool, True),
    min_contact_depth=(float, Field(default=5e-4, gt=0.0, le=0.05)),
    fem_timeout=(float, Field(default=0.5, gt=0.0)),
    fem_window=(float, Field(default=0.0, ge=0.0, le=5.0)),
    display_calib=(str | None, Field(default=None, description="display.yaml whose arm bases the reach check "
                                                               "uses")),
    head_radius=(float,
                 Field(default=0.10, gt=0.0, le=0.3, description="head sphere about the head centre, m")),
    keepout_margin=(float,
                    Field(default=0.05, ge=0.0, le=0.3, description="keep-out margin around the head, m")),
    pull_margin=(float,
                 Field(default=0.9, gt=0.0, le=1.0, description="share of the arms' torque-limited pull at "
                       "the targets sent the clamp force may reach (the bridges refuse a target past "
                       "the limit itself)")),
    arm_speed_scale=(float, Field(default=SPEED_SCALE, gt=0.0, le=1.0,
                                  description="the bridges' speed_scale: the sheet's motion is slowed until "
                                  "both arms' joints stay within it (flexsheet/arm/sheet_motion.py)")),
    arm_accel_scale=(float, Field(default=ACCEL_SCALE, gt=0.0, le=100.0,
                                  description="the bridges' accel_scale, 1/s, likewise")),
)


class PlannerNode(Node):
    """Surface-planner node (see module docstring). Params: :class:`PlannerParams`. Its work is
    :class:`flexsheet.planning.planner_stage.PlannerStage`."""

    Params = PlannerParams
    node_type = "planner"
    DYNAMIC_PARAMS = frozenset({"stiffness_scale", "contrast_gain", "use_prediction"})

    def on_params_set(self, names: set[str]) -> None:
        """``stiffness_scale`` reaches the planner's config (``use_prediction`` is read per fingertip)."""
        if getattr(self, "stage", None) is None:
            return
        planner = self.stage.planner
        if "stiffness_scale" in names:
            planner.cfg = replace(planner.cfg, stiffness_scale=self.params.stiffness_scale)
            self.stage.cfg = replace(self.stage.cfg, scale_given=True)
            self.stage.scene_scale = None
        if "contrast_gain" in names:
            planner.cfg = replace(planner.cfg, contrast_gain=self.params.contrast_gain)

    async def setup(self) -> None:
        p: PlannerParams = self.params
        scene = load_scene_or_paper(p.scene)
        self.log.info("%s", scene.describe())
        self.stage = PlannerStage(scene, stage_config(p))
        self.log.info("sheet model: %s", self.stage.describe_sheet())
        if self.stage.first_line:
            self.log.info("%s", self.stage.first_line)
        self.pub_sheet = self.publisher(topics.SHEET_TARGET)
        self.pub_left = self.publisher(topics.ARM_LEFT_TARGET)
        self.pub_right = self.publisher(topics.ARM_RIGHT_TARGET)
        self.subscribe(topics.FINGERTIP, self.on_fingertip, qos=QoS.LATEST, sim_cost=LAB.compute("planner"))
        self.subscribe(topics.DEFORMATION, self.on_deformation, qos=QoS.LATEST)
        self.subscribe(topics.FORCE_DEPTH, self.on_force_depth)
        self.subscribe(topics.EYE_POSE, self.on_eye_pose, qos=QoS.LATEST)
        self.subscribe(topics.TASK_MARK, self.on_mark, qos=QoS.LATEST)
        # the arms' measured clamp poses, read only where a motion starts from the held sheet (sampled: the
        # 140 Hz joint states are decoded then, not each)
        self._arm_states = {"left": self.sample(topics.ARM_LEFT_STATE),
                            "right": self.sample(topics.ARM_RIGHT_STATE)}

    def _held_sheet(self, size: float):
        """The sheet as the arms' measured clamps hold it (:func:`held_sheet`), or None."""
        left, right = (self._arm_states[side].read() for side in ("left", "right"))
        return None if left is None or right is None else held_sheet(left.pose, right.pose, size)

    def on_eye_pose(self, msg: EyePose) -> None:
        """The viewer's tracked eye: the keep-out follows it; lost glasses hold the sheet
        (:class:`HeadGuard`)."""
        guard = self.stage.guard
        was = guard.state
        try:
            guard.set_eye(msg.eye, msg.valid)
        except ValueError as exc:
            raise InputRejected(f"/eye/pose: {exc}") from None
        if guard.state != was:
            say = self.log.warning if guard.state == "lost" else self.log.info
            say("viewer's head %s", HEAD_WORDS[guard.state])

    def on_mark(self, msg) -> None:
        """The application's ``TaskMark`` (:meth:`SurfacePlanner.set_mark`; its ``ValueError``: rejected)."""
        self.stage.planner.set_mark(msg.header.stamp, msg.point, msg.normal, msg.visible)

    def on_force_depth(self, msg: ObjectForceDepth) -> None:
        """The object's force–depth from its FEM (:meth:`PlannerStage.set_force_depth`). A table about another
        object is ignored; a malformed one is rejected (counted)."""
        if msg.scene_key and msg.scene_key != self.stage.key:
            self.log.warning("/object/force_depth is about another object than scene %r; ignored",
                             self.stage.scene.name)
            return
        try:
            table = ForceDepth(msg.points, msg.normals, tuple(msg.names), msg.depths, msg.force,
                               msg.scene_key)
        except ValueError as exc:
            raise InputRejected(f"/object/force_depth: {exc}") from None
        line = self.stage.set_force_depth(table)
        if line:
            self.log.info("%s", line)

    def on_deformation(self, msg: ObjectDeformation) -> None:
        """The FEM's local stiffness and press of a valid solution (:meth:`PlannerStage.set_fem`)."""
        if msg.valid:
            key = getattr(msg, "scene_key", None) or ""
            self.stage.set_fem(self.now(), key, msg.stiffness, msg.contact_force, msg.depth)

    def on_fingertip(self, msg: Fingertip) -> None:
        """Plan and publish; a lost marker holds the last safe pose (status ``hold:marker_lost``); a lost head
        holds the pose while the stretch follows the push (``hold:head_lost``,
        :meth:`SurfacePlanner.hold_pose`)."""
        if not msg.valid:
            plan, line = self.stage.plan(self.now(), None, None)
        else:
            predict = self.params.use_prediction        # read once: param set may change it meanwhile
            pos = msg.predicted_position if predict else msg.position
            t = msg.header.stamp + (msg.prediction_horizon if predict else 0.0)
            plan, line = self.stage.plan(self.now(), t, pos)
        if line:
            self.state_message = f"stiffness: {line}"
            self.log.info("sheet tension from %s", line)
        if plan is None:
            raise InputRejected(f"fingertip: no safe pose yet to hold (valid={msg.valid})")
        self.publish_plan(plan, msg.exposure_stamp)
        if plan.status in INPUT_REJECTIONS:
            raise InputRejected(f"fingertip: {plan.status} (stamp={msg.header.stamp!r}, "
                                f"position={msg.position.tolist()})")

    def publish_plan(self, plan: Plan, source_stamp: float) -> None:
        """Publish the sheet target and both clamp targets for ``plan`` (:meth:`PlannerStage.command`)."""
        st = self.pub_sheet.header("display")
        f = np.asarray
        self.pub_sheet.publish(SheetTarget(
            header=st, contact_point=f(plan.contact, float), normal=f(plan.normal, float),
            axis_u=f(plan.axis_u, float), axis_v=f(plan.axis_v, float), sheet_origin=f(plan.origin, float),
            stretch=float(plan.stretch), tension=float(plan.tension), stiffness=float(plan.stiffness),
            object_stiffness=float(plan.object_stiffness), touching=bool(plan.touching), status=plan.status,
            source_stamp=float(source_stamp)))
        cmd = self.stage.command(plan, self.now(), self._held_sheet)
        if cmd.warn:
            self.log.warning("%s", cmd.warn)
        for pub, arm, pose in ((self.pub_left, "left", cmd.left), (self.pub_right, "right", cmd.right)):
            pub.publish(ArmTarget(header=pub.header("display", st.stamp), arm=arm, pose=pose, pull=cmd.pull,
                                  source_stamp=float(source_stamp), status=plan.status,
                                  joints=cmd.joints[arm], **cmd.motion))
        said = self.stage.cap_pull()            # the next plans' cap: after the targets are on their way
        if said:
            self.log.info("%s", said)

