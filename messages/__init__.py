"""flexsheet's wire contract: one strict pydantic model per topic (see docs/messages.md)."""

from messages.arm import ArmJointState
from messages.common import DISPLAY_FRAME, Header, Message, check_finite, ndarray
from messages.diagnostics import Heartbeat, TopicStats
from messages.fem import ObjectDeformation, ObjectForceDepth
from messages.render import ProjectorImage, RenderedFrame
from messages.surface import ArmTarget, SheetTarget
from messages.task import TaskMark
from messages.topics import Topic
from messages.vision import EyePose, Fingertip, StereoCalibration, StereoFrame
from messages.world import ContactTruth, FingerTruth, HeadTruth, SheetState

MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.SCHEMA: cls
    for cls in (StereoFrame, StereoCalibration, Fingertip, SheetTarget, ArmTarget, ArmJointState,
                ObjectDeformation, ObjectForceDepth, RenderedFrame, ProjectorImage, FingerTruth, SheetState,
                Heartbeat, EyePose, HeadTruth, ContactTruth, TaskMark)
}

__all__ = ["ArmJointState", "ArmTarget", "ContactTruth", "DISPLAY_FRAME", "EyePose", "Fingertip",
           "FingerTruth", "HeadTruth", "Header", "Heartbeat",
           "MESSAGE_TYPES", "Message", "ObjectDeformation", "ObjectForceDepth", "ProjectorImage",
           "RenderedFrame", "SheetState", "SheetTarget",
           "StereoCalibration", "StereoFrame", "TaskMark", "Topic", "TopicStats", "check_finite", "ndarray"]
