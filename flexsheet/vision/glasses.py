"""Tracking the viewer's stereo glasses with one head camera: a board of ArUco markers on the glasses' bar,
its pose by PnP, the eyes from that pose (library; no I/O).

* :class:`GlassesBoard`: the rigid grid of ArUco markers printed on the bar above the lenses and its pose in
  the glasses frame. OpenCV's board frame (``cv2.aruco.GridBoard``): origin at the top-left corner of the
  first marker, x along a printed row, y down the printed columns, z = x × y *into* the paper; a camera sees
  the printed face (and reads the markers) when it looks along +z of the board. The markers face the sheet
  and the head camera beside it, so the board's z is the glasses' −z: ``R_glasses_board = diag(1, −1, −1)``
  (board x = glasses x, from the right lens to the left; printed rows run left to right as the camera sees
  them, top row up).
* :class:`GlassesTracker`: detects the markers (``cv2.aruco.ArucoDetector``; corners by edge-line fits),
  solves the board pose from all detected corners (planar IPPE, both solutions, each refined by
  Levenberg–Marquardt; the lower reprojection error wins), and gives ``T_display_glasses`` and the eyes
  (:func:`tracked_eyes`).
* :class:`HeadPredictor`: constant-velocity extrapolation of the eyes to the photon time.

Frames: ``display`` (:mod:`flexsheet.model.geometry`); ``glasses`` (:mod:`flexsheet.calibration.eye`: x from
the right lens to the left lens, y up, z = x × y toward the sheet when worn); the camera's OpenCV optical
frame (+z forward, +x right, +y down). Units m, rad, s; image coordinates px (pixel centres at integers).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from flexsheet.model.checks import check_point, check_pose, check_positive

#: the glasses axes (columns, display frame) of a viewer upright and facing the
#: sheet (−x): x toward the viewer's left (−y), y up (+z), z toward the sheet (−x)
GLASSES_AXES = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

__all__ = ["GLASSES_AXES", "tracked_eyes", "GlassesBoard", "GlassesPose", "GlassesTracker", "HeadPredictor",
           "check_camera_matrix", "check_dist"]

_R_GLASSES_BOARD = np.diag([1.0, -1.0, -1.0])
_DIST_LENGTHS = (4, 5, 8, 12, 14)
_DICTIONARIES = frozenset(getattr(cv2.aruco, n) for n in dir(cv2.aruco) if n.startswith("DICT_"))


@functools.lru_cache(maxsize=16)
def _dictionary(dictionary: int):
    return cv2.aruco.getPredefinedDictionary(dictionary)


@functools.lru_cache(maxsize=16)
def _grid_board(dictionary: int, rows: int, cols: int, marker: float, gap: float, first_id: int):
    ids = np.arange(first_id, first_id + rows * cols, dtype=np.int32)
    return cv2.aruco.GridBoard((cols, rows), marker, gap, _dictionary(dictionary), ids)


@dataclass(frozen=True)
class GlassesBoard:
    """The ArUco grid board printed on the glasses' bar above the lenses (module doc for its frame).

    ``dictionary``: a ``cv2.aruco.DICT_*`` id; ``rows`` × ``cols`` markers of side ``marker`` m, ``gap`` m
    apart, ids ``first_id`` … ``first_id + rows·cols − 1`` row by row (row 0 on top). The board's centre sits
    ``height`` m above the glasses origin (+y of the glasses), in the glasses' x-y plane, face toward +z of
    the glasses. Defaults: DICT_4X4_50, 2 × 7 markers of 12 mm with 3 mm gaps (board 0.102 × 0.027 m), ids
    0–13, 30 mm above the glasses origin. Raises ``ValueError`` naming the bad field.
    """

    dictionary: int = cv2.aruco.DICT_4X4_50
    rows: int = 2
    cols: int = 7
    marker: float = 0.012
    gap: float = 0.003
    first_id: int = 0
    height: float = 0.030

    def __post_init__(self):
        for name in ("rows", "cols", "first_id"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or v < (0 if name == "first_id" else 1):
                raise ValueError(f"{name} must be an integer >= {0 if name == 'first_id' else 1}, got {v!r}")
        check_positive("marker", self.marker)
        check_positive("gap", self.gap)
        if not isinstance(self.height, (int, float, np.floating)) or not np.isfinite(self.height):
            raise ValueError(f"height must be finite (m), got {self.height!r}")
        if not isinstance(self.dictionary, (int, np.integer)) or int(self.dictionary) not in _DICTIONARIES:
            raise ValueError(f"dictionary must be a cv2.aruco.DICT_* id, got {self.dictionary!r}")
        n = len(_dictionary(int(self.dictionary)).bytesList)
        if self.first_id + self.rows * self.cols > n:
            raise ValueError(f"first_id + rows·cols must be <= {n} (dictionary size), got first_id="
                             f"{self.first_id}, rows={self.rows}, cols={self.cols}")

    @property
    def count(self) -> int:
        """Number of markers N."""
        return self.rows * self.cols

    @property
    def size(self) -> tuple[float, float]:
        """(width, height) of the printed grid, m (0.102, 0.027 by default)."""
        return (self.cols * self.marker + (self.cols - 1) * self.gap,
                self.rows * self.marker + (self.rows - 1) * self.gap)

    @property
    def cells(self) -> int:
        """Modules along a marker's side, its one-module black border included (6 for 4×4 markers)."""
        return int(_dictionary(int(self.dictionary)).markerSize) + 2

    @property
    def ids(self) -> np.ndarray:
        """Marker ids (N,) int, in board order."""
        return np.arange(self.first_id, self.first_id + self.count)

    @property
    def T_glasses_board(self) -> np.ndarray:
        """Pose (4, 4) of the OpenCV board frame in the glasses frame: R = diag(1, −1, −1), the board's centre
        at (0, ``height``, 0) m."""
        w, h = self.size
        T = np.eye(4)
        T[:3, :3] = _R_GLASSES_BOARD
        T[:3, 3] = np.array([0.0, self.height, 0.0]) - _R_GLASSES_BOARD @ np.array([w / 2, h / 2, 0.0])
        return T

    def cv_board(self):
        """The ``cv2.aruco.GridBoard`` (cached; do not modify it)."""
        return _grid_board(int(self.dictionary), self.rows, self.cols, float(self.marker), float(self.gap),
                           int(self.first_id))

    def object_points_board(self) -> np.ndarray:
        """Marker corners (4·N, 3) m in the OpenCV board frame, marker id then corner order (top-left,
        top-right, bottom-right, bottom-left as printed: ArUco's corner order)."""
        return np.asarray(self.cv_board().getObjPoints(), float).reshape(-1, 3)

    def object_points_glasses(self) -> np.ndarray:
        """Marker corners (4·N, 3) m in the glasses frame, marker id then corner order."""
        T = self.T_glasses_board
        return self.object_points_board() @ T[:3, :3].T + T[:3, 3]

    def image(self, px_per_m: float) -> tuple[np.ndarray, np.ndarray]:
        """The printed board with a white margin one ``gap`` wide, at ``px_per_m`` px/m: (image (H, W) uint8,
        black 0 / white 255, each pixel the exact white fraction of its area (equal to
        ``cv_board().generateImage`` where the cells fall on whole pixels); ``A`` (3, 3) mapping a pixel (u,
        v, 1) (pixel centres at integers) to board metres (x, y, 1): x = (u + 0.5)/px_per_m − gap, same for
        y). Raises ``ValueError`` unless 100 ≤ px_per_m ≤ 1e5."""
        ppm = check_positive("px_per_m", px_per_m)
        if not 100.0 <= ppm <= 1e5:
            raise ValueError(f"px_per_m must be in [100, 1e5] px/m, got {px_per_m!r}")
        w, h = self.size
        W = int(math.ceil((w + 2 * self.gap) * ppm - 1e-9))
        H = int(math.ceil((h + 2 * self.gap) * ppm - 1e-9))
        nb = self.cells
        cell = self.marker / nb

        def overlap(n: int, count: int) -> np.ndarray:
            """(n, count·nb): the fraction of pixel i (along one axis) that cell j covers."""
            a = np.arange(n)[:, None] / ppm - self.gap                      # pixel starts, board metres
            s = ((np.arange(count) * (self.marker + self.gap))[:, None] + np.arange(nb) * cell).ravel()[None,
                                                                                                        :]
            return np.clip(np.minimum(s + cell, a + 1.0 / ppm) - np.maximum(s, a), 0.0, None) * ppm

        bits = np.stack(
            [cv2.aruco.generateImageMarker(_dictionary(int(self.dictionary)), int(i), nb, borderBits=1)
             for i in self.ids]).reshape(self.rows, self.cols, nb, nb)
        black = (bits == 0).transpose(0, 2, 1, 3).reshape(self.rows * nb, self.cols * nb).astype(float)
        cover = overlap(H, self.rows) @ black @ overlap(W, self.cols).T                # exact black area
        img = np.clip(np.round(255.0 * (1.0 - cover)), 0, 255).astype(np.uint8)
        A = np.array([[1.0 / ppm, 0.0, 0.5 / ppm - self.gap], [0.0, 1.0 / ppm, 0.5 / ppm - self.gap],
                      [0, 0, 1]])
        return img, A


