"""The bridge's target logic, independent of the network (pure; time is passed in).

:class:`TargetTracker` turns clamp-pose targets (``ArmTarget.pose``, display frame) into a joint goal with IK
seeded from the previous goal, refuses what IK reports as unreachable, beyond limits, singular or a
branch jump (the goal stays at the last good solution: the arm stops short, the status says why), and holds
when targets stop arriving for longer than ``target_timeout``. Between targets the goal moves on at the
velocity of the last few goals (a least-squares line through the last :data:`VELOCITY_GOALS` goals over their
source stamps; at most :data:`EXTRAPOLATE_MAX_S` past the newest), and the streaming limiter follows it with
that velocity as feed-forward (:mod:`flexsheet.arm.limiter`), within the joint limits.

A target that carries the sheet's motion (:class:`flexsheet.arm.sheet_motion.SheetSegment`, the same in both
arms' targets) is followed along it instead: each cycle the clamp's pose on the segment at that instant,
reached by one Newton step from the last cycle's joints (IK where that point is far or near a singularity),
with the clamp's twist mapped through the Jacobian as the velocity feed-forward. The two bridges evaluate one
trajectory at one instant, so the clamps move as one; the limiter is then only the last guard of the joint
limits. Where IK refuses a point on the way, the arm streams to the target's IK goal as above.
"""

from __future__ import annotations

import math
from dataclasses import replace
from enum import StrEnum

import numpy as np

from flexsheet.arm.kinematics import QD_MAX, ArmKinematics, IKResult, outside_limits
from flexsheet.arm.pull_limit import max_pull
from flexsheet.arm.sheet_motion import SheetSegment, lsq_slope
from flexsheet.arm.span_guard import SpanGuard
from flexsheet.model.vec import vnorm

__all__ = ["TargetTracker", "TargetRefused", "BridgeStatus", "VELOCITY_GOALS", "EXTRAPOLATE_MAX_S",
           "PEER_ON_MOTION",
           "SPAN_ON_MOTION", "TRACK_STEP_MAX", "TRACK_W_MIN"]

#: goals the velocity is fitted over (16 at the camera's 48 Hz: the last 313 ms)
VELOCITY_GOALS = 16
#: the goal moves on at its velocity for at most this long after the newest target (then it waits there)
EXTRAPOLATE_MAX_S = 0.05
#: m: a partner whose measured clamp is this close to the sheet's motion at its
#: stamp follows it (the servo's lag at the planner's 0.3 m/s, 15 ms, is 4.5 mm)
PEER_ON_MOTION = 0.01
#: m: with both arms on the sheet's motion, a step waits only if it takes the clamp span further than
#: this from the motion's own span (0.005 m is 0.02 clamp strain on the 0.240 m sheet, the most a
#: plan may be over-stretched); the fixed band's floor sits only 0.0012 m under the planner's least
#: stretch, so the arms' millimetre of tracking in a turn made one arm wait while the other moved on
SPAN_ON_MOTION = 0.005
#: m or rad (the largest of the pose error's six parts): on the sheet's motion, a cycle's Newton step
#: (:meth:`ArmKinematics.track`) follows a point at most this far from the
#: last; further, IK solves it (a cycle of the motion at its 0.3 m/s is
#: 2.1 mm; the step's own error is then some µm, corrected the next cycle)
TRACK_STEP_MAX = 0.005
#: the least manipulability a Newton step is taken at (10× IK's ``w_singular``, where IK starts to
#: damp): nearer a singularity IK solves the point, with its damping and its ``singular`` status
TRACK_W_MIN = 2e-3


class TargetRefused(ValueError):
    """A target IK refused (``set_target(..., strict=True)``); ``result`` is the :class:`IKResult`. A
    ``ValueError``, so a node handler that lets it out counts the message as rejected input."""

    def __init__(self, result: IKResult) -> None:
        super().__init__(f"ArmTarget refused by IK: {result.status}")
        self.result = result


