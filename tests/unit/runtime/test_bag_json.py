"""The bag's viewer encoding: every message of the display goes to JSON (validating against the jsonschema
stored with it) plus foxglove.RawImage parts for its images, and comes back as the very wire frames it was
recorded from; a message whose image part is missing is not made up."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import orjson
import pytest

from flexsheet.runtime.bag_json import (
    FIELD,
    IMAGE_SCHEMA,
    JSON_ENCODING,
    PART_OF,
    VERSION,
    ViewerDecoder,
    ViewerEncoder,
    image_fields,
)
from flexsheet.runtime.codec import DecodeError, decode_any, encode
from flexsheet.viz.samples import sample_state
from messages import topics as T


def _roundtrip(frames: list, t: int = 5) -> tuple[list, list]:
    recs = ViewerEncoder().records(frames)
    dec, out = ViewerDecoder(), []
    for r in recs:
        got = dec.frames(r.topic, r.schema, r.metadata, r.data, r.schema_data, t)
        if got is not None:
            out.append(got)
    return recs, out


@pytest.mark.parametrize("topic", sorted(sample_state()))
def test_every_message_comes_back_byte_identical_from_its_viewer_records(topic):
    msg = sample_state(stamp=1234.5678, seq=7)[topic]
    frames = [bytes(f) if isinstance(f, bytes) else np.ascontiguousarray(f).tobytes()
              for f in encode(topic, msg)]
    recs, out = _roundtrip(frames)
    assert len(out) == 1 and out[0] == frames                     # the same meta and buffers, byte for byte
    main = recs[-1]
    assert (main.topic, main.encoding, main.schema) == (topic, JSON_ENCODING, msg.SCHEMA)
    assert main.metadata == {VERSION: str(msg.VERSION)}
    jsonschema.validate(orjson.loads(main.data), json.loads(main.schema_data))     # what a viewer checks
    assert decode_any(out[0]).header == msg.header                    # and it validates as its type


def test_images_are_raw_images_a_protobuf_reader_decodes():
    msg = sample_state(stamp=10.25)[T.RENDERED.name]
    assert image_fields(msg.SCHEMA) == ("left", "right")
    recs, _ = _roundtrip(encode(T.RENDERED.name, msg))
    parts = recs[:-1]
    assert [(r.topic, r.encoding, r.schema, r.metadata) for r in parts] == [
        (f"{T.RENDERED.name}/{f}", "protobuf", IMAGE_SCHEMA, {PART_OF: T.RENDERED.name, FIELD: f})
        for f in ("left", "right")]
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
    fds = descriptor_pb2.FileDescriptorSet.FromString(parts[0].schema_data)
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    img = message_factory.GetMessageClass(pool.FindMessageTypeByName(IMAGE_SCHEMA)).FromString(parts[0].data)
    h, w, _ = msg.left.shape
    assert (img.width, img.height, img.encoding, img.step) == (w, h, "rgb8", 3 * w)
    assert img.timestamp.seconds == 10 and img.timestamp.nanos == 250_000_000
    assert np.array_equal(np.frombuffer(img.data, np.uint8).reshape(h, w, 3), msg.left)
    assert "left" not in orjson.loads(recs[-1].data)                # the JSON leaves the images out


def test_a_message_whose_image_part_was_lost_is_not_yielded():
    recs = ViewerEncoder().records(encode(T.STEREO.name, sample_state()[T.STEREO.name]))
    dec = ViewerDecoder()
    r = recs[0]                                                     # only the left image survived
    assert dec.frames(r.topic, r.schema, r.metadata, r.data, r.schema_data, 5) is None
    m = recs[-1]
    assert dec.frames(m.topic, m.schema, m.metadata, m.data, m.schema_data, 5) is None
    for r in recs[:-1]:  # both parts, but of another message (t = 4)
        dec.frames(r.topic, r.schema, r.metadata, r.data, r.schema_data, 4)
    assert dec.frames(m.topic, m.schema, m.metadata, m.data, m.schema_data, 5) is None


def test_bad_records_raise_naming_the_topic():
    with pytest.raises(DecodeError, match="/fingertip"):
        ViewerEncoder().records([b"/fingertip", b"\xc1 not msgpack"])
    m = ViewerEncoder().records(encode(T.FINGERTIP.name, sample_state()[T.FINGERTIP.name]))[-1]
    with pytest.raises(ValueError, match="/fingertip: JSON record does not parse"):
        ViewerDecoder().frames(m.topic, m.schema, m.metadata, b"{nope", m.schema_data, 1)
    with pytest.raises(ValueError, match="/fingertip: JSON record is not an object"):
        ViewerDecoder().frames(m.topic, m.schema, m.metadata, b"[1, 2]", m.schema_data, 1)
