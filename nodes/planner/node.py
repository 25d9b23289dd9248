"""Planner node: fingertip in, sheet target and the two clamp (arm) targets out. A thin shell around
:class:`flexsheet.planning.surface_planner.SurfacePlanner`.

The object is the ``scene`` file's (:mod:`flexsheet.model.scenes`; the launcher fills ``scene`` from the
launch file's top-level ``scene:``; none = the paper's cylinder): its shape
(:func:`flexsheet.planning.shape.planner_shape`) and its compliance.

Subscribes ``/fingertip`` (QoS LATEST; ``predicted_position`` when ``use_prediction``),
``/object/deformation`` (QoS LATEST) and the latched ``/object/force_depth``. The sheet's tension is set so that
the finger feels the object: once the FEM node's force–depth table of this scene has arrived, its force at the
contact and depth, mapped by ``stiffness_scale`` (unless set, the scene's one scale,
:func:`flexsheet.model.force_depth.scene_scale`, logged) and ``contrast_gain`` (:meth:`SurfacePlanner.set_force_depth`);
before it, the FEM's dF/dd (``ObjectDeformation.stiffness``, and from 2 mm deep its contact force, matched in
force) while fresh and *about this scene*, else the scene's estimate at the contact
(:mod:`flexsheet.planning.compliance`: Hertz contact with the scene's material, stiffer over inclusions) when
``stiffness_from_scene``, else ``object_stiffness``; times ``stiffness_scale``. The sheet model is
``display_calib``'s identified ``sheet`` entry where it has one. The clamp force is capped at ``pull_margin`` ×
the pull the arms' joint torques allow at the targets it sends them (:mod:`flexsheet.planning.pull_guard`) and
at ``max_force``. Every
``/sheet/target`` carries the tension, the presented and the requested stiffness; the heartbeat's message
says which source is in use. The FEM's stiffness counts as about this scene when the message's ``scene_key``
(the FEM's :meth:`~flexsheet.model.scenes.Scene.key`: the FEM meshes and solves any scene) equals
this scene's; a message without one (a bag recorded before the FEM read scenes) counts only on the paper's
cylinder, the one object that FEM solved.
Publishes ``/sheet/target``, ``/arm/left/target``, ``/arm/right/target`` with ``source_stamp`` = the
fingertip's ``exposure_stamp``. The viewer's head (``/eye/pose``) bounds the sheet's motion: reduced speed near
it, hold and back off before the sheet would enter its keep-out (``head_radius`` + ``keepout_margin``), hold while
the glasses are lost (:mod:`flexsheet.planning.head_guard`); without a head camera this is inactive.
A lost marker (``valid=False``) or an input the planner refuses republishes
the last safe pose with status ``hold:<reason>``; an unreachable target holds the arms and says
``unreachable``. Malformed or NaN messages are rejected by the codec and counted in diagnostics.
Time: a fingertip stamped more than ``future_stamp_tolerance`` s ahead of the node's clock (``self.now()``) is
rejected and counted alone (``hold:future_stamp``); it never becomes the newest stamp, so the next good
fingertips are served. Staleness (a stamp not newer than the last accepted one) counts only while the node's
clock is not behind that last stamp, so a backward clock step restarts the time base instead of freezing the
planner (:meth:`~flexsheet.planning.surface_planner.SurfacePlanner.update`).
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace

import numpy as np
from pydantic import Field

from flexsheet.arm.bridge_config import BridgeConfig
from flexsheet.arm.kinematics import QD_MAX
from flexsheet.arm.sheet_motion import (
    VELOCITY_PLANS,
    JointRates,
    MotionError,
    SheetShaper,
    plan_velocity,
)
from flexsheet.calibration.display_calib import xyzyaw_from_pose
from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.calibration.sheet import TERMS
from flexsheet.model.force_depth import ForceDepth
from flexsheet.model.motion_limits import MotionLimits
from flexsheet.model.scenes import Scene, is_paper_cylinder, load_scene_or_paper
from flexsheet.model.sheet import clamp_poses, frame_from_clamps, sheet_rotation
from flexsheet.model.tension import SheetMaterial, clamp_force
from flexsheet.model.timing import LAB
from flexsheet.planning.compliance import SceneCompliance
from flexsheet.planning.head_guard import HeadGuard
from flexsheet.planning.keepout import KeepOut
from flexsheet.planning.limits import ReachModel
from flexsheet.planning.plan import INPUT_REJECTIONS, Hold, Plan
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.pull_guard import PullGuard
from flexsheet.planning.shape import planner_shape
from flexsheet.planning.surface_planner import SurfacePlanner, scale_depths, sheet_scene_scale
from flexsheet.runtime.node import InputRejected, Node
from flexsheet.runtime.params import build, config_fields, params_model
from flexsheet.runtime.qos import QoS
from messages import (
    ArmTarget,
    EyePose,
    Fingertip,
    ObjectDeformation,
    ObjectForceDepth,
    SheetTarget,
    topics,
)

__all__ = ["PlannerParams", "PlannerNode", "fem_solves_scene"]


def fem_solves_scene(msg: ObjectDeformation, sc: Scene, key: str | None = None) -> bool:
    """Whether the FEM's ``msg`` is about scene ``sc``: its ``scene_key`` equals ``sc.key()`` (or ``key``,
    precomputed); an empty ``scene_key`` (unknown: a message from before the FEM read scenes) counts only
    when ``sc`` is the paper's cylinder — the only object that FEM solved."""
    msg_key = getattr(msg, "scene_key", None)
    if msg_key:
        return msg_key == (key if key is not None else sc.key())
    return is_paper_cylinder(sc)


