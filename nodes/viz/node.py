"""Node ``viz``: the Foxglove WebSocket bridge. Serves the display's state in Foxglove's own schemas.

Thin shell around :mod:`flexsheet.viz.foxglove` (what is drawn, how it is encoded, at what rate) and
the ``foxglove-sdk`` WebSocket server (default port 8765; the SDK speaks the Foxglove WebSocket protocol v1
under the subprotocol name ``foxglove.sdk.v1``). Open ``ws://HOST:8765`` in Foxglove or Lichtblick and import
``docs/foxglove_layout.json`` (see docs/visualise.md).

Inputs: ``/fingertip``, ``/sheet/target``, ``/arm/left/joint_state``, ``/arm/right/joint_state``,
``/object/deformation``, ``/render/stereo``, ``/camera/stereo``, ``/camera/calibration`` (latched),
``/world/finger``, ``/world/sheet``, ``/diagnostics``. The bridge never slows the loop:

* it subscribes to an input only once a viewer subscribes to a Foxglove channel built from it (with no
  viewer it receives nothing; the transport has no unsubscribe, so a topic stays subscribed afterwards);
* every subscription is QoS.LATEST with an async handler that stores the message and then rests
  ``1/input_rate`` s (``/camera/stereo``: ``1/camera_rate``; ``/render/stereo``: the faster of render and
  scene rate), so at most that many messages per topic per second are decoded; newer ones replace each
  other in the depth-1 queue meanwhile (counted as ``dropped`` in the heartbeat); while no viewer is
  connected the handlers decode nothing at all (they look for a viewer once a second);
* in its own process the transport drains its inputs in batches every ``DRAIN_PERIOD`` (0.05 s;
  :class:`~flexsheet.runtime.transport.ZmqTransport` ``drain_period``): ZeroMQ queues the ~650 input
  messages/s of the sim and the loop wakes ~20 times a second instead of once per message (in a composable
  container the bus delivers as usual);
* outputs are built only for channels a viewer subscribes to: ``/viz/scene``, ``/viz/tf``, ``/viz/metrics``
  at ``scene_rate``, the camera images at ``camera_rate`` (downscaled by ``camera_scale``), ``/render/image``
  at ``render_rate``, the JSON copies of the plain topics as they arrive (≤ ``input_rate``); the scene is
  assembled from cached encoded entities, each rebuilt only when its input changed (foxglove_scene);
* a slow viewer loses the oldest queued messages (the server keeps at most ``backlog`` per client).

Publishes nothing on the graph (only its heartbeat). Input the scene cannot use (faces out of range, bad
joints) is rejected and counted.
"""

from __future__ import annotations

import asyncio
import time

import foxglove
import numpy as np
from foxglove.websocket import ServerListener
from pydantic import BaseModel, ConfigDict, Field, field_validator

from flexsheet.model import geometry
from flexsheet.model.projector import Projector
from flexsheet.model.sheet_model import SheetConfig
from flexsheet.runtime.node import InputRejected, Node, QoS
from flexsheet.viz.foxglove import (
    FoxgloveStreams,
    Rates,
    SceneBuilder,
    VizConfig,
    channel_schemas,
    inputs_for,
)
from messages import topics as T

__all__ = ["VizNode", "VizParams"]

_IDLE_S = 1.0  # how often a parked input handler looks for a viewer again, s


