"""The last steps of a plan's pose: rate limits, the viewer's head, both arms' reach (pure).

:func:`limit_and_reach` takes the sheet pose the surface planner wants
(:class:`~flexsheet.planning.surface_planner.SurfacePlanner`) and returns the one it may send:

1. rate-limited (:class:`~flexsheet.planning.limits.RateLimiter`; the head guard's reduced limits near it);
2. the sheet and clamps kept out of the head's keep-out (:meth:`HeadGuard.step
   <flexsheet.planning.head_guard.HeadGuard.step>`: a back-off along −x, ``hold:keep_out``);
3. the clamps within the reach shells, and both arms' IK (:meth:`ArmReach.screen
   <flexsheet.planning.arm_reach.ArmReach.screen>`: the nearest reachable turn, ``reach:nearest``); an
   unreachable pose holds the last plan's (``unreachable``);
4. both arms, at that pose's IK, kept out of the keep-out by the bridges' own test at the guard's larger
   margin (:meth:`HeadGuard.arms <flexsheet.planning.head_guard.HeadGuard.arms>`): inside, the pose backs off
   along −x as in 2 (``hold:keep_out;keep_out:<side> arm <part>``): no bridge refuses it for the keep-out.

Units m, rad, s; display frame.
"""

from __future__ import annotations

import numpy as np

from flexsheet.model.sheet import clamp_points, clamp_poses
from flexsheet.model.vec import cols, rot_from_cols
from flexsheet.planning.keepout import retreat_point
from flexsheet.planning.plan import Hold

__all__ = ["limit_and_reach"]


def limit_and_reach(p, origin, R, stretch: float, dt: float | None, status: list[str],
                    offset: tuple[float, float] = (0.0, 0.0)):
    """Rate-limit planner ``p``'s target pose (``origin`` (3,) m, ``R`` (3, 3) columns n, u, v), place the
    clamps and screen their reach and the arms' keep-out. Returns (origin, (n, u, v), stretch, left, right,
    reach margin); ``offset`` (s_u, s_v) m: the contact on the sheet (the arms' IK screen turns a pose out of
    reach about it). An unreachable step is undone and the last pose held. Reasons are appended to
    ``status``."""
    prev = None
    if dt is None or not p.limiter.initialised:
        p.limiter.reset(origin, R, stretch)
        o, Rc, st, limited = origin, R, stretch, False
    else:
        prev = p.limiter.snapshot()
        if p.guard is not None:
            p.limiter.limits = p.guard.limits(p.cfg.limits, prev.origin, prev.R, prev.stretch)
        o, Rc, st, limited = p.limiter.step(origin, R, stretch, dt)
    if limited:
        status.append("rate_limited")
    if p.guard is not None and p.guard.eye is not None and prev is not None:
        g = p.guard.step(prev.origin, prev.R, o, Rc, st, dt)
        if g.retreat:  # the step would enter the head's keep-out (or it was lost near): back off
            status.append(Hold.HEAD_LOST if p.guard.lost else Hold.KEEP_OUT)
            o, Rc = tuple(float(x) for x in g.origin), tuple(tuple(float(x) for x in r) for r in g.R)
            p.limiter.reset(o, Rc, st)
    size = p.cfg.material.size
    axes = cols(Rc)
    left, right = clamp_points(o, axes[1], st, size)
    ok, margin = p.cfg.reach.reachable(left, right)
    if ok and p.arm_reach is not None:
        ok, o, Rc, why = p.arm_reach.screen(o, Rc, st, size, prev.R if prev is not None else None, offset)
        if why:
            status.append(why)
        if why == "reach:nearest":
            p.limiter.reset(o, Rc, st)
            axes = cols(Rc)
            left, right = clamp_points(o, axes[1], st, size)
    if not ok:
        status.append("unreachable")
        if p.last is not None and prev is not None:
            # hold the last reachable pose (at rest), keep the rolling state of the finger
            p.limiter.restore(prev, at_rest=True)
            L = p.last
            return keep_arms_out(p, (L.origin, (L.normal, L.axis_u, L.axis_v), L.stretch, L.left, L.right,
                                     margin), dt, status)
    return keep_arms_out(p, (o, axes, st, left, right, margin), dt, status)


def keep_arms_out(p, pose: tuple, dt: float | None, status: list[str]) -> tuple:
    """``pose`` (origin, (n, u, v), stretch, left, right, margin), or, where planner ``p``'s arms at its IK
    would enter the head guard's keep-out, that pose backed off along −x by one step at the guard's reduced
    speed (:func:`~flexsheet.planning.keepout.retreat_point`), if both arms reach it. Without a tracked head
    or the arms' IK: ``pose``."""
    g, ar = p.guard, p.arm_reach
    if g is None or g.eye is None or ar is None:
        return pose
    o, axes, st, left, right, margin = pose
    size = p.cfg.material.size
    n, u = np.asarray(axes[0], float), np.asarray(axes[1], float)
    ar.solve(*clamp_poses(np.asarray(o, float), n, u, st, size), commit=False)
    v = g.arms(ar.kin, ar.solution())
    g.arms_near = v.clearance < g.keepout.near_distance
    if not v.inside:
        return pose
    status.extend((Hold.KEEP_OUT, f"keep_out:{v.what}"))
    step = 0.45 * g.keepout.reduced_speed * max(dt if dt is not None else p.cfg.max_dt, 1e-3)
    o2 = retreat_point(g.keepout, g.eye, np.asarray(o, float), n, step)
    R = rot_from_cols(*axes)
    ok, _, _, _ = ar.screen(o2, R, st, size)
    if not ok:
        return pose
    o2 = tuple(float(x) for x in o2)
    p.limiter.reset(o2, R, st)
    left, right = clamp_points(o2, axes[1], st, size)
    return o2, axes, st, left, right, margin