_MATERIAL = {"size": "sheet_size"}         # launch-file name of SheetMaterial.size


def _registered(p) -> tuple[ReachModel, SheetMaterial]:
    """The reach model and the sheet: with a ``display_calib`` (the registered display), its arm bases
    (``arms.left``/``arms.right``) and, where it has one, its identified ``sheet`` entry's terms on top of the
    sheet params; else the ``left_base``/``right_base`` and sheet params. Raises ``ValueError`` naming the file
    and entry when it is missing, unreadable or lacks an arm."""
    reach, material = build(ReachModel, p), build(SheetMaterial, p, rename=_MATERIAL)
    path = getattr(p, "display_calib", None)
    if not path:
        return reach, material
    from dataclasses import replace

    dc = load_display_calib(path, require=("arms.left", "arms.right"))
    reach = replace(reach, left_base=xyzyaw_from_pose(dc.arms["left"].T_display_base),
                    right_base=xyzyaw_from_pose(dc.arms["right"].T_display_base))
    return reach, (dc.sheet.material(material) if dc.sheet is not None else material)


def _planner_config(p) -> PlannerConfig:
    """The :class:`PlannerConfig` params ``p`` describe (raises ``ValueError`` on inconsistent values)."""
    reach, material = _registered(p)
    return build(PlannerConfig, p, material=material, limits=build(MotionLimits, p), reach=reach)


def _check(p) -> PlannerConfig:
    """Params check: the config, and the scene file (read once more in setup)."""
    if p.scene:
        load_scene_or_paper(p.scene)
    return _planner_config(p)


