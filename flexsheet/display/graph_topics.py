"""What the display's node types publish and cannot work without, and the values two of them must agree on:
the display's declarations for :class:`flexsheet.runtime.graph_builder.GraphBuilder` (handed on by its launch
extension, :mod:`flexsheet.display.launch`).

A required input is one without which the node does nothing useful: the triangulator's stereo pairs and
calibration, the planner's and the FEM's fingertip, an arm bridge's target. The rest (joint states, the eye
pose, the FEM's deformation, the task's mark, the world's truth) are optional: a node runs without them, as in
a replay of the planner alone or the lab without a head camera. ``tests/unit/runtime/test_graph_builder.py``
compares these with the publishers and subscriptions in the node types' code.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from flexsheet.runtime.graph_builder import NodeTopics, SharedValue
from messages import topics as T

__all__ = ["NODE_TOPICS", "SHARED_VALUES"]


def _names(*topics: T.Topic) -> frozenset[str]:
    return frozenset(t.name for t in topics)


def _arm(p: Mapping[str, Any]) -> str:
    return str(p.get("arm") or "left")


#: node type → params → its topics (names before remaps)
NODE_TOPICS: dict[str, Callable[[Mapping[str, Any]], NodeTopics]] = {
    "camera": lambda p: NodeTopics(_names(T.STEREO, T.STEREO_PREVIEW, T.CALIBRATION)),
    "triangulator": lambda p: NodeTopics(_names(T.FINGERTIP), _names(T.STEREO, T.CALIBRATION)),
    "planner": lambda p: NodeTopics(_names(T.SHEET_TARGET, T.ARM_LEFT_TARGET, T.ARM_RIGHT_TARGET),
                                    _names(T.FINGERTIP)),
    "arm_bridge": lambda p: NodeTopics(_names(T.arm_state(_arm(p))), _names(T.arm_target(_arm(p)))),
    "arm_controller_sim": lambda p: NodeTopics(),       # its bridge reaches it over Modbus TCP, not a topic
    "fem": lambda p: NodeTopics(_names(T.DEFORMATION, T.FORCE_DEPTH), _names(T.FINGERTIP)),
    "renderer": lambda p: NodeTopics(_names(T.RENDERED, T.PROJECTOR_IMAGE)),
    "world": lambda p: NodeTopics(_names(T.FINGER_TRUTH, T.SHEET_STATE, T.CONTACT_TRUTH, T.HEAD_TRUTH,
                                         T.TASK_MARK)),
    "head_camera": lambda p: NodeTopics(_names(T.EYE_POSE)),
    "viz": lambda p: NodeTopics(),                       # subscribes what a viewer opens
}

#: the values the planner copies from the arm bridges: it shapes the sheet's motion within the bridges' joint
#: speed and acceleration limits (flexsheet/planning/arm_command.py), so a copy that differs plans motions
#: the bridges cut short, or slows the sheet for nothing
SHARED_VALUES: tuple[SharedValue, ...] = (
    SharedValue("arm_bridge", "speed_scale", "planner", "arm_speed_scale",
                "the planner shapes the sheet's motion within the bridges' joint speed limits"),
    SharedValue("arm_bridge", "accel_scale", "planner", "arm_accel_scale",
                "the planner shapes the sheet's motion within the bridges' joint acceleration limits"),
)
