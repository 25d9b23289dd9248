"""Head camera node: the camera facing the viewer, and the glasses tracker → ``/eye/pose``.

Each frame of the head camera (a global-shutter camera beside or above the sheet, looking at the viewer) goes to
:class:`flexsheet.vision.glasses.GlassesTracker`: the ArUco board on the stereo glasses is detected, its pose
found by PnP, and the eyes placed by the lab's measured eye offset and IPD (``display.yaml``'s ``eye`` entry).
One :class:`messages.EyePose` per frame, stamped at mid-exposure, with the eye velocity
(:class:`flexsheet.vision.glasses.HeadPredictor`) for the renderer's prediction to photon time. A frame without
the glasses gives ``valid: false`` carrying the last good pose and its age.

Sources (param ``source``):

* ``sim``: the head camera's twin (:class:`flexsheet.twin.head_camera.HeadCameraTwin`) renders the glasses at
  the world's ``/world/head`` through the hidden truth's camera (``twin: {realism, truth_seed}``); the tracker
  uses only the registered camera (``display.yaml``'s ``head_camera`` entry).
* ``device``: a UVC camera through OpenCV's ``cv2.VideoCapture`` (``device``: an index or a ``/dev/video*``
  path), stamped on arrival less half the exposure.

Geometry: the ``head_camera`` and ``eye`` entries of ``display_calib`` (the launch file's top-level
``display_calib:``). Without a head camera entry the node refuses to start, naming the fix (``flexsheet
calibrate display`` registers it). Bad frames are rejected and counted; the node keeps running.
"""

from __future__ import annotations

import threading
from typing import Literal

import numpy as np
from pydantic import Field

from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.model.timing import LAB
from flexsheet.runtime.node import InputRejected, Node
from flexsheet.runtime.params import params_model
from flexsheet.runtime.qos import QoS
from flexsheet.twin.head_camera import HeadCameraTwin
from flexsheet.twin.head_rig import true_head_camera
from flexsheet.twin.truth_choice import TruthChoice
from flexsheet.vision.glasses import GlassesBoard, GlassesPose, GlassesTracker, HeadPredictor
from messages import EyePose, HeadTruth, topics

__all__ = ["HeadCameraParams", "HeadCameraNode"]

HeadCameraParams = params_model(
    "HeadCameraParams",
    """Head camera and glasses tracker (SI units): ``source`` sim | device; ``device`` (UVC index or path);
    ``rate_hz`` frames per second; ``exposure_s``; ``board_rows``/``board_cols``/``marker_m``/``gap_m``: the
    glasses' ArUco grid (dictionary 4x4_50, ids from 0); ``min_markers`` for a pose; ``ipd`` m (None: the
    ``eye`` entry's); ``display_calib`` (the head camera and eye entries); ``twin`` (sim: the hidden truth).""",
    module=__name__,
    source=(Literal["sim", "device"], Field(default="sim")),
    device=(str, Field(default="0", description="device source: a UVC index or a /dev/video* path")),
    rate_hz=(float, Field(default=60.0, gt=0.0, le=240.0)),
    exposure_s=(float, Field(default=0.004, gt=0.0, le=0.05)),
    board_rows=(int, Field(default=2, ge=1, le=10)),
    board_cols=(int, Field(default=7, ge=1, le=20)),
    marker_m=(float, Field(default=0.012, gt=0.0, le=0.1)),
    gap_m=(float, Field(default=0.003, gt=0.0, le=0.05)),
    min_markers=(int, Field(default=3, ge=1)),
    ipd=(float | None, Field(default=None, ge=0.0, le=0.1)),
    display_calib=(str | None, Field(default=None)),
    twin=(TruthChoice, Field(default_factory=TruthChoice)),
)


def _tracker(p, log) -> GlassesTracker:
    """The tracker of the registered head camera and the measured eye. Raises ``ValueError`` naming the fix."""
    if not p.display_calib:
        raise ValueError("display_calib is not set: the head camera's pose and the eye offset come from "
                         "display.yaml (flexsheet calibrate display; the launch file's display_calib:)")
    dc = load_display_calib(p.display_calib, require=("eye",))
    if dc.head_camera is None:
        raise ValueError(f"{p.display_calib}: no head_camera entry: register the head camera "
                         "(flexsheet calibrate display) or leave this node out (the image is then for V)")
    h, e = dc.head_camera, dc.eye
    ipd = e.ipd if p.ipd is None else p.ipd
    board = GlassesBoard(rows=p.board_rows, cols=p.board_cols, marker=p.marker_m, gap=p.gap_m)
    log.info("head camera %dx%d, f %.1f px, at %s mm; eye offset %s mm, ipd %.1f mm (%s)", h.width, h.height,
             h.K[0, 0], np.round(h.T_display_camera[:3, 3] * 1e3, 1).tolist(),
             np.round(e.glasses_eye_offset * 1e3, 1).tolist(), ipd * 1e3, e.provenance.source)
    return GlassesTracker(h.K, h.D, h.T_display_camera, board, e.glasses_eye_offset, ipd, p.min_markers)


