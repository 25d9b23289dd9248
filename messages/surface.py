"""Surface-planner messages: the sheet target and the end-effector (edge clamp) targets."""

from __future__ import annotations

import numpy as np
from pydantic import Field

from messages.common import Message, ndarray

__all__ = ["SheetTarget", "ArmTarget"]


class SheetTarget(Message):
    """Where the sheet must be: the tangent plane of the virtual object at the contact point.
    All vectors in the display frame. ``contact_point`` (3,) m: the point of the virtual surface the finger
    meets (paper §V-A, point A or B). ``normal`` (3,): unit outward surface normal there (the sheet's normal,
    pointing toward the user). ``axis_u`` (3,), ``axis_v`` (3,): unit in-plane axes of the sheet (``axis_u``
    from the right clamp to the left clamp, +y at home; ``axis_v = normal × axis_u``, +z at home; see
    :mod:`flexsheet.model.geometry`). ``sheet_origin`` (3,) m: where the sheet centre must be (the
    contact point shifted along the sheet by the rolled arc, Fig. 7). ``stretch``: engineering strain of the
    sheet between the clamps (dimensionless). ``tension``: membrane tension, N/m. ``stiffness``: normal
    stiffness the sheet presents at the contact, N/m. ``object_stiffness``: the requested virtual-object
    stiffness, N/m. ``touching``: the finger is in active-touch mode. ``status``: "ok", or a short reason
    (``"unreachable"``, ``"object_stiffer_than_sheet"``, ``"hold:invalid_fingertip"``…). ``source_stamp``:
    exposure stamp of the fingertip this target was planned from, s (latency accounting).
    """

    SCHEMA = "flexsheet/SheetTarget"
    VERSION = 1

    contact_point: ndarray("float64", (3,), "contact point, m, display frame")
    normal: ndarray("float64", (3,), "unit sheet normal, display frame")
    axis_u: ndarray("float64", (3,), "unit in-plane axis, right->left clamp (+y at home)")
    axis_v: ndarray("float64", (3,), "unit in-plane axis, normal x axis_u (+z at home)")
    sheet_origin: ndarray("float64", (3,), "sheet centre target, m, display frame")
    stretch: float = Field(ge=0.0, description="sheet engineering strain between clamps")
    tension: float = Field(ge=0.0, description="membrane tension, N/m")
    stiffness: float = Field(ge=0.0, description="normal stiffness presented at the contact, N/m")
    object_stiffness: float = Field(ge=0.0, description="requested object stiffness, N/m")
    touching: bool = Field(default=False, description="active-touch (stroking) mode")
    status: str = Field(default="ok", description="'ok' or the reason for a hold/clamp")
    source_stamp: float = Field(default=0.0, description="exposure stamp of the source fingertip, s")


class ArmTarget(Message):
    """End-effector (sheet-clamp tool frame) target pose for one arm, in the display frame.
    ``pose`` (4, 4): homogeneous transform T_display_clamp, m. ``arm``: "left" or "right".
    ``source_stamp``: exposure stamp of the source fingertip, s. ``status`` as in :class:`SheetTarget`.
    ``pull`` N: the sheet's pull on this clamp toward the sheet's centre at this target (the planned clamp
    force); the bridge refuses a target whose joint torques Jᵀ·F pass the arm's limits
    (:mod:`flexsheet.arm.pull_limit`, ``hold:torque:J<k>``).

    The sheet's motion to ``pose`` (:class:`flexsheet.arm.sheet_motion.SheetSegment`), the same in both arms'
    targets, so both bridges evaluate one trajectory at the same instant: ``motion_t0`` s (graph clock; None:
    no motion, the bridge's joint limiter shapes the way to ``pose``), ``motion_frame`` (3, 3) the segment's
    reference rotation, ``motion`` (8, 7) rows: start state, its velocity, its acceleration, goal, its
    velocity, and the per-DOF velocity, acceleration and jerk limits (columns: centre x, y, z m; rotation
    vector rad; clamp strain), ``motion_size`` m the sheet's unstretched side, ``motion_min_duration`` s its
    least duration.

    ``joints`` (6,) rad: the publisher's IK of ``pose`` for this arm (the planner solves once per plan, on the
    bridges' registered bases); the bridge checks them (the pose, its limits, the jump, keep-out, torque)
    instead of solving again, and solves only when they do not pass. Empty: none given, the bridge solves.
    """

    SCHEMA = "flexsheet/ArmTarget"
    VERSION = 4    # v4: joints, the planner's IK

    arm: str = Field(pattern="^(left|right)$", description="which arm: left or right")
    pose: ndarray("float64", (4, 4), "T_display_clamp, m")
    source_stamp: float = Field(default=0.0, description="exposure stamp of the source fingertip, s")
    status: str = Field(default="ok", description="'ok' or a reason")
    pull: float = Field(default=0.0, ge=0.0, description="sheet's pull on the clamp toward the sheet centre, "
                                                         "N")
    motion_t0: float | None = Field(default=None, description="start of the sheet's motion segment, s; None: "
                                                              "none")
    motion_frame: ndarray("float64", (3, 3), "segment's reference rotation, display frame") = Field(
        default_factory=lambda: np.eye(3))
    motion: ndarray("float64", (8, 7), "rows: start, velocity, acceleration, goal, goal velocity, v/a/j "
                    "limits; columns: centre m, rotation vector rad, strain") = Field(default_factory=
                                                                                  lambda: np.zeros((8, 7)))
    motion_size: float = Field(default=0.24, gt=0.0, description="sheet's unstretched side, m")
    motion_min_duration: float = Field(default=0.0, ge=0.0, description="the segment's least duration, s")
    joints: ndarray("float64", (None,), "the publisher's IK of pose, rad: (6,), or empty (none)") = Field(
        default_factory=lambda: np.zeros(0))
