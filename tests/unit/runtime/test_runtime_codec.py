"""Codec and message contract: round trips, zero-copy arrays, and rejection of bad input with clear errors."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest

from flexsheet.runtime.codec import DecodeError, decode, decode_any, encode
from messages import Fingertip, Header, Heartbeat, StereoFrame
from messages import topics as T


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
