"""Wire codec: a message is a ZeroMQ multipart ``[topic, meta, *buffers]``.

``meta`` is msgpack of ``{"s": SCHEMA, "v": VERSION, "d": fields}``; every numpy array inside ``fields`` is
replaced by a msgpack ext (code 1) holding the buffer index (uint16), ndim (uint8), the dims (uint64
each, little-endian) and ``dtype.str``; its bytes travel as
its own frame, so images and vertex arrays are never turned into lists and receivers wrap the received
frame with ``np.frombuffer`` without a copy (the arrays are read-only, like the frozen messages).

Errors: :class:`DecodeError` (a ``ValueError``) with a one-line reason naming the topic, and the field and
value where one is at fault. Source: pyzmq ``examples/serialization`` (zero-copy numpy), msgpack ext types.
"""

from __future__ import annotations

import functools
import struct
from typing import Any

import msgpack
import numpy as np
from pydantic import BaseModel, ValidationError
from pydantic_core import SchemaValidator

from messages import MESSAGE_TYPES, Message, Topic

__all__ = ["DecodeError", "encode", "pack", "unpack", "decode", "decode_any", "peek_schema", "peek_stamp",
           "MAX_ARRAY_BYTES"]

EXT_NDARRAY = 1
_HEAD = struct.Struct("<HB")  # buffer index, ndim; then ndim × uint64 dims, then the dtype string
_pack_head = _HEAD.pack


def _unpack_head(data: bytes) -> tuple[int, int]:
    return _HEAD.unpack_from(data, 0)


@functools.lru_cache(maxsize=256)
def parse_descriptor(data: bytes) -> tuple[int, np.dtype, tuple[int, ...], int] | str:
    """(buffer index, dtype, shape, nbytes) of an array descriptor, or the reason it is bad (cached:
    a topic's descriptors repeat message after message)."""
    try:
        idx, ndim = _unpack_head(data)
        shape = struct.unpack_from(f"<{ndim}Q", data, 3)
        dtype_str = data[3 + 8 * ndim:].decode()
        dtype = np.dtype(dtype_str)
    except Exception as exc:  # noqa: BLE001 - any garbage in the ext payload is a decode error
        return f"bad array descriptor ({type(exc).__name__}: {exc})"
    if idx < 2:
        return f"array buffer index {idx!r} out of range"
    if dtype.kind not in _ALLOWED_KINDS or dtype.hasobject:
        return f"array dtype {dtype_str!r:.40} not allowed"
    count = 1
    for n in shape:
        count *= n
    nbytes = count * dtype.itemsize
    if nbytes > MAX_ARRAY_BYTES:
        return (f"array shape {_shape_text(shape)} dtype {dtype} needs {_count_text(nbytes)} bytes, more "
                f"than the {MAX_ARRAY_BYTES} allowed")
    return idx, dtype, shape, nbytes


def _shape_text(shape: tuple[int, ...]) -> str:
    """A decoded array shape for an error message, at most 8 dimensions written (a hostile descriptor may give
    hundreds of huge ones: the reason must stay one bounded line)."""
    if len(shape) <= 8:
        return str(tuple(shape))
    return f"({', '.join(str(n) for n in shape[:8])}, ... {len(shape)} dims)"


def _count_text(n: int) -> str:
    """A byte count for an error message: exact up to 20 digits, else its power of ten (dims up to 2^64 each
    multiply to hundreds of digits)."""
    t = str(n)
    return t if len(t) <= 20 else f"~10^{len(t) - 1}"


#: good descriptors seen (bytes -> (index, dtype, shape, nbytes)): a topic's repeat message after message
_GOOD_DESCRIPTORS: dict[bytes, tuple[int, np.dtype, tuple[int, ...], int]] = {}


def _descriptor(data: bytes, topic_name: str) -> tuple[int, np.dtype, tuple[int, ...], int]:
    if type(data) is not bytes:
        data = bytes(data)
    # only short (well-formed-sized) descriptors go through the cache: a hostile huge one is not retained
    parsed = parse_descriptor(data) if len(data) <= 96 else parse_descriptor.__wrapped__(data)
    if isinstance(parsed, str):
        raise DecodeError(_line(f"{topic_name}: {parsed}"))
    if len(data) <= 96 and len(_GOOD_DESCRIPTORS) < 4096:
        _GOOD_DESCRIPTORS[data] = parsed
    return parsed

#: refuse arrays larger than this (bytes) on decode: a hostile size must not allocate or wrap garbage
MAX_ARRAY_BYTES = 256 * 1024 * 1024
_ALLOWED_KINDS = set("biuf")


class DecodeError(ValueError):
    """A frame set that is not a valid message for its topic (bad bytes, wrong schema/version, bad field)."""