class BridgeStatus(StrEnum):
    """The bridge's fixed statuses (``ArmState.bridge_status``; compares equal to its string). A refused IK
    target is ``"hold:" + IKResult.status`` (``hold:unreachable``, ``hold:limit:J<k>``, ...). ``wait:span``:
    following, this cycle's step waited on the span guard (:meth:`TargetTracker.span_worse`)."""

    OK = "ok"
    NO_TARGET = "hold:no_target"
    DISABLED = "hold:disabled"
    REFUSED = "hold:refused"
    PEER = "hold:peer"
    SPAN_WAIT = "wait:span"


def peer_holds(status: str) -> bool:
    """Whether a partner arm's ``bridge_status`` makes this arm hold too: an IK refusal (``hold:unreachable``,
    ``hold:limit:J<k>``, ``hold:singular``, ``hold:jump``, ``hold:torque:J<k>``), a controller fault
    (``fault:*``) or a lost controller (``disconnected``): that clamp has stopped, and the sheet between them
    must not be pulled by the other. Not a hold the partner shares itself (``hold:peer``: no deadlock), nor no
    target, a disabled controller or a refused command (both arms see those alike, or the stream restarts at
    once)."""
    if status.startswith("fault:") or status == "disconnected":
        return True
    return status.startswith("hold:") and status not in (BridgeStatus.NO_TARGET, BridgeStatus.DISABLED,
                                                          BridgeStatus.REFUSED, BridgeStatus.PEER)


