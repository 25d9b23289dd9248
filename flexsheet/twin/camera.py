"""Stereo-camera twin: camera models (BumbleBee2 defaults, or a real calibration file) and a renderer of
the fingertip marker scene (pure; numpy + OpenCV, no I/O besides reading the calibration YAML).

The renderer forms the images of whatever camera it is given: in the twin that is the **true** camera of the
hidden truth (:func:`twin_renderer`: the truth's stereo intrinsics, distortion and mount), never the
calibration the estimators use. Scene per image (8-bit mono, raw = distorted, like the real camera):

* **Background clutter**: the sheet (a 0.24 m square in the plane x = 0 of the display frame) showing a
  projected image — a shaded cylinder with soft texture — warped into each camera with the exact
  plane-induced homography (computed once), on a dim, slightly textured room.
* **Finger**: a capsule of diameter ``finger_width`` and length ``finger_length`` along ``finger_dir``
  (display frame, from the fingertip toward the hand), at ``finger_level`` DN. Sheet, room and finger are
  diffuse and scaled by ``background_gain`` (the exposure is set for the bright marker).
* **Marker**: a retro-reflective sphere of ``marker_diameter`` (the truth's: 4 mm ± 3 %) at ``marker_level``
  DN, centred on the marker position. With ``self_occlusion`` it sits on the fingernail: the capsule's axis
  runs ``finger_width/2 + marker_diameter/2`` below the marker centre along the nail normal (the part of
  +z perpendicular to the finger) and its tip ``marker_setback`` ahead of it, and **both are ray-cast** per
  sub-sample (``marker_ss``² per pixel, through the camera's exact lens model) so the finger hides the part
  of the marker it covers from that camera — the hidden part depends on the finger's direction relative
  to each camera. Without it the marker is drawn over the finger (the old twin).
* **Motion blur**: finger and marker are averaged over positions spread over the exposure ``exposure_s``
  along the velocity (box shutter; ``blur_samples`` at least, and one per 0.5 px of streak; a streak
  under 0.1 px — the paper's stroke — is one position at mid-exposure).
* **Optics**: Gaussian point-spread function ``blur_px`` (σ, px) over the drawn region.
* **Sensor**: signal-dependent noise σ² = ``noise_dn``² + ``shot_gain``·I (DN², I the noise-free level;
  read noise plus shot noise), times ``noise_scale``, then 8-bit rounding and clipping. Standard normals
  come from a pre-generated bank with a random crop per image, scaled per pixel through a 256-entry
  σ(I) table (≈ 0.6 ms per 640×512 image).

Measured sensor numbers (:data:`XIMEA_SENSOR`): on the 17 real XIMEA pairs
(/work/shared/data/stereo_calib_xi), read noise 2.54 DN, shot gain 0.312 DN/DN and optical blur σ 0.54 px (the
registration's fit of a rendered board to each image, ``flexsheet.twin.sensor_noise.measure_ximea_noise``) —
confirmed independently by ``flexsheet experiment triangulation`` (flat-patch second differences:
``docs/figures/vision/sensor_noise.json``). The marker error therefore comes out of the image pipeline:
nothing adds noise to a centroid.

Camera models (:func:`camera_model`): ``"ximea"`` — the calibration that ``flexsheet calibrate stereo``
computes from the real XIMEA pairs (``flexsheet/vision/ximea_calib.yaml``, 640×512, f ≈ 519 px);
``"bumblebee2"`` — Point Grey BumbleBee2 defaults from its datasheet: 640×480, 3.8 mm lens on 7.4 µm
pixels (f ≈ 513.5 px), baseline 0.12 m, mild radial distortion; the 1024×768 variant is ``width=1024,
height=768, pixel_um=4.65`` (f ≈ 817 px). ``"file"`` — any calibration YAML.

The design mounting pose (:func:`look_at` of :data:`DEFAULT_CAMERA_POSITION`) is the nominal
``T_display_camera``, the left camera's optical frame (+z forward, +x right, +y down) in the display frame;
the twin's true mount is drawn around it (:mod:`flexsheet.twin.truth`), the estimators' comes from
``display.yaml``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np

from flexsheet.model.checks import check_pose
from flexsheet.model.geometry import CYLINDER_CENTER, CYLINDER_RADIUS, SHEET_SIZE
from flexsheet.twin.camera_config import SimConfig
from flexsheet.vision.stereo import StereoModel

__all__ = ["nail_normal", "StereoCameraTwin", "twin_renderer", "default_trajectory"]

_UNDISTORT_CRIT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12)


def nail_normal(finger_dir) -> np.ndarray:
    """Unit normal (3,) of the fingernail for a finger along ``finger_dir`` (fingertip → hand, display frame):
    the part of +z (palm down) perpendicular to the finger; +x when the finger is vertical. Raises
    ``ValueError`` on a zero or non-finite direction."""
    d = np.asarray(finger_dir, float).reshape(3)
    if not (np.all(np.isfinite(d)) and np.linalg.norm(d) > 1e-9):
        raise ValueError(f"finger_dir must be a finite non-zero (3,) vector, got {finger_dir!r}")
    d = d / np.linalg.norm(d)
    n = np.array([0.0, 0.0, 1.0]) - d[2] * d
    if np.linalg.norm(n) < 1e-6:
        n = np.array([1.0, 0.0, 0.0]) - d[0] * d
    return n / np.linalg.norm(n)


def default_trajectory(t: float, amplitude_rad: float = 1.05, period_s: float = 10.0,
                       hover_m: float = 0.005) -> tuple[np.ndarray, np.ndarray]:
    """Fallback marker trajectory when no world node runs: a stroke over the virtual cylinder, angle
    θ(t) = amplitude · sin(2π t / period) around its axis (0 = facing the user), ``hover_m`` above its
    surface. Returns (position (3,) m, velocity (3,) m/s), display frame (scene: cylinder axis along y
    through (−R, 0, 0))."""
    w = 2 * math.pi / period_s
    th = amplitude_rad * math.sin(w * t)
    dth = amplitude_rad * w * math.cos(w * t)
    r = CYLINDER_RADIUS + hover_m
    pos = CYLINDER_CENTER + r * np.array([math.cos(th), 0.0, math.sin(th)])
    vel = r * dth * np.array([-math.sin(th), 0.0, math.cos(th)])
    return pos, vel


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


def _dot(A: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(n, M) dot products of the rows of A (n, 3) with the rays d (M, 3), without BLAS (whose threads cost
    more than they save on arrays this small, and contend on a shared machine)."""
    return A[:, 0:1] * d[None, :, 0] + A[:, 1:2] * d[None, :, 1] + A[:, 2:3] * d[None, :, 2]


