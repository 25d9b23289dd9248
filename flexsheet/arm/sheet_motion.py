"""The two arms' one motion: a time-parametrised motion of the sheet in cooperative task space (pure; ruckig).

The sheet's state ``x`` (7,): its centre ``o`` (3,) m, its orientation as a rotation vector ``r`` (3,) rad
about the segment's reference rotation (``R = R_ref · exp([r]×)``, so ``r`` is in the sheet's own frame at the
segment's start), and the clamp strain ``ε``. The absolute part of the pair's motion is (o, R), the tangent
plane's pose; the relative part is the clamps' span ``size·(1 + ε)`` along ``axis_u`` with one common
orientation (:func:`flexsheet.model.sheet.clamp_poses`). Both clamps are derived from one state at one
instant, so the span is the planned one all along the path, not only at its ends (cooperative task space:
Chiacchio, Chiaverini & Siciliano 1996; Caccavale et al. 2000).

A :class:`SheetSegment` is the start time ``t0`` (s, the graph's clock), the reference rotation, the start
state with its velocity and acceleration, the goal with its velocity and the per-DOF limits. The planner's
goal moves with the finger: the segment reaches it at its velocity, and runs on at that velocity for at most
:data:`EXTRAPOLATE_S` after its end (the next plan is due before), then stops there. Ruckig (Berscheid &
Kröger, "Jerk-limited real-time trajectory generation with arbitrary target states", RSS 2021) gives the
time-optimal jerk-limited trajectory with phase synchronisation: every DOF starts and stops together, on a
straight line in this space when the start is at rest or moving along that line (else time-synchronised).
Ruckig is deterministic: the planner and both bridges compute one trajectory from one segment, and evaluate it
at the same instant.

Limits (:class:`MotionLimits`) bound the norm of the centre's speed, the sheet's angular speed and the strain
rate: each DOF of a group gets the group's bound times its share of the group's displacement (at least
:data:`MIN_SHARE`), so a phase-synchronised move keeps the norm within the bound. The arms' joints bound it
too: :class:`~flexsheet.arm.joint_rates.JointRates` estimates the joint speeds and accelerations a segment
asks of both arms, and the shaper slows the segment (both arms alike) until they are within the bridges'
limits, so the bridges' per-joint limiters never have to brake one arm alone.
"""

from __future__ import annotations

import atexit
import math
import weakref
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from ruckig import InputParameter, Result, Ruckig, RuckigError, Synchronization, Trajectory
from scipy.spatial.transform import Rotation

from flexsheet.model import geometry
from flexsheet.model.motion_limits import MotionLimits
from flexsheet.model.vec import vnorm

if TYPE_CHECKING:
    from flexsheet.arm.joint_rates import JointRates

__all__ = ["per_dof", "SheetSegment", "SheetShaper", "MotionError", "MIN_SHARE", "DOF",
           "EXTRAPOLATE_S", "VELOCITY_PLANS", "plan_velocity", "lsq_slope"]

#: the state's size: centre (3), rotation vector (3), strain (1)
DOF = 7
#: the least share of a group's bound a DOF gets (ruckig needs positive limits; a DOF that does not move keeps
#: room to brake a start velocity)
MIN_SHARE = 0.05
_GROUPS = (slice(0, 3), slice(3, 6), slice(6, 7))
#: s: a segment runs on at its goal's velocity for at most this long past its end, then stops there
EXTRAPOLATE_S = 0.05
#: plans a goal's velocity is fitted over (16 at the camera's 48 Hz: the last 313 ms)
VELOCITY_PLANS = 16
#: segments holding a ruckig trajectory: their trajectories are freed at exit, before the interpreter's
#: teardown (nanobind reports a binding object still alive then as a leak, on every node's exit)
_LIVE: weakref.WeakSet = weakref.WeakSet()


@atexit.register
def _free_trajectories() -> None:
    for seg in list(_LIVE):
        seg.__dict__.pop("_traj", None)


class MotionError(ValueError):
    """A segment ruckig could not compute (bad limits or state); names what was wrong."""


