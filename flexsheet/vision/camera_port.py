"""The stereo camera port: where the camera node's pairs come from.

The camera node (``nodes/camera``) publishes stereo pairs and the latched calibration. It does not know where
the pairs come from: a :class:`CameraSource` gives them. Each source is an entry point of the group
:data:`SOURCES_GROUP` (``pyproject.toml``), named by the node's ``source`` param:

* ``sim``: the camera twin (:class:`flexsheet.twin.camera_source.TwinCamera`), rendering the fingertip marker
  at the world's true finger, and the registration scenes;
* ``genicam``, ``device``, ``files``: a GigE/USB3 Vision pair, UVC cameras, a folder of pairs
  (``nodes/camera/sources.py``).

A source drives itself on its host, the camera node (:class:`CameraHost`): it takes its timers, subscriptions
and services from the host's node API and hands each pair to :meth:`CameraHost.publish_pair`: (H, W) uint8
left and right images, the mid-exposure stamp (s, the node's clock) and the stereo skew (s, right − left).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, Protocol

import numpy as np

from flexsheet.runtime.plugins import plugin

__all__ = ["SOURCES_GROUP", "CameraHost", "CameraSource", "camera_source"]

#: the entry-point group of the stereo camera sources (name: the camera node's ``source`` param)
SOURCES_GROUP = "flexsheet.camera_sources"


class CameraHost(Protocol):
    """What a source needs of the camera node: its params, the runtime's node API (``now``, ``timer``,
    ``subscribe``, ``sample``, ``service``, ``clock``, ``log``) and :meth:`publish_pair`."""

    params: Any

    def publish_pair(self, left: np.ndarray, right: np.ndarray, stamp: float, skew: float = 0.0) -> None:
        """Publish one pair: (H, W) uint8 images, mid-exposure ``stamp`` s, ``skew`` s (right − left)."""


class CameraSource(ABC):
    """One stereo camera (module doc). :meth:`open` starts it on its host; :meth:`close` stops it."""

    #: whether the source models a link delay (the node's ``link_delay_s``); others refuse one
    models_link_delay: bool = False

    @classmethod
    @abstractmethod
    async def open(cls, host: CameraHost, calib: dict) -> CameraSource:
        """Start the camera of ``host.params`` for the stereo model ``calib`` (``image_size``, ``K1`` …): it
        takes its timers and inputs from ``host`` and publishes through it. Raises ``ValueError`` naming the
        param and the fix when it cannot start."""

    @classmethod
    def probe(cls, params: Any) -> list[str]:
        """What stops the camera of ``params`` on this machine, a line each (``flexsheet launch --check
        --probe``); none by default."""
        return []

    @classmethod
    def exact_nominal_registration(cls, params: Any) -> bool:
        """True when the nominal camera pose is this camera's exact pose (an ideal twin), so the node may run
        without ``display_calib``; False for a real camera."""
        return False

    @abstractmethod
    def status_line(self) -> str:
        """One line for ``/diagnostics``: what ``stereo_skew`` means for this source, with its counts."""

    def health(self, state: str) -> str:
        """The node's heartbeat state (``ok``/``warn``/``error``) given its base ``state``; the base state by
        default."""
        return state

    async def close(self) -> None:
        """Stop the camera; nothing by default."""
        return None


def camera_source(name: str) -> type[CameraSource]:
    """The :class:`CameraSource` class installed as ``name`` in :data:`SOURCES_GROUP`. Raises ``LookupError``
    naming the installed ones."""
    return plugin(SOURCES_GROUP, name, what="camera source", base=CameraSource)  # type: ignore[return-value]
