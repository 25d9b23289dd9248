"""Reading MCAP bags that may be cut or damaged: every chunk's CRC checked, a bad chunk skipped and reported.

:class:`McapScan` walks an MCAP file record by record (``mmap``; the record classes of the ``mcap`` package
parse everything but messages, which are unpacked here for speed). Each chunk is decompressed and its
``uncompressed_crc`` checked before any of its messages is used; a chunk that fails is skipped whole and
reported as a :class:`Damage` (byte range, time range, messages per topic from the message indexes that follow
it). A record whose length or opcode makes no sense breaks the framing: the scan goes on at the next chunk (by
the summary's chunk index when the footer is intact, else by searching for the next well-formed chunk header).
A file that ends before its footer is *truncated*: what was complete is read, the cut tail reported.

:func:`read_bag` yields the lossless ``flexsheet-msgpack`` messages (what the player and the report use);
:func:`bag_info` counts every channel of any MCAP (other tools' bags, ``bag export``'s JSON).
Source: MCAP specification (mcap.dev/spec): record framing, Chunk, Message Index, Footer and summary CRC.
"""

from __future__ import annotations

import io
import json
import mmap
import struct
import time
import zlib
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import msgpack
from mcap.data_stream import ReadDataStream
from mcap.records import Attachment, Channel, ChunkIndex, Header, MessageIndex, Metadata, Schema

from flexsheet.runtime.bag_json import FIELD, JSON_ENCODING, PART_OF, Parts, ViewerDecoder

__all__ = ["ENCODING", "RAW_ENCODING", "GAP_TOPIC", "GAP_SCHEMA", "Damage", "BagSummary", "BagMessage",
           "McapScan", "read_bag", "bag_info", "clock_text"]

#: message encoding of the recorder's lossless channels: msgpack list of the wire frames after the topic
ENCODING = "flexsheet-msgpack"
#: same layout, for messages whose meta frame is not a flexsheet envelope (stored as they came, never played)
RAW_ENCODING = "flexsheet-raw"
#: JSON records of the time the recorder was down (a respawn): one per topic, see :class:`BagSummary.gaps`
GAP_TOPIC = "/recorder/gap"
#: the jsonschema of a gap record
GAP_SCHEMA = {"title": "flexsheet.RecorderGap", "type": "object", "properties": {
    "topic": {"type": "string", "description": "the topic; empty: the recorder as a whole"},
    "previous": {"type": "string", "description": "the bag part written before the restart"},
    "last_before": {"type": ["number", "null"], "description": "s, last message in the previous part"},
    "first_after": {"type": ["number", "null"], "description": "s, first message in this part (null: none)"},
    "lost_s": {"type": ["number", "null"], "description": "s between the two"}}}
MAGIC = b"\x89MCAP0\r\n"
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_MSG_INDEX = 1, 2, 3, 4, 5, 6, 7
_OP_CHUNK_INDEX, _OP_ATTACHMENT, _OP_METADATA, _OP_DATA_END = 8, 9, 0x0C, 0x0F
_MAX_OP = 0x0F
_FOOTER_LEN = 1 + 8 + 20


def clock_text(t: float) -> str:
    """``HH:MM:SS.mmm`` local time of a log time (s)."""
    return time.strftime("%H:%M:%S", time.localtime(t)) + f".{int(t * 1000) % 1000:03d}"


@dataclass
class Damage:
    """A part of a bag that could not be read: ``offset``/``length`` bytes, ``reason``, the time range of its
    messages (s, 0 if unknown) and ``counts``: messages lost per topic, when a message index says."""

    offset: int
    length: int
    reason: str
    start: float = 0.0
    end: float = 0.0
    counts: Counter = field(default_factory=Counter)

    def describe(self) -> str:
        what = (", ".join(f"{t} {n}" for t, n in sorted(self.counts.items())) if self.counts
                else "messages unknown")
        when = f", {clock_text(self.start)}–{clock_text(self.end)}" if self.end else ""
        return f"bytes {self.offset}–{self.offset + self.length} ({self.reason}{when}): {what}"


