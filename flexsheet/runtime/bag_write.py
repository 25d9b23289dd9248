"""The recorder's MCAP writer: stores whatever arrives, counts what it loses, never stops on bad input.

Like rosbag2 it does not need to validate a message to store it. Each message goes on a channel per topic:

* a flexsheet message envelope (a str schema name, an int version, a dict body) in the encodings every MCAP
  viewer decodes (:mod:`flexsheet.runtime.bag_json`): ``json`` with its pydantic model's ``jsonschema``, its
  images as ``foxglove.RawImage``; what the player replays and the tools decode;
* anything else (a 1-frame message, a meta frame that is not msgpack or not an envelope, arrays that do not
  match their descriptors): its raw wire frames (msgpack list of the frames after the topic frame) as
  ``flexsheet-raw``, kept byte for byte, counted as *malformed*, never replayed.

Publisher sequence gaps are counted as drops per topic (``header.seq``; a seq that is not an int is not
counted, a step back or a jump over :data:`MAX_SEQ_JUMP` is a publisher restart, counted under ``resets``).
What cannot be stored is counted too: a full queue (``<recorder queue full>``), a failed write (``<write
error>``). The counts are in the bag's ``recorder`` metadata at close and in the recorder's heartbeat.

A respawned recorder continues in ``<stem>.N.mcap``; it reads the previous part's last message per topic (in
the background) and writes a :data:`~flexsheet.runtime.bag_read.GAP_TOPIC` record per topic (JSON: ``topic``,
``previous``, ``last_before``, ``first_after``, ``lost_s``; topic ``""`` for the recorder as a whole, whose
``first_after`` is the new part's start), so the time the recorder was down is written in the bag.
"""

from __future__ import annotations

import json
import os
import queue
import threading
import time
from collections import Counter
from pathlib import Path

import msgpack
from mcap.writer import CompressionType, Writer

from flexsheet.runtime.bag_json import PART_OF, ViewerDecoder, ViewerEncoder
from flexsheet.runtime.bag_read import ENCODING, GAP_SCHEMA, GAP_TOPIC, RAW_ENCODING, McapScan
from flexsheet.runtime.codec import DecodeError
from flexsheet.runtime.extensions import bag_channels
from flexsheet.runtime.heap import Trimmer

__all__ = ["BagWriter", "MAX_SEQ_JUMP", "CHUNK_SIZE", "FLUSH_PERIOD"]

#: bytes, uncompressed; a chunk is cut at this size or at each flush. The writer keeps one index (about 1.3
#: KB) per chunk in memory until the bag closes. The lab's recorder takes about 4.3 MB/s uncompressed (the
#: images compress about 8-fold), so 1 MiB chunks were cut 4.5 times a second (16 000 an hour, 21 MB); at 8
#: MiB the once-a-second flush cuts them, 3 600 an hour (about 5 MB). The mcap CLI's default is 8 MiB too.
CHUNK_SIZE = 8 * 1024 * 1024
#: s; the chunk in progress is written at least this often (what a kill -9 can lose), even when it is not full
FLUSH_PERIOD = 1.0
#: a forward seq jump larger than this is a publisher restart (or garbage), not that many lost messages
MAX_SEQ_JUMP = 1_000_000



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


def _envelope(meta: bytes) -> tuple[str | None, object]:
    """(schema name, header.seq) of a meta frame; schema None if it is not a flexsheet envelope."""
    try:
        obj = msgpack.unpackb(meta, ext_hook=lambda c, d: None, raw=False)
    except Exception:  # noqa: BLE001 - msgpack raises many types on garbage
        return None, None
    if not isinstance(obj, dict) or type(obj.get("s")) is not str or type(obj.get("v")) is not int \
            or not isinstance(obj.get("d"), dict):
        return None, None
    header = obj["d"].get("header")
    return obj["s"], header.get("seq") if isinstance(header, dict) else None


