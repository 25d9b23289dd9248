"""UVC stereo cameras via ``cv2.VideoCapture``: one side-by-side stereo device, or two separate devices.

Frames are converted to mono8 (``cv2.cvtColor(..., COLOR_BGR2GRAY)``). The exposure stamp is the host
time right after ``grab()`` minus half the exposure time (the best available without device stamps).

What the reported skew means (``skew_kind``; docs/camera.md):

* **one side-by-side device** (``right`` None): both halves arrive in one UVC frame from one device whose
  firmware exposes the two sensors together, so the skew is **0 by construction** (``"zero_by_construction"``)
  — not a measurement. (A rolling shutter still exposes rows at different times, equally in both halves.)
* **two devices**: the exposures are not synchronised and UVC gives no exposure time, so the skew is
  **unknown**. Both are grabbed back to back and then retrieved (OpenCV's way to sync several cameras),
  and the node reports an **upper bound** (``"upper_bound"``): |grab-to-grab interval| + one frame period.
  The grab interval alone is *not* a bound: ``grab()`` returns a frame whose exposure ended up to one
  frame period earlier, at any phase. The bound assumes no stale frame is queued in the driver
  (``CAP_PROP_BUFFERSIZE`` 1 is requested; the node grabs at least as fast as the cameras deliver).
  It is typically 30–40 ms at 30 fps: beyond the triangulator's ``max_stereo_skew_s`` (2 ms), which then
  rejects the pairs — raise that tolerance knowingly or use a synchronised pair (GenICam).
"""

from __future__ import annotations

import collections
import time

import cv2
import numpy as np

__all__ = ["DeviceSource", "split_side_by_side", "skew_upper_bound"]


def split_side_by_side(frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split a side-by-side stereo frame (H, 2W) or (H, 2W, 3) into mono8 (left, right), each (H, W).
    Raises ``ValueError`` if the width is odd or the array is not an image."""
    if not isinstance(frame, np.ndarray) or frame.ndim not in (2, 3) or frame.shape[1] % 2:
        raise ValueError("side-by-side frame must be (H, 2W[, 3]) with even width, got "
                         f"{getattr(frame, 'shape', None)}")
    if frame.ndim == 3:
        frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    w = frame.shape[1] // 2
    return np.ascontiguousarray(frame[:, :w]), np.ascontiguousarray(frame[:, w:])


def _mono(frame: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame


def skew_upper_bound(grab_interval_s: float, frame_period_s: float) -> float:
    """Upper bound of |exposure skew| (s) of two free-running devices grabbed ``grab_interval_s`` apart,
    each delivering every ``frame_period_s`` s (module doc). Raises ``ValueError`` for a non-positive or
    non-finite period."""
    if not (frame_period_s > 0 and np.isfinite(frame_period_s)):
        raise ValueError(f"frame_period_s must be a positive number, got {frame_period_s!r}")
    return abs(float(grab_interval_s)) + float(frame_period_s)


class DeviceSource:
    """Grab stereo pairs from ``left`` and ``right`` device ids/paths (``right`` None: ``left`` is a
    side-by-side stereo device). ``size`` (w, h) per image sets the capture size (0: leave as is);
    ``exposure_s`` is used only to centre the stamp; ``fallback_period_s``: frame period assumed until one
    is known (the node's ``1 / rate_hz``). ``skew_kind`` is ``"zero_by_construction"`` or ``"upper_bound"``
    (module doc). Raises ``ValueError`` if a device does not open."""

    def __init__(self, left, right=None, size: tuple[int, int] = (0, 0), exposure_s: float = 0.0,
                 fallback_period_s: float = 1.0 / 30.0):
        self.exposure_s = float(exposure_s)
        self.fallback_period_s = float(fallback_period_s)
        self.skew_kind = "zero_by_construction" if right is None else "upper_bound"
        self._grabs: collections.deque[float] = collections.deque(maxlen=31)  # left grab times, s
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
            cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # no stale frames queued (V4L2 honours it; others ignore)
            self.caps.append(cap)

    def frame_period(self) -> float:
        """Frame period for the bound, s: the larger (conservative) of 1 / ``CAP_PROP_FPS`` and the median
        interval of the last left grabs; ``fallback_period_s`` while neither is known."""
        cands = []
        fps = self.caps[0].get(cv2.CAP_PROP_FPS) if self.caps else 0.0
        if fps and fps > 0:
            cands.append(1.0 / fps)
        if len(self._grabs) >= 3:
            cands.append(float(np.median(np.diff(self._grabs))))
        return max(cands) if cands else self.fallback_period_s

    def read(self) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Grab one pair: (left, right) mono8 (H, W), exposure stamp s (host clock), skew s: 0 for a
        side-by-side device (by construction), the upper bound of |skew| for two devices (module doc).
        Raises ``ValueError`` when a grab or retrieve fails (device
        unplugged, end of stream)."""
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
        self._grabs.append(stamps[0])
        if len(frames) == 2:
            skew = skew_upper_bound(stamps[1] - stamps[0], self.frame_period())
        return left, right, stamps[0] - 0.5 * self.exposure_s, skew

    def close(self) -> None:
        """Release the devices."""
        for cap in self.caps:
            cap.release()