def _eye_pose(header, pose: GlassesPose, velocity: np.ndarray, valid: bool, age: float = 0.0) -> EyePose:
    """The ``/eye/pose`` of glasses ``pose``: this frame's (``valid``) or the last good one carried, ``age`` s old."""
    T = pose.T_display_glasses
    return EyePose(header=header, position=T[:3, 3].copy(), rotation=np.ascontiguousarray(T[:3, :3]), left=pose.left,
                   right=pose.right, eye=pose.V, velocity=velocity, valid=valid, age=age,
                   markers=pose.markers if valid else 0, reprojection_px=pose.reprojection_px if valid else 0.0)


class HeadCameraNode(Node):
    """Publishes :class:`messages.EyePose` on ``/eye/pose`` for every head-camera frame."""

    Params = HeadCameraParams
    node_type = "head_camera"

    async def setup(self) -> None:
        p = self.params
        self.tracker = _tracker(p, self.log)
        self.predictor = HeadPredictor()
        self.pub = self.publisher(topics.EYE_POSE)
        self._last: tuple[float, GlassesPose] | None = None
        self._lock = threading.Lock()
        self.lost = 0
        if p.source == "sim":
            K, D, T, w, h = true_head_camera(p.twin.truth_seed, p.twin.realism)
            self.twin = HeadCameraTwin(K, D, T, w, h, board=self.tracker.board, seed=p.twin.truth_seed)
            self._head: HeadTruth | None = None
            self.subscribe(topics.HEAD_TRUTH, self.on_head, qos=QoS.LATEST)
            self.timer(1.0 / p.rate_hz, self.on_sim_tick, sim_cost=LAB.camera_latency(p.exposure_s, w, h // 2)
                       + LAB.compute("head_camera"))
        else:
            import cv2

            dev = int(p.device) if p.device.isdigit() else p.device
            self.cap = cv2.VideoCapture(dev)
            if not self.cap.isOpened():
                raise ValueError(f"device {p.device!r}: cannot open the head camera (cv2.VideoCapture)")
            self.cap.set(cv2.CAP_PROP_FPS, p.rate_hz)
            self.timer(1.0 / p.rate_hz, self.on_device_tick)

    @classmethod
    def probe(cls, params) -> list[str]:
        """The head camera ``params`` name, if this machine cannot open it (``flexsheet launch --check --probe``):
        a UVC device by opening it and reading one frame; sim: none."""
        if params.source != "device":
            return []
        import cv2

        dev = int(params.device) if params.device.isdigit() else params.device
        cap = cv2.VideoCapture(dev)
        try:
            if not cap.isOpened():
                return [f"head camera: cannot open UVC device {params.device!r} (cv2.VideoCapture)"]
            ok, _ = cap.read()
            return [] if ok else [f"head camera: UVC device {params.device!r} opened but gave no frame"]
        finally:
            cap.release()

    async def teardown(self) -> None:
        cap = getattr(self, "cap", None)
        if cap is not None:
            cap.release()

    def on_head(self, msg: HeadTruth) -> None:
        """Keep the newest true head (sim)."""
        with self._lock:
            self._head = msg

    def on_sim_tick(self) -> None:
        """Render the glasses at mid-exposure (the truth moved on by its velocity) and track them."""
        with self._lock:
            head = self._head
        if head is None:
            return
        t = self.now() - 0.5 * self.params.exposure_s
        dt = min(max(t - head.header.stamp, 0.0), 0.1)
        T = np.eye(4)
        T[:3, :3] = head.rotation
        T[:3, 3] = head.position + head.velocity * dt
        image = self.twin.render(T, head.velocity, self.params.exposure_s, occluded=not head.visible)
        self._track(image, t)

    async def on_device_tick(self) -> None:
        """Grab one UVC frame in a worker thread (the loop stays free), stamped on arrival less half the exposure,
        and track it."""
        import asyncio

        import cv2

        ok, frame = await asyncio.to_thread(self.cap.read)
        t = self.now() - 0.5 * self.params.exposure_s
        if not ok:
            raise InputRejected(f"device {self.params.device!r}: no frame")
        self._track(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame, t)

    def _track(self, image: np.ndarray, stamp: float) -> None:
        pose = self.tracker.track(image)
        hdr = self.pub.header("display", stamp=stamp)
        if pose is not None:
            self.predictor.update(stamp, pose)
            self._last = (stamp, pose)
            v = self.predictor.velocity
            self.pub.publish(_eye_pose(hdr, pose, np.zeros(3) if v is None else v[2].copy(), True))
            return
        self.lost += 1
        if self._last is None:
            return          # nothing tracked yet: the renderer draws for V until the first pose
        t_good, good = self._last
        self.pub.publish(_eye_pose(hdr, good, np.zeros(3), False, age=max(stamp - t_good, 0.0)))

    def heartbeat(self):
        hb = super().heartbeat()
        line = f"glasses lost in {self.lost} frames"
        return hb.model_copy(update={"message": f"{line}; {hb.message}" if hb.message else line})


