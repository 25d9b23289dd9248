"""Per-frame fingertip pipeline: detect → match (epipolar) → triangulate → covariance → gate → predict.

Pure module (no I/O); :class:`nodes.triangulator.node.TriangulatorNode` wraps it.

Per stereo pair (raw mono8 images of the calibrated size):

1. :class:`~flexsheet.vision.detect.MarkerDetector` finds up to K bright-dot candidates per image in an
   ROI around the last marker position (full frame on loss or at start).
2. Candidates are undistorted and every left/right pair is checked against the epipolar constraint
   (Sampson distance ≤ ``epipolar_tol_px``); surviving pairs are triangulated
   (:class:`~flexsheet.vision.stereo.StereoModel`, method ``dlt``/``optimal``/``midpoint``) and must lie
   in front of the camera within [``z_min``, ``z_max``] m.
3. Choice among survivors: with a live track, the one nearest the Kalman prediction; without, the
   strongest — unless a second pair nearly as strong (≥ ``ambiguity_ratio``) lies more than
   ``ambiguity_m`` away (e.g. a reflection on the epipolar line): then the frame is *ambiguous* → invalid.
   A pair must also have the marker's size: each view's visible area (Σα, :mod:`.detect`) within a factor
   ``size_ratio_max`` of π(f·d/2Z)², the disk a marker of diameter ``marker_diameter`` makes at the
   triangulated depth Z — a clutter blob that happens to lie on the epipolar line rarely does
   (with the marker hidden by the finger, such pairs were accepted 100 mm off).
4. Partial occlusion check: the marker blob's area (Σα) must agree between the views
   within ``area_ratio_max`` (a blob cut by an occluder has a centroid shifted along the epipolar line).
5. Covariance σ²(JᵀJ)⁻¹, rotated into the display frame with ``T_display_camera``. The pixel noise σ is
   measured from the data (:class:`PixelNoise`: the RMS epipolar residual of the accepted matches;
   ``sigma_px`` is only its prior until enough frames have been seen).
6. Outlier gate: squared Mahalanobis distance from the constant-velocity Kalman prediction
   (:class:`~flexsheet.vision.predict.ConstantVelocityKF`) ≤ ``gate_chi2`` (χ²₃; 16.27 = 99.9 %), scaled by
   the measured mean normalised innovation² of the accepted fixes over 3 when it exceeds 3 (covariance
   matching, Mehra 1972: a smooth filter does not model the finger's tremor and turns, so the raw gate would
   reject true fixes; docs/planner.md). The filter's process noise is set by its tracking index λ = σ_w·T²/σ_v
   (Kalata 1984; Bar-Shalom et al. §6.5): q = λ²·σ_v²/T³ with σ_v² the mean variance of the measured position
   (from step 5) and T the measured frame interval, so the filter smooths the same whatever the camera's noise
   or rate. A fix outside that gate is tested again under a manoeuvre: process noise q = a²T for a finger
   accelerating at ``manoeuvre_accel`` a (the peak of a minimum-jerk reach, 5.77·D/T², Flash & Hogan 1985: 4.7
   m/s² for 0.1 m in 0.35 s), inside the same gate; it is then accepted and fused with that q, so the track
   follows the finger into and out of a reach instead of refusing it (the smooth filter lags an acceleration
   by several of its σ). A reflection or a clutter blob ≥ ``ambiguity_m`` off stays outside both gates. After
   ``max_gate_misses`` consecutive rejections the track is reset (the next fix is accepted), so a wrong track
   cannot lock out the true marker. A track not updated for ``lost_reset_s`` is reset.
7. Output: valid fix with position (display frame, m), covariance (m²) and the position predicted
   ``horizon_s`` ahead — or invalid with a reason and a zero position (never stale or invented).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flexsheet.model.checks import check_pose
from flexsheet.vision.detect import MarkerDetector, check_image
from flexsheet.vision.predict import ConstantVelocityKF, q_for_tracking_index
from flexsheet.vision.stereo import METHODS, StereoModel

__all__ = ["TrackerConfig", "TrackResult", "FingertipTracker", "PixelNoise"]


class PixelNoise:
    """Running estimate of the image pipeline's pixel noise σ (px) from the epipolar (Sampson) residuals r of
    accepted matches. For i.i.d. N(0, σ²) noise on the four image coordinates r = σ·|N(0, 1)| to first order
    (the residual is the noise's component along the constraint's unit gradient; Hartley & Zisserman §11.4.3),
    so E[r²] = σ². The prior ``prior_px`` counts as ``PRIOR_WEIGHT`` residuals; after ``window`` residuals the
    estimate is an exponential average over about that many. Raises ``ValueError`` for a non-positive
    prior."""

    PRIOR_WEIGHT = 10

    def __init__(self, prior_px: float, window: int = 500) -> None:
        if not (prior_px > 0 and np.isfinite(prior_px)):
            raise ValueError(f"prior_px must be positive and finite, got {prior_px!r}")
        self.var = float(prior_px) ** 2
        self.n = 0
        self.window = int(window)

    def add(self, residual_px: float) -> None:
        """Fuse one residual (px; a non-finite one is ignored)."""
        r2 = float(residual_px) ** 2
        if not np.isfinite(r2):
            return
        self.n += 1
        w = 1.0 / min(self.n + self.PRIOR_WEIGHT, self.window)
        self.var += w * (r2 - self.var)

    @property
    def sigma(self) -> float:
        """The current estimate, px (> 0)."""
        return max(float(np.sqrt(self.var)), 1e-4)


@dataclass(frozen=True)
class TrackerConfig:
    """Tracker settings (see module doc; lengths m, pixels px, times s). Checked on construction
    (:meth:`validate`); the triangulator node's params are these fields."""

    method: str = "optimal"
    sigma_px: float = 0.1
    epipolar_tol_px: float = 1.5
    z_min: float = 0.1
    z_max: float = 2.0
    gate_chi2: float = 16.27
    max_gate_misses: int = 3
    lost_reset_s: float = 0.25
    horizon_s: float = 0.025          # the display's measured exposure -> sheet delay (docs/planner.md)
    tracking_index: float = 0.05
    manoeuvre_accel: float = 5.0     # a finger's peak acceleration in a reach (module doc, step 6)
    v0_std: float = 1.0
    ambiguity_m: float = 0.01
    ambiguity_ratio: float = 0.8
    roi_half: int = 32
    min_contrast: float = 40.0
    se_size: int = 11
    patch_radius: int = 10
    area_ratio_max: float = 1.3
    max_candidates: int = 3
    marker_diameter: float = 0.004
    size_ratio_max: float = 2.5

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first out-of-range field (including the detector's, see
        :class:`~flexsheet.vision.detect.MarkerDetector`)."""
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        for name in ("sigma_px", "epipolar_tol_px", "z_min", "gate_chi2", "lost_reset_s", "tracking_index",
                     "v0_std",
                     "ambiguity_m", "manoeuvre_accel"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be positive and finite, got {v!r}")
        if not self.z_max > self.z_min:
            raise ValueError(f"z_max must exceed z_min={self.z_min}, got {self.z_max!r}")
        if not (np.isfinite(self.horizon_s) and 0.0 <= self.horizon_s <= 1.0):
            raise ValueError(f"horizon_s must be in [0, 1] s, got {self.horizon_s!r}")
        if not (self.area_ratio_max >= 1.0):
            raise ValueError(f"area_ratio_max must be >= 1, got {self.area_ratio_max!r}")
        if not (0.001 <= self.marker_diameter <= 0.05):
            raise ValueError(f"marker_diameter must be in [0.001, 0.05] m, got {self.marker_diameter!r}")
        if not (self.size_ratio_max > 1.0 and np.isfinite(self.size_ratio_max)):
            raise ValueError(f"size_ratio_max must be > 1, got {self.size_ratio_max!r}")
        if self.max_gate_misses < 1:
            raise ValueError(f"max_gate_misses must be >= 1, got {self.max_gate_misses!r}")
        self.detector()

    def detector(self) -> MarkerDetector:
        """The :class:`~flexsheet.vision.detect.MarkerDetector` these settings describe (raises its
        ``ValueError`` for a bad ``se_size``, ``min_contrast``, ``max_candidates``, ``patch_radius``,
        ``roi_half``)."""
        return MarkerDetector(se_size=self.se_size, min_contrast=self.min_contrast,
                              max_candidates=self.max_candidates, patch_radius=self.patch_radius,
                              roi_half=self.roi_half)


@dataclass
class TrackResult:
    """One frame's output. ``valid``; ``reason`` ("ok", "no_left", "no_right", "no_match", "depth", "size",
    "ambiguous", "occluded", "gated"); ``position`` (3,) m display frame (zeros when invalid); ``covariance``
    (3, 3) m²; ``predicted`` (3,) m display (= position when horizon 0 or invalid); ``residual_px`` epipolar
    residual; ``uv_left``/``uv_right`` (2,) raw px of the chosen marker (NaN when invalid); ``roi`` True when
    both images were found in their ROI; ``position_camera`` (3,) m left-camera frame."""

    valid: bool
    reason: str
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    predicted: np.ndarray = field(default_factory=lambda: np.zeros(3))
    residual_px: float = 0.0
    uv_left: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))
    uv_right: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))
    roi: bool = False
    position_camera: np.ndarray = field(default_factory=lambda: np.zeros(3))


class FingertipTracker:
    """Stateful per-frame pipeline (module doc).

    ``calib``: calibration dict (:func:`flexsheet.vision.calib_yaml.load_yaml`) or a
    :class:`messages.StereoCalibration`; ``config``: :class:`TrackerConfig`; ``T_display_camera`` (4, 4)
    overrides the calibration's (identity if neither has one). Raises ``ValueError`` on a bad config or
    calibration.
    """

    def __init__(self, calib, config: TrackerConfig | None = None,
                 T_display_camera: np.ndarray | None = None):
        self.cfg = config or TrackerConfig()
        self.cfg.validate()
        self.model = StereoModel.from_calib(calib)
        if T_display_camera is None:
            T_display_camera = (calib.get("T_display_camera") if isinstance(calib, dict)
                                else getattr(calib, "T_display_camera", None))
        T = (np.eye(4) if T_display_camera is None
             else check_pose("T_display_camera", T_display_camera, tol=1e-3))
        self.R_dc, self.t_dc = T[:3, :3].copy(), T[:3, 3].copy()
        w, h = self.model.image_size
        self.shape = (h, w)
        c = self.cfg
        self.detector = c.detector()
        self.kf = ConstantVelocityKF(q=1.0, v0_std=c.v0_std)   # q: set per update from the tracking index
        self.noise = PixelNoise(c.sigma_px)
        self.frame_dt: float | None = None      # measured frame interval, s (exponential average)
        self.nis = 3.0  # mean normalised innovation² of accepted fixes (3 if consistent)
        self._last_uv: tuple[np.ndarray, np.ndarray] | None = None
        self._misses = 0

    def _manoeuvre_q(self, stamp: float) -> float:
        """Process noise q = a²·T (m²/s³) of a finger accelerating at ``manoeuvre_accel`` a over a frame
        interval T (the measured one, else the time since the last fix to ``stamp`` s; the track is live):
        over T its velocity changes by about √(qT) = a·T (Bar-Shalom et al. §6.2.2)."""
        T = self.frame_dt if self.frame_dt is not None else max(float(stamp) - self.kf.t, 1e-3)
        return self.cfg.manoeuvre_accel ** 2 * T

    def reset(self) -> None:
        """Drop the track and the ROI (next frame searches the full images)."""
        self.kf.reset()
        self._last_uv = None
        self._misses = 0

    def forget_roi(self) -> None:
        """Search the full images in the next frame, keeping the track (ROI off, e.g. to time the full
        search)."""
        self._last_uv = None

    def _invalid(self, reason: str, roi: bool = False) -> TrackResult:
        return TrackResult(False, reason, roi=roi)

    def process(self, left: np.ndarray, right: np.ndarray, stamp: float) -> TrackResult:
        """Run the pipeline on one raw stereo pair (mono8, (H, W) of the calibration) exposed at ``stamp`` s.

        Returns a :class:`TrackResult`. Raises ``ValueError`` naming the image on a wrong dtype/shape (the
        tracker state is unchanged then).
        """
        check_image("left", left, self.shape)
        check_image("right", right, self.shape)
        c = self.cfg
        if self.kf.initialised and stamp - self.kf.t > c.lost_reset_s:
            self.reset()
        cl = cr = None
        if self._last_uv is not None:
            cl, cr = self._last_uv
        dl = self.detector.detect(left, cl)
        dr = self.detector.detect(right, cr)
        roi = dl.roi and dr.roi
        if len(dl.uv) == 0:
            self._last_uv = None
            return self._invalid("no_left", roi)
        if len(dr.uv) == 0:
            self._last_uv = None
            return self._invalid("no_right", roi)
        pairs = self._pairs(dl, dr)
        if isinstance(pairs, str):
            self._last_uv = None
            return self._invalid(pairs, roi)
        ia, ib, res, X = pairs
        Xd = X @ self.R_dc.T + self.t_dc
        strength = np.minimum(dl.strength[ia], dr.strength[ib])
        if self.kf.initialised and len(X) > 1:
            pred = self.kf.position_at(stamp)
            k = int(np.argmin(np.linalg.norm(Xd - pred, axis=1)))
        else:
            order = np.argsort(-strength)
            k = int(order[0])
            if len(order) > 1:
                k2 = int(order[1])
                if (strength[k2] >= c.ambiguity_ratio * strength[k]
                        and np.linalg.norm(Xd[k2] - Xd[k]) > c.ambiguity_m):
                    self._last_uv = None
                    return self._invalid("ambiguous", roi)
        return self._track(X, Xd, k, dl.uv[ia[k]], dr.uv[ib[k]], float(dl.area[ia[k]]), float(dr.area[ib[k]]),
                           float(res[k]), stamp, roi)

    def _pairs(self, dl, dr):
        """The left × right detection pairs that pass the epipolar, depth and size checks: (left index, right
        index, epipolar residual px, left-camera point (N, 3) m), or the reason none does."""
        c, m = self.cfg, self.model
        il = m.undistort(dl.uv, "left")
        ir = m.undistort(dr.uv, "right")
        nl, nr = len(il), len(ir)
        ia, ib = np.meshgrid(np.arange(nl), np.arange(nr), indexing="ij")
        ia, ib = ia.ravel(), ib.ravel()
        res = m.epipolar_residual(il[ia], ir[ib])
        ok = res <= c.epipolar_tol_px
        if not ok.any():
            return "no_match"
        ia, ib, res = ia[ok], ib[ok], res[ok]
        X = m.triangulate(il[ia], ir[ib], c.method)
        okz = np.all(np.isfinite(X), axis=1) & (X[:, 2] >= c.z_min) & (X[:, 2] <= c.z_max)
        if not okz.any():
            return "depth"
        ia, ib, res, X = ia[okz], ib[okz], res[okz], X[okz]
        # the marker's size at that depth: π (f d / 2Z)² px² in each view
        Zr = (X @ m.R.T + m.T)[:, 2]
        exp_l = np.pi * (m.K1[0, 0] * 0.5 * c.marker_diameter / X[:, 2]) ** 2
        exp_r = np.pi * (m.K2[0, 0] * 0.5 * c.marker_diameter / np.maximum(Zr, 1e-6)) ** 2
        rl, rr = dl.area[ia] / exp_l, dr.area[ib] / exp_r
        oks = ((rl <= c.size_ratio_max) & (rl >= 1.0 / c.size_ratio_max) & (rr <= c.size_ratio_max)
               & (rr >= 1.0 / c.size_ratio_max))
        if not oks.any():
            return "size"
        return ia[oks], ib[oks], res[oks], X[oks]

    def _track(self, X, Xd, k: int, uvl, uvr, al: float, ar: float, residual: float, stamp: float,
               roi: bool) -> TrackResult:
        """The chosen candidate ``k``: refused as occluded (blob areas ``al``/``ar`` px² too unequal) or gated
        (Mahalanobis), else fused into the track; the ROI follows it either way."""
        c = self.cfg
        cov_c = self.model.covariance(X[k:k + 1], self.noise.sigma)[0]
        cov_d = self.R_dc @ cov_c @ self.R_dc.T
        pos = Xd[k]
        if max(al, ar) > c.area_ratio_max * min(al, ar):
            # the blob is much smaller in one view: partly occluded (or merged with another blob); its
            # centroid is biased along the epipolar line, which no epipolar check can see
            self._last_uv = (uvl, uvr)
            return self._invalid("occluded", roi)
        # keep the ROI on the candidate even if gated: the marker is probably there
        self._last_uv = (uvl, uvr)
        q_step = None                   # this update's process noise (None: the smooth model's)
        if self.kf.initialised:
            gate = c.gate_chi2 * max(1.0, self.nis / 3.0)
            d2 = self.kf.mahalanobis2(pos, cov_d, stamp)
            if d2 > gate:
                # not the smooth model's: a manoeuvre within the finger's acceleration, or an outlier
                q_step = self._manoeuvre_q(stamp)
                if self.kf.mahalanobis2(pos, cov_d, stamp, q_step) > gate:
                    self._misses += 1
                    if self._misses >= c.max_gate_misses:
                        self.kf.reset()
                        self._misses = 0
                    return self._invalid("gated", roi)
            else:
                self.nis += 0.02 * (d2 - self.nis)
        self._misses = 0
        self.noise.add(residual)
        if self.kf.initialised and 1e-3 < stamp - self.kf.t < 0.2:
            dt = stamp - self.kf.t
            self.frame_dt = dt if self.frame_dt is None else self.frame_dt + 0.05 * (dt - self.frame_dt)
        if self.frame_dt is not None:   # q from the tracking index (module doc, step 6)
            self.kf.q = q_for_tracking_index(c.tracking_index, math.sqrt(float(np.trace(cov_d)) / 3.0),
                                             self.frame_dt)
        self.kf.update(pos, cov_d, stamp, q_step)
        pred = self.kf.position_at(stamp + c.horizon_s) if c.horizon_s > 0 else pos.copy()
        return TrackResult(True, "ok", pos.copy(), cov_d, pred, residual, uvl.copy(), uvr.copy(), roi,
                           X[k].copy())
