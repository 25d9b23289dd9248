"""Load, the short version: a LATEST subscriber slower than its publisher keeps one
message, whatever the publisher sends, so its memory stays flat. ``flexsheet bench load`` runs the full
graph's topics at 2× for 60 s and reports the slopes and the p99 (docs/reliability.md)."""

from __future__ import annotations

import asyncio
import os
import time

import numpy as np
import pytest

from flexsheet.benches.load import payload_fields, rss_mb, slope_mb_per_min
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.node import Node
from flexsheet.runtime.ports import free_port
from flexsheet.runtime.qos import QoS
from messages import topics as T

RATE = 2 * T.STEREO.nominal_hz          # 96 Hz of 655 kB stereo frames: 63 MB/s
SECONDS = 8.0
HANDLER_S = 0.05                        # the subscriber needs 50 ms per frame: 5× slower than the publisher


class StereoPublisher(Node):
    async def setup(self) -> None:
        self.pub = self.publisher(T.STEREO)
        self.fields = payload_fields(T.STEREO.name)
        self.timer(1.0 / RATE, self.send)

    def send(self) -> None:
        self.pub.publish(T.STEREO.type(header=self.pub.header("camera_left"), **self.fields))


class SlowLatest(Node):
    async def setup(self) -> None:
        self.sub = self.subscribe(T.STEREO, self.on_frame, qos=QoS.LATEST)
        self.handled = 0
        self.max_depth = 0
        self.timer(0.005, self.watch)

    def watch(self) -> None:
        self.max_depth = max(self.max_depth, len(self.sub.queue))

    def on_frame(self, msg) -> None:
        assert msg.left.shape == (512, 640)
        time.sleep(HANDLER_S)
        self.handled += 1


def test_a_slow_latest_subscriber_keeps_one_frame_and_flat_memory():
    ep = f"tcp://127.0.0.1:{free_port()}"
    pub = StereoPublisher(NodeConfig(name="pub", endpoint=ep))
    sub = SlowLatest(NodeConfig(name="sub", endpoint="", peers=[ep]))
    rss: list[tuple[float, float]] = []

    async def scenario() -> None:
        tasks = [asyncio.create_task(n.run(install_signals=False)) for n in (sub, pub)]
        t0 = time.monotonic()
        while (t := time.monotonic() - t0) < SECONDS:
            await asyncio.sleep(0.25)
            rss.append((t, rss_mb(os.getpid())))
        pub.shutdown()
        sub.shutdown()
        await asyncio.gather(*tasks)

    asyncio.run(scenario())
    sent, got = pub.pub.stats.count, sub.sub.stats.count
    # the publisher really outran the subscriber several times over …
    assert sent > 0.6 * RATE * SECONDS and sub.handled < sent / 2.5, (sent, sub.handled)
    # … the subscription kept at most one waiting frame, dropping (and counting) the stale ones …
    assert sub.max_depth <= 1
    # (every frame sent was handled or dropped as stale; only those in flight at the stop are neither)
    assert (sub.sub.stats.dropped > sent / 3
            and 0 <= sent - sub.sub.stats.dropped - sub.handled <= 0.02 * sent + 2), (
        sent, sub.sub.stats.dropped, sub.handled)
    assert 0 <= got - sub.handled <= 1   # the last one may be decoded when the run stops
    # … so the process did not keep the ~500 MB it was sent: RSS flat after the first seconds
    a = np.array(rss)
    late = a[a[:, 0] >= 2.0]
    grown = late[-1, 1] - late[0, 1]
    sent_mb = sent * 2 * 512 * 640 / 1e6
    assert grown < 30.0, (grown, sent_mb)
    assert abs(slope_mb_per_min(late[:, 0], late[:, 1])) < 0.05 * sent_mb / SECONDS * 60, late


def test_slope_fit_and_rss_reader():
    t = np.arange(0.0, 30.0, 0.5)
    assert slope_mb_per_min(t, 100 + 0.5 * t) == pytest.approx(30.0)
    assert slope_mb_per_min(t, np.full_like(t, 80.0)) == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match="RSS samples"):
        slope_mb_per_min(t[:2], t[:2])
    assert 1.0 < rss_mb(os.getpid()) < 10_000.0
    assert rss_mb(2**22 + 12345) is None


def test_load_payloads_have_the_real_sizes():
    from flexsheet.runtime.codec import encode
    from messages import Header

    sizes = {}
    for t in T.ALL:
        msg = t.type(header=Header(stamp=1.0, frame_id="display", seq=0), **payload_fields(t.name))
        sizes[t.name] = sum(memoryview(f).nbytes for f in encode(t.name, msg))
    assert sizes[T.STEREO.name] > 2 * 512 * 640 and sizes[T.RENDERED.name] > 2 * 768 * 1024 * 3
    assert sizes[T.FINGERTIP.name] < 2000