def per_dof(limits: MotionLimits, delta: np.ndarray, velocity=None) -> np.ndarray:
    """(3, 7) per-DOF limits (velocity, acceleration, jerk) of ``limits`` for a move by ``delta`` (7,) ending
    at ``velocity`` (7,) (None: at rest): each group's bound times the DOF's share of the group's displacement
    or of its end velocity, whichever is larger, at least :data:`MIN_SHARE`; a DOF's velocity bound is never
    below its end velocity."""
    g = limits.groups()
    vel = np.zeros(DOF) if velocity is None else np.abs(np.asarray(velocity, float))
    out = np.empty((3, DOF))
    for j, sl in enumerate(_GROUPS):
        share = np.full(sl.stop - sl.start, MIN_SHARE)
        for x in (np.abs(np.asarray(delta, float)[sl]), vel[sl]):
            n = vnorm(x)
            if n > 1e-12:
                share = np.maximum(share, x / n)
        out[:, sl] = g[:, j:j + 1] * share[None, :]
    out[0] = np.maximum(out[0], vel * 1.001)
    return out


def _hat(r) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def _log(R) -> np.ndarray:
    """The rotation vectors (..., 3) of rotations (..., 3, 3) (scipy's, robust near π; one call for a
    stack)."""
    return Rotation.from_matrix(np.asarray(R, float)).as_rotvec()


def _calculate(inp: InputParameter, traj: Trajectory):
    """ruckig's ``calculate``: its :class:`Result`, else a line why: a code the binding has no name for (e.g.
    −101, a duration ruckig cannot represent, on which its Python enum raises ``ValueError``) or its own
    ``RuckigError`` (limits it cannot time)."""
    try:
        return Ruckig(DOF).calculate(inp, traj)
    except ValueError as exc:
        return str(exc).split(" ", 1)[0]
    except RuckigError as exc:
        return str(exc).splitlines()[0][:120]


#: the most a segment is slowed for the joints, each pass (speed, acceleration bounds divided by at most this)
SLOW_MAX = 10.0


