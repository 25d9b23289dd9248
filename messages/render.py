"""Renderer messages: the downscaled stereo frame the projector emitted (for recording)."""

from __future__ import annotations

from pydantic import Field

from messages.common import Message, ndarray

__all__ = ["RenderedFrame"]


class RenderedFrame(Message):
    """Downscaled copy of the projector's stereo output, for recording and latency accounting.

    ``left``, ``right``: uint8 (h, w, 3) RGB images in projector pixels (downscaled by ``scale``).
    ``correction``: "none", "flat", "four_triangle" or "fine". ``render_time``: time to correct and draw
    the pair, s. ``source_stamp``: exposure stamp of the fingertip that
    drove this frame, s.
    """

    SCHEMA = "flexsheet/RenderedFrame"
    VERSION = 1

    left: ndarray("uint8", (None, None, 3), "left-eye image, RGB")
    right: ndarray("uint8", (None, None, 3), "right-eye image, RGB")
    scale: float = Field(gt=0.0, le=1.0, description="downscale factor from projector resolution")
    correction: str = Field(description="correction model used; \"image\" while show_image replaces the scene")
    render_time: float = Field(ge=0.0, description="time to correct and draw the pair, s")
    source_stamp: float = Field(default=0.0, description="exposure stamp of the driving fingertip, s")
