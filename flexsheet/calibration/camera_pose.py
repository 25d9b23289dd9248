"""Camera pose: the stereo camera's pose in the display frame from a board on the sheet (pure estimator).

Procedure (docs/calibration.md §2). A chessboard or ChArUco board is fixed flat on the sheet, centred on the
sheet centre, board x along −axis_u and board y along −axis_v (:func:`board_points`). With the sheet at its
home pose the board *is* the imaginary screen, so its corners have known display-frame coordinates: that view
gives the camera pose. The arms then hold the sheet at further poses (:data:`VIEW_PLAN`); those views give no
pose information (the sheet's pose there is unknown) but pin down the stereo intrinsics, which the
``flexsheet calibrate stereo`` result leaves uncertain by 1–2 px in f and c — worth 1 mm and 0.1° of pose.

Estimator (a stereo-consistent bundle adjustment, the structure of ``cv2.stereoCalibrate`` with a known
object pose in one view):

1. Corners in every image (:func:`detect_corners`: ``cv2.findChessboardCorners`` + ``cornerSubPix`` with a
   window scaled to the squares, or the ChArUco detector). A chessboard's 180° ordering ambiguity is resolved
   in the home view by the pose nearest the nominal mount, and in the right image of every view by the
   prediction from the left image's pose through the nominal stereo model; mirrored orderings (the detector
   orders corners by the image, so it may hand back the board as if seen from behind) are rejected by PnP.
2. Start: ``cv2.solvePnP`` on the home view's left image (display-frame corners) and on each other view's
   left image (board-frame corners), with the nominal intrinsics.
3. ``scipy.optimize.least_squares`` over the 24 stereo parameters (per camera fx, fy, cx, cy, k1, k2, p1, p2,
   k3; left→right R, T), the home pose and one board pose per other view, minimising the reprojection error
   of all corners in both images (σ-weighted) plus a Gaussian prior on the stereo parameters: the nominal
   calibration with its bootstrap covariance (``python -m flexsheet.twin.truth --bootstrap`` on
   the stereo calibration's own pairs) — the MAP estimate — and the board's bow (one paraboloid sag, the
   same in all views: a 0.25 mm bow left out costs 0.8 mm of pose with an unchanged RMS). Analytic Jacobian
   (``projectPoints``, ``composeRT``). σ is re-estimated from the residuals and the fit repeated once; the
   covariance of (stereo, home pose) is kept for the projector step.

Reported: the pose, the refined stereo model, the reprojection RMS (px), the bow (mm) and ``residual_mm``: the
RMS 3-D distance between the home corners triangulated with the refined model (placed by the pose) and their
design positions — the number a lab checks. Errors: ``ValueError`` naming the view and image when the board is
not found at home, when fewer than ``min_views`` views are usable, when the fit's RMS exceeds ``max_rms_px``
(the board moved during a capture, a corner mis-detected), or when the bow exceeds ``max_bow_mm``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares

from flexsheet.calibration.display_calib import BOOTSTRAP_FILE, stereo_from_vector, stereo_vector
from flexsheet.vision.stereo import StereoModel
from flexsheet.vision.stereo_calibration import BoardSpec, detect_board

__all__ = ["VIEW_PLAN", "detect_corners", "board_centre", "board_points", "sheet_pose", "plan_board_views",
           "load_prior",
           "CameraPoseResult", "detect_views", "estimate_camera_pose"]

#: commanded sheet poses for the board views: (tilt about y °, turn about z °, origin (x, y, z) m), home
#: first; all reachable by both RV-1As from the nominal bases within the
#: bridges' 0.02 rad joint margin, and all facing the nominal camera. The
#: order interleaves tilts, turns and depth so any prefix is well conditioned.
VIEW_PLAN: tuple = (
    (0, 0, (0, 0, 0)), (-35, 0, (0, 0, 0)), (0, -25, (0, 0, 0)), (0, 0, (0.08, 0, 0)), (0, 0, (-0.08, 0, 0)),
    (0, 0, (0, 0, 0.08)), (0, 0, (0, 0, -0.08)), (-25, -20, (0, 0, 0)), (-30, 0, (0.08, 0, 0)),
    (0, -25, (-0.08, 0, -0.06)), (-45, 0, (0, 0, 0)), (-25, -20, (0.06, 0, -0.07)),
    (-25, -20, (-0.06, 0, 0.07)), (-40, -15, (0, 0, 0.05)), (-15, -30, (0, 0, -0.05)),
    (-30, 0, (-0.08, 0, -0.06)), (15, -25, (0, 0, 0)), (-30, 10, (0, 0, 0)), (0, -15, (0, 0, 0)),
    (-20, 0, (0, 0, 0)), (-35, -28, (0, 0, 0)),
)


def board_centre(board: BoardSpec) -> tuple[float, float]:
    """Board-frame coordinates (m) of the board's centre (the point laid on the sheet centre)."""
    if board.kind == "chessboard":
        return 0.5 * (board.cols - 1) * board.square, 0.5 * (board.rows - 1) * board.square
    return 0.5 * board.cols * board.square, 0.5 * board.rows * board.square