def tracked_eyes(T_display_glasses: np.ndarray, eye_offset, ipd: float):
    """(left, right, V) eye positions (3,) m in the display frame for glasses at ``T_display_glasses`` (4, 4):
    V = T · eye_offset (3,) m (the cyclopean eye in the glasses frame), left/right = V ± ipd/2 · (glasses x
    axis). Raises ``ValueError`` on a bad pose, offset or an ipd outside [0, 0.1] m."""
    T = check_pose("T_display_glasses", T_display_glasses)
    V = T[:3, :3] @ check_point("eye_offset", eye_offset) + T[:3, 3]
    if not (np.isfinite(ipd) and 0.0 <= ipd <= 0.1):
        raise ValueError(f"ipd must be in [0, 0.1] m, got {ipd!r}")
    h = 0.5 * float(ipd) * T[:3, 0]
    return V + h, V - h, V


@dataclass(frozen=True, eq=False)
class GlassesPose:
    """One tracked glasses pose: ``T_display_glasses`` (4, 4); eyes ``left``, ``right`` and cyclopean ``V``
    (3,) m, display frame; ``markers``: board markers used; ``reprojection_px``: RMS reprojection error of
    their corners, px."""

    T_display_glasses: np.ndarray
    left: np.ndarray
    right: np.ndarray
    V: np.ndarray
    markers: int
    reprojection_px: float


