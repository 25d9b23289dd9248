"""Attacks on the recorder and on bags (:mod:`flexsheet.runtime.bag_write`,
:mod:`~flexsheet.runtime.bag_read`, :mod:`~flexsheet.runtime.bag_recover`): malformed frames between good
ones, flipped bytes in one chunk, a file cut as ``kill -9`` leaves it."""

from __future__ import annotations

from pathlib import Path

import msgpack
import numpy as np
from mcap.reader import make_reader

from flexsheet.runtime.bag_read import BagSummary, bag_info, read_bag
from flexsheet.runtime.bag_recover import recover_bag
from flexsheet.runtime.bag_write import BagWriter
from flexsheet.runtime.codec import encode
from messages import Fingertip, Header, StereoFrame
from messages import topics as T

__all__ = ["recorder_malformed", "bag_flip", "bag_cut_recover", "fingertip", "with_seq", "T0"]

T0 = 1_700_000_000_000_000_000   # ns


def fingertip(seq: int) -> Fingertip:
    """A valid fingertip with ``header.seq`` = ``seq``, stamped 1/40 s apart from :data:`T0`."""
    p = np.array([0.01, -0.02, 0.03])
    return Fingertip(header=Header(stamp=T0 / 1e9 + seq / 40, seq=seq), position=p,
                     covariance=np.eye(3) * 1e-8,
                     valid=True, predicted_position=p, exposure_stamp=T0 / 1e9 + seq / 40)


def with_seq(frames: list, seq) -> list:
    """The frames of a real message whose ``header.seq`` is replaced by ``seq`` (any msgpack value)."""
    meta = msgpack.unpackb(frames[1], raw=False, ext_hook=msgpack.ExtType)
    meta["d"]["header"]["seq"] = seq
    return [frames[0], msgpack.packb(meta), *frames[2:]]


def recorder_malformed(tmp: Path, n: int = 200) -> dict:
    """``n`` good fingertips with a hostile frame after every 20th (1-frame, undecodable, not an envelope,
    empty, seq "x" / 1.5 / None / 2⁶⁴−1): every frame must be in the bag (``lost`` 0)."""
    good = encode(T.FINGERTIP.name, fingertip(0))
    hostile = [[b"/fingertip"], [b"/fingertip", b"\xc1\xc1 not msgpack"],
               [b"/fingertip", msgpack.packb([1, 2])],
               [], with_seq(good, "x"), with_seq(good, 1.5), with_seq(good, None), with_seq(good, 2**64 - 1)]
    path = tmp / "hostile.mcap"
    w = BagWriter(path, chunk_size=4096)
    fed = 0
    for i in range(n):
        w.write(encode(T.FINGERTIP.name, fingertip(i)), T0 + i * 25_000_000)
        fed += 1
        if i % 20 == 10:
            w.write(hostile[(i // 20) % len(hostile)], T0 + i * 25_000_000 + 1)
            fed += 1
    w.close()
    info = bag_info(path)
    kept = sum(info.counts.values()) + sum(info.malformed.values())
    return {"fed": fed, "in_bag": kept, "lost": fed - kept,
            "malformed_stored_raw": sum(info.malformed.values()),
            "dropped_reported": sum(info.dropped.values())}


def _stereo_bag(path: Path, n: int) -> None:
    w = BagWriter(path, chunk_size=16384)
    for i in range(n):
        img = np.full((48, 64), i % 255, np.uint8)
        img[::7, ::5] = (i * 7) % 251
        w.write(encode(T.STEREO.name,
                       StereoFrame(header=Header(stamp=100.0 + i / 48, seq=i), left=img, right=img,
                                   exposure_stamp=100.0 + i / 48, exposure_time=0.004)),
                T0 + i * 20_000_000)
    w.close()


def _chunks(path: Path) -> list:
    with open(path, "rb") as fh:
        return sorted(make_reader(fh).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)


def bag_flip(tmp: Path, n: int = 400) -> dict:
    """8 flipped bytes in the middle chunk: reported damaged, only that chunk's messages lost."""
    path, bad = tmp / "ok.mcap", tmp / "flipped.mcap"
    _stereo_bag(path, n)
    ci = _chunks(path)[len(_chunks(path)) // 2]
    in_chunk = sum(1 for i in range(n) if ci.message_start_time <= T0 + i * 20_000_000 <= ci.message_end_time)
    # (a message with any record in the damaged chunk is lost: its records share its log time)
    data = bytearray(path.read_bytes())
    mid = ci.chunk_start_offset + ci.chunk_length // 2
    data[mid:mid + 8] = bytes(b ^ 0xFF for b in data[mid:mid + 8])
    bad.write_bytes(bytes(data))
    s = BagSummary()
    read = sum(1 for _ in read_bag(bad, summary=s))
    return {"messages": n, "read": read, "chunk_messages": in_chunk, "reported_damaged": bool(s.damaged),
            "lost_beyond_the_damaged_chunk": n - in_chunk - read}


def bag_cut_recover(tmp: Path, n: int = 400, share: float = 0.5) -> dict:
    """The bag cut at ``share`` of its length (no summary, no footer): the stock reader fails on it; the
    recovered file opens with the stock reader and holds every message whose records (its image parts and its
    JSON, at one log time) all lie in the complete chunks."""
    path = tmp / "whole.mcap"
    _stereo_bag(path, n)
    size = int(path.stat().st_size * share)
    chunks = _chunks(path)

    def msgs(c) -> set[int]:
        return {i for i in range(n) if c.message_start_time <= T0 + i * 20_000_000 <= c.message_end_time}

    whole = set().union(*(msgs(c) for c in chunks if c.chunk_start_offset + c.chunk_length <= size))
    expected = len(whole
                   - set().union(*(msgs(c) for c in chunks if c.chunk_start_offset + c.chunk_length > size)))
    cut, fixed = tmp / "cut.mcap", tmp / "fixed.mcap"
    cut.write_bytes(path.read_bytes()[:size])
    try:
        with open(cut, "rb") as fh:
            list(make_reader(fh).iter_messages())
        stock_reads_cut = True
    except Exception:  # noqa: BLE001 - whatever the stock reader raises
        stock_reads_cut = False
    kept = sum(recover_bag(cut, fixed).values())
    try:
        with open(fixed, "rb") as fh:
            reader = make_reader(fh)
            stock = sum(1 for _ in reader.iter_messages())       # records: a stereo message is 3 of them
            stock_ok = stock == reader.get_summary().statistics.message_count >= kept > 0
    except Exception:  # noqa: BLE001
        stock_ok = False
    return {"complete_chunk_messages": expected, "recovered": kept, "stock_reader_opens_recovered": stock_ok,
            "stock_reader_opens_cut": stock_reads_cut}
