"""The calibration twin: what the real stereo camera would see while the lab runs the registration procedures,
rendered from the hidden truth (:class:`flexsheet.twin.truth.TwinTruth`) only.

Scenes (each returns raw, distorted mono8 stereo pairs, like the real camera):

* :meth:`CalibrationTwin.board_views` — a calibration board (chessboard or ChArUco, the layout of
  :func:`flexsheet.calibration.camera_pose.board_points`) on the sheet; the first view is the home pose,
  which *defines* the display frame (the board marks the imaginary screen), the others are where the true
  arms put the sheet when commanded to the requested poses through the nominal kinematics.
* :meth:`CalibrationTwin.pattern_frames` — the projector's patterns lit onto the (tilted) sheet through the
  true projector (its K, distortion and pose), seen through the translucent sheet by the true cameras.
* :meth:`CalibrationTwin.marker_frames` — the clamp markers (retro-reflective spheres, exact silhouette) of
  both arms at true joint-space poses (commanded joints plus the true zero offsets, true link lengths).

Image formation (per camera): each pixel is integrated over ``ss``×``ss`` sub-samples whose rays come from
the *true* intrinsics and distortion (inverted to 1e-12), intersected with the sheet plane (or the
marker spheres); a Gaussian optical blur; then signal-dependent sensor noise σ² = read² + gain·I (DN) and
8-bit quantisation. The blur, the read noise, the shot-noise gain and the board's black/white levels were
measured on the real XIMEA pairs (:func:`measure_ximea_noise`, numbers in :data:`XIMEA_NOISE` and
``docs/figures/calibration/ximea_noise.json``).

Honest twin: this module reads the truth and only the truth; it never returns truth numbers to a procedure —
only images (and the commanded inputs the lab would know: joint vectors, pattern indices).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from flexsheet.arm.kinematics import ArmKinematics, clamp_joints, home_joints
from flexsheet.calibration.camera_pose import board_centre
from flexsheet.model import geometry
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE
from flexsheet.model.sheet import clamp_poses
from flexsheet.twin.truth import TwinTruth
from flexsheet.vision.stereo_calibration import BoardSpec

__all__ = ["NoiseModel", "XIMEA_NOISE", "CalibrationTwin", "TrueCamera", "board_texture",
           "sheet_pose_from_clamps", "commanded_sheet_joints"]


@dataclass(frozen=True)
class NoiseModel:
    """Camera image model: ``read_dn`` read-noise σ (DN); ``shot_gain`` (DN per DN: σ² = read² + gain·I);
    ``blur_px`` Gaussian PSF σ (px); ``black_dn``/``white_dn`` the board's black and white under the lab's
    light (DN); ``corner_rms_px`` the per-view chessboard reprojection RMS of the real calibration (px, for
    reference: corner jitter plus model error)."""

    read_dn: float
    shot_gain: float
    blur_px: float
    black_dn: float
    white_dn: float
    corner_rms_px: float


#: measured on /work/shared/data/stereo_calib_xi (17 XIMEA pairs) by ``measure_ximea_noise`` — see
#: docs/figures/calibration/ximea_noise.json for the per-image numbers (medians over 34 images)
XIMEA_NOISE = NoiseModel(read_dn=2.54, shot_gain=0.312, blur_px=0.54, black_dn=35.6, white_dn=165.7,
                         corner_rms_px=0.127)


def sheet_pose_from_clamps(T_left: np.ndarray, T_right: np.ndarray) -> np.ndarray:
    """Sheet frame (4, 4) held by two clamp poses: origin midway, axis_u from the right clamp to the left one,
    normal = the clamps' mean normal made orthogonal to axis_u (columns (normal, axis_u, axis_v))."""
    o = 0.5 * (T_left[:3, 3] + T_right[:3, 3])
    u = T_left[:3, 3] - T_right[:3, 3]
    u /= np.linalg.norm(u)
    n = T_left[:3, 0] + T_right[:3, 0]
    n -= (n @ u) * u
    n /= np.linalg.norm(n)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([n, u, np.cross(n, u)])
    T[:3, 3] = o
    return T


