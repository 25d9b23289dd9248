"""Both arms' inverse kinematics for the planner's clamp targets, solved once per target pair (pure).

:class:`ArmReach` owns the two :class:`~flexsheet.arm.kinematics.ArmKinematics` (the registered bases) and
their seeds (each arm's last solution). :meth:`ArmReach.solve` solves both clamp targets and keeps the
result of the last pair asked, so the planner's reach check and the pull guard
(:class:`~flexsheet.planning.pull_guard.PullGuard`) that follows it on the same plan share one solve per arm.
A target pair is *reachable* when both solve within the joint limits (the bridges' own, less
:data:`REACH_SLACK`) and off singularities, as each bridge checks before it moves
(:mod:`flexsheet.arm.tracking`; a branch jump the bridges judge from their measured joints, see
:class:`ArmReach`).

:meth:`ArmReach.nearest` answers "where no pose presents the object": from a reachable sheet pose toward a
wanted one, the farthest reachable rotation on the way (bisection on the rotation's angle), with the sheet
still through the contact point.

Units: m, rad; display frame.
"""

from __future__ import annotations

import math

import numpy as np

from flexsheet.arm.bridge_config import BridgeConfig
from flexsheet.arm.kinematics import Q_LOWER, Q_UPPER, ArmKinematics, IKResult, home_joints
from flexsheet.model.sheet import clamp_poses

__all__ = ["ArmReach", "SIDES", "REACH_SLACK", "rotation_power"]

#: the two arms, in the order of a clamp pair (left clamp at +axis_u)
SIDES = ("left", "right")
#: rad kept from each joint limit beyond the bridges' own ``limit_margin``: a target the planner finds
#: reachable near the edge must still solve from the bridge's seed (its last goal) with its slightly
#: different iterate
REACH_SLACK = 0.03
#: bisection steps of :meth:`ArmReach.nearest` (the last one within 2⁻⁶ of the way: ≤ 0.1° of a 6° step)
NEAREST_STEPS = 6


def rotation_power(R0: np.ndarray, R1: np.ndarray, t: float) -> np.ndarray:
    """The rotation a fraction ``t`` ∈ [0, 1] of the way from ``R0`` (3, 3) to ``R1`` (3, 3) (geodesic)."""
    Rr = R0.T @ R1
    c = max(-1.0, min(1.0, 0.5 * (np.trace(Rr) - 1.0)))
    th = math.acos(c)
    if th < 1e-12:
        return R0.copy()
    w = np.array([Rr[2, 1] - Rr[1, 2], Rr[0, 2] - Rr[2, 0], Rr[1, 0] - Rr[0, 1]])
    nw = np.linalg.norm(w)
    if nw < 1e-12:                      # a half turn: the axis from the symmetric part
        k = int(np.argmax(np.diag(Rr)))
        w = Rr[:, k] + np.eye(3)[:, k]
        nw = np.linalg.norm(w)
    a = w / nw
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    ang = t * th
    return R0 @ (np.eye(3) + math.sin(ang) * K + (1.0 - math.cos(ang)) * (K @ K))


