"""The clamp force the planner may ask, from the arms' joint torques at the poses it sends them to (pure).

:func:`flexsheet.arm.pull_limit.max_pull` bounds the sheet's pull at a joint configuration. The bridges refuse
a target whose pull passes it (``hold:torque:J<k>``, and the other arm holds with it), so the planner must
keep under it *at the targets it sends*, not at where the arms are: a held arm is far from its next target,
and the limit there can be lower. :class:`PullGuard` takes the IK of each plan's two clamp targets from the
:class:`~flexsheet.planning.arm_reach.ArmReach` it shares with the planner's reach check (one solve per arm
and plan, seeded from the last solutions; ~0.1 ms an arm) and returns ``margin`` × the smaller arm's limit
there, which the planner applies from its next plan on
(:meth:`flexsheet.planning.surface_planner.SurfacePlanner.set_pull_limit`); targets move by a rate-limited
step a cycle, which the margin covers.

Units: N, m, rad.
"""

from __future__ import annotations

import math

import numpy as np

from flexsheet.arm.pull_limit import max_pull
from flexsheet.planning.arm_reach import ArmReach

__all__ = ["PullGuard"]


class PullGuard:
    """Pull limits at clamp targets. ``bases``: {side: (x, y, z, yaw) or (4, 4) T_display_base} of both arms
    (the registered ones); ``margin`` in (0, 1]; ``reach``: the planner's :class:`ArmReach` to share (None:
    one of its own on ``bases``). Raises ``ValueError`` on a bad margin, side or base."""

    def __init__(self, bases: dict, margin: float = 0.9, reach: ArmReach | None = None) -> None:
        if not (0.0 < margin <= 1.0):
            raise ValueError(f"margin must be in (0, 1], got {margin!r}")
        self.reach = reach if reach is not None else ArmReach(bases)
        self.margin = float(margin)
        self.kin = self.reach.kin
        self.pull = {s: math.inf for s in self.kin}
        self.joint = {s: 0 for s in self.kin}
        #: side -> the last targets' IK solution (6,) rad, or None where it did not solve
        self.solved: dict[str, np.ndarray | None] = {s: None for s in self.kin}

    @property
    def seed(self) -> dict:
        """Each arm's last IK solution (6,) rad: the next target's seed."""
        return self.reach.seed

    def limit(self, T_left: np.ndarray, T_right: np.ndarray) -> float | None:
        """``margin`` × the smaller arm's largest pull (N) at the IK solutions of the clamp targets (4, 4); an
        arm whose target IK does not solve keeps its last figure (its bridge refuses that target anyway). None
        while no arm's limit is known (no joint loaded)."""
        self.solve(T_left, T_right)
        return self.limit_at_solved()

    def solve(self, T_left: np.ndarray, T_right: np.ndarray) -> dict[str, np.ndarray | None]:
        """The clamp targets' (4, 4) IK (the reach's one solve per arm, which moves its seeds): ``solved``,
        side → (6,) rad or None where it did not solve."""
        for side, res in self.reach.solve(T_left, T_right).items():
            self.solved[side] = res.q if res.ok else None
        return self.solved

    def limit_at_solved(self) -> float | None:
        """:meth:`limit` at the joints :meth:`solve` found last (an arm that did not solve keeps its last
        figure)."""
        for side, q in self.solved.items():
            if q is not None:
                self.pull[side], self.joint[side] = max_pull(self.kin[side], q)
        f = min(self.pull.values())
        return self.margin * f if math.isfinite(f) else None

    def limiting(self) -> tuple[str, int, float]:
        """(side, 1-based joint, pull N) of the arm that sets the limit now."""
        side = min(self.pull, key=self.pull.get)
        return side, self.joint[side], self.pull[side]
