"""Stereo calibration from image pairs of a chessboard or ChArUco board, and its OpenCV FileStorage YAML.

``flexsheet calibrate stereo --left GLOB --right GLOB --board chessboard:9x6 --square 0.024 -o calib.yaml``

Method (Zhang's method as implemented by OpenCV, *Learning OpenCV 3*, ch. 18–19):

1. Board corners per image: ``cv2.findChessboardCorners`` + ``cv2.cornerSubPix`` for chessboards, or
   opencv-contrib 5's ``cv2.aruco.CharucoDetector.detectBoard`` + ``CharucoBoard.matchImagePoints`` for
   ChArUco boards (only corners seen in *both* images of a pair are kept). A pair whose board is not found
   in both images is skipped and reported.
2. Intrinsics of each camera alone: ``cv2.calibrateCamera`` (5-term distortion k1, k2, p1, p2, k3).
3. Extrinsics with the intrinsics fixed: ``cv2.stereoCalibrateExtended(flags=CALIB_FIX_INTRINSIC)``,
   which also returns the per-pair RMS reprojection errors (px) so a user can drop bad pairs.
4. Rectification: ``cv2.stereoRectify`` (R1, R2, P1, P2, Q; alpha = 0).

Output: an OpenCV FileStorage YAML with ``image_size`` (width, height), ``K1, D1, K2, D2, R, T`` (T in m),
``E, F, R1, R2, P1, P2, Q``, ``rms_left_px``, ``rms_right_px``, ``rms_px`` (stereo), ``per_pair_rms_px``
(N, 2), the used/skipped pair names and, optionally, ``T_display_camera`` (4, 4): the left camera's pose
in the display frame. :func:`load_yaml` reads it back into a dict of numpy arrays, and
:func:`to_message` turns it into a :class:`messages.StereoCalibration`.

Validation (``--validate FOLDS``, :func:`validate_stereo`): k-fold cross-validation over the pairs — each fold
is calibrated without its pairs, then judged on them: the held-out **epipolar error** (Sampson distance of
the held-out corners, px; scale-free: it checks the intrinsics, R and the direction of T) and the held-out
**square spread** (the held-out corners triangulated with that fold's calibration: the spread of the
adjacent-corner distances over the boards and against depth). The square's absolute size cannot be
validated from the images: it scales T, and every triangulated length, by the same factor. A baseline
"check" against a length that was itself inferred from |T| would be circular, so none is made.

Board specs: ``chessboard:COLSxROWS`` (inner corners; square side from ``--square``, m) or
``charuco:NXxNY:SQUARE:MARKER:DICT`` (squares per side, square and marker side in m, an
``cv2.aruco.DICT_*`` name, e.g. ``charuco:5x7:0.04:0.03:DICT_4X4_50``).
"""

from __future__ import annotations

import argparse
import glob
import json
import os
from dataclasses import dataclass, field

import cv2
import numpy as np

from flexsheet.vision.calib_yaml import write_yaml
from flexsheet.vision.stereo import StereoModel
from messages import StereoCalibration

__all__ = ["BoardSpec", "parse_board", "detect_board", "StereoCalibrationResult", "calibrate_stereo",
           "validate_stereo", "to_message", "main"]

_SUBPIX = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)


