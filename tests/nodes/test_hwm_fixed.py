"""No high-water mark is ever changed on a bound or connected socket (the trigger of zeromq/libzmq#4524's
I/O-thread crash): every socket option call is watched while a node publishes messages far larger than it
declares, and subscribers connect and leave."""

from __future__ import annotations

import asyncio
import time

import numpy as np
import zmq

from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.node import Node
from flexsheet.runtime.ports import free_port
from flexsheet.runtime.zmq.xpub import MIN_SNDHWM, PUB_QUEUE_BYTES, send_hwm
from messages import StereoFrame
from messages import topics as T

HWM = {zmq.SNDHWM, zmq.RCVHWM}


class _Watch:
    """Wraps ``zmq.Socket`` ``bind``/``connect``/``close``/``set``: records each HWM change made on a live
    socket."""

    def __init__(self, monkeypatch) -> None:
        self.live: set[int] = set()
        self.changes: list[tuple[str, int]] = []
        self.hwm_sets = 0
        for name in ("bind", "connect", "bind_to_random_port"):
            orig = getattr(zmq.Socket, name)
            monkeypatch.setattr(zmq.Socket, name, self._live(orig))
        orig_close = zmq.Socket.close

        def close(sock, *a, **k):                       # an id is reused once its socket is gone
            self.live.discard(id(sock))
            return orig_close(sock, *a, **k)

        monkeypatch.setattr(zmq.Socket, "close", close)
        orig_set = zmq.Socket.set

        def set_(sock, option, value):
            if option in HWM:
                self.hwm_sets += 1
                if id(sock) in self.live:
                    self.changes.append((zmq.SocketOption(option).name, value))
            return orig_set(sock, option, value)

        monkeypatch.setattr(zmq.Socket, "set", set_)
        monkeypatch.setattr(zmq.Socket, "setsockopt", set_)

    def _live(self, orig):
        def wrapped(sock, *a, **k):
            out = orig(sock, *a, **k)
            self.live.add(id(sock))
            return out
        return wrapped


class _Cam(Node):
    """Publishes a 0.66 MB stereo pair every 10 ms while declaring only the default small message."""

    async def setup(self) -> None:
        self.pub = self.publisher(T.STEREO)
        self.img = np.zeros((512, 640), np.uint8)
        self.timer(0.01, self.tick)

    def tick(self) -> None:
        self.pub.publish(StereoFrame(header=self.pub.header("camera_left"), left=self.img, right=self.img,
                                     exposure_stamp=time.time(), exposure_time=0.005))


def test_no_hwm_changes_on_a_live_socket_while_big_messages_flow_and_subscribers_leave(monkeypatch):
    watch = _Watch(monkeypatch)
    ep = f"tcp://127.0.0.1:{free_port()}"

    async def run() -> tuple[int, int]:
        node = _Cam(NodeConfig(name="cam", endpoint=ep, peers=[]))
        task = asyncio.get_running_loop().create_task(node.run(install_signals=False))
        while not node.ready:
            await asyncio.sleep(0.01)
        ctx = zmq.Context()
        got = 0
        for _ in range(6):                              # subscribers connect, read a little and leave
            sub = ctx.socket(zmq.SUB)
            sub.setsockopt(zmq.RCVHWM, 2)               # before connect: allowed
            sub.connect(ep)
            sub.setsockopt(zmq.SUBSCRIBE, b"/camera")
            end = time.monotonic() + 0.3
            while time.monotonic() < end:
                if await asyncio.to_thread(sub.poll, 20):
                    sub.recv_multipart()
                    got += 1
            sub.close(linger=0)
        ctx.term()
        oversize = node.transport.xpub.oversize
        node.shutdown()
        await task
        return got, oversize

    got, oversize = asyncio.run(run())
    assert got > 10, got                                  # big messages really flowed
    assert oversize > 10, oversize                        # ... bigger than the node declared
    assert watch.hwm_sets >= 2                            # the watch saw the HWMs set (before bind/connect)
    assert watch.changes == [], watch.changes


def test_the_send_hwm_bounds_a_subscriber_queue_by_bytes():
    assert send_hwm(2000, 16 << 10) == 2000                             # small messages keep the QoS HWM
    assert send_hwm(2000, 2 * 640 * 512) == PUB_QUEUE_BYTES // (2 * 640 * 512) == 51
    assert send_hwm(2000, 64 << 20) == MIN_SNDHWM                       # never below the floor
    for bad in (0, -5, 1.5, None):
        try:
            send_hwm(2000, bad)
        except ValueError as exc:
            assert "largest_bytes must be an int >= 1" in str(exc) and repr(bad) in str(exc)
        else:
            raise AssertionError(f"send_hwm accepted largest_bytes={bad!r}")
