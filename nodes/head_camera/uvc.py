"""The head camera port's lab side (``source: device``): a UVC camera through OpenCV's ``cv2.VideoCapture``
(``device``: an index or a ``/dev/video*`` path), at ``rate_hz``. See
:mod:`flexsheet.vision.head_camera_port`."""

from __future__ import annotations

import cv2
import numpy as np

from flexsheet.model.timing import LAB
from flexsheet.vision.head_camera_port import HeadCameraSource

__all__ = ["UvcHeadCamera"]


def _device(name: str) -> int | str:
    return int(name) if name.isdigit() else name


class UvcHeadCamera(HeadCameraSource):
    """Frames of a UVC camera, grey; :meth:`grab` waits for the next one (a worker thread's call)."""

    blocking = True

    def __init__(self, cap, device: str):
        self.cap = cap
        self.device = device

    @classmethod
    def open(cls, params, board) -> UvcHeadCamera:
        """Opens ``params.device`` at ``params.rate_hz``. Raises ``ValueError`` naming the device."""
        cap = cv2.VideoCapture(_device(params.device))
        if not cap.isOpened():
            raise ValueError(f"device {params.device!r}: cannot open the head camera (cv2.VideoCapture)")
        cap.set(cv2.CAP_PROP_FPS, params.rate_hz)
        return cls(cap, params.device)

    @classmethod
    def probe(cls, params) -> list[str]:
        """Opens the device and reads one frame."""
        cap = cv2.VideoCapture(_device(params.device))
        try:
            if not cap.isOpened():
                return [f"head camera: cannot open UVC device {params.device!r} (cv2.VideoCapture)"]
            ok, _ = cap.read()
            return [] if ok else [f"head camera: UVC device {params.device!r} opened but gave no frame"]
        finally:
            cap.release()

    def frame_latency(self, exposure_s: float) -> float:
        """The lab camera's readout and transfer of a frame of the device's size."""
        w, h = int(self.cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self.cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        return LAB.camera_latency(exposure_s, max(w, 1), max(h // 2, 1))

    def grab(self, t_mid: float) -> np.ndarray:
        """The next frame, grey. Raises ``ValueError`` when the device gives none."""
        ok, frame = self.cap.read()
        if not ok:
            raise ValueError(f"device {self.device!r}: no frame")
        return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame

    def close(self) -> None:
        self.cap.release()
