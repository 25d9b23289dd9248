"""World node: the physical twin of the user's finger and the sheet (simulation only), built from the hidden
truth (:class:`flexsheet.twin.truth.TwinTruth`, param ``twin: {realism, truth_seed}``).

* Finger: plays a list of :class:`flexsheet.twin.finger.FingerScript` segments one after the other (default:
  the paper's stroking experiment at 10 s and 30 s moving time, then a combined stroke and push) and publishes
  the true marker position on ``/world/finger`` at ``rate_hz`` (100 Hz; the camera twin renders it with the
  truth's velocity between samples, extrapolating at most 0.1 s; 100 Hz and a 50 Hz sheet leave the graph's
  other nodes their share of a loaded machine's cores). The finger follows the stroke path of the ``scene``
  (:mod:`flexsheet.model.scenes`; filled by the launcher from the launch file's top-level ``scene:``; none =
  the paper's cylinder): p − depth·n along the path, with each segment's profile over the path fraction
  (stroke, push at the path's start, stroke_push). Between two segments the finger lifts off and moves through
  free space to the next start (:func:`flexsheet.twin.finger.after`).
* Sheet: the true clamp poses are the *true* arms' forward kinematics of the measured joint states
  (``ArmJointState.position``; the truth's base poses, link lengths and joint zero offsets — never the
  bridge's model in ``ArmJointState.pose``), and the pushed sheet's shape is the nonlinear membrane FEM of
  :mod:`flexsheet.model.sheet_fem` with the truth's Young's modulus, thickness, pre-strain and grip slip and
  the gripped sheet's pre-stress (:mod:`flexsheet.twin.world`); published on ``/world/sheet`` (``membrane``:
  the deflection on a G×G grid) and the finger's contact on ``/world/contact`` (depth, force, incremental
  stiffness), stamped with the time its pose was true — the mean stamp of the two joint states it comes from —
  so a world tick that runs late does not show as the display's lag in Table I (the finger's shape of a push
  is the finger's at publication). The true sheet comes from the shipped table family
  (:class:`flexsheet.twin.truth_sheet.TruthSheet`: the drawn modulus and thickness scale its force, pre-strain
  and grip slip shift its strain), so a new truth seed builds no table and simulated time starts at once; a
  family with tables missing stops the node at setup with the command that ships them.
* Task: the target mark the script shows the user (its point on the path and outward normal, without the
  finger's lag, wander, depth and tremor: :meth:`flexsheet.twin.finger.FingerScript.surface_point`) on
  ``/task/mark`` at ``rate_hz``, as the application publishes what it displays; hidden while paused.
* Head: the viewer's true head (:mod:`flexsheet.twin.head`: a seeded slow sway about V, a scripted lean-in
  toward the sheet and occlusions of the glasses, param ``head``; ``head.still: true`` keeps the eye at V) on
  ``/world/head`` at ``rate_hz``, for the head camera's twin and the report.
* Start: the script clock starts ``start_delay`` s after every node named in ``start_after`` has sent a
  heartbeat on ``/diagnostics`` (a node's heartbeats begin when its setup is done: an FEM node loading and
  attaching a scene's path table took 13 s of a loaded 2-core start, and a stroke that began before it was
  half unserved), or after ``start_timeout`` s of waiting (logged as a warning naming the nodes missing), as
  an experimenter begins when the display is up.
* Progress: one line every ``progress_period`` s; when the script ends the node exits, which ends a launch
  in which it is ``required`` (then the launch's report runs, see :mod:`flexsheet.analysis.report`).
  ``loop: true`` repeats the script until Ctrl-C (interactive mode).
"""

from __future__ import annotations

import logging
import math

import numpy as np
from pydantic import Field, field_validator