@dataclass
class BagSummary:
    """What a read found. ``counts``/``schemas``/``encodings`` per topic (every channel but the recorder's
    bookkeeping), ``start``/``end`` s (log time), ``dropped``: the recorder's counts of what it lost (wire
    sequence gaps, queue full, write errors), ``malformed``: messages stored as they came (not a flexsheet
    envelope), ``gaps``: the recorder's down times, ``damaged``: unreadable parts, ``truncated``: no footer
    (a crash, a cut copy), ``cut_bytes``: the unreadable tail, ``cut_span``: the partial chunk's span (s)
    if its header survived; ``incomplete``: messages per topic that lost an image part (not in ``counts``)."""

    counts: Counter = field(default_factory=Counter)
    schemas: dict[str, str] = field(default_factory=dict)
    encodings: dict[str, str] = field(default_factory=dict)
    start: float = 0.0
    end: float = 0.0
    dropped: dict[str, int] = field(default_factory=dict)
    malformed: Counter = field(default_factory=Counter)
    gaps: list[dict] = field(default_factory=list)
    damaged: list[Damage] = field(default_factory=list)
    truncated: bool = False
    cut_bytes: int = 0
    cut_span: tuple[float, float] | None = None
    incomplete: Counter = field(default_factory=Counter)

    @property
    def lost(self) -> int:
        """Messages known to be lost to damage (a damaged part whose index is lost too adds nothing here)."""
        return sum(sum(d.counts.values()) for d in self.damaged)


@dataclass
class BagMessage:
    """One recorded message: ``topic``, ``schema`` name, ``log_time`` s, raw ``frames`` [topic, meta, ...]."""

    topic: str
    schema: str
    log_time: float
    frames: list[bytes]


def _decompress(compression: str, data, size: int) -> bytes:
    if compression == "lz4":
        import lz4.frame
        return lz4.frame.decompress(data)
    if compression == "zstd":
        import zstandard
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if compression == "":
        return bytes(data)
    raise ValueError(f"unknown compression {compression!r}")


