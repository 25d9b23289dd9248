"""Dispatch of async handlers: called straight from the end of a drain (no task, no event), in order, never
re-entered for one subscription while a call awaits, QoS and counters kept, close cancels a suspended call."""

from __future__ import annotations

import asyncio
import time

import numpy as np

from flexsheet.runtime.codec import encode
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.node import Node
from flexsheet.runtime.qos import QoS
from flexsheet.runtime.testing import NodeHarness
from flexsheet.runtime.zmq.transport import ZmqTransport
from messages import Fingertip, Header, Topic
from messages import topics as T


def tip(seq: int, x: float = 0.0) -> Fingertip:
    p = np.array([x, 0.0, 0.0])
    return Fingertip(header=Header(stamp=1.0, seq=seq), position=p, covariance=np.eye(3), valid=True,
                     predicted_position=p, exposure_stamp=1.0)


def frames(seq: int, x: float = 0.0) -> list:
    return encode(T.FINGERTIP.name, tip(seq, x))


class Recorder(Node):
    """Test node: one async handler on /fingertip (QoS and depth from class attributes) that records the seqs,
    how many calls overlap, the task it ran in and, when ``gate`` is set, waits on it (a handler that
    awaits)."""

    qos = QoS.KEEP_ALL
    depth: int | None = None

    async def setup(self) -> None:
        self.seen: list[int] = []
        self.tasks: list[asyncio.Task | None] = []
        self.active = self.max_active = 0
        self.gate: asyncio.Event | None = None
        self.pause_s = 0.0
        self.cancelled = 0
        self.sub = self.subscribe(T.FINGERTIP, self.on_tip, qos=self.qos, depth=self.depth)

    async def on_tip(self, msg: Fingertip) -> None:
        self.active += 1
        self.max_active = max(self.max_active, self.active)
        self.tasks.append(asyncio.current_task())
        try:
            if msg.position[0] > 1.0:
                raise ValueError(f"position.x out of workspace: {msg.position[0]}")
            if self.gate is not None:
                await self.gate.wait()
            if self.pause_s:
                await asyncio.sleep(self.pause_s)
            self.seen.append(msg.header.seq)
        except asyncio.CancelledError:
            self.cancelled += 1
            raise
        finally:
            self.active -= 1


async def batch(node: Node, *items: list) -> list[int]:
    """Hand ``items`` to ``node`` as one drain of its transport, run as a loop callback (as a ready socket's
    is); returns the seqs handled when the drain returned."""
    loop = asyncio.get_running_loop()
    done = loop.create_future()

    def drain() -> None:
        for f in items:
            node._dispatch.frames(f)
        node._dispatch.drained()
        done.set_result(list(node.seen))

    loop.call_soon(drain)
    return await done


def test_a_drain_calls_the_handler_before_it_returns_without_a_task():
    async def scenario():
        async with NodeHarness(Recorder) as h:
            node = h.node
            tasks_before = len(asyncio.all_tasks())
            for i in range(50):
                assert await batch(node, frames(i)) == list(range(i + 1)), "handled when the drain ends"
            return node, tasks_before, len(asyncio.all_tasks())
    node, before, after = asyncio.run(scenario())
    assert node.tasks == [None] * 50                 # called straight from the drain: no task per message
    assert after == before
    assert node.sub.stats.count == 50 and node.sub.stats.dropped == 0 and node.sub.cpu_s > 0.0


def test_latest_keeps_the_newest_of_one_drain_and_counts_the_rest():
    class Latest(Recorder):
        qos = QoS.LATEST

    async def scenario():
        async with NodeHarness(Latest) as h:
            await batch(h.node, *(frames(i) for i in range(5)))
            return h.node
    node = asyncio.run(scenario())
    assert node.seen == [4]
    assert node.sub.stats.count == 1 and node.sub.stats.dropped == 4


def test_an_awaiting_handler_is_never_reentered_and_keeps_the_order():
    async def scenario():
        async with NodeHarness(Recorder) as h:
            node = h.node
            node.pause_s = 0.002
            for i in range(40):
                await batch(node, frames(i))          # each arrives while the previous call still sleeps
                if i % 3 == 0:
                    await asyncio.sleep(0)
            for _ in range(400):
                if len(node.seen) == 40:
                    break
                await asyncio.sleep(0.005)
            return node
    node = asyncio.run(scenario())
    assert node.seen == list(range(40))
    assert node.max_active == 1
    assert node.sub.stats.count == 40 and node.sub.stats.dropped == 0
    assert node.tasks[0] is None and any(t is not None for t in node.tasks[1:])  # the rest ran in a task


def test_a_full_queue_drops_and_counts_its_oldest_while_the_handler_waits():
    class Deep3(Recorder):
        depth = 3

    async def scenario():
        async with NodeHarness(Deep3) as h:
            node = h.node
            node.gate = asyncio.Event()
            await batch(node, frames(0))            # the call awaits the gate
            assert node.active == 1 and node.seen == []
            for i in range(1, 11):
                await batch(node, frames(i))        # queued behind it: depth 3
            assert node.max_active == 1 and len(node.sub.queue) == 3
            node.gate.set()
            for _ in range(200):
                if len(node.seen) == 4:
                    break
                await asyncio.sleep(0.005)
            return node
    node = asyncio.run(scenario())
    assert node.seen == [0, 8, 9, 10]
    assert node.sub.stats.dropped == 7 and node.sub.stats.count == 4
    assert node.max_active == 1


