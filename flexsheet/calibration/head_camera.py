"""Registering the head camera and measuring the viewer's eye in the glasses
(``flexsheet calibrate display``).

**Head camera** (intrinsics and pose in the display frame at once). The glasses' board
(:class:`flexsheet.vision.glasses.GlassesBoard`) rides on the chin-rest fixture that defines the paper's
viewpoint V: the fixture steps it over a grid of known positions (:func:`fixture_poses`: two depths, three
heights, five sideways positions, upright and facing the sheet). The board corners over all steps are one
non-planar rig of known display-frame points; one ``cv2.calibrateCamera`` view of that rig (seeded with the
design intrinsics) gives K, D and the camera's pose together (Zhang's model; with a non-planar rig the pose is
the rig's own frame, the display frame). The fixture's placement error goes into the result as noise: the
residual reports it.

**Eye in the glasses** (:func:`eye_entry`): with the viewer on the chin rest (the eye at V), one tracked pose
of the glasses gives the cyclopean eye's offset in the glasses frame
(:func:`flexsheet.calibration.eye.glasses_eye_offset`); the IPD is the pupillometer's reading.

Frames: ``display`` (:mod:`flexsheet.model.geometry`), the camera's OpenCV optical frame, the glasses frame of
:mod:`flexsheet.calibration.eye`. Units m, px.
"""

from __future__ import annotations

import cv2
import numpy as np

from flexsheet.calibration.display_calib import EyeEntry, HeadCameraEntry, Provenance
from flexsheet.calibration.eye import glasses_eye_offset, tracked_eye_entry
from flexsheet.model import geometry
from flexsheet.vision.camera_model import look_at
from flexsheet.vision.glasses import GLASSES_AXES, GlassesBoard

__all__ = ["SITTINGS", "design_head_camera", "fixture_poses", "register_head_camera", "eye_entry"]

#: the viewer's sittings on the chin rest for the eye offset
#: (each places the eye to ~1 mm; their mean to ~0.45 mm)
SITTINGS = 5


def design_head_camera() -> tuple[np.ndarray, np.ndarray, int, int]:
    """The head camera as designed: (K (3, 3) px, T_display_camera (4, 4), width, height).

    A 640 × 512 global-shutter sensor mounted in portrait (the image 512 wide × 640 tall: ±23° across, ±28° up
    and down), fx = fy = 600 px, principal point at the image centre, at (0, 0, 0.20) m in the display frame
    (above the sheet's top edge), its optical axis toward (0.25, 0, 0) m
    (:func:`flexsheet.vision.camera_model.look_at`, up = +z): the glasses stay in view from a viewer sitting
    back at 0.45 m to one leaning in to 0.11 m, sway included. The seed of its registration."""
    w, h = 512, 640
    K = np.array([[600.0, 0.0, (w - 1) / 2], [0.0, 600.0, (h - 1) / 2], [0.0, 0.0, 1.0]])
    return K, look_at((0.0, 0.0, 0.20), (0.25, 0.0, 0.0), up=(0.0, 0.0, 1.0)), w, h


def fixture_poses(V=geometry.EYE) -> list[np.ndarray]:
    """The chin-rest fixture's steps: T_display_glasses (4, 4) of the board's glasses frame at V + (dx, dy,
    dz) for dx ∈ {−0.05, 0.05}, dy ∈ {−0.08, −0.04, 0, 0.04, 0.08}, dz ∈ {−0.04, 0, 0.04} m (30 steps),
    upright and facing the sheet (:data:`~flexsheet.vision.glasses.GLASSES_AXES`)."""
    out = []
    for dx in (-0.05, 0.05):
        for dz in (-0.04, 0.0, 0.04):
            for dy in (-0.08, -0.04, 0.0, 0.04, 0.08):
                T = np.eye(4)
                T[:3, :3] = GLASSES_AXES
                T[:3, 3] = np.asarray(V, float) + (dx, dy, dz)
                out.append(T)
    return out


