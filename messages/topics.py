"""Typed topic constants: the single list of topics the display uses, each bound to its message type.

Use them when making endpoints: ``node.publisher(topics.FINGERTIP)``,
``node.subscribe(topics.FINGERTIP, handler, qos=QoS.LATEST)``. Launch-file remaps rename topics per node.
"""

from __future__ import annotations

from dataclasses import dataclass

from messages.arm import ArmJointState
from messages.common import Message
from messages.diagnostics import Heartbeat
from messages.fem import ObjectDeformation, ObjectForceDepth
from messages.render import ProjectorImage, RenderedFrame
from messages.surface import ArmTarget, SheetTarget
from messages.task import TaskMark
from messages.vision import EyePose, Fingertip, StereoCalibration, StereoFrame
from messages.world import ContactTruth, FingerTruth, HeadTruth, SheetState


@dataclass(frozen=True)
class Topic:
    """A topic name bound to its message type. ``latched`` marks topics whose last value goes to late
    joiners."""

    name: str
    type: type[Message]
    latched: bool = False
    nominal_hz: float = 0.0

    def renamed(self, name: str) -> Topic:
        """The same topic type under another name (used by launch-file remaps)."""
        return Topic(name, self.type, self.latched, self.nominal_hz)


STEREO = Topic("/camera/stereo", StereoFrame, nominal_hz=48.0)
#: the same pairs decimated for viewers (the Foxglove bridge): every frame at most ``preview_rate`` Hz
STEREO_PREVIEW = Topic("/camera/stereo_preview", StereoFrame, nominal_hz=5.0)
CALIBRATION = Topic("/camera/calibration", StereoCalibration, latched=True)
FINGERTIP = Topic("/fingertip", Fingertip, nominal_hz=48.0)
#: the viewer's tracked eyes (the head camera node)
EYE_POSE = Topic("/eye/pose", EyePose, nominal_hz=60.0)
SHEET_TARGET = Topic("/sheet/target", SheetTarget, nominal_hz=48.0)
ARM_LEFT_TARGET = Topic("/arm/left/target", ArmTarget, nominal_hz=48.0)
ARM_RIGHT_TARGET = Topic("/arm/right/target", ArmTarget, nominal_hz=48.0)
ARM_LEFT_STATE = Topic("/arm/left/joint_state", ArmJointState, nominal_hz=140.0)
ARM_RIGHT_STATE = Topic("/arm/right/joint_state", ArmJointState, nominal_hz=140.0)
DEFORMATION = Topic("/object/deformation", ObjectDeformation, nominal_hz=48.0)
#: the object's force-depth along its stroke (what the finger is asked to feel), latched
FORCE_DEPTH = Topic("/object/force_depth", ObjectForceDepth, latched=True)
RENDERED = Topic("/render/stereo", RenderedFrame, nominal_hz=10.0)
#: what the projector shows instead of the scene (registration patterns), latched
PROJECTOR_IMAGE = Topic("/projector/image", ProjectorImage, latched=True)
FINGER_TRUTH = Topic("/world/finger", FingerTruth, nominal_hz=100.0)
SHEET_STATE = Topic("/world/sheet", SheetState, nominal_hz=50.0)
HEAD_TRUTH = Topic("/world/head", HeadTruth, nominal_hz=100.0)
CONTACT_TRUTH = Topic("/world/contact", ContactTruth, nominal_hz=50.0)
DIAGNOSTICS = Topic("/diagnostics", Heartbeat, nominal_hz=1.0)
#: the target mark the application shows (the world node in simulation); the planner pre-positions the sheet
#: there while the finger is away (an optional input: nothing publishes it in the lab yet)
TASK_MARK = Topic("/task/mark", TaskMark, nominal_hz=50.0)

ALL = [STEREO, STEREO_PREVIEW, CALIBRATION, FINGERTIP, SHEET_TARGET, ARM_LEFT_TARGET, ARM_RIGHT_TARGET,
       ARM_LEFT_STATE,
       ARM_RIGHT_STATE, DEFORMATION, RENDERED, PROJECTOR_IMAGE, FINGER_TRUTH, SHEET_STATE, DIAGNOSTICS,
       EYE_POSE,
       HEAD_TRUTH, CONTACT_TRUTH, FORCE_DEPTH, TASK_MARK]
BY_NAME = {t.name: t for t in ALL}


def arm_target(arm: str) -> Topic:
    """Arm-target topic for ``arm`` ("left" or "right"); raises ``ValueError`` otherwise."""
    return {"left": ARM_LEFT_TARGET, "right": ARM_RIGHT_TARGET}[_arm(arm)]


def arm_state(arm: str) -> Topic:
    """Joint-state topic for ``arm`` ("left" or "right"); raises ``ValueError`` otherwise."""
    return {"left": ARM_LEFT_STATE, "right": ARM_RIGHT_STATE}[_arm(arm)]


def _arm(arm: str) -> str:
    if arm not in ("left", "right"):
        raise ValueError(f"arm must be 'left' or 'right', got {arm!r}")
    return arm