def _sphere_hit(d: np.ndarray, S: np.ndarray, r: float) -> np.ndarray:
    """Ray parameter of the first hit of rays X = t·d (d (M, 3) unit, from the origin) with the sphere
    (S (n, 3), r) → (n, M), +inf where missed or behind."""
    b = _dot(S, d)                                          # (n, M)
    c = np.einsum("ij,ij->i", S, S)[:, None] - r * r
    h = b * b - c
    with np.errstate(invalid="ignore"):
        t = b - np.sqrt(h)
    return np.where((h >= 0) & (t > 0), t, np.inf)


def _capsule_hit(d: np.ndarray, A: np.ndarray, B: np.ndarray, r: float) -> np.ndarray:
    """Ray parameter of the first hit of rays X = t·d (d (M, 3) unit) with the capsules of radius r around
    segments A→B (A, B (n, 3)) → (n, M), +inf where missed (Quilez's ray–capsule intersection)."""
    ba = B - A                                              # (n, 3)
    oa = -A
    baba = np.einsum("ij,ij->i", ba, ba)[:, None]
    bard = _dot(ba, d)                                      # (n, M)
    baoa = np.einsum("ij,ij->i", ba, oa)[:, None]
    rdoa = _dot(oa, d)
    oaoa = np.einsum("ij,ij->i", oa, oa)[:, None]
    a = baba - bard * bard
    b = baba * rdoa - baoa * bard
    c = baba * oaoa - baoa * baoa - r * r * baba
    h = b * b - a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (-b - np.sqrt(h)) / a
    y = baoa + t * bard
    body = (h >= 0) & (y > 0) & (y < baba) & (t > 0)
    # end caps: spheres at A (y <= 0) or B (y >= baba)
    tA = _sphere_hit(d, A, r)
    tB = _sphere_hit(d, B, r)
    return np.where(body, t, np.minimum(tA, tB))


