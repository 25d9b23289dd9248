"""Arm base registration: each RV-1A's base pose in the display frame from its clamp marker (pure estimator).

Procedure (docs/calibration.md §4). A retro-reflective sphere (10 mm) is fixed on each clamp, the sheet is
unclamped, and each arm in turn moves through N ≥ 8 joint configurations (:func:`plan_arm_configs`: random
joint offsets around the home posture, kept where the nominal model puts the marker well inside both camera
images, spread out by farthest-point sampling in joint space). At each one the stereo camera sees the
marker: :func:`detect_marker` finds it near its predicted position (the *other* arm's marker is in view too)
and takes the background-subtracted, intensity-weighted centroid; it is undistorted and triangulated
(Hartley–Sturm) with the camera-pose step's stereo model and placed in the display frame.

Fit (:func:`estimate_arm_base`): ``scipy.optimize.least_squares`` over the base pose (6: a rotation vector and
a translation correcting the nominal base) and the marker offset in the clamp frame (3), minimising the 3-D
distance between the triangulated markers and the URDF forward kinematics
(:class:`flexsheet.arm.kinematics.ArmKinematics`) of the commanded joints, each marker weighted by its
triangulation covariance (:meth:`flexsheet.vision.stereo.StereoModel.covariance`: depth is ~10× less certain
than lateral position; in the twin this cut the worst base error over 12 seeds from 1.0 to 0.8 mm). An
optional prior on the base's roll and pitch (``level_sigma_deg``, a spirit level's reading) is available; it
did not help measurably and is off by default — the hand–eye / robot–world
problem with a point target (cf. ``cv2.calibrateRobotWorldHandEye``, which needs full target poses). Reported:
RMS residual in mm. Errors (``ValueError``): fewer than ``min_configs`` usable configurations (marker not
found, out of view), or a fit whose residual exceeds ``max_residual_mm`` (wrong arm, wrong joints, a loose
marker).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares

from flexsheet.arm.kinematics import Q_LOWER, Q_UPPER, ArmKinematics, home_joints
from flexsheet.vision.stereo import StereoModel

__all__ = ["JOINT_SPAN_DEG", "plan_arm_configs", "predict_marker", "detect_marker", "triangulate_markers",
           "ArmResult", "estimate_arm_base"]

#: half-range of the random joint offsets around home, deg (J1…J6)
JOINT_SPAN_DEG = np.array([20.0, 15.0, 15.0, 45.0, 35.0, 60.0])


def predict_marker(side: str, q_list, T_display_base: np.ndarray, marker_offset, stereo: dict,
                   T_display_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nominal marker positions (N, 3) m (display) and their raw pixels in the left and right images (N, 2)
    for joints ``q_list`` (N, 6) rad, from a base pose, marker offset (3,) m in the clamp frame, a stereo
    dict and the camera pose."""
    kin = ArmKinematics(side, np.asarray(T_display_base, float))
    m = np.asarray(marker_offset, float)
    X = np.array([(lambda T: T[:3, :3] @ m + T[:3, 3])(kin.fk(q)) for q in q_list]).reshape(-1, 3)
    R_cd = T_display_camera[:3, :3].T
    Xc = (X - T_display_camera[:3, 3]) @ R_cd.T
    ul, ur = StereoModel.from_calib(stereo).project(Xc)
    return X, ul, ur