def check_camera_matrix(K) -> np.ndarray:
    """``K`` as a (3, 3) camera matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]], fx, fy > 0; else
    ``ValueError``."""
    try:
        A = np.asarray(K, float)
    except (TypeError, ValueError):
        raise ValueError(f"camera_matrix must be a finite (3, 3) matrix, got {K!r}") from None
    if A.shape != (3, 3) or not np.all(np.isfinite(A)):
        raise ValueError(f"camera_matrix must be a finite (3, 3) matrix, got shape {A.shape}")
    if A[0, 0] <= 0 or A[1, 1] <= 0 or np.abs(A[2] - (0, 0, 1)).max() > 1e-9 or A[1, 0] != 0:
        raise ValueError(f"camera_matrix must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got "
                         f"{A.tolist()}")
    return A


def check_dist(D) -> np.ndarray:
    """OpenCV distortion coefficients (4/5/8/12/14 finite; None: five zeros); else ``ValueError``."""
    if D is None:
        return np.zeros(5)
    try:
        a = np.asarray(D, float).ravel()
    except (TypeError, ValueError):
        raise ValueError(f"dist must be None or 4/5/8/12/14 finite OpenCV coefficients, got {D!r}") from None
    if len(a) not in _DIST_LENGTHS or not np.all(np.isfinite(a)):
        raise ValueError(f"dist must be None or 4/5/8/12/14 finite OpenCV coefficients, got {D!r}")
    return a


_EDGE_FRAC = (0.3, 0.5, 0.7)  # profiles per inner cell along a marker edge (cell fractions)
_EDGE_T = np.linspace(-2.5, 2.5, 21)                 # offsets across the edge, px (outward +)
_EDGE_SIGMA = 1.0                                    # mean-shift window σ, px (at most 0.45 of a module)