@dataclass(frozen=True, eq=False)
class SheetSegment:
    """One segment of the sheet's motion (module doc).

    ``t0`` s (graph clock); ``frame`` (3, 3): the reference rotation R_ref (columns normal, axis_u, axis_v at
    ``r`` = 0, display frame); ``start`` (3, 7): the start state, its velocity and its acceleration; ``goal``
    (2, 7): the goal and its velocity; ``limits`` (3, 7): per-DOF velocity, acceleration and jerk; ``size`` m:
    the sheet's unstretched side; ``min_duration`` s: the segment takes at least this long (the plan's period:
    a goal moving at its velocity is reached on its track, not rushed to and passed). Raises
    :class:`MotionError` if ruckig cannot compute it (non-finite values, limits not positive)."""

    t0: float
    frame: np.ndarray
    start: np.ndarray
    goal: np.ndarray
    limits: np.ndarray
    size: float = geometry.SHEET_SIZE
    min_duration: float = 0.0
    _traj: Trajectory = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name, shape in (("frame", (3, 3)), ("start", (3, DOF)), ("goal", (2, DOF)), ("limits", (3, DOF))):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != shape or not np.isfinite(a).all():
                raise MotionError(f"SheetSegment.{name} must be a finite {shape} array, got shape {a.shape}")
            object.__setattr__(self, name, a)
        if np.abs(self.frame.T @ self.frame - np.eye(3)).max() > 1e-6 or np.linalg.det(self.frame) <= 0.0:
            raise MotionError(f"SheetSegment.frame must be a rotation, got {self.frame.tolist()}")
        if not (math.isfinite(self.t0) and self.size > 0.0 and 0.0 <= self.min_duration < 10.0):
            raise MotionError(f"SheetSegment t0 must be finite, size > 0 and min_duration in [0, 10) s, got "
                              f"t0={self.t0!r}, size={self.size!r}, min_duration={self.min_duration!r}")
        if (self.limits <= 0.0).any():
            raise MotionError(f"SheetSegment.limits must be > 0, got {self.limits.tolist()}")
        inp = InputParameter(DOF)
        inp.current_position, inp.current_velocity, inp.current_acceleration = (r.tolist()
                                                                                for r in self.start)
        inp.target_position, inp.target_velocity = (r.tolist() for r in self.goal)
        inp.target_acceleration = [0.0] * DOF
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = (r.tolist() for r in self.limits)
        inp.synchronization = Synchronization.Phase
        if self.min_duration > 0.0:
            inp.minimum_duration = float(self.min_duration)
        traj = Trajectory(DOF)
        res = _calculate(inp, traj)
        if res != Result.Working:
            inp.synchronization = Synchronization.Time      # a start off the line: time-synchronised
            res = _calculate(inp, traj)
        if res != Result.Working:
            raise MotionError(f"ruckig could not compute the sheet segment: {getattr(res, 'name', res)}")
        object.__setattr__(self, "_traj", traj)
        _LIVE.add(self)

    @property
    def duration(self) -> float:
        """s from ``t0`` to the goal."""
        return float(self._traj.duration)

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, ẋ, ẍ), each (7,), at time ``t`` s: the start before ``t0``; after the end, the goal run on at
        its velocity for at most :data:`EXTRAPOLATE_S`, then at rest there."""
        return tuple(np.asarray(v, float) for v in self._state(t))

    def _state(self, t: float) -> tuple[list, list, list]:
        """:meth:`state` as three lists of 7 floats (the bridges' per-cycle path: no array per value)."""
        tau = t - self.t0
        end = self._traj.duration
        if tau <= end:
            return self._traj.at_time(max(tau, 0.0))
        over = tau - end
        g, gv = self.goal
        if over < EXTRAPOLATE_S:
            return (g + gv * over).tolist(), gv.tolist(), [0.0] * DOF
        return (g + gv * EXTRAPOLATE_S).tolist(), [0.0] * DOF, [0.0] * DOF

    def rotation(self, r) -> np.ndarray:
        """The sheet's rotation (3, 3) for the rotation vector ``r`` (3,) of this segment."""
        return self.frame @ _rodrigues(*np.asarray(r, float))[0]

    def sheet(self, t: float) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, np.ndarray, float]:
        """The sheet at time ``t``: (centre (3,) m, rotation (3, 3), strain, centre velocity (3,) m/s,
        angular velocity (3,) rad/s in the display frame, strain rate 1/s)."""
        x, xd, _ = self.state(t)
        R = self.rotation(x[3:6])
        # ω in the display frame: R · J_r(r) · ṙ (the right Jacobian of SO(3); body rate ≈ ṙ for small r)
        w_body = _right_jacobian(x[3:6]) @ xd[3:6]
        return x[:3], R, float(x[6]), xd[:3], R @ w_body, float(xd[6])

    def clamp(self, arm: str, t: float, accel: bool = False) -> tuple[np.ndarray, ...]:
        """The ``arm``'s ("left" or "right") clamp at time ``t``: pose T_display_clamp (4, 4) m, and its twist
        (6,) (v m/s, ω rad/s) in the clamp's own frame, the frame of :meth:`ArmKinematics.jacobian`; with
        ``accel`` also the twist's rate (6,) (m/s², rad/s²; the rotating frame's terms, second order, left
        out). Raises ``ValueError`` for another arm name."""
        if arm not in ("left", "right"):
            raise ValueError(f"arm must be 'left' or 'right', got {arm!r}")
        return self.clamps(t, accel, (arm,))[0]

    def clamps(self, t: float, accel: bool, arms) -> list[tuple[np.ndarray, ...]]:
        """:meth:`clamp` for each of ``arms`` ("left"/"right") from one evaluation of the trajectory at ``t``
        s: a list of (T (4, 4), twist (6,)[, twist rate (6,) with ``accel``]) in the order of ``arms``. Worked
        in the sheet's frame (clamp axis e_y): with ω_b = J_r(r)·ṙ the clamp moves at Rᵀẋ_c ± (ȧ·e_y + a·ω_b ×
        e_y) (a: half the span); the twist's angular part is ω_b (the clamps share the sheet's
        orientation)."""
        x, xd, xdd = self._state(t)
        E, C, D = _rodrigues(x[3], x[4], x[5])
        R = self.frame @ E
        wb = _right_jacobian_times(x[3], x[4], x[5], xd[3], xd[4], xd[5], C, D)
        a = 0.5 * self.size * (1.0 + x[6])
        ad = 0.5 * self.size * xd[6]
        vb = (R.T @ xd[:3]).tolist()
        wx, wy, wz = wb
        centre, u = np.asarray(x[:3], float), R[:, 1]
        if accel:
            ab = (R.T @ xdd[:3]).tolist()
            al = _right_jacobian_times(x[3], x[4], x[5], xdd[3], xdd[4], xdd[5], C, D)
            add = 0.5 * self.size * xdd[6]
            # ω_b × e_y = (−ω_z, 0, ω_x); ω_b × (ω_b × e_y) = (ω_x ω_y, −ω_x² − ω_z², ω_z ω_y)
            rel = (-2.0 * ad * wz + a * (-al[2] + wx * wy),
                   add - a * (wx * wx + wz * wz),
                   2.0 * ad * wx + a * (al[0] + wz * wy))
        out = []
        for arm in arms:
            s = 1.0 if arm == "left" else -1.0
            T = np.eye(4)
            T[:3, :3] = R
            T[:3, 3] = centre + (s * a) * u
            twist = np.array([vb[0] - s * a * wz, vb[1] + s * ad, vb[2] + s * a * wx, wx, wy, wz])
            if not accel:
                out.append((T, twist))
                continue
            out.append((T, twist, np.array([ab[0] + s * rel[0], ab[1] + s * rel[1], ab[2] + s * rel[2],
                                            al[0], al[1], al[2]])))
        return out

    def clamp_points(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The left and the right clamp's positions (3,) m, display frame, at ``t`` s (:meth:`clamps`'
        points)."""
        x = self._state(t)[0]
        E = _rodrigues(x[3], x[4], x[5])[0]
        h = (0.5 * self.size * (1.0 + x[6])) * (self.frame @ E[:, 1])
        c = np.asarray(x[:3], float)
        return c + h, c - h

    def fields(self) -> dict:
        """This segment as :class:`messages.ArmTarget`'s ``motion_*`` fields (the inverse of
        :meth:`from_fields`)."""
        return {"motion_t0": float(self.t0), "motion_frame": self.frame.copy(),
                "motion": np.vstack([self.start, self.goal, self.limits]), "motion_size": float(self.size),
                "motion_min_duration": float(self.min_duration)}

    @classmethod
    def from_fields(cls, msg) -> SheetSegment | None:
        """The segment an :class:`messages.ArmTarget` carries, or None when it carries none (``motion_t0``
        None). Raises :class:`MotionError` naming the bad field."""
        if msg.motion_t0 is None:
            return None
        m = np.asarray(msg.motion, float)
        return cls(float(msg.motion_t0), msg.motion_frame, m[0:3], m[3:5], m[5:8], float(msg.motion_size),
                   float(msg.motion_min_duration))

    def goal_pose(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(centre (3,) m, rotation (3, 3), strain) at the goal."""
        g = self.goal[0]
        return g[:3], self.rotation(g[3:6]), float(g[6])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _rodrigues(rx: float, ry: float, rz: float) -> tuple[np.ndarray, float, float]:
    """exp([r]×) (3, 3) for the rotation vector (rx, ry, rz) rad, and the right Jacobian's coefficients
    C = (1 − cos θ)/θ², D = (θ − sin θ)/θ³ (series below 1e-4 rad). exp([r]×) = I + A·K + B·K² with
    A = sin θ/θ, B = C and K² = r rᵀ − θ² I."""
    th2 = rx * rx + ry * ry + rz * rz
    if th2 < 1e-8:
        A, B, D = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0, 1.0 / 6.0 - th2 / 120.0
    else:
        th = math.sqrt(th2)
        sn, cs = math.sin(th), math.cos(th)
        A, B, D = sn / th, (1.0 - cs) / th2, (th - sn) / (th2 * th)
    E = np.array([[1.0 + B * (rx * rx - th2), -A * rz + B * rx * ry, A * ry + B * rx * rz],
                  [A * rz + B * rx * ry, 1.0 + B * (ry * ry - th2), -A * rx + B * ry * rz],
                  [-A * ry + B * rx * rz, A * rx + B * ry * rz, 1.0 + B * (rz * rz - th2)]])
    return E, B, D


