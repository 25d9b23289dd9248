"""The bag's message encoding: what the recorder writes so that Foxglove, Lichtblick and any MCAP reader
decode every message, and how a recorded message becomes wire frames again for ``bag play`` and the report.

A flexsheet message on topic ``T`` is stored as

* one ``foxglove.RawImage`` (``protobuf``, the schema from ``foxglove-sdk``) on channel ``T/<field>`` for each
  of its image fields (``uint8`` arrays of 2 or 3 dimensions: ``mono8`` or ``rgb8``), written first; the
  channel's metadata names the message's topic and field (``flexsheet.part_of``, ``flexsheet.field``);
* then the rest of it as ``json`` on channel ``T``, with the ``jsonschema`` of its pydantic model (the image
  fields left out); numpy arrays are nested lists of numbers; the channel's metadata carries the message's
  version (``flexsheet.version``).

:class:`ViewerEncoder` makes these records from a message's wire frames (no validation: the recorder stores
what came); :class:`ViewerDecoder` makes the wire frames again from them (arrays back to their declared dtype
and shape, the images joined in), to be validated by whoever receives them, as any message from the wire.
Source: MCAP well-known encodings (mcap.dev/spec/registry: json + jsonschema, protobuf); foxglove.RawImage.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import orjson
from foxglove.messages import RawImage, Timestamp
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from flexsheet.runtime.codec import DecodeError, pack, unpack
from messages import MESSAGE_TYPES
from messages.common import array_spec

__all__ = ["JSON_ENCODING", "IMAGE_SCHEMA", "PART_OF", "FIELD", "VERSION", "Record", "Parts",
           "ViewerEncoder", "ViewerDecoder", "image_fields", "json_schema"]

JSON_ENCODING = "json"
IMAGE_SCHEMA = "foxglove.RawImage"
#: channel metadata keys
PART_OF, FIELD, VERSION = "flexsheet.part_of", "flexsheet.field", "flexsheet.version"
_IMAGE_ENCODINGS = {2: "mono8", 3: "rgb8"}
_OPTS = orjson.OPT_SERIALIZE_NUMPY


@dataclass
class Record:
    """One MCAP message to write: its channel (``topic``, ``encoding``, ``schema`` name, ``schema_encoding``,
    ``schema_data``, channel ``metadata``) and ``data``."""

    topic: str
    encoding: str
    schema: str
    schema_encoding: str
    schema_data: bytes
    metadata: dict
    data: bytes


def image_fields(schema: str) -> tuple[str, ...]:
    """The image fields of message type ``schema``: ``uint8`` arrays declared with 2 or 3 dimensions."""
    cls = MESSAGE_TYPES.get(schema)
    if cls is None:
        return ()
    out = []
    for name, f in cls.model_fields.items():
        spec = array_spec(f)
        if (spec is not None and spec.dtype == "uint8" and spec.shape is not None
            and len(spec.shape) in (2, 3)):
            out.append(name)
    return tuple(out)


def json_schema(schema: str) -> bytes:
    """The jsonschema (bytes) of message type ``schema`` as the bag stores it: its image fields left out."""
    cls = MESSAGE_TYPES.get(schema)
    if cls is None:
        return b"{}"
    js = cls.model_json_schema()
    drop = set(image_fields(schema))
    js["properties"] = {k: v for k, v in js.get("properties", {}).items() if k not in drop}
    if "required" in js:
        js["required"] = [k for k in js["required"] if k not in drop]
    return json.dumps(js).encode()


class ViewerEncoder:
    """Wire frames → the :class:`Record` list of one message (module doc). Raises
    :class:`~flexsheet.runtime.codec.DecodeError` for frames that are not a flexsheet message envelope."""

    def __init__(self) -> None:
        self._schemas: dict[str, bytes] = {}
        self._images: dict[str, tuple[str, ...]] = {}
        self._image_schema = RawImage.get_schema().data

    def records(self, frames: list) -> list[Record]:
        topic = bytes(frames[0]).decode(errors="replace")
        env = unpack(frames, topic)
        schema, version, fields = env["s"], env["v"], env["d"]
        if schema not in self._schemas:
            self._schemas[schema] = json_schema(schema)
            self._images[schema] = image_fields(schema)
        out = []
        images = self._images[schema]
        if images:
            header = fields.get("header") if isinstance(fields.get("header"), dict) else {}
            stamp = float(header.get("stamp", 0.0))
            fields = dict(fields)
            for name in images:
                img = fields.pop(name, None)
                if isinstance(img, np.ndarray) and img.ndim in _IMAGE_ENCODINGS and img.dtype == np.uint8:
                    out.append(self._image(topic, name, img, stamp, str(header.get("frame_id", ""))))
        out.append(Record(topic, JSON_ENCODING, schema, "jsonschema", self._schemas[schema],
                          {VERSION: str(version)}, orjson.dumps(fields, option=_OPTS)))
        return out

    def _image(self, topic: str, name: str, img: np.ndarray, stamp: float, frame_id: str) -> Record:
        h, w = img.shape[:2]
        sec = int(stamp)
        msg = RawImage(timestamp=Timestamp(sec, int(round((stamp - sec) * 1e9)) % 1_000_000_000),
                       frame_id=frame_id, width=w, height=h, encoding=_IMAGE_ENCODINGS[img.ndim],
                       step=w * (3 if img.ndim == 3 else 1), data=np.ascontiguousarray(img).tobytes())
        return Record(f"{topic}/{name}", "protobuf", IMAGE_SCHEMA, "protobuf", self._image_schema,
                      {PART_OF: topic, FIELD: name}, msg.encode())


class Parts:
    """Which messages of a bag are whole: the recorder writes a message's image parts before its JSON record,
    all at the message's log time, so a JSON record read in file order is whole when every image field of its
    type came as a part with the same topic and log time (a damaged or cut chunk can take some of them). Feed
    each part to :meth:`add` and ask :meth:`whole` at each JSON record."""

    def __init__(self) -> None:
        self.got: dict[str, tuple[int, dict]] = {}     # owner topic -> (log time ns, {field: value})
        self._fields: dict[str, tuple[str, ...]] = {}

    def add(self, owner: str, field: str, log_time: int, value=None) -> None:
        t, parts = self.got.get(owner, (None, None))
        if t != log_time:
            parts = {}
            self.got[owner] = (log_time, parts)
        parts[field] = value

    def whole(self, topic: str, schema: str, log_time: int) -> dict | None:
        """The parts ``{field: value}`` of the message at ``log_time`` if it is whole (``{}`` for a type
        without images), else None. The parts are handed over once."""
        if schema not in self._fields:
            self._fields[schema] = image_fields(schema)
        need = self._fields[schema]
        if not need:
            return {}
        t, parts = self.got.pop(topic, (None, None))
        if t != log_time or not set(need) <= set(parts):
            return None
        return parts


class ViewerDecoder:
    """The bag's records → wire frames. Feed every record of a channel that :meth:`wants` in file order to
    :meth:`frames`: an image part is held until its message's JSON record arrives, which returns the message's
    frames ``[topic, meta, *buffers]``; a part returns None, and so does a message whose parts were lost
    (:class:`Parts`). Raises ``ValueError`` naming the topic for a record that does not parse."""

    def __init__(self) -> None:
        self.parts = Parts()
        self._image_cls = None

    @staticmethod
    def wants(encoding: str, schema: str, metadata: dict) -> bool:
        """True for a channel of this encoding: a flexsheet message's JSON or one of its image parts."""
        return (encoding == JSON_ENCODING and schema in MESSAGE_TYPES) or (
            encoding == "protobuf" and schema == IMAGE_SCHEMA and PART_OF in (metadata or {}))

    def frames(self, topic: str, schema: str, metadata: dict, data: bytes, schema_data: bytes = b"",
               log_time: int = 0) -> list | None:
        metadata = metadata or {}
        if PART_OF in metadata:
            self.parts.add(metadata[PART_OF], metadata.get(FIELD, ""), log_time,
                           self._image(topic, data, schema_data))
            return None
        images = self.parts.whole(topic, schema, log_time)
        if images is None:
            return None
        try:
            fields = orjson.loads(data)
        except orjson.JSONDecodeError as exc:
            raise ValueError(f"{topic}: JSON record does not parse: {exc}") from None
        if not isinstance(fields, dict):
            raise ValueError(f"{topic}: JSON record is not an object")
        cls = MESSAGE_TYPES[schema]
        for name, f in cls.model_fields.items():
            spec = array_spec(f)
            if spec is not None and name in fields and fields[name] is not None:
                fields[name] = _array(fields[name], spec, topic, name)
        fields.update(images)
        ordered = {k: fields.pop(k) for k in cls.model_fields if k in fields}    # the wire's field order
        ordered.update(fields)
        try:
            version = int(metadata.get(VERSION, cls.VERSION))
        except ValueError:
            version = cls.VERSION
        frames = pack(topic, schema, version, ordered)
        return frames[:2] + [b.tobytes() for b in frames[2:]]

    def _image(self, topic: str, data: bytes, schema_data: bytes) -> np.ndarray:
        if self._image_cls is None:
            self._image_cls = _message_class(schema_data or RawImage.get_schema().data, IMAGE_SCHEMA)
        try:
            m = self._image_cls.FromString(bytes(data))
        except Exception as exc:  # noqa: BLE001 - protobuf raises its own DecodeError
            raise ValueError(f"{topic}: foxglove.RawImage does not parse: {exc}") from None
        ch = 3 if m.encoding == "rgb8" else 1
        img = np.frombuffer(m.data, np.uint8)
        if img.size != m.height * m.width * ch:
            raise ValueError(f"{topic}: image of {img.size} bytes is not {m.height} x {m.width} x {ch}")
        return img.reshape((m.height, m.width, 3) if ch == 3 else (m.height, m.width))


def _array(value, spec, topic: str, name: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=spec.dtype)
    except (TypeError, ValueError) as exc:
        raise DecodeError(f"{topic}: field {name}: not an array of {spec.dtype}: {exc}") from None
    if arr.size == 0 and spec.shape is not None and arr.ndim != len(spec.shape):
        arr = arr.reshape(tuple(0 if n is None else n for n in spec.shape))
    return arr


def _message_class(fds_bytes: bytes, name: str):
    """The protobuf message class ``name`` of a serialized FileDescriptorSet (google.protobuf)."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(fds_bytes)
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))
