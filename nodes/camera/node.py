"""Camera node: publishes synchronised raw stereo pairs (mono8) on ``/camera/stereo`` and the latched stereo
calibration on ``/camera/calibration``.

Pairs come through the stereo camera port (:mod:`flexsheet.vision.camera_port`), the source named by param
``source`` (an entry point): ``sim`` — the camera twin (:mod:`flexsheet.twin.camera_source`); ``genicam`` — a
GigE Vision / USB3 Vision pair through Aravis, opened by serial, hardware/software-triggered or PTP-synced,
stamped and paired by device timestamp; ``device`` — UVC cameras through ``cv2.VideoCapture``; ``files`` — a
folder of pairs (:mod:`nodes.camera.sources`).

``stereo_skew`` in each :class:`messages.StereoFrame` by source (docs/camera.md): ``sim`` 0 (the twin
renders both views at one instant); ``genicam`` measured right − left device stamp (shared clock: PTP) or
the difference of the two mapped stamps (independent clocks); ``device`` 0 by construction for one
side-by-side device, an upper bound of |skew| for two devices; ``files`` 0 (unknown; the recording's).
``/diagnostics`` carries one line saying which, with the measured skew and dropped frames (GenICam).

Honest twin. ``/camera/calibration`` carries what a lab has: the camera's pose in the display frame
``T_display_camera`` from ``display.yaml``'s ``camera`` entry (param ``display_calib``, filled in by the
launch file's top-level ``display_calib:``) with the stereo model that pose was fitted with (the entry's, else
the stereo calibration file's: ``model``/``calib_file``). A missing ``display_calib`` is an error at start-up
— except for a source whose nominal registration is exact (the *ideal* twin). The twin forms its images
through the hidden truth instead (param ``twin: {realism, truth_seed}``).
"""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np
from pydantic import Field, model_validator

from flexsheet.calibration.published_registration import published_registration
from flexsheet.model.truth_choice import TruthChoice
from flexsheet.runtime.node import Node
from flexsheet.runtime.params import config_fields, params_model
from flexsheet.vision.calib_yaml import load_yaml
from flexsheet.vision.camera_config import CameraConfig
from flexsheet.vision.camera_model import camera_model
from flexsheet.vision.camera_port import camera_source
from flexsheet.vision.stereo_calibration import to_message
from messages import StereoFrame, topics

__all__ = ["CameraParams", "CameraNode"]



def _genicam_ids(self):
    if self.source == "genicam":
        for key in ("left_id", "right_id"):
            if not getattr(self, key):
                raise ValueError(f"{key} must name a camera (serial number) when source is genicam")
        if self.left_id == self.right_id:
            raise ValueError(f"left_id and right_id are both {self.left_id!r}: they must name two "
                             "cameras")
    return self


def _split(fields: dict, *at: str) -> list[dict]:
    """``fields`` (ordered) cut before each name of ``at``: consecutive dicts that together hold them all."""
    keys = list(fields)
    cuts = [0, *(keys.index(name) for name in at), len(keys)]
    return [{k: fields[k] for k in keys[a:b]} for a, b in pairwise(cuts)]


_MODEL, _SENSING, _PREVIEW = _split(config_fields(CameraConfig), "noise_dn", "preview_rate")

#: the display registration (display.yaml): the published camera pose comes from its camera entry; twin: the
#: hidden truth it renders through
_REGISTRATION = {
    "display_calib": (str | None, Field(default=None)),
    "twin": (TruthChoice, Field(default_factory=TruthChoice)),
}

#: genicam source (docs/camera.md): the pair by serial number (or Aravis id / IP address)
_GENICAM = {
    "left_id": (str, Field(default="")),
    "right_id": (str, Field(default="")),
    "trigger": (str, Field(default="software", pattern="^(hardware|master|software|free)$")),
    "trigger_line": (str, Field(default="Line1")),
    "master_output_line": (str, Field(default="Line2")),
    "ptp": (str, Field(default="auto", pattern="^(auto|on|off)$")),
    "ptp_timeout_s": (float, Field(default=10.0, ge=0.0, le=120.0)),
    "device_clock": (str, Field(default="auto", pattern="^(auto|shared|independent)$")),
    "timestamp_at": (str, Field(default="exposure_start", pattern="^(exposure_start|exposure_end)$")),
    "pair_tolerance_s": (float, Field(default=0.0, ge=0.0, le=0.5)),
    "offset_x": (int, Field(default=0, ge=0)),
    "offset_y": (int, Field(default=0, ge=0)),
    "gain_db": (float | None, Field(default=None)),
    "packet_size": (int, Field(default=0, ge=0, le=16384)),
    "packet_delay_ns": (int, Field(default=0, ge=0)),
    "n_buffers": (int, Field(default=16, ge=2, le=256)),
    "discover_timeout_s": (float, Field(default=10.0, ge=0.0, le=120.0)),
}

