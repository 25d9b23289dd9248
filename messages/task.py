"""Task messages: what the application shows the user to touch (the display's own content, not a measurement
of the finger)."""

from __future__ import annotations

from pydantic import Field

from messages.common import Message, ndarray

__all__ = ["TaskMark"]


class TaskMark(Message):
    """The target mark the application shows on the object: where it asks the user to touch (the start of a
    stroke, the mark moving along it). The planner pre-positions the sheet there while the finger is away
    (:mod:`flexsheet.planning.landing`); it never replaces the tracked fingertip.
    ``point`` (3,) m: the mark on the object's surface, display frame. ``normal`` (3,): the object's unit
    outward normal there, display frame. ``visible``: False while the application shows no mark (the planner
    then ignores the message). ``header.stamp``: when the mark was shown there, s.
    """

    SCHEMA = "flexsheet/TaskMark"
    VERSION = 1

    point: ndarray("float64", (3,), "the mark on the object's surface, m, display frame")
    normal: ndarray("float64", (3,), "unit outward normal of the object at the mark, display frame")
    visible: bool = Field(default=True, description="a mark is shown (False: none; the planner ignores it)")