OTHER = Topic("/tip2", Fingertip)


def test_other_subscriptions_go_on_while_one_handler_awaits():
    class Two(Recorder):
        async def setup(self) -> None:
            await super().setup()
            self.other: list[int] = []
            self.subscribe(OTHER, self.on_other, qos=QoS.KEEP_ALL)

        async def on_other(self, msg: Fingertip) -> None:
            self.other.append(msg.header.seq)

    async def scenario():
        async with NodeHarness(Two) as h:
            node = h.node
            node.gate = asyncio.Event()
            await batch(node, frames(0), *(encode(OTHER.name, tip(i)) for i in range(5)))
            other = list(node.other)
            node.gate.set()
            await asyncio.sleep(0.05)
            return node, other
    node, other = asyncio.run(scenario())
    assert other == [0, 1, 2, 3, 4]      # handled in the same drain, while /fingertip's call waited
    assert node.seen == [0]


def test_rejections_before_and_after_an_await_are_counted():
    async def scenario():
        async with NodeHarness(Recorder) as h:
            node = h.node
            await batch(node, frames(0, x=2.0))                        # raises before any await
            await batch(node, [T.FINGERTIP.name.encode(), b"garbage"])  # undecodable
            node.pause_s = 0.001
            await batch(node, frames(1))
            await asyncio.sleep(0.05)
            return node
    node = asyncio.run(scenario())
    assert node.sub.stats.rejected == 2 and node.rejected_total == 2
    assert node.seen == [1] and node.sub.stats.count == 2


def test_close_cancels_a_suspended_call_and_nothing_runs_after():
    async def scenario():
        async with NodeHarness(Recorder) as h:
            node = h.node
            node.gate = asyncio.Event()
            await batch(node, frames(0))
            await batch(node, frames(1))
            sub = node.sub
            assert not sub.task.done()
            sub.close()
            await asyncio.sleep(0.01)
            await batch(node, frames(2))
            await asyncio.sleep(0.01)
            return node, sub
    node, sub = asyncio.run(scenario())
    assert node.cancelled == 1 and node.seen == [] and sub.task.done()
    assert node.tasks.count(None) == 1 and len(node.tasks) == 1   # 1 and 2 never called


def test_cpu_time_counts_the_handlers_own_steps_only():
    class Burn(Recorder):
        async def on_tip(self, msg: Fingertip) -> None:
            _burn(0.02)
            await asyncio.sleep(0.03)
            _burn(0.02)
            self.seen.append(msg.header.seq)

    async def scenario():
        async with NodeHarness(Burn) as h:
            await batch(h.node, frames(0))
            await asyncio.sleep(0.005)
            _burn(0.1)                 # another coroutine's CPU while the handler sleeps: not the handler's
            for _ in range(100):
                if h.node.seen:
                    break
                await asyncio.sleep(0.005)
            return h.node
    node = asyncio.run(scenario())
    assert node.seen == [0]
    assert 0.035 <= node.sub.cpu_s < 0.09, node.sub.cpu_s


def _burn(seconds: float) -> None:
    t0 = time.thread_time()
    while time.thread_time() - t0 < seconds:
        pass


def test_over_zeromq_every_message_is_handled_in_order_from_the_drain():
    """A node subscribed to its own publisher (ZeroMQ over loopback TCP): 300 fingertips, KEEP_ALL, every one
    handled in order, none in a task."""
    class Loop(Recorder):
        async def setup(self) -> None:
            await super().setup()
            self.pub = self.publisher(T.FINGERTIP)

    async def scenario():
        from flexsheet.runtime.ports import free_port
        ep = f"tcp://127.0.0.1:{free_port()}"
        node = Loop(NodeConfig(name="loop", endpoint=ep, peers=[ep], heartbeat_period=10.0))
        task = asyncio.get_running_loop().create_task(node.run(install_signals=False))
        while not node.ready:
            await asyncio.sleep(0.01)
        assert isinstance(node.transport, ZmqTransport)
        for _ in range(200):    # the SUB's subscription reaches the XPUB
            if node.transport.wants(T.FINGERTIP.name.encode()):
                break
            await asyncio.sleep(0.01)
        for i in range(300):
            node.pub.publish(tip(i))
            if i % 10 == 9:
                await asyncio.sleep(0.001)
        for _ in range(400):
            if len(node.seen) >= 300:
                break
            await asyncio.sleep(0.005)
        node.shutdown()
        await task
        return node
    node = asyncio.run(scenario())
    assert node.seen == list(range(300))
    assert node.tasks == [None] * 300 and node.max_active == 1
    assert node.sub.stats.count == 300 and node.sub.stats.dropped == 0


def test_close_right_after_a_call_suspends_still_cancels_it():
    """The close comes before the task that would finish the call first runs: the call is cancelled all the
    same (its ``except CancelledError`` and ``finally`` run), once."""
    async def scenario():
        async with NodeHarness(Recorder) as h:
            node = h.node
            node.gate = asyncio.Event()
            loop = asyncio.get_running_loop()
            done = loop.create_future()

            def drain_and_close() -> None:
                node._dispatch.frames(frames(0))
                node._dispatch.drained()
                node.sub.close()
                done.set_result(node.active)

            loop.call_soon(drain_and_close)
            active_after_close = await done
            await asyncio.sleep(0.01)
            return node, active_after_close
    node, active_after_close = asyncio.run(scenario())
    assert node.cancelled == 1 and active_after_close == 0 and node.active == 0 and node.seen == []
