"""World node: the physical twin of the user's finger and the sheet (simulation only).

* Finger: plays a list of :class:`flexsheet.model.finger.FingerScript` segments one after the other (default:
  the paper's stroking experiment at 10 s and 30 s moving time, then a combined stroke and push) and
  publishes the true marker position on ``/world/finger`` at ``rate_hz``; the camera twin renders it.
* Sheet: its pose comes from the arms' *measured* joint states (``ArmJointState.pose`` is the FK of the
  clamp frames), and its depression from the finger when the finger is behind the sheet plane, through
  the membrane model of :mod:`flexsheet.model.sheet`; published on ``/world/sheet``.
* Progress: one line every ``progress_period`` s; when the script ends the node exits, which ends a launch
  in which it is ``required`` (then the launch's report runs, see :mod:`flexsheet.experiments.report`).
  ``loop: true`` repeats the script until Ctrl-C (interactive mode).
"""

from __future__ import annotations

import math
import time

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from flexsheet.model.finger import FingerScript
from flexsheet.model.sheet import SheetSurface
from flexsheet.runtime.node import Node, QoS
from messages import ArmJointState, FingerTruth, SheetState
from messages import topics as T

__all__ = ["WorldNode", "WorldParams", "Segment"]


class Segment(BaseModel):
    """One scripted segment: ``mode`` stroke | push | stroke_push, ``moving_time`` s, ``push_depth`` m,
    ``end_angle_deg`` (target mark travel, deg), ``tremor_rms`` m, ``seed``."""

    model_config = ConfigDict(extra="forbid")
    mode: str = Field(default="stroke", pattern="^(stroke|push|stroke_push)$")
    moving_time: float = Field(default=10.0, gt=0.0, le=600.0)
    push_depth: float = Field(default=0.005, ge=0.0, le=0.05)
    end_angle_deg: float = Field(default=60.0, ge=-80.0, le=80.0)
    tremor_rms: float = Field(default=5e-5, ge=0.0, le=0.002)
    seed: int = 0


DEFAULT_SCRIPT = [Segment(mode="stroke", moving_time=10.0), Segment(mode="stroke", moving_time=30.0, seed=1),
                  Segment(mode="stroke_push", moving_time=10.0, push_depth=0.010, seed=2)]


class WorldParams(BaseModel):
    """``script``: segments played in order; ``rate_hz`` of ``/world/finger``; ``sheet_rate_hz`` of
    ``/world/sheet``; ``membrane_grid`` G (G×G deflection samples); ``start_delay`` s before the script
    starts (lets the graph connect and the arms reach the first pose); ``loop``: repeat until Ctrl-C;
    ``progress_period`` s."""

    model_config = ConfigDict(extra="forbid")
    script: list[Segment] = Field(default_factory=lambda: list(DEFAULT_SCRIPT))
    rate_hz: float = Field(default=200.0, gt=0.0, le=2000.0)
    sheet_rate_hz: float = Field(default=100.0, gt=0.0, le=1000.0)
    membrane_grid: int = Field(default=16, ge=2, le=128)
    start_delay: float = Field(default=3.0, ge=0.0)
    loop: bool = False
    progress_period: float = Field(default=2.0, gt=0.0)


class WorldNode(Node):
    """Publishes ``/world/finger`` and ``/world/sheet``; subscribes the two arms' joint states."""

    Params = WorldParams
    node_type = "world"

    async def setup(self) -> None:
        p = self.params
        self.scripts = [FingerScript(mode=s.mode, moving_time=s.moving_time, push_depth=s.push_depth,
                                     end_angle=math.radians(s.end_angle_deg), tremor_rms=s.tremor_rms, seed=s.seed)
                        for s in p.script]
        self.total = sum(s.duration for s in self.scripts)
        self.finger_pub = self.publisher(T.FINGER_TRUTH)
        self.sheet_pub = self.publisher(T.SHEET_STATE)
        self.poses: dict[str, np.ndarray] = {}
        self.finger = self.scripts[0].position(0.0)
        self.subscribe(T.ARM_LEFT_STATE, self.on_arm, qos=QoS.LATEST)
        self.subscribe(T.ARM_RIGHT_STATE, self.on_arm, qos=QoS.LATEST)
        self.t0 = time.monotonic() + p.start_delay
        self.last_progress = 0.0
        self.timer(1.0 / p.rate_hz, self.tick_finger)
        self.timer(1.0 / p.sheet_rate_hz, self.tick_sheet)
        self.log.info("script: %s; %.1f s in all, starting in %.1f s",
                      ", ".join(f"{s.mode} {s.moving_time:g} s" for s in p.script), self.total, p.start_delay)

    def on_arm(self, msg: ArmJointState) -> None:
        self.poses[msg.arm] = msg.pose

    def _segment(self, t: float) -> tuple[int, float]:
        for i, s in enumerate(self.scripts):
            if t < s.duration:
                return i, t
            t -= s.duration
        return -1, t

    def tick_finger(self) -> None:
        t = time.monotonic() - self.t0
        if t < 0:
            i, ts = 0, 0.0
        else:
            if self.params.loop:
                t %= self.total
            i, ts = self._segment(t)
            if i < 0:
                self.log.info("script finished after %.1f s", t)
                self.shutdown()
                return
        script, seg = self.scripts[i], self.params.script[i]
        pos = script.position(ts)
        self.finger = pos
        self.finger_pub.publish(FingerTruth(
            header=self.finger_pub.header("display"), position=pos, velocity=script.velocity(ts),
            phase=f"{i}:{seg.mode}:{seg.moving_time:g}:{script.phase(ts)}",
            target_angle=float(script.target_angle(ts)), visible=True))
        now = time.monotonic()
        if now - self.last_progress >= self.params.progress_period and t >= 0:
            self.last_progress = now
            done = min(1.0, (sum(s.duration for s in self.scripts[:i]) + ts) / self.total)
            bar = "#" * int(done * 30)
            self.log.info("[%-30s] %3.0f%%  segment %d/%d %s %g s: %s, mark at %.1f deg", bar, done * 100, i + 1,
                          len(self.scripts), seg.mode, seg.moving_time, script.phase(ts),
                          math.degrees(float(script.target_angle(ts))))

    def tick_sheet(self) -> None:
        if "left" not in self.poses or "right" not in self.poses:
            return
        sheet = SheetSurface.from_clamps(self.poses["left"], self.poses["right"], pushed_point=self.finger,
                                         membrane_kwargs={"modes": 64})
        g = self.params.membrane_grid
        if sheet.membrane is not None:
            u = np.linspace(-sheet.half_span, sheet.half_span, g)
            v = np.linspace(-sheet.half_width, sheet.half_width, g)
            grid = sheet.membrane.deflection(*np.meshgrid(u, v, indexing="ij"))
            depth = float(sheet.membrane.depth)
        else:
            grid, depth = np.zeros((g, g)), 0.0
        stretch = max(0.0, 2.0 * sheet.half_span / 0.240 - 1.0)
        self.sheet_pub.publish(SheetState(
            header=self.sheet_pub.header("display"), origin=sheet.origin, normal=sheet.normal, axis_u=sheet.axis_u,
            corners=sheet.corners, pushed_point=sheet.pushed_point, depth=depth, stretch=stretch,
            membrane=np.ascontiguousarray(grid)))