@dataclass(frozen=True)
class BoardSpec:
    """A calibration target. ``kind`` "chessboard" or "charuco"; ``cols``, ``rows``: inner corners
    (chessboard) or squares (ChArUco) along x and y; ``square`` m; ``marker`` m (ChArUco only);
    ``dictionary``: ``cv2.aruco`` dictionary name (ChArUco only)."""

    kind: str
    cols: int
    rows: int
    square: float
    marker: float = 0.0
    dictionary: str = ""

    def object_points(self) -> np.ndarray:
        """All board corners in the board frame, (N, 3) float32, m (z = 0). Chessboard order is OpenCV's
        (row-major, x fastest); ChArUco order is the corner-id order of ``CharucoBoard``."""
        if self.kind == "chessboard":
            obj = np.zeros((self.cols * self.rows, 3), np.float32)
            obj[:, :2] = np.mgrid[0:self.cols, 0:self.rows].T.reshape(-1, 2) * self.square
            return obj
        return np.asarray(self.charuco_board().getChessboardCorners(), np.float32).reshape(-1, 3)

    def charuco_board(self) -> cv2.aruco.CharucoBoard:
        """The ``cv2.aruco.CharucoBoard`` (opencv-contrib 5 API). Raises ``ValueError`` for a chessboard."""
        if self.kind != "charuco":
            raise ValueError(f"board kind must be 'charuco' for a CharucoBoard, got {self.kind!r}")
        dic = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.cols, self.rows), self.square, self.marker, dic)


def parse_board(spec: str, square: float | None = None) -> BoardSpec:
    """Parse a board spec string (see module doc). ``square`` (m) is required for chessboards.

    Raises ``ValueError`` naming the spec on any malformed part (unknown kind, bad size, non-positive
    square/marker, marker ≥ square, unknown dictionary).
    """
    parts = spec.split(":")
    kind = parts[0].lower()

    def size(text: str) -> tuple[int, int]:
        try:
            c, r = (int(v) for v in text.lower().split("x"))
        except ValueError:
            raise ValueError(f"board size must look like 9x6, got {text!r} in board spec {spec!r}") from None
        if c < 2 or r < 2:
            raise ValueError(f"board size must be at least 2x2, got {text!r} in board spec {spec!r}")
        return c, r

    if kind == "chessboard" and len(parts) == 2:
        c, r = size(parts[1])
        if square is None or not (square > 0 and np.isfinite(square)):
            raise ValueError(f"square must be a positive side length in m for a chessboard, got {square!r}")
        return BoardSpec("chessboard", c, r, float(square))
    if kind == "charuco" and len(parts) == 5:
        c, r = size(parts[1])
        try:
            sq, mk = float(parts[2]), float(parts[3])
        except ValueError:
            raise ValueError(f"charuco square/marker must be numbers in m, got {parts[2]!r}, "
                             f"{parts[3]!r}") from None
        if not (0 < mk < sq):
            raise ValueError(f"charuco needs 0 < marker < square, got square={sq}, marker={mk}")
        if not parts[4].startswith("DICT_") or not hasattr(cv2.aruco, parts[4]):
            raise ValueError(f"unknown aruco dictionary {parts[4]!r} in board spec {spec!r}")
        return BoardSpec("charuco", c, r, sq, mk, parts[4])
    raise ValueError("board spec must be 'chessboard:COLSxROWS' or 'charuco:NXxNY:SQUARE:MARKER:DICT', got "
                     f"{spec!r}")


