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
   ``CALIB_USE_INTRINSIC_GUESS`` from the nominal projector (fixed aspect ratio, no tangential terms, k1
   only), refitted on the inliers (points within 3σ) — K_p, distortion and the pose
(:func:`estimate_projector`). 6. Refined (:func:`flexsheet.calibration.projector_joint.refine_joint`) by
maximum likelihood with the projector as a third camera: the residuals are the correspondences' reprojection
errors in the two camera images, where the noise is, with each point's depth along its projector ray
eliminated. The reprojection RMS is reported in projector pixels.

Errors (``ValueError``): fewer than ``min_poses`` poses, a pose whose patterns do not decode (dark sheet,
projector off, wrong pattern order: too few valid pixels), or too few correspondences in both cameras.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from flexsheet.calibration.camera_pose import sheet_pose
from flexsheet.vision.stereo import StereoModel

__all__ = ["POSE_PLAN", "plan_projector_poses", "gray_code_patterns", "decode", "grid_correspondences",
           "PoseCorrespondences", "ProjectorResult", "triangulate_pose", "estimate_projector"]

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
    the bool mask. Vectorised equivalent of ``GrayCodePattern.getProjPixel`` (checked against it in the tests)
    with a shadow mask (white − black ≥ ``min_contrast`` DN) and a per-bit reliability test (|pattern −
    inverse| ≥ ``min_bit_contrast`` DN; 5 is OpenCV's ``whiteThreshold`` default). Raises ``ValueError`` on a
    wrong image count or shape.
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

    For every grid point (u, v) = spacing·(i, j), the valid camera pixels whose code lies in its cell (|col −
    u| ≤ spacing/2, |row − v| ≤ spacing/2) fit (col, row) = A (x, y) + b by least squares; one pass drops
    pixels off by > 1.5 projector px (mis-decoded bits) and refits. Returns ``(proj (M, 2), cam (M, 2))``:
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
            pc = (sol["a"][inv, 0] + sol["a"][inv, 1] * (x - sol["mx"][inv])
                  + sol["a"][inv, 2] * (y - sol["my"][inv]))
            pr = (sol["b"][inv, 0] + sol["b"][inv, 1] * (x - sol["mx"][inv])
                  + sol["b"][inv, 2] * (y - sol["my"][inv]))
            keep = ok[inv] & (np.abs(pc - c) <= 1.5) & (np.abs(pr - r) <= 1.5)
    u = (keys // 100003).astype(np.float64) * spacing
    v = (keys % 100003).astype(np.float64) * spacing
    A = np.stack([np.stack([sol["a"][:, 1], sol["a"][:, 2]], -1),
                  np.stack([sol["b"][:, 1], sol["b"][:, 2]], -1)], 1)
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
    dropped. Raises ``ValueError`` if either camera decodes fewer than ``min_valid_pixels`` pixels or fewer
    than 20 grid points, or fewer than 20 points are seen by both."""
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
                             f"{lit:.1f} DN on the brightest 5 % of the image (need ≥ {min_contrast} DN, and "
                             "well above the noise): sheet too dark, projector off or out of focus, or "
                             f"frames out of order")
        res[side] = (proj, cam, nv)
    (pl, cl, nl), (pr, cr, nr) = res["left"], res["right"]
    kl = {(int(u), int(v)): i for i, (u, v) in enumerate(pl)}
    pairs = [(kl[(int(u), int(v))], j) for j, (u, v) in enumerate(pr) if (int(u), int(v)) in kl]
    if len(pairs) < 20:
        raise ValueError(f"only {len(pairs)} projector points seen by both cameras (need >= 20): is the "
                         f"sheet in view of both?")
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
        raise ValueError(f"projector calibration needs at least {min_poses} sheet poses (home and tilts), "
                         f"got {len(poses)}")
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
                                                  tuple(int(s) for s in size), K.copy(), D.copy(),
                                                  flags=flags,
                                                  criteria=crit)
        rv, tv = rvs[0], tvs[0]
        pred = cv2.projectPoints(X, rv, tv, K, D)[0].reshape(-1, 2)
        err = np.linalg.norm(pred - uv, axis=1)
        s = 1.4826 * np.median(err[keep])
        keep = err <= max(3.0 * s, 0.05)
    rms = float(np.sqrt(np.mean(err[keep] ** 2)))
    per_pose = [float(np.sqrt(np.mean(err[keep & (which == k)] ** 2))) if np.any(keep & (which == k))
                else math.nan
                for k in range(len(poses))]
    R = cv2.Rodrigues(rv)[0]                      # display -> projector
    T = np.eye(4)
    T[:3, :3] = R.T
    T[:3, 3] = (-R.T @ tv).ravel()
    return ProjectorResult(K, np.asarray(D, float).ravel()[:5], T, rms, len(X), int(keep.sum()), per_pose,
                           len(poses))