class McapScan:
    """One pass over an MCAP file (see the module docstring). Iterate :meth:`records` for
    ``("schema", Schema)``, ``("channel", Channel)``, ``("metadata", Metadata)``,
    ``("attachment", Attachment)`` and ``("message", (channel_id, sequence, log_time_ns, publish_time_ns,
    data))`` in file order; damage and truncation go to ``summary``. ``channels``/``schemas``: known so far
    (seeded from an intact summary section). Raises ``ValueError`` (not MCAP) or ``FileNotFoundError``."""

    def __init__(self, path: str | Path, summary: BagSummary | None = None) -> None:
        self.path = str(path)
        self.summary = summary if summary is not None else BagSummary()
        self.channels: dict[int, Channel] = {}
        self.schemas: dict[int, Schema] = {}
        self.complete = False           # the footer and its summary CRC are intact
        self._chunk_index: list[ChunkIndex] = []
        self._pending: dict | None = None  # the damaged chunk's log times, for the next message indexes
        self._data_end = 0
        self.pos = 0                    # byte offset reached (progress)
        self.size = 0
        self.header = None              # the file's Header record (profile, library)
        self._lost_by_channel: list[tuple[Damage, dict]] = []

    # ---------------------------------------------------------------- footer and summary
    def _read_summary(self, mm) -> None:
        size = len(mm)
        foot = size - len(MAGIC) - _FOOTER_LEN
        if foot < len(MAGIC) or mm[size - len(MAGIC):] != MAGIC or mm[foot] != _OP_FOOTER:
            return
        length, start, _offsets, crc = struct.unpack_from("<QQQI", mm, foot + 1)
        if length != 20 or start > foot:
            return
        if crc and zlib.crc32(mm[foot:foot + 1 + 8 + 16], zlib.crc32(mm[start or foot:foot])) != crc:
            self.summary.damaged.append(Damage(start, foot - start, "summary CRC mismatch"))
            return
        try:
            pos = start or foot
            while pos + 9 <= foot:
                op, n = struct.unpack_from("<BQ", mm, pos)
                body = ReadDataStream(io.BytesIO(mm[pos + 9:pos + 9 + n]))
                if op == _OP_SCHEMA:
                    sc = Schema.read(body)
                    self.schemas[sc.id] = sc
                elif op == _OP_CHANNEL:
                    c = Channel.read(body)
                    self.channels[c.id] = c
                elif op == _OP_CHUNK_INDEX:
                    self._chunk_index.append(ChunkIndex.read(body))
                pos += 9 + n
        except Exception:  # noqa: BLE001 - a summary without a CRC that does not parse: read without it
            self.schemas.clear()
            self.channels.clear()
            self._chunk_index.clear()
            self.summary.damaged.append(Damage(start, foot - start, "summary unreadable"))
            return
        self.complete = True
        self._data_end = start or foot
        self._chunk_index.sort(key=lambda c: c.chunk_start_offset)

    # ---------------------------------------------------------------- chunks
    @staticmethod
    def _chunk_header(mm, pos: int, end: int):
        """(start_ns, end_ns, size, crc, compression, records_offset, records_len) of a plausible chunk record
        at ``pos`` whose record ends at or before ``end``, else None."""
        if pos + 9 + 32 > end or mm[pos] != _OP_CHUNK:
            return None
        n, t0, t1, size, crc, clen = struct.unpack_from("<QQQQII", mm, pos + 1)
        if clen > 16 or pos + 9 + n > end or t1 < t0:
            return None
        p = pos + 9 + 32
        comp = bytes(mm[p:p + clen])
        if comp not in (b"", b"lz4", b"zstd") or p + clen + 8 > end:
            return None
        (rlen,) = struct.unpack_from("<Q", mm, p + clen)
        if 32 + clen + 8 + rlen != n:
            return None
        return t0, t1, size, crc, comp.decode(), p + clen + 8, rlen

    def _chunk(self, mm, pos: int, n: int) -> Iterator[tuple]:
        head = self._chunk_header(mm, pos, pos + 9 + n)
        if head is None:
            self._damage(pos, 9 + n, "malformed chunk header")
            return
        t0, t1, size, crc, comp, rp, rlen = head
        try:
            data = _decompress(comp, mm[rp:rp + rlen], size)
        except Exception as exc:  # noqa: BLE001 - lz4/zstd raise their own types on garbage
            self._damage(pos, 9 + n, f"chunk does not decompress ({type(exc).__name__})", t0, t1)
            return
        if len(data) != size or (crc and zlib.crc32(data) != crc):
            self._damage(pos, 9 + n, "chunk CRC mismatch", t0, t1)
            return
        out, p, total = [], 0, len(data)
        unpack_from = struct.unpack_from
        try:
            while p < total:
                op, m = unpack_from("<BQ", data, p)
                q = p + 9 + m
                if q > total:
                    raise ValueError("record overruns the chunk")
                if op == _OP_MESSAGE:
                    cid, seq, lt, pt = unpack_from("<HIQQ", data, p + 9)
                    out.append(("message", (cid, seq, lt, pt, data[p + 31:q])))
                elif op in (_OP_SCHEMA, _OP_CHANNEL):
                    out.append(self._record(op, data[p + 9:q]))
                p = q
        except Exception:  # noqa: BLE001 - only a chunk written without a CRC can get here
            self._damage(pos, 9 + n, "chunk records do not parse", t0, t1)
            return
        yield from out   # the whole chunk checked first: a bad one yields nothing

    def _damage(self, offset: int, length: int, reason: str, t0: int = 0, t1: int = 0) -> None:
        d = Damage(offset, length, reason, t0 / 1e9, t1 / 1e9)
        self.summary.damaged.append(d)
        by_channel: dict[int, list[int]] = {}      # channel -> log times (ns) of its records in the damage
        self._lost_by_channel.append((d, by_channel))
        for ci in self._chunk_index:  # the summary's index says what the chunks in this range held
            if offset <= ci.chunk_start_offset < offset + length:
                d.start = d.start or ci.message_start_time / 1e9
                d.end = max(d.end, ci.message_end_time / 1e9)
                self._index_counts(ci, by_channel)
        self._pending = None if by_channel else by_channel  # else: the message indexes that follow will say

    def _index_counts(self, ci: ChunkIndex, by_channel: dict) -> None:
        for cid, off in ci.message_index_offsets.items():
            try:
                op, n = struct.unpack_from("<BQ", self._mm, off)
                if op == _OP_MSG_INDEX:
                    mi = MessageIndex.read(ReadDataStream(io.BytesIO(self._mm[off + 9:off + 9 + n])))
                    by_channel.setdefault(cid, []).extend(t for t, _ in mi.records)
            except Exception:  # noqa: BLE001 - an index in a damaged area says nothing
                continue

    def _record(self, op: int, body) -> tuple:
        stream = ReadDataStream(io.BytesIO(body))
        if op == _OP_SCHEMA:
            s = Schema.read(stream)
            self.schemas[s.id] = s
            return ("schema", s)
        c = Channel.read(stream)
        self.channels[c.id] = c
        return ("channel", c)

    def _resync(self, mm, pos: int, end: int) -> int:
        """The offset of the next chunk after the broken framing at ``pos`` (``end`` if none)."""
        for ci in self._chunk_index:
            if ci.chunk_start_offset > pos:
                return ci.chunk_start_offset
        p = pos + 1
        while True:
            p = mm.find(bytes([_OP_CHUNK]), p, end)
            if p < 0:
                return end
            if self._chunk_header(mm, p, end) is not None:
                return p
            p += 1

    # ---------------------------------------------------------------- the pass
    def records(self) -> Iterator[tuple]:
        with open(self.path, "rb") as fh:
            size = fh.seek(0, 2)
            if size < len(MAGIC) or fh.seek(0) != 0 or fh.read(len(MAGIC)) != MAGIC:
                raise ValueError(f"{self.path}: not an MCAP file (no MCAP magic at its start)")
            self.size = size
            with mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
                self._mm = mm
                try:
                    yield from self._records(mm, size)
                finally:
                    self._finish()
                    self._mm = None

    def _records(self, mm, size: int) -> Iterator[tuple]:
        self._read_summary(mm)
        s = self.summary
        end = self._data_end if self.complete else size
        pos = len(MAGIC)
        while pos < end:
            self.pos = pos
            op, n = struct.unpack_from("<BQ", mm, pos) if pos + 9 <= end else (0, 0)
            if op != _OP_MSG_INDEX:
                self._pending = None
            fits = pos + 9 <= end and 0 < op <= _MAX_OP and pos + 9 + n <= end
            if fits and op == _OP_CHUNK and self._chunk_header(mm, pos, end) is None:
                fits = False
            if not fits:
                nxt = self._resync(mm, pos, end)
                if nxt >= end and not self.complete:
                    break                                    # no chunk after it in a cut file: the cut tail
                self._damage(pos, nxt - pos, f"unreadable record (opcode {op}, length {n})")
                pos = nxt
                continue
            if op == _OP_CHUNK:
                yield from self._chunk(mm, pos, n)
                nxt = pos + 9 + n
                if nxt < end and not self._plausible(mm, nxt, end):
                    nxt = self._resync(mm, pos, end)         # the chunk's length itself was damaged
                pos = nxt
                continue
            if op == _OP_MSG_INDEX:
                if self._pending is not None:
                    try:
                        mi = MessageIndex.read(ReadDataStream(io.BytesIO(mm[pos + 9:pos + 9 + n])))
                        self._pending.setdefault(mi.channel_id, []).extend(t for t, _ in mi.records)
                    except Exception:  # noqa: BLE001 - a damaged index only costs the count
                        pass
            elif op in (_OP_SCHEMA, _OP_CHANNEL, _OP_METADATA, _OP_ATTACHMENT, _OP_MESSAGE):
                try:
                    rec = self._plain(op, mm[pos + 9:pos + 9 + n])
                except Exception:  # noqa: BLE001 - a record that does not parse is damage, not the end
                    self._damage(pos, 9 + n, f"record (opcode {op}) does not parse")
                    rec = None
                if rec is not None:
                    yield rec
            elif op == _OP_HEADER:
                try:
                    self.header = Header.read(ReadDataStream(io.BytesIO(mm[pos + 9:pos + 9 + n])))
                except Exception:  # noqa: BLE001 - the profile is only informative
                    self.header = None
            elif op == _OP_DATA_END:
                return
            pos += 9 + n
        self.pos = pos
        if not self.complete:
            s.truncated = True
            s.cut_bytes = size - pos
            if pos + 9 + 16 <= size and mm[pos] == _OP_CHUNK:   # the partial chunk still says its time range
                t0, t1 = struct.unpack_from("<QQ", mm, pos + 9)
                s.cut_span = (t0 / 1e9, t1 / 1e9)

    @staticmethod
    def _plausible(mm, pos: int, end: int) -> bool:
        if pos + 9 > end:
            return False
        op, n = struct.unpack_from("<BQ", mm, pos)
        return 0 < op <= _MAX_OP and pos + 9 + n <= end

    def _plain(self, op: int, body) -> tuple:
        if op == _OP_MESSAGE:
            cid, seq, lt, pt = struct.unpack_from("<HIQQ", body, 0)
            return ("message", (cid, seq, lt, pt, bytes(body[22:])))
        if op in (_OP_SCHEMA, _OP_CHANNEL):
            return self._record(op, body)
        stream = ReadDataStream(io.BytesIO(body))
        if op == _OP_METADATA:
            md = Metadata.read(stream)
            if md.name == "flexsheet.channel":  # the recorder's copy of a channel, outside the chunks
                self._fallback_channel(md.metadata)
            return ("metadata", md)
        return ("attachment", Attachment.read(stream))

    def _fallback_channel(self, m: dict) -> None:
        try:
            cid, sid = int(m["id"]), int(m["schema_id"])
        except (KeyError, ValueError):
            return
        if cid not in self.channels:
            try:
                meta = json.loads(m.get("metadata", "{}"))
            except ValueError:
                meta = {}
            self.channels[cid] = Channel(id=cid, topic=m.get("topic", ""),
                                         message_encoding=m.get("encoding", ""),
                                         metadata=meta if isinstance(meta, dict) else {}, schema_id=sid)
        if sid and sid not in self.schemas:
            self.schemas[sid] = Schema(id=sid, data=b"", encoding="", name=m.get("schema", ""))

    def _finish(self) -> None:
        """Each damage's lost messages per topic: the distinct log times of its records per message topic (a
        message's image parts count with it, :mod:`flexsheet.runtime.bag_json`)."""
        for d, by_channel in self._lost_by_channel:
            times: dict[str, set] = {}
            for cid, ts in by_channel.items():
                ch = self.channels.get(cid)
                topic = (ch.metadata.get(PART_OF, ch.topic)) if ch else f"<channel {cid}>"
                times.setdefault(topic, set()).update(ts if ch else range(len(ts)))
            for topic, ts in times.items():
                d.counts[topic] += len(ts)