def plan_arm_configs(side: str, n: int, T_display_base: np.ndarray, marker_offset, stereo: dict,
                     T_display_camera: np.ndarray, seed: int = 0, margin_px: float = 30.0,
                     candidates: int = 400) -> list[np.ndarray]:
    """``n`` joint configurations (each (6,) rad) for arm ``side``: home plus random offsets within
    :data:`JOINT_SPAN_DEG`, inside the joint limits with 5° margin, whose nominal marker lands ≥ ``margin_px``
    inside both images and ≥ 0.2 m in front of the camera, chosen by farthest-point sampling (joint space,
    normalised by the spans) so the set is spread. Deterministic in ``seed``. Raises ``ValueError`` if fewer
    than ``n`` candidates qualify."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n!r}")
    rng = np.random.default_rng([int(seed), 0 if side == "left" else 1])
    q0 = home_joints(side)
    span = np.radians(JOINT_SPAN_DEG)
    Q = q0 + rng.uniform(-1.0, 1.0, (candidates, 6)) * span
    lo, hi = Q_LOWER + math.radians(5), Q_UPPER - math.radians(5)
    Q = Q[np.all((Q > lo) & (Q < hi), axis=1)]
    Q = np.vstack([q0, Q])
    X, ul, ur = predict_marker(side, Q, T_display_base, marker_offset, stereo, T_display_camera)
    w, h = stereo["image_size"]
    depth = (X - T_display_camera[:3, 3]) @ T_display_camera[:3, 2]
    ok = depth > 0.2
    for uv in (ul, ur):
        ok &= ((uv[:, 0] > margin_px) & (uv[:, 0] < w - margin_px) & (uv[:, 1] > margin_px)
               & (uv[:, 1] < h - margin_px))
    Q = Q[ok]
    if len(Q) < n:
        raise ValueError(f"only {len(Q)} of {candidates} candidate configurations keep the {side} marker in "
                         f"view, need {n}")
    chosen = [0]                                     # home first (always first: ok keeps index 0 if in view)
    d = np.linalg.norm((Q - Q[0]) / span, axis=1)
    while len(chosen) < n:
        k = int(np.argmax(d))
        chosen.append(k)
        d = np.minimum(d, np.linalg.norm((Q - Q[k]) / span, axis=1))
    return [Q[k].copy() for k in chosen]


def detect_marker(image: np.ndarray, predicted_uv, search_px: float = 45.0, min_area: int = 4,
                  min_peak_dn: float = 40.0) -> np.ndarray | None:
    """Centroid (2,) px of the bright blob nearest ``predicted_uv`` within ``search_px`` in a mono8 image, or
    ``None``. Threshold halfway between the window's median (background) and its peak picks the blob; centroid
    of the intensity above a quarter of the way from background to peak, over the blob dilated by 2 px
    (symmetric weights, so a symmetric blob gives its centre; the background slope stays out). Raises
    ``ValueError`` on a bad image."""
    if not isinstance(image, np.ndarray) or image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError(f"image must be a (H, W) uint8 array, got {getattr(image, 'shape', type(image))}")
    h, w = image.shape
    u, v = float(predicted_uv[0]), float(predicted_uv[1])
    if not (np.isfinite(u) and np.isfinite(v)):
        return None
    x0, x1 = int(max(0, u - search_px)), int(min(w, u + search_px + 1))
    y0, y1 = int(max(0, v - search_px)), int(min(h, v + search_px + 1))
    if x1 - x0 < 5 or y1 - y0 < 5:
        return None
    win = image[y0:y1, x0:x1].astype(np.float32)
    bg = float(np.median(win))
    peak = float(win.max())
    if peak - bg < min_peak_dn:
        return None
    thr = bg + 0.5 * (peak - bg)
    n, lab, stats, cents = cv2.connectedComponentsWithStats((win > thr).astype(np.uint8), connectivity=8)
    best = None
    for i in range(1, n):
        if stats[i, cv2.CC_STAT_AREA] < min_area:
            continue
        d = math.hypot(cents[i, 0] + x0 - u, cents[i, 1] + y0 - v)
        if best is None or d < best[0]:
            best = (d, i)
    if best is None:
        return None
    # weights above a low threshold only: a dilated mask with (I − background) weights lets the room's
    # brightness slope under the blob's rim pull the centroid by ~0.04 px (0.2 mm of depth at 0.5 m)
    mask = cv2.dilate((lab == best[1]).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    wgt = np.clip(win - (bg + 0.25 * (peak - bg)), 0.0, None) * mask
    s = float(wgt.sum())
    if s <= 0:
        return None
    ys, xs = np.mgrid[y0:y1, x0:x1]
    return np.array([float((wgt * xs).sum() / s), float((wgt * ys).sum() / s)])


def triangulate_markers(frames: list[tuple[np.ndarray, np.ndarray]], predicted: tuple[np.ndarray, np.ndarray],
                        stereo: dict, T_display_camera: np.ndarray, max_epipolar_px: float = 1.5,
                        sigma_px: float = 0.03):
    """Detect and triangulate the marker in each stereo pair. ``predicted``: (left (N, 2), right (N, 2)) raw
    pixels from :func:`predict_marker`. Returns (indices of the usable frames, X (M, 3) display m, skipped
    index → reason, covariances (M, 3, 3) m² in the display frame for a centroid σ of ``sigma_px``, from
    :meth:`flexsheet.vision.stereo.StereoModel.covariance` — depth is ~10× worse than lateral and grows as
    Z²)."""
    model = StereoModel.from_calib(stereo)
    idx, pts, covs, skipped = [], [], [], {}
    Rdc = T_display_camera[:3, :3]
    for k, (left, right) in enumerate(frames):
        a = detect_marker(left, predicted[0][k])
        b = detect_marker(right, predicted[1][k])
        if a is None or b is None:
            skipped[k] = "marker not found in the " + " and ".join(
                s for s, d in (("left", a), ("right", b)) if d is None) + " image"
            continue
        ul, ur = model.undistort(a[None], "left"), model.undistort(b[None], "right")
        ep = float(model.epipolar_residual(ul, ur)[0])
        if ep > max_epipolar_px:
            skipped[k] = f"epipolar residual {ep:.2f} px > {max_epipolar_px} (wrong blob matched?)"
            continue
        X = model.triangulate(ul, ur, "optimal")[0]
        idx.append(k)
        pts.append(Rdc @ X + T_display_camera[:3, 3])
        covs.append(Rdc @ model.covariance(X[None], sigma_px)[0] @ Rdc.T)
    return np.array(idx, int), np.array(pts).reshape(-1, 3), skipped, np.array(covs).reshape(-1, 3, 3)


@dataclass
class ArmResult:
    """Result of :func:`estimate_arm_base`: ``T_display_base`` (4, 4), ``marker_offset`` (3,) m (clamp frame),
    ``residual_mm`` RMS 3-D residual, ``per_config_mm`` (N,), ``n_configs``, ``skipped`` index → reason."""

    T_display_base: np.ndarray
    marker_offset: np.ndarray
    residual_mm: float
    per_config_mm: np.ndarray
    n_configs: int
    skipped: dict[int, str] = field(default_factory=dict)


def estimate_arm_base(side: str, q_list, X_display: np.ndarray, T_base_nominal: np.ndarray, marker_nominal,
                      *, min_configs: int = 8, max_residual_mm: float = 2.0,
                      level_sigma_deg: float | None = None,
                      marker_sigma_mm: float = 0.15, cov: np.ndarray | None = None,
                      skipped: dict[int, str] | None = None) -> ArmResult:
    """Least-squares base pose and marker offset of arm ``side`` (module doc).

    ``q_list`` (N, 6) rad: the commanded joints of the usable frames; ``X_display`` (N, 3) m: the triangulated
    markers; ``T_base_nominal`` (4, 4) and ``marker_nominal`` (3,) m: the starting point. ``level_sigma_deg``:
    the base was levelled (spirit level / digital inclinometer) to this accuracy — a Gaussian prior on its
    roll and pitch about vertical (the markers span only ±0.1 m, 0.5 m from the base origin). ``None``: no
    prior. ``cov`` (N, 3, 3) m²: the markers' triangulation covariances (:func:`triangulate_markers`),
    whitening each residual (Mahalanobis; depth counts ~10× less than lateral); without it an isotropic
    ``marker_sigma_mm``. The reported residuals are Euclidean, mm. Raises ``ValueError`` with fewer than
    ``min_configs`` configurations, mismatched inputs, or an RMS residual above ``max_residual_mm``.
    """
    Q = np.asarray(q_list, float).reshape(-1, 6)
    X = np.asarray(X_display, float).reshape(-1, 3)
    if len(Q) != len(X):
        raise ValueError(f"q_list and X_display must have the same length, got {len(Q)} and {len(X)}")
    if len(Q) < min_configs:
        raise ValueError(f"arm {side}: only {len(Q)} usable marker configurations, need at least "
                         f"{min_configs} (skipped: {skipped or {}})")
    kin = ArmKinematics(side, np.eye(4))
    T_bc = np.array([kin.fk(q) for q in Q])          # clamp in the base frame
    Tn = np.asarray(T_base_nominal, float)

    def unpack(p):
        T = np.eye(4)
        T[:3, :3] = cv2.Rodrigues(p[:3].copy())[0] @ Tn[:3, :3]
        T[:3, 3] = Tn[:3, 3] + p[3:6]
        return T, p[6:9]

    if cov is None:
        W = np.repeat(np.eye(3)[None] / (marker_sigma_mm * 1e-3), len(Q), axis=0)
    else:
        C = np.asarray(cov, float)
        if C.shape != (len(Q), 3, 3):
            raise ValueError(f"cov must be ({len(Q)}, 3, 3), got {C.shape}")
        W = np.linalg.inv(np.linalg.cholesky(C))            # whitening: W C Wᵀ = I

    def res(p):
        T, m = unpack(p)
        Mb = np.einsum("nij,j->ni", T_bc[:, :3, :3], m) + T_bc[:, :3, 3]
        r = np.einsum("nij,nj->ni", W, (Mb @ T[:3, :3].T + T[:3, 3]) - X).ravel()
        if level_sigma_deg is None:
            return r
        z = T[:3, 2]                                  # the base's vertical axis: level means z = (0, 0, 1)
        return np.concatenate([r, np.array([z[0], z[1]]) / math.radians(level_sigma_deg)])

    p0 = np.concatenate([np.zeros(6), np.asarray(marker_nominal, float)])
    sol = least_squares(res, p0, method="lm", x_scale=np.r_[[0.01] * 3, [0.005] * 3, [0.005] * 3])
    T, m = unpack(sol.x)
    Mb = np.einsum("nij,j->ni", T_bc[:, :3, :3], m) + T_bc[:, :3, 3]
    per = np.linalg.norm((Mb @ T[:3, :3].T + T[:3, 3]) - X, axis=1) * 1e3
    rms = float(np.sqrt(np.mean(per ** 2)))
    if rms > max_residual_mm:
        raise ValueError(f"arm {side}: fit residual {rms:.2f} mm RMS > {max_residual_mm} mm (per "
                         f"configuration {np.round(per, 2).tolist()}): wrong arm or joints, or a loose "
                         "marker?")
    return ArmResult(T, m, rms, per, len(Q), dict(skipped or {}))
