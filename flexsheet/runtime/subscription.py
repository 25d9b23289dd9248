"""One typed subscription of a node (:class:`Subscription`, made by
:meth:`flexsheet.runtime.node.Node.subscribe`): its queue and QoS, its consumer (an ``async def`` handler is
called on the loop by the node once messages are queued, :meth:`Subscription.dispatch`; a plain ``def`` runs
in its own worker thread, :class:`SubscriptionWorker`) and its counters. See :mod:`flexsheet.runtime.node` for
the threading model."""

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

__all__ = ["Subscription", "SubscriptionWorker", "Sampled", "Direct", "Dispatcher"]

_thread_time = time.thread_time
_current_task = asyncio.current_task


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


class Direct(Sampled):
    """The consumer of an ``async def`` handler's subscription: no task waits between messages; the node calls
    :meth:`Subscription.dispatch` when messages are queued. ``done()``: closed; ``cancel()``: close (a handler
    call suspended in an await is cancelled)."""


class Dispatcher:
    """Calls a node's async handlers (on its loop): the subscriptions with queued items are dispatched
    (:meth:`Subscription.dispatch`) at the end of the transport's drain in progress (:meth:`drained`), once
    their QoS has seen the whole batch, else (a message from the node's container, a tool) on the loop's next
    iteration. ``on_frames``: the node's handler of wire frames."""

    __slots__ = ("on_frames", "loop", "ready", "draining", "pending")

    def __init__(self, on_frames: Callable[[list], None]) -> None:
        self.on_frames = on_frames
        self.loop: asyncio.AbstractEventLoop | None = None
        self.ready: list[Subscription] = []
        self.draining = False
        self.pending = False

    async def start(self, transport: Any) -> None:
        """Start ``transport`` on the running loop; one with an ``on_drained`` hook hands its drains in
        batches (:meth:`frames`, then :meth:`drained`)."""
        self.loop = asyncio.get_running_loop()
        if hasattr(transport, "on_drained"):
            transport.on_drained = self.drained
            await transport.start(self.frames)
        else:
            await transport.start(self.on_frames)

    def frames(self, frames: list) -> None:
        """One message of a transport's drain (on the loop)."""
        self.draining = True
        self.on_frames(frames)

    def drained(self) -> None:
        """The end of a transport's drain (on the loop): call the handlers of what it queued now when the
        drain runs as a loop callback (a ready socket); inside a task (a ``subscribe`` during ``setup``, the
        safety poll) on the loop's next iteration, so that no handler runs inside another's task."""
        self.draining = False
        if self.ready:
            if _current_task(self.loop) is None:
                self._run()
            else:
                self._later()

    def mark(self, sub: Subscription) -> None:
        """``sub`` (idle) has queued items (on the loop)."""
        self.ready.append(sub)
        if not self.draining:
            self._later()

    def _later(self) -> None:
        if not self.pending:
            self.pending = True
            self.loop.call_soon(self._soon)

    def _soon(self) -> None:
        self.pending = False
        if self.ready:
            self._run()

    def _run(self) -> None:
        ready, self.ready = self.ready, []
        for sub in ready:     # one marked again meanwhile waits for the next call
            sub.dispatch()


