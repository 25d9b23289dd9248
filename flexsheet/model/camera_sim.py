"""Stereo-camera twin: camera models (BumbleBee2 defaults, or a real calibration file) and a renderer of
the fingertip marker scene (pure; numpy + OpenCV drawing, no I/O besides reading the calibration YAML).

Scene per image (8-bit mono, raw = distorted, like the real camera):

* **Background clutter**: the sheet (a 0.24 m square in the plane x = 0 of the display frame) showing a
  projected image — a shaded cylinder with soft texture — warped into each camera with the exact
  plane-induced homography (computed once), on a dim, slightly textured room.
* **Finger**: a darker capsule (``finger_width`` × ``finger_length``) from the marker toward the hand
  (``finger_dir``, display frame), drawn at its projected width.
* **Marker**: a bright disk of ``marker_diameter`` (3–6 mm, default 4 mm) centred on the marker position,
  rendered with anti-aliased area coverage (so its centroid is exact to ~0.01 px without noise).
* **Motion blur**: the finger and marker are averaged over positions spread over the exposure
  ``exposure_s`` along the velocity (box shutter; ``blur_samples`` at least, and one per 0.5 px of streak),
  so the blurred centroid is the mid-exposure position.
* **Sensor noise**: additive Gaussian read noise ``noise_dn`` (DN), drawn from a pre-generated bank with a
  random crop per image (cheap enough for 48 Hz on a shared 2-core machine).

Camera models (:func:`camera_model`): ``"ximea"`` — the calibration that ``flexsheet calibrate stereo``
computes from the real XIMEA pairs (``flexsheet/model/ximea_calib.yaml``, 640×512, f ≈ 519 px,
|T| ≈ 92.6 mm); ``"bumblebee2"`` — Point Grey BumbleBee2 defaults from its datasheet: 640×480,
3.8 mm lens on 7.4 µm pixels (f ≈ 513.5 px), baseline 0.12 m, mild radial distortion; the 1024×768
variant is ``width=1024, height=768, pixel_um=4.65`` (f ≈ 817 px). ``"file"`` — any calibration YAML.

The mounting pose (:func:`look_at`) gives ``T_display_camera``, the left camera's optical frame
(+z forward, +x right, +y down) in the display frame.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import cv2
import numpy as np

from flexsheet.model.calibration import load_yaml
from flexsheet.model.checks import check_pose

__all__ = ["XIMEA_CALIB", "DEFAULT_CAMERA_POSITION", "DEFAULT_LOOK_AT", "bumblebee2_calibration", "camera_model",
           "look_at", "SimConfig", "StereoRenderer", "default_trajectory"]

XIMEA_CALIB = os.path.join(os.path.dirname(os.path.abspath(__file__)), "ximea_calib.yaml")
#: default mounting: above-right of the user's eye, 0.5 m from the sheet centre, looking at it (display frame, m)
DEFAULT_CAMERA_POSITION = (0.38, -0.25, 0.22)
DEFAULT_LOOK_AT = (0.0, 0.0, 0.0)


def bumblebee2_calibration(width: int = 640, height: int = 480, focal_mm: float = 3.8, pixel_um: float = 7.4,
                           baseline: float = 0.12, k1: float = -0.05, k2: float = 0.02) -> dict:
    """Ideal calibration dict of a BumbleBee2-like rectified-mount pair (Point Grey datasheet values).

    f = focal_mm / pixel_um · 1000 px, principal point at the image centre, same lens both sides, R = I,
    T = (−baseline, 0, 0) m. Returns the dict format of :func:`flexsheet.model.calibration.load_yaml`.
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


def default_trajectory(t: float, amplitude_rad: float = 1.05, period_s: float = 10.0,
                       hover_m: float = 0.005) -> tuple[np.ndarray, np.ndarray]:
    """Fallback marker trajectory when no world node runs: a stroke over the virtual cylinder, angle
    θ(t) = amplitude · sin(2π t / period) around its axis (0 = facing the user), ``hover_m`` above its
    surface. Returns (position (3,) m, velocity (3,) m/s), display frame (scene: cylinder axis along y
    through (−R, 0, 0))."""
    from flexsheet.model.scene import CYLINDER_CENTER, CYLINDER_RADIUS

    w = 2 * math.pi / period_s
    th = amplitude_rad * math.sin(w * t)
    dth = amplitude_rad * w * math.cos(w * t)
    r = CYLINDER_RADIUS + hover_m
    pos = CYLINDER_CENTER + r * np.array([math.cos(th), 0.0, math.sin(th)])
    vel = r * dth * np.array([-math.sin(th), 0.0, math.cos(th)])
    return pos, vel


