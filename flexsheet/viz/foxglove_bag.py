"""Foxglove channels in bags: the live viz bridge's scene, frames, images and metrics, written into MCAP.

A bag opened in Foxglove or Lichtblick then shows the same 3-D scene and images as the live bridge
(``nodes/viz``), from the same code (:mod:`flexsheet.viz.foxglove`). Two ways in:

* **while recording** — :class:`FoxgloveBagChannels` on the recorder's MCAP writer, fed every raw message
  (:meth:`add_frames`, from the writer thread). It only keeps the newest raw frames per topic and decodes
  them when an output is due (by log time: 10 Hz scene by default), so its cost does not grow with the
  message rate. It writes ``/viz/scene``, ``/viz/tf``, ``/viz/metrics``, ``/camera/*`` and ``/render/image``:
  names that no flexsheet topic uses, so the lossless ``flexsheet-msgpack`` channels stay as they are.
* **on export** — the same object fed decoded messages (:meth:`add_message`) inside ``bag export``, or
  :func:`add_foxglove` to append the channels to any MCAP writer from a bag file.

Channels carry the Foxglove schemas (``protobuf`` FileDescriptorSets from the foxglove-sdk, or
``jsonschema``), so any MCAP reader decodes them. Nothing here ever raises into the recorder: a message
that cannot be decoded or drawn is counted in ``rejected``.
Source: MCAP specification (mcap.dev/spec): schema/channel records may appear anywhere before their messages.
"""

from __future__ import annotations

import logging
from collections import Counter
from pathlib import Path

from mcap.writer import Writer

from flexsheet.runtime.bag_read import read_bag
from flexsheet.runtime.codec import DecodeError, decode_any
from flexsheet.viz.config import VizConfig
from flexsheet.viz.foxglove import JSON_TOPICS, channel_schemas
from flexsheet.viz.scene_builder import SceneBuilder
from flexsheet.viz.streams import FoxgloveStreams, Output, Rates
from messages import Message

__all__ = ["FoxgloveBagChannels", "add_foxglove"]

log = logging.getLogger(__name__)
_JSON_NAMES = {t.name for t in JSON_TOPICS}


