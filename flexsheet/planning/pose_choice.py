"""The sheet's in-plane rotation ψ about the contact normal, chosen between touches (pure).

The paper's rule sets the clamp axis ``axis_u`` to ``u_ref`` (+y) projected onto the tangent plane: ``u₀``.
:class:`PoseChoice` turns it by ψ about the normal ``n``: ``axis_u = cos ψ·u₀ + sin ψ·(n × u₀)``. While the
finger touches, the sheet rolls without slip and ``axis_u`` is parallel-transported: ψ is not chosen there.

Between touches, a sweep every ``psi_period`` s (:data:`PER_PLAN` candidates a plan) scores each candidate
ψ_k = k·``psi_step``, |ψ_k| ≤ ``psi_range``, by both arms' IK (each arm's
:class:`~flexsheet.arm.kinematics.ArmKinematics` of :class:`~flexsheet.planning.arm_reach.ArmReach`, from
its current solution, which stays) at

* the pose itself: the sheet through the contact ``q`` at its offset (s_u, s_v), at the current strain;
* its look-ahead: the sheet rolled without slip on the object from ``q`` toward ±u₀ and ±v₀ as far as a
  stroke of :data:`LOOK_LENGTH` m turns it, at most ``psi_lookahead`` rad (the normal's turn rate κ from
  one projection :data:`LOOK_STEP` m away per direction; on the osculating circle of radius 1/κ). A flat
  direction adds no pose. Those are the poses a stroke from here asks for.

Score (higher is better) = min joint-limit margin over those poses (each joint's distance to its limit as a
share of its range, 0…0.5) + :data:`W_MANIP`·min(1, w/:data:`W_REF`) (Yoshikawa's w, the least over those
poses) − :data:`W_TRAVEL`·(the pose's largest joint move from the arms' current solution / its speed limit,
s) + :data:`W_CLEAR`·min(1, clearance/``near_distance``) (head keep-out, sheet and arms, when tracked; −1
inside). A candidate whose own pose an arm does not solve within :data:`IK_ITER` iterations scores −∞ and is
never chosen; a look-ahead pose that does not solve ends the scoring: −2 per pose, less the poses that did
solve. Choice: the current ψ while it is within ``psi_hysteresis`` of the best, or while no candidate's
pose solves; else the paper's ψ = 0 when it is; else the best. The rate limiter turns the
sheet to it. Units m, rad, s; display frame.
"""

from __future__ import annotations

import math

import numpy as np

from flexsheet.arm.kinematics import QD_MAX
from flexsheet.model.sheet import clamp_poses
from flexsheet.model.vec import Vec, cross, dot, norm, perp_unit, rodrigues

__all__ = ["PoseChoice", "LOOK_LENGTH", "LOOK_STEP", "W_MANIP", "W_REF", "W_TRAVEL", "W_CLEAR"]

#: m: the stroke whose turn of the sheet the look-ahead poses cover
LOOK_LENGTH = 0.06
#: m: how far from the contact the normal is sampled for its turn rate
LOOK_STEP = 0.005
#: weight of the manipulability term, and the manipulability counted as enough (home pose ≈ 0.012)
W_MANIP, W_REF = 0.05, 0.005
#: weight per second of the joints' travel from where they are
W_TRAVEL = 0.02
#: weight of the head keep-out clearance within ``near_distance``
W_CLEAR = 0.1
#: candidates scored per plan: a sweep spreads over a few plans (the plan's time)
PER_PLAN = 3
#: IK iterations a scored pose may take (from the arms' current solution; more: counted as not solving)
IK_ITER = 12


