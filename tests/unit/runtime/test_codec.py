"""The codec and the message contract (flexsheet.runtime.codec): round trips, zero-copy arrays, rejection of
bad input with clear errors; and hostile input against every message decoder: property-based fuzzing with
hypothesis.

Targets: :func:`flexsheet.runtime.codec.decode` for every topic of ``messages.topics.ALL``, :func:`decode_any`
and :func:`peek_schema`. Inputs: random bytes, truncated frames, valid envelopes with mutated fields (wrong
types, NaN/inf, huge or negative numbers, missing/extra keys), schema and version mismatches (``True`` and
``1.0`` are not version 1), hostile array descriptors (huge, negative-as-uint64 and zero dims, 40-D shapes,
object/structured/sub-array/byte-swapped dtypes, out-of-range buffer indices) and random array contents
(NaN/inf bit patterns).

Oracle for every input: either a :class:`DecodeError` (one line, naming the topic) or a message of the
topic's type whose floats are all finite and that survives a re-encode — never another exception type,
never a hang (SIGALRM guard), never an allocation much larger than the input (tracemalloc peak).
Counts of inputs tried vs rejected are printed at the end of the module (``pytest -s``).
"""

from __future__ import annotations

import collections
import contextlib
import math
import signal
import struct
import tracemalloc

import msgpack
import numpy as np
import pytest
import zmq
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

from flexsheet.runtime.codec import DecodeError, decode, decode_any, encode, peek_schema
from messages import Fingertip, Header, Heartbeat, Message, StereoFrame
from messages import topics as T
from messages.common import array_spec
from messages.samples import sample_fields

FUZZ = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow],
                derandomize=False, database=None)
COUNTS: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
HANG_S = 20  # a single decode taking this long is a hang (generous: 2 busy cores)


# ---------------------------------------------------------------------------------------------- samples
def sample(cls: type[Message], seed: int = 0) -> Message:
    """A valid instance of ``cls`` built from its field declarations (:func:`messages.samples.sample_fields`),
    so the fuzz follows the message contract as it changes."""
    return cls(header=Header(stamp=1000.0 + seed, frame_id="display", seq=seed), **sample_fields(cls, seed))


TOPICS = list(T.ALL)
SAMPLES = {t.name: encode(t.name, sample(t.type)) for t in TOPICS}
ARRAY_FIELDS = {t.name: [n for n, i in t.type.model_fields.items() if array_spec(i)] for t in TOPICS}


# ---------------------------------------------------------------------------------------------- oracle
class _Hang(Exception):
    pass


@contextlib.contextmanager
def _hang_guard(seconds: int = HANG_S):
    def on_alarm(signum, frame):
        raise _Hang(f"decode still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@pytest.fixture(scope="module", autouse=True)
def _trace_and_report():
    tracemalloc.start()
    yield
    tracemalloc.stop()
    print("\n[fuzz] codec: inputs tried / rejected (DecodeError) / accepted")
    for target, c in sorted(COUNTS.items()):
        print(f"[fuzz]   {target:<32} tried {c['tried']:6d}  rejected {c['rejected']:6d}  accepted "
              f"{c['accepted']:6d}")
    total = sum(c["tried"] for c in COUNTS.values()), sum(c["rejected"] for c in COUNTS.values())
    print(f"[fuzz]   {'TOTAL codec':<32} tried {total[0]:6d}  rejected {total[1]:6d}")


def _finite_floats(obj, where: str = "") -> None:
    if isinstance(obj, float):
        assert math.isfinite(obj), f"accepted non-finite float at {where}: {obj!r}"
    elif isinstance(obj, np.ndarray) and obj.dtype.kind == "f":
        assert np.isfinite(obj).all(), f"accepted non-finite array at {where}"
    elif isinstance(obj, BaseModel):
        for k, v in obj.__dict__.items():
            _finite_floats(v, f"{where}.{k}")
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            _finite_floats(v, f"{where}[{i}]")


def _size(frames) -> int:
    n = 0
    for f in frames:
        try:
            n += memoryview(f).nbytes
        except TypeError:
            n += 64
    return n


def check(frames: list, topic: T.Topic, target: str, any_too: bool = True) -> Message | None:
    """Decode ``frames`` on ``topic`` (and with ``decode_any``); assert the oracle; count the outcome."""
    result = None
    for fn, name in ((lambda f: decode(f, topic), target), (decode_any, "decode_any")):
        if name == "decode_any" and not any_too:
            continue
        COUNTS[name]["tried"] += 1
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        try:
            with _hang_guard():
                msg = fn(frames)
        except DecodeError as exc:
            text = str(exc)
            assert "\n" not in text and len(text) <= 400, f"reason not one bounded line: {text[:500]!r}"
            assert text, "empty DecodeError"
            COUNTS[name]["rejected"] += 1
            msg = None
        else:
            COUNTS[name]["accepted"] += 1
            assert isinstance(msg, topic.type if name == target else Message)
            _finite_floats(msg, type(msg).__name__)
            again = decode(encode(topic.name, msg), T.Topic(topic.name, type(msg)))
            assert again.header == msg.header
        peak = tracemalloc.get_traced_memory()[1] - base
        assert (peak < 8 * _size(frames)
                + (4 << 20)), f"decode allocated {peak} bytes for {_size(frames)} input bytes"
        if name == target:
            result = msg
    return result


# ---------------------------------------------------------------------------------------------- strategies
topic_st = st.sampled_from(TOPICS)
scalar_st = st.one_of(
    st.none(), st.booleans(), st.integers(-(2 ** 63), 2 ** 64 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([math.nan, math.inf, -math.inf, -0.0, 1e308]),
    st.text(max_size=40), st.binary(max_size=40))
hostile_st = st.one_of(
    scalar_st,
    st.lists(scalar_st, max_size=6),
    st.dictionaries(st.text(max_size=8), scalar_st, max_size=4),
    st.recursive(scalar_st,
                 lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=4), c, max_size=3),
                 max_leaves=12))
