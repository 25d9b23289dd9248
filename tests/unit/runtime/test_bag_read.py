"""Reading a bag (flexsheet.runtime.bag_read): a file that also carries Foxglove channels still reads as a
flexsheet bag."""

from __future__ import annotations

import base64

import msgpack
from mcap.writer import CompressionType, Writer
from test_foxglove_bag import _read, _run

from flexsheet.runtime.bag_export import export_bag
from flexsheet.runtime.bag_read import ENCODING, bag_info, read_bag
from flexsheet.runtime.bag_write import BagWriter
from flexsheet.viz.foxglove_bag import FoxgloveBagChannels


def test_a_bag_with_foxglove_channels_still_reads_as_a_flexsheet_bag(tmp_path):
    """The recorder hook writes both kinds of channel into one file; read_bag (play, info, report) must
    return the msgpack messages only. Needs read_bag to skip channels of other encodings (hook 1)."""
    run, _ = _run()
    path = tmp_path / "mixed.mcap"
    bw = BagWriter(path)
    fox = FoxgloveBagChannels(bw._writer)
    for t, frames in run[:200]:
        bw.write(frames, int(t * 1e9))
    bw._q.put(None)          # let the writer thread drain, then add Foxglove channels to the same file
    bw._thread.join()
    for t, frames in run[:200]:
        fox.add_frames(frames, int(t * 1e9))
    fox.close()
    bw._writer.finish()
    bw._fh.close()
    msgs = list(read_bag(path))
    assert len(msgs) == 200 and all(m.schema.startswith("flexsheet/") for m in msgs)
    assert fox.counts["/viz/scene"] > 0
    # and the file is readable by the plain mcap reader with both kinds of channel
    got = _read(path)
    assert "/viz/scene" in got and base64  # noqa: B018


def test_a_bag_of_the_earlier_msgpack_encoding_still_plays_and_exports(tmp_path):
    """Bags recorded before the viewer encoding (``flexsheet-msgpack`` channels: the wire frames as a msgpack
    list) read as before: the same frames, counted by ``bag info``, exported to JSON."""
    run, _ = _run()
    path = tmp_path / "old.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh, compression=CompressionType.LZ4)
        w.start(profile="flexsheet", library="flexsheet")
        channels: dict[str, int] = {}
        for t, frames in run[:120]:
            topic = bytes(frames[0]).decode()
            if topic not in channels:
                channels[topic] = w.register_channel(topic, ENCODING,
                                                     w.register_schema("s", "jsonschema", b"{}"))
            w.add_message(channels[topic], log_time=int(t * 1e9), publish_time=int(t * 1e9),
                          data=msgpack.packb([bytes(f) for f in frames[1:]]))
        w.finish()
    msgs = list(read_bag(path))
    assert [m.frames for m in msgs] == [[bytes(f) for f in frames] for _t, frames in run[:120]]
    assert sum(bag_info(path).counts.values()) == 120
    counts = export_bag(path, tmp_path / "old_json.mcap", foxglove=False, workers=0)
    assert sum(v for k, v in counts.items() if not k.startswith("<")) >= 120 and not counts.get("<rejected>")