class TargetTracker:
    """Joint goal for one arm from its stream of clamp-pose targets.

    ``kin``: the arm's :class:`ArmKinematics`. ``target_timeout``: s without a target before holding.
    ``max_jump``: rad, largest joint change one new target may ask of IK (larger = a branch jump, refused).
    After a pause of the target stream longer than ``target_timeout`` (the arm held) the first target may ask
    ``max_jump`` plus what the fastest joint could have moved in the pause (``QD_MAX``'s largest, rad/s, times
    the pause): the finger went on meanwhile, and a respawned planner's first target is where it is now. A
    stream that has not started yet (the first target, or the first after :meth:`release`) counts its pause
    from the first target heard, or from the release: a target refused then does not start the stream, so the
    allowance keeps growing and the arm joins a stream that begins far away (after a registration moved it)
    instead of holding on ``hold:jump`` for as long as the targets keep coming. The streaming limiter still
    moves the arm there at the speed limit. A branch flip inside a flowing stream is refused. After
    :meth:`seed` (or the first target) ``goal`` is a (6,) rad joint vector.
    """

    def __init__(self, kin: ArmKinematics, target_timeout: float = 0.25, max_jump: float = 0.5) -> None:
        if not target_timeout > 0.0:
            raise ValueError(f"target_timeout must be > 0 s, got {target_timeout!r}")
        if not max_jump > 0.0:
            raise ValueError(f"max_jump must be > 0 rad, got {max_jump!r}")
        self.kin = kin
        self.target_timeout = float(target_timeout)
        self.max_jump = float(max_jump)
        self.goal: np.ndarray | None = None
        self.source_stamp = 0.0
        self.last_target_at: float | None = None
        #: s: when the arm last stopped following (the release,
        #: or the first target heard): a new stream's pause
        self.held_since: float | None = None
        self.ik_status = "no_target"
        self.last_ik: IKResult | None = None
        self.refused = 0
        self.planned_taken = 0        # targets whose publisher's IK passed the checks (not solved again)
        self.planned_solved = 0       # targets whose publisher's IK did not: solved here
        self._history: list[tuple[float, np.ndarray]] = []   # (source stamp, goal) of the last accepted goals
        self.velocity = np.zeros(6)
        #: (6,) rad: a goal a service set (hold, home, move-to); while set, targets are not followed
        self.manual: np.ndarray | None = None
        #: the partner arm's hold this arm shares (its bridge_status, e.g.
        #: "hold:limit:J3"), or None: the sheet couples the two clamps, so while
        #: one arm cannot follow, the other stops too (:func:`peer_holds`)
        self.peer_hold: str | None = None
        #: ``q (6,) -> bool``: whether joints ``q`` put this arm or its clamp
        #: in the viewer's keep-out (the last line behind the planner's head
        #: guard); such a target is refused as ``hold:keep_out``. None: no head
        self.keep_out = None
        #: the two-arm span guard (:class:`flexsheet.arm.span_guard.SpanGuard`): the band, the partner's clamp
        self.span = SpanGuard(kin)
        #: the sheet's motion the arm follows (:class:`SheetSegment`), or None: stream to :attr:`goal`
        self.motion: SheetSegment | None = None
        #: (6,) rad: the joints of the last point followed on :attr:`motion` (the next cycle's IK seed)
        self._motion_q: np.ndarray | None = None
        #: cycles a point on the motion was refused by IK (the arm streamed to the goal instead)
        self.motion_refused = 0

    def span_worse(self, q_from, q_to, q_stop=None, at: float | None = None) -> bool:
        """Whether this arm's step from joints ``q_from`` to ``q_to`` (6,) rad, ending at time ``at`` s, waits
        on the span guard (:meth:`flexsheet.arm.span_guard.SpanGuard.worse`; ``wait:span``); ``q_stop``: where
        the clamp would come to rest braking from ``q_to`` (default ``q_to``). A service's goal
        (:meth:`move_to`: a registration's configurations, homing) is the operator's and is not judged. While
        both arms follow the sheet's motion, a partner whose measured clamp is on it (within
        :data:`PEER_ON_MOTION` of the motion at its measurement's stamp) is judged where the motion has it at
        ``at``, against the step's end, and the band is the motion's own span at ``at`` ±
        :data:`SPAN_ON_MOTION`: its measurement lags its command by the servo and a cycle, and judging against
        it, this arm's braking point or the fixed band made the arms wait on each other in fast moves and
        turns. Otherwise the braking point is judged against the partner's measured clamp and the fixed
        band."""
        if self.manual is not None:
            return False
        guard = self.span
        measured = guard.peer_clamp
        if (self.motion is not None and measured is not None and guard.peer_stamp is not None
                and at is not None and guard.band is not None):
            k = 1 if self.kin.side == "left" else 0        # the partner's place in clamp_points (left, right)
            at_meas = self.motion.clamp_points(guard.peer_stamp)[k]
            if vnorm(measured - at_meas) <= PEER_ON_MOTION:
                points = self.motion.clamp_points(at)
                theirs = points[k]
                span = vnorm(points[0] - points[1])
                return guard.worse(q_from, q_to, theirs,
                                   (max(span - SPAN_ON_MOTION, 1e-3), span + SPAN_ON_MOTION))
        return guard.worse(q_from, q_to if q_stop is None else q_stop)

    def move_to(self, q) -> np.ndarray:
        """Stream to joints ``q`` (6,) rad and stay there, ignoring targets until :meth:`release`. Raises
        ``ValueError`` naming the joint outside the kinematics' limits."""
        q = self.kin.check_q(q)
        bad = outside_limits(q, self.kin.q_lower, self.kin.q_upper)
        if bad:
            raise ValueError("joints outside the limits (with the bridge's margin): " + "; ".join(bad))
        self.manual = q.copy()
        self.motion = None
        self.goal = self.manual.copy()
        self.velocity = np.zeros(6)
        self._history.clear()
        return self.manual

    def release(self, now: float | None = None) -> None:
        """Follow targets again (from the next one; the arm holds where it is until then). ``now`` (s): the
        release's time, from which a new stream's first target counts its pause (class doc)."""
        self.manual = None
        self.last_target_at = None
        self.held_since = now
        self._history.clear()

    def seed(self, q) -> None:
        """Start IK from joints ``q`` (6,) rad (the measured joints) if no goal exists yet."""
        if self.goal is None:
            self.goal = self.kin.check_q(q).copy()

    def set_target(self, T_display_clamp, source_stamp: float, now: float, q_measured=None, *,
                   strict: bool = False, pull: float = 0.0, motion: SheetSegment | None = None,
                   q_planned=None) -> IKResult:
        """Solve IK for a new target pose (4, 4) at time ``now`` (s); returns the :class:`IKResult`. ``pull``
        N: the sheet's pull on the clamp there; a solution whose joint torques pass the arm's limits is
        refused as ``torque:J<k>`` (:func:`flexsheet.arm.pull_limit.max_pull`). ``motion``: the sheet's motion
        to the target (module doc), followed once the target is accepted; None: stream to its IK goal.

        ``q_planned`` (6,) rad: the publisher's IK of the pose (the planner's; None or empty: none), checked
        rather than solved again: taken when it puts this arm's clamp at the pose (within the IK's tolerance,
        one Newton step at most) inside this arm's limits, not singular, and within the jump limit of the
        seed; otherwise IK solves from the seed as without it (``planned_taken``, ``planned_solved`` count
        each way).

        Seed: the current goal, else ``q_measured``; the jump limit as the class doc says. If the result is
        not ok, the goal is unchanged, ``ik_status`` holds the reason, ``refused`` counts it and, with
        ``strict``, :class:`TargetRefused` is raised (after that bookkeeping: the hold status still shows).
        Raises ``ValueError`` for a malformed pose or ``q_planned`` (before anything changes).
        """
        if q_planned is not None:
            q_planned = np.asarray(q_planned, dtype=float)
            if q_planned.size == 0:
                q_planned = None
            elif q_planned.shape != (6,) or not np.isfinite(q_planned).all():
                raise ValueError(f"joints (the publisher's IK) must be 6 finite values in rad or none, got "
                                 f"{q_planned.tolist()}")
        seed = self.goal if self.goal is not None else q_measured
        if seed is None:
            raise ValueError("no seed: call seed(q_measured) or pass q_measured before the first target")
        max_jump = self.max_jump
        if self.last_target_at is None and self.held_since is None:
            self.held_since = now                       # the first target heard: the arm is held from here
        flowing = self.last_target_at is not None and now - self.last_target_at <= self.target_timeout
        resumed = not flowing
        if resumed:                                     # resumed after a pause, or a stream not started yet
            since = self.last_target_at if self.last_target_at is not None else self.held_since
            max_jump += float(np.max(QD_MAX)) * max(now - since, 0.0)
        res = self._planned(T_display_clamp, q_planned, seed, max_jump) if q_planned is not None else None
        if res is None:
            res = self.kin.ik(T_display_clamp, seed, max_jump=max_jump)
        if res.ok and self.keep_out is not None and self.keep_out(res.q):
            res = replace(res, ok=False, status="keep_out")      # the arm would enter the viewer's keep-out
        if res.ok and pull > 0.0:
            limit, joint = max_pull(self.kin, res.q)
            if pull > limit:
                res = replace(res, ok=False, status=f"torque:J{joint}")   # the sheet would overload a joint
        self.last_ik = res
        if res.ok or self.last_target_at is not None:   # a refused first target does not start the stream
            self.last_target_at = now
        if res.ok:
            if motion is not None and self.motion is None:
                self._motion_q = self.goal.copy() if self.goal is not None else res.q.copy()
            self.motion = motion
            self.goal = res.q
            self.source_stamp = float(source_stamp)
            self.ik_status = "ok"
            self._fit_velocity(resumed)
        else:
            self.ik_status = res.status
            self.refused += 1
            if strict:
                raise TargetRefused(res)
        return res

    def _planned(self, T, q_planned, seed: np.ndarray, max_jump: float) -> IKResult | None:
        """``q_planned`` judged as this arm's IK of ``T`` (:meth:`set_target`): the :class:`IKResult` of IK
        seeded there when it converges at once and passes every check, else None (solve from ``seed``)."""
        res = self.kin.ik(T, q_planned, max_jump=math.inf, max_iter=2)
        if res.ok and float(np.max(np.abs(res.q - seed))) <= max_jump:
            self.planned_taken += 1
            return res
        self.planned_solved += 1
        return None

    def _fit_velocity(self, restart: bool) -> None:
        """The goal's velocity (6,) rad/s: slope of the least-squares line through the last goals over their
        source stamps (0 with fewer than 2, after a pause, or for stamps that do not increase)."""
        h = self._history
        if restart or (h and self.source_stamp <= h[-1][0]):
            h.clear()
        h.append((self.source_stamp, self.goal.copy()))
        del h[:-VELOCITY_GOALS]
        if len(h) < 2:
            self.velocity = np.zeros(6)
            return
        self.velocity = lsq_slope([x[0] for x in h], [x[1] for x in h])

    def status(self, now: float) -> str:
        """"ok", "hold:no_target" (none yet or timed out), "hold:<ik status>" (last target refused) or
        "manual" (a service's goal, :meth:`move_to`)."""
        if self.manual is not None:
            return "manual"
        if self.peer_hold is not None:
            return BridgeStatus.PEER
        if self.last_target_at is None or now - self.last_target_at > self.target_timeout:
            return BridgeStatus.NO_TARGET
        return BridgeStatus.OK if self.ik_status == "ok" else f"hold:{self.ik_status}"

    def reference(self, now: float, q_command: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joint goal (6,) rad and its velocity (6,) rad/s to stream toward at ``now`` (s): while targets are
        fresh, the IK goal moved on at :attr:`velocity` for the time since it arrived (at most
        :data:`EXTRAPOLATE_MAX_S`); else ``q_command`` at rest (hold where the command is: the limiter brakes
        to a stop)."""
        if self.manual is not None:
            return self.manual, np.zeros(6)
        if self.goal is None or self.status(now) in (BridgeStatus.NO_TARGET, BridgeStatus.PEER):
            return q_command, np.zeros(6)
        if self.motion is not None and self.ik_status == "ok":
            ref = self._on_motion(now)
            if ref is not None:
                return ref
        ahead = min(max(now - self.last_target_at, 0.0), EXTRAPOLATE_MAX_S)
        w = self.velocity if ahead < EXTRAPOLATE_MAX_S else np.zeros(6)
        return self.goal + self.velocity * ahead, w

    def _on_motion(self, now: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Joints (6,) rad of the clamp's point on :attr:`motion` at ``now`` and their velocity (6,) rad/s
        (the clamp's twist through the Jacobian); None when IK refuses the point (counted in
        ``motion_refused``). From the last cycle's point, one Newton step (:meth:`ArmKinematics.track`) while
        its error is under :data:`TRACK_STEP_MAX`, its manipulability over :data:`TRACK_W_MIN` and the step
        within the joint limits; otherwise IK solves the point, with its checks."""
        T, twist = self.motion.clamp(self.kin.side, now)
        kin = self.kin
        if self._motion_q is not None:
            try:
                q, w, err, manip = kin.track(T, self._motion_q, twist)
            except np.linalg.LinAlgError:
                err = np.inf
            if (err <= TRACK_STEP_MAX and manip >= TRACK_W_MIN and (q >= kin.q_lower).all()
                    and (q <= kin.q_upper).all()):
                self._motion_q = q
                return q, w
        seed = self._motion_q if self._motion_q is not None else self.goal
        res = kin.ik(T, seed, max_jump=self.max_jump, tol_pos=1e-7, tol_rot=1e-7)   # 0.1 µm: 1-2 iterations
        if not res.ok:
            self.motion_refused += 1
            return None
        self._motion_q = res.q
        try:
            w = np.linalg.solve(kin.jacobian(res.q), twist)
        except np.linalg.LinAlgError:
            w = np.zeros(6)
        return res.q, w

    def goal_for(self, now: float, q_command: np.ndarray) -> np.ndarray:
        """The goal of :meth:`reference` alone (6,) rad."""
        return self.reference(now, q_command)[0]