class FoxgloveBagChannels:
    """Writes Foxglove channels into an open :class:`mcap.writer.Writer` (see module docstring).

    ``rates``: :class:`Rates` by log time (default: scene 10 Hz, images 5 Hz); ``config``: scene geometry
    (:class:`VizConfig`); ``json_copies``: also write JSON copies of the plain topics under their own names —
    only for a file that has no other channel of those names (never beside the recorder's raw channels).
    ``counts``: messages written per Foxglove topic; ``rejected``: inputs skipped, per reason.
    Not thread-safe: call from one thread (the recorder's writer thread).
    """

    def __init__(self, writer: Writer, rates: Rates | None = None, config: VizConfig | None = None,
                 json_copies: bool = False) -> None:
        self.writer = writer
        self.streams = FoxgloveStreams(SceneBuilder(config), rates or Rates())
        self.json_copies = json_copies
        self._schemas = channel_schemas()
        self._channels: dict[str, int] = {}
        self._pending: dict[str, list] = {}
        self._tick = max((r for r in (self.streams.rates.scene, self.streams.rates.camera,
                                      self.streams.rates.render) if r > 0), default=1.0)
        self._next = 0.0
        self._last_t = 0.0
        self.counts: Counter = Counter()
        self.rejected: Counter = Counter()

    def _wanted(self, topic: str) -> bool:
        return self.json_copies or topic not in _JSON_NAMES

    def _channel(self, topic: str) -> int:
        ch = self._channels.get(topic)
        if ch is None:
            schema, encoding = self._schemas[topic]
            sid = self.writer.register_schema(schema.name, schema.encoding, schema.data)
            ch = self._channels[topic] = self.writer.register_channel(topic, encoding, sid)
        return ch

    def _write(self, outputs: list[Output]) -> None:
        for topic, data, t in outputs:
            t_ns = int(t * 1e9)
            self.writer.add_message(self._channel(topic), log_time=t_ns, data=data, publish_time=t_ns,
                                    sequence=self.counts[topic] & 0xFFFFFFFF)
            self.counts[topic] += 1

    def add_message(self, topic: str, msg: Message, log_time_ns: int) -> None:
        """Feed one decoded message (log time in ns); writes whatever is due. Never raises."""
        t = log_time_ns / 1e9
        try:
            self._write(self.streams.on_message(topic, msg, t, self._wanted))
        except Exception as exc:  # noqa: BLE001 - a bad message must never stop a recording or an export
            self.rejected[f"{topic}: {type(exc).__name__}"] += 1
            log.debug("foxglove channels: %s rejected: %s", topic, exc)
        self._poll(t)

    def add_frames(self, frames: list, log_time_ns: int) -> None:
        """Feed one raw wire message ``[topic, meta, *buffers]`` (log time in ns). Decodes lazily: only the
        newest frames of each topic, when an output is due. Never raises."""
        topic = bytes(frames[0]).decode(errors="replace")
        self._pending[topic] = frames
        t = log_time_ns / 1e9
        if t >= self._next - 1e-3 / self._tick or t < self._last_t:
            self._flush_pending(t)
            self._poll(t)

    def _flush_pending(self, t: float) -> None:
        pending, self._pending = self._pending, {}
        for topic, frames in pending.items():
            try:
                msg = decode_any(frames)
            except DecodeError:
                self.rejected[f"{topic}: undecodable"] += 1
                continue
            try:
                self._write(self.streams.on_message(topic, msg, t, self._wanted))
            except Exception as exc:  # noqa: BLE001
                self.rejected[f"{topic}: {type(exc).__name__}"] += 1
                log.debug("foxglove channels: %s rejected: %s", topic, exc)

    def _poll(self, t: float) -> None:
        period = 1.0 / self._tick
        self._next = self._next + period if self._last_t <= t < self._next + period else t + period
        self._last_t = t
        try:
            self._write(self.streams.poll(t, self._wanted))
        except Exception as exc:  # noqa: BLE001
            self.rejected[f"poll: {type(exc).__name__}"] += 1
            log.warning("foxglove channels: building the scene failed: %s", exc)

    def close(self) -> None:
        """Write what the last messages changed (call before ``writer.finish()``)."""
        if self._pending:
            self._flush_pending(self._last_t)
        self.streams.rearm()  # the bag ends on the final state
        self._poll(self._last_t)


def add_foxglove(src: str | Path, writer: Writer, rates: Rates | None = None, config: VizConfig | None = None,
                 json_copies: bool = False) -> Counter:
    """Append the Foxglove channels built from bag ``src`` (a flexsheet MCAP) to an open MCAP ``writer``.

    Returns messages written per Foxglove topic (plus ``"<rejected>"``). Raises ``ValueError`` if ``src`` is
    not an MCAP file. Example::

        with open("run_fox.mcap", "wb") as fh:
            w = Writer(fh); w.start()
            add_foxglove("run.mcap", w, json_copies=True)
            w.finish()
    """
    fox = FoxgloveBagChannels(writer, rates, config, json_copies)
    for m in read_bag(src):
        if not json_copies:
            fox.add_frames(m.frames, int(m.log_time * 1e9))  # lazy: decodes only what is drawn
            continue
        try:
            msg = decode_any(m.frames)
        except DecodeError:
            fox.rejected[f"{m.topic}: undecodable"] += 1
            continue
        fox.add_message(m.topic, msg, int(m.log_time * 1e9))  # every message: full-rate JSON copies
    fox.close()
    out = Counter(fox.counts)
    if fox.rejected:
        out["<rejected>"] = sum(fox.rejected.values())
    return out