class VizParams(BaseModel):
    """Parameters of the viz bridge (SI units, display frame)."""

    model_config = ConfigDict(extra="forbid")
    host: str = Field("127.0.0.1", description="address the WebSocket server binds (0.0.0.0: every interface)")
    port: int = Field(8765, ge=0, le=65535, description="WebSocket port (0: any free port)")
    backlog: int = Field(64, ge=1, le=100000, description="messages queued per viewer; older ones are dropped")
    scene_rate: float = Field(5.0, ge=0.0, le=100.0,
                              description="/viz/scene, /viz/tf, /viz/metrics, Hz (5: under 5 % of a core in the sim "
                                          "with a viewer; 10 costs ~1.2 % more, docs/visualise.md)")
    camera_rate: float = Field(5.0, ge=0.0, le=100.0, description="/camera/left, /camera/right, Hz")
    camera_topic: str = Field("/camera/stereo_preview", pattern="^/camera/(stereo|stereo_preview)$",
                              description="where the camera images come from: the camera's decimated preview "
                                          "(5 Hz) or the full 48 Hz stream (replays of bags that only have it)")
    render_rate: float = Field(5.0, ge=0.0, le=100.0, description="/render/image, Hz")
    input_rate: float = Field(5.0, gt=0.0, le=1000.0,
                              description="most messages decoded per input topic, Hz (camera and rendered "
                                          "frames: camera_rate and render_rate)")
    json_rate: float = Field(5.0, ge=0.0, le=1000.0, description="cap per JSON topic, Hz (≤ input_rate)")
    calibration_rate: float = Field(0.5, ge=0.0, le=10.0, description="camera calibrations resent, Hz")
    poll_rate: float = Field(20.0, gt=0.0, le=200.0, description="how often due outputs are checked, Hz")
    camera_scale: float = Field(0.5, gt=0.0, le=1.0,
                                description="downscale of the camera images (0.5: a quarter of the pixels)")
    eye: list[float] = Field(default_factory=lambda: geometry.EYE.tolist(), description="cyclopean eye V, m")
    ipd: float = Field(0.064, ge=0.0, le=0.1, description="interpupillary distance, m")
    projector_position: list[float] = Field(default_factory=lambda: geometry.PROJECTOR.tolist(), description="m")
    projector_pixel: float = Field(geometry.PIXEL_ON_SCREEN, gt=0.0, description="m per px on the screen")
    width: int = Field(1024, ge=16, description="projector width, px")
    height: int = Field(768, ge=16, description="projector height, px")
    left_base: list[float] = Field(default_factory=lambda: list(geometry.LEFT_BASE), min_length=4, max_length=4,
                                   description="left arm base (x, y, z, yaw), m and rad (as arm_bridge 'base')")
    right_base: list[float] = Field(default_factory=lambda: list(geometry.RIGHT_BASE), min_length=4, max_length=4,
                                    description="right arm base (x, y, z, yaw), m and rad")
    sheet_grid: int = Field(20, ge=2, le=200, description="sheet mesh vertices per side")
    # the believed sheet: the renderer's pushed-sheet model (flexsheet.model.sheet_model.sheet_model_for); give
    # these the renderer's values (same names as its params) and the drawn dent is the one it corrects for
    fine_modes: int = Field(SheetConfig.fine_modes, ge=1, le=16, description="as the renderer's fine_modes")
    tension_ratio: float = Field(SheetConfig.tension_ratio, gt=0.0, description="as the renderer's tension_ratio")
    sheet_cache: str | None = Field(None, description="as the renderer's sheet_cache (its FEM tables are read "
                                                      "from there, never built by the bridge)")
    sheet_mesh: dict[str, float] = Field(default_factory=dict, description="as the renderer's sheet_mesh")
    push_threshold: float = Field(SheetConfig.push_threshold, ge=0.0, description="as the renderer's, m")
    sheet_half_width: float = Field(SheetConfig.half_width, gt=0.0, description="as the renderer's, m")

    @field_validator("eye", "projector_position")
    @classmethod
    def _vec3(cls, v: list[float]) -> list[float]:
        if len(v) != 3 or not all(np.isfinite(v)):
            raise ValueError(f"must be 3 finite numbers, got {v!r}")
        return v

    @field_validator("left_base", "right_base")
    @classmethod
    def _finite(cls, v: list[float]) -> list[float]:
        if not all(np.isfinite(v)):
            raise ValueError(f"must be finite, got {v!r}")
        return v


class _Listener(ServerListener):
    """foxglove-sdk ``ServerListener``: forwards viewer subscriptions to the node's loop (SDK threads call it)."""

    def __init__(self, node: VizNode) -> None:
        self.node = node

    def on_subscribe(self, client, channel) -> None:
        loop = self.node._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self.node._on_viewer_subscribe, channel.topic)


