"""flexsheet messages -> Foxglove messages: the output channels, their schemas and the JSON copies (no I/O).
The 3-D scene is built by :mod:`flexsheet.viz.scene_builder` from :mod:`flexsheet.viz.primitives`; what is
due when, by :mod:`flexsheet.viz.streams`.

Shared by the live bridge (``nodes/viz``, which serves these on the foxglove-sdk WebSocket server) and by
bags (:mod:`flexsheet.viz.foxglove_bag`, which writes them into MCAP), so a recorded run shows what the
live view showed. Pure apart from building messages: numpy, scipy, the ``foxglove`` SDK's schema classes
(protobuf encoders), :mod:`flexsheet.model` (sheet, kinematics, projector); no sockets, no asyncio.

Outputs (Foxglove topic: schema, what):

* ``/viz/scene`` (``foxglove.SceneUpdate``), display frame: the object's surface mesh exactly as
  ``/object/deformation`` carries it (the vertices the renderer draws; the undeformed paper cylinder until the
  FEM has published); the sheet the display believes in (clamp poses by forward kinematics of both arms'
  measured joints, :meth:`SheetSurface.from_clamps`; depressed by a valid fingertip behind it with the
  renderer's own pushed-sheet model, :func:`flexsheet.model.sheet_model.sheet_model_for` of the same
  :class:`~flexsheet.model.sheet_model.SheetConfig`: the dent the projected image is corrected for); in the
  twin the true sheet (``/world/sheet``, wireframe); the fingertip measured, predicted and true
  (``/world/finger``); the contact point with the object normal (``/sheet/target``) and the sheet normal;
  camera and projector frusta; the eyes; both arms drawn from ``rv1a.urdf`` (link frames by Pinocchio FK, a
  cylinder per link, a box for each clamp jaw).
* ``/viz/tf`` (``foxglove.FrameTransforms``): ``display`` → ``camera_left`` → ``camera_right``,
  ``projector``, ``eye``, ``sheet``, ``sheet_target``, and per arm ``<arm>/base_link`` → … → ``<arm>/clamp``
  (the URDF links, ``<arm>`` = left | right).
* ``/camera/left``, ``/camera/right`` (``foxglove.RawImage`` mono8, optionally downscaled) with
  ``/camera/left/calibration``, ``/camera/right/calibration`` (``foxglove.CameraCalibration``, scaled alike);
  ``/render/image`` (``foxglove.RawImage`` rgb8): the projector's left|right pair side by side.
* ``/viz/metrics`` (JSON): Δθ (deg; angle between the object normal at the contact, ``SheetTarget.normal``,
  and the measured sheet normal, the paper's Fig. 9 angle error, live), the hop latencies (ms, from the
  exposure stamp each message carries) and the sheet tension (N/m).
* the plain topics (``/fingertip``, ``/sheet/target``, ``/arm/<arm>/joint_state``, ``/object/deformation``
  without its mesh arrays, ``/diagnostics``) as JSON with the message's JSON schema.

Rates are set by :class:`flexsheet.viz.streams.Rates`; :class:`flexsheet.viz.streams.FoxgloveStreams` decides
what is due from the newest inputs, with time given by the caller (wall clock live, log time in a bag).
Source: Foxglove schemas (docs.foxglove.dev/docs/visualization/message-schemas), foxglove-sdk Python API.
"""

from __future__ import annotations

import json

from foxglove import Schema
from foxglove.messages import (
    CameraCalibration,
    FrameTransforms,
    RawImage,
    SceneUpdate,
)

from messages import (
    Message,
)
from messages import topics as T

__all__ = ["SCENE", "TF", "METRICS", "CAMERA_LEFT", "CAMERA_RIGHT", "CAMERA_LEFT_INFO", "CAMERA_RIGHT_INFO",
           "RENDER_IMAGE", "JSON_TOPICS", "INPUT_TOPICS", "inputs_for", "channel_schemas", "json_schema"]

SCENE = "/viz/scene"
TF = "/viz/tf"
METRICS = "/viz/metrics"
CAMERA_LEFT = "/camera/left"
CAMERA_RIGHT = "/camera/right"
CAMERA_LEFT_INFO = "/camera/left/calibration"
CAMERA_RIGHT_INFO = "/camera/right/calibration"
RENDER_IMAGE = "/render/image"
#: our topics republished as JSON (same names): Foxglove can plot any of their fields
JSON_TOPICS = [T.FINGERTIP, T.SHEET_TARGET, T.ARM_LEFT_STATE, T.ARM_RIGHT_STATE, T.DEFORMATION, T.DIAGNOSTICS]
#: every topic the scene is built from
INPUT_TOPICS = [T.FINGERTIP, T.SHEET_TARGET, T.ARM_LEFT_STATE, T.ARM_RIGHT_STATE, T.DEFORMATION, T.RENDERED,
                T.STEREO, T.CALIBRATION, T.FINGER_TRUTH, T.SHEET_STATE, T.DIAGNOSTICS]
