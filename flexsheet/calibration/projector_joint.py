"""The joint refinement of the registration (:func:`refine_joint`): the stereo camera's intrinsics and pose
and the projector's intrinsics and pose fitted together to the decoded Gray-code correspondences of every
sheet pose, by nonlinear least squares on the camera-image reprojection errors (each point's depth along its
projector ray eliminated), with the camera calibration's covariance as a prior. Units: m, px."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from flexsheet.calibration.display_calib import stereo_from_vector, stereo_vector
from flexsheet.calibration.projector import PoseCorrespondences
from flexsheet.vision.stereo import StereoModel

__all__ = ["JointResult", "refine_joint"]


@dataclass
class JointResult:
    """Result of :func:`refine_joint`: the refined ``stereo`` dict and ``T_display_camera`` (4, 4), the
    projector ``K`` (3, 3), ``D`` (5,), ``T_display_projector`` (4, 4); ``sigma_px`` the camera-pixel σ of the
    correspondences; ``reprojection_px`` RMS in projector px of the re-triangulated points; ``n_points``."""

    stereo: dict
    T_display_camera: np.ndarray
    K: np.ndarray
    D: np.ndarray
    T_display_projector: np.ndarray
    sigma_px: float
    reprojection_px: float
    n_points: int


def _cam_vector(stereo: dict, T_dc: np.ndarray) -> np.ndarray:
    R_cd = T_dc[:3, :3].T
    return np.concatenate([stereo_vector(stereo), cv2.Rodrigues(R_cd)[0].ravel(), -R_cd @ T_dc[:3, 3]])


def _joint_points(poses: list[PoseCorrespondences], max_points: int):
    """(uv, left px, right px, X) of all poses' correspondences, thinned evenly to ``max_points``. Raises
    ``ValueError`` without the raw camera pixels or with fewer than 50 points."""
    if any(p.left_px is None for p in poses):
        raise ValueError("poses lack their raw camera pixels (made by an old triangulate_pose?)")
    uv = np.concatenate([p.uv for p in poses]).astype(np.float64)
    lp = np.concatenate([p.left_px for p in poses]).astype(np.float64)
    rp = np.concatenate([p.right_px for p in poses]).astype(np.float64)
    X0 = np.concatenate([p.X for p in poses]).astype(np.float64)
    if len(uv) < 50:
        raise ValueError(f"only {len(uv)} correspondences, need >= 50")
    if len(uv) > max_points:
        sel = np.linspace(0, len(uv) - 1, max_points).astype(int)
        uv, lp, rp, X0 = uv[sel], lp[sel], rp[sel], X0[sel]
    return uv, lp, rp, X0


def _camera_prior_sqrt_inv(camera_cov: np.ndarray | None) -> np.ndarray | None:
    """L⁻¹ of the camera prior's (symmetrised, regularised) Cholesky factor; None without one."""
    if camera_cov is None:
        return None
    C = np.asarray(camera_cov, float)
    if C.shape != (30, 30) or not np.all(np.isfinite(C)):
        raise ValueError(f"camera_cov must be a finite (30, 30) matrix, got {C.shape}")
    C = 0.5 * (C + C.T) + np.diag(np.maximum(np.diag(C), 1e-14) * 1e-6)
    return np.linalg.inv(np.linalg.cholesky(C))


