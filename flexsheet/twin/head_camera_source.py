"""The head camera port's simulated side (``source: sim``): the head camera's twin renders the viewer's
glasses at the world's true head (``/world/head``), through the hidden truth's camera
(``twin: {realism, truth_seed}``); the tracker beside it knows only the registered camera. See
:mod:`flexsheet.vision.head_camera_port`."""

from __future__ import annotations

import threading

import numpy as np

from flexsheet.model.timing import LAB
from flexsheet.twin.head_camera import HeadCameraTwin
from flexsheet.twin.head_rig import true_head_camera
from flexsheet.vision.head_camera_port import HeadCameraSource
from messages import HeadTruth, topics

__all__ = ["TwinHeadCamera"]


class TwinHeadCamera(HeadCameraSource):
    """Frames of the head camera's twin (module doc): each drawn at its mid-exposure time, the newest true
    head moved on by its velocity (by at most 0.1 s); an occluded head gives a dark frame."""

    inputs = (topics.HEAD_TRUTH,)

    def __init__(self, twin: HeadCameraTwin, exposure_s: float):
        self.twin = twin
        self.exposure_s = float(exposure_s)
        self._head: HeadTruth | None = None
        self._lock = threading.Lock()

    @classmethod
    def open(cls, params, board) -> TwinHeadCamera:
        """The twin of truth ``params.twin`` (``truth_seed``, ``realism``) drawing ``board``;
        ``params.exposure_s``."""
        K, D, T, w, h = true_head_camera(params.twin.truth_seed, params.twin.realism)
        return cls(HeadCameraTwin(K, D, T, w, h, board=board, seed=params.twin.truth_seed), params.exposure_s)

    def feed(self, topic, msg: HeadTruth) -> None:
        """Keep the newest true head."""
        with self._lock:
            self._head = msg

    def frame_latency(self, exposure_s: float) -> float:
        """The lab camera's readout and transfer of a frame of the twin's size
        (:data:`flexsheet.model.timing.LAB`)."""
        w, h = self.twin.size
        return LAB.camera_latency(exposure_s, w, h // 2)

    def grab(self, t_mid: float) -> np.ndarray | None:
        """The frame exposed around ``t_mid`` (s); None before the first true head."""
        with self._lock:
            head = self._head
        if head is None:
            return None
        dt = min(max(t_mid - head.header.stamp, 0.0), 0.1)
        T = np.eye(4)
        T[:3, :3] = head.rotation
        T[:3, 3] = head.position + head.velocity * dt
        return self.twin.render(T, head.velocity, self.exposure_s, occluded=not head.visible)
