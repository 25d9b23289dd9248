"""The :class:`Node` base: typed publishers and subscribers, QoS, timers, parameters and diagnostics on asyncio.

A node is a thin shell around a pure algorithm module::

    class PlannerNode(Node):
        Params = PlannerParams                      # pydantic model, validated before any socket opens
        async def setup(self):
            self.pub = self.publisher(topics.SHEET_TARGET)
            self.subscribe(topics.FINGERTIP, self.on_fingertip, qos=QoS.LATEST)
            self.timer(0.01, self.on_timer)
        def on_fingertip(self, msg): ...            # sync: runs in this subscription's worker thread

Threading model: the asyncio loop owns the sockets. Each subscription has its own queue and consumer
task; an ``async def`` handler runs on the loop, a plain ``def`` handler runs in the subscription's own
worker thread (one thread per subscription, so messages of one topic stay in order and a slow handler
never stalls the loop or other topics). :meth:`Publisher.publish` is thread-safe.

QoS (per subscription): ``LATEST`` keeps only the newest message (depth 1: stale ones are dropped and
counted), ``KEEP_ALL`` queues everything (bounded by ``depth``, default 1 000 000, drops counted),
``LATCHED`` is ``LATEST`` plus the publisher's last value delivered on joining.

Bad input never crashes a node: an undecodable or wrong-type message, or a handler raising
:class:`InputRejected`/``ValueError``, is logged in one line, counted in diagnostics and skipped.
Source: rclpy ``create_publisher``/``create_subscription`` (API shape), DDS QoS history/durability.
"""

from __future__ import annotations

import asyncio
import collections
import enum
import inspect
import logging
import os
import signal
import socket
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict

from flexsheet.runtime.codec import DecodeError, decode, encode
from flexsheet.runtime.transport import CurveConfig, InProcTransport, Transport, ZmqTransport
from messages import Header, Heartbeat, Message, Topic, TopicStats
from messages import topics as T

__all__ = ["Node", "NodeConfig", "QoS", "InputRejected", "ConfigError", "EXIT_CONFIG", "Publisher", "Subscription",
           "EmptyParams", "ticks"]

#: exit status of a node whose configuration is unusable (BSD ``sysexits.h`` EX_CONFIG): a bad param, a missing
#: or unreadable file a param names, a ``ValueError`` from :meth:`Node.setup`. The supervisor never respawns it.
EXIT_CONFIG = 78


class InputRejected(ValueError):
    """Raised by a handler for input it refuses (message names the field and value). Counted, not fatal."""


class ConfigError(ValueError):
    """The node's configuration cannot work (message names the param and value). Raised from :meth:`Node.setup`
    (a ``ValueError`` or ``FileNotFoundError`` there is turned into one); ``flexsheet run`` exits with
    :data:`EXIT_CONFIG` and the launcher does not respawn the node."""


class QoS(enum.Enum):
    """Per-subscription quality of service (see module docstring)."""

    LATEST = "latest"
    KEEP_ALL = "keep_all"
    LATCHED = "latched"


class EmptyParams(BaseModel):
    """Parameters of a node that takes none."""

    model_config = ConfigDict(extra="forbid")


@dataclass
class NodeConfig:
    """How a node is wired: its name, type, host, bound endpoint, peer endpoints and raw params.

    Filled by the launcher (:mod:`flexsheet.runtime.launch`) or ``flexsheet run``. ``params`` are validated against
    the node's ``Params`` model in :meth:`Node.__init__`, before any socket opens. ``remaps`` rename topics
    (``{"/fingertip": "/fingertip_raw"}``).
    """

    name: str
    node_type: str = ""
    host: str = "localhost"
    endpoint: str = "tcp://127.0.0.1:0"
    peers: list[str] = field(default_factory=list)
    params: dict[str, Any] = field(default_factory=dict)
    remaps: dict[str, str] = field(default_factory=dict)
    heartbeat_period: float = 1.0
    curve: CurveConfig | None = None
    display_calib: str | None = None  # the launch file's display calibration (display.yaml), path or None


class _Stats:
    __slots__ = ("count", "dropped", "rejected", "last_count", "rate")

    def __init__(self) -> None:
        self.count = self.dropped = self.rejected = self.last_count = 0
        self.rate = 0.0