from flexsheet.model.scene_parts import SceneError
from flexsheet.model.scenes import Scene, load_scene
from flexsheet.runtime.node import Node
from flexsheet.runtime.params import build, config_fields, params_model
from flexsheet.runtime.qos import QoS
from flexsheet.twin.finger import FingerScript, after
from flexsheet.twin.head import Viewer
from flexsheet.twin.truth import TwinTruth
from flexsheet.twin.world import TruePhysics
from flexsheet.twin.world_config import WorldConfig
from messages import ArmJointState, ContactTruth, FingerTruth, HeadTruth, Heartbeat, SheetState, TaskMark
from messages import topics as T

__all__ = ["WorldNode", "WorldParams", "Segment"]


Segment = params_model(
    "Segment",
    """One scripted segment: the fields of — defined, defaulted and checked in —
    :class:`flexsheet.twin.finger.FingerScript` (SI: ``mode`` stroke | push | stroke_push, ``moving_time`` s,
    ``push_depth`` m, ``end_angle`` rad, ``tremor_rms`` m, ``seed``, …) but its ``scene`` (the world's);
    ``script(scene=None)`` builds it on that scene (a :class:`flexsheet.model.scenes.Scene`; ``None``: the
    cylinder parameters ``center``, ``axis``, ``radius``, ``up``, ``start_angle``, ``end_angle``).""",
    config_fields(FingerScript, exclude=("scene",)),
    check=lambda seg: build(FingerScript, seg, scene=None),
    methods={"script": lambda self, scene=None: build(FingerScript, self, scene=scene)},
    module=__name__,
)


def load_world_scene(path: str | None) -> Scene | None:
    """The scene of the ``scene`` param (``None`` for none: the script's cylinder parameters). Raises
    ``ValueError`` naming the param, the file, the key and the value."""
    if not path:
        return None
    try:
        return load_scene(path)
    except SceneError as exc:
        raise ValueError(f"scene: {exc}") from None

#: the paper's stroking experiment at 10 s and 30 s moving time, then a combined stroke and push
#: m, display frame: where the finger waits while a tool pauses the script (0.30 m in front of the home sheet,
#: toward the viewer: away from the sheet's and the arms' registration poses)
AWAY = np.array([0.30, 0.0, 0.0])

DEFAULT_SCRIPT = [Segment(mode="stroke", moving_time=10.0), Segment(mode="stroke", moving_time=30.0, seed=1),
                  Segment(mode="stroke_push", moving_time=10.0, push_depth=0.010, seed=2)]


def _scene_file(cls, v: str | None) -> str | None:
    load_world_scene(v)
    return v


WorldParams = params_model(
    "WorldParams",
    """``script``: segments played in order; ``rate_hz`` of ``/world/finger``; ``sheet_rate_hz`` of
    ``/world/sheet``; ``membrane_grid`` G (G×G deflection samples of the true shape); ``twin``: the hidden
    truth (:class:`~flexsheet.model.truth_choice.TruthChoice`); ``sheet_size`` m: unstretched sheet side
    between the clamps (for the stretch); ``start_delay`` s before the script starts (lets the graph connect
    and the arms reach the first pose), counted from the heartbeat of the last node named in ``start_after``
    (node names of the launch file; empty: from the world's own start) or from ``start_timeout`` s of waiting
    for them; ``loop``: repeat until Ctrl-C; ``scene``: the scene file whose stroke path the finger follows
    (launch/scenes/*.yaml; none: the paper's cylinder by the segments' own parameters); ``progress_period`` s.
    ``script`` and ``scene`` are the node's own; every other param is a field of — defined,
    defaulted and range-checked in — :class:`flexsheet.twin.world_config.WorldConfig`.""",
    {"script": (list[Segment], Field(default_factory=lambda: list(DEFAULT_SCRIPT), min_length=1))},
    config_fields(WorldConfig),
    validators={"_scene_file": field_validator("scene")(_scene_file)},
    module=__name__,
    scene=(str | None, Field(default=None)),
)