@dataclass
class SimConfig:
    """Renderer settings (m, s, DN). ``finger_dir``: unit-ish vector from the fingertip toward the hand,
    display frame. ``clutter``: draw the projected sheet image (else a flat grey)."""

    marker_diameter: float = 0.004
    marker_level: float = 235.0
    finger_level: float = 70.0
    finger_width: float = 0.016
    finger_length: float = 0.07
    finger_dir: tuple[float, float, float] = (0.8, 0.0, 0.6)
    noise_dn: float = 2.0
    exposure_s: float = 0.004
    blur_samples: int = 5
    clutter: bool = True
    seed: int = 0

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first out-of-range field."""
        if not (0.001 <= self.marker_diameter <= 0.02):
            raise ValueError(f"marker_diameter must be in [0.001, 0.02] m, got {self.marker_diameter!r}")
        for name in ("marker_level", "finger_level"):
            if not (0 <= getattr(self, name) <= 255):
                raise ValueError(f"{name} must be in [0, 255] DN, got {getattr(self, name)!r}")
        if not (self.noise_dn >= 0 and self.exposure_s >= 0):
            raise ValueError(f"noise_dn and exposure_s must be >= 0, got {self.noise_dn!r}, {self.exposure_s!r}")
        if self.blur_samples < 1:
            raise ValueError(f"blur_samples must be >= 1, got {self.blur_samples!r}")
        if np.linalg.norm(self.finger_dir) < 1e-9:
            raise ValueError(f"finger_dir must be non-zero, got {self.finger_dir!r}")


def _sheet_texture(n: int, rng: np.random.Generator) -> np.ndarray:
    """Projected image on the sheet, (n, n) uint8: a shaded cylinder band with smooth blotches (no
    marker-sized bright specks: features are wider than ~1 cm on the sheet)."""
    u = np.linspace(-1, 1, n)
    U, V = np.meshgrid(u, u)
    cyl = np.clip(1 - (V / 0.6) ** 2, 0, 1) ** 0.5          # cylinder shading band (axis along sheet u)
    img = 60 + 110 * cyl
    noise = rng.normal(0, 1, (n // 16, n // 16))
    noise = cv2.resize(noise, (n, n), interpolation=cv2.INTER_CUBIC)
    img += 18 * noise
    img += 20 * (np.sin(U * 9.0) > 0.6)                      # a few wide stripes (projected pattern)
    img = cv2.GaussianBlur(img, (0, 0), n / 128)
    return np.clip(img, 0, 255).astype(np.uint8)


class StereoRenderer:
    """Renders raw stereo pairs of the marker scene (module doc).

    ``calib``: calibration dict (:func:`camera_model`); ``T_display_camera`` (4, 4): left camera pose in the
    display frame; ``cfg``: :class:`SimConfig`. Raises ``ValueError`` on a bad config or pose.
    """

    def __init__(self, calib: dict, T_display_camera: np.ndarray, cfg: SimConfig | None = None):
        from flexsheet.model.stereo import StereoModel

        self.cfg = cfg or SimConfig()
        self.cfg.validate()
        T = check_pose("T_display_camera", T_display_camera, tol=1e-3)
        self.model = StereoModel.from_calib(calib)
        self.T_dc = T
        self.R_cd = T[:3, :3].T                       # display -> left camera
        self.t_cd = -self.R_cd @ T[:3, 3]
        w, h = self.model.image_size
        self.size = (w, h)
        self.rng = np.random.default_rng(self.cfg.seed)
        self.backgrounds = [self._background(side) for side in ("left", "right")]
        pad = 64
        self._bank = np.empty((3, h + pad, w + pad), np.int16)
        for b in self._bank:
            cv2.randn(b, 0, float(self.cfg.noise_dn))
        self._pad = pad
        fd = np.asarray(self.cfg.finger_dir, float)
        self._fdir = fd / np.linalg.norm(fd)

    def to_camera(self, X_display: np.ndarray) -> np.ndarray:
        """Display-frame points (N, 3) m → left-camera-frame points (N, 3) m."""
        return np.asarray(X_display, float).reshape(-1, 3) @ self.R_cd.T + self.t_cd

    def _background(self, side: str) -> np.ndarray:
        from flexsheet.model.scene import SHEET_SIZE

        w, h = self.size
        room = 25 + 8 * cv2.resize(self.rng.normal(0, 1, (8, 8)), (w, h), interpolation=cv2.INTER_CUBIC)
        img = np.clip(room, 0, 255).astype(np.uint8)
        if not self.cfg.clutter:
            return np.full((h, w), 110, np.uint8)
        n = 512
        tex = _sheet_texture(n, self.rng)
        a = SHEET_SIZE / 2
        # sheet corners in display frame (plane x = 0): texture (col, row) = (0,0) at (y=+a, z=+a)
        corners_d = np.array([[0, a, a], [0, -a, a], [0, -a, -a], [0, a, -a]], float)
        Xc = self.to_camera(corners_d)
        if np.any(Xc[:, 2] <= 0.01):
            return img
        ul, ur = self.model.project(Xc, distort=False)
        dst = (ul if side == "left" else ur).astype(np.float32)
        src = np.array([[0, 0], [n - 1, 0], [n - 1, n - 1], [0, n - 1]], np.float32)
        H = cv2.getPerspectiveTransform(src, dst)
        warped = cv2.warpPerspective(tex, H, (w, h), flags=cv2.INTER_LINEAR)
        mask = cv2.warpPerspective(np.full((n, n), 255, np.uint8), H, (w, h), flags=cv2.INTER_NEAREST)
        img[mask > 0] = warped[mask > 0]
        # apply the lens distortion to the background (remap ideal -> raw)
        K, D = (self.model.K1, self.model.D1) if side == "left" else (self.model.K2, self.model.D2)
        grid = np.stack(np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32)), -1)
        und = cv2.undistortPoints(grid.reshape(-1, 1, 2), K, D, P=K).reshape(h, w, 2)
        return cv2.remap(img, und[..., 0], und[..., 1], cv2.INTER_LINEAR)

    def _project(self, Xc: np.ndarray, side: str) -> np.ndarray:
        ul, ur = self.model.project(Xc, distort=True)
        return ul if side == "left" else ur

    def render(self, position: np.ndarray, velocity: np.ndarray | None = None, visible: bool = True,
               extra_markers: tuple = (), occlusion: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Render one raw stereo pair (left, right), each uint8 (H, W).

        ``position`` (3,) m and ``velocity`` (3,) m/s of the marker at mid-exposure, display frame;
        ``visible`` False hides the marker (finger still drawn); ``extra_markers``: display-frame points
        (M, 3) m of further bright dots of the same size (e.g. a reflection); ``occlusion`` ∈ [0, 1]: the
        fraction of the marker disk hidden by a finger-coloured edge in the **left** image only (partial
        occlusion). Raises ``ValueError`` on non-finite position/velocity or occlusion outside [0, 1].
        """
        p = np.asarray(position, float).reshape(3)
        v = np.zeros(3) if velocity is None else np.asarray(velocity, float).reshape(3)
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(v))):
            raise ValueError(f"position/velocity must be finite, got {p!r}, {v!r}")
        if not (0.0 <= occlusion <= 1.0):
            raise ValueError(f"occlusion must be in [0, 1], got {occlusion!r}")
        c = self.cfg
        n = 1
        if c.exposure_s > 0 and np.linalg.norm(v) > 0:
            # at least one sample per 0.5 px of streak, so the streak is continuous, not a row of dots
            zc = max(float(self.to_camera(p)[0, 2]), 0.05)
            streak_px = self.model.focal * float(np.linalg.norm(v)) * c.exposure_s / zc
            n = min(max(c.blur_samples, int(np.ceil(2.0 * streak_px)) + 1), 200)
        offs = (np.linspace(-0.5, 0.5, n) if n > 1 else np.zeros(1))[:, None] * (v * c.exposure_s)[None, :]
        tips = p[None, :] + offs                                          # (n, 3) display
        bases = tips + c.finger_length * self._fdir
        extra = np.asarray(extra_markers, float).reshape(-1, 3)
        out = []
        for k, side in enumerate(("left", "right")):
            pts_c = self.to_camera(np.vstack([tips, bases, extra]))
            if np.any(pts_c[:, 2] <= 0.02):
                img = self.backgrounds[k].copy()
            else:
                uv = self._project(pts_c, side)
                img = self._draw(self.backgrounds[k], uv[:n], uv[n:2 * n], pts_c[:n, 2], uv[2 * n:],
                                 pts_c[2 * n:, 2], visible, occlusion if side == "left" else 0.0)
            out.append(self._noise(img))
        return out[0], out[1]

    def _draw(self, bg, tip_uv, base_uv, tip_z, extra_uv, extra_z, visible, occlusion):
        c = self.cfg
        f = self.model.focal
        h, w = bg.shape
        fw = max(1.0, f * c.finger_width / float(np.mean(tip_z)))
        rm = 0.5 * f * c.marker_diameter / float(np.mean(tip_z))
        allpts = np.vstack([tip_uv, base_uv, extra_uv]) if len(extra_uv) else np.vstack([tip_uv, base_uv])
        m = int(fw + rm + 4)
        x0 = int(max(0, np.floor(allpts[:, 0].min()) - m))
        y0 = int(max(0, np.floor(allpts[:, 1].min()) - m))
        x1 = int(min(w, np.ceil(allpts[:, 0].max()) + m + 1))
        y1 = int(min(h, np.ceil(allpts[:, 1].max()) + m + 1))
        img = bg.copy()
        if x1 <= x0 or y1 <= y0:
            return img
        crop = bg[y0:y1, x0:x1].astype(np.float32)
        acc = np.zeros_like(crop)
        yy, xx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
        sh = 4  # fixed-point shift for sub-pixel cv2 drawing
        for i in range(len(tip_uv)):
            layer = crop.copy()
            a = np.round((tip_uv[i] - (x0, y0)) * (1 << sh)).astype(np.int32)
            b = np.round((base_uv[i] - (x0, y0)) * (1 << sh)).astype(np.int32)
            cv2.line(layer, tuple(int(t) for t in a), tuple(int(t) for t in b), float(c.finger_level),
                     thickness=int(round(fw)), lineType=cv2.LINE_AA, shift=sh)
            cv2.circle(layer, tuple(int(t) for t in a), int(round(0.5 * fw * (1 << sh))), float(c.finger_level),
                       thickness=-1, lineType=cv2.LINE_AA, shift=sh)
            if visible:
                d = np.sqrt((xx - tip_uv[i, 0]) ** 2 + (yy - tip_uv[i, 1]) ** 2)
                cov = np.clip(rm + 0.5 - d, 0.0, 1.0)
                if occlusion > 0:
                    # hide the part of the disk beyond a chord: u > u_c, u_c from the covered fraction
                    u_c = tip_uv[i, 0] + rm * (1 - 2 * occlusion)
                    cov *= np.clip(u_c + 0.5 - xx, 0.0, 1.0)
                layer += cov * (c.marker_level - layer)
            acc += layer
        acc /= len(tip_uv)
        for j in range(len(extra_uv)):
            re = 0.5 * f * c.marker_diameter / float(extra_z[j])
            d = np.sqrt((xx - extra_uv[j, 0]) ** 2 + (yy - extra_uv[j, 1]) ** 2)
            cov = np.clip(re + 0.5 - d, 0.0, 1.0)
            acc += cov * (c.marker_level - acc)
        img[y0:y1, x0:x1] = np.clip(acc + 0.5, 0, 255).astype(np.uint8)
        return img

    def _noise(self, img: np.ndarray) -> np.ndarray:
        if self.cfg.noise_dn <= 0:
            return img
        h, w = img.shape
        b = self._bank[int(self.rng.integers(len(self._bank)))]
        oy, ox = (int(v) for v in self.rng.integers(0, self._pad, 2))
        return cv2.add(img, b[oy:oy + h, ox:ox + w], dtype=cv2.CV_8U)