def detect_board(image: np.ndarray, board: BoardSpec,
                 detector: cv2.aruco.CharucoDetector | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """Find the board in one mono8 image (H, W).

    Returns ``(ids, corners)``: ids (N,) int of the board corners found and their subpixel image positions
    (N, 2) float32 px, or ``None`` when the board is not found. Raises ``ValueError`` if ``image`` is not a
    2-D uint8 array.
    """
    if not isinstance(image, np.ndarray) or image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError(f"image must be a (H, W) uint8 array, got {getattr(image, 'shape', type(image))}")
    if board.kind == "chessboard":
        ok, corners = cv2.findChessboardCorners(
            image, (board.cols, board.rows),
            flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not ok:
            return None
        corners = cv2.cornerSubPix(image, corners, (11, 11), (-1, -1), _SUBPIX)
        return np.arange(len(corners)), corners.reshape(-1, 2)
    det = detector or cv2.aruco.CharucoDetector(board.charuco_board())
    ch_corners, ch_ids, _, _ = det.detectBoard(image)
    if ch_ids is None or len(ch_ids) < 6:
        return None
    return ch_ids.ravel().astype(int), ch_corners.reshape(-1, 2).astype(np.float32)


@dataclass
class StereoCalibrationResult:
    """Result of :func:`calibrate_stereo`: every array of the YAML (see module doc) plus bookkeeping.

    ``per_pair_rms_px`` (N, 2): RMS reprojection error of each used pair (left, right), px;
    ``used``/``skipped``: pair names; ``skipped_reason``: name → why.
    """

    image_size: tuple[int, int]
    K1: np.ndarray
    D1: np.ndarray
    K2: np.ndarray
    D2: np.ndarray
    R: np.ndarray
    T: np.ndarray
    E: np.ndarray
    F: np.ndarray
    R1: np.ndarray
    R2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    Q: np.ndarray
    rms_left_px: float
    rms_right_px: float
    rms_px: float
    per_pair_rms_px: np.ndarray
    used: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    skipped_reason: dict[str, str] = field(default_factory=dict)

    def as_dict(self) -> dict:
        """Plain dict of the calibration (numpy arrays and scalars), the shape :func:`write_yaml` takes."""
        return {k: getattr(self, k) for k in ("image_size", "K1", "D1", "K2", "D2", "R", "T", "E", "F", "R1",
                                              "R2", "P1", "P2", "Q", "rms_left_px", "rms_right_px", "rms_px",
                                              "per_pair_rms_px", "used", "skipped")}


def calibrate_stereo(left: list[np.ndarray], right: list[np.ndarray], board: BoardSpec,
                     names: list[str] | None = None, min_pairs: int = 3) -> StereoCalibrationResult:
    """Calibrate a stereo pair from images of a board (method in the module doc).

    ``left``, ``right``: equal-length lists of mono8 images (H, W), all the same size; ``names``: a label per
    pair for the report (default "pair00"…). Raises ``ValueError`` on mismatched lists or image sizes, or
    when fewer than ``min_pairs`` pairs show the board in both images.
    """
    if len(left) != len(right):
        raise ValueError(f"left and right must have the same number of images, got {len(left)} and "
                         f"{len(right)}")
    names = names or [f"pair{i:02d}" for i in range(len(left))]
    if not left:
        raise ValueError("no image pairs given")
    h, w = left[0].shape[:2]
    det = cv2.aruco.CharucoDetector(board.charuco_board()) if board.kind == "charuco" else None
    all_obj = board.object_points()
    obj_pts, l_pts, r_pts, used, skipped, reasons = [], [], [], [], [], {}
    for name, a, b in zip(names, left, right, strict=True):
        for side, img in (("left", a), ("right", b)):
            if img.shape[:2] != (h, w):
                raise ValueError(f"image size of {name} {side} is {img.shape[1]}x{img.shape[0]}, expected "
                                 f"{w}x{h}")
        da, db = detect_board(a, board, det), detect_board(b, board, det)
        if da is None or db is None:
            skipped.append(name)
            reasons[name] = "board not found in " + " and ".join(
                s for s, d in (("left", da), ("right", db)) if d is None)
            continue
        common, ia, ib = np.intersect1d(da[0], db[0], return_indices=True)
        if len(common) < 6:
            skipped.append(name)
            reasons[name] = f"only {len(common)} common corners"
            continue
        obj_pts.append(all_obj[common].astype(np.float32))
        l_pts.append(da[1][ia].reshape(-1, 1, 2))
        r_pts.append(db[1][ib].reshape(-1, 1, 2))
        used.append(name)
    if len(used) < min_pairs:
        raise ValueError(f"board found in both images of only {len(used)} pairs, need at least {min_pairs}: "
                         f"{reasons}")
    size = (w, h)
    rms1, K1, D1, _, _ = cv2.calibrateCamera(obj_pts, l_pts, size, None, None)
    rms2, K2, D2, _, _ = cv2.calibrateCamera(obj_pts, r_pts, size, None, None)
    out = cv2.stereoCalibrateExtended(obj_pts, l_pts, r_pts, K1, D1, K2, D2, size, None, None,
                                      flags=cv2.CALIB_FIX_INTRINSIC)
    rms, K1, D1, K2, D2, R, T, E, F = out[:9]
    per_view = np.asarray(out[-1], float).reshape(-1, 2)
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(K1, D1, K2, D2, size, R, T, alpha=0)
    return StereoCalibrationResult(
        image_size=size, K1=K1, D1=D1.ravel()[:5].copy(), K2=K2, D2=D2.ravel()[:5].copy(), R=R, T=T.ravel(),
        E=E, F=F, R1=R1, R2=R2, P1=P1, P2=P2, Q=Q, rms_left_px=float(rms1), rms_right_px=float(rms2),
        rms_px=float(rms), per_pair_rms_px=per_view, used=used, skipped=skipped, skipped_reason=reasons)


def validate_stereo(left: list[np.ndarray], right: list[np.ndarray], board: BoardSpec, folds: int = 0,
                    names: list[str] | None = None) -> dict:
    """Held-out validation of :func:`calibrate_stereo` (k-fold over the pairs; module doc).

    ``folds``: number of folds (≥ 2; 0 = leave-one-out). Pairs are dealt to folds in turn (pair i → fold
    i mod k); each fold's pairs are held out, the others calibrated, and on every held-out pair whose board is
    found in both images: the **epipolar** residual of its corners (Sampson distance of the undistorted
    corners under the fold's F, px) and, triangulated with the fold's calibration (optimal method), the
    distances between adjacent corners along both board axes and the corners' mean depth.

    Returns a dict: ``folds``, ``pairs`` (used), ``epipolar_rms_px`` / ``epipolar_p95_px`` (held out, all
    corners), ``square_mean_m``, ``square_std_rel`` (std of all held-out adjacent distances / their mean),
    ``square_pair_spread_rel`` (max − min of the per-pair means / mean), ``square_depth_slope_rel_per_m``
    (least-squares slope of per-pair mean square size against depth, relative, 1/m) and ``per_pair``
    (name → epipolar RMS px, mean square m, depth m). Source: cross-validation as in Hastie, Tibshirani &
    Friedman, *The Elements of Statistical Learning*, §7.10. Raises ``ValueError`` when fewer than 4 pairs
    show the board, folds is 1 or larger than the pairs, or a fold leaves fewer than 3 pairs to calibrate.
    """
    if len(left) != len(right):
        raise ValueError(f"left and right must have the same number of images, got {len(left)} and "
                         f"{len(right)}")
    names = names or [f"pair{i:02d}" for i in range(len(left))]
    det = cv2.aruco.CharucoDetector(board.charuco_board()) if board.kind == "charuco" else None
    found = []
    for i, (a, b) in enumerate(zip(left, right, strict=True)):
        da, db = detect_board(a, board, det), detect_board(b, board, det)
        if da is not None and db is not None:
            found.append((i, da, db))
    n = len(found)
    if n < 4:
        raise ValueError(f"board found in both images of only {n} pairs, need >= 4 to validate")
    k = n if folds == 0 else int(folds)
    if not (2 <= k <= n):
        raise ValueError(f"folds must be 0 (leave-one-out) or in 2..{n}, got {folds!r}")
    obj = board.object_points()
    eps, sq_all, per = [], [], {}
    for f in range(k):
        held = [found[j] for j in range(n) if j % k == f]
        keep = [found[j][0] for j in range(n) if j % k != f]
        if len(keep) < 3:
            raise ValueError(f"fold {f} leaves only {len(keep)} pairs to calibrate, need >= 3")
        res = calibrate_stereo([left[i] for i in keep], [right[i] for i in keep], board)
        m = StereoModel.from_calib(res.as_dict())
        for i, da, db in held:
            common, ia, ib = np.intersect1d(da[0], db[0], return_indices=True)
            ul = m.undistort(da[1][ia], "left")
            ur = m.undistort(db[1][ib], "right")
            e = m.epipolar_residual(ul, ur)
            X = m.triangulate(ul, ur, "optimal")
            # adjacent corners along the board's x and y axes (ids whose board points are one square apart)
            P = obj[common]
            d = []
            for u in range(len(P)):
                for v in range(u + 1, len(P)):
                    if abs(np.linalg.norm(P[u] - P[v]) - board.square) < 1e-6 * board.square + 1e-9:
                        d.append(float(np.linalg.norm(X[u] - X[v])))
            eps.append(e)
            sq_all += d
            per[names[i]] = {"epipolar_rms_px": float(np.sqrt(np.mean(e ** 2))),
                             "square_mean_m": float(np.mean(d)),
                             "depth_m": float(np.mean(X[:, 2]))}
    e = np.concatenate(eps)
    sq = np.asarray(sq_all)
    means = np.array([p["square_mean_m"] for p in per.values()])
    depth = np.array([p["depth_m"] for p in per.values()])
    slope = float(np.polyfit(depth, means / sq.mean(), 1)[0]) if np.ptp(depth) > 1e-6 else 0.0
    return {"folds": k, "pairs": n, "epipolar_rms_px": float(np.sqrt(np.mean(e ** 2))),
            "epipolar_p95_px": float(np.percentile(e, 95)), "square_mean_m": float(sq.mean()),
            "square_std_rel": float(sq.std() / sq.mean()),
            "square_pair_spread_rel": float(np.ptp(means) / sq.mean()), "square_depth_slope_rel_per_m": slope,
            "per_pair": per}


def to_message(calib: dict, header, T_display_camera: np.ndarray | None = None):
    """Build a :class:`messages.StereoCalibration` from a calibration dict (:func:`load_yaml`).

    ``header``: the :class:`messages.Header`; ``T_display_camera`` (4, 4) m overrides the dict's (identity
    when neither gives one). Raises pydantic ``ValidationError`` (a ``ValueError``) on bad shapes.
    """
    T_dc = T_display_camera if T_display_camera is not None else calib.get("T_display_camera", np.eye(4))
    f64 = lambda k: np.ascontiguousarray(np.asarray(calib[k], np.float64))  # noqa: E731
    return StereoCalibration(
        header=header,
        image_size=np.array([int(calib["image_size"][0]), int(calib["image_size"][1])], np.int64),
        K1=f64("K1"), D1=f64("D1").ravel(), K2=f64("K2"), D2=f64("D2").ravel(), R=f64("R"),
        T=f64("T").ravel(),
        R1=f64("R1"), R2=f64("R2"), P1=f64("P1"), P2=f64("P2"), Q=f64("Q"),
        T_display_camera=np.ascontiguousarray(np.asarray(T_dc, np.float64)),
        rms_px=float(calib.get("rms_px", 0.0)))


def main(argv: list[str] | None = None) -> int:
    """CLI ``flexsheet calibrate stereo`` (argparse; see ``--help``). Returns the exit code."""
    p = argparse.ArgumentParser(
        prog="flexsheet calibrate stereo", description="Stereo calibration from chessboard or ChArUco image "
                                                       "pairs.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example:\n  flexsheet calibrate stereo --left 'tests/data/stereo_xi/left*.jpg' "
               "--right 'tests/data/stereo_xi/right*.jpg' --board chessboard:9x6 --square 0.024 -o "
               "calib.yaml --validate 0")
    p.add_argument("--left", required=True, help="glob of left images (sorted by name)")
    p.add_argument("--right", required=True, help="glob of right images (sorted by name, same count)")
    p.add_argument("--board", default="chessboard:9x6",
                   help="chessboard:COLSxROWS (inner corners) or charuco:NXxNY:SQUARE:MARKER:DICT")
    p.add_argument("--square", type=float, default=None, help="chessboard square side, m")
    p.add_argument("-o", "--output", required=True, help="output FileStorage YAML")
    p.add_argument("--camera-pose", default=None,
                   help="optional left-camera pose in the display frame as 'x,y,z,rx,ry,rz' (m, Rodrigues "
                        "rad)")
    p.add_argument("--validate", type=int, default=None, metavar="FOLDS",
                   help="also cross-validate: held-out epipolar error and square spread over FOLDS folds "
                        "(0 = leave-one-out)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    a = p.parse_args(argv)
    lefts, rights = sorted(glob.glob(a.left)), sorted(glob.glob(a.right))
    if not lefts or len(lefts) != len(rights):
        p.error(f"--left matched {len(lefts)} files and --right {len(rights)}; need the same non-zero count")
    try:
        board = parse_board(a.board, a.square)
        imgs_l = [_read(f) for f in lefts]
        imgs_r = [_read(f) for f in rights]
        names = [os.path.basename(f) for f in lefts]
        res = calibrate_stereo(imgs_l, imgs_r, board, names)
    except ValueError as e:
        p.error(str(e))
    d = res.as_dict()
    if a.camera_pose:
        v = [float(x) for x in a.camera_pose.split(",")]
        T = np.eye(4)
        T[:3, :3] = cv2.Rodrigues(np.array(v[3:6]))[0]
        T[:3, 3] = v[:3]
        d["T_display_camera"] = T
    write_yaml(a.output, d)
    val = None
    if a.validate is not None:
        try:
            val = validate_stereo(imgs_l, imgs_r, board, a.validate, names)
        except ValueError as e:
            p.error(str(e))
    report = {"output": a.output, "pairs": len(lefts), "used": len(res.used), "skipped": res.skipped_reason,
              "rms_left_px": res.rms_left_px, "rms_right_px": res.rms_right_px, "stereo_rms_px": res.rms_px,
              "baseline_m": float(np.linalg.norm(res.T)), "T_m": res.T.tolist(),
              "fx_left_px": float(res.K1[0, 0]),
              "per_pair_rms_px": {n: [round(float(x), 4) for x in e] for n,
                                  e in zip(res.used, res.per_pair_rms_px, strict=False)}}
    if val is not None:
        report["validation"] = val
    if a.json:
        print(json.dumps(report, indent=1))
    else:
        print(f"stereo RMS {res.rms_px:.4f} px (left {res.rms_left_px:.4f}, right {res.rms_right_px:.4f}); "
              f"|T| = {report['baseline_m'] * 1000:.2f} mm; fx = {report['fx_left_px']:.1f} px; "
              f"{len(res.used)}/{len(lefts)} pairs used")
        for n, e in zip(res.used, res.per_pair_rms_px, strict=False):
            print(f"  {n:16s} left {e[0]:.4f} px  right {e[1]:.4f} px")
        for n, why in res.skipped_reason.items():
            print(f"  skipped {n}: {why}")
        if val is not None:
            print(f"held out ({val['folds']} folds, {val['pairs']} pairs): epipolar RMS "
                  f"{val['epipolar_rms_px']:.3f} px "
                  f"(p95 {val['epipolar_p95_px']:.3f}); square {val['square_mean_m'] * 1e3:.2f} mm, spread "
                  f"{val['square_std_rel'] * 100:.2f} % (per pair {val['square_pair_spread_rel'] * 100:.2f} "
                  f"%, depth slope {val['square_depth_slope_rel_per_m'] * 100:.2f} %/m); the square's "
                  "absolute size is the --square you gave (not checkable from images)")
        print(f"wrote {a.output}")
    return 0


def _read(path: str) -> np.ndarray:
    img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise ValueError(f"cannot read image {path!r}")
    return img