class ArmReach:
    """Two arms' IK for clamp target pairs (module doc). ``bases``: {"left", "right"}: (x, y, z, yaw) or
    (4, 4) T_display_base of each arm (the registered ones); ``limit_margin`` rad kept from each joint limit
    (the bridges' own, :class:`~flexsheet.arm.bridge_config.BridgeConfig`, plus :data:`REACH_SLACK`);
    ``max_jump`` rad, the largest joint change from the last solution a target may ask (default: none. The
    planner's seeds are its own last solutions, not the arms' joints: from the first target on, a bound
    there would refuse the re-pose from wherever the arms start, and keep refusing, since a refused target
    never moves the seed; the bridges judge their own jump from their measured joints). Raises
    ``ValueError`` on a bad side or base."""

    def __init__(self, bases: dict, limit_margin: float = BridgeConfig.limit_margin + REACH_SLACK,
                 max_jump: float = math.inf) -> None:
        if set(bases) != set(SIDES):
            raise ValueError(f"bases must name 'left' and 'right', got {sorted(bases)}")
        self.kin = {s: ArmKinematics(s, bases[s], Q_LOWER + limit_margin, Q_UPPER - limit_margin)
                    for s in SIDES}
        self.seed = {s: home_joints(s) for s in SIDES}
        self.max_jump = float(max_jump)
        self._last: tuple[bytes, dict[str, IKResult]] | None = None
        #: IK solves run (both arms counted), for the planner's cost
        self.solves = 0

    def solve(self, T_left: np.ndarray, T_right: np.ndarray, commit: bool = True) -> dict[str, IKResult]:
        """Each arm's :class:`~flexsheet.arm.kinematics.IKResult` for clamp targets (4, 4), seeded from its
        last solution; the same pair again returns the kept results without solving. With ``commit`` an arm
        whose target solved takes that solution as its next seed."""
        Tl, Tr = np.asarray(T_left, float), np.asarray(T_right, float)
        key = Tl.tobytes() + Tr.tobytes()
        if self._last is not None and self._last[0] == key:
            res = self._last[1]
        else:
            res = {s: self.kin[s].ik(T, self.seed[s], max_jump=self.max_jump) for s, T in zip(SIDES, (Tl, Tr),
                                                                                               strict=True)}
            self.solves += 2
            self._last = (key, res)
        if commit:
            for s in SIDES:
                if res[s].ok:
                    self.seed[s] = res[s].q
        return res

    def solution(self) -> dict:
        """{side: (6,) rad, or None where it did not solve}: the joints of the last pair solved (none yet:
        every side None)."""
        res = self._last[1] if self._last is not None else {}
        return {s: (res[s].q if s in res and res[s].ok else None) for s in SIDES}

    def reachable(self, T_left: np.ndarray, T_right: np.ndarray) -> tuple[bool, str]:
        """(both targets solve, the first failing arm's "side:status" or "ok"); an arm that solves takes its
        solution as its next seed."""
        res = self.solve(T_left, T_right)
        for s in SIDES:
            if not res[s].ok:
                return False, f"{s}:{res[s].status}"
        return True, "ok"

    def screen(self, origin, R, stretch: float, size: float, R_last=None,
               offset: tuple[float, float] = (0.0, 0.0)) -> tuple[bool, tuple, tuple, str]:
        """The arms' IK screen of a sheet pose: ``origin`` (3,) m, ``R`` (3, 3; columns normal, axis_u,
        axis_v; rows as nested tuples or an array), ``stretch``, side ``size`` m. Returns (ok, origin, R as
        nested tuples, what to say): the pose itself ("" ), else the pose turned from ``R_last`` (the last
        reachable rotation) toward it only as far as both arms reach, through the sheet's point at
        ``offset`` (s_u, s_v) m (``"reach:nearest"``), else not ok with ``"ik:<side>:<status>"``."""
        Ra = np.asarray(R, float)
        o = np.asarray(origin, float)
        ok, why = self.reachable(*clamp_poses(o, Ra[:, 0], Ra[:, 1], stretch, size))
        if ok:
            return True, tuple(origin), R, ""
        if R_last is None:
            return False, tuple(origin), R, f"ik:{why}"
        point = o + offset[0] * Ra[:, 1] + offset[1] * Ra[:, 2]
        near = self.nearest(point, offset, np.asarray(R_last, float), Ra, stretch, size)
        if near is None:
            return False, tuple(origin), R, f"ik:{why}"
        _, on, Rn = near
        return (True, tuple(float(x) for x in on), tuple(tuple(float(x) for x in row) for row in Rn),
                "reach:nearest")

    def nearest(self, contact, offset: tuple[float, float], R_from: np.ndarray, R_to: np.ndarray,
                stretch: float, size: float) -> tuple[float, np.ndarray, np.ndarray] | None:
        """The farthest fraction ``t`` ∈ [0, 1] of the rotation from ``R_from`` toward ``R_to`` (3, 3; columns
        normal, axis_u, axis_v) whose sheet, through ``contact`` (3,) m at ``offset`` (s_u, s_v) m on the
        sheet with ``stretch``, is reachable by both arms: (t, origin (3,) m, R (3, 3)). ``None`` when not
        even ``R_from`` is. The arms' seeds end at the returned pose's solutions."""
        q = np.asarray(contact, float)
        seeds = dict(self.seed)

        def pose(t: float) -> tuple[np.ndarray, np.ndarray, bool]:
            R = rotation_power(R_from, R_to, t)
            o = q - offset[0] * R[:, 1] - offset[1] * R[:, 2]
            Tl, Tr = clamp_poses(o, R[:, 0], R[:, 1], stretch, size)
            self.seed = dict(seeds)
            ok = all(r.ok for r in self.solve(Tl, Tr, commit=False).values())
            return o, R, ok

        o0, R0, ok0 = pose(0.0)
        if not ok0:
            self.seed = seeds
            return None
        lo, hi, best = 0.0, 1.0, (0.0, o0, R0)
        for _ in range(NEAREST_STEPS):
            mid = 0.5 * (lo + hi)
            o, R, ok = pose(mid)
            if ok:
                lo, best = mid, (mid, o, R)
            else:
                hi = mid
        t, o, R = best
        Tl, Tr = clamp_poses(o, R[:, 0], R[:, 1], stretch, size)
        self.seed = seeds
        self.solve(Tl, Tr)                       # kept for the pull guard, and the seeds move there
        return t, o, R
