"""``bag export``: a flexsheet bag transcoded to JSON-encoded MCAP that Foxglove and Lichtblick open.

Each lossless message becomes JSON on a channel of the same topic with the message's jsonschema; image fields
(uint8 arrays of 2 or 3 dimensions) become ``foxglove.CompressedImage`` (PNG) channels ``<topic>/<field>``.
The recorder's gap records are copied. With ``foxglove`` the scene channels of
:mod:`flexsheet.viz.foxglove_bag` are added (through the ``flexsheet.bag_channels`` entry point), built lazily
as while recording (only when an output is due). The source is read with every chunk's CRC checked
(:mod:`flexsheet.runtime.bag_read`).

Decoding and JSON encoding run in ``workers`` forked processes, batch by batch, in order, and the scene
channels in one more (its writer calls are recorded there and replayed here, :class:`_Recorder`); this
process reads and writes. ``progress`` is called about every 2 s with the share read.
Source: Foxglove schemas (foxglove.CompressedImage).
"""

from __future__ import annotations

import base64
import json
import os
import time
from collections import Counter, deque
from collections.abc import Callable, Iterator
from pathlib import Path

import msgpack
import numpy as np
from mcap.writer import CompressionType, Writer

from flexsheet.runtime.bag_json import PART_OF, ViewerDecoder
from flexsheet.runtime.bag_read import ENCODING, GAP_SCHEMA, GAP_TOPIC, BagSummary, McapScan
from flexsheet.runtime.codec import DecodeError, decode_any
from flexsheet.runtime.extensions import bag_channels
from messages import MESSAGE_TYPES

__all__ = ["export_bag"]

_IMAGE = "foxglove.CompressedImage"
_IMAGE_SCHEMA = {"title": _IMAGE, "type": "object", "properties": {
    "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
    "frame_id": {"type": "string"},
    "data": {"type": "string", "contentEncoding": "base64"},
    "format": {"type": "string"}}}
_BATCH_BYTES = 4 << 20
_BATCH_MESSAGES = 500


def _transcode(batch: list[tuple[str, int, bytes]]) -> list[tuple]:
    """JSON outputs ``(topic, schema name, log time ns, data)`` of a batch of lossless messages, in order;
    ``("<rejected>", "", t, b"")`` for one that does not decode."""
    import cv2

    out = []
    for topic, t, data in batch:
        try:
            msg = decode_any([topic.encode(), *msgpack.unpackb(data)])
        except (DecodeError, ValueError, TypeError):
            out.append(("<rejected>", "", t, b""))
            continue
        images = {k: v for k, v in msg.__dict__.items() if isinstance(v, np.ndarray) and v.dtype == np.uint8
                  and v.ndim in (2, 3) and v.shape[0] > 8}
        stamp = msg.header.stamp
        for fname, img in images.items():
            _ok, png = cv2.imencode(".png", img if img.ndim == 2 else img[:, :, ::-1])
            payload = {"timestamp": {"sec": int(stamp), "nsec": int((stamp % 1) * 1e9)},
                       "frame_id": msg.header.frame_id, "data": base64.b64encode(png.tobytes()).decode(),
                       "format": "png"}
            out.append((f"{topic}/{fname}", _IMAGE, t, json.dumps(payload).encode()))
        if not images:
            out.append((topic, msg.SCHEMA, t, msg.model_dump_json().encode()))
    return out


class _Recorder:
    """The calls a bag-channels object makes on its MCAP writer, recorded in the scene worker and replayed on
    the real writer by :func:`_replay` (ids are the worker's own, mapped there)."""

    def __init__(self) -> None:
        self.ops: list[tuple] = []
        self._n = 0

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        self._n += 1
        self.ops.append(("s", self._n, name, encoding, data))
        return self._n

    def register_channel(self, topic: str, message_encoding: str, schema_id: int, metadata=None) -> int:
        self._n += 1
        self.ops.append(("c", self._n, topic, message_encoding, schema_id))
        return self._n

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                    sequence: int = 0) -> None:
        self.ops.append(("m", channel_id, log_time, data, publish_time, sequence))

    def take(self) -> list[tuple]:
        ops, self.ops = self.ops, []
        return ops


