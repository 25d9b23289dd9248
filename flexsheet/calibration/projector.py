"""Projector calibration by structured light and stereo triangulation (pure estimator).

Method: Moreno & Taubin, "Simple, accurate, and robust projector-camera calibration", 3DIMPVT 2012 — Gray-code
patterns decoded per camera pixel, *local* fits around each correspondence to reach sub-pixel precision,
then ``cv2.calibrateCamera`` on the projector as an inverse camera. Here the 3-D points come from the
calibrated stereo camera instead of a checkerboard: the sheet needs no markings and may take any pose.

1. The renderer projects :func:`gray_code_patterns` (``cv2.structured_light.GrayCodePattern``: column and row
   codes, each pattern followed by its inverse, then all-white and all-black) onto the sheet, which the arms
   hold at ≥ 3 poses (:data:`POSE_PLAN`: home, tilts and a step in depth — the depth spread separates the
   focal length from the distance).
2. :func:`decode` turns each camera's stack into a projector column/row per camera pixel (bit = pattern >
   inverse; a pixel is kept where white − black ≥ ``min_contrast`` and every bit differs from its inverse
   by ≥ ``min_bit_contrast``).
3. :func:`grid_correspondences`: for a grid of projector points (every ``spacing`` px), the camera pixels
   that decoded within the grid cell are fitted with a local affine map camera → projector (Moreno &
   Taubin's local homography, which averages the codes' quantisation); inverting it gives the sub-pixel
   camera position of the projector point.
4. Points found in both cameras are triangulated (Hartley–Sturm, :class:`flexsheet.vision.stereo.StereoModel`)
   with the camera-pose step's stereo model and placed in the display frame by its ``T_display_camera``.
5. All poses' 3-D ↔ projector-pixel pairs form one non-planar rig: ``cv2.calibrateCamera`` with
   ``CALIB_USE_INTRINSIC_GUESS`` from the nominal projector (fixed aspect ratio, no tangential terms, k1 only),
   refitted on the inliers (points within 3σ) — K_p, distortion and the pose (:func:`estimate_projector`).
6. Refined (:func:`refine_joint`) by maximum likelihood with the projector as a third camera: the residuals
   are the correspondences' reprojection errors in the two camera images, where the noise is, with each
   point's depth along its projector ray eliminated. The reprojection RMS is reported in projector pixels.

Errors (``ValueError``): fewer than ``min_poses`` poses, a pose whose patterns do not decode (dark sheet,
projector off, wrong pattern order: too few valid pixels), or too few correspondences in both cameras.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from flexsheet.calibration.camera_pose import sheet_pose
from flexsheet.calibration.display_calib import stereo_from_vector
from flexsheet.vision.stereo import StereoModel

__all__ = ["POSE_PLAN", "plan_projector_poses", "gray_code_patterns", "decode", "grid_correspondences",
           "PoseCorrespondences", "ProjectorResult", "triangulate_pose", "estimate_projector", "JointResult",
           "refine_joint"]

#: commanded sheet poses for the projector (tilt about y °, turn about z °, origin m), home first
POSE_PLAN: tuple = (
    (0, 0, (0, 0, 0)), (-35, 0, (0, 0, 0)), (0, 0, (-0.08, 0, 0)), (0, -25, (0, 0, 0)), (0, 0, (0.08, 0, 0)),
    (20, 0, (0, 0, 0)), (-25, -20, (0, 0, 0)), (0, 15, (0, 0, 0)),
)


def plan_projector_poses(n_poses: int) -> list[np.ndarray]:
    """The first ``n_poses`` commanded sheet poses (4, 4) of :data:`POSE_PLAN`. Raises ``ValueError`` outside
    1…len(POSE_PLAN)."""
    if not (1 <= n_poses <= len(POSE_PLAN)):
        raise ValueError(f"n_poses must be in 1..{len(POSE_PLAN)}, got {n_poses!r}")
    return [sheet_pose(a, b, o) for a, b, o in POSE_PLAN[:n_poses]]


def gray_code_patterns(width: int, height: int) -> list[np.ndarray]:
    """The projector images, uint8 (height, width): ``cv2.structured_light.GrayCodePattern`` column then row
    bit planes, MSB first, each followed by its inverse, then all-white and all-black. Raises ``ValueError``
    on a non-positive size."""
    if width < 2 or height < 2:
        raise ValueError(f"projector size must be >= 2x2, got {width}x{height}")
    g = cv2.structured_light.GrayCodePattern.create(int(width), int(height))
    ok, pats = g.generate()
    if not ok:
        raise ValueError("GrayCodePattern.generate failed")
    white = np.full((height, width), 255, np.uint8)
    return [np.asarray(p, np.uint8) for p in pats] + [white, np.zeros_like(white)]


def _nbits(n: int) -> int:
    return int(math.ceil(math.log2(n)))


def decode(images: list[np.ndarray], width: int, height: int, min_contrast: float = 15.0,
           min_bit_contrast: float = 5.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Decode one camera's captures of :func:`gray_code_patterns` (same order) into projector coordinates.

    Returns ``(col, row, valid)``: int32 (H, W) projector column/row per camera pixel (−1 where invalid) and
    the bool mask. Vectorised equivalent of ``GrayCodePattern.getProjPixel`` (checked against it in the
    tests) with a shadow mask (white − black ≥ ``min_contrast`` DN) and a per-bit reliability test
    (|pattern − inverse| ≥ ``min_bit_contrast`` DN; 5 is OpenCV's ``whiteThreshold`` default). Raises ``ValueError`` on a wrong image count or shape.
    """
    nc, nr = _nbits(width), _nbits(height)
    need = 2 * (nc + nr) + 2
    if len(images) != need:
        raise ValueError(f"need {need} images for a {width}x{height} Gray code (patterns, inverses, white, "
                         f"black), got {len(images)}")
    shp = images[0].shape
    if any(im.shape != shp or im.ndim != 2 for im in images):
        raise ValueError("all pattern images must be 2-D and of one size")
    white = images[-2].astype(np.int16)
    black = images[-1].astype(np.int16)
    valid = (white - black) >= min_contrast

    def axis(offset: int, n: int) -> np.ndarray:
        val = np.zeros(shp, np.int32)
        prev = np.zeros(shp, bool)
        for i in range(n):
            a = images[offset + 2 * i].astype(np.int16)
            b = images[offset + 2 * i + 1].astype(np.int16)
            d = a - b
            valid[...] &= np.abs(d) >= min_bit_contrast
            bit = prev ^ (d > 0)                  # Gray -> binary: b_i = b_{i-1} xor g_i
            val = (val << 1) | bit
            prev = bit
        return val

    col = axis(0, nc)
    row = axis(2 * nc, nr)
    valid &= (col < width) & (row < height)
    col[~valid] = -1
    row[~valid] = -1
    return col, row, valid