def board_points(board: BoardSpec, offset: float = 0.0) -> np.ndarray:
    """All board corners (N, 3) m in the **sheet frame** (columns: along normal, axis_u, axis_v), in the order
    of ``board.object_points()``: corner (bx, by) sits at (offset, cx − bx, cy − by), (cx, cy) the centre.
    At the home pose the sheet frame is the display frame. ``offset``: the printed surface's height above the
    sheet's mid-plane (board thickness + half the sheet), m."""
    P = board.object_points().astype(np.float64)
    cx, cy = board_centre(board)
    return np.column_stack([np.full(len(P), float(offset)), cx - P[:, 0], cy - P[:, 1]])


def sheet_pose(tilt_y_deg: float, turn_z_deg: float, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Commanded sheet pose (4, 4): the home sheet turned about z by ``turn_z_deg`` then tilted about y by
    ``tilt_y_deg`` (extrinsic axes), centred at ``origin`` (3,) m."""
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("zy", [turn_z_deg, tilt_y_deg], degrees=True).as_matrix()
    T[:3, 3] = np.asarray(origin, float)
    return T


def plan_board_views(n_views: int) -> list[np.ndarray]:
    """The first ``n_views`` commanded sheet poses (4, 4) of :data:`VIEW_PLAN` (home first). Raises
    ``ValueError`` outside 1…len(VIEW_PLAN)."""
    if not (1 <= n_views <= len(VIEW_PLAN)):
        raise ValueError(f"n_views must be in 1..{len(VIEW_PLAN)}, got {n_views!r}")
    return [sheet_pose(a, b, o) for a, b, o in VIEW_PLAN[:n_views]]


def load_prior(path: str = BOOTSTRAP_FILE, scale: float = 1.0) -> np.ndarray:
    """(24, 24) covariance of the stereo parameters (:func:`flexsheet.calibration.display_calib.stereo_vector`
    order) from a bootstrap JSON (``{"deviations": (n, 24)}``), times ``scale``². Raises ``ValueError`` on a
    bad file."""
    try:
        with open(path) as fh:
            D = np.asarray(json.load(fh)["deviations"], float)
    except (OSError, KeyError, TypeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not a stereo bootstrap file ({exc})") from None
    if D.ndim != 2 or D.shape[1] != 24 or len(D) < 5:
        raise ValueError(f"{path}: deviations must be (n >= 5, 24), got {D.shape}")
    return np.cov(D.T) * scale ** 2


@dataclass
class CameraPoseResult:
    """Result of :func:`estimate_camera_pose`.

    ``T_display_camera`` (4, 4) left optical frame in the display frame; ``stereo``: refined stereo dict;
    ``rms_px``: reprojection RMS over all corners and views; ``residual_mm``: RMS 3-D distance of the
    triangulated home corners from their design positions (mm); ``flatness_mm``: RMS of their out-of-plane
    component (mm); ``per_view_rms_px`` (n,); ``used``/``skipped`` view indices with reasons; ``cov`` (30,
    30): covariance of (the 24 stereo parameters, the home pose as display→left rotation vector and
    translation), the prior the projector step refines them under; ``sigma_px``: the corner σ the fit found;
    ``bow_mm``: the board's fitted bow (sag at the farthest corner toward the user, mm).
    """

    T_display_camera: np.ndarray
    stereo: dict
    rms_px: float
    residual_mm: float
    flatness_mm: float
    per_view_rms_px: np.ndarray
    n_views: int
    used: list[int] = field(default_factory=list)
    skipped: dict[int, str] = field(default_factory=dict)
    cov: np.ndarray | None = None
    sigma_px: float = 0.0
    bow_mm: float = 0.0


def _undist(model: StereoModel, uv: np.ndarray, side: str) -> np.ndarray:
    return model.undistort(uv, side)


def detect_corners(image: np.ndarray, board: BoardSpec, detector=None):
    """Board corners in one mono8 image: ``(ids (M,), corners (M, 2) px)`` or ``None`` if not found.

    Chessboards: ``cv2.findChessboardCorners`` then ``cv2.cornerSubPix`` with a window of 0.4× the smallest
    corner spacing (2…11 px; a fixed 11 px window reaches across the small, foreshortened squares of a board
    0.5 m away and pulls corners by several px). ChArUco:
    :func:`flexsheet.vision.stereo_calibration.detect_board`. Raises ``ValueError`` if ``image`` is not a 2-D
    uint8 array.
    """
    if not isinstance(image, np.ndarray) or image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError(f"image must be a (H, W) uint8 array, got {getattr(image, 'shape', type(image))}")
    if board.kind != "chessboard":
        return detect_board(image, board, detector)
    ok, c = cv2.findChessboardCorners(image, (board.cols, board.rows),
                                      flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok:
        return None
    g = c.reshape(board.rows, board.cols, 2)
    dmin = min(float(np.linalg.norm(np.diff(g, axis=0), axis=2).min()),
               float(np.linalg.norm(np.diff(g, axis=1), axis=2).min()))
    win = int(np.clip(round(0.4 * dmin), 2, 11))
    c = cv2.cornerSubPix(image, c, (win, win), (-1, -1),
                         (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4))
    return np.arange(len(c)), c.reshape(-1, 2)


def _orderings(board: BoardSpec, uv: np.ndarray) -> list[np.ndarray]:
    """The orderings a chessboard detection may come in (the detector orders by the image, not by the board):
    as is, turned 180°, and the two mirrors (plus the transposes for a square board)."""
    g = uv.reshape(board.rows, board.cols, 2)
    out = [g, g[::-1, ::-1], g[::-1, :], g[:, ::-1]]
    if board.rows == board.cols:
        out += [np.swapaxes(a, 0, 1) for a in list(out)]
    return [a.reshape(-1, 2).copy() for a in out]


def _facing(P: np.ndarray, uv: np.ndarray, K: np.ndarray, D: np.ndarray):
    """PnP pose of sheet-frame points P seen at uv; None unless the board's front (+x of the sheet frame)
    faces the camera. Returns (camera centre in the points' frame (3,), reprojection RMS px)."""
    ok, rv, tv = cv2.solvePnP(P, uv, K, D, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        return None
    ok, rv, tv = cv2.solvePnP(P, uv, K, D, rv, tv, useExtrinsicGuess=True)
    R = cv2.Rodrigues(rv)[0]
    C = -R.T @ tv.ravel()
    if (C - P.mean(axis=0))[0] <= 0.0:          # camera behind the board's printed face
        return None
    err = cv2.projectPoints(P, rv, tv, K, D)[0].reshape(-1, 2) - uv
    return C, float(np.sqrt(np.mean(np.sum(err ** 2, 1))))


def _order_left(board: BoardSpec, ul: np.ndarray, P: np.ndarray, st: dict, C_nominal: np.ndarray | None):
    """The left ordering whose PnP pose sees the board's front; at home (``C_nominal`` given) the one putting
    the camera nearest its nominal position."""
    best = None
    for cand in _orderings(board, ul):
        f = _facing(P, cand, st["K1"], st["D1"])
        if f is None:
            continue
        key = float(np.linalg.norm(f[0] - C_nominal)) if C_nominal is not None else f[1]
        if best is None or key < best[0]:
            best = (key, cand)
    return None if best is None else best[1]


def _order_right(board: BoardSpec, st: dict, P: np.ndarray, ul: np.ndarray, ur: np.ndarray) -> np.ndarray:
    """The right ordering nearest the prediction from the left PnP pose through the nominal stereo model (the
    epipolar constraint alone cannot tell a mirror along the epipolar lines)."""
    ok, rv, tv = cv2.solvePnP(P, ul, st["K1"], st["D1"], flags=cv2.SOLVEPNP_SQPNP)
    R = st["R"] @ cv2.Rodrigues(rv)[0]
    t = st["R"] @ tv.ravel() + np.asarray(st["T"], float).ravel()
    pred = cv2.projectPoints(P, cv2.Rodrigues(R)[0], t, st["K2"], st["D2"])[0].reshape(-1, 2)
    errs = [(float(np.median(np.linalg.norm(c - pred, axis=1))), i, c) for i,
            c in enumerate(_orderings(board, ur))]
    return min(errs, key=lambda e: (e[0], e[1]))[2]


def detect_views(views: list[tuple[np.ndarray, np.ndarray]], board: BoardSpec, stereo_nominal: dict,
                 T_dc_nominal: np.ndarray, offset: float = 0.0) -> tuple[list, dict[int, str]]:
    """Detect the board in every stereo pair. Returns (detections, skipped): ``detections[k]`` is ``None`` or
    ``(ids (M,), left (M, 2), right (M, 2))`` (corners seen in both images, consistently ordered),
    ``skipped`` maps a view index to the reason. Chessboard orderings are resolved (module doc)."""
    det = cv2.aruco.CharucoDetector(board.charuco_board()) if board.kind == "charuco" else None
    P_home = board_points(board, offset)
    out, skipped = [], {}
    for k, (left, right) in enumerate(views):
        dl, dr = detect_corners(left, board, det), detect_corners(right, board, det)
        if dl is None or dr is None:
            out.append(None)
            skipped[k] = "board not found in the " + " and ".join(
                s for s, d in (("left", dl), ("right", dr)) if d is None) + " image"
            continue
        ids_l, ul = dl[0], dl[1].astype(np.float64)
        ids_r, ur = dr[0], dr[1].astype(np.float64)
        if board.kind == "chessboard":
            ul = _order_left(board, ul, P_home, stereo_nominal, T_dc_nominal[:3, 3] if k == 0 else None)
            if ul is None:
                out.append(None)
                skipped[k] = "no corner ordering shows the board's front to the left camera"
                continue
            ur = _order_right(board, stereo_nominal, P_home, ul, ur)
            out.append((ids_l, ul, ur))
        else:
            common, ia, ib = np.intersect1d(ids_l, ids_r, return_indices=True)
            if len(common) < 6:
                out.append(None)
                skipped[k] = f"only {len(common)} ChArUco corners seen in both images"
                continue
            out.append((common, ul[ia], ur[ib]))
    return out, skipped


def _pose_vec(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.concatenate([cv2.Rodrigues(R)[0].ravel(), np.asarray(t, float).ravel()])


def _usable_views(views, board: BoardSpec, stereo_nominal: dict, T_dc_nominal: np.ndarray, offset: float,
                  min_views: int) -> tuple[list, dict[int, str], list[int]]:
    """The board detected in every view (:func:`detect_views`): (detections, skipped, used view indices).
    Raises ``ValueError`` (module doc) without the home view or with fewer than ``min_views`` usable views."""
    if not views:
        raise ValueError("no board views given (need the home view first)")
    if min_views < 1:
        raise ValueError(f"min_views must be >= 1, got {min_views!r}")
    dets, skipped = detect_views(views, board, stereo_nominal, T_dc_nominal, offset)
    if dets[0] is None:
        raise ValueError(f"board not found in the home view (view 0): {skipped.get(0)}; it defines the "
                         f"display frame — check the board is in view, lit and not occluded")
    used = [k for k, d in enumerate(dets) if d is not None]
    if len(used) < min_views:
        raise ValueError(f"board found in only {len(used)} of {len(views)} views, need at least {min_views}: "
                         f"{skipped}")
    return dets, skipped, used


def _start_vector(obs: list, s0: np.ndarray, stereo_nominal: dict, fit_bow: bool) -> np.ndarray:
    """x0: the nominal stereo parameters, each view's PnP pose with the nominal left intrinsics, no bow."""
    x0 = [s0]
    for P, ul, _ in obs:
        ok, rv, tv = cv2.solvePnP(P, ul, stereo_nominal["K1"], stereo_nominal["D1"])
        if not ok:
            raise ValueError("solvePnP failed on a board view")
        x0.append(np.concatenate([rv.ravel(), tv.ravel()]))
    if fit_bow:
        x0.append(np.zeros(1))
    return np.concatenate(x0)


def _prior_sqrt_inv(prior_cov: np.ndarray | None) -> np.ndarray | None:
    """L⁻¹ of the prior's (regularised) Cholesky factor, or None without a prior. ``ValueError`` on a bad
    one."""
    if prior_cov is None:
        return None
    C = np.asarray(prior_cov, float)
    if C.shape != (24, 24) or not np.all(np.isfinite(C)):
        raise ValueError(f"prior_cov must be a finite (24, 24) matrix, got {C.shape}")
    C = C + np.diag(np.maximum(np.diag(C), 1e-12) * 1e-6 + 1e-14)
    return np.linalg.inv(np.linalg.cholesky(C))


_EX = np.array([1.0, 0.0, 0.0])


class _BoardFit:
    """The stereo bundle adjustment's residuals and analytic Jacobian (module doc, step 3): parameters x = the
    24 stereo parameters, one pose (rotation vector, translation) per used view, and (``fit_bow``) the bow."""

    def __init__(self, obs: list, P_sheet: np.ndarray, size: tuple, s0: np.ndarray, Linv: np.ndarray | None,
                 fit_bow: bool):
        self.obs, self.size, self.s0, self.Linv, self.fit_bow = obs, size, s0, Linv, fit_bow
        self.n_res = sum(4 * len(P) for P, _, _ in obs)
        self.n_par = 24 + 6 * len(obs) + (1 if fit_bow else 0)
        self.n_pri = 24 if Linv is not None else 0
        r2 = [P[:, 1] ** 2 + P[:, 2] ** 2 for P, _, _ in obs]
        r2max = max(float(np.max(P_sheet[:, 1] ** 2 + P_sheet[:, 2] ** 2)), 1e-12)
        self.quad = [q / r2max for q in r2]                # 0 at the centre, 1 at the farthest corner

    def model(self, x: np.ndarray, sigma: float, want_jac: bool):
        """Residuals (n_res + n_pri,) and, if asked, their analytic Jacobian: ``cv2.projectPoints`` gives
        d(pixel)/d(pose, f, c, distortion); ``cv2.composeRT`` chains the right camera through R, T."""
        st = stereo_from_vector(x[:24], self.size)
        r = np.empty(self.n_res + self.n_pri)
        J = np.zeros((self.n_res + self.n_pri, self.n_par)) if want_jac else None
        row = 0
        bow = x[-1] if self.fit_bow else 0.0
        for k, (P0, ul, ur) in enumerate(self.obs):
            P = P0 + (bow * self.quad[k])[:, None] * _EX          # the bowed board
            row = self._left(x, st, k, P, ul, sigma, r, J, row)
            row = self._right(x, st, k, P, ur, sigma, r, J, row)
        if self.n_pri:
            r[row:] = self.Linv @ (x[:24] - self.s0)
            if want_jac:
                J[row:, :24] = self.Linv
        return r, J

    def _left(self, x, st, k, P, ul, sigma, r, J, row) -> int:
        n = len(P)
        cv = slice(24 + 6 * k, 30 + 6 * k)
        rv, tv = x[24 + 6 * k:27 + 6 * k], x[27 + 6 * k:30 + 6 * k]
        pl, jl = cv2.projectPoints(P, rv, tv, st["K1"], st["D1"])
        r[row:row + 2 * n] = ((pl.reshape(-1, 2) - ul) / sigma).ravel()
        if J is not None:
            J[row:row + 2 * n, cv] = jl[:, :6] / sigma
            J[row:row + 2 * n, 0:9] = jl[:, 6:15] / sigma
            if self.fit_bow:                               # d pixel / d X_cam = d pixel / d t
                dX = cv2.Rodrigues(rv.copy())[0] @ _EX
                J[row:row + 2 * n, -1] = (jl[:, 3:6] @ dX) * np.repeat(self.quad[k], 2) / sigma
        return row + 2 * n

    def _right(self, x, st, k, P, ur, sigma, r, J, row) -> int:
        n = len(P)
        cv = slice(24 + 6 * k, 30 + 6 * k)
        rv, tv = x[24 + 6 * k:27 + 6 * k], x[27 + 6 * k:30 + 6 * k]
        c = cv2.composeRT(rv, tv, x[18:21], x[21:24])
        pr, jr = cv2.projectPoints(P, c[0], c[1], st["K2"], st["D2"])
        r[row:row + 2 * n] = ((pr.reshape(-1, 2) - ur) / sigma).ravel()
        if J is not None:
            dr1, dt1, dr2, dt2, tr1, tt1, tr2, tt2 = c[2:10]
            A, B = jr[:, 0:3], jr[:, 3:6]                  # d pixel / d (r3, t3)
            J[row:row + 2 * n, cv] = np.hstack([A @ dr1 + B @ tr1, A @ dt1 + B @ tt1]) / sigma
            J[row:row + 2 * n, 18:21] = (A @ dr2 + B @ tr2) / sigma
            J[row:row + 2 * n, 21:24] = (A @ dt2 + B @ tt2) / sigma
            J[row:row + 2 * n, 9:18] = jr[:, 6:15] / sigma
            if self.fit_bow:
                dX = cv2.Rodrigues(c[0])[0] @ _EX
                J[row:row + 2 * n, -1] = (B @ dX) * np.repeat(self.quad[k], 2) / sigma
        return row + 2 * n

    def residuals(self, v: np.ndarray, sg: float) -> np.ndarray:
        return self.model(v, sg, False)[0]

    def solve(self, x0: np.ndarray) -> tuple[np.ndarray, float]:
        """Levenberg–Marquardt from ``x0``, σ re-estimated from the residuals and the fit repeated once: (x,
        σ)."""
        sigma = 0.1
        x = x0
        for _ in range(2):
            sol = least_squares(self.residuals, x, jac=lambda v, sg: self.model(v, sg, True)[1],
                                args=(sigma,),
                                method="lm", x_scale="jac", max_nfev=400)
            x = sol.x
            data = sol.fun[:self.n_res] * sigma
            dof = max(self.n_res + self.n_pri - self.n_par, 1)
            sigma = max(float(math.sqrt(data @ data / dof)), 0.01)
        return x, sigma

    def rms(self, x: np.ndarray) -> tuple[float, list[float]]:
        """Reprojection RMS per corner (px), over all views and per view."""
        data = self.residuals(x, 1.0)[:self.n_res]
        rms = float(np.sqrt(np.mean(data ** 2 * 2.0)))    # per corner (2 coordinates), px
        per_view, row = [], 0
        for P, _, _ in self.obs:
            d = data[row:row + 4 * len(P)]
            per_view.append(float(np.sqrt(np.mean(d ** 2) * 2.0)))
            row += 4 * len(P)
        return rms, per_view


def _home_residual(fit: _BoardFit, st: dict, T_dc: np.ndarray, bow: float) -> np.ndarray:
    """The home corners triangulated with the refined model, placed by the pose, minus their (bowed) design
    positions (N, 3) m."""
    P, ul, ur = fit.obs[0]
    P = P + (bow * fit.quad[0])[:, None] * _EX
    model = StereoModel.from_calib(st)
    Xl = model.triangulate(model.undistort(ul, "left"), model.undistort(ur, "right"), "optimal")
    Xd = Xl @ T_dc[:3, :3].T + T_dc[:3, 3]
    return Xd - P


def estimate_camera_pose(views: list[tuple[np.ndarray, np.ndarray]], board: BoardSpec, stereo_nominal: dict,
                         T_dc_nominal: np.ndarray, *, offset: float = 0.0,
                         prior_cov: np.ndarray | None = None,
                         min_views: int = 3, max_rms_px: float = 0.6, fit_bow: bool = True,
                         max_bow_mm: float = 1.0) -> CameraPoseResult:
    """Estimate the stereo camera's pose in the display frame (module doc).

    ``views``: stereo pairs (left, right) mono8 (H, W); ``views[0]`` at the home pose, the others at any
    poses. ``stereo_nominal``: the stereo calibration dict to start from (``image_size``, K1, D1, K2, D2, R,
    T); ``T_dc_nominal`` (4, 4): the design mount (resolves the chessboard's 180° ambiguity; error tolerated ≲
    10 cm). ``offset`` m: see :func:`board_points`. ``prior_cov`` (24, 24): covariance of the nominal stereo
    parameters (:func:`load_prior`); ``None`` fits them without a prior (needs many, varied views).
    ``min_views``: usable views required (home included). ``fit_bow``: also fit the board's bow (one
    parameter: a paraboloid sag, m at the farthest corner, toward the user) — a bow of 0.25 mm otherwise costs
    0.9 mm of camera pose (the views fit a flat board just as well with other intrinsics); a fitted bow above
    ``max_bow_mm`` is refused. Raises ``ValueError`` (see module doc).
    """
    dets, skipped, used = _usable_views(views, board, stereo_nominal, T_dc_nominal, offset, min_views)
    size = tuple(stereo_nominal["image_size"])
    s0 = stereo_vector(stereo_nominal)
    P_sheet = board_points(board, offset)                  # = display coordinates at home
    obs = []
    for k in used:
        ids, ul, ur = dets[k]
        obs.append((P_sheet[ids], ul, ur))
    # starting poses: PnP with the nominal left intrinsics
    x0 = _start_vector(obs, s0, stereo_nominal, fit_bow)
    fit = _BoardFit(obs, P_sheet, size, s0, _prior_sqrt_inv(prior_cov), fit_bow)
    x, sigma = fit.solve(x0)
    # covariance of (stereo 24, home pose 6) from the final Jacobian (residuals are σ-normalised)
    J = fit.model(x, sigma, True)[1]
    cov = np.linalg.pinv(J.T @ J)[:30, :30]
    rms, per_view = fit.rms(x)
    if rms > max_rms_px:
        raise ValueError(f"board fit RMS {rms:.3f} px > {max_rms_px} px (per view "
                         f"{np.round(per_view, 3).tolist()}): is the board flat on the sheet and still "
                         "during each capture?")
    st = stereo_from_vector(x[:24], size)
    R_cd = cv2.Rodrigues(x[24:27])[0]
    t_cd = x[27:30]
    T_dc = np.eye(4)
    T_dc[:3, :3] = R_cd.T
    T_dc[:3, 3] = -R_cd.T @ t_cd
    bow = float(x[-1]) if fit_bow else 0.0
    if abs(bow) * 1e3 > max_bow_mm:
        raise ValueError(f"the board is bowed by {bow * 1e3:.2f} mm at its farthest corner (> {max_bow_mm} "
                         f"mm): fix it flat on a rigid plate (docs/calibration.md)")
    err = _home_residual(fit, st, T_dc, bow)               # triangulated home corners vs design
    return CameraPoseResult(T_dc, st, rms, float(np.sqrt(np.mean(np.sum(err ** 2, 1)))) * 1e3,
                            float(np.sqrt(np.mean(err[:, 0] ** 2))) * 1e3, np.array(per_view), len(used),
                            used,
                            skipped, cov, sigma, bow * 1e3)
