"""Node ``viz``: the Foxglove WebSocket bridge. Serves the display's state in Foxglove's own schemas.

Thin shell around :mod:`flexsheet.viz.foxglove` (what is drawn, how it is encoded, at what rate) and the
``foxglove-sdk`` WebSocket server behind :class:`~flexsheet.viz.ws_relay.SubprotocolRelay` (default port 8765;
a viewer may offer either ``foxglove.websocket.v1``, as Lichtblick and the official ``@foxglove/ws-protocol``
client do, or ``foxglove.sdk.v1``). Open ``ws://HOST:8765`` in Foxglove or Lichtblick and import
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
  :class:`~flexsheet.runtime.zmq.transport.ZmqTransport` ``drain_period``): ZeroMQ queues the ~650 input
  messages/s of the sim and the loop wakes ~20 times a second instead of once per message (in a composable
  container the bus delivers as usual);
* outputs are built only for channels a viewer subscribes to: ``/viz/scene``, ``/viz/tf``, ``/viz/metrics``
  at ``scene_rate``, the camera images at ``camera_rate`` (downscaled by ``camera_scale``), ``/render/image``
  at ``render_rate``, the JSON copies of the plain topics as they arrive (≤ ``input_rate``); the scene is
  assembled from cached encoded entities, each rebuilt only when its input changed (foxglove_scene);
* a slow viewer loses the oldest queued messages (the server keeps at most ``backlog`` per client);
* it advertises Foxglove's ``time`` capability and broadcasts the graph's time every ``TIME_PERIOD`` (0.25 s
  of the graph's clock): on a simulated clock a viewer's timeline follows simulated time. The SDK server
  queues these per viewer in a queue of ``backlog`` that it does not thin, and lets go a viewer whose queue is
  full (a viewer that reads nothing for ``backlog`` × 0.25 s, 16 s at the defaults), so they are few.

Publishes nothing on the graph (only its heartbeat). Input the scene cannot use (faces out of range, bad
joints) is rejected and counted.
"""

from __future__ import annotations

import dataclasses
import math

import foxglove
import numpy as np
from foxglove.websocket import Capability, ServerListener
from pydantic import Field, field_validator

from flexsheet.model.projector import Projector
from flexsheet.model.sheet_model import SheetConfig
from flexsheet.rendering.config import SHEET_PARAMS, RendererConfig
from flexsheet.runtime.heap import Trimmer
from flexsheet.runtime.node import InputRejected, Node
from flexsheet.runtime.params import config_fields, params_model
from flexsheet.runtime.qos import QoS
from flexsheet.viz.config import VizConfig, VizNodeConfig
from flexsheet.viz.foxglove import channel_schemas, inputs_for
from flexsheet.viz.scene_builder import SceneBuilder
from flexsheet.viz.streams import FoxgloveStreams, Rates
from flexsheet.viz.ws_relay import SubprotocolRelay
from messages import topics as T

__all__ = ["VizNode", "VizParams"]

_IDLE_S = 1.0  # how often a parked input handler looks for a viewer again, s


def _vec3(cls, v: list[float]) -> list[float]:
    if len(v) != 3 or not all(np.isfinite(v)):
        raise ValueError(f"must be 3 finite numbers, got {v!r}")
    return v


def _finite(cls, v: list[float]) -> list[float]:
    if not all(np.isfinite(v)):
        raise ValueError(f"must be finite, got {v!r}")
    return v


#: the WebSocket server: device settings, the node's own
_SERVER = {
    "host": (str, Field("127.0.0.1", description="address the WebSocket server binds (0.0.0.0: every "
                                                 "interface)")),
    "port": (int, Field(8765, ge=0, le=65535, description="WebSocket port (0: any free port)")),
    "backlog": (int, Field(64, ge=1, le=100000, description="messages queued per viewer; older ones are "
                                                            "dropped")),
}

#: the believed sheet: the renderer's pushed-sheet model
#: (flexsheet.model.sheet_model.sheet_model_for); these are the renderer's params (same names,
#: defaults and ranges): give them its values and the drawn dent is the one it corrects for
_SHEET = config_fields(
    RendererConfig,
    exclude=[f.name for f in dataclasses.fields(RendererConfig) if f.name not in SHEET_PARAMS],
    descriptions={"depth_table_step": "as the renderer's depth_table_step, m",
                  "tension_ratio": "as the renderer's tension_ratio",
                  "sheet_cache": "as the renderer's sheet_cache (its FEM tables are read from there, never "
                                 "built by the bridge)",
                  "sheet_mesh": "as the renderer's sheet_mesh", "push_threshold": "as the renderer's, m",
                  "sheet_half_width": "as the renderer's, m"})

VizParams = params_model(
    "VizParams",
    """Parameters of the viz bridge (SI units, display frame).

    The server's ``host``, ``port``, ``backlog`` are the node's own; the believed sheet's
    (``depth_table_step`` … ``sheet_half_width``) are the renderer's
    (:class:`flexsheet.rendering.config.RendererConfig`); every other param is a field of — defined, defaulted
    and range-checked in — :class:`flexsheet.viz.config.VizNodeConfig`.
    """,
    _SERVER,
    config_fields(VizNodeConfig),
    _SHEET,
    validators={"_vec3": field_validator("eye", "projector_position")(_vec3),
                "_finite": field_validator("left_base", "right_base")(_finite)},
    module=__name__,
)