DTYPES = ["<f8", "<f4", ">f8", "|u1", "<i4", "<i8", "|b1", "<u2", "<f2", "<c16", "|O", "|V8", "<U4", "|S3",
          "<M8[s]",
          "(2,)f8", "f8,f8", "", "x", "\xff", "<f8" * 20, "float64", "bool", "int32"]
dtype_st = st.one_of(st.sampled_from(DTYPES), st.text(max_size=12))
dims_st = st.lists(st.one_of(st.integers(0, 8),
                             st.sampled_from([2 ** 31, 2 ** 32 + 3, 2 ** 63, 2 ** 64 - 1, 2 ** 64 - 3])),
                   max_size=40)


def _ext(idx: int, dims: list[int], dtype: str) -> msgpack.ExtType:
    return msgpack.ExtType(1, struct.pack("<HB", idx, len(dims)) + struct.pack(f"<{len(dims)}Q", *dims)
                           + dtype.encode(errors="surrogatepass"))


def _meta(topic: T.Topic) -> dict:
    return msgpack.unpackb(SAMPLES[topic.name][1], raw=False, ext_hook=lambda c, d: msgpack.ExtType(c, d))


def _pack(obj) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


# ---------------------------------------------------------------------------------------------- tests
def test_samples_round_trip_for_every_topic():
    for t in TOPICS:
        msg = check(list(SAMPLES[t.name]), t, "valid sample")
        assert msg is not None, f"{t.name}: valid sample rejected"


@FUZZ
@given(topic=topic_st, meta=st.binary(max_size=600), buffers=st.lists(st.binary(max_size=300), max_size=4),
       n_frames=st.integers(0, 6))
def test_random_bytes(topic, meta, buffers, n_frames):
    frames = [topic.name.encode(), meta, *buffers][:n_frames]
    msg = check(frames, topic, "random bytes")
    assert msg is None or len(frames) >= 2


@FUZZ
@given(topic=topic_st, data=st.data())
def test_truncated_and_reordered_frames(topic, data):
    frames = list(SAMPLES[topic.name])
    kind = data.draw(st.sampled_from(["cut_meta", "cut_buffer", "drop_buffer", "extra_buffer", "swap"]))
    if kind == "cut_meta":
        frames[1] = frames[1][:data.draw(st.integers(0, len(frames[1]) - 1))]
    elif kind == "cut_buffer" and len(frames) > 2:
        i = data.draw(st.integers(2, len(frames) - 1))
        b = bytes(frames[i])
        frames[i] = b[:data.draw(st.integers(0, max(len(b) - 1, 0)))]
    elif kind == "drop_buffer" and len(frames) > 2:
        del frames[data.draw(st.integers(2, len(frames) - 1))]
    elif kind == "extra_buffer":
        frames.append(data.draw(st.binary(max_size=64)))
    elif kind == "swap" and len(frames) > 3:
        frames[2], frames[3] = frames[3], frames[2]
    msg = check(frames, topic, "truncated frames")
    if kind == "cut_meta" or (kind in ("cut_buffer", "drop_buffer") and len(SAMPLES[topic.name]) > 2):
        # a cut meta is not msgpack of the envelope; a cut or
        # dropped array buffer never matches its descriptor
        assert msg is None, f"{topic.name}: accepted after {kind}"


