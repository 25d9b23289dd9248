"""Triangulator node: ``/camera/stereo`` (+ latched ``/camera/calibration``) → ``/fingertip`` (display frame).

A thin shell around :class:`nodes.triangulator.pipeline.FingertipTracker`. Every frame gives one
:class:`messages.Fingertip`: valid with position, covariance and prediction, or invalid (zero position)
when the marker is lost, occluded, ambiguous or gated out. Bad frames (wrong size or dtype, unsynchronised
pair) are rejected with a one-line reason and counted; the node keeps running. Frames that arrive before
the calibration are rejected too.
"""

from __future__ import annotations

import threading

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from flexsheet.runtime.node import InputRejected, Node, QoS
from messages import Fingertip, StereoCalibration, StereoFrame, topics
from nodes.triangulator.pipeline import FingertipTracker, TrackerConfig

__all__ = ["TriangulatorParams", "TriangulatorNode"]


class TriangulatorParams(BaseModel):
    """Triangulator parameters (px, m, s; see docs/vision.md and :class:`TrackerConfig`)."""

    model_config = ConfigDict(extra="forbid")
    method: str = Field(default="optimal", pattern="^(dlt|optimal|midpoint)$")
    sigma_px: float = Field(default=0.1, gt=0.0)
    epipolar_tol_px: float = Field(default=1.5, gt=0.0)
    z_min: float = Field(default=0.1, gt=0.0)
    z_max: float = Field(default=2.0, gt=0.0)
    gate_chi2: float = Field(default=16.27, gt=0.0)
    max_gate_misses: int = Field(default=3, ge=1)
    lost_reset_s: float = Field(default=0.25, gt=0.0)
    horizon_s: float = Field(default=0.0, ge=0.0, le=1.0)
    q: float = Field(default=2.0, gt=0.0)
    roi_half: int = Field(default=32, ge=14)
    min_contrast: float = Field(default=40.0, gt=0.0, lt=255.0)
    max_stereo_skew_s: float = Field(default=0.002, gt=0.0)


class TriangulatorNode(Node):
    """Publishes :class:`messages.Fingertip` for every :class:`messages.StereoFrame` once calibrated."""

    Params = TriangulatorParams
    node_type = "triangulator"

    async def setup(self) -> None:
        p = self.params
        self.cfg = TrackerConfig(method=p.method, sigma_px=p.sigma_px, epipolar_tol_px=p.epipolar_tol_px,
                                 z_min=p.z_min, z_max=p.z_max, gate_chi2=p.gate_chi2,
                                 max_gate_misses=p.max_gate_misses, lost_reset_s=p.lost_reset_s,
                                 horizon_s=p.horizon_s, q=p.q, roi_half=p.roi_half, min_contrast=p.min_contrast)
        self.cfg.validate()
        self.tracker: FingertipTracker | None = None
        self._lock = threading.Lock()
        self.pub = self.publisher(topics.FINGERTIP)
        self.subscribe(topics.CALIBRATION, self.on_calibration, qos=QoS.LATCHED)
        self.subscribe(topics.STEREO, self.on_stereo, qos=QoS.LATEST)

    def on_calibration(self, msg: StereoCalibration) -> None:
        """(Re)build the tracker from a calibration (bad calibration → rejected, old one kept)."""
        tracker = FingertipTracker(msg, self.cfg, msg.T_display_camera)
        with self._lock:
            self.tracker = tracker
        self.log.info("calibration: %dx%d, |T| = %.1f mm, f = %.1f px", msg.image_size[0], msg.image_size[1],
                      tracker.model.baseline * 1e3, tracker.model.focal)

    def on_stereo(self, msg: StereoFrame) -> None:
        """Process one stereo pair and publish the fingertip (valid or invalid)."""
        with self._lock:
            tracker = self.tracker
        if tracker is None:
            raise InputRejected("stereo frame before calibration: waiting for /camera/calibration")
        if abs(msg.stereo_skew) > self.params.max_stereo_skew_s:
            raise InputRejected(f"stereo_skew {msg.stereo_skew:.4f} s exceeds max_stereo_skew_s "
                                f"{self.params.max_stereo_skew_s} s: left/right not synchronised")
        if msg.left.shape != msg.right.shape:
            raise InputRejected(f"left shape {msg.left.shape} != right shape {msg.right.shape}")
        try:
            res = tracker.process(msg.left, msg.right, msg.exposure_stamp)
        except ValueError as exc:
            raise InputRejected(str(exc)) from None
        self.pub.publish(Fingertip(
            header=self.pub.header("display", stamp=msg.exposure_stamp), position=res.position,
            covariance=res.covariance, valid=res.valid, predicted_position=res.predicted if res.valid else np.zeros(3),
            prediction_horizon=float(self.cfg.horizon_s), exposure_stamp=msg.exposure_stamp,
            frame_stamp=msg.header.stamp,
            reprojection_px=float(res.residual_px)))