class _JointFit:
    """:func:`refine_joint`'s variable-projection problem. θ (40,) = the 24 stereo parameters, the camera pose
    (display → left rotation vector, translation), the projector's f, cx, cy, k1 and pose (display → projector
    rotation vector, translation); ``free`` its fitted entries; ``state`` the depths λ and the inliers."""

    def __init__(self, uv, lp, rp, X0, size, c0, p0, Lc, fit_k1: bool):
        self.uv, self.lp, self.rp, self.size, self.c0, self.Lc = uv, lp, rp, size, c0, Lc
        self.full0 = np.concatenate([c0, p0])
        free = np.arange(40) if Lc is not None else np.arange(30, 40)
        if not fit_k1:
            free = free[free != 33]
        self.free = free
        Rp0 = cv2.Rodrigues(p0[4:7].copy())[0]
        self.state = {"lam": (X0 @ Rp0.T + p0[7:10])[:, 2], "keep": np.ones(len(uv), bool)}
        steps_all = np.r_[np.full(24, 1e-6), np.full(6, 1e-7), [1e-3, 1e-3, 1e-3, 1e-6], np.full(6, 1e-7)]
        steps_all[[0, 1, 2, 3, 9, 10, 11, 12]] = 1e-4             # focal lengths and principal points, px
        self.steps = steps_all[free]

    def expand(self, v):
        th = self.full0.copy()
        th[self.free] = v
        return th

    def rays(self, th):
        f, cx, cy, k1 = th[30:34]
        xd, yd = (self.uv[:, 0] - cx) / f, (self.uv[:, 1] - cy) / f
        x, y = xd.copy(), yd.copy()
        for _ in range(8):
            r2 = x * x + y * y
            x, y = xd / (1 + k1 * r2), yd / (1 + k1 * r2)
        return np.column_stack([x, y, np.ones_like(x)])

    def points(self, th, lam):
        Rp = cv2.Rodrigues(th[34:37].copy())[0]
        return (lam[:, None] * self.rays(th) - th[37:40]) @ Rp     # = Rpᵀ (λ d − t), rows

    def cam_res(self, th, X):
        st = stereo_from_vector(th[:24], self.size)
        Xc = X @ cv2.Rodrigues(th[24:27].copy())[0].T + th[27:30]
        pl = cv2.projectPoints(Xc, np.zeros(3), np.zeros(3), st["K1"], st["D1"])[0].reshape(-1, 2)
        pr = cv2.projectPoints(Xc, th[18:21].copy(), th[21:24].copy(), st["K2"], st["D2"])[0].reshape(-1, 2)
        return np.hstack([pl - self.lp, pr - self.rp])             # (N, 4) px

    def solve_lam(self, th, lam):
        h = 1e-6
        for _ in range(4):
            r = self.cam_res(th, self.points(th, lam))
            j = (self.cam_res(th, self.points(th, lam + h)) - r) / h
            lam = lam - np.einsum("ij,ij->i", j, r) / np.maximum(np.einsum("ij,ij->i", j, j), 1e-30)
        return lam

    def fun(self, v, sigma):
        th = self.expand(v)
        self.state["lam"] = self.solve_lam(th, self.state["lam"])
        r = (self.cam_res(th, self.points(th, self.state["lam"]))[self.state["keep"]] / sigma).ravel()
        return r if self.Lc is None else np.concatenate([r, self.Lc @ (th[:30] - self.c0)])

    def jac(self, v, sigma):
        th = self.expand(v)
        free, steps = self.free, self.steps
        lam, keep = self.state["lam"], self.state["keep"]
        r0 = self.cam_res(th, self.points(th, lam))[keep]
        cols = []
        for k, idx in enumerate(free):
            t = th.copy()
            t[idx] += steps[k]
            cols.append((self.cam_res(t, self.points(t, lam))[keep] - r0) / steps[k])
        Jt = np.stack(cols, -1)                                     # (N, 4, P)
        jl = (self.cam_res(th, self.points(th, lam + 1e-6))[keep] - r0) / 1e-6     # (N, 4)
        proj = np.einsum("ni,nip->np", jl, Jt) / np.maximum(np.einsum("ni,ni->n", jl, jl), 1e-30)[:, None]
        Jr = (Jt - jl[:, :, None] * proj[:, None, :]).reshape(-1, len(free)) / sigma
        if self.Lc is None:
            return Jr
        Jp = np.zeros((30, len(free)))
        Jp[:, free < 30] = self.Lc[:, free[free < 30]]
        return np.vstack([Jr, Jp])

    def solve(self, n_effective: float | None) -> tuple[np.ndarray, float]:
        """Two Levenberg–Marquardt passes; between them the outliers (> 4σ) dropped and σ re-estimated."""
        from scipy.optimize import least_squares

        sigma = 0.05
        v = self.full0[self.free].copy()
        for it in range(2):
            sol = least_squares(self.fun, v, jac=self.jac, args=(sigma,), method="lm", x_scale="jac",
                                max_nfev=60)
            v = sol.x
            if it == 0:
                res = self.cam_res(self.expand(v), self.points(self.expand(v), self.state["lam"]))
                rr = np.linalg.norm(res, axis=1) / 2.0
                self.state["keep"] = rr <= 4.0 * 1.4826 * max(float(np.median(rr)), 0.003)
                sigma = max(float(np.sqrt(np.mean(res[self.state["keep"]] ** 2))), 0.005)
                if n_effective and self.Lc is not None:
                    sigma *= math.sqrt(max(1.0, self.state["keep"].sum() / n_effective))
        return v, sigma

    def result(self, v, sigma: float) -> JointResult:
        """The refined camera and projector, and the projector-px RMS of the re-triangulated inliers."""
        th = self.expand(v)
        keep = self.state["keep"]
        st = stereo_from_vector(th[:24], self.size)
        R_cd = cv2.Rodrigues(th[24:27].copy())[0]
        T_dc = np.eye(4)
        T_dc[:3, :3] = R_cd.T
        T_dc[:3, 3] = -R_cd.T @ th[27:30]
        f, cx, cy, k1 = th[30:34]
        Kp = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
        Dp = np.array([k1, 0.0, 0.0, 0.0, 0.0])
        R_pd = cv2.Rodrigues(th[34:37].copy())[0]
        T_dp = np.eye(4)
        T_dp[:3, :3] = R_pd.T
        T_dp[:3, 3] = -R_pd.T @ th[37:40]
        # reprojection in projector px of the points triangulated with the (refined) stereo model
        model = StereoModel.from_calib(st)
        Xl = model.triangulate(model.undistort(self.lp[keep], "left"),
                               model.undistort(self.rp[keep], "right"),
                               "optimal")
        Xd = Xl @ T_dc[:3, :3].T + T_dc[:3, 3]
        pred = cv2.projectPoints(Xd, th[34:37].copy(), th[37:40].copy(), Kp, Dp)[0].reshape(-1, 2)
        rms = float(np.sqrt(np.mean(np.sum((pred - self.uv[keep]) ** 2, 1))))
        return JointResult(st, T_dc, Kp, Dp, T_dp, sigma, rms, int(keep.sum()))