class Publisher:
    """Typed publisher for one topic. ``publish`` checks the type and is safe to call from any thread."""

    def __init__(self, node: Node, topic: Topic) -> None:
        self.node, self.topic = node, topic
        self.name = topic.name
        self._seq = 0
        self._lock = threading.Lock()
        self.stats = _Stats()

    def header(self, frame_id: str = "display", stamp: float | None = None) -> Header:
        """Next :class:`Header` for this publisher: ``seq`` incremented, ``stamp`` = ``time.time()`` if None."""
        with self._lock:
            seq = self._seq
            self._seq += 1
        return Header(stamp=time.time() if stamp is None else float(stamp), frame_id=frame_id, seq=seq)

    def publish(self, msg: Message) -> None:
        """Encode and send ``msg``. Raises ``TypeError`` naming expected vs given type."""
        if type(msg) is not self.topic.type:
            raise TypeError(f"{self.name}: expected {self.topic.type.__name__}, got {type(msg).__name__}")
        frames = encode(self.name, msg)
        node = self.node
        if node._loop_thread is threading.current_thread():
            node._send(self, frames)
        else:
            node._loop.call_soon_threadsafe(node._send, self, frames)


class Subscription:
    """One typed subscription: its queue, QoS, handler, consumer task and statistics."""

    def __init__(self, node: Node, topic: Topic, handler: Callable, qos: QoS, depth: int | None) -> None:
        self.node, self.topic, self.handler, self.qos = node, topic, handler, qos
        self.depth = depth or (1 if qos in (QoS.LATEST, QoS.LATCHED) else 1_000_000)
        self.queue: collections.deque = collections.deque()
        self.event = asyncio.Event()
        self.is_async = inspect.iscoroutinefunction(handler)
        self.executor = None if self.is_async else ThreadPoolExecutor(1, thread_name_prefix=f"sub{topic.name}")
        self.stats = _Stats()
        self.last_seq: int | None = None
        self.last_meta: bytes | None = None
        self.task: asyncio.Task | None = None

    def push(self, frames: list) -> None:
        if self.qos is QoS.LATCHED:
            key = b"\0".join(bytes(f) for f in frames[1:])
            if key == self.last_meta:  # the same latched value resent for another late joiner
                return
            self.last_meta = key
        if len(self.queue) >= self.depth:
            self.queue.popleft()
            self.stats.dropped += 1
        self.queue.append(frames)
        self.event.set()

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            if not self.queue:
                self.event.clear()
                await self.event.wait()
                continue
            frames = self.queue.popleft()
            if self.is_async:
                msg = self._decode(frames)
                if msg is not None:
                    await self._call_async(msg)
            else:
                await loop.run_in_executor(self.executor, self._decode_and_call, frames)

    def _decode(self, frames: list) -> Message | None:
        try:
            msg = decode(frames, self.topic)
        except DecodeError as exc:
            self.stats.rejected += 1
            self.node._reject(str(exc))
            return None
        seq = msg.header.seq
        if (self.last_seq is not None and seq > self.last_seq + 1 and self.qos is QoS.KEEP_ALL
                and self.topic.name != T.DIAGNOSTICS.name):  # every node publishes /diagnostics
            self.stats.dropped += seq - self.last_seq - 1  # lost on the wire (HWM)
        self.last_seq = seq
        self.stats.count += 1
        return msg

    def _decode_and_call(self, frames: list) -> None:
        msg = self._decode(frames)
        if msg is None:
            return
        try:
            self.handler(msg)
        except ValueError as exc:  # InputRejected included
            self.stats.rejected += 1
            self.node._reject(f"{self.topic.name}: {exc}")
        except Exception:  # noqa: BLE001 - a handler bug must not kill the node; logged with traceback
            self.node._handler_error(self.topic.name)

    async def _call_async(self, msg: Message) -> None:
        try:
            await self.handler(msg)
        except ValueError as exc:
            self.stats.rejected += 1
            self.node._reject(f"{self.topic.name}: {exc}")
        except Exception:  # noqa: BLE001
            self.node._handler_error(self.topic.name)

    def close(self) -> None:
        if self.task is not None:
            self.task.cancel()
        if self.executor is not None:
            self.executor.shutdown(wait=False, cancel_futures=True)