def _line(text: str, limit: int = 300) -> str:
    """``text`` on one line (runs of whitespace, e.g. a numpy repr's newlines, become one space), at most
    ``limit`` characters: a hostile value must not turn one rejection into a multi-line or huge log entry."""
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _topic_name(frame: Any) -> str:
    """Printable name of a topic frame (bytes-like only; anything else, e.g. an int, is not turned into
    ``bytes(n)`` zeros), at most 120 characters."""
    if isinstance(frame, (bytes, bytearray, memoryview)) or hasattr(frame, "bytes"):
        raw = frame.bytes if hasattr(frame, "bytes") else bytes(frame[:120])
        return _line(raw[:120].decode(errors="replace"), 120)
    return f"<{type(frame).__name__} topic frame>"


_EXT_CACHE: dict[tuple, msgpack.ExtType] = {}
_ExtType, _ndarray, _BaseModel = msgpack.ExtType, np.ndarray, BaseModel
_unpackb = msgpack.unpackb
_good_descriptor = _GOOD_DESCRIPTORS.get


def _ext(index: int, arr: np.ndarray) -> msgpack.ExtType:
    """The array descriptor ext of buffer ``index`` for ``arr`` (cached: a topic's descriptors repeat)."""
    shape = arr.shape
    key = (index, shape, arr.dtype.str)
    ext = _EXT_CACHE.get(key)
    if ext is None:
        ext = _ExtType(EXT_NDARRAY, _pack_head(index, len(shape)) + struct.pack(f"<{len(shape)}Q", *shape)
                       + arr.dtype.str.encode())
        if len(_EXT_CACHE) < 4096:
            _EXT_CACHE[key] = ext
    return ext


def _fields(d: dict, buffers: list) -> dict:
    out = {}
    for k, v in d.items():
        t = type(v)
        if t is _ndarray or isinstance(v, _ndarray):
            arr = v if v.flags.c_contiguous else np.ascontiguousarray(v)
            buffers.append(arr)
            v = _ext(len(buffers) + 1, arr)
        elif isinstance(v, _BaseModel):
            v = _fields(v.__dict__, buffers)
        elif t is list and v and isinstance(v[0], _BaseModel):
            v = [_fields(x.__dict__, buffers) if isinstance(x, _BaseModel) else x for x in v]
        out[k] = v
    return out


def _default(value: Any) -> Any:  # msgpack calls it only for what neither _fields nor msgpack handles
    if isinstance(value, _BaseModel):
        return value.__dict__
    raise TypeError(f"cannot encode {type(value).__name__}")


def encode(topic: str, msg: Message) -> list:
    """Encode ``msg`` for ``topic`` into multipart frames ``[topic, meta, *buffers]``.

    Buffers are the arrays' own memory (C-contiguous views; a non-contiguous array is copied once).
    Raises ``TypeError`` for a field value msgpack cannot carry.
    """
    return pack(topic, msg.SCHEMA, msg.VERSION, msg.__dict__)


def pack(topic: str, schema: str, version: int, fields: dict) -> list:
    """Frames ``[topic, meta, *buffers]`` of a message given as its ``schema`` name, ``version`` and
    ``fields`` (plain values, dicts for nested models, numpy arrays), not validated (a receiver validates).
    Raises ``TypeError`` for a value msgpack cannot carry."""
    buffers: list = []
    meta = msgpack.packb({"s": schema, "v": version, "d": _fields(fields, buffers)}, default=_default)
    return [topic.encode(), meta, *buffers]


def unpack(frames: list, topic_name: str) -> dict:
    """The envelope ``{"s": schema, "v": version, "d": fields}`` of ``frames`` (arrays as read-only numpy
    views of their buffers), not validated against its type. Raises :class:`DecodeError` naming
    ``topic_name``."""
    return _unpack(frames, topic_name)