@FUZZ
@given(topic=topic_st, data=st.data())
def test_mutated_envelope_fields(topic, data):
    meta = _meta(topic)
    d = meta["d"]
    where = data.draw(st.sampled_from(["field", "header", "delete", "extra", "root"]))
    value = data.draw(hostile_st)
    if where == "field":
        key = data.draw(st.sampled_from(sorted(d)))
        d[key] = value
    elif where == "header":
        key = data.draw(st.sampled_from(["stamp", "frame_id", "seq", "bogus"]))
        d["header"][key] = value
    elif where == "delete":
        key = data.draw(st.sampled_from(sorted(d)))
        required = topic.type.model_fields[key].is_required()
        del d[key]
    elif where == "extra":
        key = data.draw(st.text(min_size=1, max_size=10).filter(lambda k: k not in d))
        d[key] = value
    else:
        key = data.draw(st.sampled_from(["d", "s", "v", "x"]))
        meta[key] = value
    try:
        frames = [topic.name.encode(), _pack(meta), *SAMPLES[topic.name][2:]]
    except (OverflowError, ValueError, TypeError):
        return  # msgpack cannot carry it: not an input a peer can send
    msg = check(frames, topic, "mutated envelope")
    if where == "extra" or (where == "header" and key == "bogus") or (where == "delete" and required):
        assert msg is None, f"{topic.name}: accepted {where} {key!r}"
    if where == "root" and key in ("s", "v", "d"):
        assert msg is None or (key == "s" and value == topic.type.SCHEMA) or (
            key == "v" and type(value) is int and value == topic.type.VERSION), f"accepted {key}={value!r}"
    if msg is not None and where == "field":
        ann = topic.type.model_fields[key].annotation
        if ann is float:
            assert type(value) in (float, int) and math.isfinite(value)
        elif ann in (int, bool, str):
            assert type(value) is ann, f"{key}: {ann.__name__} field accepted {value!r}"


@FUZZ
@given(topic=topic_st.filter(lambda t: ARRAY_FIELDS[t.name]), data=st.data(),
       idx=st.one_of(st.integers(0, 6), st.sampled_from([65535, 2 ** 15])), dims=dims_st, dtype=dtype_st,
       buf=st.binary(max_size=256))
def test_hostile_array_descriptors(topic, data, idx, dims, dtype, buf):
    meta = _meta(topic)
    key = data.draw(st.sampled_from(ARRAY_FIELDS[topic.name]))
    meta["d"][key] = _ext(idx, dims, dtype)
    frames = [topic.name.encode(), _pack(meta), *SAMPLES[topic.name][2:], buf]
    msg = check(frames, topic, "array descriptors")
    if msg is not None:  # only a descriptor that matches its buffer exactly may pass
        arr = getattr(msg, key)
        assert tuple(arr.shape) == tuple(dims) and arr.nbytes == memoryview(frames[idx]).nbytes
        assert arr.dtype.kind in "biuf" and not arr.flags.writeable


@FUZZ
@given(topic=topic_st.filter(lambda t: ARRAY_FIELDS[t.name]), data=st.data())
def test_random_array_contents_nan_inf(topic, data):
    frames = list(SAMPLES[topic.name])
    i = data.draw(st.integers(2, len(frames) - 1))
    n = memoryview(frames[i]).nbytes
    special = data.draw(st.sampled_from([None, math.nan, math.inf, -math.inf]))
    if special is not None and n % 8 == 0 and n:
        arr = np.frombuffer(bytes(frames[i]), np.uint8).copy()
        vals = np.frombuffer(arr.tobytes(), "<f8").copy()
        vals[data.draw(st.integers(0, len(vals) - 1))] = special
        raw = vals.tobytes()
    else:
        raw = data.draw(st.binary(min_size=n, max_size=n))
    frames[i] = raw
    msg = check(frames, topic, "array contents (NaN/inf)")
    meta = _meta(topic)
    for key, v in meta["d"].items():  # which field owns buffer i, and is it float?
        if isinstance(v, msgpack.ExtType) and struct.unpack_from("<H", v.data)[0] == i:
            arr = np.frombuffer(raw, np.dtype(v.data[3 + 8 * v.data[2]:].decode()))
            if arr.dtype.kind == "f" and not np.isfinite(arr).all():
                assert msg is None, f"{topic.name}.{key}: non-finite array accepted"