class Subscription:
    """One typed subscription of ``node`` (its :class:`~flexsheet.runtime.node.Node`): its queue, QoS,
    handler, consumer (:class:`Direct` dispatch on the loop, or a worker thread) and statistics.

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
        self._wake: queue.SimpleQueue | None = None if self.is_async or self.sampled else queue.SimpleQueue()
        self._held: Any = None          # sampled: the newest item, and the one decoded last with its message
        self._held_read: Any = None
        self._held_msg: Message | None = None
        self._read_lock = threading.Lock()
        self._taken: Message | None = None     # sampled: the message take() applied last
        self._lock = threading.Lock()
        self._busy = False      # async handler: a call in progress (its queue waits for it)
        self._marked = False    # async handler: in the node's list of subscriptions to dispatch
        self._rest: asyncio.Task | None = None  # async handler: a call that awaited, finishing in a task
        self._suspended: Any = None  # ... its coroutine until that task first runs
        self._queue_drops = 0   # queue drops since the last item taken (not lost on the wire)
        self._closed = False
        self.stats = TopicCounters()
        self.cpu_s = 0.0  # CPU time of the sync handler (its worker thread), s
        self.last_seq: int | None = None
        self.last_meta: Any = None
        # the consumer, once started (all have done(), cancel())
        self.task: Direct | Sampled | SubscriptionWorker | None = None

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """Start the consumer: none runs for an async handler (:class:`Direct`: items already queued are
        dispatched on ``loop`` soon) or a sampled subscription; the worker thread for a sync handler."""
        if self.sampled:
            self.task = Sampled(self)
        elif self.is_async:
            self.task = Direct(self)
            if self.queue:
                self._mark()
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
                self._queue_drops += 1
                q.append(item)
                return  # the dropped item's wake-up token serves this one
            q.append(item)
        self._wake.put(None)

    def _push_async(self, item: Any) -> None:
        """Queue ``item`` (on the loop); an idle subscription asks the node to dispatch it."""
        q = self.queue
        if len(q) >= self.depth:
            q.popleft()
            self.stats.dropped += 1
            self._queue_drops += 1
        q.append(item)
        if not (self._busy or self._marked or self._closed) and self.task is not None:
            self._mark()

    def _mark(self) -> None:
        self._marked = True
        self.node._dispatch.mark(self)

    def dispatch(self) -> None:
        """Handle the queued items in order, on the loop, by calling the async handler straight away (no task,
        no event). A call that awaits something not yet done continues in a task; items that arrive meanwhile
        wait in the queue (QoS applies) and that task handles them, so the handler is never re-entered."""
        self._marked = False
        if self._busy or self._closed:
            return
        q = self.queue
        self._busy = True
        try:
            while q:
                msg = self._accept(q.popleft())
                if msg is None:
                    continue
                rest = self._step(msg)
                if rest is not None:
                    self._suspended = rest[0]
                    self._rest = self.node._loop.create_task(self._finish(*rest))
                    return
        finally:
            self._busy = self._rest is not None

    def _step(self, msg: Message) -> tuple | None:
        """Run the handler on ``msg`` up to its first suspension: None when it returned (or raised: counted),
        else ``(coroutine, what it yielded, CPU s so far)``."""
        t0 = _thread_time()
        try:
            coro = self.handler(msg)
            yielded = coro.send(None)
        except StopIteration:
            self.cpu_s += _thread_time() - t0
            return None
        except ValueError as exc:  # InputRejected included
            self.cpu_s += _thread_time() - t0
            self.reject(str(exc))
            return None
        except Exception:  # noqa: BLE001 - a handler bug must not kill the node; logged with traceback
            self.cpu_s += _thread_time() - t0
            self.node._handler_error(self.topic.name)
            return None
        return coro, yielded, _thread_time() - t0

    async def _finish(self, coro: Any, yielded: Any, spent: float) -> None:
        """The task of a handler call that awaited: its rest, then the items queued meanwhile, in order."""
        self._suspended = None
        cpu = CpuCounter()
        cpu.s = spent
        try:
            await self._timed_call(coro, cpu, yielded)
            q = self.queue
            while q and not self._closed:
                msg = self._accept(q.popleft())
                if msg is not None:
                    await self._call_async(msg)
        finally:
            self._rest = None
            self._busy = False

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
            # lost on the wire (HWM): the gap less what the queue dropped (counted there)
            self.stats.dropped += max(0, seq - last - 1 - self._queue_drops)
        self._queue_drops = 0
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
        await self._timed_call(self.handler(msg), CpuCounter())   # its own steps only, not the loop's others

    async def _timed_call(self, coro: Any, cpu: CpuCounter, *first: Any) -> None:
        """Await the handler call ``coro`` (``first``: what its first step, already run, yielded), counting a
        ``ValueError`` as rejected input and another error as a handler bug, its steps' CPU into ``cpu_s``."""
        try:
            await timed(coro, cpu, *first)
        except ValueError as exc:
            self.reject(str(exc))
        except Exception:  # noqa: BLE001 - a handler bug must not kill the node; logged with traceback
            self.node._handler_error(self.topic.name)
        finally:
            self.cpu_s += cpu.s

    def close(self) -> None:
        self._closed = True
        if self._rest is not None:
            self._rest.cancel()
            coro, self._suspended = self._suspended, None
            if coro is not None:   # its task never ran (cancelled before its first step): cancel the call
                _cancel(coro)
        elif self._wake is not None:
            self._wake.put(None)


def _cancel(coro: Any) -> None:
    """Throw ``CancelledError`` into a suspended handler coroutine (its cleanup runs); closed if it awaits
    again."""
    try:
        coro.throw(asyncio.CancelledError())
    except BaseException:  # noqa: BLE001 - the cancellation itself, its return or its own error: it is over
        return
    coro.close()