class VizNode(Node):
    """Foxglove bridge (see module docstring). Params: :class:`VizParams`."""

    Params = VizParams
    node_type = "viz"
    DRAIN_PERIOD = 0.05     #: s, inputs received in ~20 batches a second (module docstring)

    async def setup(self) -> None:
        p: VizParams = self.params
        cfg = VizConfig(eye=np.asarray(p.eye), ipd=p.ipd,
                        projector=Projector.default(p.width, p.height, p.projector_pixel, p.projector_position),
                        left_base=tuple(p.left_base), right_base=tuple(p.right_base), sheet_grid=p.sheet_grid,
                        camera_scale=p.camera_scale,
                        sheet=SheetConfig(half_width=p.sheet_half_width, push_threshold=p.push_threshold,
                                          fine_modes=p.fine_modes, tension_ratio=p.tension_ratio,
                                          cache_dir=p.sheet_cache, mesh=dict(p.sheet_mesh)))
        self.streams = FoxgloveStreams(SceneBuilder(cfg), Rates(scene=p.scene_rate, camera=p.camera_rate,
                                                                render=p.render_rate, json=p.json_rate,
                                                                calibration=p.calibration_rate))
        self.context = foxglove.Context()
        self.channels = {topic: foxglove.Channel(topic, schema=schema, message_encoding=enc, context=self.context)
                         for topic, (schema, enc) in channel_schemas().items()}
        try:
            self.server = foxglove.start_server(name=f"flexsheet {self.name}", host=p.host, port=p.port,
                                                context=self.context, message_backlog_size=p.backlog,
                                                server_listener=_Listener(self))
        except Exception as exc:  # the SDK raises its own error type; name the address
            raise RuntimeError(f"viz: cannot serve Foxglove on {p.host}:{p.port}: {exc}") from exc
        self.port = self.server.port
        self.sent = 0
        self._subscribed: set[str] = set()
        self.timer(1.0 / p.poll_rate, self.on_poll)
        self.log.info("Foxglove WebSocket server on ws://%s:%d", p.host, self.port)

    def _on_viewer_subscribe(self, topic: str) -> None:
        """A viewer subscribed to Foxglove channel ``topic`` (called on the loop): subscribe its inputs."""
        for t in inputs_for(topic):
            if t.name not in self._subscribed:
                self._subscribed.add(t.name)
                src = t.renamed(self.params.camera_topic) if t is T.STEREO else t   # same type, same stream key
                self.subscribe(src, self._handler(t.name), qos=QoS.LATCHED if t.latched else QoS.LATEST)

    def wanted(self, topic: str) -> bool:
        """True if a viewer subscribes to Foxglove channel ``topic``."""
        return self.channels[topic].has_sinks()

    def _handler(self, name: str):
        p: VizParams = self.params
        rate = {T.STEREO.name: p.camera_rate, T.RENDERED.name: max(p.render_rate, p.scene_rate)}.get(name,
                                                                                                   p.input_rate)
        rest = 1.0 / (rate if rate > 0 else p.input_rate)

        async def on_message(msg) -> None:
            try:
                out = self.streams.on_message(name, msg, time.time(), self.wanted)
            except ValueError as exc:
                raise InputRejected(str(exc)) from exc
            self._emit(out)
            await asyncio.sleep(rest)  # QoS latest: what arrives meanwhile replaces itself (counted dropped)
            while not self._watched():  # no viewer now: decode nothing, the newest message waits in the queue
                await asyncio.sleep(_IDLE_S)
        return on_message

    def _watched(self) -> bool:
        """True while a viewer subscribes to any Foxglove channel (checked once a second per input)."""
        return any(ch.has_sinks() for ch in self.channels.values())

    def on_poll(self) -> None:
        self._emit(self.streams.poll(time.time(), self.wanted))

    def _emit(self, outputs) -> None:
        for topic, data, t in outputs:
            self.channels[topic].log(data, log_time=int(t * 1e9))
            self.sent += 1

    async def teardown(self) -> None:
        if hasattr(self, "server"):
            self.server.stop()
        for ch in getattr(self, "channels", {}).values():
            ch.close()
