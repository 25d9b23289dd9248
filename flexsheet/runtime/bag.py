"""Bags in MCAP (the ``mcap`` package): record, play, info, export.

* Record stores each message's raw wire frames (``meta`` + array buffers, msgpack-framed as one record, no
  re-encoding: lossless) on a channel per topic, with message encoding ``flexsheet-msgpack`` and the
  message's pydantic JSON schema (encoding ``jsonschema``). Chunks are small (256 KiB, LZ4) and written
  unbuffered, so a bag cut by a crash or ``kill -9`` stays readable up to its last complete chunk.
  Messages lost on the wire (publisher sequence gaps) are counted and stored as MCAP metadata.
* Play republishes the same frames with the original relative timing (``--rate`` scales it), from a node
  endpoint, so that subscribers cannot tell a replay from a live run.
* Export transcodes to JSON-encoded MCAP with jsonschema (Foxglove/Lichtblick open it); image fields become
  ``foxglove.CompressedImage`` (PNG) channels ``<topic>/<field>``.

Source: MCAP specification (mcap.dev/spec), Foxglove schemas (foxglove.CompressedImage).
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import json
import os
import queue
import threading
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import msgpack
import numpy as np
from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from pydantic import BaseModel, ConfigDict, Field

from flexsheet.runtime.codec import DecodeError, decode_any, peek_schema
from flexsheet.runtime.extensions import bag_channels
from flexsheet.runtime.node import Node, NodeConfig
from messages import MESSAGE_TYPES

__all__ = ["BagWriter", "read_bag", "BagMessage", "bag_info", "export_bag", "RecorderNode", "PlayerNode"]

ENCODING = "flexsheet-msgpack"
CHUNK_SIZE = 256 * 1024


class _DirectFile:
    """A file whose every ``write`` goes straight to the OS (no user-space buffer), so a completed MCAP
    chunk is on disk even if the process is killed right after. (mcap's Writer would wrap a raw file in a
    ``BufferedWriter``; this object is not a ``RawIOBase`` so it is used as is.)"""

    def __init__(self, path: Path) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._pos = 0

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        while view:
            n = os.write(self._fd, view)
            view = view[n:]
            self._pos += n
        return len(data)

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        pass

    def close(self) -> None:
        os.close(self._fd)


class BagWriter:
    """Writes raw wire frames to an MCAP file from a background thread (the caller never blocks on disk).

    If ``path`` already holds data (a respawned recorder), the bag goes to ``<stem>.1.mcap``, ``.2``…
    instead, so nothing recorded before is lost. ``write(frames, log_time_ns)`` queues one message (``frames`` = ``[topic, meta, *buffers]``);
    ``close()`` flushes and writes the summary and the ``recorder`` metadata (message and drop counts).
    """

    def __init__(self, path: str | Path, chunk_size: int = CHUNK_SIZE, max_queue_bytes: int = 256 << 20,
                 foxglove: bool = False) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        n = 1
        while path.exists() and path.stat().st_size > 0:  # a respawned recorder never overwrites its bag
            path = Path(path.parent, f"{Path(path).name.split('.')[0]}.{n}.mcap")
            n += 1
        self.path = path
        self.max_queue_bytes = max_queue_bytes
        self._queued = 0
        self._fh = _DirectFile(self.path)
        self._writer = Writer(self._fh, chunk_size=chunk_size, compression=CompressionType.LZ4)
        self._writer.start(profile="flexsheet", library="flexsheet")
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._seq: dict[str, int] = {}
        self.counts: Counter = Counter()
        self.dropped: Counter = Counter()
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self.foxglove = None
        if foxglove:  # Foxglove channels (/viz/*, images) beside the lossless ones: the bag opens with the scene
            self.foxglove = bag_channels("foxglove")(self._writer)
        self._thread = threading.Thread(target=self._run, name="bag-writer", daemon=True)
        self._thread.start()

    def write(self, frames: list, log_time_ns: int) -> None:
        """Queue one message; if the disk falls behind by more than ``max_queue_bytes`` it is dropped and
        counted under ``"<recorder queue full>"`` (memory stays bounded)."""
        size = sum(memoryview(f).nbytes for f in frames)
        if self._queued + size > self.max_queue_bytes:
            self.dropped["<recorder queue full>"] += 1
            return
        self._queued += size
        self._q.put((frames, log_time_ns, size))

    def _channel(self, topic: str, meta: bytes) -> int:
        ch = self._channels.get(topic)
        if ch is None:
            schema_name, _version = peek_schema(meta)
            sid = self._schemas.get(schema_name)
            if sid is None:
                cls = MESSAGE_TYPES.get(schema_name)
                data = json.dumps(cls.model_json_schema() if cls else {}).encode()
                sid = self._schemas[schema_name] = self._writer.register_schema(schema_name, "jsonschema", data)
            ch = self._channels[topic] = self._writer.register_channel(topic, ENCODING, sid)
        return ch

    def _run(self) -> None:
        while True:
            item = self._q.get()
            if item is None:
                return
            frames, t_ns, size = item
            self._queued -= size
            topic = bytes(frames[0]).decode(errors="replace")
            meta = bytes(frames[1])
            try:
                ch = self._channel(topic, meta)
                seq = msgpack.unpackb(meta, ext_hook=lambda c, d: None)["d"]["header"]["seq"]
            except Exception:  # noqa: BLE001 - a garbage message is counted, never crashes the recorder
                self.dropped["<undecodable>"] += 1
                continue
            if topic != "/diagnostics":
                last = self._seq.get(topic)
                if last is not None and seq > last + 1:
                    self.dropped[topic] += seq - last - 1
                self._seq[topic] = seq
            data = msgpack.packb([bytes(f) for f in frames[1:]])
            self._writer.add_message(ch, log_time=t_ns, data=data, publish_time=t_ns, sequence=seq & 0xFFFFFFFF)
            self.counts[topic] += 1
            if self.foxglove is not None:
                self.foxglove.add_frames(frames, t_ns)

    def close(self) -> None:
        self._q.put(None)
        self._thread.join()
        if self.foxglove is not None:
            self.foxglove.close()
        self._writer.add_metadata("recorder", {"counts": json.dumps(dict(self.counts)),
                                               "dropped": json.dumps(dict(self.dropped))})
        self._writer.finish()
        self._fh.close()


@dataclass
class BagMessage:
    """One recorded message: ``topic``, ``schema`` name, ``log_time`` (s), raw ``frames`` [topic, meta, *buffers]."""

    topic: str
    schema: str
    log_time: float
    frames: list[bytes]


@dataclass
class BagSummary:
    """Summary of a bag: per-topic counts and schemas, time span (s), drops, whether it was cut short."""

    counts: Counter = field(default_factory=Counter)
    schemas: dict[str, str] = field(default_factory=dict)
    start: float = 0.0
    end: float = 0.0
    dropped: dict[str, int] = field(default_factory=dict)
    truncated: bool = False


def _records(fh, path: str | Path, summary: BagSummary | None) -> Iterator:
    """The MCAP records of the open file ``fh`` up to its last readable one. A truncated or corrupt tail ends
    the iteration (``summary.truncated`` set unless the footer was already read); a file that is not MCAP
    from its first bytes raises ``ValueError`` naming ``path``."""
    it = iter(StreamReader(fh).records)
    complete = False
    while True:
        try:
            rec = next(it)
        except StopIteration:
            return
        except Exception as exc:  # noqa: BLE001 - truncated/corrupt tail: keep what was complete
            if fh.tell() <= 8:
                raise ValueError(f"{path}: not an MCAP file ({exc})") from None
            if summary is not None and not complete:
                summary.truncated = True
            return
        complete = complete or isinstance(rec, Footer)
        yield rec


def read_bag(path: str | Path, topics: list[str] | None = None, summary: BagSummary | None = None) -> Iterator[BagMessage]:
    """Iterate the messages of a bag in file order, even if the file was cut by a crash.

    ``topics``: only these (all if empty). A truncated file yields every message up to its last complete
    chunk and sets ``summary.truncated``; the recorder's drop counts go to ``summary.dropped``. Raises
    ``ValueError`` naming the file if it is not an MCAP file at all.
    """
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    with open(path, "rb") as fh:
        for rec in _records(fh, path, summary):
            if isinstance(rec, Message):
                ch = channels[rec.channel_id]
                if ch.message_encoding != ENCODING:   # e.g. the Foxglove /viz/* channels beside ours
                    continue
                if not topics or ch.topic in topics:
                    schema = schemas[ch.schema_id].name if ch.schema_id in schemas else ""
                    yield BagMessage(ch.topic, schema, rec.log_time / 1e9, [ch.topic.encode(), *msgpack.unpackb(rec.data)])
            elif isinstance(rec, Schema):
                schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
            elif isinstance(rec, Metadata) and rec.name == "recorder" and summary is not None:
                summary.dropped = json.loads(rec.metadata.get("dropped", "{}"))


def bag_info(path: str | Path) -> BagSummary:
    """Counts, schemas, time span and drops of a bag (reads the whole file; tolerant of truncation)."""
    s = BagSummary()
    first = True
    for m in read_bag(path, summary=s):
        s.counts[m.topic] += 1
        s.schemas[m.topic] = m.schema
        if first:
            s.start, first = m.log_time, False
        s.end = max(s.end, m.log_time)
    return s


def _foxglove_image_schema() -> dict:
    return {"title": "foxglove.CompressedImage", "type": "object", "properties": {
        "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
        "frame_id": {"type": "string"},
        "data": {"type": "string", "contentEncoding": "base64"},
        "format": {"type": "string"}}}


def export_bag(src: str | Path, dst: str | Path, foxglove: bool = True) -> Counter:
    """Transcode ``src`` to JSON-encoded MCAP ``dst`` with jsonschema channels; images → foxglove.CompressedImage.

    Returns per-channel message counts. Messages that fail to decode are skipped and counted under
    ``"<rejected>"``. With ``foxglove`` the Foxglove scene channels (``/viz/scene``, ``/viz/tf``, images;
    :mod:`flexsheet.viz.foxglove_bag`) are added, so the exported bag opens in Foxglove with the 3-D scene.
    """
    import cv2

    counts: Counter = Counter()
    with open(dst, "wb") as fh:
        w = Writer(fh)
        w.start(profile="", library="flexsheet")
        fox = None
        if foxglove:
            fox = bag_channels("foxglove")(w)
        sids: dict[str, int] = {}
        chans: dict[str, int] = {}

        def channel(topic: str, schema_name: str, schema: dict) -> int:
            if topic not in chans:
                if schema_name not in sids:
                    sids[schema_name] = w.register_schema(schema_name, "jsonschema", json.dumps(schema).encode())
                chans[topic] = w.register_channel(topic, "json", sids[schema_name])
            return chans[topic]

        for m in read_bag(src):
            try:
                msg = decode_any(m.frames)
            except DecodeError:
                counts["<rejected>"] += 1
                continue
            t = int(m.log_time * 1e9)
            if fox is not None:
                fox.add_message(m.topic, msg, t)
            images = {k: v for k, v in msg.__dict__.items() if isinstance(v, np.ndarray) and v.dtype == np.uint8
                      and v.ndim in (2, 3) and v.shape[0] > 8}
            stamp = msg.header.stamp
            for fname, img in images.items():
                ok, png = cv2.imencode(".png", img if img.ndim == 2 else img[:, :, ::-1])
                payload = {"timestamp": {"sec": int(stamp), "nsec": int((stamp % 1) * 1e9)},
                           "frame_id": msg.header.frame_id, "data": base64.b64encode(png.tobytes()).decode(),
                           "format": "png"}
                topic = f"{m.topic}/{fname}"
                w.add_message(channel(topic, "foxglove.CompressedImage", _foxglove_image_schema()), log_time=t,
                              data=json.dumps(payload).encode(), publish_time=t)
                counts[topic] += 1
            if not images:
                data = msg.model_dump_json().encode()
                w.add_message(channel(m.topic, msg.SCHEMA, type(msg).model_json_schema()), log_time=t, data=data,
                              publish_time=t)
                counts[m.topic] += 1
        if fox is not None:
            fox.close()
            counts.update(fox.counts)
        w.finish()
    return counts


# ------------------------------------------------------------------------------------------------ nodes
class RecorderParams(BaseModel):
    """``output``: .mcap path (``$(out)`` allowed); ``topics``: topics to record (empty: all); ``foxglove``:
    also write the Foxglove scene channels while recording (costs the recorder a decode per message; off by
    default on a small machine — ``flexsheet bag export`` adds them afterwards)."""

    model_config = ConfigDict(extra="forbid")
    output: str = "bag.mcap"
    topics: list[str] = Field(default_factory=list)
    foxglove: bool = False


class RecorderNode(Node):
    """Records raw frames of the live graph into an MCAP bag (QoS keep-all; nothing is decoded)."""

    Params = RecorderParams
    node_type = "recorder"

    async def setup(self) -> None:
        self.writer = BagWriter(self.params.output, foxglove=self.params.foxglove)
        for t in self.params.topics or [""]:
            self.transport.subscribe(t)
        self.log.info("recording %s to %s", ", ".join(self.params.topics) or "all topics", self.params.output)

    def _on_frames(self, frames: list) -> None:  # raw frames straight from the transport
        if self.params.topics and bytes(frames[0]).decode(errors="replace") not in self.params.topics:
            return
        self.writer.write(frames, time.time_ns())

    async def teardown(self) -> None:
        self.writer.close()
        total = sum(self.writer.counts.values())
        self.log.info("bag %s: %d messages on %d topics, %d dropped", self.params.output, total,
                      len(self.writer.counts), sum(self.writer.dropped.values()))


class PlayerParams(BaseModel):
    """``file``: bag to play; ``rate``: speed factor; ``loop``; ``topics`` (empty: all);
    ``start_delay`` s before the first message (subscribers connect); ``exit_when_done``; ``mode``:
    ``realtime`` (the bag's timing × ``rate``) or ``lockstep`` (as fast as the nodes of the player's container
    handle it, each message handled before the next, on the bag's clock: :mod:`flexsheet.runtime.lockstep`)."""

    model_config = ConfigDict(extra="forbid")
    file: str
    rate: float = Field(default=1.0, gt=0.0)
    loop: bool = False
    topics: list[str] = Field(default_factory=list)
    start_delay: float = Field(default=0.5, ge=0.0)
    exit_when_done: bool = True
    mode: Literal["realtime", "lockstep"] = "realtime"


_PLAY_LEAD_S = 0.005  # s; see PlayerNode._play


class PlayerNode(Node):
    """Republishes a bag's raw frames with the original relative timing, from this node's endpoint."""

    Params = PlayerParams
    node_type = "player"

    async def setup(self) -> None:
        if not Path(self.params.file).exists():
            raise ValueError(f"file: bag {self.params.file!r} not found")
        self.done = asyncio.Event()
        self.sent = 0
        if self.params.mode == "lockstep":
            from flexsheet.runtime import lockstep

            lockstep.check(self)  # ConfigError (exit 78) unless the player is in a lockstep container
            self._task = asyncio.get_running_loop().create_task(lockstep.play(self))
            return
        asyncio.get_running_loop().create_task(self._play())

    async def _play(self) -> None:
        await asyncio.sleep(self.params.start_delay)
        latched = {t.name for t in __import__("messages.topics", fromlist=["ALL"]).ALL if t.latched}
        while True:
            t0_bag = t0 = None
            for m in read_bag(self.params.file, self.params.topics or None):
                if t0_bag is None:  # anchor once the bag is open, a little ahead: the first message then waits
                    t0_bag = m.log_time  # through the same timer as the rest and shares their wake-up latency
                    t0 = time.monotonic() + _PLAY_LEAD_S
                due = t0 + (m.log_time - t0_bag) / self.params.rate
                delay = due - time.monotonic()
                if delay > 0:
                    await asyncio.sleep(delay)
                if m.topic in latched:
                    self.transport.set_latched(m.topic, m.frames)
                self.transport.send(m.frames)
                self.sent += 1
            if not self.params.loop:
                break
        self.log.info("played %d messages from %s", self.sent, self.params.file)
        self.done.set()
        if self.params.exit_when_done:
            await asyncio.sleep(0.2)
            self.shutdown()


# ------------------------------------------------------------------------------------------------ CLI
def _graph(launch: str):
    from flexsheet.runtime.launch import curve_config, load_launch

    lf = load_launch(launch)
    return list(lf.endpoints().values()), curve_config(lf, None)


def cmd_record(args: argparse.Namespace) -> int:
    import logging
    logging.basicConfig(level="INFO", format="%(levelname)s %(name)s: %(message)s")
    out = args.output or time.strftime("bag_%Y%m%d_%H%M%S.mcap")
    peers, curve = _graph(args.launch)
    node = RecorderNode(NodeConfig(name="bag_record", node_type="recorder", endpoint="", peers=peers, curve=curve,
                                   params={"output": out, "topics": args.topics}))

    async def main() -> None:
        if args.duration:
            asyncio.get_running_loop().call_later(args.duration, node.shutdown)
        await node.run()

    asyncio.run(main())
    print(f"wrote {out}: {sum(node.writer.counts.values())} messages, {sum(node.writer.dropped.values())} dropped")
    return 0


def cmd_play(args: argparse.Namespace) -> int:
    import logging
    logging.basicConfig(level="INFO", format="%(levelname)s %(name)s: %(message)s")
    node = PlayerNode(NodeConfig(name="bag_play", node_type="player", endpoint=args.endpoint, peers=[],
                                 params={"file": args.file, "rate": args.rate, "loop": args.loop,
                                         "topics": args.topics or [], "start_delay": args.start_delay}))
    asyncio.run(node.run())
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    try:
        s = bag_info(args.file)
    except (ValueError, FileNotFoundError) as exc:
        print(f"flexsheet bag info: {exc}")
        return 2
    size = Path(args.file).stat().st_size
    print(f"file:      {args.file} ({size / 1e6:.2f} MB){'  [TRUNCATED: read up to last complete chunk]' if s.truncated else ''}")
    print(f"duration:  {s.end - s.start:.3f} s  (start {time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(s.start))})")
    print(f"messages:  {sum(s.counts.values())}   dropped on the wire: {sum(s.dropped.values()) if s.dropped else 0}")
    w = max((len(t) for t in s.counts), default=5)
    for topic, n in sorted(s.counts.items()):
        rate = n / (s.end - s.start) if s.end > s.start else 0.0
        print(f"  {topic:<{w}}  {n:7d} msgs  {rate:8.1f} Hz  {s.schemas[topic]}")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    counts = export_bag(args.file, args.output, foxglove=not args.no_foxglove)
    print(f"wrote {args.output}: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    return 0