def _note_metadata(summary: BagSummary, md: Metadata) -> None:
    if md.name == "recorder":
        try:
            summary.dropped = json.loads(md.metadata.get("dropped", "{}"))
        except ValueError:
            pass


def read_bag(path: str | Path, topics: list[str] | None = None,
             summary: BagSummary | None = None) -> Iterator[BagMessage]:
    """Iterate the flexsheet messages of a bag in file order, as wire frames, every chunk's CRC checked: the
    recorder's ``json`` messages with their image parts (:mod:`flexsheet.runtime.bag_json`), and the
    ``flexsheet-msgpack`` ones of older bags.

    ``topics``: only these (all if empty). A damaged chunk is skipped (``summary.damaged``); a truncated file
    yields every message up to its last complete chunk and sets ``summary.truncated``; the recorder's drop
    counts go to ``summary.dropped``. Other channels (Foxglove, malformed input, gap records) are not yielded;
    a record that does not parse is skipped. Raises ``ValueError`` naming the file if it is not an MCAP file.
    """
    scan = McapScan(path, summary)
    want = set(topics or ())
    viewer = ViewerDecoder()
    for kind, rec in scan.records():
        if kind == "message":
            ch = scan.channels.get(rec[0])
            if ch is None:
                continue
            sch = scan.schemas.get(ch.schema_id)
            schema = sch.name if sch is not None else ""
            if ch.message_encoding == ENCODING:
                if want and ch.topic not in want:
                    continue
                try:
                    frames = msgpack.unpackb(rec[4])
                except Exception:  # noqa: BLE001 - CRC-checked, so only a writer's bug gets here: skip
                    continue
                yield BagMessage(ch.topic, schema, rec[2] / 1e9, [ch.topic.encode(), *frames])
            elif viewer.wants(ch.message_encoding, schema, ch.metadata):
                owner = ch.metadata.get(PART_OF, ch.topic)
                if want and owner not in want:
                    continue
                try:
                    sdata = sch.data if sch else b""
                    frames = viewer.frames(ch.topic, schema, ch.metadata, rec[4], sdata, rec[2])
                except (ValueError, TypeError):
                    continue
                if frames is not None:
                    yield BagMessage(ch.topic, schema, rec[2] / 1e9, frames)
        elif kind == "metadata":
            _note_metadata(scan.summary, rec)