def commanded_sheet_joints(T_sheet_cmd: np.ndarray, stretch: float = 0.0, cache: dict | None = None) -> dict:
    """The joints the lab commands to hold the sheet at ``T_sheet_cmd`` (4, 4, display frame): each clamp pose
    (:func:`flexsheet.model.sheet.clamp_poses`) solved with the *nominal* kinematics, seeded at the home
    joints. Returns ``{"left": (6,), "right": (6,)}`` rad; raises ``ValueError`` naming the arm that cannot
    reach it. ``cache``: a dict to keep the kinematics in between calls."""
    cache = {} if cache is None else cache
    for side, base in (("left", LEFT_BASE), ("right", RIGHT_BASE)):
        cache.setdefault(side, ArmKinematics(side, base))
    T_sheet_cmd = np.asarray(T_sheet_cmd, float)
    Tl, Tr = clamp_poses(T_sheet_cmd[:3, 3], T_sheet_cmd[:3, 0], T_sheet_cmd[:3, 1], stretch)
    return clamp_joints(cache, Tl, Tr)


@dataclass
class _PatternMaps:
    """:meth:`CalibrationTwin.pattern_maps`: sub-samples per pixel side and, per camera, the projector map."""

    ss: int
    maps: list


def board_texture(board: BoardSpec, px_per_m: float = 8000.0, margin_squares: float = 0.5):
    """Texture of a printed board on a white plate: (image float32 in [0, 1], px_per_m, origin) where board
    coordinate (bx, by) m maps to texture pixel ((bx − origin[0])·px_per_m, (by − origin[1])·px_per_m).

    Chessboard: (cols+1)×(rows+1) squares around the inner corners (corner (0, 0) at the board origin), the
    corner squares black. ChArUco: ``CharucoBoard.generateImage`` (board origin at its outer corner).
    ``margin_squares``: white plate margin around the pattern, in squares.
    """
    s = board.square
    if board.kind == "chessboard":
        x0, y0 = -s * (1 + margin_squares), -s * (1 + margin_squares)
        x1, y1 = (board.cols + margin_squares) * s, (board.rows + margin_squares) * s
        W, H = int(round((x1 - x0) * px_per_m)), int(round((y1 - y0) * px_per_m))
        bx = x0 + (np.arange(W) + 0.5) / px_per_m
        by = y0 + (np.arange(H) + 0.5) / px_per_m
        i = np.floor(bx / s).astype(int) + 1
        j = np.floor(by / s).astype(int) + 1
        inside_x = (bx >= -s) & (bx < board.cols * s)
        inside_y = (by >= -s) & (by < board.rows * s)
        black = ((j[:, None] + i[None, :]) % 2 == 0) & inside_y[:, None] & inside_x[None, :]
        return np.where(black, 0.0, 1.0).astype(np.float32), px_per_m, (x0, y0)
    cb = board.charuco_board()
    m = margin_squares * s
    W = int(round((board.cols * s + 2 * m) * px_per_m))
    H = int(round((board.rows * s + 2 * m) * px_per_m))
    img = cb.generateImage((W, H), marginSize=int(round(m * px_per_m)), borderBits=1)
    return (img.astype(np.float32) / 255.0), px_per_m, (-m, -m)


def _project(X: np.ndarray, R: np.ndarray, t: np.ndarray, K: np.ndarray, D: np.ndarray):
    """OpenCV's pinhole + 5-term distortion projection of points X (N, 3) with x_cam = R X + t, vectorised
    (``cv2.projectPoints`` computes Jacobians too and is slow for millions of points). Returns (u, v)."""
    Xc = X @ R.T + t
    x, y = Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2]
    k1, k2, p1, p2, k3 = (float(v) for v in np.asarray(D, float).ravel()[:5])
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]


