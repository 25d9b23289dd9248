"""Triangulator node: ``/camera/stereo`` (+ latched ``/camera/calibration``) → ``/fingertip`` (display frame).

A thin shell around :class:`flexsheet.vision.tracker.FingertipTracker`. Every frame gives one
:class:`messages.Fingertip`: valid with position, covariance and prediction, or invalid (zero position)
when the marker is lost, occluded, ambiguous or gated out. Bad frames (wrong size or dtype, unsynchronised
pair) are rejected with a one-line reason and counted; the node keeps running. Frames that arrive before
the calibration are rejected too.

Registration: with ``display_calib`` set (the launch file's top-level ``display_calib:`` fills it),
the camera's pose in the display frame — and the stereo model it was fitted with, when the entry has one —
come from that ``display.yaml``'s camera entry, overriding the ``/camera/calibration`` message's (the image
size must agree; a pose differing from the message's by > 1 mm or 0.05° is logged). The node never reads
the twin's truth.
"""

from __future__ import annotations

import threading

import numpy as np
from pydantic import Field

from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.model.timing import LAB
from flexsheet.runtime.node import InputRejected, Node
from flexsheet.runtime.params import build, config_fields, params_model
from flexsheet.runtime.qos import QoS
from flexsheet.vision.tracker import FingertipTracker, TrackerConfig
from messages import Fingertip, StereoCalibration, StereoFrame, topics

__all__ = ["TriangulatorParams", "TriangulatorNode"]


TriangulatorParams = params_model(
    "TriangulatorParams",
    """Triangulator parameters (px, m, s; see docs/vision.md). Every param but ``max_stereo_skew_s`` is a
    field of — defined, defaulted and checked in — :class:`flexsheet.vision.tracker.TrackerConfig`;
    ``max_stereo_skew_s``: largest left/right exposure difference accepted, s.""",
    config_fields(TrackerConfig),
    check=lambda p: build(TrackerConfig, p),
    methods={"tracker_config": lambda self: build(TrackerConfig, self)},
    module=__name__,
    max_stereo_skew_s=(float, Field(default=0.002, gt=0.0)),
    display_calib=(str | None, Field(default=None, description="display.yaml: the camera entry's pose (and "
                                                               "stereo model) override the calibration "
                                                               "message's")),
)


class TriangulatorNode(Node):
    """Publishes :class:`messages.Fingertip` for every :class:`messages.StereoFrame` once calibrated."""

    Params = TriangulatorParams
    node_type = "triangulator"

    async def setup(self) -> None:
        p = self.params
        self.cfg: TrackerConfig = p.tracker_config()
        self.tracker: FingertipTracker | None = None
        self._lock = threading.Lock()
        self.display = None
        if p.display_calib:
            self.display = load_display_calib(p.display_calib, require=("camera",)).camera
        self.pub = self.publisher(topics.FINGERTIP)
        self.subscribe(topics.CALIBRATION, self.on_calibration, qos=QoS.LATCHED)
        self.subscribe(topics.STEREO, self.on_stereo, qos=QoS.LATEST, sim_cost=LAB.compute("triangulator"))

    def on_calibration(self, msg: StereoCalibration) -> None:
        """(Re)build the tracker from a calibration (bad calibration → rejected, old one kept); with
        ``display_calib`` its camera entry's pose and stereo model replace the message's."""
        calib, T = msg, msg.T_display_camera
        if self.display is not None:
            T = self.display.T_display_camera
            st = self.display.stereo
            if st is not None:
                if tuple(int(v) for v in st["image_size"]) != tuple(int(v) for v in msg.image_size):
                    raise InputRejected(f"{self.params.display_calib}: camera entry is for "
                                        f"{st['image_size']} images, the calibration message for "
                                        f"{tuple(msg.image_size)}")
                calib = st
            dt = float(np.linalg.norm(T[:3, 3] - msg.T_display_camera[:3, 3]))
            dr = float(
                np.degrees(np.arccos(np.clip((np.trace(T[:3, :3].T @ msg.T_display_camera[:3, :3]) - 1) / 2,
                                             -1.0, 1.0))))
            if dt > 1e-3 or dr > 0.05:
                self.log.warning("display_calib's camera pose differs from /camera/calibration's by %.1f mm, "
                                 "%.2f deg: using display_calib's", dt * 1e3, dr)
        tracker = FingertipTracker(calib, self.cfg, T)
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
            covariance=res.covariance, valid=res.valid,
            predicted_position=res.predicted if res.valid else np.zeros(3),
            prediction_horizon=float(self.cfg.horizon_s), exposure_stamp=msg.exposure_stamp,
            frame_stamp=msg.header.stamp, sent_stamp=self.clock.stamp(),
            reprojection_px=float(res.residual_px)))
