"""Renderer messages: the downscaled stereo frame the projector emitted (for recording), and the image it
shows instead of the scene (registration)."""

from __future__ import annotations

from pydantic import Field

from messages.common import Message, ndarray

__all__ = ["RenderedFrame", "ProjectorImage"]


class RenderedFrame(Message):
    """Downscaled copy of the projector's stereo output, for recording and latency accounting.

    ``left``, ``right``: uint8 (h, w, 3) RGB images in projector pixels (downscaled by ``scale``).
    ``correction``: "none", "flat", "four_triangle" or "fine". ``render_time``: time to correct and draw
    the pair, s. ``source_stamp``: exposure stamp of the fingertip that
    drove this frame, s. ``eyes`` (2, 3) m: the left and right eye the pair was corrected for (display frame);
    ``eye_source``: where they came from: "tracked" (``/eye/pose``, predicted to photon time), "held" (the
    last good tracked pose while the glasses are lost) or "fixed" (the registered viewpoint V).
    """

    SCHEMA = "flexsheet/RenderedFrame"
    VERSION = 2

    left: ndarray("uint8", (None, None, 3), "left-eye image, RGB")
    right: ndarray("uint8", (None, None, 3), "right-eye image, RGB")
    scale: float = Field(gt=0.0, le=1.0, description="downscale factor from projector resolution")
    correction: str = Field(description="correction model used; \"image\" while show_image replaces the "
                                        "scene")
    render_time: float = Field(ge=0.0, description="time to correct and draw the pair, s")
    source_stamp: float = Field(default=0.0, description="exposure stamp of the driving fingertip, s")
    eyes: ndarray("float64", (2, 3), "left and right eye drawn for, m, display frame")
    eye_source: str = Field(default="fixed", pattern="^(tracked|held|fixed)$",
                            description="tracked | held | fixed: where the eyes drawn for came from")


class ProjectorImage(Message):
    """The image the projector shows in both eyes instead of the scene (the renderer's ``show_image`` service:
    registration patterns), latched; ``showing`` false once ``clear_image`` brought the scene back.

    ``image``: uint8 (h, w) luminance at the projector's resolution, px ((0, 0) when not showing).
    ``header.stamp``: when the renderer took it, s (the graph's clock); ``name``: the file it came from.
    """

    SCHEMA = "flexsheet/ProjectorImage"
    VERSION = 1

    image: ndarray("uint8", (None, None), "projector image, luminance, (h, w) px")
    showing: bool = Field(description="true while the image replaces the scene")
    name: str = Field(default="", description="file the image came from")
