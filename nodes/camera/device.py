"""Real stereo camera via ``cv2.VideoCapture``: two devices, or one side-by-side stereo device.

Frames are converted to mono8 (``cv2.cvtColor(..., COLOR_BGR2GRAY)``). The exposure stamp is the host
time right after ``grab()`` minus half the exposure time (best available without hardware stamps); with two
devices both are grabbed back to back and then retrieved (OpenCV's recommended way to sync several
cameras), and the difference of the two grab times is reported as the stereo skew.
"""

from __future__ import annotations

import time

import cv2
import numpy as np

__all__ = ["DeviceSource", "split_side_by_side"]


def split_side_by_side(frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split a side-by-side stereo frame (H, 2W) or (H, 2W, 3) into mono8 (left, right), each (H, W).
    Raises ``ValueError`` if the width is odd or the array is not an image."""
    if not isinstance(frame, np.ndarray) or frame.ndim not in (2, 3) or frame.shape[1] % 2:
        raise ValueError(f"side-by-side frame must be (H, 2W[, 3]) with even width, got {getattr(frame, 'shape', None)}")
    if frame.ndim == 3:
        frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    w = frame.shape[1] // 2
    return np.ascontiguousarray(frame[:, :w]), np.ascontiguousarray(frame[:, w:])


def _mono(frame: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame


class DeviceSource:
    """Grab stereo pairs from ``left`` and ``right`` device ids/paths (``right`` None: ``left`` is a
    side-by-side stereo device). ``size`` (w, h) per image sets the capture size (0: leave as is);
    ``exposure_s`` is used only to centre the stamp. Raises ``ValueError`` if a device does not open."""

    def __init__(self, left, right=None, size: tuple[int, int] = (0, 0), exposure_s: float = 0.0):
        self.exposure_s = float(exposure_s)
        self.caps = []
        for dev, scale in ((left, 2 if right is None else 1), (right, 1)):
            if dev is None:
                continue
            cap = cv2.VideoCapture(dev)
            if not cap.isOpened():
                raise ValueError(f"cannot open video device {dev!r}")
            if size[0] > 0:
                cap.set(cv2.CAP_PROP_FRAME_WIDTH, size[0] * scale)
                cap.set(cv2.CAP_PROP_FRAME_HEIGHT, size[1])
            self.caps.append(cap)

    def read(self) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Grab one pair: (left, right) mono8 (H, W), exposure stamp s (host clock), skew s (right − left).
        Raises ``ValueError`` when a grab or retrieve fails (device unplugged, end of stream)."""
        stamps = []
        for cap in self.caps:
            if not cap.grab():
                raise ValueError("video device grab failed")
            stamps.append(time.time())
        frames = []
        for cap in self.caps:
            ok, f = cap.retrieve()
            if not ok:
                raise ValueError("video device retrieve failed")
            frames.append(f)
        if len(frames) == 1:
            left, right = split_side_by_side(frames[0])
            skew = 0.0
        else:
            left, right = _mono(frames[0]), _mono(frames[1])
            skew = stamps[1] - stamps[0]
        return left, right, stamps[0] - 0.5 * self.exposure_s, skew

    def close(self) -> None:
        """Release the devices."""
        for cap in self.caps:
            cap.release()
