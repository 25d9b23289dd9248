"""Node ``arm_bridge``: one per arm PC. ArmTarget (clamp pose) → IK → limited command stream, one command per
controller cycle (7.1 ms) → ArmJointState.

Thin shell: IK and target logic in :mod:`flexsheet.arm.tracking` / :mod:`flexsheet.arm.kinematics` (the
sheet's motion both bridges follow at the same instant: :mod:`flexsheet.arm.sheet_motion`), the
two-arm span guard in :mod:`flexsheet.arm.span_guard`, command shaping in :mod:`flexsheet.arm.limiter`, the
protocol-independent streaming loop in :mod:`flexsheet.arm.stream`, and one backend per ``protocol``:
``modbus`` (:mod:`nodes.arm_bridge.modbus_link`, Modbus TCP register map, docs/register_map.md) or ``mxt``
(:mod:`nodes.arm_bridge.mxt_link`, MELFA real-time external control over UDP, docs/arm.md). Subscribes
``topics.arm_target(arm)`` (QoS.LATEST, async handler on the loop: IK takes tens of µs), publishes
``topics.arm_state(arm)`` every cycle with the measured joints, their FK clamp pose (display frame),
controller status/fault, ``write_stamp`` (wall time the command left: Modbus write / MXT MOVE) and
``target_stamp`` (= the executed ``ArmTarget.source_stamp``) for latency accounting. The heartbeat message
carries the link counters (MXT: packets sent, replies, late, lost, repeats, refused).

``bridge_status``: "ok"; "hold:no_target" (no target yet, or none for ``target_timeout`` s: the arm stops);
"hold:unreachable" / "hold:limit:J<k>" / "hold:singular" / "hold:jump" / "hold:keep_out" / "hold:torque:J<k>"
(last target refused by IK, by the sheet's pull (``ArmTarget.pull``) passing a joint's torque limit there
(:mod:`flexsheet.arm.pull_limit`), or — once ``/eye/pose`` tracks the viewer — by the head's keep-out with
``keepout_margin``: the arm stops short at the last good goal); "hold:disabled" (controller not enabled yet,
or ``enabled: false``); "fault:watchdog", "fault:estop" (controller faulted; the bridge follows the measured
joints); "hold:refused" (the controller did not take a command: the stream restarts from what it executes);
"disconnected"; "hold:peer" (the other arm holds on an IK refusal, a fault or a lost controller, read from its
joint state: the sheet couples the clamps, so this arm stops where it is, from the cycle that state arrives
in, until the other follows again).

Span guard (``span_band`` [lo, hi] m): a cycle whose goal would take this clamp further outside the band from
the partner's measured clamp than the command already is waits at rest (``bridge_status`` ``wait:span``;
counted as ``span waits`` in the heartbeat): when one arm lags or stops, the other does not slacken the sheet
or over-pull it. When the partner says ``wait:span`` too, both step
(:meth:`~flexsheet.arm.span_guard.SpanGuard.worse`).
"""

from __future__ import annotations

import math

import numpy as np

from flexsheet.arm.chain import bridge_chain
from flexsheet.arm.controller_port import controller_source
from flexsheet.arm.sheet_motion import SheetSegment
from flexsheet.arm.stream import ArmStream, CycleReport
from flexsheet.arm.tracking import BridgeStatus, peer_holds
from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE
from flexsheet.model.timing import LAB
from flexsheet.planning.keepout import KeepOut, arm_keepout_clearance
from flexsheet.runtime.node import InputRejected, Node
from flexsheet.runtime.qos import QoS
from messages import ArmJointState, ArmTarget, EyePose, topics
from nodes.arm_bridge.modbus_link import ModbusLink
from nodes.arm_bridge.mxt_link import MxtLink
from nodes.arm_bridge.params import ArmBridgeParams
from nodes.arm_bridge.services import BridgeServices

__all__ = ["ArmBridgeNode"]


