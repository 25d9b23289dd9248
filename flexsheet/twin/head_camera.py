"""The head camera's twin: renders what the camera beside the sheet sees of the viewer's glasses board
(:class:`flexsheet.vision.glasses.GlassesBoard`), for :class:`flexsheet.vision.glasses.GlassesTracker`.

Scene per image (8-bit mono, raw = distorted, like the real camera):

* a uniform grey background (``background`` DN);
* the printed board (black ``black`` DN, white ``white`` DN, one gap of white margin) warped into the image by
  the exact homography of the board plane, from a texture whose scale matches the image's (area-averaged
  edges, so edges fall where the geometry puts them). The board is drawn only while its printed face is toward
  the camera and in front of it;
* lens distortion (when ``dist`` is non-zero): the ideal image is remapped through the exact inverse of the
  OpenCV model (``cv2.undistortPoints`` of every raw pixel, computed once);
* motion blur: a line kernel along the board centre's image-plane streak over the exposure ``exposure_s``
  (box shutter; skipped under 0.3 px);
* optics: Gaussian point-spread function ``blur_px`` (σ, px);
* ``exposure_gain`` times the levels, then sensor noise: Gaussian ``noise_sigma`` DN (a pre-generated bank of
  standard normals, a seeded random crop per image), 8-bit rounding and clipping.

``occluded`` renders a black frame (lens covered; noise clipped at 0). Frames: ``display``
(:mod:`flexsheet.model.geometry`), ``glasses`` (:mod:`flexsheet.calibration.eye`), the camera's OpenCV optical
frame (+z forward, +x right, +y down). Units m, s, px.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from flexsheet.model.checks import check_pose, check_positive, check_vector
from flexsheet.vision.glasses import GlassesBoard, check_camera_matrix, check_dist

__all__ = ["HeadCameraTwin"]

_UNDISTORT_CRIT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12)


def _line_kernel(streak: np.ndarray) -> np.ndarray:
    """Normalised (n, n) float32 box-shutter kernel of the image streak (2,) px, centred, symmetric."""
    L = float(np.hypot(*streak))
    r = int(math.ceil(L / 2)) + 1
    n = 2 * r + 1
    k = np.zeros((n, n), np.float32)
    m = max(8, int(math.ceil(4 * L)))
    s = (np.arange(m) + 0.5) / m - 0.5
    pts = r + s[:, None] * streak[None, :]                  # (m, 2) x, y in the kernel
    x0, y0 = np.floor(pts[:, 0]).astype(int), np.floor(pts[:, 1]).astype(int)
    fx, fy = (pts[:, 0] - x0).astype(np.float32), (pts[:, 1] - y0).astype(np.float32)
    np.add.at(k, (y0, x0), (1 - fx) * (1 - fy))
    np.add.at(k, (y0, x0 + 1), fx * (1 - fy))
    np.add.at(k, (y0 + 1, x0), (1 - fx) * fy)
    np.add.at(k, (y0 + 1, x0 + 1), fx * fy)
    return k / k.sum()


class HeadCameraTwin:
    """Renders raw head-camera frames of the glasses board (module doc).

    ``camera_matrix`` (3, 3) px, ``dist`` (None or OpenCV coefficients, 4/5/8/12/14), ``T_display_camera``
    (4, 4): the camera that forms the images; ``width`` × ``height`` px; ``board``: the glasses' board;
    ``noise_sigma`` DN ≥ 0; ``blur_px`` PSF σ px ≥ 0; ``exposure_gain`` > 0 multiplies the levels;
    ``background``, ``black``, ``white``: scene levels DN in [0, 255]; ``seed``: the noise's seed.
    Raises ``ValueError`` naming the bad argument.
    """

    def __init__(self, camera_matrix, dist, T_display_camera, width: int = 640, height: int = 512,
                 board: GlassesBoard = GlassesBoard(), noise_sigma: float = 2.0, blur_px: float = 0.6,
                 exposure_gain: float = 1.0, seed: int = 0, background: float = 90.0, black: float = 25.0,
                 white: float = 210.0):
        self.K = check_camera_matrix(camera_matrix)
        self.D = check_dist(dist)
        self.T_display_camera = check_pose("T_display_camera", T_display_camera, tol=1e-6)
        for name, v in (("width", width), ("height", height)):
            if not isinstance(v, (int, np.integer)) or not 16 <= v <= 8192:
                raise ValueError(f"{name} must be an integer in [16, 8192] px, got {v!r}")
        self.size = (int(width), int(height))
        self.board = board
        if not isinstance(board, GlassesBoard):
            raise ValueError(f"board must be a GlassesBoard, got {board!r}")
        self.noise_sigma = check_positive("noise_sigma", noise_sigma, allow_zero=True)
        self.blur_px = check_positive("blur_px", blur_px, allow_zero=True)
        self.exposure_gain = check_positive("exposure_gain", exposure_gain)
        for name, v in (("background", background), ("black", black), ("white", white)):
            if not (isinstance(v, (int, float, np.floating)) and 0.0 <= v <= 255.0):
                raise ValueError(f"{name} must be a level in [0, 255] DN, got {v!r}")
        self.levels = (float(background), float(black), float(white))
        self.T_camera_display = np.linalg.inv(self.T_display_camera)
        self.rng = np.random.default_rng(seed)
        w, h = self.size
        self._pad = 64
        self._bank = (self.noise_sigma
                      * self.rng.standard_normal((h + self._pad, w + self._pad), dtype=np.float32))
        self._textures: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._maps = None
        if np.any(self.D != 0):
            grid = np.stack(np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)), -1)
            und = cv2.undistortPoints(grid.reshape(-1, 1, 2), self.K, self.D, P=self.K,
                                      criteria=_UNDISTORT_CRIT).reshape(h, w, 2).astype(np.float32)
            self._maps = (und[..., 0].copy(), und[..., 1].copy())

    def _texture(self, px_per_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Board texture (levels, float32) near ``px_per_m`` with its pixel → board-metre map; cached by the
        number of texture pixels per marker cell (1 … 16)."""
        cell = self.board.marker / self.board.cells
        n = int(min(16, max(1, round(px_per_m * cell))))
        if n not in self._textures:
            img, A = self.board.image(n / cell)
            _, lo, hi = self.levels
            self._textures[n] = ((lo + (hi - lo) / 255.0 * img.astype(np.float32)), A)
        return self._textures[n]

    def board_corners_camera(self, T_display_glasses) -> np.ndarray:
        """The board's marker corners (4·N, 3) m in the camera frame for glasses at ``T_display_glasses``
        (4, 4). Raises ``ValueError`` on a bad pose."""
        T = self.T_camera_display @ check_pose("T_display_glasses", T_display_glasses, tol=1e-6)
        return self.board.object_points_glasses() @ T[:3, :3].T + T[:3, 3]

    def _draw_board(self, T_cb: np.ndarray, velocity_c: np.ndarray, exposure_s: float):
        """The board drawn into the raw image's region that holds it: (region (h, w) float32 DN, distorted,
        not blurred; box (x0, y0, x1, y1) px; streak (2,) px over the exposure), or None when the board is
        behind the camera, turned away or outside the image."""
        w, h = self.size
        bw, bh = self.board.size
        g = self.board.gap
        s = np.linspace(0.0, 1.0, 5)[:, None]
        xs, ys = -g + (bw + 2 * g) * s, -g + (bh + 2 * g) * s
        outline = np.vstack([np.hstack([xs, np.full_like(xs, y), 0 * xs]) for y in (-g, bh + g)]
                            + [np.hstack([np.full_like(ys, x), ys, 0 * ys]) for x in (-g, bw + g)])
        outline = outline @ T_cb[:3, :3].T + T_cb[:3, 3]      # (20, 3) camera frame
        normal = -T_cb[:3, 2]                                  # printed face, camera frame
        centre = T_cb[:3, :3] @ np.array([bw / 2, bh / 2, 0.0]) + T_cb[:3, 3]
        if np.any(outline[:, 2] <= 0.01) or float(normal @ -centre) <= 0.0:
            return None
        tex, A = self._texture(self.K[0, 0] / float(centre[2]))
        H = self.K @ np.column_stack([T_cb[:3, 0], T_cb[:3, 1], T_cb[:3, 3]]) @ A
        uv = (outline @ self.K.T)[:, :2] / outline[:, 2:]
        if self._maps is not None:
            raw = cv2.projectPoints(outline, np.zeros(3), np.zeros(3), self.K, self.D)[0].reshape(-1, 2)
            uv = np.vstack([uv, raw])
        streak = np.zeros(2)
        if exposure_s > 0:
            p2 = centre + velocity_c * 1e-3
            d = (p2[:2] / p2[2] - centre[:2] / centre[2]) * (self.K[0, 0], self.K[1, 1]) * 1e3
            streak = d * exposure_s
        m = int(math.ceil(4 * self.blur_px + 0.5 * float(np.hypot(*streak)))) + 4
        x0, y0 = (int(max(0, math.floor(v) - m)) for v in uv.min(0))
        x1, y1 = (int(min(w, math.ceil(uv[:, 0].max()) + m + 1)),
                  int(min(h, math.ceil(uv[:, 1].max()) + m + 1)))
        if x1 <= x0 or y1 <= y0:
            return None
        bg = self.levels[0]
        roi = np.full((y1 - y0, x1 - x0), bg, np.float32)
        Hr = np.array([[1.0, 0, -x0], [0, 1.0, -y0], [0, 0, 1]]) @ H
        roi = cv2.warpPerspective(tex, Hr, (x1 - x0, y1 - y0), dst=roi, flags=cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_TRANSPARENT)
        if self._maps is not None:                            # raw pixel -> ideal pixel, within the region
            mx, my = self._maps
            roi = cv2.remap(roi, mx[y0:y1, x0:x1] - np.float32(x0), my[y0:y1, x0:x1] - np.float32(y0),
                            cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=bg)
        return roi, (x0, y0, x1, y1), streak

    def render(self, T_display_glasses, velocity=None, exposure_s: float = 0.004,
               occluded: bool = False) -> np.ndarray:
        """One raw frame (H, W) uint8 of the glasses at ``T_display_glasses`` (4, 4) (mid-exposure)
        translating at ``velocity`` (3,) m/s (display frame; None: at rest) over ``exposure_s`` s (the streak
        of the board's centre blurs the whole board); ``occluded``: a black frame. Raises ``ValueError`` on a
        bad pose, velocity or exposure."""
        T = check_pose("T_display_glasses", T_display_glasses, tol=1e-6)
        v = np.zeros(3) if velocity is None else check_vector("velocity", velocity)
        exposure_s = check_positive("exposure_s", exposure_s, allow_zero=True)
        w, h = self.size
        if occluded:
            return self._noise(np.zeros((h, w), np.uint8))
        T_cb = self.T_camera_display @ T @ self.board.T_glasses_board
        drawn = self._draw_board(T_cb, self.T_camera_display[:3, :3] @ v, exposure_s)
        img = np.full((h, w), int(np.clip(self.levels[0] * self.exposure_gain + 0.5, 0, 255)), np.uint8)
        if drawn is not None:
            roi, (x0, y0, x1, y1), streak = drawn
            if float(np.hypot(*streak)) >= 0.3:
                roi = cv2.filter2D(roi, -1, _line_kernel(streak), borderType=cv2.BORDER_REPLICATE)
            if self.blur_px > 0:
                roi = cv2.GaussianBlur(roi, (0, 0), self.blur_px, borderType=cv2.BORDER_REPLICATE)
            img[y0:y1, x0:x1] = cv2.convertScaleAbs(roi, alpha=self.exposure_gain)
        return self._noise(img)

    def _noise(self, img: np.ndarray) -> np.ndarray:
        if self.noise_sigma <= 0:
            return img
        h, w = img.shape
        oy, ox = (int(t) for t in self.rng.integers(0, self._pad, 2))
        return cv2.add(img, self._bank[oy:oy + h, ox:ox + w], dtype=cv2.CV_8U)