_SCENE: tuple | None = None   # the scene worker's (bag-channels object, recorder)


def _scene_start() -> None:
    global _SCENE
    rec = _Recorder()
    _SCENE = (bag_channels("foxglove")(rec), rec)


def _scene_batch(batch: list[tuple[str, int, bytes]]) -> list[tuple]:
    fox, rec = _SCENE
    for topic, t, data in batch:
        fox.add_frames([topic.encode(), *msgpack.unpackb(data)], t)
    return rec.take()


def _scene_close() -> tuple[list[tuple], dict]:
    fox, rec = _SCENE
    fox.close()
    return rec.take(), dict(fox.counts)


def _replay(w: Writer, ops: list[tuple], ids: dict) -> None:
    """Apply recorded writer calls ``ops`` to ``w``; ``ids`` maps the worker's schema/channel ids to
    ``w``'s."""
    for op in ops:
        if op[0] == "m":
            _, ch, log_time, data, publish_time, seq = op
            w.add_message(ids[ch], log_time=log_time, data=data, publish_time=publish_time, sequence=seq)
        elif op[0] == "c":
            ids[op[1]] = w.register_channel(op[2], op[3], ids[op[4]])
        else:
            ids[op[1]] = w.register_schema(op[2], op[3], op[4])


def _schema(name: str) -> dict:
    if name == _IMAGE:
        return _IMAGE_SCHEMA
    if name == "flexsheet.RecorderGap":
        return GAP_SCHEMA
    cls = MESSAGE_TYPES.get(name)
    return cls.model_json_schema() if cls else {}


def _batches(scan: McapScan, progress: Callable[[float, int], None] | None, t_next: list[float],
             n_read: list[int],
             gap_records: list[tuple[int, bytes]]) -> Iterator[list[tuple[str, int, bytes]]]:
    """The lossless messages of ``scan`` as ``(topic, log time ns, data)`` in batches of about
    ``_BATCH_BYTES`` or ``_BATCH_MESSAGES``; the recorder's gap records go to ``gap_records``. ``n_read[0]``
    counts the messages read; ``progress`` is called when ``t_next[0]`` (monotonic s) has passed, then 2 s
    later."""
    batch, size = [], 0
    viewer = ViewerDecoder()
    for kind, rec in scan.records():
        if kind != "message":
            continue
        n_read[0] += 1
        if progress is not None and time.monotonic() >= t_next[0]:
            progress(scan.pos / max(scan.size, 1), n_read[0])
            t_next[0] = time.monotonic() + 2.0
        ch = scan.channels.get(rec[0])
        if ch is None:
            continue
        if ch.topic == GAP_TOPIC:
            gap_records.append((rec[2], rec[4]))
        else:
            data = rec[4] if ch.message_encoding == ENCODING else _assembled(viewer, scan, ch, rec[4], rec[2])
            if data is None:
                continue
            batch.append((ch.metadata.get(PART_OF, ch.topic), rec[2], data))
            size += len(data)
            if size > _BATCH_BYTES or len(batch) >= _BATCH_MESSAGES:
                yield batch
                batch, size = [], 0
    if batch:
        yield batch


def _assembled(viewer: ViewerDecoder, scan: McapScan, ch, data: bytes, log_time: int) -> bytes | None:
    """A recorder's ``json`` message (with its image parts) as the msgpack list of its wire frames after the
    topic, as older bags stored it; None for an image part (held until its message) and any other channel."""
    sch = scan.schemas.get(ch.schema_id)
    if sch is None or not viewer.wants(ch.message_encoding, sch.name, ch.metadata):
        return None
    try:
        frames = viewer.frames(ch.topic, sch.name, ch.metadata, data, sch.data, log_time)
    except (ValueError, TypeError):
        return None
    return None if frames is None else msgpack.packb([bytes(f) for f in frames[1:]])