class ArmBridgeNode(BridgeServices, Node):
    """Node type ``arm_bridge`` (see module doc)."""

    Params = ArmBridgeParams
    node_type = "arm_bridge"

    async def setup(self) -> None:
        p = self.params
        if p.display_calib:   # the registered base (a ValueError names the file and the missing entry)
            if p.base is not None:
                raise ValueError("base and display_calib are both set: the base comes from display.yaml's "
                                 f"arms.{p.arm} entry; drop the base param")
            calib = load_display_calib(p.display_calib, require=(f"arms.{p.arm}",))
            base = calib.arms[p.arm].T_display_base
            self.log.info("%s arm base from %s (arms.%s, %s)", p.arm, p.display_calib, p.arm,
                          calib.arms[p.arm].provenance.source)
        else:
            base = tuple(p.base) if p.base is not None else (LEFT_BASE if p.arm == "left" else RIGHT_BASE)
            if not all(math.isfinite(v) for v in base):
                raise ValueError(f"base must be finite, got {base!r}")
            self.log.warning("%s arm base: design values %s (no display_calib; docs/calibration.md)", p.arm,
                             [round(float(v), 4) for v in base])
        chain = bridge_chain(p.arm, base, p.period, p)
        self.kin, self.fk_kin, self.tracker, limiter = chain.kin, chain.fk, chain.tracker, chain.limiter
        source = controller_source(p.source)
        source.check_clock(self.clock)
        if p.protocol not in source.protocols:
            raise ValueError(f"source {p.source} carries protocol {' or '.join(sorted(source.protocols))}, "
                             f"not {p.protocol}")
        self._paced_by_node = source.paced_by_node
        # the arm PC's clock: main's plus its offset (the twin's draw; the lab's own is
        # whatever chrony leaves, docs/deploy.md); the sheet's motion is evaluated on it
        self.clock_offset = source.clock_offset(p)
        if p.protocol == "mxt":
            self.link = MxtLink(p.host, p.port, period=p.period, open_timeout=p.mxt_open_timeout,
                                lost_cycles=p.mxt_lost_cycles)
        else:
            client = source.modbus_client()
            self.link = ModbusLink(p.host, p.port, device_id=p.device_id, request_timeout=p.request_timeout,
                                   auto_reset=p.auto_reset,
                                   **({} if client is None else {"client_factory": client}))
        self.stream = ArmStream(self.tracker, limiter, self.link, backoff_min=p.backoff_min,
                                backoff_max=p.backoff_max, on_cycle=self.on_cycle, clock=self.arm_stamp,
                                enabled=p.enabled, monotonic=self.monotonic)
        self._diag_at = 0.0
        self._pending: ArmTarget | None = None
        self._last_status = ""
        self.pub = self.publisher(topics.arm_state(p.arm))
        # simulated clock: the target crosses the lab network to the arm PC,
        # then IK (flexsheet/model/timing.py) every target is handled and a
        # refused one counted (QoS latest would drop them before decoding)
        self.subscribe(topics.arm_target(p.arm), self.on_target, qos=QoS.KEEP_ALL, depth=256,
                       sim_cost=LAB.network_s + LAB.compute("arm_bridge"))
        other = "right" if p.arm == "left" else "left"
        # a status read, no compute worth charging: on the simulated clock it must not keep the bridge busy (a
        # sim_cost here delayed its cycles and moved the default run's arm latency by 0.2 ms)
        self.subscribe(topics.arm_state(other), self.on_peer_state, qos=QoS.LATEST)
        self.keepout = KeepOut(margin=p.keepout_margin)
        self._eye: np.ndarray | None = None
        self.subscribe(topics.EYE_POSE, self.on_eye_pose, qos=QoS.LATEST)
        # the node's timer paces the cycles (else the stream's own loop, on the wall clock)
        if self._paced_by_node:
            self.timer(p.period, self._paced_cycle)
        else:
            self.stream.start()
        self._q_measured: np.ndarray | None = None
        #: targets that arrived while a service held the arm (None: not held); said at the release
        self.ignored_while_held: int | None = None
        self.service("hold", self.srv_hold, "stop following targets and stay where the arm is; returns its "
                                            "joints, rad",
                     commanding=True)
        self.service("home", self.srv_home, "move to the home sheet's clamp pose (IK), within the speed "
                                            "limits",
                     commanding=True)
        self.service("move_to", self.srv_move_to, "{joints: [6] rad} or {pose: 4x4 clamp pose, m, display "
                     "frame}: move there within the speed limits and stay", commanding=True)
        self.service("release", self.srv_release, "follow the targets again", commanding=True)

    def arm_now(self) -> float:
        """This arm PC's clock, s: the graph's :meth:`now` plus :attr:`clock_offset` (0 on the wall clock)."""
        return self.now() + self.clock_offset

    def arm_stamp(self) -> float:
        """As :meth:`arm_now` for what leaves now (the graph's ``clock.stamp()``): the stream's clock."""
        return self.clock.stamp() + self.clock_offset

    async def _paced_cycle(self) -> None:
        await self.stream.step(self.now())

    async def teardown(self) -> None:
        stream = getattr(self, "stream", None)   # None when setup failed before the stream existed
        if stream is not None:
            await stream.stop(end=True)    # MXT: END, the controller's Mxt instruction finishes

    def on_peer_state(self, msg: ArmJointState) -> None:
        """The other arm's state: hold with it while it cannot follow
        (:func:`~flexsheet.arm.tracking.peer_holds`)."""
        self.tracker.span.peer_clamp = np.asarray(msg.pose, float)[:3, 3].copy()
        self.tracker.span.peer_stamp = float(msg.header.stamp)
        self.tracker.span.peer_waiting = msg.bridge_status == BridgeStatus.SPAN_WAIT
        hold = msg.bridge_status if peer_holds(msg.bridge_status) else None
        if hold != self.tracker.peer_hold:
            if hold is not None:
                self.log.warning("%s arm: holding with the %s arm (%s)", self.params.arm, msg.arm, hold)
            else:
                self.log.info("%s arm: the %s arm follows again: following too", self.params.arm, msg.arm)
            self.tracker.peer_hold = hold

    def on_eye_pose(self, msg: EyePose) -> None:
        """The viewer's tracked eye: from the first one, targets that would bring this arm into the head's
        keep-out are refused (``hold:keep_out``, which the partner arm shares)."""
        if msg.valid:
            if not np.all(np.isfinite(msg.eye)):
                raise InputRejected(f"/eye/pose: eye must be finite, got {msg.eye.tolist()}")
            self._eye = np.asarray(msg.eye, float).copy()
            self.tracker.keep_out = self._in_keep_out

    def _in_keep_out(self, q: np.ndarray) -> bool:
        """Whether joints ``q`` put this arm's links or its clamp bar in the keep-out of the newest tracked
        eye (:func:`~flexsheet.planning.keepout.arm_keepout_clearance`; the planner's test, at its margin)."""
        return arm_keepout_clearance(self.keepout, self._eye, self.kin, q)[0] < 0.0

    async def on_target(self, msg: ArmTarget) -> None:
        """New clamp target: IK now (or once the first controller state arrived)."""
        if msg.arm != self.params.arm:
            raise InputRejected(f"ArmTarget.arm={msg.arm!r} on the {self.params.arm} arm's topic")
        if self.tracker.manual is not None:   # by design while a tool holds the arm: counted, said at release
            self.ignored_while_held += 1
            return
        motion = SheetSegment.from_fields(msg)     # a MotionError (a ValueError) names the bad field
        if self.tracker.goal is None:
            self._pending = msg
            return
        self.tracker.set_target(msg.pose, msg.source_stamp, self.arm_now(), strict=True, pull=msg.pull,
                                motion=motion, q_planned=msg.joints)
        if await self.stream.refresh() and self._paced_by_node:   # write it now rather than at the next tick
            await self.stream.rewrite_now()

    def on_cycle(self, rep: CycleReport) -> None:
        """Publish the joint state of this cycle (runs on the loop every period)."""
        if self._pending is not None and self.tracker.goal is not None:
            msg, self._pending = self._pending, None
            try:
                self.tracker.set_target(msg.pose, msg.source_stamp, self.arm_now(), strict=True,
                                        pull=msg.pull, motion=SheetSegment.from_fields(msg),
                                        q_planned=msg.joints)
            except ValueError as exc:
                self._reject(f"ArmTarget: {exc}")
        # not logged
        shown = BridgeStatus.OK if rep.bridge_status == BridgeStatus.SPAN_WAIT else rep.bridge_status
        if shown != self._last_status or rep.t_cycle - self._diag_at > 1.0:
            if shown != self._last_status:
                self.log.info("%s arm: %s", self.params.arm, shown)
            self._last_status = shown
            self._diag_at = rep.t_cycle
            counters = ", ".join(f"{k} {v}" for k, v in self.link.counters().items())
            waits = f"; span waits {self.tracker.span.waits}" if self.tracker.span.waits else ""
            if self.tracker.motion_refused:
                waits += f"; motion points off IK {self.tracker.motion_refused}"
            if self.tracker.planned_solved:
                waits += (f"; planner IK taken {self.tracker.planned_taken}, solved here "
                          f"{self.tracker.planned_solved}")
            self.state_message = f"{shown}; {self.link.name}: {counters}{waits}"
        st = rep.state
        if st is None:
            return
        q = st.position
        self._q_measured = np.asarray(q, float)
        pose, manipulability = self.fk_kin.fk_manipulability(q)
        self.pub.publish(ArmJointState(
            header=self.pub.header("display"), arm=self.params.arm, position=q, velocity=st.velocity,
            commanded=rep.commanded, executing=st.active, pose=pose, status=st.status, fault=st.fault,
            manipulability=manipulability, target_stamp=rep.target_stamp,
            write_stamp=rep.write_stamp, bridge_status=rep.bridge_status))