PlannerParams = params_model(
    "PlannerParams",
    """Planner parameters (launch file / ``--param k=v``). SI units, display frame.

    Node-only: ``scene``: the scene file (launch/scenes/*.yaml; filled by the launcher from the launch file's
    ``scene:``; none = the paper's cylinder) — its shape and material (every shape a scene names:
    launch/scenes/*.yaml, e.g. ``rounded_box``).
    ``use_prediction``: plan on ``Fingertip.predicted_position``; ``use_fem_stiffness``: use the FEM's
    stiffness while fresher than ``fem_timeout`` s and about this scene — with ``fem_window`` > 0 the median
    of its messages of the last ``fem_window`` s (default 0: the latest only; a median steadies a scene whose
    FEM dF/dd jumps with the few surface nodes a light touch moves, such as the sphere, but lags the tension
    on the cylinder); ``stiffness_from_scene``: else the
    scene's compliance estimate at the contact (:mod:`flexsheet.planning.compliance`), else ``object_stiffness``;
    ``min_contact_depth`` m: the depth below which the estimate takes that depth (light touch);
    ``display_calib``: the display registration
    (``display.yaml``, filled by the launcher from the launch file's ``display_calib:``) whose arm bases
    replace ``left_base``/``right_base`` in the reach check (the planner never reads the twin's truth).
    Every other param is a field of — defined, defaulted and
    checked in — :class:`PlannerConfig` (``touch_distance`` … ``max_dt``), :class:`SheetMaterial`
    (``young`` … ``max_force``; its ``size`` is ``sheet_size``), :class:`MotionLimits` and
    :class:`ReachModel`; ``planner_config()`` builds the config.
    """,
    config_fields(PlannerConfig, exclude=("material", "limits", "reach")),
    config_fields(SheetMaterial, rename=_MATERIAL),
    config_fields(MotionLimits),
    config_fields(ReachModel),
    check=_check,
    methods={"planner_config": _planner_config},
    module=__name__,
    scene=(str | None, Field(default=None, description="scene file (launch/scenes/*.yaml); none: the paper's")),
    use_prediction=(bool, False),
    use_fem_stiffness=(bool, True),
    stiffness_from_scene=(bool, True),
    min_contact_depth=(float, Field(default=5e-4, gt=0.0, le=0.05)),
    fem_timeout=(float, Field(default=0.5, gt=0.0)),
    fem_window=(float, Field(default=0.0, ge=0.0, le=5.0)),
    display_calib=(str | None, Field(default=None, description="display.yaml whose arm bases the reach check uses")),
    head_radius=(float, Field(default=0.10, gt=0.0, le=0.3, description="head sphere about the head centre, m")),
    keepout_margin=(float, Field(default=0.05, ge=0.0, le=0.3, description="keep-out margin around the head, m")),
    pull_margin=(float, Field(default=0.9, gt=0.0, le=1.0, description="share of the arms' torque-limited pull at "
                              "the targets sent the clamp force may reach (the bridges refuse a target past "
                              "the limit itself)")),
    arm_speed_scale=(float, Field(default=BridgeConfig.speed_scale, gt=0.0, le=1.0,
                                  description="the bridges' speed_scale: the sheet's motion is slowed until both "
                                  "arms' joints stay within it (flexsheet/arm/sheet_motion.py)")),
    arm_accel_scale=(float, Field(default=BridgeConfig.accel_scale, gt=0.0, le=100.0,
                                  description="the bridges' accel_scale, 1/s, likewise")),
)


