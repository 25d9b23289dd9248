"""The twin's head camera as built, and the scenes of its registration (twin only; estimators never read it).

* :func:`true_head_camera`: the head camera of truth seed ``seed``: the design camera
  (:func:`flexsheet.calibration.head_camera.design_head_camera`) with its focal length off by ~1 %, its
  principal point by ~4 px, a small radial distortion, and its mount off by ~5 mm and ~1°, as a camera fixed
  by hand beside the sheet is.
* :class:`HeadRigTwin`: what the head camera sees during ``flexsheet calibrate display``: the glasses board on
  the chin-rest fixture at each step (each step placed to ~0.3 mm and ~0.2°, the fixture's tolerance), the
  viewer on the chin rest wearing the glasses (the eye at V to ~1 mm), and the pupillometer's IPD.
"""

from __future__ import annotations

import math

import numpy as np

from flexsheet.calibration.head_camera import design_head_camera
from flexsheet.model import geometry
from flexsheet.twin.head import Viewer, seeded_stream
from flexsheet.twin.head_camera import HeadCameraTwin
from flexsheet.vision.glasses import GLASSES_AXES, GlassesBoard

__all__ = ["true_head_camera", "HeadRigTwin"]


def _small_rotation(rng: np.random.Generator, sd_rad: float) -> np.ndarray:
    import cv2

    return cv2.Rodrigues(rng.normal(0.0, sd_rad, 3))[0]


def true_head_camera(seed: int, realism: str = "realistic") -> tuple[np.ndarray, np.ndarray, np.ndarray, int,
                                                                     int]:
    """(K (3, 3) px, D (5,), T_display_camera (4, 4), width, height) of the twin's head camera for truth
    ``seed``; ``realism`` "ideal": the design camera exactly. Raises ``ValueError`` on an unknown realism."""
    K, T, w, h = design_head_camera()
    if realism not in ("ideal", "realistic"):
        raise ValueError(f"realism must be 'ideal' or 'realistic', got {realism!r}")
    if realism == "ideal":
        return K, np.zeros(5), T, w, h
    rng = seeded_stream(seed, "head camera")
    K = K.copy()
    f = 1.0 + rng.normal(0.0, 0.01)
    K[0, 0] *= f
    K[1, 1] *= f * (1.0 + rng.normal(0.0, 0.001))
    K[:2, 2] += rng.normal(0.0, 4.0, 2)
    D = np.array([rng.normal(-0.08, 0.03), rng.normal(0.05, 0.03), 0.0, 0.0, 0.0])
    T = T.copy()
    T[:3, :3] = _small_rotation(rng, math.radians(1.0)) @ T[:3, :3]
    T[:3, 3] += rng.normal(0.0, 0.005, 3)
    return K, D, T, w, h


class HeadRigTwin:
    """Renders the head camera's registration scenes for truth ``seed`` (module doc)."""

    def __init__(self, seed: int, realism: str = "realistic", board: GlassesBoard | None = None) -> None:
        self.seed, self.realism = int(seed), realism
        K, D, T, w, h = true_head_camera(seed, realism)
        self.board = board or GlassesBoard()
        self.camera = HeadCameraTwin(K, D, T, w, h, board=self.board, seed=seed)
        self.viewer = Viewer.draw(seed, realism)
        self._rng = seeded_stream(seed, "chin-rest fixture")
        self.ideal = realism == "ideal"

    def _placed(self, T_nominal: np.ndarray, pos_sd: float, rot_sd: float) -> np.ndarray:
        T = np.asarray(T_nominal, float).copy()
        if not self.ideal:
            T[:3, :3] = _small_rotation(self._rng, rot_sd) @ T[:3, :3]
            T[:3, 3] += self._rng.normal(0.0, pos_sd, 3)
        return T

    def fixture_images(self, poses: list[np.ndarray]) -> list[np.ndarray]:
        """One head-camera image (H, W) uint8 per fixture step (nominal T_display_glasses (4, 4) each), the
        board where the fixture truly put it."""
        return [self.camera.render(self._placed(T, 3e-4, math.radians(0.2))) for T in poses]

    def chin_rest_image(self, V=geometry.EYE) -> np.ndarray:
        """The viewer on the chin rest (the true eye at ``V`` (3,) m to ~1 mm), glasses on: one image."""
        T = np.eye(4)
        T[:3, :3] = GLASSES_AXES
        eye = np.asarray(V, float) + (0.0 if self.ideal else self._rng.normal(0.0, 0.001, 3))
        T[:3, 3] = eye - GLASSES_AXES @ self.viewer.eye_offset
        return self.camera.render(T)

    def pupillometer_ipd(self) -> float:
        """The viewer's IPD as the lab's pupillometer reads it, m."""
        return self.viewer.ipd if self.ideal else self.viewer.measured_ipd(self.seed)
