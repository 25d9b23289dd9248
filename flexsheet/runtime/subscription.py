"""One typed subscription of a node (:class:`Subscription`, made by
:meth:`flexsheet.runtime.node.Node.subscribe`): its queue and QoS, its consumer (a task on the loop for an
``async def`` handler, its own worker thread, :class:`SubscriptionWorker`, for a plain ``def``) and its
counters. See :mod:`flexsheet.runtime.node` for the threading model."""

from __future__ import annotations

import asyncio
import collections
import inspect
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

from flexsheet.runtime.codec import DecodeError, decode
from flexsheet.runtime.cpu_time import CpuCounter, timed
from flexsheet.runtime.publisher import TopicCounters
from flexsheet.runtime.qos import KEEP_ALL_DEPTH, QoS
from messages import Message, Topic
from messages import topics as T

__all__ = ["Subscription", "SubscriptionWorker", "Sampled"]

_thread_time = time.thread_time


class SubscriptionWorker(threading.Thread):
    """The worker thread of a sync handler's subscription, with the task-like ``done()`` and ``cancel()``."""

    def __init__(self, sub: Subscription) -> None:
        super().__init__(target=sub._work, name=f"sub{sub.topic.name}@{sub.node.name}", daemon=True)
        self.sub = sub

    def done(self) -> bool:
        return not self.is_alive()

    def cancel(self) -> None:
        self.sub.close()


class Sampled:
    """The consumer of a sampled subscription (:meth:`flexsheet.runtime.node.Node.sample`): none runs; the
    task-like ``done()`` and ``cancel()`` of the others."""

    def __init__(self, sub: Subscription) -> None:
        self.sub = sub

    def done(self) -> bool:
        return self.sub._closed

    def cancel(self) -> None:
        self.sub.close()


