"""The two arms' command for a plan (pure; time is passed in): both clamp poses, the pull, and the sheet's
motion.

The one owner of the two arms' motion on the planner's side. For each :class:`~flexsheet.planning.plan.Plan`
the :class:`ArmCommander`

- takes both clamp targets' IK (:class:`~flexsheet.planning.pull_guard.PullGuard`, from the planner's
  :class:`~flexsheet.planning.arm_reach.ArmReach`: one solve per arm and plan), sends it with the targets
  (the bridges check it rather than solve again) and caps the next plans' clamp force at ``pull_margin`` ×
  the arms' torque-limited pull there;
- shapes the sheet's motion from where it is to the plan (:class:`flexsheet.arm.sheet_motion.SheetShaper`),
  within both arms' joint rates (:class:`~flexsheet.arm.joint_rates.JointRates` at ``speed_scale`` × the
  URDF's joint speeds and ``accel_scale`` × that per second: the bridges' own scales), and at the plan's own
  velocity fitted over its last plans, so that the motion reaches the plan's track by the next plan.

Both arms get the same motion; each bridge evaluates it at one instant (:mod:`flexsheet.arm.tracking`).
Units: m, rad, s, N; display frame.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from flexsheet.arm.bridge_config import BridgeConfig
from flexsheet.arm.joint_rates import JointRates
from flexsheet.arm.kinematics import QD_MAX
from flexsheet.arm.sheet_motion import VELOCITY_PLANS, MotionError, SheetShaper, plan_velocity
from flexsheet.model.motion_limits import MotionLimits
from flexsheet.model.sheet import clamp_poses, sheet_rotation
from flexsheet.model.tension import SheetMaterial, clamp_force
from flexsheet.planning.arm_reach import ArmReach
from flexsheet.planning.plan import Plan
from flexsheet.planning.pull_guard import PullGuard

__all__ = ["ArmCommand", "ArmCommander", "SPEED_SCALE", "ACCEL_SCALE"]

#: the bridges' default ``speed_scale`` and ``accel_scale`` (1/s): the commander's defaults
SPEED_SCALE = BridgeConfig.speed_scale
ACCEL_SCALE = BridgeConfig.accel_scale


@dataclass(frozen=True)
class ArmCommand:
    """One plan's command to both arms. ``left``/``right``: clamp poses (4, 4), display frame; ``joints``:
    {side: (6,) rad IK of that pose, or an empty array where it did not solve} for the bridges to check
    instead of solving; ``pull`` N: the sheet's clamp force at the plan's stretch; ``motion``:
    :class:`flexsheet.arm.sheet_motion.SheetSegment` fields for :class:`messages.ArmTarget` (``{}`` when the
    motion could not be shaped: the bridges then stream to the goal joint by joint); ``warn``: a warning to
    log (the motion's first failure) or ''."""

    left: np.ndarray
    right: np.ndarray
    joints: dict
    pull: float
    motion: dict
    warn: str = ""


class ArmCommander:
    """Both arms' command for each plan (see module docstring). ``bases``: {"left", "right"}: (x, y, z, yaw)
    of the arms' bases (registered); ``material``: the sheet; ``pull_margin`` in (0, 1]; ``speed_scale`` in
    (0, 1], ``accel_scale`` 1/s > 0; ``reach``: the planner's :class:`~flexsheet.planning.arm_reach.ArmReach`,
    whose solve of each plan's targets the pull guard reuses (None: one of its own). Raises ``ValueError`` on
    a bad margin or base."""

    def __init__(self, bases: dict, material: SheetMaterial, pull_margin: float = 0.9,
                 speed_scale: float = SPEED_SCALE, accel_scale: float = ACCEL_SCALE,
                 reach: ArmReach | None = None) -> None:
        self.material = material
        self.pull_guard = PullGuard(bases, pull_margin, reach)
        qd = QD_MAX * speed_scale
        self.shaper = SheetShaper(size=material.size, rates=JointRates(bases, qd, qd * accel_scale))
        self._motion_q: dict[str, np.ndarray] = {}
        self._plans: deque = deque(maxlen=VELOCITY_PLANS)  # (time s, origin, R, strain) of the last plans
        self._pull_said: tuple[int, float] | None = None      # (joint, limit N) last said

    def home_limit(self) -> tuple[float | None, str]:
        """(pull limit N or None, log line or '') at the sheet's home pose: the first plans' cap."""
        m = self.material
        return self._cap_pull(*clamp_poses(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]),
                                           m.min_stretch, m.size))

    def command(self, plan: Plan, now: float, limits: MotionLimits,
                held: Callable[[float], tuple | None]) -> ArmCommand:
        """The command for ``plan`` at time ``now`` s. ``limits``: the planner's current motion limits;
        ``held(size)``: the sheet as the arms' measured clamps hold it ((origin (3,), R (3, 3), strain) or
        None), read only where a motion starts from rest. The pull limit at its targets is
        :meth:`cap_pull`'s, once the command is sent."""
        Tl, Tr = plan.clamp_matrices()
        solved = self.pull_guard.solve(Tl, Tr)
        motion, failed = self._motion(plan, now, limits, held)
        pull = clamp_force(plan.stretch, self.material)
        joints = {s: (np.zeros(0) if q is None else q) for s, q in solved.items()}
        return ArmCommand(Tl, Tr, joints, pull, motion, failed)

    def cap_pull(self) -> tuple[float | None, str]:
        """(``pull_margin`` × the arms' torque-limited pull N at the last command's targets, or None; a line
        when the limiting joint changes or the limit by more than 10 %, else ''): the next plans' cap."""
        return self._cap_pull(None, None)

    def _cap_pull(self, T_left: np.ndarray | None, T_right: np.ndarray | None) -> tuple[float | None, str]:
        """:meth:`cap_pull` at these targets (None: at the joints solved last)."""
        limit = (self.pull_guard.limit_at_solved() if T_left is None
                 else self.pull_guard.limit(T_left, T_right))
        side, joint, _ = self.pull_guard.limiting()
        said = self._pull_said
        if limit is not None and (said is None or said[0] != joint or abs(limit - said[1]) > 0.1 * said[1]):
            self._pull_said = (joint, limit)
            return limit, (f"clamp force limited to {limit:.1f} N by the {side} arm's J{joint} torque at its "
                           f"target (flexsheet/arm/pull_limit.py; material max_force "
                           f"{self.material.max_force:.0f} N)")
        return limit, ""

    def _motion(self, plan: Plan, now: float, limits: MotionLimits, held) -> tuple[dict, str]:
        """The sheet's motion from where it is now to ``plan`` as message fields, and a line on its first
        failure."""
        self.shaper.size = float(plan.sheet_size)
        q_goal = dict(self.pull_guard.seed)                     # the IK of this plan's two targets
        self.shaper.rates.at({s: [q_goal[s]] + ([self._motion_q[s]] if s in self._motion_q else [])
                              for s in q_goal})
        self._motion_q = q_goal
        # the plan's own velocity, fitted over its last plans, and its period: the motion reaches the plan's
        # track by the next plan instead of stopping at each
        # (a finger's tremor makes each plan's own rate noisy)
        R = sheet_rotation(plan.normal, plan.axis_u)
        moving = not plan.status.startswith("hold")
        hist = self._plans
        if not moving or (hist and not 0.0 < now - hist[-1][0] <= 0.1):
            hist.clear()
        period = now - hist[-1][0] if hist else 0.0
        hist.append((now, np.asarray(plan.origin, float), R, float(plan.stretch)))
        velocity = plan_velocity(hist) if moving and len(hist) >= 2 else None
        try:
            seg = self.shaper.update(now, plan.origin, R, plan.stretch, limits,
                                     velocity=velocity,
                                     lead=min(period, 0.05) if velocity is not None else 0.0,
                                     current=None if self.shaper.segment is not None
                                     else held(float(plan.sheet_size)))
        except MotionError as exc:
            if self.shaper.failures == 1:
                return {}, f"sheet motion: {exc}; the arms stream to this target joint by joint (said once)"
            return {}, ""
        return seg.fields(), ""
