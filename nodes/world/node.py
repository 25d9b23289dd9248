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

from flexsheet.model import scene
from flexsheet.model.checks import check_pose
from flexsheet.model.finger import FingerScript
from flexsheet.model.sheet import TRUE_MODES, SheetSurface
from flexsheet.runtime.node import InputRejected, Node, QoS
from flexsheet.runtime.params import build, config_fields, params_model
from messages import ArmJointState, FingerTruth, SheetState
from messages import topics as T

__all__ = ["WorldNode", "WorldParams", "Segment"]


Segment = params_model(
    "Segment",
    """One scripted segment: the fields of — defined, defaulted and checked in —
    :class:`flexsheet.model.finger.FingerScript` (SI: ``mode`` stroke | push | stroke_push, ``moving_time`` s,
    ``push_depth`` m, ``end_angle`` rad, ``tremor_rms`` m, ``seed``, …); ``script()`` builds it.""",
    config_fields(FingerScript),
    check=lambda seg: build(FingerScript, seg),
    methods={"script": lambda self: build(FingerScript, self)},
    module=__name__,
)

#: the paper's stroking experiment at 10 s and 30 s moving time, then a combined stroke and push
DEFAULT_SCRIPT = [Segment(mode="stroke", moving_time=10.0), Segment(mode="stroke", moving_time=30.0, seed=1),
                  Segment(mode="stroke_push", moving_time=10.0, push_depth=0.010, seed=2)]


class WorldParams(BaseModel):
    """``script``: segments played in order; ``rate_hz`` of ``/world/finger``; ``sheet_rate_hz`` of
    ``/world/sheet``; ``membrane_grid`` G (G×G deflection samples); ``membrane_modes``: modes of the
    :class:`flexsheet.model.sheet.Membrane` sampled; ``sheet_size`` m: unstretched sheet side between the
    clamps (for the stretch); ``start_delay`` s before the script starts (lets the graph connect and the arms
    reach the first pose); ``loop``: repeat until Ctrl-C; ``progress_period`` s."""

    model_config = ConfigDict(extra="forbid")
    script: list[Segment] = Field(default_factory=lambda: list(DEFAULT_SCRIPT), min_length=1)
    rate_hz: float = Field(default=200.0, gt=0.0, le=2000.0)
    sheet_rate_hz: float = Field(default=100.0, gt=0.0, le=1000.0)
    membrane_grid: int = Field(default=16, ge=2, le=128)
    membrane_modes: int = Field(default=64, ge=1, le=TRUE_MODES)
    sheet_size: float = Field(default=scene.SHEET_SIZE, gt=0.0)
    start_delay: float = Field(default=3.0, ge=0.0)
    loop: bool = False
    progress_period: float = Field(default=2.0, gt=0.0)


class WorldNode(Node):
    """Publishes ``/world/finger`` and ``/world/sheet``; subscribes the two arms' joint states."""

    Params = WorldParams
    node_type = "world"

    async def setup(self) -> None:
        p = self.params
        self.scripts: list[FingerScript] = [s.script() for s in p.script]
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
        """Keep the arm's measured clamp pose (FK of its joints); a pose that is not a rigid transform is
        rejected (the last good one is kept)."""
        try:
            self.poses[msg.arm] = check_pose(f"{msg.arm} arm pose", msg.pose, tol=1e-3)
        except ValueError as exc:
            raise InputRejected(str(exc)) from None

    def _segment(self, t: float) -> tuple[int, float]:
        """(segment index, time in it) at script time ``t`` s; (-1, overshoot) after the last segment."""
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
        script = self.scripts[i]
        pos = script.position(ts)
        self.finger = pos
        self.finger_pub.publish(FingerTruth(
            header=self.finger_pub.header("display"), position=pos, velocity=script.velocity(ts), segment=i,
            mode=script.mode, moving_time=float(script.moving_time), phase=script.phase(ts),
            target_angle=float(script.target_angle(ts)), visible=True))
        now = time.monotonic()
        if now - self.last_progress >= self.params.progress_period and t >= 0:
            self.last_progress = now
            done = min(1.0, (sum(s.duration for s in self.scripts[:i]) + ts) / self.total)
            bar = "#" * int(done * 30)
            self.log.info("[%-30s] %3.0f%%  segment %d/%d %s %g s: %s, mark at %.1f deg", bar, done * 100, i + 1,
                          len(self.scripts), script.mode, script.moving_time, script.phase(ts),
                          math.degrees(float(script.target_angle(ts))))

    def tick_sheet(self) -> None:
        if "left" not in self.poses or "right" not in self.poses:
            return
        p: WorldParams = self.params
        try:
            sheet = SheetSurface.from_clamps(self.poses["left"], self.poses["right"], pushed_point=self.finger,
                                             membrane_kwargs={"modes": p.membrane_modes}, size=p.sheet_size)
        except ValueError as exc:      # e.g. the two measured clamps coincide: no sheet to publish
            self.log.warning("no sheet state: %s", exc)
            return
        g = p.membrane_grid
        if sheet.membrane is not None:
            grid, depth = sheet.membrane.grid(g), float(sheet.membrane.depth)
        else:
            grid, depth = np.zeros((g, g)), 0.0
        self.sheet_pub.publish(SheetState(
            header=self.sheet_pub.header("display"), origin=sheet.origin, normal=sheet.normal, axis_u=sheet.axis_u,
            corners=sheet.corners, pushed_point=sheet.pushed_point, depth=depth, stretch=sheet.stretch,
            membrane=np.ascontiguousarray(grid)))