def _unpack(frames: list, topic_name: str) -> dict:
    if len(frames) < 2:
        raise DecodeError(f"{topic_name}: expected at least 2 frames [topic, meta], got {len(frames)}")
    nbuf = len(frames)

    def ext_hook(code: int, data: bytes) -> Any:
        if code != EXT_NDARRAY:
            raise DecodeError(f"{topic_name}: unknown msgpack ext code {code}")
        desc = _good_descriptor(data)
        idx, dtype, shape, nbytes = desc if desc is not None else _descriptor(data, topic_name)
        if idx >= nbuf:
            raise DecodeError(f"{topic_name}: array buffer index {idx!r} out of range (frames: {nbuf})")
        buf = frames[idx]
        if type(buf) is bytes:
            have = len(buf)
        else:
            if hasattr(buf, "buffer"):      # a zmq.Frame: its memory
                buf = buf.buffer
            have = buf.nbytes if type(buf) is memoryview else memoryview(buf).nbytes
        if have != nbytes:
            raise DecodeError(f"{topic_name}: array shape {_shape_text(shape)} dtype {dtype} needs {nbytes} "
                              f"bytes, buffer has {have}")
        return _ndarray(shape, dtype, buf)   # a view of the frame's memory (read-only for bytes), no copy

    meta = frames[1]
    if type(meta) is not bytes and hasattr(meta, "bytes"):
        meta = meta.bytes
    try:
        obj = _unpackb(meta, ext_hook=ext_hook, raw=False, strict_map_key=True)
    except DecodeError:
        raise
    except Exception as exc:  # noqa: BLE001 - msgpack raises many types on garbage
        raise DecodeError(_line(f"{topic_name}: undecodable meta frame ({type(exc).__name__}: "
                                f"{exc})")) from None
    if not isinstance(obj, dict) or not {"s", "v", "d"} <= obj.keys() or not isinstance(obj["d"], dict):
        raise DecodeError(f"{topic_name}: meta frame is not a flexsheet message envelope")
    return obj


def decode(frames: list, topic: Topic) -> Message:
    """Decode multipart ``frames`` received on ``topic`` into a validated ``topic.type`` message.

    ``frames`` may be ``bytes`` or ``zmq.Frame`` objects (zero-copy). Raises :class:`DecodeError` naming the
    topic and the reason: undecodable bytes, wrong schema (expected vs received), wrong version, a bad array
    descriptor, or a field that fails validation (field name and value).
    """
    obj = _unpack(frames, topic.name)
    cls = topic.type
    if type(obj["s"]) is not str or obj["s"] != cls.SCHEMA:
        raise DecodeError(_line(f"{topic.name}: expected type {cls.SCHEMA} v{cls.VERSION}, "
                                f"got {obj['s']!r:.80} v{obj['v']!r:.40}"))
    if type(obj["v"]) is not int or obj["v"] != cls.VERSION:
        raise DecodeError(_line(f"{topic.name}: {cls.SCHEMA} version mismatch: expected v{cls.VERSION}, "
                                f"got v{obj['v']!r:.40}"))
    try:
        return _validator(cls)(obj["d"])
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err["loc"])
        raise DecodeError(_line(f"{topic.name}: field {loc or '<message>'}: {err['msg']:.200} "
                                f"(value {err.get('input')!r:.80})")) from None


_VALIDATORS: dict[type, Any] = {}


def _validator(cls: type[Message]) -> Any:
    """``cls.model_validate`` as pydantic-core's prebuilt ``validate_python`` of the class (cached per class;
    the same validation, less the per-call Python wrapper)."""
    fn = _VALIDATORS.get(cls)
    if fn is None:
        v = cls.__pydantic_validator__
        fn = _VALIDATORS[cls] = v.validate_python if isinstance(v, SchemaValidator) else cls.model_validate
    return fn


def decode_any(frames: list) -> Message:
    """Decode frames by the schema name they carry (used by tools that do not know the topic's type)."""
    topic_name = _topic_name(frames[0]) if frames else "?"
    obj = _unpack(frames, topic_name)
    cls = MESSAGE_TYPES.get(obj["s"]) if type(obj["s"]) is str else None
    if cls is None:
        raise DecodeError(_line(f"{topic_name}: unknown schema {obj['s']!r:.80}"))
    return decode(frames, Topic(topic_name, cls))


def peek_schema(meta: bytes) -> tuple[str, int]:
    """Return ``(schema, version)`` of an encoded meta frame without building arrays or validating.

    Raises :class:`DecodeError` if ``meta`` is not msgpack of an envelope with a str schema and an int
    version.
    """
    try:
        obj = msgpack.unpackb(meta, ext_hook=lambda c, d: None, raw=False)
    except Exception as exc:  # noqa: BLE001 - msgpack raises many types on garbage
        raise DecodeError(_line(f"undecodable meta frame ({type(exc).__name__}: {exc})")) from None
    if not isinstance(obj, dict) or type(obj.get("s")) is not str or type(obj.get("v")) is not int:
        raise DecodeError("meta frame is not a flexsheet message envelope (str 's', int 'v')")
    return obj["s"], obj["v"]


def peek_stamp(frames: list) -> float | None:
    """The ``header.stamp`` (s, the sender's clock) of an encoded message ``[topic, meta, *buffers]``, read
    from its meta frame without building arrays or validating; None when it has no numeric stamp."""
    try:
        obj = msgpack.unpackb(bytes(frames[1]), ext_hook=lambda c, d: None, raw=False)
        stamp = obj["d"]["header"]["stamp"]
    except Exception:  # noqa: BLE001 - garbage, a short message or a message without a header: no stamp
        return None
    return float(stamp) if isinstance(stamp, (int, float)) and not isinstance(stamp, bool) else None
