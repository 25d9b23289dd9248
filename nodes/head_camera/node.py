"""Head camera node: the camera facing the viewer, and the glasses tracker → ``/eye/pose``.

Each frame of the head camera (a global-shutter camera beside or above the sheet, looking at the viewer) goes
to :class:`flexsheet.vision.glasses.GlassesTracker`: the ArUco board on the stereo glasses is detected, its
pose found by PnP, and the eyes placed by the lab's measured eye offset and IPD (``display.yaml``'s ``eye``
entry). One :class:`messages.EyePose` per frame, stamped at mid-exposure, with the eye velocity
(:class:`flexsheet.vision.glasses.HeadPredictor`) for the renderer's prediction to photon time. A frame
without the glasses gives ``valid: false`` carrying the last good pose and its age.

Frames come through the head camera port (:mod:`flexsheet.vision.head_camera_port`), the source named by param
``source`` (an entry point): ``sim``, the head camera's twin at the world's true head
(:mod:`flexsheet.twin.head_camera_source`; the tracker uses only the registered camera); ``device``, a UVC
camera (:mod:`nodes.head_camera.uvc`), stamped on arrival less half the exposure.

Geometry: the ``head_camera`` and ``eye`` entries of ``display_calib`` (the launch file's top-level
``display_calib:``). Without a head camera entry the node refuses to start, naming the fix (``flexsheet
calibrate display`` registers it). Bad frames are rejected and counted; the node keeps running.
"""

from __future__ import annotations

import asyncio

import numpy as np
from pydantic import Field

from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.model.timing import LAB
from flexsheet.model.truth_choice import TruthChoice
from flexsheet.runtime.node import Node
from flexsheet.runtime.params import params_model
from flexsheet.runtime.plugins import EntryName
from flexsheet.runtime.qos import QoS
from flexsheet.vision.glasses import GlassesBoard, GlassesPose, GlassesTracker, HeadPredictor
from flexsheet.vision.head_camera_port import SOURCES_GROUP, head_camera_source
from messages import EyePose, topics

__all__ = ["HeadCameraParams", "HeadCameraNode"]

HeadCameraParams = params_model(
    "HeadCameraParams",
    """Head camera and glasses tracker (SI units): ``source`` sim | device; ``device`` (UVC index or path);
    ``rate_hz`` frames per second; ``exposure_s``; ``board_rows``/``board_cols``/``marker_m``/``gap_m``: the
    glasses' ArUco grid (dictionary 4x4_50, ids from 0); ``min_markers`` for a pose; ``ipd`` m (None: the
    ``eye`` entry's); ``display_calib`` (the head camera and eye entries); ``twin`` (sim: the hidden
    truth).""",
    module=__name__,
    source=(EntryName(SOURCES_GROUP, "head camera source"),
            Field(default="sim", description="an entry point of flexsheet.head_camera_sources: sim (twin) "
                  "or device (UVC)")),
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
    """The tracker of the registered head camera and the measured eye. Raises ``ValueError`` naming the
    fix."""
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
    """The ``/eye/pose`` of glasses ``pose``: this frame's (``valid``) or the last good one carried, ``age`` s
    old."""
    T = pose.T_display_glasses
    return EyePose(header=header, position=T[:3, 3].copy(), rotation=np.ascontiguousarray(T[:3, :3]),
                   left=pose.left,
                   right=pose.right, eye=pose.V, velocity=velocity, valid=valid, age=age,
                   markers=pose.markers if valid else 0,
                   reprojection_px=pose.reprojection_px if valid else 0.0)


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
        self.lost = 0
        self.source = head_camera_source(p.source).open(p, self.tracker.board)
        for topic in self.source.inputs:
            self.subscribe(topic, lambda msg, t=topic: self.source.feed(t, msg), qos=QoS.LATEST)
        self.timer(1.0 / p.rate_hz, self.on_frame_blocking if self.source.blocking else self.on_frame,
                   sim_cost=self.source.frame_latency(p.exposure_s) + LAB.compute("head_camera"))

    @classmethod
    def probe(cls, params) -> list[str]:
        """What stops the head camera of ``params`` on this machine (``flexsheet launch --check --probe``)."""
        return head_camera_source(params.source).probe(params)

    async def teardown(self) -> None:
        source = getattr(self, "source", None)
        if source is not None:
            source.close()

    def on_frame(self) -> None:
        """One frame, exposed around now less half the exposure, tracked."""
        t = self.now() - 0.5 * self.params.exposure_s
        image = self.source.grab(t)
        if image is not None:
            self._track(image, t)

    async def on_frame_blocking(self) -> None:
        """One frame from a device, waited for in a worker thread (the loop stays free), stamped on arrival
        less half the exposure, and tracked."""
        image = await asyncio.to_thread(self.source.grab, self.now() - 0.5 * self.params.exposure_s)
        if image is not None:
            self._track(image, self.now() - 0.5 * self.params.exposure_s)

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