def _right_jacobian_times(rx, ry, rz, dx, dy, dz, C: float, D: float) -> tuple[float, float, float]:
    """J_r(r)·ṙ (3,) as floats: ṙ − C·(r × ṙ) + D·r × (r × ṙ) (C, D from :func:`_rodrigues`)."""
    cx, cy, cz = ry * dz - rz * dy, rz * dx - rx * dz, rx * dy - ry * dx
    ccx, ccy, ccz = ry * cz - rz * cy, rz * cx - rx * cz, rx * cy - ry * cx
    return dx - C * cx + D * ccx, dy - C * cy + D * ccy, dz - C * cz + D * ccz


def _right_jacobian(r: np.ndarray) -> np.ndarray:
    """SO(3)'s right Jacobian J_r(r) (3, 3): body angular velocity = J_r(r)·ṙ for R = R_ref·exp([r]×)."""
    _, C, D = _rodrigues(*np.asarray(r, float))
    K = _hat(r)
    return np.eye(3) - C * K + D * (K @ K)


def plan_velocity(plans) -> tuple[np.ndarray, np.ndarray, float]:
    """The velocity of plans: least-squares slopes over their times. ``plans``: at least two (time s, centre
    (3,) m, rotation (3, 3), strain), oldest first. Returns (centre velocity (3,) m/s, angular velocity (3,)
    rad/s display frame, strain rate 1/s). Raises ``ValueError`` for fewer than two plans or times that do not
    spread."""
    if len(plans) < 2:
        raise ValueError(f"plan_velocity needs at least two plans, got {len(plans)}")
    Rn = plans[-1][2]      # rotation vectors (n, 3) about the newest, one call
    x = np.column_stack([np.array([p[1] for p in plans]), _log(Rn.T @ np.array([p[2] for p in plans])),
                         [p[3] for p in plans]])
    slope = lsq_slope([p[0] for p in plans], x)
    return slope[:3], Rn @ slope[3:6], float(slope[6])