#: device source (V4L2 index or path) and files source
_DEVICE_FILES = {
    "device_left": (int | str, Field(default=0)),
    "device_right": (int | str | None, Field(default=None)),
    "files_left": (str, Field(default="")),
    "files_right": (str, Field(default="")),
    "files_csv": (str, Field(default="")),
    "loop": (bool, Field(default=True)),
}

CameraParams = params_model(
    "CameraParams",
    """Camera node parameters (SI units; see docs/vision.md, and docs/camera.md for the device sources).

    ``display_calib``, ``twin`` and the devices' settings (``left_id`` … ``discover_timeout_s``,
    ``device_left`` … ``loop``) are the node's own; every other param is a field of — defined, defaulted and
    range-checked in — :class:`flexsheet.vision.camera_config.CameraConfig`.
    """,
    _MODEL, _REGISTRATION, _SENSING, _GENICAM, _PREVIEW, _DEVICE_FILES,
    validators={"_genicam_ids": model_validator(mode="after")(_genicam_ids)},
    module=__name__,
)


class CameraNode(Node):
    """Publishes :class:`messages.StereoFrame` (at ``rate_hz``, or as the GenICam pair delivers) and latches
    :class:`messages.StereoCalibration`. Every pair at most ``preview_rate`` Hz is also published on
    ``/camera/stereo_preview`` (the same message; encoded only when a subscriber outside the process wants
    it), so a viewer does not receive the 48 Hz stream it would mostly drop (docs/visualise.md)."""

    Params = CameraParams
    #: a stereo pair of the XIMEA's 640 x 512 mono8 images, with room for its header (sizes the send queue)
    LARGEST_MESSAGE_BYTES = 2 * 640 * 512 + (16 << 10)

    node_type = "camera"

    @classmethod
    def probe(cls, params) -> list[str]:
        """What stops the camera ``params`` name on this machine (``flexsheet launch --check --probe``):
        GenICam serials/ids by Aravis discovery (~1 s), UVC devices by opening them; sim and files: none."""
        return camera_source(params.source).probe(params)

    async def setup(self) -> None:
        p = self.params
        if p.model == "file":
            calib = load_yaml(p.calib_file)
        else:
            calib = camera_model(p.model, width=p.width, height=p.height, focal_mm=p.focal_mm,
                                 pixel_um=p.pixel_um, baseline=p.baseline)
        self.calib = calib
        source = camera_source(p.source)
        published, self.T_dc, self.registration = published_registration(
            p.display_calib, calib, source.exact_nominal_registration(p), p.model)
        self.stereo_pub = self.publisher(topics.STEREO)
        self.preview_pub = self.publisher(topics.STEREO_PREVIEW)
        self._preview_next = -math.inf
        self.calib_pub = self.publisher(topics.CALIBRATION)
        self.calib_pub.publish(to_message(published, self.calib_pub.header("camera_left"), self.T_dc))
        self.frames = 0
        if p.link_delay_s > 0 and not source.models_link_delay:
            raise ValueError(f"link_delay_s {p.link_delay_s:g} is the camera twin's on the simulated clock "
                             f"(source sim, launch file clock: sim); here source {p.source}")
        self.source = await source.open(self, calib)

    def publish_pair(self, left: np.ndarray, right: np.ndarray, stamp: float, skew: float = 0.0) -> None:
        """Publish one pair: (H, W) uint8 images, mid-exposure ``stamp`` s, ``skew`` s (right − left); every
        ``preview_rate`` Hz also on the preview topic."""
        self.stereo_pub.publish(StereoFrame(   # header.stamp: handed to the graph now; exposure: mid-exposure
            header=self.stereo_pub.header("camera_left"), left=left, right=right,
            exposure_stamp=stamp, exposure_time=float(self.params.exposure_s), stereo_skew=float(skew)))
        self.frames += 1
        rate = self.params.preview_rate
        if rate > 0 and stamp >= self._preview_next:
            self._preview_next = stamp + 1.0 / rate - 0.5 / self.params.rate_hz   # half a frame of slack
            self.preview_pub.publish(StereoFrame(
                header=self.preview_pub.header("camera_left"), left=left, right=right, exposure_stamp=stamp,
                exposure_time=float(self.params.exposure_s), stereo_skew=float(skew)))

    def status_line(self) -> str:
        """One line for ``/diagnostics``: the source's (what ``stereo_skew`` means, its counts)."""
        source = getattr(self, "source", None)
        return source.status_line() if source is not None else f"{self.params.source}: starting"

    def heartbeat(self):
        """The base heartbeat with :meth:`status_line` in ``message`` (before any warning line), its state as
        the source judges it (GenICam: ``warn`` on lost pairs, ``error`` on a lost control channel)."""
        hb = super().heartbeat()
        line = self.status_line()
        source = getattr(self, "source", None)
        state = source.health(hb.state) if source is not None else hb.state
        return hb.model_copy(update={"message": f"{line}; {hb.message}" if hb.message else line,
                                     "state": state})

    async def teardown(self) -> None:
        source = getattr(self, "source", None)
        if source is not None:
            await source.close()