def _edge_samples(board: GlassesBoard) -> tuple[np.ndarray, np.ndarray]:
    """Where each marker edge's profile is sampled: (fractions s (S,) along the edge, in the inner cells;
    usable (N, 4, S) bool: the inner cell beside the border there is black, so the black border is two cells
    deep and the next edge is far from the one measured)."""
    nb = board.cells
    j = np.repeat(np.arange(1, nb - 1), len(_EDGE_FRAC))
    s = (j + np.tile(_EDGE_FRAC, nb - 2)) / nb
    use = np.zeros((board.count, 4, len(s)), bool)
    for i, mid in enumerate(board.ids):
        b = cv2.aruco.generateImageMarker(_dictionary(int(board.dictionary)), int(mid), nb, borderBits=1) == 0
        use[i] = [b[1, j], b[j, nb - 2], b[nb - 2, nb - 1 - j], b[nb - 1 - j, 1]]
    return s, use


def _edge_corners(gray: np.ndarray, corners: np.ndarray, K: np.ndarray, D: np.ndarray, edge_s: np.ndarray,
                  usable: np.ndarray, cells: int, origin=(0, 0)) -> np.ndarray:
    """Marker corners (M, 4, 2) px (ArUco order, raw image) refined by straight-edge fits; ``gray`` is the
    raw image's part whose top-left pixel is ``origin`` (x, y) px (it must hold every edge profile's reach).

    Each outer edge of each marker is located across its length at the fractions ``edge_s`` (S,) of the
    initial ``corners`` (M, 4, 2) px (``cells`` modules a side), where ``usable`` (M, 4, S) (else at all of
    them): the mode of the brightness gradient across the edge (mean shift with a Gaussian window, so a
    symmetric blur gives no bias).
    The points are undistorted (``K``, ``D``), fitted with lines, and the lines intersected. Unlike a corner
    detector's window fit (``cornerSubPix``), this has no inward bias at a blurred convex corner (≈ 0.3 px on
    20 px markers). Markers whose edges cannot be fitted keep their input corners."""
    M = len(corners)
    c = corners.astype(np.float64)
    d = np.roll(c, -1, axis=1) - c                                     # (M, 4, 2) edge k: corner k -> k+1
    L = np.linalg.norm(d, axis=2, keepdims=True)
    u = d / np.maximum(L, 1e-9)
    n = np.stack([u[..., 1], -u[..., 0]], -1)
    mid = c + 0.5 * d
    n *= np.sign(np.sum(n * (mid - c.mean(1, keepdims=True)), -1, keepdims=True))   # outward
    p = c[:, :, None, :] + edge_s[None, None, :, None] * d[:, :, None, :]           # (M, 4, S, 2)
    q = p[..., None, :] + _EDGE_T[:, None] * n[:, :, None, None, :]                  # (M, 4, S, T, 2)
    prof = cv2.remap(gray, (q[..., 0] - origin[0]).reshape(-1, len(_EDGE_T)).astype(np.float32),
                     (q[..., 1] - origin[1]).reshape(-1, len(_EDGE_T)).astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE).reshape(M, 4, len(edge_s), len(_EDGE_T))
    g = np.clip(np.gradient(prof, _EDGE_T, axis=-1), 0.0, None)                      # dark inside, bright out
    sig = np.minimum(_EDGE_SIGMA, 0.45 * L[..., 0] / cells)[:, :, None, None]          # (M, 4, 1, 1) px
    t = _EDGE_T[np.argmax(np.where(np.abs(_EDGE_T) <= 2.0, g, -1.0), axis=-1)]      # (M, 4, S)
    k = -0.5 / sig ** 2
    # mean shift: a symmetric window, so a symmetric edge is unbiased. Its weight g·exp(k (T − t)²) is
    # g·exp(k T²) · r^j · (a factor of the profile alone, which cancels), r = exp(−2 k t ΔT),
    # T_j = T_0 + j ΔT: one exp per profile and a running product, not one exp per sample.
    # The last step is the direct form (its weight sum is the one the edge test below reads).
    gk = g * np.exp(k * _EDGE_T ** 2)
    step = -2.0 * k[..., 0] * (_EDGE_T[1] - _EDGE_T[0])                              # (M, 4, 1)
    for _ in range(5):
        # (M, 4, S, 1); |exponent| ≤ 14: r^21 stays finite
        r = np.exp(np.clip(step * t, -14.0, 14.0))[..., None]
        w = gk * np.cumprod(np.broadcast_to(r, g.shape), axis=-1)
        t = (w @ _EDGE_T) / np.maximum(w.sum(-1), 1e-300)
    d = _EDGE_T - t[..., None]
    w = g * np.exp(d * d * k)
    sw = w.sum(-1)
    t = (w @ _EDGE_T) / np.maximum(sw, 1e-12)
    gm = g.max(-1)
    ok = (sw > 1e-6) & (np.abs(t) < 2.0) & (gm > 0.25 * np.median(gm))
    ok &= usable | (np.sum(ok & usable, axis=-1, keepdims=True) < 4)
    e = (p + t[..., None] * n[:, :, None, :]).reshape(-1, 1, 2)
    e = cv2.undistortPoints(e, K, D).reshape(M, 4, len(edge_s), 2)                # normalised coordinates
    wk = ok.astype(np.float64)                                                       # (M, 4, S)
    cnt = wk.sum(-1)
    ctr = (wk[..., None] * e).sum(2) / np.maximum(cnt, 1.0)[..., None]                # (M, 4, 2)
    r = (e - ctr[:, :, None, :]) * wk[..., None]
    _, vec = np.linalg.eigh(np.einsum("mksi,mksj->mkij", r, r))                       # ascending eigenvalues
    nrm = vec[..., :, 0]                                                              # line normals (M, 4, 2)
    lines = np.concatenate([nrm, -np.sum(nrm * ctr, -1, keepdims=True)], -1)         # a x + b y + c = 0
    X = np.cross(np.roll(lines, 1, axis=1), lines)                                   # corner k: edges k-1, k
    good = np.all(cnt >= 4, axis=1) & np.all(np.abs(X[..., 2]) > 1e-12, axis=1)
    out = c.copy()
    if np.any(good):
        xy = X[good, :, :2] / X[good, :, 2:]
        xyz = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], -1).reshape(-1, 3)
        out[good] = cv2.projectPoints(xyz, np.zeros(3), np.zeros(3), K, D)[0].reshape(-1, 4, 2)
    return out