def grid_correspondences(col: np.ndarray, row: np.ndarray, valid: np.ndarray, spacing: int = 8,
                         min_pixels: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel camera positions of projector grid points from one camera's decoded maps.

    For every grid point (u, v) = spacing·(i, j), the valid camera pixels whose code lies in its cell
    (|col − u| ≤ spacing/2, |row − v| ≤ spacing/2) fit (col, row) = A (x, y) + b by least squares; one pass
    drops pixels off by > 1.5 projector px (mis-decoded bits) and refits. Returns ``(proj (M, 2), cam (M, 2))``:
    projector points (px) and their raw camera positions (px), for cells with ≥ ``min_pixels`` pixels whose
    solution lies within their pixels' extent.
    """
    ys, xs = np.nonzero(valid)
    if len(xs) == 0:
        return np.zeros((0, 2)), np.zeros((0, 2))
    c = col[ys, xs].astype(np.float64)
    r = row[ys, xs].astype(np.float64)
    x = xs.astype(np.float64)
    y = ys.astype(np.float64)
    h = spacing / 2.0
    iu = np.floor((c + h) / spacing).astype(np.int64)
    iv = np.floor((r + h) / spacing).astype(np.int64)
    key = iu * 100003 + iv
    keys, inv = np.unique(key, return_inverse=True)
    keep = np.ones(len(x), bool)
    for _ in range(2):
        sol, ok = _cell_fit(inv, len(keys), x, y, c, r, keep)
        if _ == 0:
            pc = sol["a"][inv, 0] + sol["a"][inv, 1] * (x - sol["mx"][inv]) + sol["a"][inv, 2] * (y - sol["my"][inv])
            pr = sol["b"][inv, 0] + sol["b"][inv, 1] * (x - sol["mx"][inv]) + sol["b"][inv, 2] * (y - sol["my"][inv])
            keep = ok[inv] & (np.abs(pc - c) <= 1.5) & (np.abs(pr - r) <= 1.5)
    u = (keys // 100003).astype(np.float64) * spacing
    v = (keys % 100003).astype(np.float64) * spacing
    A = np.stack([np.stack([sol["a"][:, 1], sol["a"][:, 2]], -1), np.stack([sol["b"][:, 1], sol["b"][:, 2]], -1)], 1)
    rhs = np.stack([u - sol["a"][:, 0], v - sol["b"][:, 0]], -1)
    det = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
    good = ok & (np.abs(det) > 1e-6)
    dxy = np.zeros((len(keys), 2))
    dxy[good] = np.linalg.solve(A[good], rhs[good][..., None])[..., 0]
    cam = np.stack([sol["mx"] + dxy[:, 0], sol["my"] + dxy[:, 1]], -1)
    good &= (np.abs(dxy[:, 0]) <= sol["ex"]) & (np.abs(dxy[:, 1]) <= sol["ey"])
    good &= sol["n"] >= min_pixels
    return np.stack([u, v], -1)[good], cam[good]


def _cell_fit(inv, n_cells, x, y, c, r, keep):
    """Per-cell least squares of c and r on (1, x − x̄, y − ȳ) with bincount sums (vectorised)."""
    w = keep.astype(np.float64)

    def S(v):
        return np.bincount(inv, weights=w * v, minlength=n_cells)

    n = S(np.ones_like(x))
    nz = np.maximum(n, 1.0)
    mx, my = S(x) / nz, S(y) / nz
    dx, dy = x - mx[inv], y - my[inv]
    sxx, sxy, syy = S(dx * dx), S(dx * dy), S(dy * dy)
    M = np.stack([np.stack([sxx, sxy], -1), np.stack([sxy, syy], -1)], 1)
    det = sxx * syy - sxy * sxy
    ok = (n >= 6) & (det > 1e-9 * np.maximum(n, 1) ** 2)
    out = {"mx": mx, "my": my, "n": n}
    for name, v in (("a", c), ("b", r)):
        mv = S(v) / nz
        rhs = np.stack([S(dx * (v - mv[inv])), S(dy * (v - mv[inv]))], -1)
        g = np.zeros((n_cells, 2))
        g[ok] = np.linalg.solve(M[ok], rhs[ok][..., None])[..., 0]
        out[name] = np.column_stack([mv, g])
    out["ex"] = np.sqrt(np.maximum(sxx / nz, 0.0)) * 2.5 + 0.5
    out["ey"] = np.sqrt(np.maximum(syy / nz, 0.0)) * 2.5 + 0.5
    return out, ok


@dataclass
class PoseCorrespondences:
    """One sheet pose: ``X`` (M, 3) display-frame points (m) and ``uv`` (M, 2) their projector pixels;
    ``valid_left``/``valid_right``: decoded pixel counts; ``epipolar_px``: median epipolar residual;
    ``left_px``/``right_px`` (M, 2): the raw camera pixels X was triangulated from."""

    X: np.ndarray
    uv: np.ndarray
    valid_left: int
    valid_right: int
    epipolar_px: float
    left_px: np.ndarray | None = None
    right_px: np.ndarray | None = None


def triangulate_pose(frames: list[tuple[np.ndarray, np.ndarray]], width: int, height: int, stereo: dict,
                     T_display_camera: np.ndarray, *, spacing: int = 8, min_contrast: float = 15.0,
                     min_valid_pixels: int = 2000, max_epipolar_px: float = 1.0) -> PoseCorrespondences:
    """Decode one pose's stereo captures of :func:`gray_code_patterns`, find grid correspondences in both
    cameras and triangulate them into the display frame. ``stereo``: the stereo dict the camera-pose step
    refined; ``T_display_camera`` (4, 4). Matches whose epipolar residual exceeds ``max_epipolar_px`` are
    dropped. Raises ``ValueError`` if either camera decodes fewer than ``min_valid_pixels`` pixels or fewer than
    20 grid points, or fewer than 20 points are seen by both."""
    lefts = [f[0] for f in frames]
    rights = [f[1] for f in frames]
    model = StereoModel.from_calib(stereo)
    res = {}
    for side, imgs in (("left", lefts), ("right", rights)):
        col, row, valid = decode(imgs, width, height, min_contrast)
        nv = int(valid.sum())
        proj, cam = grid_correspondences(col, row, valid, spacing)
        if nv < min_valid_pixels or len(proj) < 20:
            lit = float(np.percentile(imgs[-2].astype(float) - imgs[-1].astype(float), 95))
            raise ValueError(f"patterns did not decode in the {side} camera: {nv} valid pixels (need "
                             f"{min_valid_pixels}), {len(proj)} grid points (need 20); white−black contrast "
                             f"{lit:.1f} DN on the brightest 5 % of the image (need ≥ {min_contrast} DN, and well "
                             f"above the noise): sheet too dark, projector off or out of focus, or frames out of "
                             f"order")
        res[side] = (proj, cam, nv)
    (pl, cl, nl), (pr, cr, nr) = res["left"], res["right"]
    kl = {(int(u), int(v)): i for i, (u, v) in enumerate(pl)}
    pairs = [(kl[(int(u), int(v))], j) for j, (u, v) in enumerate(pr) if (int(u), int(v)) in kl]
    if len(pairs) < 20:
        raise ValueError(f"only {len(pairs)} projector points seen by both cameras (need >= 20): is the sheet in "
                         f"view of both?")
    il, ir = np.array(pairs).T
    ul = model.undistort(cl[il], "left")
    ur = model.undistort(cr[ir], "right")
    ep = model.epipolar_residual(ul, ur)
    ok = ep <= max_epipolar_px
    Xl = model.triangulate(ul[ok], ur[ok], "optimal")
    Xd = Xl @ T_display_camera[:3, :3].T + T_display_camera[:3, 3]
    return PoseCorrespondences(Xd, pl[il][ok], nl, nr, float(np.median(ep)), cl[il][ok], cr[ir][ok])


@dataclass
class ProjectorResult:
    """Result of :func:`estimate_projector`: ``K`` (3, 3), ``D`` (5,), ``T_display_projector`` (4, 4) (columns
    = projector axes, translation = centre P, m), ``reprojection_px`` RMS over the inliers (projector px),
    ``n_points``/``n_inliers``, ``per_pose_px`` RMS per pose."""

    K: np.ndarray
    D: np.ndarray
    T_display_projector: np.ndarray
    reprojection_px: float
    n_points: int
    n_inliers: int
    per_pose_px: list[float] = field(default_factory=list)
    n_poses: int = 0


def estimate_projector(poses: list[PoseCorrespondences], K_guess: np.ndarray, size: tuple[int, int], *,
                       min_poses: int = 3, fit_k1: bool = False) -> ProjectorResult:
    """K_p, distortion and pose of the projector from 3-D ↔ projector-pixel pairs (module doc, step 5).

    ``poses``: one :class:`PoseCorrespondences` per sheet pose; ``K_guess`` (3, 3): the nominal intrinsics;
    ``size``: projector (width, height) px; ``fit_k1``: also fit radial k1 (the sheet covers only the middle
    third of the image, where k1 is weakly observable). Raises ``ValueError`` with fewer than ``min_poses``
    poses (a single flat pose cannot separate focal length from distance) or fewer than 50 points.
    """
    if len(poses) < min_poses:
        raise ValueError(f"projector calibration needs at least {min_poses} sheet poses (home and tilts), got "
                         f"{len(poses)}")
    X = np.concatenate([p.X for p in poses]).astype(np.float64)
    uv = np.concatenate([p.uv for p in poses]).astype(np.float64)
    if len(X) < 50:
        raise ValueError(f"only {len(X)} projector correspondences, need >= 50")
    which = np.concatenate([np.full(len(p.X), k) for k, p in enumerate(poses)])
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_ASPECT_RATIO | cv2.CALIB_ZERO_TANGENT_DIST
             | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3)
    if not fit_k1:
        flags |= cv2.CALIB_FIX_K1
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    keep = np.ones(len(X), bool)
    K, D, rv, tv = np.asarray(K_guess, float).copy(), np.zeros(5), None, None
    for _ in range(2):
        rms, K, D, rvs, tvs = cv2.calibrateCamera([X[keep].astype(np.float32)], [uv[keep].astype(np.float32)],
                                                  tuple(int(s) for s in size), K.copy(), D.copy(), flags=flags,
                                                  criteria=crit)
        rv, tv = rvs[0], tvs[0]
        pred = cv2.projectPoints(X, rv, tv, K, D)[0].reshape(-1, 2)
        err = np.linalg.norm(pred - uv, axis=1)
        s = 1.4826 * np.median(err[keep])
        keep = err <= max(3.0 * s, 0.05)
    rms = float(np.sqrt(np.mean(err[keep] ** 2)))
    per_pose = [float(np.sqrt(np.mean(err[keep & (which == k)] ** 2))) if np.any(keep & (which == k)) else math.nan
                for k in range(len(poses))]
    R = cv2.Rodrigues(rv)[0]                      # display -> projector
    T = np.eye(4)
    T[:3, :3] = R.T
    T[:3, 3] = (-R.T @ tv).ravel()
    return ProjectorResult(K, np.asarray(D, float).ravel()[:5], T, rms, len(X), int(keep.sum()), per_pose,
                           len(poses))


@dataclass
class JointResult:
    """Result of :func:`refine_joint`: the refined ``stereo`` dict and ``T_display_camera`` (4, 4), the projector
    ``K`` (3, 3), ``D`` (5,), ``T_display_projector`` (4, 4); ``sigma_px`` the camera-pixel σ of the
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
    from flexsheet.calibration.display_calib import stereo_vector

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
            sol = least_squares(self.fun, v, jac=self.jac, args=(sigma,), method="lm", x_scale="jac", max_nfev=60)
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
        Xl = model.triangulate(model.undistort(self.lp[keep], "left"), model.undistort(self.rp[keep], "right"),
                               "optimal")
        Xd = Xl @ T_dc[:3, :3].T + T_dc[:3, 3]
        pred = cv2.projectPoints(Xd, th[34:37].copy(), th[37:40].copy(), Kp, Dp)[0].reshape(-1, 2)
        rms = float(np.sqrt(np.mean(np.sum((pred - self.uv[keep]) ** 2, 1))))
        return JointResult(st, T_dc, Kp, Dp, T_dp, sigma, rms, int(keep.sum()))


def refine_joint(poses: list[PoseCorrespondences], stereo: dict, T_display_camera: np.ndarray,
                 camera_cov: np.ndarray | None, K: np.ndarray, D: np.ndarray, T_display_projector: np.ndarray, *,
                 max_points: int = 3000, fit_k1: bool = True, n_effective: float | None = 200.0) -> JointResult:
    """Maximum-likelihood projector (and optionally camera) refinement: the projector is a third camera.

    Each correspondence is a point on the ray of its projector pixel (u, v) at an unknown depth λ; its
    residuals are its reprojection errors in both camera images (px) — where the measurement noise is, unlike
    :func:`estimate_projector`, which treats the triangulated points as exact (their depth noise then biases
    the principal point and the rotation: 0.27° on one twin seed, 0.04° after this step). Parameters: the
    projector's f (fx = fy), cx, cy, k1 and pose; with ``camera_cov`` (30, 30) also the 24 stereo parameters and
    the camera pose, under the camera-pose step's estimate as a Gaussian prior (``None``: camera fixed, the
    default of :mod:`flexsheet.calibration.procedures`). The depths are eliminated by variable projection
    (Golub & Pereyra 1973): each λ is solved by Gauss–Newton for the current parameters and the Jacobian
    (finite differences) is projected onto the complement of ∂r/∂λ. Start: the triangulated points and the
    :func:`estimate_projector` result. Points off by > 4σ after a first pass are dropped. ``n_effective``:
    the correspondences share systematic errors (decoding, sampling) that do not average out, so they are
    weighted as this many independent points (matters only when the camera is free). Raises ``ValueError``
    on a bad covariance or fewer than 50 points.
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