def _undistort_normalized(xd: np.ndarray, yd: np.ndarray, D: np.ndarray, iters: int = 40):
    """Invert OpenCV's 5-term lens model on normalised coordinates (vectorised fixed-point iteration, the
    scheme of ``cv2.undistortPoints``, run until the update is < 1e-11)."""
    k1, k2, p1, p2, k3 = (float(v) for v in np.asarray(D, float).ravel()[:5])
    x, y = xd.copy(), yd.copy()
    for _ in range(iters):
        r2 = x * x + y * y
        rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        xn, yn = (xd - dx) / rad, (yd - dy) / rad
        err = max(float(np.abs(xn - x).max()), float(np.abs(yn - y).max()))
        x, y = xn, yn
        if err < 1e-11:
            break
    return x, y


class TrueCamera:
    """One true camera: K, D, size, pose in the display frame, cached sub-sample rays."""

    def __init__(self, K, D, size, T_display_cam):
        self.K = np.asarray(K, float)
        self.D = np.asarray(D, float).ravel()
        self.size = (int(size[0]), int(size[1]))
        self.T = np.asarray(T_display_cam, float)
        self._rays: dict[int, np.ndarray] = {}

    def rays(self, ss: int) -> np.ndarray:
        """(H·ss, W·ss, 3) float32 ray directions (z = 1) in the camera frame of every sub-sample."""
        if ss not in self._rays:
            w, h = self.size
            xs = (np.arange(w * ss, dtype=np.float64) + 0.5) / ss - 0.5
            ys = (np.arange(h * ss, dtype=np.float64) + 0.5) / ss - 0.5
            X, Y = np.meshgrid((xs - self.K[0, 2]) / self.K[0, 0], (ys - self.K[1, 2]) / self.K[1, 1])
            x, y = _undistort_normalized(X, Y, self.D)
            r = np.empty((h * ss, w * ss, 3), np.float32)
            r[..., 0] = x
            r[..., 1] = y
            r[..., 2] = 1.0
            self._rays[ss] = r
        return self._rays[ss]

    def plane_hit(self, T_display_plane: np.ndarray, ss: int):
        """Intersect every sub-sample ray with the plane through T[:3, 3] with normal T[:3, 0] (sheet
        convention). Returns (u, v, depth_ok): in-plane coordinates along T[:3, 1] and T[:3, 2] (m, float32)
        and the mask of rays that hit it in front of the camera."""
        R, C = self.T[:3, :3], self.T[:3, 3]
        n, o = T_display_plane[:3, 0], T_display_plane[:3, 3]
        a1, a2 = T_display_plane[:3, 1], T_display_plane[:3, 2]
        d = self.rays(ss)
        # everything in the camera frame: ray X = s·d, plane n_c·X = n_c·(o_c)
        n_c, o_c = R.T @ n, R.T @ (o - C)
        a1_c, a2_c = R.T @ a1, R.T @ a2
        den = d @ n_c.astype(np.float32)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.float32(n_c @ o_c) / den
        ok = s > 0.01
        X = d * s[..., None] - o_c.astype(np.float32)
        return X @ a1_c.astype(np.float32), X @ a2_c.astype(np.float32), ok, d * s[..., None]