class Subscription:
    """One typed subscription of ``node`` (its :class:`~flexsheet.runtime.node.Node`): its queue, QoS,
    handler, consumer (task or worker thread) and statistics.

    Queue items are wire frames (decoded and validated by the consumer: the wire boundary) or, from a node of
    the same container, the message object itself (already validated when it was built).

    ``handler`` None: a sampled subscription (:meth:`flexsheet.runtime.node.Node.sample`): no consumer; the
    newest item is kept as it arrives and decoded only when :meth:`read` reads it.
    """

    def __init__(self, node: Any, topic: Topic, handler: Callable, qos: QoS, depth: int | None,
                 sim_cost: float = 0.0) -> None:
        self.node, self.topic, self.handler, self.qos = node, topic, handler, qos
        self.sim_cost = float(sim_cost)  # s charged per message on a live simulated clock
        self.newest: tuple | None = None  # live simulated clock: (due, order) of the newest queued item
        self.name_b = topic.name.encode()
        self.depth = depth or (1 if qos in (QoS.LATEST, QoS.LATCHED) else KEEP_ALL_DEPTH)
        self.queue: collections.deque = collections.deque()
        self.sampled = handler is None
        self.is_async = inspect.iscoroutinefunction(handler)
        self.event = asyncio.Event() if self.is_async else None
        self._wake: queue.SimpleQueue | None = None if self.is_async or self.sampled else queue.SimpleQueue()
        self._held: Any = None          # sampled: the newest item, and the one decoded last with its message
        self._held_read: Any = None
        self._held_msg: Message | None = None
        self._read_lock = threading.Lock()
        self._taken: Message | None = None     # sampled: the message take() applied last
        self._lock = threading.Lock()
        self._waiting = False
        self._closed = False
        self.stats = TopicCounters()
        self.cpu_s = 0.0  # CPU time of the sync handler (its worker thread), s
        self.last_seq: int | None = None
        self.last_meta: Any = None
        # the consumer, once started (both have done(), cancel())
        self.task: asyncio.Task | SubscriptionWorker | None = None

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """Start the consumer: a task on ``loop`` (async handler), the worker thread (sync handler), or none
        (sampled)."""
        if self.sampled:
            self.task = Sampled(self)
        elif self.is_async:
            self.task = loop.create_task(self.run())
        else:
            self.task = SubscriptionWorker(self)
            self.task.start()

    def _fresh_latched(self, item: Any) -> bool:
        if type(item) is list:
            key = b"\0".join(bytes(f) for f in item[1:])
            if key == self.last_meta:  # the same latched value resent for another late joiner
                return False
            self.last_meta = key
        else:
            if item is self.last_meta:
                return False
            self.last_meta = item
        return True

    def push(self, item: Any) -> None:
        """Queue frames or a message (any thread); QoS: a full queue drops its oldest item (counted)."""
        if self.qos is QoS.LATCHED and not self._fresh_latched(item):
            return
        sched = self.node._lockstep
        if sched is not None:
            sched.enqueue(self, item)
            return
        if self.sampled:
            self._hold(item)
            return
        if self.is_async:
            node = self.node
            if threading.get_ident() != node._loop_tid:
                node._loop.call_soon_threadsafe(self._push_async, item)
            else:
                self._push_async(item)
            return
        q = self.queue
        with self._lock:
            if len(q) >= self.depth:
                q.popleft()
                self.stats.dropped += 1
                q.append(item)
                return  # the dropped item's wake-up token serves this one
            q.append(item)
        self._wake.put(None)

    def _push_async(self, item: Any) -> None:
        q = self.queue
        if len(q) >= self.depth:
            q.popleft()
            self.stats.dropped += 1
        q.append(item)
        if self._waiting:
            self.event.set()

    async def run(self) -> None:
        """Consumer task of an async handler."""
        q = self.queue
        while True:
            if not q:
                self.event.clear()
                self._waiting = True
                try:
                    await self.event.wait()
                finally:
                    self._waiting = False
                continue
            msg = self._accept(q.popleft())
            if msg is not None:
                await self._call_async(msg)

    def _work(self) -> None:
        """Worker thread of a sync handler: one wake-up token per queued item."""
        get, q, lock = self._wake.get, self.queue, self._lock
        while True:
            get()
            if self._closed:
                return
            with lock:
                if not q:
                    continue
                item = q.popleft()
            msg = self._accept(item)
            if msg is not None:
                self._call_sync(msg)

    def _hold(self, item: Any) -> None:
        with self._lock:
            if self._held is not None and self._held is not self._held_read:
                self.stats.dropped += 1        # never read: superseded, as a latest-QoS queue drops it
            self._held = item

    def read(self) -> Message | None:
        """The newest message of a sampled subscription, decoded and validated now (once per message; any
        thread), or None before the first. A message that fails validation is counted as rejected (the node's
        ``rejected``, naming the topic) and the last good one is returned."""
        with self._read_lock:
            with self._lock:
                item = self._held
            if item is not None and item is not self._held_read:
                self._held_read = item
                msg = self._accept(item)
                if msg is not None:
                    self._held_msg = msg
            return self._held_msg

    def take(self, apply: Callable[[Message], Any]) -> bool:
        """Call ``apply(msg)`` with the newest message of a sampled subscription if it is new since the last
        take (:meth:`read`); a ``ValueError`` from it counts the message as rejected (:meth:`reject`). True if
        a new message was applied without error."""
        msg = self.read()
        if msg is None or msg is self._taken:
            return False
        self._taken = msg
        try:
            apply(msg)
        except ValueError as exc:
            self.reject(str(exc))
            return False
        return True

    def reject(self, reason: str) -> None:
        """Count a message of this topic as rejected input (a handler's ``ValueError``, or a sampled message
        its reader found unusable): the node's ``rejected``, its reason naming the topic."""
        self.stats.rejected += 1
        self.node._reject(f"{self.topic.name}: {reason}")

    async def handle_now(self, item: Any) -> None:
        """Handle one item to completion on the loop (lockstep replay: deterministic order, one at a time)."""
        if self.sampled:
            self._hold(item)
            return
        msg = self._accept(item)
        if msg is None:
            return
        if self.is_async:
            await self._call_async(msg)
        else:
            self._call_sync(msg)

    def _accept(self, item: Any) -> Message | None:
        """The message of a queue item (wire frames decoded and validated), counted; None if rejected."""
        if type(item) is list:
            try:
                msg = decode(item, self.topic)
            except DecodeError as exc:
                self.stats.rejected += 1
                self.node._reject(str(exc))
                return None
        else:
            msg = item
        seq = msg.header.seq
        last = self.last_seq
        if (last is not None and seq > last + 1 and self.qos is QoS.KEEP_ALL
                and self.topic.name != T.DIAGNOSTICS.name):  # every node publishes /diagnostics
            self.stats.dropped += seq - last - 1  # lost on the wire (HWM)
        self.last_seq = seq
        self.stats.count += 1
        return msg

    def _call_sync(self, msg: Message) -> None:
        t0 = _thread_time()
        try:
            self.handler(msg)
        except ValueError as exc:  # InputRejected included
            self.reject(str(exc))
        except Exception:  # noqa: BLE001 - a handler bug must not kill the node; logged with traceback
            self.node._handler_error(self.topic.name)
        finally:
            self.cpu_s += _thread_time() - t0

    async def _call_async(self, msg: Message) -> None:
        cpu = CpuCounter()          # its own steps only, not what the loop ran while it awaited
        try:
            await timed(self.handler(msg), cpu)
        except ValueError as exc:
            self.reject(str(exc))
        except Exception:  # noqa: BLE001
            self.node._handler_error(self.topic.name)
        finally:
            self.cpu_s += cpu.s

    def close(self) -> None:
        self._closed = True
        if isinstance(self.task, asyncio.Task):
            self.task.cancel()
        elif self._wake is not None:
            self._wake.put(None)