class PlannerNode(Node):
    """Surface-planner node (see module docstring). Params: :class:`PlannerParams`."""

    Params = PlannerParams
    node_type = "planner"
    DYNAMIC_PARAMS = frozenset({"stiffness_scale", "contrast_gain", "use_prediction"})

    def on_params_set(self, names: set[str]) -> None:
        """``stiffness_scale`` reaches the planner's config (``use_prediction`` is read per fingertip)."""
        if getattr(self, "planner", None) is None:
            return
        if "stiffness_scale" in names:
            self.planner.cfg = replace(self.planner.cfg, stiffness_scale=self.params.stiffness_scale)
            self.scene_scale = None
        if "contrast_gain" in names:
            self.planner.cfg = replace(self.planner.cfg, contrast_gain=self.params.contrast_gain)

    async def setup(self) -> None:
        p: PlannerParams = self.params
        self.scene: Scene = load_scene_or_paper(p.scene)
        shape = planner_shape(self.scene)
        compliance = SceneCompliance(self.scene, shape, p.min_contact_depth) if p.stiffness_from_scene else None
        self.log.info("%s", self.scene.describe())
        self._scene_key = self.scene.key()
        cfg = p.planner_config()
        m = cfg.material
        params = build(SheetMaterial, p, rename=_MATERIAL)
        identified = any(getattr(m, k) != getattr(params, k) for k in TERMS)
        self.log.info("sheet model: %s (w %.1f mm, growth %.2f, own %.3g N + %.3g N/m, stretching %.3g N/m³, "
                      "strain offset %+.4f, position %+.3f along / %+.3f across)",
                      "identified from presses (display_calib sheet)" if identified
                      else "the nominal string band (no identified sheet in display_calib)",
                      m.contact_width * 1e3, m.contact_growth, m.own_stiffness, m.own_growth, m.stretching,
                      m.strain_offset, m.position_u, m.position_v)
        self.guard = HeadGuard(KeepOut(head_radius=p.head_radius, margin=p.keepout_margin), cfg.material.size)
        self.planner = SurfacePlanner(shape, cfg, compliance, self.guard)
        qd = QD_MAX * p.arm_speed_scale                          # the two arms' one motion, within both arms' joints
        self.shaper = SheetShaper(size=cfg.material.size, rates=JointRates(
            {"left": cfg.reach.left_base, "right": cfg.reach.right_base}, qd, qd * p.arm_accel_scale))
        self._motion_q: dict[str, np.ndarray] = {}
        self._plans: deque = deque(maxlen=VELOCITY_PLANS)       # (time s, origin, R, strain) of the last plans
        self._k_fem: float | None = None
        self._k_fem_at = 0.0
        self._press: tuple[float, float] | None = None
        self._k_hist: deque[tuple[float, float]] = deque(maxlen=256)
        self._fem_other_scene = 0
        self._source = ""
        self.scene_scale = None
        self.pub_sheet = self.publisher(topics.SHEET_TARGET)
        self.pub_left = self.publisher(topics.ARM_LEFT_TARGET)
        self.pub_right = self.publisher(topics.ARM_RIGHT_TARGET)
        self.subscribe(topics.FINGERTIP, self.on_fingertip, qos=QoS.LATEST, sim_cost=LAB.compute("planner"))
        self.subscribe(topics.DEFORMATION, self.on_deformation, qos=QoS.LATEST)
        self.subscribe(topics.FORCE_DEPTH, self.on_force_depth)
        self.subscribe(topics.EYE_POSE, self.on_eye_pose, qos=QoS.LATEST)
        # the arms' measured clamp poses, read only where a motion starts from the held sheet (sampled: the
        # 140 Hz joint states are decoded then, not each)
        self._arm_states = {"left": self.sample(topics.ARM_LEFT_STATE), "right": self.sample(topics.ARM_RIGHT_STATE)}
        self.pull_guard = PullGuard({"left": cfg.reach.left_base, "right": cfg.reach.right_base}, p.pull_margin)
        self._pull_said: tuple[int, float] | None = None     # (joint, limit N) last said
        self._cap_pull(*clamp_poses(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]),
                                    cfg.material.min_stretch, cfg.material.size))        # the sheet's home pose

    def _cap_pull(self, T_left: np.ndarray, T_right: np.ndarray) -> None:
        """The next plans' clamp force: ``pull_margin`` × the arms' torque-limited pull at these targets
        (:class:`PullGuard`); said when the limiting joint changes, or the limit by more than 10 %."""
        limit = self.pull_guard.limit(T_left, T_right)
        self.planner.set_pull_limit(limit)
        side, joint, _ = self.pull_guard.limiting()
        said = self._pull_said
        if limit is not None and (said is None or said[0] != joint or abs(limit - said[1]) > 0.1 * said[1]):
            self._pull_said = (joint, limit)
            self.log.info("clamp force limited to %.1f N by the %s arm's J%d torque at its target "
                          "(flexsheet/arm/pull_limit.py; material max_force %.0f N)", limit, side, joint,
                          self.planner.cfg.material.max_force)

    def _held_sheet(self, size: float):
        """(origin (3,) m, rotation (3, 3), strain) of the sheet as the arms' measured clamps hold it, or None
        (a state missing or not a sheet: :func:`flexsheet.model.sheet.frame_from_clamps`)."""
        left, right = (self._arm_states[side].read() for side in ("left", "right"))
        if left is None or right is None:
            return None
        try:
            o, n, u, a = frame_from_clamps(np.asarray(left.pose, float), np.asarray(right.pose, float))
        except ValueError:
            return None
        return o, sheet_rotation(n, u), max(2.0 * a / size - 1.0, 0.0)   # slack: from a straight sheet

    def on_eye_pose(self, msg: EyePose) -> None:
        """The viewer's tracked eye: the keep-out follows it; lost glasses hold the sheet (:class:`HeadGuard`)."""
        was = self.guard.state
        try:
            self.guard.set_eye(msg.eye, msg.valid)
        except ValueError as exc:
            raise InputRejected(f"/eye/pose: {exc}") from None
        if self.guard.state != was:
            (self.log.warning if self.guard.state == "lost" else self.log.info)(
                "viewer's head %s", {"tracking": "tracked: the sheet keeps out of its keep-out volume",
                                     "lost": "lost: holding the sheet until the glasses are seen again"}[self.guard.state])

    def on_force_depth(self, msg: ObjectForceDepth) -> None:
        """The object's force–depth from its FEM: the planner's request from now on
        (:meth:`SurfacePlanner.set_force_depth`). Unless ``stiffness_scale`` was set, the scene's one scale
        (:func:`flexsheet.model.force_depth.scene_scale`) maps it between the sheet's force at its least stretch
        and at ``pull_margin`` × the arms' pull at the home pose, over 2 mm to twice the scene's stroke depth.
        A table about another object is ignored; a malformed one is rejected (counted)."""
        if msg.scene_key and msg.scene_key != self._scene_key:
            self.log.warning("/object/force_depth is about another object than scene %r; ignored", self.scene.name)
            return
        try:
            table = ForceDepth(msg.points, msg.normals, tuple(msg.names), msg.depths, msg.force, msg.scene_key)
        except ValueError as exc:
            raise InputRejected(f"/object/force_depth: {exc}") from None
        p: PlannerParams = self.params
        cfg = self.planner.cfg
        if "stiffness_scale" not in p.model_fields_set:
            stroke_depth = self.scene.use.stroke_depth
            sc = sheet_scene_scale(table, cfg.material, self.planner.max_stretch, stroke_depth, cfg.contrast_gain)
            self.planner.cfg = replace(cfg, stiffness_scale=sc.scale)
            self.scene_scale = sc
            d_lo, d_hi = scale_depths(stroke_depth)
            self.log.info("object's force-depth from its FEM (%d points): one scale %.3g for the scene (presentable "
                          "from %.3g to %.3g over %.0f-%.0f mm; %s, %.0f %% of its samples saturate)", len(table.names),
                          sc.scale, sc.low, sc.high, d_lo * 1e3, d_hi * 1e3,
                          "it fits" if sc.fits else "it does NOT fit", 100 * sc.saturated)
        self.planner.set_force_depth(table)

    def on_deformation(self, msg: ObjectDeformation) -> None:
        """Keep the FEM's local stiffness (N/m) and its press (contact force N at its depth m) while the solution
        is valid, positive and about this scene (:func:`fem_solves_scene`)."""
        if not (msg.valid and msg.stiffness > 0.0):
            return
        if not fem_solves_scene(msg, self.scene, self._scene_key):
            self._fem_other_scene += 1
            return
        now = self.now()
        self._k_hist.append((now, float(msg.stiffness)))
        w = self.params.fem_window
        recent = [k for t, k in self._k_hist if now - t <= w] if w > 0 else [float(msg.stiffness)]
        self._k_fem = float(np.median(recent))
        self._k_fem_at = now
        self._press = (float(msg.contact_force), float(msg.depth))

    def _stiffness(self) -> tuple[float | None, str]:
        """(stiffness N/m, source): the FEM's while fresh ("fem"); ``None`` for the planner's compliance model
        ("scene"); else ``object_stiffness`` ("param")."""
        p: PlannerParams = self.params
        if p.use_fem_stiffness and self._k_fem is not None and self.now() - self._k_fem_at <= p.fem_timeout:
            return self._k_fem, "fem"
        if self.planner.compliance is None:
            return p.object_stiffness, "param"
        return None, "scene"

    def _note_source(self, source: str) -> None:
        """Say in the heartbeat's message which stiffness sets the tension (on change)."""
        text = {"table": "the object's force-depth from its FEM (/object/force_depth)",
                "fem": "the FEM's dF/dd, and its force from 2 mm deep",
                "scene": "the scene's estimate at the contact (Hertz contact + inclusions, flexsheet/planning/compliance.py)",
                "param": f"object_stiffness {self.params.object_stiffness:g} N/m"}[source]
        if self._fem_other_scene and source != "fem":
            text += (f"; the FEM's stiffness is not used: it solves another object than scene "
                     f"{self.scene.name!r} ({self._fem_other_scene} messages so far)")
        cfg = self.planner.cfg
        if cfg.stiffness_scale != 1.0:
            text += f"; x {cfg.stiffness_scale:.4g} (stiffness_scale" + (", the scene's)" if self.scene_scale else ")")
        if cfg.contrast_gain != 1.0:
            text += f"; contrast_gain {cfg.contrast_gain:g}"
        if text != self._source:
            self._source = text
            self.state_message = f"stiffness: {text}"
            self.log.info("sheet tension from %s", text)

    def on_fingertip(self, msg: Fingertip) -> None:
        """Plan and publish; a lost marker holds the last safe pose (status ``hold:marker_lost``); a lost head
        holds the pose while the stretch follows the push (``hold:head_lost``, :meth:`SurfacePlanner.hold_pose`)."""
        if not msg.valid:
            plan = self.planner.hold(Hold.MARKER_LOST)
        else:
            predict = self.params.use_prediction        # read once: param set may change it meanwhile
            pos = msg.predicted_position if predict else msg.position
            k, source = self._stiffness()
            t = msg.header.stamp + (msg.prediction_horizon if predict else 0.0)
            press = self._press if source == "fem" else None
            if self.guard.lost and not self.guard.near:
                plan = self.planner.hold_pose(Hold.HEAD_LOST, t, pos, k, now=self.now(), object_press=press)
            else:
                plan = self.planner.update(t, pos, k, now=self.now(), object_press=press)
            if plan is not None and not plan.status.startswith("hold"):
                self._note_source("table" if plan.k_source == "table" else source)
        if plan is None:
            raise InputRejected(f"fingertip: no safe pose yet to hold (valid={msg.valid})")
        self.publish_plan(plan, msg.exposure_stamp)
        if plan.status in INPUT_REJECTIONS:
            raise InputRejected(f"fingertip: {plan.status} (stamp={msg.header.stamp!r}, "
                                f"position={msg.position.tolist()})")

    def publish_plan(self, plan: Plan, source_stamp: float) -> None:
        """Publish the sheet target and both clamp targets for ``plan``."""
        st = self.pub_sheet.header("display")
        f = np.asarray
        self.pub_sheet.publish(SheetTarget(
            header=st, contact_point=f(plan.contact, float), normal=f(plan.normal, float),
            axis_u=f(plan.axis_u, float), axis_v=f(plan.axis_v, float), sheet_origin=f(plan.origin, float),
            stretch=float(plan.stretch), tension=float(plan.tension), stiffness=float(plan.stiffness),
            object_stiffness=float(plan.object_stiffness), touching=bool(plan.touching), status=plan.status,
            source_stamp=float(source_stamp)))
        Tl, Tr = plan.clamp_matrices()
        pull = clamp_force(plan.stretch, self.planner.cfg.material)
        self._cap_pull(Tl, Tr)                                  # for the next plans, at these targets
        motion = self._motion(plan)
        self.pub_left.publish(ArmTarget(header=self.pub_left.header("display", st.stamp), arm="left", pose=Tl,
                                        source_stamp=float(source_stamp), status=plan.status, pull=pull, **motion))
        self.pub_right.publish(ArmTarget(header=self.pub_right.header("display", st.stamp), arm="right", pose=Tr,
                                         source_stamp=float(source_stamp), status=plan.status, pull=pull, **motion))

    def _motion(self, plan: Plan) -> dict:
        """The sheet's motion from where it is now to ``plan``, as :class:`ArmTarget` fields (both arms get the
        same: :mod:`flexsheet.arm.sheet_motion`), under the planner's current limits (reduced near the head).
        ``{}`` when ruckig fails: the bridges then stream to the goal joint by joint (said once)."""
        lim = self.planner.limiter.limits
        self.shaper.size = float(plan.sheet_size)
        q_goal = dict(self.pull_guard.seed)                     # the IK of this plan's two targets
        self.shaper.rates.at({s: [q_goal[s]] + ([self._motion_q[s]] if s in self._motion_q else []) for s in q_goal})
        self._motion_q = q_goal
        # the plan's own velocity, fitted over its last plans, and its period: the motion reaches the plan's
        # track by the next plan instead of stopping at each (a finger's tremor makes each plan's own rate noisy)
        now = self.now()
        R = sheet_rotation(plan.normal, plan.axis_u)
        moving = not plan.status.startswith("hold")
        hist = self._plans
        if not moving or (hist and not 0.0 < now - hist[-1][0] <= 0.1):
            hist.clear()
        period = now - hist[-1][0] if hist else 0.0
        hist.append((now, np.asarray(plan.origin, float), R, float(plan.stretch)))
        velocity = plan_velocity(hist) if moving and len(hist) >= 2 else None
        try:
            seg = self.shaper.update(now, plan.origin, R, plan.stretch, lim,
                                     velocity=velocity, lead=min(period, 0.05) if velocity is not None else 0.0,
                                     current=None if self.shaper.segment is not None
                                     else self._held_sheet(float(plan.sheet_size)))
        except MotionError as exc:
            if self.shaper.failures == 1:
                self.log.warning("sheet motion: %s; the arms stream to this target joint by joint (said once)", exc)
            return {}
        return seg.fields()