class CalibrationTwin:
    """Renders the registration scenes of one truth (module doc).

    ``truth``: the hidden truth; ``noise``: :class:`NoiseModel` (default :data:`XIMEA_NOISE`);
    ``seed``: image-noise seed; ``ss``: sub-samples per pixel side for boards and markers (patterns use
    ``max(2, ss - 1)``); ``frames``: frames averaged per capture (each with its own noise, as the lab's
    capture averages them). Raises ``ValueError`` on ``ss < 1`` or ``frames < 1``.
    """

    ROOM_DN = 22.0          #: dark lab behind the sheet, DN
    SHEET_DN = 70.0         #: the bare translucent sheet under the room light, DN
    PATTERN_BLUR_PX = 0.6   #: projector optics + diffusion in the 1 mm sheet, σ in projector px (assumption)

    def __init__(self, truth: TwinTruth, noise: NoiseModel = XIMEA_NOISE, seed: int = 0, ss: int = 3,
                 frames: int = 1):
        if ss < 1 or frames < 1:
            raise ValueError(f"ss and frames must be >= 1, got {ss!r}, {frames!r}")
        self.frames = int(frames)
        self.truth = truth
        self.noise = noise
        self.ss = int(ss)
        self.rng = np.random.default_rng([int(truth.seed), int(seed), 77])
        c = truth.camera_calib
        T_dl = truth.T_display_camera
        T_lr = np.eye(4)
        T_lr[:3, :3] = np.asarray(c["R"]).T
        T_lr[:3, 3] = -np.asarray(c["R"]).T @ np.asarray(c["T"]).ravel()
        self.cams = (TrueCamera(c["K1"], c["D1"], c["image_size"], T_dl),
                     TrueCamera(c["K2"], c["D2"], c["image_size"], T_dl @ T_lr))
        self.size = tuple(c["image_size"])
        self._tex: dict = {}
        self._ik = {}

    # ----------------------------------------------------------------------------------------- image model
    def _finish(self, acc: np.ndarray, ss: int, frames: int | None = None) -> np.ndarray:
        """Sub-sample image (H·ss, W·ss) DN → pixel integration, optical blur, sensor noise, uint8."""
        return self.expose(self.clean(acc, ss), frames)

    def clean(self, acc: np.ndarray, ss: int) -> np.ndarray:
        """Sub-sample image (H·ss, W·ss) DN → the noise-free pixel image (H, W) float32 DN: pixel integration
        and optical blur."""
        h, w = acc.shape[0] // ss, acc.shape[1] // ss
        # INTER_AREA with an integer factor is the exact block mean
        img = cv2.resize(acc, (w, h), interpolation=cv2.INTER_AREA) if ss > 1 else acc
        if self.noise.blur_px > 0:
            img = cv2.GaussianBlur(img.astype(np.float32), (0, 0), self.noise.blur_px)
        return img

    def expose(self, img: np.ndarray, frames: int | None = None) -> np.ndarray:
        """A noise-free image from :meth:`clean` → what the camera delivers (uint8): sensor noise σ² = read² +
        gain·I and quantisation per frame, ``frames`` frames averaged (default: the twin's ``frames``)."""
        sig = np.sqrt(self.noise.read_dn ** 2 + self.noise.shot_gain * np.maximum(img, 0.0))
        n = self.frames if frames is None else int(frames)
        acc = np.zeros(img.shape, np.float32)
        for _ in range(n):          # each frame quantised on its own, then averaged (the lab's capture)
            acc += np.clip(np.rint(img + sig * self.rng.standard_normal(img.shape, dtype=np.float32)), 0, 255)
        return np.clip(np.rint(acc / n), 0, 255).astype(np.uint8)

    # ----------------------------------------------------------------------------------------- sheet poses
    def sheet_pose(self, T_sheet_cmd: np.ndarray, stretch: float = 0.0) -> np.ndarray:
        """Where the true arms put the sheet when the lab commands ``T_sheet_cmd`` (4, 4): the clamp poses are
        solved with the *nominal* kinematics (what the bridges would do), then the *true* arms move there."""
        qs = commanded_sheet_joints(T_sheet_cmd, stretch, self._ik)
        return self.true_sheet_pose(qs["left"], qs["right"])

    def true_sheet_pose(self, q_left, q_right) -> np.ndarray:
        """(4, 4) the sheet's true pose with the arms at joints ``q_left``, ``q_right`` (6,) rad."""
        return sheet_pose_from_clamps(self.truth.clamp_pose("left", q_left),
                                      self.truth.clamp_pose("right", q_right))

    # ----------------------------------------------------------------------------------------- board views
    def board_views(self, board: BoardSpec, sheet_poses: list[np.ndarray], board_offset: float = 0.0,
                    bow_mm: float = 0.0) -> list[tuple[np.ndarray, np.ndarray]]:
        """Stereo pairs of ``board`` on the sheet at each commanded pose (4, 4). The first pose is the home
        pose: the board is rendered exactly at the display frame (it defines it); the others are moved by
        the true arms (:meth:`sheet_pose`). ``board_offset`` m: printed surface in front of the sheet's mid
        plane (known to the procedure). ``bow_mm``: the board is not flat — a paraboloid bow toward the user
        of this sag (mm) at the sheet's corners (±120, ±120 mm); 0 = flat."""
        out = []
        for k, T_cmd in enumerate(sheet_poses):
            T = np.eye(4) if k == 0 else self.sheet_pose(np.asarray(T_cmd, float))
            pair = [self._finish(dn, self.ss) for dn in self.board_dn(board, T, board_offset, bow_mm)]
            out.append((pair[0], pair[1]))
        return out

    def board_dn(self, board: BoardSpec, T_sheet: np.ndarray, board_offset: float = 0.0,
                 bow_mm: float = 0.0) -> list[np.ndarray]:
        """Sub-sample DN images (one per camera, (H·ss, W·ss) float32) of ``board`` on the sheet at its true
        pose ``T_sheet`` (4, 4); arguments as :meth:`board_views`."""
        key = (board, round(self.ss))
        if key not in self._tex:
            self._tex[key] = board_texture(board)
        tex, ppm, (x0, y0) = self._tex[key]
        cx, cy = board_centre(board)
        half = 0.5 * geometry.SHEET_SIZE
        T = np.asarray(T_sheet, float).copy()
        T[:3, 3] += board_offset * T[:3, 0]
        out = []
        for cam in self.cams:
            u, v, ok, _ = cam.plane_hit(T, self.ss)
            if bow_mm:
                # bowed board: a point at in-plane radius r sits sag·(r/r_corner)² toward the user, so the
                # ray meets it earlier; to first order its in-plane coordinate shifts along the ray
                r2 = (u * u + v * v) / (half * half * 2)
                dz = np.float32(bow_mm * 1e-3) * r2
                n_c = cam.T[:3, :3].T @ T[:3, 0]
                d = cam.rays(self.ss)
                cosd = (d @ n_c.astype(np.float32)) / np.linalg.norm(d, axis=-1)
                tan_scale = dz / np.maximum(np.abs(cosd), 0.2)
                a1c = (cam.T[:3, :3].T @ T[:3, 1]).astype(np.float32)
                a2c = (cam.T[:3, :3].T @ T[:3, 2]).astype(np.float32)
                dn = d / np.linalg.norm(d, axis=-1, keepdims=True)
                u = u + tan_scale * (dn @ a1c) * np.sign(cosd)
                v = v + tan_scale * (dn @ a2c) * np.sign(cosd)
            bx, by = cx - u, cy - v
            mx = ((bx - x0) * ppm - 0.5).astype(np.float32)
            my = ((by - y0) * ppm - 0.5).astype(np.float32)
            val = cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
            on_plate = (mx >= 0) & (my >= 0) & (mx <= tex.shape[1] - 1) & (my <= tex.shape[0] - 1) & ok
            on_sheet = (np.abs(u) <= half) & (np.abs(v) <= half) & ok
            nz = self.noise
            out.append(np.where(on_plate, nz.black_dn + (nz.white_dn - nz.black_dn) * np.clip(val, 0, 1),
                                np.where(on_sheet, self.SHEET_DN, self.ROOM_DN)).astype(np.float32))
        return out

    # ----------------------------------------------------------------------------------------- patterns
    def pattern_frames(self, patterns: list[np.ndarray], T_sheet_cmd: np.ndarray, white_dn: float = 190.0,
                       ambient_dn: float = 12.0, home_exact: bool = False,
                       frames: int | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
        """Stereo pairs of each projector image in ``patterns`` (uint8 (h, w) at the projector's resolution)
        lit through the true projector onto the sheet held at the commanded pose ``T_sheet_cmd`` (4, 4).

        ``white_dn``: brightness of a full-white projector pixel on a sheet facing the projector (DN; a dark
        or thick sheet is lower — the decode fails below ~10 DN of contrast); ``ambient_dn``: room light on
        the sheet. The translucent sheet is a Lambertian diffuser: brightness ∝ cos(incidence).
        ``home_exact``: render the home pose at the display frame instead of through the true arms.
        ``frames``: frames averaged per pattern (default: the twin's ``frames``).
        """
        T = np.eye(4) if home_exact else self.sheet_pose(np.asarray(T_sheet_cmd, float))
        maps = self.pattern_maps(T, white_dn, ambient_dn)
        out = []
        for pat in patterns:
            pair = [self._finish(img, maps.ss, frames) for img in self.pattern_dn(maps, pat)]
            out.append((pair[0], pair[1]))
        return out

    def pattern_maps(self, T_sheet: np.ndarray, white_dn: float = 190.0,
                     ambient_dn: float = 12.0) -> _PatternMaps:
        """Where each camera sub-sample looks into the true projector with the sheet at its true pose
        ``T_sheet`` (4, 4), and how bright a white projector pixel is there (arguments as
        :meth:`pattern_frames`)."""
        t = self.truth
        T = np.asarray(T_sheet, float)
        ss = max(2, self.ss - 1)
        half = 0.5 * geometry.SHEET_SIZE
        Tp = t.T_display_projector
        tvec = -Tp[:3, :3].T @ Tp[:3, 3]
        maps = []
        for cam in self.cams:
            u, v, ok, Xc = cam.plane_hit(T, ss)
            on = ok & (np.abs(u) <= half) & (np.abs(v) <= half)
            full = np.full(on.shape, np.float32(self.ROOM_DN), np.float32)
            rows, cols = np.nonzero(on.any(axis=1))[0], np.nonzero(on.any(axis=0))[0]
            if len(rows) == 0:
                maps.append((None, None, None, None, full))
                continue
            # only the sheet's bounding box (whole pixels) is lit: compute the projector map there
            r0, r1 = rows[0] // ss * ss, (rows[-1] // ss + 1) * ss
            c0, c1 = cols[0] // ss * ss, (cols[-1] // ss + 1) * ss
            box = (slice(r0, r1), slice(c0, c1))
            onb = on[box]
            Xd = (Xc[box].reshape(-1, 3).astype(np.float64) @ cam.T[:3, :3].T) + cam.T[:3, 3]
            pu, pv = _project(Xd, Tp[:3, :3].T, tvec.ravel(), t.projector_K, t.projector_D)
            ray = Xd - Tp[:3, 3]
            cos_in = np.abs(ray @ T[:3, 0]) / np.linalg.norm(ray, axis=1)
            gain = (cos_in.reshape(onb.shape) * onb).astype(np.float32) * np.float32(white_dn)
            base = np.where(onb, np.float32(ambient_dn), np.float32(self.ROOM_DN)).astype(np.float32)
            maps.append((pu.reshape(onb.shape).astype(np.float32), pv.reshape(onb.shape).astype(np.float32),
                         gain, (base, box), full))
        return _PatternMaps(ss, maps)

    def pattern_dn(self, maps: _PatternMaps, pattern: np.ndarray | None) -> list[np.ndarray]:
        """Sub-sample DN images (one per camera) of projector image ``pattern`` (uint8 (h, w) at the
        projector's resolution; ``None``: the projector dark) through :meth:`pattern_maps`. Raises
        ``ValueError`` on another size."""
        pw, ph = self.truth.projector_size
        if pattern is None:
            pattern = np.zeros((ph, pw), np.uint8)
        if pattern.shape != (ph, pw):
            raise ValueError(f"pattern must be ({ph}, {pw}) (the projector's resolution), got "
                             f"{pattern.shape}")
        p = cv2.GaussianBlur(pattern.astype(np.float32) / 255.0, (0, 0), self.PATTERN_BLUR_PX)
        out = []
        for mx, my, gain, bb, full in maps.maps:
            img = full.copy()
            if mx is not None:
                base, box = bb
                val = cv2.remap(p, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
                img[box] = base + gain * val
            out.append(img)
        return out

    # ----------------------------------------------------------------------------------------- markers
    def marker_frames(self, side: str, joint_list: list[np.ndarray], other_q: np.ndarray | None = None,
                      marker_dn: float = 230.0) -> list[tuple[np.ndarray, np.ndarray]]:
        """Stereo pairs of the clamp markers while arm ``side`` goes through the commanded joints in
        ``joint_list`` (each (6,) rad) and the other arm rests at ``other_q`` (default: its home joints).
        Both arms' markers are in view (the detector must pick the right one)."""
        other = "right" if side == "left" else "left"
        oq = home_joints(other) if other_q is None else np.asarray(other_q, float)
        P_other = self.truth.clamp_marker_position(other, oq)
        out = []
        for q in joint_list:
            P = self.truth.clamp_marker_position(side, np.asarray(q, float))
            pair = [self._finish(dn, self.ss) for dn in self.marker_dn([P, P_other], marker_dn)]
            out.append((pair[0], pair[1]))
        return out

    def marker_dn(self, centres: list[np.ndarray], marker_dn: float = 230.0) -> list[np.ndarray]:
        """Sub-sample DN images (one per camera) of clamp markers (true diameter) at ``centres`` (each (3,) m,
        display frame) in the dark room."""
        r = 0.5 * self.truth.clamp_marker_diameter
        out = []
        for cam in self.cams:
            acc = self._room(cam).copy()
            for X in centres:
                self._draw_sphere(acc, cam, X, r, marker_dn)
            out.append(acc)
        return out

    def _room(self, cam: TrueCamera) -> np.ndarray:
        key = ("room", id(cam))
        if key not in self._tex:
            w, h = cam.size
            rng = np.random.default_rng(5)
            room = self.ROOM_DN + 6.0 * cv2.resize(rng.normal(0, 1, (6, 8)), (w * self.ss, h * self.ss),
                                                   interpolation=cv2.INTER_CUBIC)
            self._tex[key] = room.astype(np.float32)
        return self._tex[key]

    def _draw_sphere(self, acc: np.ndarray, cam: TrueCamera, X: np.ndarray, r: float, level: float) -> None:
        """Exact silhouette of a sphere (centre X display, radius r) on the sub-sample image ``acc``."""
        R, C = cam.T[:3, :3], cam.T[:3, 3]
        Xc = R.T @ (X - C)
        if Xc[2] <= 0.05:
            return
        uv = cv2.projectPoints(Xc.reshape(1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.D)[0].ravel()
        rad = cam.K[0, 0] * r / Xc[2] * 1.3 + 3
        ss = self.ss
        w, h = cam.size
        x0, x1 = int(max(0, math.floor(uv[0] - rad))), int(min(w, math.ceil(uv[0] + rad) + 1))
        y0, y1 = int(max(0, math.floor(uv[1] - rad))), int(min(h, math.ceil(uv[1] + rad) + 1))
        if x1 <= x0 or y1 <= y0:
            return
        d = cam.rays(ss)[y0 * ss:y1 * ss, x0 * ss:x1 * ss].astype(np.float64)
        dn = d / np.linalg.norm(d, axis=-1, keepdims=True)
        along = dn @ Xc
        dist2 = float(Xc @ Xc) - along * along
        inside = (dist2 <= r * r) & (along > 0)
        sub = acc[y0 * ss:y1 * ss, x0 * ss:x1 * ss]
        sub[inside] = level