class Node:
    """Base class of every flexsheet node (see the module docstring for the API and threading model).

    Subclasses set ``Params`` (a pydantic model) and override :meth:`setup` (and optionally
    :meth:`teardown`). Construct with a :class:`NodeConfig`; ``params`` are validated here, so a bad value
    raises ``pydantic.ValidationError`` naming the field before any socket opens.
    """

    Params: ClassVar[type[BaseModel]] = EmptyParams
    node_type: ClassVar[str] = ""

    def __init__(self, config: NodeConfig, transport: Transport | None = None) -> None:
        self.config = config
        self.name = config.name
        self.params = self.Params.model_validate(config.params)
        self.log = logging.getLogger(config.name)
        self.transport = transport or ZmqTransport(config.endpoint, config.peers, curve=config.curve)
        self._publishers: dict[str, Publisher] = {}
        self._subs: dict[str, list[Subscription]] = {}
        self._timers: list[asyncio.Task] = []
        self._stop: asyncio.Event | None = None  # created in run(), inside the loop
        self._loop: asyncio.AbstractEventLoop | None = None
        self._loop_thread: threading.Thread | None = None
        self._started = time.monotonic()
        self.rejected_total = 0
        self.errors_total = 0
        self.last_rejection = ""
        self.state_message = ""
        self._last_log = 0.0
        self._suppressed = 0

    # ------------------------------------------------------------------ API for subclasses
    async def setup(self) -> None:
        """Create publishers, subscriptions and timers; do heavy precompute here. Override."""

    async def teardown(self) -> None:
        """Release resources on shutdown. Override if needed."""

    def now(self) -> float:
        """Current time, s (``time.time()``, the clock of ``Header.stamp``)."""
        return time.time()

    def topic(self, topic: Topic) -> Topic:
        """``topic`` after this node's launch-file remaps."""
        new = self.config.remaps.get(topic.name)
        return topic.renamed(new) if new else topic

    def publisher(self, topic: Topic) -> Publisher:
        """Typed publisher for ``topic`` (remaps applied). Latched topics keep their last value for late joiners."""
        topic = self.topic(topic)
        pub = self._publishers.get(topic.name)
        if pub is None:
            pub = self._publishers[topic.name] = Publisher(self, topic)
        elif pub.topic.type is not topic.type:
            raise TypeError(f"{topic.name}: already published as {pub.topic.type.__name__}")
        return pub

    def subscribe(self, topic: Topic, handler: Callable[[Any], Any], qos: QoS = QoS.LATEST,
                  depth: int | None = None) -> Subscription:
        """Subscribe ``handler`` to ``topic`` with ``qos``; ``depth`` overrides the queue bound."""
        topic = self.topic(topic)
        sub = Subscription(self, topic, handler, qos, depth)
        self._subs.setdefault(topic.name, []).append(sub)
        if self._loop is not None:
            self._start_sub(sub)
        return sub

    def timer(self, period: float, callback: Callable[[], Any]) -> asyncio.Task:
        """Call ``callback`` every ``period`` s (drift-free schedule). Sync callbacks run on the loop."""
        if not period > 0:
            raise ValueError(f"timer period must be > 0 s, got {period!r}")
        is_async = inspect.iscoroutinefunction(callback)

        async def run() -> None:
            async for _ in ticks(period):
                try:
                    if is_async:
                        await callback()
                    else:
                        callback()
                except ValueError as exc:
                    self._reject(f"timer: {exc}")
                except Exception:  # noqa: BLE001
                    self._handler_error("timer")

        task = asyncio.get_running_loop().create_task(run())
        self._timers.append(task)
        return task

    def shutdown(self) -> None:
        """Ask the node to stop (thread-safe)."""
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)

    # ------------------------------------------------------------------ runtime
    def _start_sub(self, sub: Subscription) -> None:
        self.transport.subscribe(sub.topic.name)
        sub.task = self._loop.create_task(sub.run())

    def _send(self, pub: Publisher, frames: list) -> None:
        pub.stats.count += 1
        if pub.topic.latched:
            self.transport.set_latched(pub.name, frames)
        if not self.transport.send(frames):
            pub.stats.dropped += 1

    def _on_frames(self, frames: list) -> None:
        topic = bytes(frames[0]).decode(errors="replace")
        subs = self._subs.get(topic)
        if subs:
            for sub in subs:
                sub.push(frames)

    def _reject(self, reason: str) -> None:
        self.rejected_total += 1
        self.last_rejection = reason.splitlines()[0][:300]
        self._log_limited(logging.WARNING, f"rejected: {self.last_rejection}")

    def _handler_error(self, where: str) -> None:
        self.errors_total += 1
        self.state_message = f"handler error in {where}"
        self.log.exception("handler error in %s (node keeps running)", where)

    def _log_limited(self, level: int, line: str) -> None:
        now = time.monotonic()
        if now - self._last_log >= 1.0:
            extra = f" (+{self._suppressed} more suppressed)" if self._suppressed else ""
            self.log.log(level, line + extra)
            self._last_log, self._suppressed = now, 0
        else:
            self._suppressed += 1

    def heartbeat(self) -> Heartbeat:
        """Current diagnostics as a :class:`Heartbeat` (rates over the last heartbeat period)."""
        period = self.config.heartbeat_period
        pubs, subs = [], []
        for pub in self._publishers.values():
            s = pub.stats
            s.rate, s.last_count = (s.count - s.last_count) / period, s.count
            pubs.append(TopicStats(topic=pub.name, type=pub.topic.type.SCHEMA, rate_hz=s.rate, count=s.count,
                                   dropped=s.dropped))
        for lst in self._subs.values():
            for sub in lst:
                s = sub.stats
                s.rate, s.last_count = (s.count - s.last_count) / period, s.count
                subs.append(TopicStats(topic=sub.topic.name, type=sub.topic.type.SCHEMA, qos=sub.qos.value,
                                       rate_hz=s.rate, count=s.count, dropped=s.dropped, rejected=s.rejected))
        state = "error" if self.errors_total else ("warn" if self.rejected_total else "ok")
        return Heartbeat(header=self._hb_pub.header("display"), node=self.name, node_type=self.config.node_type,
                         host=self.config.host, pid=os.getpid(), endpoint=self.transport.endpoint,
                         uptime=time.monotonic() - self._started, state=state,
                         message=self.state_message, publishers=pubs, subscriptions=subs,
                         rejected_total=self.rejected_total, last_rejection=self.last_rejection, period=period)

    async def run(self, install_signals: bool = True) -> None:
        """Start the transport, call :meth:`setup`, serve until SIGINT/SIGTERM or :meth:`shutdown`, tear down."""
        self._loop = asyncio.get_running_loop()
        self._loop_thread = threading.current_thread()
        self._stop = asyncio.Event()
        if install_signals:
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._loop.add_signal_handler(sig, self._stop.set)
        await self.transport.start(self._on_frames)
        self._hb_pub = self.publisher(T.DIAGNOSTICS)
        try:
            try:
                await self.setup()
            except ConfigError:
                raise
            except (ValueError, FileNotFoundError) as exc:  # a param or a file it names is unusable
                raise ConfigError(f"setup: {' '.join(str(exc).split())[:400]}") from exc
            for lst in self._subs.values():
                for sub in lst:
                    if sub.task is None:
                        self._start_sub(sub)
            self.timer(self.config.heartbeat_period, lambda: self._hb_pub.publish(self.heartbeat()))
            self.log.info("%s up: endpoint %s, %d peers, publishes %s", self.name, self.transport.endpoint or "-",
                          len(getattr(self.transport, "peers", [])),
                          ", ".join(n for n in self._publishers if n != T.DIAGNOSTICS.name) or "-")
            await self._stop.wait()
        finally:
            await self._close()

    async def _close(self) -> None:
        for task in self._timers:
            task.cancel()
        for lst in self._subs.values():
            for sub in lst:
                sub.close()
        try:
            await asyncio.wait_for(self.teardown(), timeout=2.0)
        except Exception:  # noqa: BLE001 - shutdown must finish whatever teardown does
            self.log.exception("teardown failed")
        self.transport.close()
        self.log.info("%s stopped", self.name)


async def ticks(period: float):
    """Async generator: yields every ``period`` s on a drift-free schedule; an overrun restarts the schedule
    rather than bursting to catch up. Used by :meth:`Node.timer` and the device twins' loops."""
    nxt = time.monotonic()
    while True:
        nxt += period
        delay = nxt - time.monotonic()
        if delay > 0:
            await asyncio.sleep(delay)
        else:
            nxt = time.monotonic()  # overrun: do not burst to catch up
        yield


def hostname() -> str:
    """This machine's host name (for diagnostics)."""
    return socket.gethostname()


def in_process(node_cls: type[Node], name: str = "harness", params: dict | None = None) -> Node:
    """Construct ``node_cls`` on an :class:`InProcTransport` (used by :mod:`flexsheet.runtime.testing`)."""
    return node_cls(NodeConfig(name=name, node_type=node_cls.node_type, params=params or {}),
                    transport=InProcTransport())
