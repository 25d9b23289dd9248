"""The nominal stereo camera: its calibration (the shipped real XIMEA pair, a BumbleBee2-like ideal pair, or a
file) and its mounting in the display frame. Estimators start from it (``display.yaml``'s nominal camera
entry); the twin draws its truth around it."""

from __future__ import annotations

import math
import os

import cv2
import numpy as np

from flexsheet.vision.calib_yaml import load_yaml

__all__ = ["XIMEA_CALIB", "DEFAULT_CAMERA_POSITION", "DEFAULT_LOOK_AT", "bumblebee2_calibration",
           "camera_model",
           "look_at"]

#: the shipped calibration of the lab's real XIMEA stereo pair (OpenCV FileStorage YAML)
XIMEA_CALIB = os.path.join(os.path.dirname(os.path.abspath(__file__)), "ximea_calib.yaml")
#: default mounting: above-right of the user's eye, 0.5 m
#: from the sheet centre, looking at it (display frame, m)
DEFAULT_CAMERA_POSITION = (0.38, -0.25, 0.22)
DEFAULT_LOOK_AT = (0.0, 0.0, 0.0)

def bumblebee2_calibration(width: int = 640, height: int = 480, focal_mm: float = 3.8, pixel_um: float = 7.4,
                           baseline: float = 0.12, k1: float = -0.05, k2: float = 0.02) -> dict:
    """Ideal calibration dict of a BumbleBee2-like rectified-mount pair (Point Grey datasheet values).

    f = focal_mm / pixel_um · 1000 px, principal point at the image centre, same lens both sides, R = I,
    T = (−baseline, 0, 0) m. Returns the dict format of :func:`flexsheet.vision.calib_yaml.load_yaml`.
    Raises ``ValueError`` on non-positive sizes.
    """
    for name, v in (("width", width), ("height", height), ("focal_mm", focal_mm), ("pixel_um", pixel_um),
                    ("baseline", baseline)):
        if not (v > 0 and math.isfinite(v)):
            raise ValueError(f"{name} must be positive, got {v!r}")
    f = focal_mm / pixel_um * 1000.0
    K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])
    D = np.array([k1, k2, 0.0, 0.0, 0.0])
    R = np.eye(3)
    T = np.array([-baseline, 0.0, 0.0])
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(K, D, K, D, (width, height), R, T.reshape(3, 1), alpha=0)
    tx = np.array([[0, 0, 0], [0, 0, baseline], [0, -baseline, 0.0]])
    E = tx @ R
    F = np.linalg.inv(K).T @ E @ np.linalg.inv(K)
    return {"image_size": (width, height), "K1": K, "D1": D, "K2": K.copy(), "D2": D.copy(), "R": R, "T": T,
            "E": E, "F": F, "R1": R1, "R2": R2, "P1": P1, "P2": P2, "Q": Q, "rms_px": 0.0}


def camera_model(model: str = "ximea", calib_file: str = "", **bb2) -> dict:
    """Calibration dict of the twin: ``model`` "ximea" (shipped real calibration), "bumblebee2" (keyword
    overrides ``bb2`` go to :func:`bumblebee2_calibration`) or "file" (``calib_file``). Raises
    ``ValueError`` for an unknown model or unreadable file."""
    if model == "ximea":
        return load_yaml(XIMEA_CALIB)
    if model == "bumblebee2":
        return bumblebee2_calibration(**bb2)
    if model == "file":
        return load_yaml(calib_file)
    raise ValueError(f"model must be 'ximea', 'bumblebee2' or 'file', got {model!r}")


def look_at(position, target=DEFAULT_LOOK_AT, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Pose T_display_camera (4, 4) of an OpenCV optical frame at ``position`` (3,) m looking at ``target``
    (3,) m with image "up" as close to ``up`` as possible (+z forward, +x right, +y down).
    Raises ``ValueError`` if position == target or the view direction is parallel to ``up``."""
    p, t, u = (np.asarray(v, float) for v in (position, target, up))
    z = t - p
    if np.linalg.norm(z) < 1e-9:
        raise ValueError(f"position and target must differ, got {p} and {t}")
    z /= np.linalg.norm(z)
    x = np.cross(z, u)
    if np.linalg.norm(x) < 1e-6:
        raise ValueError(f"view direction {z} is parallel to up {u}")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = p
    return T
