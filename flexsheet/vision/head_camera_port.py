"""The head camera port: where the glasses tracker's frames come from.

A head camera node (``nodes/head_camera``) tracks the viewer's glasses in frames of the camera facing the
viewer. It does not know where the frames come from: a :class:`HeadCameraSource` gives them. Each source is an
entry point of the group :data:`SOURCES_GROUP` (``pyproject.toml``), named by the node's ``source`` param:

* ``sim``: the head camera's twin (:class:`flexsheet.twin.head_camera_source.TwinHeadCamera`), rendering the
  glasses at the world's true head;
* ``device``: a UVC camera through OpenCV (``nodes/head_camera/uvc.py``).

Frames are (H, W) uint8 grey images, raw (distorted), as the camera delivers them; times are the node's clock
(s), stamped at mid-exposure.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np

from flexsheet.runtime.plugins import plugin

__all__ = ["SOURCES_GROUP", "HeadCameraSource", "head_camera_source"]

#: the entry-point group of the head camera sources (name: a head camera node's ``source`` param)
SOURCES_GROUP = "flexsheet.head_camera_sources"


class HeadCameraSource(ABC):
    """One head camera: frames of the viewer for the glasses tracker.

    :meth:`open` makes one from the node's params; the node feeds it the messages of its :attr:`inputs` and
    calls :meth:`grab` once per frame period (in a worker thread when :attr:`blocking`)."""

    #: the topics the source reads from the graph (QoS latest), handed to :meth:`feed`
    inputs: ClassVar[tuple[Any, ...]] = ()
    #: True when :meth:`grab` waits on a device: the node calls it in a worker thread, off its loop
    blocking: ClassVar[bool] = False

    @classmethod
    @abstractmethod
    def open(cls, params: Any, board: Any) -> HeadCameraSource:
        """The source of a head camera node's ``params`` (its ``device``, ``rate_hz``, ``exposure_s``,
        ``twin``) for the glasses ``board`` (:class:`flexsheet.vision.glasses.GlassesBoard`). Raises
        ``ValueError`` naming the param and the fix when it cannot open."""

    @classmethod
    def probe(cls, params: Any) -> list[str]:
        """What stops the source of ``params`` on this machine, one line each (``flexsheet launch --check
        --probe``); none by default."""
        return []

    def feed(self, topic: Any, msg: Any) -> None:
        """Take the newest message ``msg`` of ``topic``, one of :attr:`inputs`; a source without inputs needs
        none."""
        return None

    @abstractmethod
    def frame_latency(self, exposure_s: float) -> float:
        """Modelled time (s) from a frame's mid-exposure until the node holds it (readout and transfer); a
        simulated clock charges it to each frame."""

    @abstractmethod
    def grab(self, t_mid: float) -> np.ndarray | None:
        """The next frame, (H, W) uint8, or None when there is none yet. ``t_mid``: its mid-exposure time (s,
        the node's clock) where the source makes the frame (a twin); a device delivers its own. Raises
        ``ValueError`` for a frame the device failed to give."""

    def close(self) -> None:
        """Release the device; nothing by default."""
        return None


def head_camera_source(name: str) -> type[HeadCameraSource]:
    """The :class:`HeadCameraSource` class installed as ``name`` in :data:`SOURCES_GROUP`. Raises
    ``LookupError`` naming the installed ones."""
    return plugin(SOURCES_GROUP, name, what="head camera source", base=HeadCameraSource)  # type: ignore[return-value]