def lsq_slope(t, x) -> np.ndarray:
    """Slope (k,) of the least-squares line through samples ``x`` (n, k) at times ``t`` (n,) s. Raises
    ``ValueError`` for times that do not spread."""
    t = np.asarray(t, float)
    t = t - t.mean()
    tt = float(t @ t)
    if not tt > 0.0:
        raise ValueError("lsq_slope: the times do not spread")
    x = np.asarray(x, float)
    return (t @ (x - x.mean(axis=0))) / tt


class SheetShaper:
    """The planner's side: one segment per plan, each starting where the last one is at that instant (its
    state, velocity and acceleration), so the motion stays continuous in position, velocity and acceleration.

    ``limits``: :class:`MotionLimits`; ``size`` m: the sheet's side; ``rates``: a
    :class:`~flexsheet.arm.joint_rates.JointRates` whose ``at`` the caller keeps current, or None (Cartesian
    limits only). :meth:`update` returns the new segment; ``slowed`` counts the segments slowed for the
    joints."""

    def __init__(self, limits: MotionLimits | None = None, size: float = geometry.SHEET_SIZE,
                 rates: JointRates | None = None) -> None:
        self.limits = limits or MotionLimits()
        self.size = float(size)
        self.rates = rates
        self.segment: SheetSegment | None = None
        self.failures = 0
        self.slowed = 0

    def reset(self) -> None:
        """Forget the motion: the next :meth:`update` starts at its goal, at rest (after a hold or a jump the
        bridges' joint limiters bring the arms there)."""
        self.segment = None

    def _start(self, t: float) -> np.ndarray:
        """(3, 7): the current motion's state, velocity and acceleration at ``t``, in a segment whose rotation
        vector is 0 at the current orientation: the body rate J_r(r)·ṙ and, to first order, its change
        J_r(r)·r̈ (the J̇_r·ṙ term is second order in r, which stays small within a segment)."""
        x, xd, xdd = self.segment.state(t)
        out = np.zeros((3, DOF))
        out[:, :3] = np.stack([x[:3], xd[:3], xdd[:3]])
        out[:, 6] = (x[6], xd[6], xdd[6])
        J = _right_jacobian(x[3:6])
        out[1, 3:6] = J @ xd[3:6]
        out[2, 3:6] = J @ xdd[3:6]
        return out

    def update(self, t: float, origin, rotation, stretch: float, limits: MotionLimits | None = None,
               velocity=None, lead: float = 0.0, current=None) -> SheetSegment:
        """The segment from the current motion at ``t`` s to the sheet at ``origin`` (3,) m, ``rotation`` (3,
        3) and strain ``stretch``, under ``limits`` (default: the shaper's). ``velocity``: the goal's (centre
        m/s (3,), angular rad/s (3,) display frame, strain rate 1/s), or None (at rest); the goal is taken
        ``lead`` s ahead at that velocity (the plan's period: the motion is on the plan's track when the next
        plan comes). ``current``: (origin (3,) m, rotation (3, 3), strain) of the sheet where the arms hold it
        (their measured clamps), where a motion starts when there is none yet (the first plan, after
        :meth:`reset` or a failure);
        None: it starts at the goal (the bridges' limiters then take the arms there joint by joint).
        Raises :class:`MotionError` when ruckig fails (the shaper then restarts at the next goal, and counts
        it in ``failures``)."""
        lim = limits or self.limits
        o = np.asarray(origin, float)
        R = np.asarray(rotation, float)
        v, w, ed = (np.zeros(3), np.zeros(3), 0.0) if velocity is None else (
            np.asarray(velocity[0], float), np.asarray(velocity[1], float), float(velocity[2]))
        if lead > 0.0:
            o, R, stretch = o + v * lead, _rodrigues(*(w * lead))[0] @ R, stretch + ed * lead
        if self.segment is None:
            frame = R if current is None else np.asarray(current[1], float)
            start = np.zeros((3, DOF))
            start[0, :3] = o if current is None else np.asarray(current[0], float)
            start[0, 6] = stretch if current is None else float(current[2])
        else:
            x = self.segment.state(t)[0]
            frame = self.segment.rotation(x[3:6])
            start = self._start(t)
        rg = _log(frame.T @ R)
        goal = np.zeros((2, DOF))
        goal[0] = np.concatenate([o, rg, [float(stretch)]])
        goal[1] = np.concatenate([v, np.linalg.solve(_right_jacobian(rg), R.T @ w), [ed]])
        try:
            bounds = per_dof(lim, goal[0] - start[0], goal[1])
            seg = SheetSegment(float(t), frame, start, goal, bounds, self.size, lead)
            if self.rates is not None:
                for _ in range(2):  # slow both arms alike until their joints can follow (10 % spare)
                    rv, ra = self.rates.ratios(seg)
                    if rv <= 1.0 and ra <= 1.0:
                        break
                    # at most SLOW_MAX-fold: a motion through a joint singularity cannot be slowed enough
                    kv, ka = (min(max(r, 1.0) * 1.1, SLOW_MAX) for r in (rv, ra))
                    # the jerk stays: a motion already accelerating past the lowered
                    # bound must be braked within it, or it runs on while its
                    # acceleration ramps down (the strain overshot its goal 4-fold)
                    bounds = bounds / np.array([[kv], [ka], [1.0]])
                    bounds[0] = np.maximum(bounds[0], np.abs(goal[1]) * 1.001)
                    seg = SheetSegment(float(t), frame, start, goal, bounds, self.size, lead)
                    self.slowed += 1
        except MotionError:
            self.failures += 1
            self.segment = None
            raise
        self.segment = seg
        return seg