def register_head_camera(detections: list[tuple[np.ndarray, np.ndarray]], poses: list[np.ndarray],
                         board: GlassesBoard, K0: np.ndarray, size: tuple[int, int],
                         source: str = "lab") -> HeadCameraEntry:
    """The head camera's entry from the fixture's steps.

    ``detections``: per step (ids (M,) int, corners (M, 4, 2) px) as
    :meth:`flexsheet.vision.glasses.GlassesTracker.detect` gives them (steps with no markers are skipped);
    ``poses``: the steps' nominal T_display_glasses (4, 4) (:func:`fixture_poses`); ``K0`` (3, 3): the design
    intrinsics (the seed); ``size`` (width, height) px. Residuals: ``rms_px``. Raises ``ValueError`` with
    fewer than 40 corners over at least 6 steps, or on mismatched inputs."""
    if len(detections) != len(poses):
        raise ValueError(f"need one detection per fixture step, got {len(detections)} and {len(poses)}")
    obj_b = board.object_points_board().reshape(-1, 4, 3)
    T_gb = board.T_glasses_board
    X, x, steps = [], [], 0
    for (ids, corners), T in zip(detections, poses, strict=True):
        ids = np.asarray(ids, int)
        if len(ids) == 0:
            continue
        steps += 1
        P = obj_b[ids - board.first_id].reshape(-1, 3)
        Tdb = np.asarray(T, float) @ T_gb
        X.append(P @ Tdb[:3, :3].T + Tdb[:3, 3])
        x.append(np.asarray(corners, float).reshape(-1, 2))
    if steps < 6 or sum(len(a) for a in X) < 40:
        raise ValueError(f"the head camera saw the board in {steps} fixture steps ({sum(len(a) for a in X)} "
                         "corners): need >= 6 steps and >= 40 corners (is the camera facing the chin rest?)")
    Xa = np.concatenate(X).astype(np.float32)
    xa = np.concatenate(x).astype(np.float32)
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3 | cv2.CALIB_FIX_K2
             | cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_FIX_ASPECT_RATIO)
    rms, K, D, rvecs, tvecs = cv2.calibrateCamera([Xa], [xa], tuple(int(v) for v in size),
                                                  np.asarray(K0, float).copy(), np.zeros(5), flags=flags)
    T_cd = np.eye(4)
    T_cd[:3, :3] = cv2.Rodrigues(rvecs[0])[0]
    T_cd[:3, 3] = np.asarray(tvecs[0]).ravel()
    return HeadCameraEntry(K, np.asarray(D, float).ravel()[:5], int(size[0]), int(size[1]),
                           np.linalg.inv(T_cd),
                           Provenance("glasses board on the chin-rest fixture, one non-planar rig "
                                      "(cv2.calibrateCamera)", source=source, n_poses=steps,
                                      residuals={"rms_px": float(rms)}))


def eye_entry(T_display_glasses: list[np.ndarray], ipd: float, V=geometry.EYE,
              source: str = "lab") -> EyeEntry:
    """The tracked eye entry from the glasses' tracked poses (4, 4), one per sitting of the viewer on the chin
    rest (the eye at ``V`` (3,) m each time), and the pupillometer's ``ipd`` m: the mean of the sittings' eye
    offsets (each sitting places the eye anew, so its error averages down). Raises ``ValueError`` without a
    pose or on bad inputs."""
    poses = list(T_display_glasses)
    if not poses:
        raise ValueError("need at least one tracked glasses pose from the chin rest")
    offsets = np.array([glasses_eye_offset(T, V) for T in poses])
    entry = tracked_eye_entry(V, ipd, offsets.mean(axis=0), source)
    entry.provenance.n_poses = len(poses)
    entry.provenance.residuals["offset_spread_mm"] = (float(1e3 * offsets.std(axis=0).max()) if len(poses) > 1
                                                      else 0.0)
    return entry
