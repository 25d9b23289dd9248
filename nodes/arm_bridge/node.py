"""Node ``arm_bridge``: one per arm PC. ArmTarget (clamp pose) → IK → limited 7.1 ms Modbus TCP stream → ArmJointState.

Thin shell: IK and target logic in :mod:`.tracking`/:mod:`.kinematics`, command shaping in :mod:`.interp`,
the Modbus client loop in :mod:`.link`. Subscribes ``topics.arm_target(arm)`` (QoS.LATEST, async handler on
the loop: IK takes tens of µs), publishes ``topics.arm_state(arm)`` every cycle with the measured joints,
their FK clamp pose (display frame), controller status/fault, ``write_stamp`` (wall time of the Modbus write)
and ``target_stamp`` (= the executed ``ArmTarget.source_stamp``) for latency accounting.

``bridge_status``: "ok"; "hold:no_target" (no target yet, or none for ``target_timeout`` s: the arm stops);
"hold:unreachable" / "hold:limit:J<k>" / "hold:singular" / "hold:jump" (last target refused by IK: the arm
stops short at the last good goal); "hold:disabled" (controller not enabled yet); "fault:watchdog",
"fault:estop" (controller faulted; the bridge follows the measured joints); "disconnected".
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from flexsheet.model.kinematics import LEFT_BASE, Q_LOWER, Q_UPPER, QD_MAX, RIGHT_BASE, ArmKinematics
from flexsheet.runtime.node import InputRejected, Node, QoS
from messages import ArmJointState, ArmTarget, topics
from nodes.arm_bridge.interp import StreamLimiter
from nodes.arm_bridge.link import ArmStream, CycleReport
from nodes.arm_bridge.tracking import TargetTracker

__all__ = ["ArmBridgeParams", "ArmBridgeNode"]


class ArmBridgeParams(BaseModel):
    """Parameters of one arm bridge (SI units: m, rad, s)."""

    model_config = ConfigDict(extra="forbid")
    arm: str = Field(default="left", pattern="^(left|right)$", description="which sheet edge: left or right")
    host: str = Field(default="127.0.0.1", description="controller (or twin) address")
    port: int = Field(default=15020, ge=1, le=65535, description="controller Modbus TCP port")
    device_id: int = Field(default=1, ge=0, le=255, description="Modbus unit id")
    base: list[float] | None = Field(default=None, min_length=4, max_length=4,
                                     description="arm base (x, y, z, yaw) in the display frame; "
                                                 "default kinematics.LEFT_BASE / RIGHT_BASE")
    period: float = Field(default=0.0071, gt=0.0, description="stream period, s (RV-1A real-time control)")
    target_timeout: float = Field(default=0.25, gt=0.0, description="hold after this long without a target, s")
    speed_scale: float = Field(default=0.5, gt=0.0, le=1.0, description="commanded speed limit × URDF speed")
    accel_scale: float = Field(default=2.0, gt=0.0, description="commanded accel limit = scale × speed limit, 1/s")
    limit_margin: float = Field(default=0.02, ge=0.0, description="kept from each joint limit, rad")
    max_ik_jump: float = Field(default=0.5, gt=0.0, description="largest joint change one target may ask, rad")
    auto_reset: bool = Field(default=True, description="reset watchdog faults automatically (never e-stops)")
    request_timeout: float = Field(default=0.1, gt=0.0, description="Modbus request timeout, s")
    backoff_min: float = Field(default=0.05, gt=0.0, description="first reconnect delay, s")
    backoff_max: float = Field(default=2.0, gt=0.0, description="largest reconnect delay, s")


class ArmBridgeNode(Node):
    """Node type ``arm_bridge`` (see module doc)."""

    Params = ArmBridgeParams
    node_type = "arm_bridge"

    async def setup(self) -> None:
        p = self.params
        base = tuple(p.base) if p.base is not None else (LEFT_BASE if p.arm == "left" else RIGHT_BASE)
        if not all(math.isfinite(v) for v in base):
            raise ValueError(f"base must be finite, got {base!r}")
        margin = p.limit_margin
        self.kin = ArmKinematics(p.arm, base, Q_LOWER + margin, Q_UPPER - margin)
        self.fk_kin = ArmKinematics(p.arm, base)
        self.tracker = TargetTracker(self.kin, p.target_timeout, p.max_ik_jump)
        qd = QD_MAX * p.speed_scale
        limiter = StreamLimiter(np.clip(np.zeros(6), Q_LOWER, Q_UPPER), p.period, qd, qd * p.accel_scale,
                                Q_LOWER, Q_UPPER, margin)
        self.stream = ArmStream(self.tracker, limiter, p.host, p.port, device_id=p.device_id,
                                request_timeout=p.request_timeout, backoff_min=p.backoff_min,
                                backoff_max=p.backoff_max, auto_reset=p.auto_reset, on_cycle=self.on_cycle,
                                clock=self.now)
        self._pending: ArmTarget | None = None
        self._last_status = ""
        self.pub = self.publisher(topics.arm_state(p.arm))
        self.subscribe(topics.arm_target(p.arm), self.on_target, qos=QoS.LATEST)
        self.stream.start()

    async def teardown(self) -> None:
        await self.stream.stop()

    async def on_target(self, msg: ArmTarget) -> None:
        """New clamp target: IK now (or once the first controller state arrived)."""
        if msg.arm != self.params.arm:
            raise InputRejected(f"ArmTarget.arm={msg.arm!r} on the {self.params.arm} arm's topic")
        if self.tracker.goal is None:
            self._pending = msg
            return
        self.tracker.set_target(msg.pose, msg.source_stamp, self.now())
        await self.stream.refresh()   # write it now rather than at the next tick

    def on_cycle(self, rep: CycleReport) -> None:
        """Publish the joint state of this cycle (runs on the loop every period)."""
        if self._pending is not None and self.tracker.goal is not None:
            msg, self._pending = self._pending, None
            try:
                self.tracker.set_target(msg.pose, msg.source_stamp, self.now())
            except ValueError as exc:
                self._reject(f"ArmTarget: {exc}")
        if rep.bridge_status != self._last_status:
            self.log.info("%s arm: %s", self.params.arm, rep.bridge_status)
            self._last_status = rep.bridge_status
            self.state_message = rep.bridge_status
        st = rep.state
        if st is None:
            return
        q = st.position
        self.pub.publish(ArmJointState(
            header=self.pub.header("display"), arm=self.params.arm, position=q, velocity=st.velocity,
            commanded=rep.commanded, pose=self.fk_kin.fk(q), status=st.status, fault=st.fault,
            manipulability=self.fk_kin.manipulability(q), target_stamp=rep.target_stamp,
            write_stamp=rep.write_stamp, bridge_status=rep.bridge_status))
