"""The planner's guard of the viewer's head: reduced speed near it, hold and retreat before the sheet enters
it.

:class:`HeadGuard` keeps the newest tracked eye (``/eye/pose``) and judges each rate-limited sheet pose the
planner would send against the head's keep-out volume (:class:`flexsheet.planning.keepout.KeepOut`: a head
sphere plus a margin, from the eye):

* **near** (the current sheet within ``near_distance`` of the keep-out): the sheet's motion limits drop so no
  point of the sheet moves faster than ``reduced_speed`` (ISO 10218-1's 250 mm/s): centre speed
  ``v ≤ 0.45·reduced_speed``, turn rate ``ω ≤ 0.35·reduced_speed / r`` (r: the sheet's corner radius) and
  clamp strain rate ``≤ 0.1·reduced_speed / (size/2)``: together at most 0.9 of it at any corner;
* **inside** (the next pose would put a point of the sheet or a clamp in the keep-out): the step is not taken;
  the sheet backs off along −x (:func:`~flexsheet.planning.keepout.retreat_point`) at the reduced speed;
* **the arms** (:meth:`HeadGuard.arms`): both arms at the IK of the pose to send, by the bridges' own test
  (:func:`~flexsheet.planning.keepout.arm_keepout_clearance`) at this guard's larger margin, so no bridge
  refuses a target for the keep-out; inside, the planner backs off the same way (``keep_out:<arm> <part>``);
* **lost** (the head camera runs but the glasses are not found): the planner holds the pose while the stretch
  follows the push (:meth:`~flexsheet.planning.surface_planner.SurfacePlanner.hold_pose`); lost while near
  (:attr:`HeadGuard.near`), every step backs off from the last known head instead, since a head that was that
  close may come closer unseen.

The guard judges the *planned* sheet against the *tracked* head, so it keeps a guard band (``band``, 0.01 m)
beyond the margin: the tracked eye's error (≤ 3.5 mm p95 in the twin, docs/head.md) and the arms' tracking of
the planned clamps must not carry the true sheet into the margin.

No tracked eye yet (no head camera): the guard is inactive and says so through :attr:`HeadGuard.state`.
Units m, s; display frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from flexsheet.model.motion_limits import MotionLimits
from flexsheet.model.sheet import clamp_half_span
from flexsheet.planning.keepout import (
    KeepOut,
    KeepOutVerdict,
    arm_keepout_clearance,
    check_targets,
    retreat_point,
    sheet_points,
)

__all__ = ["HeadGuard", "GuardStep", "GUARD_BAND"]


@dataclass(frozen=True)
class GuardStep:
    """What the guard made of one step: ``origin`` (3,) m and the rotation (3, 3) to send, ``retreat`` (True:
    the step was replaced by a back-off), ``verdict`` of the pose sent."""

    origin: np.ndarray
    R: np.ndarray
    retreat: bool
    verdict: KeepOutVerdict


#: m the guard adds to the keep-out's margin for the errors of the tracked eye and of the arms (module doc)
GUARD_BAND = 0.01


class HeadGuard:
    """See the module docstring. ``keepout``: the volume to keep out of; ``size`` m: the unstretched sheet
    side; ``band`` m: added to its margin for the estimates' errors. Raises ``ValueError`` for a negative
    band."""

    def __init__(self, keepout: KeepOut | None = None, size: float = 0.240, band: float = GUARD_BAND) -> None:
        if not (math.isfinite(band) and band >= 0.0):
            raise ValueError(f"band must be >= 0 m, got {band!r}")
        base = keepout or KeepOut()
        self.keepout = replace(base, margin=base.margin + band)
        self.size = float(size)
        self.eye: np.ndarray | None = None
        self.lost = False
        #: the last judged sheet (or arms, :meth:`arms`) was within ``near_distance`` of the keep-out
        self.near = False
        #: the arms of the last plan were within ``near_distance`` of the keep-out (its caller sets it)
        self.arms_near = False
        self.counts = {"near": 0, "retreat": 0}

    @property
    def state(self) -> str:
        """"inactive" (no eye yet), "lost" or "tracking"."""
        return "inactive" if self.eye is None else ("lost" if self.lost else "tracking")

    def set_eye(self, eye, valid: bool) -> None:
        """A new ``/eye/pose``: the cyclopean eye (3,) m and whether the glasses were found. Raises
        ``ValueError`` on a non-finite eye."""
        e = np.asarray(eye, float).ravel()
        if e.shape != (3,) or not np.all(np.isfinite(e)):
            raise ValueError(f"eye must be 3 finite numbers (m), got {eye!r}")
        if valid:
            self.eye, self.lost = e, False
        elif self.eye is not None:
            self.lost = True

    def verdict(self, origin, R, stretch: float) -> KeepOutVerdict:
        """The keep-out verdict of the sheet at ``origin`` (3,) m with axes ``R`` (3, 3) (columns n, u, v) and
        clamp strain ``stretch``. Requires a tracked eye."""
        Rm = np.asarray(R, float)
        pts = sheet_points(np.asarray(origin, float), Rm[:, 0], Rm[:, 1], clamp_half_span(stretch, self.size),
                           self.size)
        return check_targets(self.keepout, self.eye, pts)

    def limits(self, base: MotionLimits, origin, R, stretch: float) -> MotionLimits:
        """``base``, or the reduced limits while the sheet at (``origin``, ``R``, ``stretch``) is near the
        head."""
        if self.eye is None or origin is None:
            return base
        v = self.verdict(origin, R, stretch)
        self.near = v.clearance < self.keepout.near_distance or self.arms_near
        if not self.near:
            return base
        self.counts["near"] += 1
        r = math.hypot(0.5 * self.size, 0.5 * self.size)
        vs = self.keepout.reduced_speed
        return replace(base, v_max=min(base.v_max, 0.45 * vs), w_max=min(base.w_max, 0.35 * vs / r),
                       stretch_rate=min(base.stretch_rate, 0.1 * vs / (0.5 * self.size)))

    def arms(self, kins: dict, joints: dict) -> KeepOutVerdict:
        """The keep-out verdict of the arms ``kins`` {side: ArmKinematics} at ``joints`` {side: (6,) rad or
        None (not judged)}: the nearest arm part (``what`` "<side> arm link k" / "<side> arm clamp bar").
        Requires a tracked eye."""
        best, what = float("inf"), ""
        for side, q in joints.items():
            if q is not None:
                c, part = arm_keepout_clearance(self.keepout, self.eye, kins[side], q)
                if c < best:
                    best, what = c, f"{side} arm {part}"
        return KeepOutVerdict(best, best < 0.0, what, self.keepout.speed_limit(best))

    def step(self, prev_origin, prev_R, origin, R, stretch: float, dt: float) -> GuardStep:
        """Judge the step from (``prev_origin``, ``prev_R``) to (``origin``, ``R``) at ``stretch`` over ``dt``
        s: the step itself if it keeps out of the volume (and the head is tracked), else a back-off from the
        previous pose."""
        v = self.verdict(origin, R, stretch)
        if not v.inside and not self.lost:
            return GuardStep(np.asarray(origin, float), np.asarray(R, float), False, v)
        self.counts["retreat"] += 1
        Rp = np.asarray(prev_R, float)
        step = 0.45 * self.keepout.reduced_speed * max(float(dt), 1e-3)
        o = retreat_point(self.keepout, self.eye, np.asarray(prev_origin, float), Rp[:, 0], step)
        return GuardStep(o, Rp, True, self.verdict(o, Rp, stretch))
