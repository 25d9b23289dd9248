"""Nothing lost: the recorder stores or counts every malformed input and keeps recording; every read checks
the chunk CRCs and skips only a damaged chunk; a bag cut by kill -9 is recovered for the stock ``mcap``
reader; ``bag info`` reads any MCAP; ``bag play`` refuses a bad file in one line; a respawned recorder writes
its gap."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import time

import msgpack
import numpy as np
import pytest
from conftest import ROOT, free_port
from mcap.reader import make_reader
from mcap.writer import Writer

from flexsheet.experiments.faults.bags import T0, fingertip, with_seq
from flexsheet.runtime.bag import RecorderNode
from flexsheet.runtime.bag_export import export_bag
from flexsheet.runtime.bag_read import GAP_TOPIC, BagSummary, bag_info, read_bag
from flexsheet.runtime.bag_recover import recover_bag
from flexsheet.runtime.bag_write import BagWriter
from flexsheet.runtime.codec import decode, encode
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.node import Node
from messages import Header, StereoFrame
from messages import topics as T

tip = fingertip


def hostile_inputs() -> list[tuple[list, str]]:
    """(frames, where it must end up): ``stored`` on the lossless channel, ``raw`` (malformed, stored as it
    came)."""
    good = encode(T.FINGERTIP.name, tip(0))
    return [([b"/fingertip"], "raw"),                                   # a 1-frame multipart message
            ([b"/fingertip", b"\xc1\xc1 not msgpack"], "raw"),          # undecodable meta
            ([b"/fingertip", msgpack.packb([1, 2, 3])], "raw"),         # msgpack, not an envelope
            ([], "raw"),                                                # no frame at all
            (with_seq(good, "x"), "stored"), (with_seq(good, 1.5), "stored"),
            (with_seq(good, None), "stored"),
            (with_seq(good, 2**64 - 1), "stored")]  # a huge seq: a reset, not 1.8e19 drops


def test_malformed_frames_are_stored_or_counted_and_the_recording_goes_on(tmp_path):
    path = tmp_path / "hostile.mcap"
    w = BagWriter(path, chunk_size=4096)
    hostile = hostile_inputs()
    good_seqs = [s for s in range(200) if not 50 <= s < 55]            # 5 lost on the wire
    fed = 0
    for i, seq in enumerate(good_seqs):
        w.write(encode(T.FINGERTIP.name, tip(seq)), T0 + i * 25_000_000)
        fed += 1
        if i % 20 == 10:                                                 # hostile input between good messages
            frames, _ = hostile[(i // 20) % len(hostile)]
            w.write(frames, T0 + i * 25_000_000 + 1)
            fed += 1
    w.write([b"/fingertip", 5], T0)  # not bytes: counted, cannot be stored
    w.close()
    info = bag_info(path)
    n_hostile = sum(1 for i in range(len(good_seqs)) if i % 20 == 10)
    where = [hostile[(i // 20) % len(hostile)][1] for i in range(len(good_seqs)) if i % 20 == 10]
    stored_bad, raw = where.count("stored"), where.count("raw")
    assert n_hostile == 10 and stored_bad == 4 and raw == 6
    # 0 frames lost to malformed input: every one is in the bag, on its channel
    assert info.counts[T.FINGERTIP.name] == len(good_seqs) + stored_bad
    assert sum(info.malformed.values()) == raw
    assert sum(info.counts.values()) + sum(info.malformed.values()) == fed
    # drops are the real wire gap only; the huge and non-int seqs counted nothing
    assert info.dropped == {T.FINGERTIP.name: 5, "<not bytes>": 1}
    assert w.resets[T.FINGERTIP.name] == 2  # into the huge seq and back out of it
    # the recording went on to the end: the last good message is there and decodes
    msgs = list(read_bag(path))
    assert decode(msgs[-1].frames, T.FINGERTIP).header.seq == 199
    assert not info.damaged and not info.truncated


class _Hostile(Node):
    """Publishes good fingertips with hostile frames between them, as raw wire frames."""

    async def setup(self) -> None:
        asyncio.get_running_loop().create_task(self._send())

    async def _send(self) -> None:
        await asyncio.sleep(1.0)   # the recorder's subscription reaches us
        hostile = hostile_inputs()
        for i in range(100):
            self.transport.send(encode(T.FINGERTIP.name, tip(i)))
            if i % 10 == 5:
                frames = hostile[(i // 10) % len(hostile)][0]
                if frames:                 # zmq cannot send an empty multipart message
                    self.transport.send(frames)
            await asyncio.sleep(0.002)


def test_recorder_node_records_through_hostile_input_and_says_so_in_its_heartbeat(tmp_path):
    pub_ep = f"tcp://127.0.0.1:{free_port()}"
    path = tmp_path / "rec.mcap"

    async def scenario():
        pub = _Hostile(NodeConfig(name="hostile", endpoint=pub_ep))
        rec = RecorderNode(NodeConfig(name="rec", endpoint="", peers=[pub_ep],
                                      params={"output": str(path), "topics": [T.FINGERTIP.name]}))
        tasks = [asyncio.get_running_loop().create_task(n.run(install_signals=False)) for n in (rec, pub)]
        t0 = time.monotonic()
        while time.monotonic() - t0 < 15 and not (
                hasattr(rec, "writer")
                and sum(rec.writer.counts.values()) + sum(rec.writer.malformed.values()) >= 110):
            await asyncio.sleep(0.02)
        await asyncio.sleep(0.1)
        hb = rec.heartbeat()
        for n in (rec, pub):
            n.shutdown()
        await asyncio.gather(*tasks)
        return hb

    hb = asyncio.run(scenario())
    # 10 hostile frames sent: 3 with a bad seq (stored), 1 with a huge seq (stored), 6 malformed (stored raw)
    hostile = [hostile_inputs()[(i // 10) % 8] for i in range(100) if i % 10 == 5]
    n_raw = sum(1 for f, where in hostile if where == "raw" and f)
    n_stored = sum(1 for _f, where in hostile if where == "stored")
    info = bag_info(path)
    assert info.counts[T.FINGERTIP.name] == 100 + n_stored and sum(info.malformed.values()) == n_raw
    assert info.dropped.get(T.FINGERTIP.name, 0) == 0
    st = {s.topic: s for s in hb.subscriptions}[T.FINGERTIP.name]
    assert st.count == 100 + n_stored + n_raw and st.rejected == n_raw and st.dropped == 0
    assert hb.state == "warn" and f"{n_raw} malformed" in hb.message


def _stereo(i: int) -> StereoFrame:
    img = np.full((48, 64), i % 255, np.uint8)
    img[::7, ::5] = (i * 7) % 251   # not all one value: chunks hold a few messages each
    return StereoFrame(header=Header(stamp=100.0 + i / 48, frame_id="camera_left", seq=i), left=img,
                       right=img,
                       exposure_stamp=100.0 + i / 48, exposure_time=0.004)


def _log_time(i: int) -> int:
    return T0 + i * 20_000_000


def _write_stereo(path, n: int = 400, close: bool = True) -> BagWriter:
    w = BagWriter(path, chunk_size=16384)
    for i in range(n):
        w.write(encode(T.STEREO.name, _stereo(i)), _log_time(i))
    if close:
        w.close()
    return w


def _chunks(path) -> list:
    with open(path, "rb") as fh:
        return sorted(make_reader(fh).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)


def _in_chunk(ci, n: int = 400) -> list[int]:
    """The messages with a record in chunk ``ci`` (a message's image parts and its JSON share its log
    time)."""
    return [i for i in range(n) if ci.message_start_time <= _log_time(i) <= ci.message_end_time]


def _whole(chunks: list, kept) -> list[int]:
    """The messages every record of which lies in the chunks ``kept`` (a predicate on a chunk index)."""
    inside = {i for c in chunks if kept(c) for i in _in_chunk(c)}
    return sorted(inside - {i for c in chunks if not kept(c) for i in _in_chunk(c)})


def _flexsheet(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flexsheet", *args], capture_output=True, text=True,
                          timeout=timeout,
                          cwd=ROOT)


def test_flipped_bytes_in_one_chunk_lose_that_chunk_only_and_bag_info_says_so(tmp_path):
    path, bad = tmp_path / "ok.mcap", tmp_path / "flipped.mcap"
    _write_stereo(path)
    chunks = _chunks(path)
    assert len(chunks) >= 8
    ci = chunks[len(chunks) // 2]
    lost = _in_chunk(ci)
    assert lost
    data = bytearray(path.read_bytes())
    mid = ci.chunk_start_offset + ci.chunk_length // 2
    data[mid:mid + 8] = bytes(b ^ 0xFF for b in data[mid:mid + 8])   # 8 flipped bytes
    bad.write_bytes(bytes(data))

    s = BagSummary()
    seqs = [decode(m.frames, T.STEREO).header.seq for m in read_bag(bad, summary=s)]
    assert seqs == [i for i in range(400) if i not in lost]           # every other chunk's messages, in order
    assert len(s.damaged) == 1 and s.damaged[0].counts == {T.STEREO.name: len(lost)} and not s.truncated
    assert s.damaged[0].offset == ci.chunk_start_offset
    info = bag_info(bad)
    assert info.counts[T.STEREO.name] == 400 - len(lost) and info.lost == len(lost)

    out = _flexsheet("bag", "info", str(bad))
    assert out.returncode == 1, out
    line = next(x for x in out.stdout.splitlines() if x.startswith("damaged:"))
    assert f"{len(lost)} messages lost" in line and "1 unreadable part" in line
    assert f"{T.STEREO.name} {len(lost)}" in out.stdout
    assert _flexsheet("bag", "info", str(path)).returncode == 0
    out = _flexsheet("bag", "info", str(bad), "--json")  # --json: the same facts, the same status
    assert out.stdout.startswith("{"), (out.stdout[-500:], out.stderr[-1500:])
    j = json.loads(out.stdout)
    assert out.returncode == 1 and j["topics"][T.STEREO.name]["count"] == 400 - len(lost)
    assert len(j["damaged"]) == 1 and j["damaged"][0]["offset"] == ci.chunk_start_offset and not j[
        "truncated"]
    assert (
        json.loads(_flexsheet("bag", "info", str(path), "--json").stdout)["topics"][T.STEREO.name]["count"]
            == 400)


def test_a_damaged_chunk_length_in_a_cut_bag_skips_to_the_next_chunk(tmp_path):
    """No summary to lean on (the bag was cut): the reader finds the next chunk header by itself."""
    path = tmp_path / "ok.mcap"
    _write_stereo(path)
    chunks = _chunks(path)
    ci = chunks[3]
    data = bytearray(path.read_bytes()[:chunks[-2].chunk_start_offset])   # cut: no footer, no summary
    data[ci.chunk_start_offset + 5] ^= 0x10                            # the chunk's record length
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    s = BagSummary()
    seqs = [decode(m.frames, T.STEREO).header.seq for m in read_bag(bad, summary=s)]
    assert (seqs
            == _whole(chunks, lambda c: c.chunk_start_offset < chunks[-2].chunk_start_offset and c is not ci))
    assert len(s.damaged) == 1 and s.truncated


@pytest.mark.parametrize("share", [0.0, 0.31, 0.5, 0.77, 1.0])
def test_a_bag_cut_by_kill_9_is_recovered_for_the_stock_mcap_reader(tmp_path, share):
    path = tmp_path / "live.mcap"
    w = _write_stereo(path, close=False)
    t0 = time.monotonic()
    while sum(w.counts.values()) < 400 and time.monotonic() - t0 < 30:
        time.sleep(0.01)
    killed = path.read_bytes()        # what kill -9 leaves: the completed chunks, no summary, no footer
    w.close()
    chunks = _chunks(path)
    cut = tmp_path / "cut.mcap"
    size = len(killed) if share == 1.0 else max(8, int(len(killed) * share))
    cut.write_bytes(killed[:size])
    with open(cut, "rb") as fh, pytest.raises(Exception):  # noqa: B017 - the stock reader fails, whatever it raises
        list(make_reader(fh).iter_messages())

    fixed = tmp_path / "fixed.mcap"
    kept = recover_bag(cut, fixed)
    expected = _whole(chunks, lambda c: c.chunk_start_offset + c.chunk_length <= size)
    assert sum(kept.values()) == len(expected)
    with open(fixed, "rb") as fh:
        reader = make_reader(fh)
        records = list(reader.iter_messages())               # the stock reader reads the whole recovered file
        assert reader.get_summary().statistics.message_count == len(records)
    seqs = [decode(m.frames, T.STEREO).header.seq for m in read_bag(fixed)]
    assert seqs == expected
    if share == 0.5:
        out = _flexsheet("bag", "recover", str(cut), str(tmp_path / "cli.mcap"))
        assert out.returncode == 0 and f"kept {T.STEREO.name}: {len(expected)}" in out.stdout
        assert "TRUNCATED" in out.stdout
        assert _flexsheet("bag", "info", str(tmp_path / "cli.mcap")).returncode == 0
        out = _flexsheet("bag", "recover", str(cut), str(tmp_path / "cli2.mcap"), "--json")   # the same facts
        j = json.loads(out.stdout)
        assert out.returncode == 0 and j["kept"] == {T.STEREO.name: len(expected)} and j["truncated"]
        assert j["output"] == str(tmp_path / "cli2.mcap") and j["cut_bytes"] > 0


def test_bag_play_refuses_a_bad_file_in_one_line(tmp_path):
    text = tmp_path / "notes.txt"
    text.write_text("not a bag\n" * 100)
    for f in (text, tmp_path / "missing.mcap"):
        t0 = time.monotonic()
        out = _flexsheet("bag", "play", str(f), "--endpoint", f"tcp://127.0.0.1:{free_port()}", timeout=30)
        assert out.returncode == 2, out
        assert out.stdout == "" and len(out.stderr.strip().splitlines()) == 1, out.stderr
        assert "Traceback" not in out.stderr and str(f) in out.stderr
        assert time.monotonic() - t0 < 30
    out = _flexsheet("bag", "info", str(text))
    assert out.returncode == 2 and "not an MCAP file" in out.stderr


def test_bag_info_reads_an_export_and_other_tools_bags(tmp_path):
    src, dst = tmp_path / "raw.mcap", tmp_path / "json.mcap"
    w = BagWriter(src)
    for i in range(30):
        w.write(encode(T.FINGERTIP.name, tip(i)), T0 + i * 25_000_000)
        w.write(encode(T.STEREO.name, _stereo(i)), T0 + i * 25_000_000 + 1000)
    w.close()
    counts = export_bag(src, dst, foxglove=False, workers=0)
    info = bag_info(dst)
    assert dict(info.counts) == dict(counts) == {"/fingertip": 30, "/camera/stereo/left": 30,
                                                 "/camera/stereo/right": 30}
    assert info.start == T0 / 1e9 and info.end == (T0 + 29 * 25_000_000 + 1000) / 1e9
    assert (info.encodings["/fingertip"] == "json"
            and info.schemas["/camera/stereo/left"] == "foxglove.CompressedImage")
    out = _flexsheet("bag", "info", str(dst))
    assert out.returncode == 0 and "messages:  90" in out.stdout and "1970" not in out.stdout
    out = _flexsheet("bag", "export", str(src), str(tmp_path / "cli.mcap"), "--no-foxglove", "--json")
    j = json.loads(out.stdout)                          # one document on stdout; progress stays on stderr
    assert (out.returncode == 0 and j["counts"] == dict(sorted(counts.items()))
            and j["damaged"] == []), out.stderr

    # another tool's bag: ROS 2 cdr and protobuf channels, no flexsheet metadata
    other = tmp_path / "other.mcap"
    with open(other, "wb") as fh:
        ow = Writer(fh)
        ow.start(profile="ros2", library="another tool")
        sid = ow.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        a = ow.register_channel("/chatter", "cdr", sid)
        b = ow.register_channel("/pose", "protobuf", ow.register_schema("foxglove.Pose", "protobuf", b"\x00"))
        for i in range(12):
            ow.add_message(a, log_time=5_000_000_000 + i * 10**8, data=b"\x00\x01\x00\x00hi", publish_time=0)
        for i in range(5):
            ow.add_message(b, log_time=5_050_000_000 + i * 10**8, data=b"\x08\x01", publish_time=0)
        ow.finish()
    info = bag_info(other)
    assert dict(info.counts) == {"/chatter": 12, "/pose": 5}
    assert (info.start, info.end) == (5.0, 6.1) and info.encodings["/chatter"] == "cdr"
    assert list(read_bag(other)) == []     # nothing to replay: not flexsheet channels


def test_a_respawned_recorder_writes_the_time_it_was_down_per_topic(tmp_path):
    path = tmp_path / "sim.mcap"
    first = BagWriter(path, chunk_size=4096)
    now = time.time_ns()
    for i in range(200):
        first.write(encode(T.FINGERTIP.name, tip(i)), now - 3_000_000_000 + i * 5_000_000)
        if i % 4 == 0:
            first.write(encode(T.STEREO.name, _stereo(i)), now - 3_000_000_000 + i * 5_000_000 + 1)
    t0 = time.monotonic()
    while sum(first.counts.values()) < 250 and time.monotonic() - t0 < 30:
        time.sleep(0.01)
    killed = path.read_bytes()       # the first recorder is killed here: its bag has no footer
    last = {m.topic: int(round(m.log_time * 1e9)) for m in read_bag(path)}
    second = BagWriter(path, chunk_size=4096)
    assert second.path.name == "sim.1.mcap" and second.previous == path
    for i in range(50):
        second.write(encode(T.FINGERTIP.name, tip(300 + i)), now + i * 5_000_000)
    second.close()
    first.close()
    path.write_bytes(killed)
    info = bag_info(second.path)
    gaps = {g["topic"]: g for g in info.gaps}
    assert set(gaps) == {"", T.FINGERTIP.name, T.STEREO.name}
    g = gaps[T.FINGERTIP.name]
    assert g["previous"] == "sim.mcap" and g["last_before"] == last[T.FINGERTIP.name] / 1e9
    assert (g["first_after"] == now / 1e9
            and g["lost_s"] == pytest.approx((now - last[T.FINGERTIP.name]) / 1e9))
    assert gaps[T.STEREO.name]["first_after"] is None                 # not recorded again since
    assert gaps[""]["last_before"] == max(last.values()) / 1e9
    assert info.counts == {T.FINGERTIP.name: 50} and GAP_TOPIC not in info.counts
    out = _flexsheet("bag", "info", str(second.path))
    assert "gap:       recorder restarted after sim.mcap" in out.stdout