@FUZZ
@given(topic=topic_st,
       version=st.one_of(st.integers(-(2 ** 63), 2 ** 64 - 1), st.booleans(), st.floats(),
                         st.text(max_size=4),
                         st.none()),
       schema=st.one_of(st.sampled_from(sorted({t.type.SCHEMA for t in TOPICS})), st.text(max_size=30)))
def test_schema_version_mismatch(topic, version, schema):
    meta = _meta(topic)
    meta["s"], meta["v"] = schema, version
    frames = [topic.name.encode(), _pack(meta), *SAMPLES[topic.name][2:]]
    msg = check(frames, topic, "schema/version", any_too=False)
    ok = schema == topic.type.SCHEMA and type(version) is int and version == topic.type.VERSION
    assert (msg is not None) == ok, f"schema {schema!r} version {version!r}: accepted={msg is not None}"
    COUNTS["peek_schema"]["tried"] += 1
    try:
        s, v = peek_schema(frames[1])
        assert (s, v) == (schema, version)
    except DecodeError:
        COUNTS["peek_schema"]["rejected"] += 1
        assert not (type(schema) is str and type(version) is int)


@FUZZ
@given(meta=st.one_of(st.binary(max_size=200),
                      hostile_st.map(lambda v: _pack(v) if _packable(v) else b"\xc1")))
def test_peek_schema_garbage(meta):
    COUNTS["peek_schema"]["tried"] += 1
    try:
        with _hang_guard():
            s, v = peek_schema(meta)
    except DecodeError as exc:
        COUNTS["peek_schema"]["rejected"] += 1
        assert "\n" not in str(exc)
    else:
        assert type(s) is str and type(v) is int


def _packable(v) -> bool:
    try:
        _pack(v)
        return True
    except (OverflowError, ValueError, TypeError):
        return False


def test_huge_declared_sizes_allocate_nothing():
    """Descriptors claiming petabytes (or wrapping to small products) are refused before any allocation."""
    topic = T.STEREO
    for dims in ([2 ** 32, 2 ** 32], [0, 2 ** 63], [2 ** 64 - 1, 2], [2 ** 62, 4], [1] * 33):
        meta = _meta(topic)
        meta["d"]["left"] = _ext(2, dims, "|u1")
        frames = [topic.name.encode(), _pack(meta), *SAMPLES[topic.name][2:]]
        assert check(frames, topic, "huge sizes") is None


def test_non_bytes_frames_are_decode_errors():
    """Wrong Python types where frames belong (a topic frame that is an int must not become ``bytes(n)``)."""
    for frames in ([10 ** 12, SAMPLES["/fingertip"][1]], [None, b"x"], [b"/fingertip", None],
                   [b"/fingertip", "str"],
                   [b"/fingertip", 12345], [], [b"/fingertip"],
                   [b"/fingertip", SAMPLES["/fingertip"][1], None]):
        assert check(frames, T.FINGERTIP, "wrong frame types") is None


def tip(**kw) -> Fingertip:
    base = dict(header=Header(stamp=12.5, frame_id="display", seq=7), position=np.array([0.01, -0.02, 0.03]),
                covariance=np.eye(3) * 1e-8, valid=True, predicted_position=np.array([0.011, -0.02, 0.03]),
                prediction_horizon=0.02, exposure_stamp=12.49)
    base.update(kw)
    return Fingertip(**base)


def test_round_trip_preserves_every_field():
    msg = tip()
    out = decode(encode(T.FINGERTIP.name, msg), T.FINGERTIP)
    assert out.header == msg.header
    np.testing.assert_array_equal(out.position, msg.position)
    np.testing.assert_array_equal(out.covariance, msg.covariance)
    assert out.prediction_horizon == 0.02 and out.exposure_stamp == 12.49 and out.valid


def test_images_travel_as_raw_frames_not_lists():
    left = np.arange(480 * 640, dtype=np.uint32).astype(np.uint8).reshape(480, 640)
    msg = StereoFrame(header=Header(stamp=1.0, frame_id="camera_left"), left=left, right=left[::-1].copy(),
                      exposure_stamp=1.0, exposure_time=0.004)
    frames = encode(T.STEREO.name, msg)
    assert len(frames) == 4
    assert len(frames[1]) < 400  # meta holds no pixel data
    assert memoryview(frames[2]).nbytes == 480 * 640
    out = decode([bytes(f) for f in frames], T.STEREO)
    np.testing.assert_array_equal(out.left, left)
    assert not out.left.flags.writeable  # wraps the received buffer, no copy


