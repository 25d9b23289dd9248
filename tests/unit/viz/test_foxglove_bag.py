"""Foxglove channels in bags (flexsheet.viz.foxglove_bag): written from raw recorder frames or from a recorded
bag, read back with the ``mcap`` reader and decoded against the schemas they carry (protobuf FileDescriptorSet
/ JSON schema); bad messages counted, never raised."""

from __future__ import annotations

import json
from collections import Counter, defaultdict
from functools import cache

import jsonschema
import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from mcap.writer import Writer

from flexsheet.runtime.bag_read import ENCODING
from flexsheet.runtime.bag_write import BagWriter
from flexsheet.runtime.codec import encode
from flexsheet.viz.foxglove_bag import FoxgloveBagChannels, add_foxglove
from flexsheet.viz.samples import sample_state
from flexsheet.viz.streams import Rates

T0 = 1.7e9
DURATION, RATE = 3.0, 50.0   # a 3 s synthetic run, every input at 50 Hz


@cache
def _run():
    """(log time s, raw frames) of a synthetic run: the finger pushes 0 → 6 mm; the arms stay at home."""
    out = []
    n = int(DURATION * RATE)
    for k in range(n):
        t = T0 + k / RATE
        st = sample_state(stamp=t, push=0.006 * k / (n - 1), seq=k)
        for name, msg in st.items():
            if name == "/camera/calibration" and k:
                continue                       # latched: once
            out.append((t, encode(name, msg)))
    return out, st


def _decoders(reader):
    """schema id -> decode(bytes) from the schemas stored in the file."""
    summary = reader.get_summary()
    dec = {}
    for sid, s in summary.schemas.items():
        if s.encoding == "protobuf":
            fds = descriptor_pb2.FileDescriptorSet.FromString(s.data)
            pool = descriptor_pool.DescriptorPool()
            for f in fds.file:
                pool.Add(f)
            dec[sid] = message_factory.GetMessageClass(pool.FindMessageTypeByName(s.name)).FromString
        elif s.encoding == "jsonschema":
            dec[sid] = json.loads
    return dec


def _read(path):
    """topic -> [(schema name, log time ns, decoded)] of every non-msgpack channel; the last JSON message of
    each channel is validated against the channel's JSON schema."""
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        dec = _decoders(reader)
        got = defaultdict(list)
        schemas = {}
        for schema, channel, message in reader.iter_messages():
            if channel.message_encoding == ENCODING:
                continue
            got[channel.topic].append((schema.name, message.log_time, dec[schema.id](message.data)))
            if schema.encoding == "jsonschema":
                schemas[channel.topic] = json.loads(schema.data)
    for topic, schema in schemas.items():
        jsonschema.validate(got[topic][-1][2], schema)
    return got


def test_channels_from_raw_frames_decode_against_their_schemas(tmp_path):
    run, last = _run()
    path = tmp_path / "fox.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        fox = FoxgloveBagChannels(w)
        for t, frames in run:
            fox.add_frames(frames, int(t * 1e9))
        fox.close()
        w.finish()
    assert not fox.rejected
    got = _read(path)
    names = {t: v[0][0] for t, v in got.items()}
    assert names["/viz/scene"] == "foxglove.SceneUpdate" and names["/viz/tf"] == "foxglove.FrameTransforms"
    assert names["/camera/left"] == names["/render/image"] == "foxglove.RawImage"
    assert names["/camera/left/calibration"] == "foxglove.CameraCalibration"
    assert names["/viz/metrics"] == "flexsheet/VizMetrics"
    assert "/fingertip" not in got                 # no JSON copies beside a recorder's raw channels
    # rates by log time: 10 Hz scene, 5 Hz images over 3 s (+ the final state written at close)
    n_scene, n_img = len(got["/viz/scene"]), len(got["/camera/left"])
    assert 28 <= n_scene <= 33 and 14 <= n_img <= 17, (n_scene, n_img)
    times = np.array([lt for _, lt, _ in got["/viz/scene"]]) / 1e9
    assert times[0] >= T0 and times[-1] <= T0 + DURATION
    # the last scene shows the last deformation and fingertip
    ents = {e.id: e for e in got["/viz/scene"][-1][2].entities}
    v = last["/object/deformation"].vertices
    pts = np.array([[p.x, p.y, p.z] for p in ents["object"].triangles[0].points])
    assert np.allclose(pts, v, atol=1e-7)
    tip = last["/fingertip"].position
    assert any(np.allclose([s.pose.position.x, s.pose.position.y, s.pose.position.z], tip)
               for s in ents["fingertip"].spheres)
    # metrics follow the run: the FEM push depth grows to 6 mm
    depth = [m["push_depth_mm"] for _, _, m in got["/viz/metrics"] if m["push_depth_mm"] is not None]
    assert len(depth) >= 28 and depth[0] < 1.0 and abs(depth[-1] - 6.0) < 1e-9 and np.all(np.diff(depth) >= 0)
    assert got["/viz/metrics"][-1][2]["latency_ms"]["fingertip"] > 0


def test_add_foxglove_to_a_recorded_bag_with_json_copies(tmp_path):
    run, last = _run()
    src = tmp_path / "run.mcap"
    bw = BagWriter(src)
    for t, frames in run:
        bw.write(frames, int(t * 1e9))
    bw.close()
    dst = tmp_path / "run_foxglove.mcap"
    with open(dst, "wb") as fh:
        w = Writer(fh)
        w.start()
        counts = add_foxglove(src, w, Rates(scene=5.0), json_copies=True)
        w.finish()
    assert "<rejected>" not in counts
    got = _read(dst)
    n = int(DURATION * RATE)
    assert len(got["/fingertip"]) == n and len(got["/sheet/target"]) == n   # full-rate JSON copies
    assert 14 <= len(got["/viz/scene"]) <= 17 and counts["/viz/scene"] == len(got["/viz/scene"])
    j = got["/object/deformation"][-1][2]
    assert "vertices" not in j and abs(j["depth"] - 0.006) < 1e-12
    assert np.allclose(got["/fingertip"][-1][2]["position"], last["/fingertip"].position)
    js = got["/arm/left/joint_state"][-1][2]
    assert js["arm"] == "left" and len(js["position"]) == 6


def test_bad_messages_are_counted_never_raised(tmp_path):
    run, _ = _run()
    st = sample_state(stamp=T0)
    d = st["/object/deformation"]
    bad = d.model_copy(update={"faces": np.full_like(d.faces, len(d.vertices))})
    with open(tmp_path / "x.mcap", "wb") as fh:
        w = Writer(fh)
        w.start()
        fox = FoxgloveBagChannels(w)
        fox.add_frames([b"/object/deformation", b"\x00garbage"], int(T0 * 1e9))
        fox.add_message("/object/deformation", bad, int(T0 * 1e9))
        for t, frames in run[:40]:
            fox.add_frames(frames, int(t * 1e9))
        fox.close()
        w.finish()
    assert fox.rejected == Counter({"/object/deformation: undecodable": 1,
                                    "/object/deformation: ValueError": 1})
    assert fox.counts["/viz/scene"] >= 1