class PoseChoice:
    """ψ between touches (module doc). ``shape``: the planner's shape (its ``project``); ``cfg``: the
    :class:`~flexsheet.planning.planner_config.PlannerConfig` (``psi_*``, ``u_ref``, ``material.size``,
    ``singular_eps``); ``arm_reach``: the planner's :class:`~flexsheet.planning.arm_reach.ArmReach`;
    ``guard``: its :class:`~flexsheet.planning.head_guard.HeadGuard` or None. ``psi`` rad: the choice;
    ``scores``: {ψ: score} of the last evaluation; ``evaluations`` counts them."""

    def __init__(self, shape, cfg, arm_reach, guard=None) -> None:
        self.shape, self.cfg, self.arm_reach, self.guard = shape, cfg, arm_reach, guard
        k = int(math.floor(cfg.psi_range / cfg.psi_step + 1e-9))
        self.candidates = [i * cfg.psi_step for i in range(-k, k + 1)]
        self.evaluations = 0
        self.reset()

    def reset(self) -> None:
        """Back to the paper's rule (ψ = 0), nothing evaluated."""
        self.psi = 0.0
        self.t_eval: float | None = None
        self.scores: dict[float, float] = {}
        self._pending: list[float] = []
        self._sweep: dict[float, float] = {}

    def axis(self, t: float, q: Vec, n: Vec, offset: tuple[float, float], stretch: float,
             choose: bool) -> Vec | None:
        """``axis_u`` (3,) for contact ``q`` (3,) m, unit normal ``n`` (3,), the contact's ``offset`` (s_u,
        s_v) m on the sheet and clamp ``stretch``, at time ``t`` s: u₀ turned by ψ about ``n``; with
        ``choose`` (between touches) the sweep goes on (module doc). None where
        ``u_ref`` is along ``n`` (no u₀: the caller keeps its axis)."""
        ref = self.cfg.u_ref
        if abs(dot(ref, n)) >= 0.999 * norm(ref):
            return None
        u0 = perp_unit(n, ref)
        if not choose:
            self._pending = []                          # touching: a sweep under way is dropped
        elif not self._pending and (self.t_eval is None or not 0.0 <= t - self.t_eval < self.cfg.psi_period):
            self._pending = sorted(self.candidates, key=lambda p: (p != self.psi, p != 0.0, abs(p)))
            self._sweep = {}
        if self._pending:
            looks = self._looks(q, n, u0)
            for psi in self._pending[:PER_PLAN]:
                self._sweep[psi] = self.score(q, n, turn(n, u0, psi), offset, stretch, looks)
            del self._pending[:PER_PLAN]
            if not self._pending:
                self.t_eval = t
                self.decide(self._sweep)
        return turn(n, u0, self.psi)

    def decide(self, scores: dict[float, float]) -> float:
        """Pick ψ from ``scores`` {ψ: score} with the hysteresis (module doc); returns ψ rad."""
        self.scores = dict(scores)
        self.evaluations += 1
        best = max(scores, key=lambda p: (scores[p], -abs(p)))
        top, h = scores[best], self.cfg.psi_hysteresis
        if top == -math.inf or scores.get(self.psi, -math.inf) >= top - h:
            return self.psi
        self.psi = 0.0 if scores.get(0.0, -math.inf) >= top - h else best
        return self.psi

    def _looks(self, q: Vec, n: Vec, u0: Vec) -> list[tuple[np.ndarray, float, float]]:
        """The roll toward ±u₀, ±v₀: (rotation vector (3,) rad, roll length m, direction t as (3,)) for each
        direction that turns the sheet."""
        out = []
        for t in (u0, cross(n, u0)):
            p = (q[0] + LOOK_STEP * t[0], q[1] + LOOK_STEP * t[1], q[2] + LOOK_STEP * t[2])
            try:
                pr = self.shape.project(p, n, self.cfg.singular_eps)
            except (ValueError, ArithmeticError):
                continue
            a = np.cross(n, pr.normal)
            s = float(np.linalg.norm(a))
            ang = math.atan2(s, float(np.dot(n, pr.normal)))
            if pr.singular or ang < 1e-4:
                continue
            kappa = ang / LOOK_STEP
            th = min(kappa * LOOK_LENGTH, self.cfg.psi_lookahead)
            for sign in (1.0, -1.0):
                out.append((sign * th * a / s, th / kappa, sign * np.asarray(t, float)))
        return out

    def score(self, q: Vec, n: Vec, u: Vec, offset: tuple[float, float], stretch: float, looks) -> float:
        """The score (module doc) of the sheet with axis ``u`` through contact ``q`` at ``offset``, with the
        look-ahead rolls ``looks`` (:meth:`_looks`)."""
        qa, na, ua = np.asarray(q, float), np.asarray(n, float), np.asarray(u, float)
        va = np.cross(na, ua)
        poses = [(qa - offset[0] * ua - offset[1] * va, na, ua)]
        for w, length, t in looks:
            th = float(np.linalg.norm(w))
            n2, u2, v2 = (rodrigues(tuple(w / th), th, tuple(x)) for x in (na, ua, va))
            n2, u2, v2 = np.asarray(n2), np.asarray(u2), np.asarray(v2)
            q2 = qa + (n2 - na) * (length / th)          # on the osculating circle, radius length/th
            su = offset[0] + length * float(t @ ua)
            sv = offset[1] + length * float(t @ va)
            poses.append((q2 - su * u2 - sv * v2, n2, u2))
        ar, size = self.arm_reach, self.cfg.material.size
        margin, w_min, travel, q0 = 0.5, math.inf, 0.0, {}
        for i, (o, nn, uu) in enumerate(poses):
            for side, T in zip(("left", "right"), clamp_poses(o, nn, uu, stretch, size), strict=True):
                kin = ar.kin[side]
                r = kin.ik(T, q0.get(side, ar.seed[side]), max_iter=IK_ITER, max_jump=math.inf)
                if not r.ok:            # the pose itself: never chosen; a look-ahead: counted
                    return -math.inf if i == 0 else -2.0 * len(poses) + i
                margin = min(margin, float(np.min(np.minimum(r.q - kin.q_lower, kin.q_upper - r.q)
                                                  / (kin.q_upper - kin.q_lower))))
                w_min = min(w_min, r.manipulability)
                if i == 0:
                    q0[side] = r.q
                    travel = max(travel, float(np.max(np.abs(r.q - ar.seed[side]) / QD_MAX)))
        s = margin + W_MANIP * min(1.0, w_min / W_REF) - W_TRAVEL * travel
        g = self.guard
        if g is not None and g.eye is not None and not g.lost:
            c = min(g.verdict(poses[0][0], np.column_stack((na, ua, va)), stretch).clearance,
                    g.arms(ar.kin, q0).clearance)
            s += -1.0 if c < 0.0 else W_CLEAR * min(1.0, c / g.keepout.near_distance)
        return s


def turn(n: Vec, u0: Vec, psi: float) -> Vec:
    """``u0`` (3,) turned by ``psi`` rad about the unit normal ``n`` (3,): cos ψ·u₀ + sin ψ·(n × u₀)."""
    if psi == 0.0:
        return u0
    c, s = math.cos(psi), math.sin(psi)
    v0 = cross(n, u0)
    return (c * u0[0] + s * v0[0], c * u0[1] + s * v0[1], c * u0[2] + s * v0[2])