@pytest.mark.parametrize("frames, needle", [
    ([b"/fingertip"], "at least 2 frames"),
    ([b"/fingertip", b"\xc1\xc1garbage"], "undecodable"),
    ([b"/fingertip", msgpack.packb([1, 2, 3])], "envelope"),
])
def test_garbage_frames_rejected_with_reason(frames, needle):
    with pytest.raises(DecodeError, match=needle):
        decode(frames, T.FINGERTIP)


def test_wrong_type_and_version_named():
    hb = Heartbeat(header=Header(stamp=1.0), node="x")
    frames = encode(T.FINGERTIP.name, hb)
    with pytest.raises(DecodeError, match="expected type flexsheet/Fingertip v1, got 'flexsheet/Heartbeat'"):
        decode(frames, T.FINGERTIP)
    frames = encode(T.FINGERTIP.name, tip())
    env = msgpack.unpackb(frames[1], ext_hook=lambda c, d: msgpack.ExtType(c, d))
    env["v"] = 99
    frames[1] = msgpack.packb(env)
    with pytest.raises(DecodeError, match="version mismatch: expected v1, got v99"):
        decode(frames, T.FINGERTIP)


def test_nan_and_wrong_shape_name_the_field():
    with pytest.raises(ValueError, match="position"):
        tip(position=np.array([np.nan, 0.0, 0.0]))
    frames = encode(T.FINGERTIP.name, tip())
    frames[2] = np.array([np.inf, 0, 0], dtype=np.float64).tobytes()
    with pytest.raises(DecodeError, match="field position"):
        decode(frames, T.FINGERTIP)
    frames = encode(T.FINGERTIP.name, tip())
    frames[2] = np.zeros(4).tobytes()  # 4 floats where the descriptor says 3
    with pytest.raises(DecodeError, match="needs 24 bytes, buffer has 32"):
        decode(frames, T.FINGERTIP)


def test_decode_any_uses_carried_schema():
    out = decode_any(encode("/anything", tip()))
    assert isinstance(out, Fingertip) and out.header.seq == 7


def test_a_descriptor_with_many_huge_dims_gives_one_bounded_line():
    """The fuzz test's falsifying example: a 37-dim descriptor with 2^31 / 2^63 sizes made the
    reason 401 characters; the shape is now cut after 8 dims (here in the too-many-bytes reason, which writes
    the shape the same way as the buffer-size one)."""
    import struct

    from flexsheet.runtime.codec import parse_descriptor

    dims = [1] * 23 + [2 ** 31] * 4 + [2 ** 63] * 10
    data = struct.pack("<HB", 2, len(dims)) + struct.pack(f"<{len(dims)}Q", *dims) + b"<f8"
    why = parse_descriptor(data)
    assert isinstance(why, str) and "\n" not in why and len(why) <= 200, why
    assert "... 37 dims" in why and "needs" in why


def test_frames_received_as_zmq_frames_decode_to_the_same_message():
    msg = tip()
    frames = encode(T.FINGERTIP.name, msg)
    zframes = [bytes(frames[0]), bytes(frames[1])] + [zmq.Frame(bytes(memoryview(f))) for f in frames[2:]]
    out = decode(zframes, T.FINGERTIP)
    assert out.header == msg.header and out.exposure_stamp == msg.exposure_stamp
    for name in ("position", "covariance", "predicted_position"):
        np.testing.assert_array_equal(getattr(out, name), getattr(msg, name))
    short = zframes[:3] + [zmq.Frame(b"\0" * 8), zframes[4]]
    with pytest.raises(DecodeError, match="needs 72 bytes, buffer has 8"):
        decode(short, T.FINGERTIP)


def test_decode_rejects_what_model_validate_rejects_with_the_field():
    frames = encode(T.FINGERTIP.name, tip())
    env = msgpack.unpackb(frames[1], ext_hook=lambda c, d: msgpack.ExtType(c, d))
    for field, value, needle in (("prediction_horizon", -1.0, "field prediction_horizon"),
                                 ("valid", 1, "field valid"), ("exposure_stamp", "x", "field exposure_stamp"),
                                 ("extra", 1.0, "field extra")):
        bad = dict(env, d=dict(env["d"], **{field: value}))
        with pytest.raises(DecodeError, match=needle):
            decode([frames[0], msgpack.packb(bad), *frames[2:]], T.FINGERTIP)