class StereoCameraTwin:
    """Renders raw stereo pairs of the marker scene (module doc) through the camera it is given.

    ``calib``: calibration dict (:func:`camera_model`) of the cameras that form the images;
    ``T_display_camera`` (4, 4): their left camera's pose in the display frame; ``cfg``: :class:`SimConfig`.
    In the twin both are the truth's (:func:`twin_renderer`). Raises ``ValueError`` on a bad config or pose.
    """

    def __init__(self, calib: dict, T_display_camera: np.ndarray, cfg: SimConfig | None = None):
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
        self._bank = self.rng.standard_normal((3, h + pad, w + pad), dtype=np.float32)
        self._pad = pad
        c = self.cfg
        levels = np.arange(256, dtype=np.float64)
        self._sigma_lut = (c.noise_scale * np.sqrt(c.noise_dn ** 2 + c.shot_gain * levels)).astype(
            np.float32).reshape(1, 256)
        fd = np.asarray(c.finger_dir, float)
        self._fdir = fd / np.linalg.norm(fd)
        self._nail = nail_normal(self._fdir)
        self._corner_maps: dict[str, tuple[np.ndarray, np.ndarray]] = {}   # side → (corners, bands filled)

    # ------------------------------------------------------------------------------------------ geometry
    def to_camera(self, X_display: np.ndarray) -> np.ndarray:
        """Display-frame points (N, 3) m → left-camera-frame points (N, 3) m."""
        return np.asarray(X_display, float).reshape(-1, 3) @ self.R_cd.T + self.t_cd

    def _to_side(self, X_left: np.ndarray, side: str) -> np.ndarray:
        return X_left if side == "left" else X_left @ self.model.R.T + self.model.T

    def finger_axis(self, position: np.ndarray, marker_diameter: float | None = None) -> tuple[np.ndarray,
                                                                                               np.ndarray]:
        """Display-frame end points (A, B) (3,) m of the finger capsule's axis for a marker centred at
        ``position``: A the centre of the fingertip's cap, B toward the hand (module doc)."""
        c = self.cfg
        rm = 0.5 * (c.marker_diameter if marker_diameter is None else marker_diameter)
        p = np.asarray(position, float).reshape(3)
        if c.self_occlusion:
            A = p - (0.5 * c.finger_width + rm) * self._nail - c.marker_setback * self._fdir
        else:
            A = p
        return A, A + c.finger_length * self._fdir

    def _background(self, side: str) -> np.ndarray:
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
        img = cv2.remap(img, und[..., 0], und[..., 1], cv2.INTER_LINEAR)
        g = self.cfg.background_gain
        return img if g == 1.0 else np.clip(img.astype(np.float32) * g + 0.5, 0, 255).astype(np.uint8)

    def _project(self, Xc: np.ndarray, side: str) -> np.ndarray:
        ul, ur = self.model.project(Xc, distort=True)
        return ul if side == "left" else ur

    def _corner_rows(self, side: str, y0: int, y1: int) -> np.ndarray:
        """Normalised image coordinates (H + 1, W + 1, 2) of the pixel corners of camera ``side`` (row y,
        column x: the corner at (x − 0.5, y − 0.5) px), valid at least in corner rows [y0, y1]: the lens model
        inverted exactly (``cv2.undistortPoints``, 40 iterations to 1e-12, each point on its own). Filled in
        bands of 16 rows on first use and kept: the values a per-box inversion gives, each computed once."""
        K, D = (self.model.K1, self.model.D1) if side == "left" else (self.model.K2, self.model.D2)
        w, h = self.size
        if side not in self._corner_maps:
            self._corner_maps[side] = (np.empty((h + 1, w + 1, 2)), np.zeros((h + 16) // 16 + 1, bool))
        g, done = self._corner_maps[side]
        for b in range(y0 // 16, y1 // 16 + 1):
            if not done[b]:
                r0, r1 = 16 * b, min(16 * b + 16, h + 1)
                GX, GY = np.meshgrid(np.arange(w + 1, dtype=np.float64) - 0.5,
                                     np.arange(r0, r1, dtype=np.float64) - 0.5)
                pts = np.stack([GX.ravel(), GY.ravel()], -1).reshape(-1, 1, 2)
                g[r0:r1] = cv2.undistortPoints(pts, K, D, criteria=_UNDISTORT_CRIT).reshape(r1 - r0, w + 1, 2)
                done[b] = True
        return g

    def _rays(self, side: str, x0: int, y0: int, x1: int, y1: int, ss: int) -> np.ndarray:
        """Unit ray directions (M, 3), camera ``side``'s frame, of the ``ss``² sub-samples of every pixel in
        [x0, x1) × [y0, y1) (sub-sample grid row-major). The lens model is inverted exactly at the pixel
        corners (:meth:`_corner_rows`) and interpolated bilinearly inside each pixel (the interpolation error
        of the smooth lens map over 1 px is < 1e-4 px)."""
        g = self._corner_rows(side, y0, y1)[y0:y1 + 1, x0:x1 + 1]
        nx, ny = x1 - x0 + 1, y1 - y0 + 1
        s = (np.arange(x0 * ss, x1 * ss) + 0.5) / ss - x0          # sub-sample offsets from the first corner
        t = (np.arange(y0 * ss, y1 * ss) + 0.5) / ss - y0
        i, fx = np.minimum(np.floor(s).astype(int), nx - 2), s - np.minimum(np.floor(s), nx - 2)
        j, fy = np.minimum(np.floor(t).astype(int), ny - 2), t - np.minimum(np.floor(t), ny - 2)
        fx, fy = fx[None, :, None], fy[:, None, None]
        n = ((1 - fy) * ((1 - fx) * g[j][:, i] + fx * g[j][:, i + 1])
             + fy * ((1 - fx) * g[j + 1][:, i] + fx * g[j + 1][:, i + 1])).reshape(-1, 2)
        d = np.hstack([n, np.ones((len(n), 1))])
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def _box_coverage(self, side: str, box: tuple[int, int, int, int], S: np.ndarray, rm: float,
                      A: np.ndarray | None, B: np.ndarray | None, rf: float) -> tuple[np.ndarray, np.ndarray]:
        """Per-pixel coverage (h, w) of the visible marker and of the finger inside ``box`` (x0, y0, x1, y1),
        averaged over the exposure samples: S (n, 3) marker centres, A, B (n, 3) capsule axes (None: no
        finger in the ray-cast), all in camera ``side``'s frame. Memory stays bounded: a box over 2.5e5
        sub-samples gets fewer per pixel (a marker that near is many pixels wide) and the samples are
        ray-cast in chunks."""
        x0, y0, x1, y1 = box
        h, w = y1 - y0, x1 - x0
        ss = int(min(self.cfg.marker_ss, max(1, math.floor(math.sqrt(2.5e5 / (h * w))))))
        d = self._rays(side, x0, y0, x1, y1, ss)
        mk = np.zeros(len(d))
        fg = np.zeros(len(d))
        step = max(1, int(2e6 // len(d)))
        for k in range(0, len(S), step):
            ts = _sphere_hit(d, S[k:k + step], rm)           # (chunk, M)
            if A is not None:
                tc = _capsule_hit(d, A[k:k + step], B[k:k + step], rf)
                mk += (ts < tc).sum(axis=0)
                fg += (np.isfinite(tc) & (tc <= ts)).sum(axis=0)
            else:
                mk += np.isfinite(ts).sum(axis=0)

        def pool(a):
            return (a / len(S)).reshape(h, ss, w, ss).mean(axis=(1, 3))
        return pool(mk), pool(fg)

    def marker_visibility(self, position: np.ndarray) -> tuple[float, float]:
        """Fraction (left, right) of the marker's silhouette that the finger leaves visible at ``position``
        (3,) m, display frame (1 without self-occlusion). Ray-cast like :meth:`render`, no noise."""
        c = self.cfg
        p = np.asarray(position, float).reshape(3)
        A, B = self.finger_axis(p)
        out = []
        for side in ("left", "right"):
            S, Ac, Bc = (self._to_side(self.to_camera(X), side) for X in (p, A, B))
            box = self._marker_box(S, c.marker_diameter / 2, side)
            if box is None:
                out.append(0.0)
                continue
            full, _ = self._box_coverage(side, box, S, c.marker_diameter / 2, None, None, 0.0)
            vis, _ = self._box_coverage(side, box, S, c.marker_diameter / 2,
                                        Ac if c.self_occlusion else None, Bc, c.finger_width / 2)
            out.append(float(vis.sum() / max(full.sum(), 1e-12)))
        return out[0], out[1]

    def _marker_box(self, S: np.ndarray, rm: float, side: str) -> tuple[int, int, int, int] | None:
        """Integer pixel box (x0, y0, x1, y1) holding the marker silhouettes of centres S (n, 3), or None if
        a centre is behind the camera or the box is outside the image."""
        if np.any(S[:, 2] <= 0.02):
            return None
        uv = self._project(self._to_left(S, side), side)
        rad = self.model.focal * rm / float(S[:, 2].min()) * 1.15 + 2.0
        w, h = self.size
        x0 = int(max(0, math.floor(uv[:, 0].min() - rad)))
        y0 = int(max(0, math.floor(uv[:, 1].min() - rad)))
        x1 = int(min(w, math.ceil(uv[:, 0].max() + rad) + 1))
        y1 = int(min(h, math.ceil(uv[:, 1].max() + rad) + 1))
        return None if (x1 <= x0 or y1 <= y0) else (x0, y0, x1, y1)

    def _to_left(self, X_side: np.ndarray, side: str) -> np.ndarray:
        return X_side if side == "left" else (X_side - self.model.T) @ self.model.R

    # ------------------------------------------------------------------------------------------ rendering
    def render(self, position: np.ndarray, velocity: np.ndarray | None = None, visible: bool = True,
               extra_markers: tuple = (), occlusion: float = 0.0,
               marker_diameter: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Render one raw stereo pair (left, right), each uint8 (H, W).

        ``position`` (3,) m and ``velocity`` (3,) m/s of the marker centre at mid-exposure, display frame;
        ``visible`` False hides the marker (finger still drawn); ``extra_markers``: display-frame points
        (M, 3) m of further bright spheres of the same size (e.g. a reflection); ``occlusion`` ∈ [0, 1]: an
        extra, synthetic occluder hiding that fraction of the marker's width beyond a vertical chord in the
        **left** image only (stress test; the physical occlusion is ``self_occlusion``);
        ``marker_diameter`` m overrides the config's. Raises ``ValueError`` on non-finite position/velocity
        or occlusion outside [0, 1].
        """
        p = np.asarray(position, float).reshape(3)
        v = np.zeros(3) if velocity is None else np.asarray(velocity, float).reshape(3)
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(v))):
            raise ValueError(f"position/velocity must be finite, got {p!r}, {v!r}")
        if not (0.0 <= occlusion <= 1.0):
            raise ValueError(f"occlusion must be in [0, 1], got {occlusion!r}")
        c = self.cfg
        md = c.marker_diameter if marker_diameter is None else float(marker_diameter)
        if not (0.001 <= md <= 0.02):
            raise ValueError(f"marker_diameter must be in [0.001, 0.02] m, got {md!r}")
        n = 1
        if c.exposure_s > 0 and np.linalg.norm(v) > 0:
            # at least one sample per 0.5 px of streak, so the streak is continuous, not a row of dots; a
            # streak under 0.1 px is rendered at its mid-exposure position (its blur is below the PSF's)
            zc = max(float(self.to_camera(p)[0, 2]), 0.05)
            streak_px = self.model.focal * float(np.linalg.norm(v)) * c.exposure_s / zc
            if streak_px >= 0.1:
                n = min(max(c.blur_samples, int(np.ceil(2.0 * streak_px)) + 1), 200)
        offs = (np.linspace(-0.5, 0.5, n) if n > 1 else np.zeros(1))[:, None] * (v * c.exposure_s)[None, :]
        tips = p[None, :] + offs                                          # (n, 3) display, marker centres
        A0, B0 = self.finger_axis(p, md)
        As, Bs = A0[None, :] + offs, B0[None, :] + offs
        extra = np.asarray(extra_markers, float).reshape(-1, 3)
        out = []
        for side in ("left", "right"):
            S = self._to_side(self.to_camera(tips), side)
            Ac = self._to_side(self.to_camera(As), side)
            Bc = self._to_side(self.to_camera(Bs), side)
            Ec = self._to_side(self.to_camera(extra), side)
            if np.any(S[:, 2] <= 0.02) or np.any(Ac[:, 2] <= 0.02) or np.any(Bc[:, 2] <= 0.02):
                img = self.backgrounds[0 if side == "left" else 1].copy()
            else:
                img = self._draw(side, S, Ac, Bc, Ec, md / 2, visible, occlusion if side == "left" else 0.0)
            out.append(self._noise(img))
        return out[0], out[1]

    def _draw(self, side, S, Ac, Bc, Ec, rm, visible, occlusion):
        c = self.cfg
        f = self.model.focal
        bg = self.backgrounds[0 if side == "left" else 1]
        h, w = bg.shape
        rf = 0.5 * c.finger_width
        a_uv = self._project(self._to_left(Ac, side), side)
        b_uv = self._project(self._to_left(Bc, side), side)
        s_uv = self._project(self._to_left(S, side), side)
        fw_a = 2.0 * f * rf / float(np.mean(Ac[:, 2]))
        fw_b = 2.0 * f * rf / float(np.mean(Bc[:, 2]))
        e_uv = self._project(self._to_left(Ec, side), side) if len(Ec) else np.zeros((0, 2))
        allpts = np.vstack([a_uv, b_uv, s_uv, e_uv])
        m = int(max(fw_a, fw_b) + 8 + 3 * c.blur_px)
        x0 = int(max(0, np.floor(allpts[:, 0].min()) - m))
        y0 = int(max(0, np.floor(allpts[:, 1].min()) - m))
        x1 = int(min(w, np.ceil(allpts[:, 0].max()) + m + 1))
        y1 = int(min(h, np.ceil(allpts[:, 1].max()) + m + 1))
        img = bg.copy()
        if x1 <= x0 or y1 <= y0:
            return img
        crop = bg[y0:y1, x0:x1].astype(np.float32)
        acc = np.zeros_like(crop)
        sh = 4  # fixed-point shift for sub-pixel cv2 drawing
        fw = 0.5 * (fw_a + fw_b)
        finger = float(c.finger_level * c.background_gain)     # diffuse skin: same exposure as the sheet
        for i in range(len(a_uv)):
            layer = crop.copy()
            a = np.round((a_uv[i] - (x0, y0)) * (1 << sh)).astype(np.int32)
            b = np.round((b_uv[i] - (x0, y0)) * (1 << sh)).astype(np.int32)
            cv2.line(layer, tuple(int(t) for t in a), tuple(int(t) for t in b), finger,
                     thickness=max(1, int(round(fw))), lineType=cv2.LINE_AA, shift=sh)
            cv2.circle(layer, tuple(int(t) for t in a), int(round(0.5 * fw_a * (1 << sh))), finger,
                       thickness=-1, lineType=cv2.LINE_AA, shift=sh)
            acc += layer
        acc /= len(a_uv)
        if visible:
            box = self._marker_box(S, rm, side)
            if box is not None:
                bx0, by0, bx1, by1 = box
                mk, fg = self._box_coverage(side, box, S, rm, Ac if c.self_occlusion else None, Bc, rf)
                if occlusion > 0:
                    # synthetic occluder: hide the marker beyond a vertical chord at the covered fraction
                    u_c = (float(np.mean(s_uv[:, 0])) + (f * rm / float(np.mean(S[:, 2])))
                           * (1 - 2 * occlusion))
                    xx = np.arange(bx0, bx1, dtype=np.float32)[None, :]
                    keep = np.clip(u_c + 0.5 - xx, 0.0, 1.0)
                    fg = fg + mk * (1.0 - keep)
                    mk = mk * keep
                sub = (slice(by0 - y0, by1 - y0), slice(bx0 - x0, bx1 - x0))
                if c.self_occlusion:
                    # the ray-cast decides marker / finger / background in the box
                    base = crop[sub]
                    acc[sub] = base * (1.0 - mk - fg) + c.marker_level * mk + finger * fg
                else:
                    acc[sub] = acc[sub] + mk * (c.marker_level - acc[sub]) + fg * (finger - acc[sub])
        for j in range(len(Ec)):
            box = self._marker_box(Ec[j:j + 1], rm, side)
            if box is None:
                continue
            bx0, by0, bx1, by1 = box
            mk, _ = self._box_coverage(side, box, Ec[j:j + 1], rm, None, None, 0.0)
            sub = (slice(by0 - y0, by1 - y0), slice(bx0 - x0, bx1 - x0))
            acc[sub] += mk * (c.marker_level - acc[sub])
        if c.blur_px > 0:
            acc = cv2.GaussianBlur(acc, (0, 0), c.blur_px)
        img[y0:y1, x0:x1] = np.clip(acc + 0.5, 0, 255).astype(np.uint8)
        return img

    def _noise(self, img: np.ndarray) -> np.ndarray:
        c = self.cfg
        if c.noise_scale <= 0 or (c.noise_dn <= 0 and c.shot_gain <= 0):
            return img
        h, w = img.shape
        b = self._bank[int(self.rng.integers(len(self._bank)))]
        oy, ox = (int(v) for v in self.rng.integers(0, self._pad, 2))
        sigma = cv2.LUT(img, self._sigma_lut)
        return cv2.add(img, cv2.multiply(sigma, b[oy:oy + h, ox:ox + w]), dtype=cv2.CV_8U)


def twin_renderer(truth, cfg: SimConfig | None = None, calib: dict | None = None) -> StereoCameraTwin:
    """The camera twin of a hidden truth (:class:`flexsheet.twin.truth.TwinTruth`): renders through the
    truth's stereo cameras (``truth.camera_calib``, or ``calib`` for another camera model) at the truth's
    mount ``truth.T_display_camera``, with the truth's marker diameter. ``cfg``: :class:`SimConfig`
    (default: realistic). Never hand the result's ``model`` to an estimator."""
    cfg = replace(cfg or SimConfig(), marker_diameter=float(truth.marker_diameter))
    return StereoCameraTwin(truth.camera_calib if calib is None else calib, truth.T_display_camera, cfg)