def refine_joint(poses: list[PoseCorrespondences], stereo: dict, T_display_camera: np.ndarray,
                 camera_cov: np.ndarray | None, K: np.ndarray, D: np.ndarray, T_display_projector: np.ndarray,
                 *,
                 max_points: int = 3000, fit_k1: bool = True,
                 n_effective: float | None = 200.0) -> JointResult:
    """Maximum-likelihood projector (and optionally camera) refinement: the projector is a third camera.

    Each correspondence is a point on the ray of its projector pixel (u, v) at an unknown depth λ; its
    residuals are its reprojection errors in both camera images (px) — where the measurement noise is, unlike
    :func:`estimate_projector`, which treats the triangulated points as exact (their depth noise then biases
    the principal point and the rotation: 0.27° on one twin seed, 0.04° after this step). Parameters: the
    projector's f (fx = fy), cx, cy, k1 and pose; with ``camera_cov`` (30, 30) also the 24 stereo parameters
    and the camera pose, under the camera-pose step's estimate as a Gaussian prior (``None``: camera fixed,
    the default of :mod:`flexsheet.calibration.procedures`). The depths are eliminated by variable projection
    (Golub & Pereyra 1973): each λ is solved by Gauss–Newton for the current parameters and the Jacobian
    (finite differences) is projected onto the complement of ∂r/∂λ. Start: the triangulated points and the
    :func:`estimate_projector` result. Points off by > 4σ after a first pass are dropped. ``n_effective``: the
    correspondences share systematic errors (decoding, sampling) that do not average out, so they are weighted
    as this many independent points (matters only when the camera is free). Raises ``ValueError`` on a bad
    covariance or fewer than 50 points.
    """
    uv, lp, rp, X0 = _joint_points(poses, max_points)
    Lc = _camera_prior_sqrt_inv(camera_cov)
    size = tuple(stereo["image_size"])
    c0 = _cam_vector(stereo, T_display_camera)
    R_pd = T_display_projector[:3, :3].T
    p0 = np.concatenate([[0.5 * (K[0, 0] + K[1, 1]), K[0, 2], K[1, 2], float(np.ravel(D)[0])],
                         cv2.Rodrigues(R_pd)[0].ravel(), -R_pd @ T_display_projector[:3, 3]])
    fit = _JointFit(uv, lp, rp, X0, size, c0, p0, Lc, fit_k1)
    v, sigma = fit.solve(n_effective)
    return fit.result(v, sigma)
