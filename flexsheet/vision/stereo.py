"""Two-view geometry of a calibrated stereo pair: undistortion, epipolar residual, triangulation, covariance.

Frames and units: 3-D points are in the **left camera optical frame** (OpenCV: +z forward, +x right,
+y down), m. Image points are px. "Ideal" pixels are undistorted pixels of the same camera matrix
(``cv2.undistortPoints(..., P=K)``), in which the pinhole model holds exactly.

Triangulation methods (Hartley & Zisserman, *Multiple View Geometry*, 2nd ed., ch. 12):

* ``"dlt"``: linear homogeneous DLT (§12.2) via ``cv2.triangulatePoints`` on P1 = K1 [I | 0],
  P2 = K2 [R | T].
* ``"optimal"``: Hartley–Sturm optimal correction (§12.5) via ``cv2.correctMatches`` with the fundamental
  matrix F = K2⁻ᵀ [T]× R K1⁻¹ — moves both points the least (in the image, L2) onto a pair of epipolar
  lines — followed by DLT (then exact, since the corrected rays intersect).
* ``"midpoint"``: midpoint of the common perpendicular of the two back-projected rays (§12.1).

Covariance (H&Z §5.2.3, backward propagation): with the 4×3 Jacobian J of the two projections at the
estimate X and isotropic pixel noise σ on each of the four image coordinates,
Σ_X = σ² (Jᵀ J)⁻¹ (m²). Distortion is neglected in J (its Jacobian is within a few % of identity for the
mild lenses modelled here).
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["METHODS", "StereoModel", "skew"]

METHODS = ("dlt", "optimal", "midpoint")


def skew(t: np.ndarray) -> np.ndarray:
    """Cross-product matrix [t]× (3, 3) of a (3,) vector (so that [t]× v = t × v)."""
    return np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])


class StereoModel:
    """A calibrated stereo pair (OpenCV conventions: x_right = R x_left + T).

    Parameters
    ----------
    K1, K2 : (3, 3) camera matrices, px.  D1, D2 : (5,) distortion (k1, k2, p1, p2, k3).
    R : (3, 3) rotation left→right.  T : (3,) translation left→right, m.
    image_size : (width, height), px.

    Raises ``ValueError`` naming the field on a wrong shape, non-finite entry or a zero baseline.
    """

    def __init__(self, K1, D1, K2, D2, R, T, image_size):
        arrs = {}
        for name, v, shape in (("K1", K1, (3, 3)), ("K2", K2, (3, 3)), ("R", R, (3, 3)), ("T", T, (3,)),
                               ("D1", D1, None), ("D2", D2, None)):
            a = np.asarray(v, np.float64)
            a = a.ravel() if shape in (None, (3,)) else a
            if (shape is not None and a.shape != shape) or not np.all(np.isfinite(a)):
                raise ValueError(f"{name} must be a finite array of shape {shape or '(5,)'}, got {a!r}")
            arrs[name] = a
        if np.linalg.norm(arrs["T"]) < 1e-6:
            raise ValueError(f"T must be a non-zero baseline, got {arrs['T']!r}")
        self.K1, self.K2, self.R, self.T = arrs["K1"], arrs["K2"], arrs["R"], arrs["T"]
        self.D1 = np.zeros(5)
        self.D1[:min(5, arrs["D1"].size)] = arrs["D1"][:5]
        self.D2 = np.zeros(5)
        self.D2[:min(5, arrs["D2"].size)] = arrs["D2"][:5]
        self.image_size = (int(image_size[0]), int(image_size[1]))
        self.P1 = self.K1 @ np.hstack([np.eye(3), np.zeros((3, 1))])
        self.P2 = self.K2 @ np.hstack([self.R, self.T.reshape(3, 1)])
        self.E = skew(self.T) @ self.R
        self.F = np.linalg.inv(self.K2).T @ self.E @ np.linalg.inv(self.K1)
        self.F /= np.linalg.norm(self.F)
        self.K1inv, self.K2inv = np.linalg.inv(self.K1), np.linalg.inv(self.K2)
        self.C2 = -self.R.T @ self.T               # right camera centre in the left frame, m
        self.baseline = float(np.linalg.norm(self.T))
        self.focal = float(0.5 * (self.K1[0, 0] + self.K1[1, 1]))
        self._rvec0 = np.zeros(3)
        self._rvec2 = cv2.Rodrigues(self.R)[0].ravel()

    @classmethod
    def from_calib(cls, calib) -> StereoModel:
        """Build from a calibration dict (:func:`flexsheet.vision.calib_yaml.load_yaml`) or a
        :class:`messages.StereoCalibration` (anything with K1, D1, K2, D2, R, T, image_size)."""
        get = (lambda k: calib[k]) if isinstance(calib, dict) else (lambda k: getattr(calib, k))
        return cls(get("K1"), get("D1"), get("K2"), get("D2"), get("R"), get("T"), get("image_size"))

    # --- projection ------------------------------------------------------------------------------------
    def project(self, X: np.ndarray, distort: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Project points X (N, 3) m, left camera frame, into both images.

        Returns (uv_left, uv_right), each (N, 2) px: with lens distortion (raw images) when ``distort``,
        else ideal pixels. Points behind a camera give meaningless pixels (check depth yourself).
        """
        X = np.ascontiguousarray(np.asarray(X, np.float64).reshape(-1, 3))
        if distort:
            ul = cv2.projectPoints(X, self._rvec0, np.zeros(3), self.K1, self.D1)[0].reshape(-1, 2)
            ur = cv2.projectPoints(X, self._rvec2, self.T, self.K2, self.D2)[0].reshape(-1, 2)
            return ul, ur
        xl = X @ self.P1[:, :3].T + self.P1[:, 3]
        xr = X @ self.P2[:, :3].T + self.P2[:, 3]
        return xl[:, :2] / xl[:, 2:], xr[:, :2] / xr[:, 2:]

    def undistort(self, uv: np.ndarray, side: str) -> np.ndarray:
        """Raw pixels (N, 2) of camera ``side`` ("left"/"right") → ideal pixels (N, 2)
        (``cv2.undistortPoints`` with P = K). Raises ``ValueError`` for another side."""
        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        K, D = (self.K1, self.D1) if side == "left" else (self.K2, self.D2)
        pts = np.asarray(uv, np.float64).reshape(-1, 1, 2)
        return cv2.undistortPoints(pts, K, D, P=K).reshape(-1, 2)

    # --- epipolar geometry -----------------------------------------------------------------------------
    def epipolar_residual(self, ul: np.ndarray, ur: np.ndarray) -> np.ndarray:
        """First-order geometric (Sampson) distance of ideal-pixel matches (N, 2), (N, 2) from the epipolar
        constraint x_rᵀ F x_l = 0 (H&Z eq. 11.9). Returns (N,) px: the norm of the least 4-vector correction
        (u_l, v_l, u_r, v_r) that satisfies it, to first order (δ/√2 for a vertical offset δ on a rectified
        rig; 0 for an exact match)."""
        ul = np.asarray(ul, np.float64).reshape(-1, 2)
        ur = np.asarray(ur, np.float64).reshape(-1, 2)
        xl = np.hstack([ul, np.ones((len(ul), 1))])
        xr = np.hstack([ur, np.ones((len(ur), 1))])
        Fx = xl @ self.F.T
        Ftx = xr @ self.F
        num = np.einsum("ij,ij->i", xr, Fx)
        den = Fx[:, 0] ** 2 + Fx[:, 1] ** 2 + Ftx[:, 0] ** 2 + Ftx[:, 1] ** 2
        return np.abs(num) / np.sqrt(np.maximum(den, 1e-300))

    # --- triangulation ---------------------------------------------------------------------------------
    def triangulate(self, ul: np.ndarray, ur: np.ndarray, method: str = "optimal") -> np.ndarray:
        """Triangulate ideal-pixel matches ul, ur (N, 2) px → X (N, 3) m in the left camera frame.

        ``method``: "dlt", "optimal" or "midpoint" (module doc). Raises ``ValueError`` on an unknown method
        or mismatched shapes. Points at infinity come back with huge or non-finite coordinates: callers
        gate on depth.
        """
        ul = np.ascontiguousarray(np.asarray(ul, np.float64).reshape(-1, 2))
        ur = np.ascontiguousarray(np.asarray(ur, np.float64).reshape(-1, 2))
        if ul.shape != ur.shape:
            raise ValueError(f"ul and ur must have the same shape, got {ul.shape} and {ur.shape}")
        if method == "dlt":
            return self._dlt(ul, ur)
        if method == "optimal":
            cl, cr = cv2.correctMatches(self.F, ul.reshape(1, -1, 2), ur.reshape(1, -1, 2))
            return self._dlt(cl.reshape(-1, 2), cr.reshape(-1, 2))
        if method == "midpoint":
            return self._midpoint(ul, ur)
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")

    def _dlt(self, ul: np.ndarray, ur: np.ndarray) -> np.ndarray:
        Xh = cv2.triangulatePoints(self.P1, self.P2, ul.T.copy(), ur.T.copy())
        with np.errstate(divide="ignore", invalid="ignore"):
            return (Xh[:3] / Xh[3]).T

    def _midpoint(self, ul: np.ndarray, ur: np.ndarray) -> np.ndarray:
        n = len(ul)
        d1 = np.hstack([ul, np.ones((n, 1))]) @ self.K1inv.T              # rays in the left frame
        d2 = (np.hstack([ur, np.ones((n, 1))]) @ self.K2inv.T) @ self.R   # = R^T K2^-1 x, rows
        w0 = -self.C2                                                      # C1 - C2 with C1 = 0
        a = np.einsum("ij,ij->i", d1, d1)
        b = np.einsum("ij,ij->i", d1, d2)
        c = np.einsum("ij,ij->i", d2, d2)
        d = d1 @ w0
        e = d2 @ w0
        den = a * c - b * b
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (b * e - c * d) / den
            t = (a * e - b * d) / den
        return 0.5 * (s[:, None] * d1 + (self.C2 + t[:, None] * d2))

    def jacobian(self, X: np.ndarray) -> np.ndarray:
        """Jacobian of the ideal-pixel projections (u_l, v_l, u_r, v_r) w.r.t. X, (N, 4, 3) px/m."""
        X = np.asarray(X, np.float64).reshape(-1, 3)
        J = np.empty((len(X), 4, 3))
        for k, P in enumerate((self.P1, self.P2)):
            h = X @ P[:, :3].T + P[:, 3]                       # (N, 3)
            u = h[:, :2] / h[:, 2:]
            J[:, 2 * k:2 * k + 2,
              :] = ((P[None, :2, :3] - u[:, :, None] * P[None, 2:3, :3]) / h[:, 2, None, None])
        return J

    def covariance(self, X: np.ndarray, sigma_px: float) -> np.ndarray:
        """First-order covariance (N, 3, 3) m² of triangulated points X (N, 3) for isotropic pixel noise
        ``sigma_px`` (px, > 0) on each image coordinate: σ² (Jᵀ J)⁻¹ (H&Z result 5.10).
        Raises ``ValueError`` if sigma_px is not positive and finite."""
        if not (np.isfinite(sigma_px) and sigma_px > 0):
            raise ValueError(f"sigma_px must be positive and finite, got {sigma_px!r}")
        J = self.jacobian(X)
        JtJ = np.einsum("nki,nkj->nij", J, J)
        return sigma_px ** 2 * np.linalg.inv(JtJ)

    def depth_floor(self, Z: float, sigma_px: float) -> float:
        """Theoretical depth standard deviation (m) of a rectified pair at depth Z (m) with per-coordinate
        pixel noise σ: ΔZ = Z² · √2 σ / (f B) (disparity noise σ_d = √2 σ; H&Z §12.6 / Gallup et al.)."""
        return Z * Z * np.sqrt(2.0) * sigma_px / (self.focal * self.baseline)