class _JsonChannels:
    """The JSON channels of an export on MCAP writer ``w``: a schema per message type and a channel per topic,
    registered on first use; each message written is counted in ``counts``."""

    def __init__(self, w: Writer, counts: Counter) -> None:
        self.w, self.counts = w, counts
        self.sids: dict[str, int] = {}
        self.chans: dict[str, int] = {}

    def write(self, topic: str, schema_name: str, t: int, data: bytes) -> None:
        w, sids, chans = self.w, self.sids, self.chans
        ch = chans.get(topic)
        if ch is None:
            if schema_name not in sids:  # the schema is built once per type, not per message
                sids[schema_name] = w.register_schema(schema_name, "jsonschema",
                                                      json.dumps(_schema(schema_name)).encode())
            ch = chans[topic] = w.register_channel(topic, "json", sids[schema_name])
        w.add_message(ch, log_time=t, data=data, publish_time=t)
        self.counts[topic] += 1


def export_bag(src: str | Path, dst: str | Path, foxglove: bool = True, summary: BagSummary | None = None,
               progress: Callable[[float, int], None] | None = None, workers: int | None = None) -> Counter:
    """Transcode ``src`` to JSON-encoded MCAP ``dst`` (module docstring). Returns per-channel message counts;
    messages that fail to decode are skipped and counted under ``"<rejected>"``. Damage and truncation of
    ``src`` go to ``summary``. ``progress(share_read, messages)`` is called about every 2 s. ``workers``:
    processes that transcode (default: one per core, at most 4; 0: all in this process)."""
    counts: Counter = Counter()
    scan = McapScan(src, summary)
    workers = min(4, os.cpu_count() or 1) if workers is None else workers
    n_read = [0]
    t_next = [time.monotonic() + 2.0]
    gap_records: list[tuple[int, bytes]] = []

    with open(dst, "wb") as fh:
        w = Writer(fh, compression=CompressionType.LZ4)
        w.start(profile="", library="flexsheet")
        write = _JsonChannels(w, counts).write

        pool = _pool(workers)  # forked before the scene builder loads anything
        scene = _pool(1, _scene_start) if (foxglove and pool is not None) else None
        fox = bag_channels("foxglove")(w) if (foxglove and scene is None) else None
        ids: dict = {}
        try:
            pending: deque = deque()

            def drain(limit: int) -> None:
                while len(pending) > limit:
                    batch, result, scene_ops = pending.popleft()
                    for topic, schema_name, t, data in (result.result() if pool else result):
                        if topic == "<rejected>":
                            counts[topic] += 1
                        else:
                            write(topic, schema_name, t, data)
                    if scene_ops is not None:
                        _replay(w, scene_ops.result(), ids)
                    elif fox is not None:
                        for topic, t, data in batch:
                            fox.add_frames([topic.encode(), *msgpack.unpackb(data)], t)

            for batch in _batches(scan, progress, t_next, n_read, gap_records):
                pending.append((batch, pool.submit(_transcode, batch) if pool else _transcode(batch),
                                scene.submit(_scene_batch, batch) if scene else None))
                drain(2 * max(workers, 1))
            drain(0)
            if scene is not None:
                ops, scene_counts = scene.submit(_scene_close).result()
                _replay(w, ops, ids)
                counts.update(scene_counts)
        finally:
            for p in (pool, scene):
                if p is not None:
                    p.shutdown(cancel_futures=True)
        for t, data in gap_records:
            write(GAP_TOPIC, "flexsheet.RecorderGap", t, data)
        if fox is not None:
            fox.close()
            counts.update(fox.counts)
        w.finish()
    if progress is not None:
        progress(1.0, n_read[0])
    return counts


def _pool(workers: int, initializer=None):
    if workers < 1:
        return None
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    try:
        ctx = multiprocessing.get_context("fork")
    except ValueError:  # no fork on this platform: transcode here
        return None
    pool = ProcessPoolExecutor(workers, mp_context=ctx, initializer=initializer)
    for f in [pool.submit(os.getpid) for _ in range(workers)]:
        f.result()
    return pool
