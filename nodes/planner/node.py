"""Planner node: fingertip in, sheet target and the two clamp (arm) targets out. A thin shell around
:class:`nodes.planner.stroke.SurfacePlanner`.

Subscribes ``/fingertip`` (QoS LATEST; ``predicted_position`` when ``use_prediction``) and
``/object/deformation`` (QoS LATEST; its ``stiffness`` N/m sets the sheet tension while fresh).
Publishes ``/sheet/target``, ``/arm/left/target``, ``/arm/right/target`` with ``source_stamp`` = the
fingertip's ``exposure_stamp``. A lost marker (``valid=False``) or an input the planner refuses republishes
the last safe pose with status ``hold:<reason>``; an unreachable target holds the arms and says
``unreachable``. Malformed or NaN messages are rejected by the codec and counted in diagnostics.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from flexsheet.model.shapes import make_shape
from flexsheet.model.tension import SheetMaterial
from flexsheet.runtime.node import InputRejected, Node, QoS
from flexsheet.runtime.params import build, config_fields, params_model
from messages import ArmTarget, Fingertip, ObjectDeformation, SheetTarget, topics
from nodes.planner.limits import MotionLimits, ReachModel
from nodes.planner.stroke import Plan, PlannerConfig, SurfacePlanner

__all__ = ["PlannerParams", "PlannerNode"]


_MATERIAL = {"size": "sheet_size"}         # launch-file name of SheetMaterial.size


def _reach(p) -> ReachModel:
    """The reach model: the bases of ``display_calib`` (the registered display, ``arms.left``/``arms.right``)
    when the params name one, else the ``left_base``/``right_base`` params. Raises ``ValueError`` naming the
    file and entry when it is missing, unreadable or lacks an arm."""
    reach = build(ReachModel, p)
    path = getattr(p, "display_calib", None)
    if not path:
        return reach
    from dataclasses import replace

    from flexsheet.model.display_calib import load_display_calib, xyzyaw_from_pose

    dc = load_display_calib(path, require=("arms.left", "arms.right"))
    return replace(reach, left_base=xyzyaw_from_pose(dc.arms["left"].T_display_base),
                   right_base=xyzyaw_from_pose(dc.arms["right"].T_display_base))


def _planner_config(p) -> PlannerConfig:
    """The :class:`PlannerConfig` params ``p`` describe (raises ``ValueError`` on inconsistent values)."""
    return build(PlannerConfig, p, material=build(SheetMaterial, p, rename=_MATERIAL),
                 limits=build(MotionLimits, p), reach=_reach(p))


PlannerParams = params_model(
    "PlannerParams",
    """Planner parameters (launch file / ``--param k=v``). SI units, display frame.

    Node-only: ``shape``: cylinder | sphere | box | plane | mesh; ``shape_params``: that shape's keys (see
    :func:`flexsheet.model.shapes.make_shape`; empty = the paper's scene). ``use_prediction``: plan on
    ``Fingertip.predicted_position``; ``use_fem_stiffness``: use the FEM's stiffness while fresher than
    ``fem_timeout`` s, else ``object_stiffness``; ``display_calib``: the display registration
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
    check=_planner_config,
    methods={"planner_config": _planner_config},
    module=__name__,
    shape=(str, Field(default="cylinder", pattern="^(cylinder|sphere|box|plane|mesh)$")),
    shape_params=(dict, Field(default_factory=dict)),
    use_prediction=(bool, False),
    use_fem_stiffness=(bool, True),
    fem_timeout=(float, Field(default=0.5, gt=0.0)),
    display_calib=(str | None, Field(default=None, description="display.yaml whose arm bases the reach check uses")),
)


class PlannerNode(Node):
    """Surface-planner node (see module docstring). Params: :class:`PlannerParams`."""

    Params = PlannerParams
    node_type = "planner"

    async def setup(self) -> None:
        p: PlannerParams = self.params
        self.planner = SurfacePlanner(make_shape(p.shape, p.shape_params), p.planner_config())
        self._k_fem: float | None = None
        self._k_fem_at = 0.0
        self.pub_sheet = self.publisher(topics.SHEET_TARGET)
        self.pub_left = self.publisher(topics.ARM_LEFT_TARGET)
        self.pub_right = self.publisher(topics.ARM_RIGHT_TARGET)
        self.subscribe(topics.FINGERTIP, self.on_fingertip, qos=QoS.LATEST)
        self.subscribe(topics.DEFORMATION, self.on_deformation, qos=QoS.LATEST)

    def on_deformation(self, msg: ObjectDeformation) -> None:
        """Keep the FEM's local stiffness (N/m) while the solution is valid and positive."""
        if msg.valid and msg.stiffness > 0.0:
            self._k_fem = float(msg.stiffness)
            self._k_fem_at = self.now()

    def _stiffness(self) -> float:
        p: PlannerParams = self.params
        if p.use_fem_stiffness and self._k_fem is not None and self.now() - self._k_fem_at <= p.fem_timeout:
            return self._k_fem
        return p.object_stiffness

    def on_fingertip(self, msg: Fingertip) -> None:
        """Plan and publish; a lost marker holds the last safe pose (status ``hold:marker_lost``)."""
        if not msg.valid:
            plan = self.planner.hold("hold:marker_lost")
        else:
            pos = msg.predicted_position if self.params.use_prediction else msg.position
            plan = self.planner.update(msg.header.stamp + (msg.prediction_horizon if self.params.use_prediction else 0.0),
                                       pos, self._stiffness())
        if plan is None:
            raise InputRejected(f"fingertip: no safe pose yet to hold (valid={msg.valid})")
        self.publish_plan(plan, msg.exposure_stamp)
        if plan.status in ("hold:invalid_fingertip", "hold:invalid_stamp", "hold:stale_fingertip",
                           "hold:invalid_stiffness"):
            raise InputRejected(f"fingertip: {plan.status} (position={msg.position.tolist()})")

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
        self.pub_left.publish(ArmTarget(header=self.pub_left.header("display", st.stamp), arm="left", pose=Tl,
                                        source_stamp=float(source_stamp), status=plan.status))
        self.pub_right.publish(ArmTarget(header=self.pub_right.header("display", st.stamp), arm="right", pose=Tr,
                                         source_stamp=float(source_stamp), status=plan.status))
