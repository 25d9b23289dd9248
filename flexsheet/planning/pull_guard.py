"""The clamp force the planner may ask, from the arms' joint torques at the poses it sends them to (pure).

:func:`flexsheet.arm.pull_limit.max_pull` bounds the sheet's pull at a joint configuration. The bridges refuse
a target whose pull passes it (``hold:torque:J<k>``, and the other arm holds with it), so the planner must
keep under it *at the targets it sends*, not at where the arms are: a held arm is far from its next target,
and the limit there can be lower. :class:`PullGuard` solves IK for each plan's two clamp targets (seeded from
the last solutions; ~0.1 ms an arm) and returns ``margin`` × the smaller arm's limit there, which the planner
applies from its next plan on (:meth:`flexsheet.planning.surface_planner.SurfacePlanner.set_pull_limit`);
targets move by a rate-limited step a cycle, which the margin covers.

Units: N, m, rad.
"""

from __future__ import annotations

import math

import numpy as np

from flexsheet.arm.kinematics import ArmKinematics, home_joints
from flexsheet.arm.pull_limit import max_pull

__all__ = ["PullGuard"]


class PullGuard:
    """Pull limits at clamp targets. ``bases``: {side: (x, y, z, yaw) or (4, 4) T_display_base} of both arms
    (the registered ones); ``margin`` in (0, 1]. Raises ``ValueError`` on a bad margin, side or base."""

    def __init__(self, bases: dict, margin: float = 0.9) -> None:
        if not (0.0 < margin <= 1.0):
            raise ValueError(f"margin must be in (0, 1], got {margin!r}")
        if set(bases) != {"left", "right"}:
            raise ValueError(f"bases must name 'left' and 'right', got {sorted(bases)}")
        self.margin = float(margin)
        self.kin = {s: ArmKinematics(s, b) for s, b in bases.items()}
        self.seed = {s: home_joints(s) for s in self.kin}
        self.pull = {s: math.inf for s in self.kin}
        self.joint = {s: 0 for s in self.kin}

    def limit(self, T_left: np.ndarray, T_right: np.ndarray) -> float | None:
        """``margin`` × the smaller arm's largest pull (N) at the IK solutions of the clamp targets (4, 4); an
        arm whose target IK does not solve keeps its last figure (its bridge refuses that target anyway). None
        while no arm's limit is known (no joint loaded)."""
        for side, T in (("left", T_left), ("right", T_right)):
            res = self.kin[side].ik(T, self.seed[side])
            if res.ok:
                self.seed[side] = res.q
                self.pull[side], self.joint[side] = max_pull(self.kin[side], res.q)
        f = min(self.pull.values())
        return self.margin * f if math.isfinite(f) else None

    def limiting(self) -> tuple[str, int, float]:
        """(side, 1-based joint, pull N) of the arm that sets the limit now."""
        side = min(self.pull, key=self.pull.get)
        return side, self.joint[side], self.pull[side]