_SCENE_INPUTS = [T.FINGERTIP, T.SHEET_TARGET, T.ARM_LEFT_STATE, T.ARM_RIGHT_STATE, T.DEFORMATION, T.RENDERED,
                 T.CALIBRATION, T.FINGER_TRUTH, T.SHEET_STATE]


def inputs_for(topic: str) -> list:
    """The input topics (:class:`messages.Topic`) Foxglove output ``topic`` is built from; [] if unknown."""
    if topic in (SCENE, TF, METRICS):
        return list(_SCENE_INPUTS)
    if topic in (CAMERA_LEFT, CAMERA_RIGHT):
        return [T.STEREO]
    if topic in (CAMERA_LEFT_INFO, CAMERA_RIGHT_INFO):
        return [T.CALIBRATION]
    if topic == RENDER_IMAGE:
        return [T.RENDERED]
    return [t for t in JSON_TOPICS if t.name == topic]


#: fields left out of a JSON copy (the mesh travels in /viz/scene; thousands of numbers per message)
JSON_EXCLUDE = {T.DEFORMATION.name: {"vertices", "faces"}}
ARM_LINKS = ("base_link", "shoulder", "upper_arm", "elbow", "forearm", "wrist", "flange", "clamp")
#: drawn diameter (m) of the segment from each link's origin to the next one's (RV-1A-like proportions)
LINK_DIAMETER = (0.12, 0.09, 0.07, 0.07, 0.06, 0.05, 0.04)

def json_schema(topic: str, cls: type[Message]) -> dict:
    """JSON schema of the JSON copy of ``topic`` (the pydantic schema, less :data:`JSON_EXCLUDE` fields)."""
    s = cls.model_json_schema()
    drop = JSON_EXCLUDE.get(topic, set())
    if drop:
        s = dict(s)
        s["properties"] = {k: v for k, v in s["properties"].items() if k not in drop}
        s["required"] = [k for k in s.get("required", []) if k not in drop]
    s["title"] = cls.SCHEMA
    return s


_METRICS_SCHEMA = {
    "title": "flexsheet/VizMetrics", "type": "object",
    "description": "live metrics computed by the viz bridge (see flexsheet/viz/foxglove.py)",
    "properties": {
        "stamp": {"type": "number", "description": "time of the newest input, s"},
        "dtheta_deg": {"type": ["number", "null"],
                       "description": "angle between the object normal at the contact (SheetTarget.normal) "
                                      "and the measured sheet normal (arm FK), deg"},
        "tension": {"type": ["number", "null"], "description": "planned membrane tension, N/m"},
        "stretch": {"type": ["number", "null"], "description": "planned sheet strain"},
        "contact_force": {"type": ["number", "null"], "description": "FEM fingertip reaction, N"},
        "push_depth_mm": {"type": ["number", "null"], "description": "FEM push depth, mm"},
        "latency_ms": {"type": "object", "description": "exposure -> this hop, ms (sender clocks)",
                       "properties": {k: {"type": ["number", "null"]} for k in
                                      ("fingertip", "target", "fem", "arm_left", "arm_right", "render")}},
    },
}

_FOX_TYPES = {SCENE: SceneUpdate, TF: FrameTransforms, CAMERA_LEFT: RawImage, CAMERA_RIGHT: RawImage,
              CAMERA_LEFT_INFO: CameraCalibration, CAMERA_RIGHT_INFO: CameraCalibration,
              RENDER_IMAGE: RawImage}


def channel_schemas() -> dict[str, tuple[Schema, str]]:
    """Every Foxglove output topic → (``foxglove.Schema``, message encoding): protobuf for the Foxglove
    schemas (``get_schema()`` of the SDK's classes), ``json`` + jsonschema for the JSON topics."""
    out: dict[str, tuple[Schema, str]] = {t: (cls.get_schema(), "protobuf") for t, cls in _FOX_TYPES.items()}
    out[METRICS] = (Schema(name=_METRICS_SCHEMA["title"], encoding="jsonschema",
                           data=json.dumps(_METRICS_SCHEMA).encode()), "json")
    for t in JSON_TOPICS:
        s = json_schema(t.name, t.type)
        out[t.name] = (Schema(name=t.type.SCHEMA, encoding="jsonschema", data=json.dumps(s).encode()), "json")
    return out


