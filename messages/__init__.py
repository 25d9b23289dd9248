"""flexsheet's wire contract: one strict pydantic model per topic (see docs/messages.md)."""

from .arm import ArmJointState
from .common import DISPLAY_FRAME, Header, Message, check_finite, ndarray
from .diagnostics import Heartbeat, TopicStats
from .fem import ObjectDeformation
from .render import RenderedFrame
from .surface import ArmTarget, SheetTarget
from .topics import Topic
from .vision import Fingertip, StereoCalibration, StereoFrame
from .world import FingerTruth, SheetState

MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.SCHEMA: cls
    for cls in (StereoFrame, StereoCalibration, Fingertip, SheetTarget, ArmTarget, ArmJointState,
                ObjectDeformation, RenderedFrame, FingerTruth, SheetState, Heartbeat)
}

__all__ = ["ArmJointState", "ArmTarget", "DISPLAY_FRAME", "Fingertip", "FingerTruth", "Header", "Heartbeat",
           "MESSAGE_TYPES", "Message", "ObjectDeformation", "RenderedFrame", "SheetState", "SheetTarget",
           "StereoCalibration", "StereoFrame", "Topic", "TopicStats", "check_finite", "ndarray"]