class GlassesTracker:
    """Glasses pose and eyes from one head-camera image (module doc).

    ``camera_matrix`` (3, 3) px and ``dist`` (5,) OpenCV distortion (None: none; 4, 8, 12 or 14 coefficients
    also accepted) of the head camera; ``T_display_camera`` (4, 4): its optical frame in the display frame;
    ``board``: :class:`GlassesBoard`; ``eye_offset`` (3,) m: the cyclopean eye in the glasses frame; ``ipd``
    m in [0, 0.1]; ``min_markers``: fewest board markers that give a pose (1 … N). Raises ``ValueError``
    naming the bad argument.
    """

    def __init__(self, camera_matrix, dist, T_display_camera, board: GlassesBoard, eye_offset, ipd: float,
                 min_markers: int = 3):
        self.K = check_camera_matrix(camera_matrix)
        self.D = check_dist(dist)
        self.T_display_camera = check_pose("T_display_camera", T_display_camera, tol=1e-6)
        self.board = board
        if not isinstance(board, GlassesBoard):
            raise ValueError(f"board must be a GlassesBoard, got {board!r}")
        self.eye_offset = check_point("eye_offset", eye_offset)
        if not (isinstance(ipd, (int, float, np.floating)) and np.isfinite(ipd) and 0.0 <= ipd <= 0.1):
            raise ValueError(f"ipd must be in [0, 0.1] m, got {ipd!r}")
        self.ipd = float(ipd)
        if not isinstance(min_markers, (int, np.integer)) or not 1 <= min_markers <= self.board.count:
            raise ValueError(f"min_markers must be an integer in [1, {self.board.count}], got "
                             f"{min_markers!r}")
        self.min_markers = int(min_markers)
        params = cv2.aruco.DetectorParameters()
        # no corner refinement here: the edge-line fit (_edge_corners) replaces the corners
        # (cornerSubPix's were biased ~0.3 px inward on these ~20 px markers, and refining first changed
        # nothing: 0.19 mm median eye error either way, 0.1 ms a frame saved)
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
        params.perspectiveRemovePixelPerCell = 8  # small markers (~20 px): read the bits at cell centres
        params.perspectiveRemoveIgnoredMarginPerCell = 0.25
        self.detector = cv2.aruco.ArucoDetector(_dictionary(int(self.board.dictionary)), params)
        self._T_board_glasses = np.linalg.inv(self.board.T_glasses_board)
        self._roi: tuple[float, float, float, float] | None = None    # where the last pose's markers were
        self._edge_s, self._edge_use = _edge_samples(self.board)

    def detect(self, image: np.ndarray, roi=None) -> tuple[np.ndarray, np.ndarray]:
        """The board's markers in ``image`` (H, W) uint8 (or (H, W, 3) BGR): (ids (M,) int, sorted; corners
        (M, 4, 2) px, ArUco corner order, full-image coordinates). ``roi`` (x0, y0, x1, y1) px: search only
        there. Other ids are dropped. Raises ``ValueError`` on a bad image."""
        img = np.asarray(image)
        if img.dtype != np.uint8 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
            raise ValueError(f"image must be a uint8 (H, W) or (H, W, 3) array, got {img.dtype} {img.shape}")
        if img.ndim == 3:
            img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        x0, y0 = 0, 0
        if roi is not None:                  # search the region only (detection costs ~ its area)
            x0, y0, x1, y1 = (int(v) for v in roi)
            x0, y0 = max(x0, 0), max(y0, 0)
            corners, ids, _ = self.detector.detectMarkers(img[y0:max(y1, y0 + 1), x0:max(x1, x0 + 1)])
        else:
            corners, ids, _ = self.detector.detectMarkers(img)
        if ids is None or len(ids) == 0:
            return np.zeros(0, int), np.zeros((0, 4, 2))
        ids = ids.ravel().astype(int)
        c = np.asarray(corners, float).reshape(-1, 4, 2) + (x0, y0)
        keep = (ids >= self.board.first_id) & (ids < self.board.first_id + self.board.count)
        ids, c = ids[keep], c[keep]
        # a duplicated id (a reflection, a second pair of glasses) makes the correspondence ambiguous: drop it
        uniq, counts = np.unique(ids, return_counts=True)
        single = np.isin(ids, uniq[counts == 1])
        ids, c = ids[single], c[single]
        order = np.argsort(ids)
        ids, c = ids[order], c[order]
        if len(ids):            # the edge profiles read only the markers' box (+ the profile's reach, 2.5 px)
            h, w = img.shape
            (bx0, by0), (bx1, by1) = (np.floor(c.reshape(-1, 2).min(0)) - 4,
                                      np.ceil(c.reshape(-1, 2).max(0)) + 5)
            bx0, by0 = int(min(max(bx0, 0), w - 1)), int(min(max(by0, 0), h - 1))
            bx1, by1 = int(min(max(bx1, bx0 + 1), w)), int(min(max(by1, by0 + 1), h))
            c = _edge_corners(img[by0:by1, bx0:bx1].astype(np.float32), c, self.K, self.D, self._edge_s,
                              self._edge_use[ids - self.board.first_id], self.board.cells, origin=(bx0, by0))
        return ids, c

    def _solve(self, obj: np.ndarray, img: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
        """Best board pose (rvec, tvec, RMS px) over the IPPE solutions, each refined (LM); the mirror
        solution is skipped when IPPE finds it over 2× + 0.5 px worse than the first."""
        best = None
        try:
            n, rvecs, tvecs, err = cv2.solvePnPGeneric(obj, img, self.K, self.D, flags=cv2.SOLVEPNP_IPPE)
        except cv2.error:
            return None
        e = np.asarray(err, float).ravel()
        if n == 2 and len(e) == 2 and e[1] > 2.0 * e[0] + 0.5:
            n = 1               # the mirror solution far worse (IPPE sorts them): refining it cannot win
        for rv, tv in zip(rvecs[:n], tvecs[:n], strict=True):
            rv, tv = cv2.solvePnPRefineLM(obj, img, self.K, self.D, rv.copy(), tv.copy())
            proj, _ = cv2.projectPoints(obj, rv, tv, self.K, self.D)
            rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
            if float(tv[2, 0]) > 0 and (best is None or rms < best[2]):
                best = (rv, tv, rms)
        return best

    def track(self, image: np.ndarray) -> GlassesPose | None:
        """Glasses pose and eyes from one image (H, W) uint8 (display frame, m), or None when fewer than
        ``min_markers`` board markers are found or PnP fails. Raises ``ValueError`` on a bad image.

        After a frame with a pose, the next search is the region around its markers (their box grown by its
        own size each way, ≥ 40 px), and the whole image only when that finds too few."""
        ids, corners = self.detect(image, self._roi) if self._roi is not None else (np.zeros(0, int), None)
        if len(ids) < self.min_markers:
            ids, corners = self.detect(image)
        self._roi = None
        if len(ids) < self.min_markers:
            return None
        lo, hi = corners.reshape(-1, 2).min(0), corners.reshape(-1, 2).max(0)
        grow = np.maximum(hi - lo, 40.0)
        self._roi = (*(lo - grow), *(hi + grow))
        obj = self.board.object_points_board().reshape(-1, 4, 3)[ids - self.board.first_id].reshape(-1, 3)
        sol = self._solve(obj, corners.reshape(-1, 2))
        if sol is None:
            return None
        rv, tv, rms = sol
        T_cb = np.eye(4)
        T_cb[:3, :3] = cv2.Rodrigues(rv)[0]
        T_cb[:3, 3] = tv.ravel()
        T = self.T_display_camera @ T_cb @ self._T_board_glasses
        left, right, V = tracked_eyes(T, self.eye_offset, self.ipd)
        return GlassesPose(T, left, right, V, int(len(ids)), rms)


class HeadPredictor:
    """Constant-velocity prediction of the eyes to the photon time.

    :meth:`update` takes time-stamped :class:`GlassesPose` s; the eye velocity (m/s) is the finite difference
    of the last two accepted poses, exponentially smoothed: v ← ``smoothing``·v_new + (1 − ``smoothing``)·v
    (``smoothing`` in (0, 1]; 1: no smoothing; the first difference initialises v). :meth:`predict`
    extrapolates linearly, by at most ``max_extrapolation`` s. After a gap longer than ``max_gap`` s between
    poses the eyes are held still until the next difference restarts the velocity. Raises ``ValueError`` on
    bad parameters.
    """

    def __init__(self, smoothing: float = 0.5, max_extrapolation: float = 0.1, max_gap: float = 0.25):
        self.smoothing = check_positive("smoothing", smoothing)
        if self.smoothing > 1.0:
            raise ValueError(f"smoothing must be in (0, 1], got {smoothing!r}")
        self.max_extrapolation = check_positive("max_extrapolation", max_extrapolation, allow_zero=True)
        self.max_gap = check_positive("max_gap", max_gap)
        self.stamp: float | None = None
        self.eyes: np.ndarray | None = None            # (3, 3): left, right, V rows, m, display frame
        self.velocity: np.ndarray | None = None        # (3, 3) m/s, same rows

    def update(self, stamp: float, pose: GlassesPose) -> bool:
        """Accept ``pose`` seen at ``stamp`` s. Returns False (pose ignored) unless ``stamp`` is later than
        the last accepted one. Raises ``ValueError`` on a non-finite stamp or a non-finite pose."""
        t = float(stamp)
        if not np.isfinite(t):
            raise ValueError(f"stamp must be finite (s), got {stamp!r}")
        eyes = np.array([pose.left, pose.right, pose.V], float)
        if eyes.shape != (3, 3) or not np.all(np.isfinite(eyes)):
            raise ValueError(f"pose eyes must be finite (3,) points, got {eyes.tolist()}")
        if self.stamp is not None and t <= self.stamp:
            return False
        if self.stamp is None or t - self.stamp > self.max_gap:
            self.velocity = None                       # at rest until the next difference
        else:
            v = (eyes - self.eyes) / (t - self.stamp)
            a = self.smoothing
            self.velocity = v if self.velocity is None else a * v + (1.0 - a) * self.velocity
        self.stamp, self.eyes = t, eyes
        return True

    def predict(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(left, right, V) (3,) m, display frame, extrapolated to time ``t`` s (clamped to [0,
        ``max_extrapolation``] s after the last pose); None before the first pose. Raises ``ValueError`` on
        a non-finite ``t``."""
        if not np.isfinite(float(t)):
            raise ValueError(f"t must be finite (s), got {t!r}")
        if self.stamp is None:
            return None
        dt = min(max(float(t) - self.stamp, 0.0), self.max_extrapolation)
        p = self.eyes if self.velocity is None else self.eyes + dt * self.velocity
        return p[0].copy(), p[1].copy(), p[2].copy()