class WorldNode(Node):
    """Publishes ``/world/finger``, ``/world/sheet``, ``/world/contact``, ``/world/head`` and ``/task/mark``;
    subscribes the two arms' joint states."""

    Params = WorldParams
    node_type = "world"

    async def setup(self) -> None:
        p = self.params
        self.scene = load_world_scene(p.scene)
        self.scripts: list[FingerScript] = [s.script(self.scene) for s in p.script]
        self.total = sum(s.duration for s in self.scripts)
        self.finger_pub = self.publisher(T.FINGER_TRUTH)
        self.sheet_pub = self.publisher(T.SHEET_STATE)
        self.contact_pub = self.publisher(T.CONTACT_TRUTH)
        self.head_pub = self.publisher(T.HEAD_TRUTH)
        self.mark_pub = self.publisher(T.TASK_MARK)
        self.truth = TwinTruth.draw(p.twin.truth_seed, p.twin.realism)
        self.head = p.head.motion(Viewer.draw(p.twin.truth_seed, p.twin.realism), p.twin.truth_seed)
        self.phys = TruePhysics(self.truth, size=p.sheet_size)    # FileNotFoundError: family not shipped
        self.phys.sheet.preload()
        self.poses: dict[str, np.ndarray] = {}
        self.pose_stamps: dict[str, float] = {}
        self.finger = self.scripts[0].position(0.0)
        self._warned_flat = False
        # the arms' measured joints, read at each sheet tick (sampled: the 140 Hz joint states are decoded and
        # put through the truth's FK per tick, not each)
        self._arm_states = {"left": self.sample(T.ARM_LEFT_STATE), "right": self.sample(T.ARM_RIGHT_STATE)}
        # on a simulated clock the graph's time starts only once every node is active: nothing to wait for
        self.waiting_for: set[str] = set() if self.clock.simulated else set(p.start_after)
        self.t_setup = self.monotonic()
        if self.waiting_for:
            self.subscribe(T.DIAGNOSTICS, self.on_heartbeat, qos=QoS.KEEP_ALL)
        self.t0: float | None = None
        self._arm_t0()
        self.last_progress = 0.0
        self.paused_at: float | None = None   # script time stands still from here while a tool pauses it
        self._no_sheet: tuple[str, int] | None = None  # (why, ticks) while no sheet can be made of the clamps
        self.timer(1.0 / p.rate_hz, self.tick_finger)
        self.timer(1.0 / p.sheet_rate_hz, self.tick_sheet)
        self.service("script/pause", self.srv_pause, "stop the script's time and take the finger away from "
                     "the display (out of the camera's view) until script/resume, e.g. for a registration",
                     commanding=True)
        self.service("script/resume", self.srv_resume, "the finger back where it was and the script on from "
                                                       "there",
                     commanding=True)
        self.log.info("twin: %s truth, seed %d (sheet E %.2f MPa, t %.3f mm, pre-strain %.4f, grip slip "
                      "%.3f)",
                      p.twin.realism, p.twin.truth_seed, self.truth.sheet_young * 1e-6,
                      self.truth.sheet_thickness * 1e3, self.truth.sheet_prestrain, self.truth.grip_slip)
        self.log.info("finger on %s",
                      self.scene.describe() + f", stroke {self.scene.stroke_length() * 1e3:.1f} mm"
                      if self.scene is not None else "the cylinder of the script's parameters")
        self.log.info("script: %s; %.1f s in all, starting in %.1f s%s",
                      ", ".join(f"{s.mode} {s.moving_time:g} s" for s in p.script), self.total, p.start_delay,
                      "" if self.t0 is not None else
                      f" (after {self._waiting_text()})")

    # ------------------------------------------------------------------------------------------ pause
    def srv_pause(self, args: dict) -> str:
        if self.paused_at is None:
            self.paused_at = self.monotonic()
            self.log.info("script paused by a tool: the finger is away until script/resume")
        return "paused"

    def srv_resume(self, args: dict) -> str:
        if self.paused_at is not None:
            if self.t0 is not None:
                self.t0 += self.monotonic() - self.paused_at
            self.log.info("script resumed after %.1f s", self.monotonic() - self.paused_at)
            self.paused_at = None
        return "running"

    # ------------------------------------------------------------------------------------------ start
    def _arm_t0(self) -> None:
        """Start the script clock unless it must wait for a node of ``start_after``."""
        if self.waiting_for and self.monotonic() - self.t_setup > self.params.start_timeout:
            self.log.warning("starting the script without a heartbeat from %s after %g s (start_timeout)",
                             ", ".join(sorted(self.waiting_for)), self.params.start_timeout)
            self.waiting_for = set()
        if self.t0 is None and not self.waiting_for:
            self.t0 = self.monotonic() + self.params.start_delay

    def _waiting_text(self) -> str:
        """What the script clock waits for, for the log."""
        return "a heartbeat from " + ", ".join(sorted(self.waiting_for)) if self.waiting_for else "nothing"

    def on_heartbeat(self, msg: Heartbeat) -> None:
        """A node of ``start_after`` is up (its heartbeats begin after its setup): stop waiting for it."""
        if msg.node in self.waiting_for:
            self.waiting_for.discard(msg.node)
            self.log.info("%s is up (%.1f s after the world)%s", msg.node, self.monotonic() - self.t_setup,
                          "" if self.waiting_for else f"; the script starts in {self.params.start_delay:.1f} "
                                                      "s")
            self._arm_t0()

    def _read_arms(self) -> None:
        """Keep each arm's *true* clamp pose: the truth's forward kinematics of its newest measured joints
        (the bridge's own FK in ``ArmJointState.pose`` is not used). Joints the truth's FK refuses are
        rejected (counted, naming the arm); the last good pose stays."""
        for side, sub in self._arm_states.items():
            sub.take(lambda msg, side=side: self._true_pose(side, msg))

    def _true_pose(self, side: str, msg: ArmJointState) -> None:
        try:
            self.poses[side] = self.phys.clamp_pose(side, msg.position)
        except ValueError as exc:
            raise ValueError(f"{side} arm joints: {exc}") from None
        self.pose_stamps[side] = float(msg.header.stamp)

    def _segment(self, t: float) -> tuple[int, float]:
        """(segment index, time in it) at script time ``t`` s; (-1, overshoot) after the last segment."""
        for i, s in enumerate(self.scripts):
            if t < s.duration:
                return i, t
            t -= s.duration
        return -1, t

    def tick_finger(self) -> None:
        if self.t0 is None:
            self._arm_t0()
        if self.t0 is None and self.monotonic() - self.last_progress >= self.params.progress_period:
            self.last_progress = self.monotonic()
            self.log.info("waiting for %s before the script starts (%.0f s)", self._waiting_text(),
                          self.monotonic() - self.t_setup)
        if self.paused_at is not None:
            self._publish_head(0.0 if self.t0 is None else max(self.paused_at - self.t0, 0.0))
            self._publish_away()
            return
        t = -1.0 if self.t0 is None else self.monotonic() - self.t0
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
        self._publish_head(max(t, 0.0))
        script = self.scripts[i]
        pos, vel = after(self.scripts[i - 1], script, ts) if i > 0 else script.state(ts)
        self.finger = pos
        self.finger_pub.publish(FingerTruth(
            header=self.finger_pub.header("display"), position=pos, velocity=vel, segment=i,
            mode=script.mode, moving_time=float(script.moving_time), phase=script.phase(ts),
            target_angle=float(script.target_angle(ts)), visible=True))
        mq, mn = script.surface_point(ts)
        self.mark_pub.publish(TaskMark(header=self.mark_pub.header("display"), point=mq[0], normal=mn[0]))
        now = self.monotonic()
        if now - self.last_progress >= self.params.progress_period and t >= 0:
            self.last_progress = now
            done = min(1.0, (sum(s.duration for s in self.scripts[:i]) + ts) / self.total)
            bar = "#" * int(done * 30)
            self.log.info("[%-30s] %3.0f%%  segment %d/%d %s %g s: %s, mark at %.1f deg (%.0f %% of the "
                          "path)", bar,
                          done * 100, i + 1, len(self.scripts), script.mode, script.moving_time,
                          script.phase(ts),
                          math.degrees(float(script.target_angle(ts))),
                          100.0 * float(script.target_fraction(ts)))

    def _publish_head(self, t: float) -> None:
        """The viewer's true head at script time ``t`` s on ``/world/head``."""
        hs = self.head.state(t)
        self.head_pub.publish(HeadTruth(
            header=self.head_pub.header("display"), position=hs.T_display_glasses[:3, 3].copy(),
            rotation=np.ascontiguousarray(hs.T_display_glasses[:3, :3]), left=hs.left, right=hs.right,
            eye=hs.eye,
            velocity=hs.velocity, visible=hs.visible))

    def _publish_away(self) -> None:
        """The finger while the script is paused: at :data:`AWAY` (display frame), still, hidden from the
        camera."""
        self.finger = AWAY.copy()
        self.finger_pub.publish(FingerTruth(header=self.finger_pub.header("display"), position=AWAY.copy(),
                                            velocity=np.zeros(3), phase="paused", visible=False))
        self.mark_pub.publish(TaskMark(header=self.mark_pub.header("display"), point=AWAY.copy(),
                                       normal=np.array([1.0, 0.0, 0.0]), visible=False))

    async def tick_sheet(self) -> None:
        self._read_arms()
        if "left" not in self.poses or "right" not in self.poses:
            return
        p: WorldParams = self.params
        try:
            sheet, stretch = self.phys.surface(self.poses["left"], self.poses["right"], self.finger)
        except ValueError as exc:      # e.g. the two true clamps coincide: no sheet to publish
            why = str(exc)
            if self._no_sheet is None or self._no_sheet[0] != why:   # said once per reason, not per tick
                self.log.log(logging.INFO if self.paused_at is not None else logging.WARNING,
                             "no sheet state: %s (said once until it changes)", why)
                self._no_sheet = (why, 0)
            self._no_sheet = (why, self._no_sheet[1] + 1)
            return
        if self._no_sheet is not None:
            self.log.info("sheet state again after %d ticks without one", self._no_sheet[1])
            self._no_sheet = None
        g = p.membrane_grid
        force = stiffness = 0.0
        if sheet.membrane is not None:
            grid, depth, pushed = sheet.membrane.grid(g), float(sheet.membrane.depth), sheet.pushed_point
            force, stiffness = float(sheet.membrane.force), float(sheet.membrane.stiffness)
        else:
            depth = max(0.0, -float((np.asarray(self.finger) - sheet.origin) @ sheet.normal))
            inside = abs(float((np.asarray(self.finger) - sheet.origin) @ sheet.axis_u)) < sheet.half_span
            if depth > 0.0 and inside and not self._warned_flat:
                self._warned_flat = True
                self.log.warning("sheet pushed %.1f mm within a fingertip of a clamp (outside the true "
                                 "sheet's contacts): publishing the depth with a flat membrane "
                                 "grid", depth * 1e3)
            depth = depth if inside else 0.0
            pushed = np.asarray(self.finger, float) if depth > 0.0 else sheet.origin
            grid = np.zeros((g, g))
        # stamped when its pose was true: the mean of the two joint measurements' stamps (they are one
        # controller cycle apart at most), not the publication's — a world tick late under load (a median
        # 50 ms, seconds in a stall) would read as the display's lag in Table I
        stamp = 0.5 * (self.pose_stamps["left"] + self.pose_stamps["right"])
        self.sheet_pub.publish(SheetState(
            header=self.sheet_pub.header("display", stamp=stamp), origin=sheet.origin, normal=sheet.normal,
            axis_u=sheet.axis_u,
            corners=sheet.corners, pushed_point=pushed, depth=depth, stretch=stretch,
            membrane=np.ascontiguousarray(grid)))
        self.contact_pub.publish(ContactTruth(
            header=self.contact_pub.header("display", stamp=stamp), touching=depth > 0.0, depth=depth,
            force=max(force, 0.0), point=np.asarray(pushed, float), stiffness=max(stiffness, 0.0)))