class _Listener(ServerListener):
    """foxglove-sdk ``ServerListener``: forwards viewer subscriptions to the node's loop (SDK threads call
    it)."""

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
    TIME_PERIOD = 0.25      #: s of the graph's clock between two server times (module docstring)

    async def setup(self) -> None:
        p: VizParams = self.params
        cfg = VizConfig(eye=np.asarray(p.eye), ipd=p.ipd,
                        projector=Projector.default(p.width, p.height, p.projector_pixel,
                                                    p.projector_position),
                        left_base=tuple(p.left_base), right_base=tuple(p.right_base), sheet_grid=p.sheet_grid,
                        camera_scale=p.camera_scale,
                        sheet=SheetConfig(half_width=p.sheet_half_width, push_threshold=p.push_threshold,
                                          grid_step=p.depth_table_step, tension_ratio=p.tension_ratio,
                                          cache_dir=p.sheet_cache, mesh=dict(p.sheet_mesh)))
        self.streams = FoxgloveStreams(SceneBuilder(cfg), Rates(scene=p.scene_rate, camera=p.camera_rate,
                                                                render=p.render_rate, json=p.json_rate,
                                                                calibration=p.calibration_rate))
        self.context = foxglove.Context()
        self.channels = {topic: foxglove.Channel(topic, schema=schema, message_encoding=enc,
                                                 context=self.context)
                         for topic, (schema, enc) in channel_schemas().items()}
        try:    # the SDK's server on a loopback port of its own; viewers reach it through the relay
            self.server = foxglove.start_server(name=f"flexsheet {self.name}", host="127.0.0.1", port=0,
                                                context=self.context, message_backlog_size=p.backlog,
                                                server_listener=_Listener(self),
                                                capabilities=[Capability.Time])
        except Exception as exc:  # the SDK raises its own error type; name the address
            raise RuntimeError(f"viz: cannot start the Foxglove server: {exc}") from exc
        self.relay = SubprotocolRelay(p.host, p.port, self.server.port)
        try:
            self.relay.start()
        except OSError as exc:
            self.server.stop()
            raise RuntimeError(f"viz: {exc}") from None
        self.port = self.relay.port
        self.sent = 0
        self._subscribed: set[str] = set()
        self._time_sent = -math.inf
        self._trimmer = Trimmer()
        self.timer(1.0 / p.poll_rate, self.on_poll)
        self.log.info("Foxglove WebSocket server on ws://%s:%d", p.host, self.port)

    def _on_viewer_subscribe(self, topic: str) -> None:
        """A viewer subscribed to Foxglove channel ``topic`` (called on the loop): subscribe its inputs."""
        for t in inputs_for(topic):
            if t.name not in self._subscribed:
                self._subscribed.add(t.name)
                # same type, same stream key
                src = t.renamed(self.params.camera_topic) if t is T.STEREO else t
                self.subscribe(src, self._handler(t.name), qos=QoS.LATCHED if t.latched else QoS.LATEST)

    def wanted(self, topic: str) -> bool:
        """True if a viewer subscribes to Foxglove channel ``topic``."""
        return self.channels[topic].has_sinks()

    def _handler(self, name: str):
        p: VizParams = self.params
        rate = {T.STEREO.name: p.camera_rate, T.RENDERED.name: max(p.render_rate, p.scene_rate)}.get(name,
                                                                                                   p.input_rate)
        rest = 1.0 / (rate if rate > 0 else p.input_rate)

        last = [-math.inf]

        async def on_message(msg) -> None:
            # skip what the rate or an absent viewer does not want (the next message brings the newest state)
            now = self.monotonic()
            if now - last[0] >= rest and self._watched():
                last[0] = now
                try:
                    out = self.streams.on_message(name, msg, self.now(), self.wanted)
                except ValueError as exc:
                    raise InputRejected(str(exc)) from exc
                self._emit(out)
            # QoS latest: what arrives meanwhile replaces itself (counted dropped); no viewer: decode nothing
            await self.pause(rest, self._watched, _IDLE_S)
        return on_message

    def _watched(self) -> bool:
        """True while a viewer subscribes to any Foxglove channel (checked once a second per input)."""
        return any(ch.has_sinks() for ch in self.channels.values())

    def on_poll(self) -> None:
        self._emit(self.streams.poll(self.now(), self.wanted))
        self._trimmer.maybe()          # the freed frame buffers back to the OS every 10 s of wall time
        # the viewers' timeline follows the graph's clock
        # (simulated time on a simulated clock): capability "time"
        now = self.now()
        if now - self._time_sent >= self.TIME_PERIOD:
            self._time_sent = now
            self.server.broadcast_time(int(round(now * 1e9)))

    def _emit(self, outputs) -> None:
        for topic, data, t in outputs:
            self.channels[topic].log(data, log_time=int(t * 1e9))
            self.sent += 1

    async def teardown(self) -> None:
        if hasattr(self, "relay"):
            self.relay.stop()
        if hasattr(self, "server"):
            self.server.stop()
        for ch in getattr(self, "channels", {}).values():
            ch.close()