def bag_info(path: str | Path) -> BagSummary:
    """Counts, schemas, encodings and time span (log time) of every channel of any MCAP file, and what the
    recorder and the read found lost (drops, malformed input, gaps, damage, truncation). Reads it all."""
    s = BagSummary()
    scan = McapScan(path, s)
    parts = Parts()
    t0, t1 = None, 0
    for kind, rec in scan.records():
        if kind == "message":
            ch = scan.channels.get(rec[0])
            topic = ch.topic if ch else f"<channel {rec[0]}>"
            if ch is not None and ch.topic == GAP_TOPIC:
                try:
                    s.gaps.append(json.loads(rec[4]))
                except ValueError:
                    pass
                continue
            if ch is not None and ch.message_encoding == RAW_ENCODING:
                s.malformed[topic] += 1
                continue
            if ch is not None and PART_OF in ch.metadata:      # an image of a message: counted with it
                parts.add(ch.metadata[PART_OF], ch.metadata.get(FIELD, ""), rec[2])
                continue
            if ch is not None and ch.message_encoding == JSON_ENCODING and ch.schema_id in scan.schemas \
                    and parts.whole(topic, scan.schemas[ch.schema_id].name, rec[2]) is None:
                s.incomplete[topic] += 1                       # its image went with a damaged or cut chunk
                continue
            s.counts[topic] += 1
            if topic not in s.encodings:
                s.encodings[topic] = ch.message_encoding if ch else "?"
                s.schemas[topic] = (scan.schemas[ch.schema_id].name if ch and ch.schema_id in scan.schemas
                                    else "")
            t0 = rec[2] if t0 is None or rec[2] < t0 else t0
            t1 = max(t1, rec[2])
        elif kind == "metadata":
            _note_metadata(s, rec)
    s.start, s.end = (t0 or 0) / 1e9, t1 / 1e9
    return s