class BagWriter:
    """Writes raw wire frames to an MCAP file from a background thread (the caller never blocks on disk).

    If ``path`` already holds data (a respawned recorder), the bag goes to ``<stem>.1.mcap``, ``.2``… instead,
    so nothing recorded before is lost, and the gap is recorded (module docstring).
    ``write(frames, log_time_ns)`` queues one message (``frames`` = ``[topic, meta, *buffers]``, any content);
    ``close()`` flushes and writes the summary and the ``recorder`` metadata. Counters: ``counts`` (stored,
    per topic), ``malformed`` (stored raw, per topic), ``dropped`` (lost: wire gaps per topic, queue full,
    write errors), ``resets`` (publisher restarts seen in the seq); ``error``: the last write error, if any.
    """

    def __init__(self, path: str | Path, chunk_size: int = CHUNK_SIZE, max_queue_bytes: int = 256 << 20,
                 foxglove: bool = False) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.previous: Path | None = None
        n = 1
        while path.exists() and path.stat().st_size > 0:  # a respawned recorder never overwrites its bag
            self.previous = path
            path = Path(path.parent, f"{Path(path).name.split('.')[0]}.{n}.mcap")
            n += 1
        self.path = path
        self.started = time.time()
        self.max_queue_bytes = max_queue_bytes
        self._queued = 0
        self._fh = _DirectFile(self.path)
        self._writer = Writer(self._fh, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        self._writer.start(profile="flexsheet", library="flexsheet")
        self._channels: dict[tuple[str, str, str], int] = {}
        self._schemas: dict[str, int] = {}
        self._seq: dict[str, int] = {}
        self.counts: Counter = Counter()
        self.malformed: Counter = Counter()
        self.dropped: Counter = Counter()
        self.resets: Counter = Counter()
        self.error = ""
        self._first: dict[str, int] = {}        # first log time per topic in this part (for the gap records)
        self._prev_last: dict[str, int] | None = None
        self._gaps_written: set[str] = set()
        self._encoder = ViewerEncoder()
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self.foxglove = None
        # Foxglove channels (/viz/*, images) beside the lossless ones: the bag opens with the scene
        if foxglove:
            self.foxglove = bag_channels("foxglove")(self._writer)
        self._thread = threading.Thread(target=self._run, name="bag-writer", daemon=True)
        self._thread.start()
        self._scanner = None
        if self.previous is not None:
            self._scanner = threading.Thread(target=self._scan_previous, name="bag-gap", daemon=True)
            self._scanner.start()

    # ---------------------------------------------------------------- input (any thread)
    def write(self, frames: list, log_time_ns: int) -> None:
        """Queue one message; if the disk falls behind by more than ``max_queue_bytes`` it is dropped and
        counted under ``"<recorder queue full>"`` (memory stays bounded). Never raises."""
        try:
            size = sum(memoryview(f).nbytes for f in frames)
        except TypeError:  # not buffers at all: nothing that could be stored
            self.dropped["<not bytes>"] += 1
            return
        if self._queued + size > self.max_queue_bytes:
            self.dropped["<recorder queue full>"] += 1
            return
        self._queued += size
        self._q.put((frames, log_time_ns, size))

    @property
    def lost(self) -> int:
        return sum(self.dropped.values())

    # ---------------------------------------------------------------- the writer thread
    def _run(self) -> None:
        flushed, trimmer = time.monotonic(), Trimmer()
        while True:
            try:
                item = self._q.get(timeout=FLUSH_PERIOD)
            except queue.Empty:
                item = "flush"
            if time.monotonic() - flushed >= FLUSH_PERIOD:  # a kill -9 loses at most this much
                try:
                    self._writer.flush()
                except Exception as exc:  # noqa: BLE001
                    self.error = f"{type(exc).__name__}: {exc}"[:300]
                trimmer.maybe()  # the freed chunk buffers back to the OS (flexsheet/runtime/heap.py)
                flushed = time.monotonic()
            if item is None:
                return
            if item == "flush":
                continue
            if item == "gaps":
                self._write_gaps(final=False)
                continue
            frames, t_ns, size = item
            self._queued -= size
            try:
                self._store(frames, t_ns)
            except Exception as exc:  # noqa: BLE001 - a disk error costs this message, not the recording
                self.dropped["<write error>"] += 1
                self.error = f"{type(exc).__name__}: {exc}"[:300]

    def _channel(self, topic: str, encoding: str, schema: str, schema_encoding: str = "jsonschema",
                 schema_data: bytes | None = None, metadata: dict | None = None) -> int:
        key = (topic, encoding, schema)
        ch = self._channels.get(key)
        if ch is None:
            sid = self._schemas.get(schema, 0)
            if schema and not sid:
                if schema_data is None:
                    schema_data = json.dumps(GAP_SCHEMA).encode() if schema == GAP_SCHEMA["title"] else b"{}"
                sid = self._schemas[schema] = self._writer.register_schema(schema, schema_encoding,
                                                                           schema_data)
            ch = self._channels[key] = self._writer.register_channel(topic, encoding, sid, metadata or {})
            # the channel again outside the chunks: a later chunk's messages keep their topic even if
            # the chunk holding the Channel record is damaged (bag_read.McapScan reads these back)
            self._writer.add_metadata("flexsheet.channel",
                                      {"id": str(ch), "topic": topic, "encoding": encoding,
                                       "schema": schema, "schema_id": str(sid),
                                       "metadata": json.dumps(metadata or {})})
        return ch

    def _store(self, frames: list, t_ns: int) -> None:
        topic = bytes(frames[0]).decode(errors="replace") if frames else ""
        schema, seq = _envelope(bytes(frames[1])) if len(frames) > 1 else (None, None)
        records = None
        if schema is not None:
            try:
                records = self._encoder.records(frames)
            except (DecodeError, TypeError, ValueError):
                records = None
        if records is None:
            data = msgpack.packb([bytes(f) for f in frames[1:]])
            self._writer.add_message(self._channel(topic, RAW_ENCODING, ""), log_time=t_ns, data=data,
                                     publish_time=t_ns)
            self.malformed[topic] += 1
            return
        if type(seq) is int:
            self._count_gap(topic, seq)
        for r in records:
            ch = self._channel(r.topic, r.encoding, r.schema, r.schema_encoding, r.schema_data, r.metadata)
            self._writer.add_message(ch, log_time=t_ns, data=r.data, publish_time=t_ns,
                                     sequence=seq & 0xFFFFFFFF if type(seq) is int else 0)
        self.counts[topic] += 1
        if topic not in self._first:
            self._first[topic] = t_ns
            if self._prev_last is not None:
                self._write_gaps(final=False)
        if self.foxglove is not None:
            self.foxglove.add_frames(frames, t_ns)

    def _count_gap(self, topic: str, seq: int) -> None:
        if topic == "/diagnostics":  # one publisher per node: its seqs interleave
            return
        last = self._seq.get(topic)
        if last is not None:
            jump = seq - last - 1
            if 0 < jump <= MAX_SEQ_JUMP:
                self.dropped[topic] += jump
            elif jump < -1 or jump > MAX_SEQ_JUMP:
                self.resets[topic] += 1
        self._seq[topic] = seq

    # ---------------------------------------------------------------- down time after a respawn
    def _scan_previous(self) -> None:
        last: dict[str, int] = {}
        try:
            scan = McapScan(self.previous)
            for kind, rec in scan.records():
                if kind == "message":
                    ch = scan.channels.get(rec[0])
                    sch = scan.schemas.get(ch.schema_id) if ch is not None else None
                    if ch is not None and (ch.message_encoding == ENCODING or ViewerDecoder.wants(
                            ch.message_encoding, sch.name if sch else "", ch.metadata)) \
                            and PART_OF not in ch.metadata and rec[2] > last.get(ch.topic, 0):
                        last[ch.topic] = rec[2]
        except Exception:  # noqa: BLE001 - an unreadable previous part: the gap starts where we know nothing
            pass
        self._prev_last = last
        self._q.put("gaps")

    def _write_gaps(self, final: bool) -> None:
        prev = self._prev_last or {}
        todo = ([("", max(prev.values(), default=0), int(self.started * 1e9))] if "" not in self._gaps_written
                else [])
        todo += [(t, prev[t], self._first.get(t)) for t in prev
                 if t not in self._gaps_written and (final or t in self._first)]
        for topic, before, after in todo:
            rec = {"topic": topic, "previous": self.previous.name,
                   "last_before": before / 1e9 if before else None,
                   "first_after": after / 1e9 if after else None,
                   "lost_s": (after - before) / 1e9 if before and after else None}
            t = after or int(time.time() * 1e9)
            try:
                self._writer.add_message(self._channel(GAP_TOPIC, "json", "flexsheet.RecorderGap"),
                                         log_time=t,
                                         data=json.dumps(rec).encode(), publish_time=t)
            except Exception as exc:  # noqa: BLE001
                self.error = f"{type(exc).__name__}: {exc}"[:300]
            self._gaps_written.add(topic)

    # ---------------------------------------------------------------- close
    def close(self) -> None:
        if self._scanner is not None:
            self._scanner.join(timeout=10.0)
        self._q.put(None)
        self._thread.join()
        try:
            if self._prev_last is not None:
                self._write_gaps(final=True)
            if self.foxglove is not None:
                self.foxglove.close()
            self._writer.add_metadata("recorder", {"counts": json.dumps(dict(self.counts)),
                                                   "dropped": json.dumps(dict(self.dropped)),
                                                   "malformed": json.dumps(dict(self.malformed)),
                                                   "resets": json.dumps(dict(self.resets))})
            self._writer.finish()
        except Exception as exc:  # noqa: BLE001 - the chunks written so far stay readable (bag recover)
            self.error = f"{type(exc).__name__}: {exc}"[:300]
        finally:
            self._fh.close()
