"""The :class:`Node` base: typed publishers and subscribers, QoS, timers, parameters and diagnostics on
asyncio.

A node is a thin shell around a pure algorithm module::

    class PlannerNode(Node):
        Params = PlannerParams                      # pydantic model, validated before any socket opens
        async def setup(self):
            self.pub = self.publisher(topics.SHEET_TARGET)
            self.subscribe(topics.FINGERTIP, self.on_fingertip, qos=QoS.LATEST) self.timer(0.01,
        self.on_timer) def on_fingertip(self, msg): ...            # sync: runs in this subscription's worker
        thread

Threading model: the asyncio loop owns the sockets' reads. Each subscription has its own queue (QoS applies
there) and consumer. An ``async def`` handler is called on the loop straight from the end of the socket drain
that queued its messages (in-process messages: on the loop's next iteration), in order; a call that awaits
finishes in a task and what arrives meanwhile queues for it (never two calls at once for one subscription:
:class:`~flexsheet.runtime.subscription.Dispatcher`). A plain ``def`` handler runs in the subscription's own
worker thread (one per subscription: messages of one topic stay in order and a slow handler never stalls the
loop or other topics; a message costs one thread wake-up). ``Publisher.publish`` is thread-safe: from a worker
thread it sends directly (the publisher socket has a lock), without waking the loop.

Publishing: a message is encoded once, and only when a subscriber outside this process may want it (the
publisher socket tracks its subscriptions, :class:`flexsheet.runtime.zmq.xpub.XPub`) or the topic is latched.
In a composable container (:mod:`flexsheet.runtime.container`) the nodes of the container get the frozen
message object itself (its arrays as read-only views), never a copy.

Time: :meth:`Node.now`, the header stamps of :meth:`~flexsheet.runtime.publisher.Publisher.header` and
:meth:`Node.timer` read the node's :class:`~flexsheet.runtime.clock.Clock` — the wall clock, or in a lockstep
replay the bag's clock (:class:`~flexsheet.runtime.clock.SimClock`, like ROS's ``use_sim_time``). A node that
wants replayable time reads ``self.now()``, never ``time.time()``.

QoS (per subscription, :mod:`flexsheet.runtime.qos`): ``LATEST`` keeps only the newest message (depth 1: stale
ones are dropped and counted), ``KEEP_ALL`` queues everything (bounded by ``depth``, default
:data:`~flexsheet.runtime.qos.KEEP_ALL_DEPTH`, drops counted), ``LATCHED`` is ``LATEST`` plus the publisher's
last value delivered on joining.

Bad input never crashes a node: an undecodable or wrong-type message, or a handler raising
:class:`InputRejected`/``ValueError``, is logged in one line, counted in diagnostics and skipped.
Source: rclpy ``create_publisher``/``create_subscription`` (API shape), DDS QoS history/durability.
"""

from __future__ import annotations

import asyncio
import inspect
import logging
import os
import signal
import threading
import time
from collections.abc import Callable
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict

from flexsheet.runtime.clock import WALL_CLOCK, Clock, ticks
from flexsheet.runtime.config import ConfigError, NodeConfig
from flexsheet.runtime.cpu_time import CpuCounter, timed
from flexsheet.runtime.discovery import announce, withdraw
from flexsheet.runtime.publisher import Publisher
from flexsheet.runtime.qos import QoS
from flexsheet.runtime.services import ParamServices, ServiceServer, topic_pub
from flexsheet.runtime.subscription import Dispatcher, Subscription, SubscriptionWorker
from flexsheet.runtime.transport import Transport
from flexsheet.runtime.zmq.transport import ZmqTransport
from flexsheet.runtime.zmq.xpub import SMALL_MESSAGE_BYTES
from messages import Heartbeat, Message, Topic, TopicStats
from messages import topics as T

__all__ = ["Node", "InputRejected", "EmptyParams", "WORKER_JOIN_S"]

_thread_time = time.thread_time

#: how long a stopping node waits for its sync handlers to return, s (see :meth:`Node._join_workers`)
WORKER_JOIN_S = 2.0   # within the launcher's 3 s before it escalates a SIGINT (launch.py shutdown_timeout)


class InputRejected(ValueError):
    """Raised by a handler for input it refuses (message names the field and value). Counted, not fatal."""


class EmptyParams(BaseModel):
    """Parameters of a node that takes none."""

    model_config = ConfigDict(extra="forbid")


class Node:
    """Base class of every flexsheet node (see the module docstring for the API and threading model).

    Subclasses set ``Params`` (a pydantic model) and override :meth:`setup` (and optionally
    :meth:`teardown`). Construct with a :class:`NodeConfig`; ``params`` are validated here, so a bad value
    raises ``pydantic.ValidationError`` naming the field before any socket opens.
    """

    Params: ClassVar[type[BaseModel]] = EmptyParams
    node_type: ClassVar[str] = ""
    #: s; > 0: in its own process the node receives its inputs in batches every DRAIN_PERIOD s instead of on
    #: every ready socket (:class:`~flexsheet.runtime.zmq.transport.ZmqTransport`
    #: ``drain_period``) — for nodes that want the newest of many inputs, not
    #: each on time (the Foxglove bridge). No effect in a container.
    DRAIN_PERIOD: ClassVar[float] = 0.0
    #: the params ``flexsheet param set`` may change while the node runs (the others are read-only at run
    #: time); the node reads them from ``self.params`` where it uses them, or reacts in :meth:`on_params_set`
    DYNAMIC_PARAMS: ClassVar[frozenset[str]] = frozenset()

    #: the largest message this node publishes, bytes: sizes its publisher's high-water mark once, before bind
    #: (:class:`~flexsheet.runtime.zmq.xpub.XPub`); a node of images declares its own
    LARGEST_MESSAGE_BYTES: ClassVar[int] = SMALL_MESSAGE_BYTES

    def __init__(self, config: NodeConfig, transport: Transport | None = None) -> None:
        self.config = config
        self.name = config.name
        self.params = self.Params.model_validate(config.params)
        self.log = logging.getLogger(config.name)
        self.transport = transport or ZmqTransport(config.endpoint, config.peers, curve=config.curve,
                                                   drain_period=self.DRAIN_PERIOD,
                                                   largest_bytes=self.LARGEST_MESSAGE_BYTES)
        self._bus = getattr(self.transport, "bus", None)  # the container's in-process bus, if any
        attach = getattr(self.transport, "attach", None)
        if attach is not None:
            attach(self)
        self._clock: Clock = getattr(self._bus, "clock", None) or WALL_CLOCK
        self._lockstep = getattr(self._bus, "lockstep", None)
        self._publishers: dict[str, Publisher] = {}
        self._subs: dict[str, list[Subscription]] = {}
        self._subs_b: dict[bytes, list[Subscription]] = {}
        self._dispatch = Dispatcher(self._on_frames)  # calls the async handlers
        self._timers: list = []
        self._stop: asyncio.Event | None = None  # created in run(), inside the loop
        self._loop: asyncio.AbstractEventLoop | None = None
        self._loop_thread: threading.Thread | None = None
        self._loop_tid: int | None = None
        self._started = time.monotonic()
        self.ready = False  # True once setup() returned and the subscriptions are served
        self.rejected_total = 0
        self.errors_total = 0
        self.timer_cpu_s = 0.0
        self.last_rejection = ""
        self.state_message = ""
        self._last_log = 0.0
        self._suppressed = 0
        self.services = None  # its ServiceServer once running (flexsheet.runtime.services)
        # its entry in the local graph discovery (flexsheet.runtime.discovery) while up
        self._announced = None
        self._pending_services: dict[str, tuple[Callable, str, bool]] = {}

    # ------------------------------------------------------------------ API for subclasses
    async def setup(self) -> None:
        """Create publishers, subscriptions and timers; do heavy precompute here. Override."""

    @classmethod
    def probe(cls, params: BaseModel) -> list[str]:
        """The devices the validated ``params`` name that this machine lacks, one line each
        (``flexsheet launch --check --probe``); override in nodes that open devices. The default: none to
        probe."""
        return []

    def on_params_set(self, names: set[str]) -> None:
        """Called on the loop after ``flexsheet param set`` changed ``names`` (of :attr:`DYNAMIC_PARAMS`) in
        ``self.params``. Override to react (the default: nothing, the node reads the params where it uses
        them)."""

    def service(self, name: str, handler: Callable[[dict], Any], doc: str, commanding: bool = False) -> None:
        """Offer ``handler(args: dict) -> result`` as the service ``name``
        (``flexsheet service call NODE name``); it runs on the loop, may be ``async``, returns plain msgpack
        types and raises ``ValueError`` with one line for a bad request. ``commanding``: it changes what the
        node does (moves, settings), so only the hosts' tools may call it (:mod:`flexsheet.runtime.services`).
        Served once :meth:`setup` returned."""
        if self.services is not None:
            self.services.add(name, handler, doc, commanding)
        else:
            self._pending_services[name] = (handler, doc, commanding)

    async def teardown(self) -> None:
        """Release resources on shutdown. Override if needed."""

    def now(self) -> float:
        """Current time, s: ``time.time()`` (the clock of ``Header.stamp``), or simulated time
        (:class:`SimClock`: a lockstep replay's bag time, or a live simulated graph's; there the start of the
        running handler)."""
        return self._clock.now()

    def charge(self, seconds: float) -> None:
        """On a live simulated clock: the running handler takes ``seconds`` more of simulated time than its
        declared ``sim_cost`` (work it does only sometimes, e.g. a redraw); its output leaves that much later.
        No effect on the wall clock or in a lockstep replay."""
        if self._lockstep is not None:
            self._lockstep.charge(self, seconds)

    def monotonic(self) -> float:
        """Time for intervals, s: ``time.monotonic()``, or :meth:`now` on a simulated clock."""
        return self._clock.now() if self._clock.simulated else time.monotonic()

    async def background(self, target: Callable[..., Any], name: str, *args: Any) -> None:
        """Run ``target(*args)`` in a daemon thread named ``name``, for work a node attaches when it is done.
        On a simulated clock it runs to completion (in a worker thread, the loop free) before this returns:
        what it attaches must not arrive at a host-dependent moment of simulated time."""
        if self._clock.simulated:
            await asyncio.to_thread(target, *args)
        else:
            threading.Thread(target=target, args=args, name=name, daemon=True).start()

    async def pause(self, seconds: float, until: Callable[[], bool], poll: float) -> None:
        """A handler's rest before its next message: on the wall clock sleep ``seconds``, then every ``poll``
        s until ``until()``; at once on a simulated clock, which waits for every handler (skip there
        instead)."""
        if self._clock.simulated:
            return
        await asyncio.sleep(seconds)
        while not until():
            await asyncio.sleep(poll)

    def require_wall_clock(self, what: str) -> None:
        """Raise ``ValueError`` naming ``what`` when this node runs on a simulated clock (a real device's
        timing, such as a window's vsync, cannot follow simulated time)."""
        if self._clock.simulated:
            raise ValueError(f"{what} needs the wall clock (launch file clock: wall), not a simulated one")

    @property
    def clock(self) -> Clock:
        """This node's :class:`Clock` (``clock.simulated`` is True in a lockstep replay)."""
        return self._clock

    def topic(self, topic: Topic) -> Topic:
        """``topic`` after this node's launch-file remaps."""
        new = self.config.remaps.get(topic.name)
        return topic.renamed(new) if new else topic

    def publisher(self, topic: Topic) -> Publisher:
        """Typed publisher for ``topic`` (remaps applied). Latched topics keep their last value for late
        joiners."""
        topic = self.topic(topic)
        pub = self._publishers.get(topic.name)
        if pub is None:
            pub = self._publishers[topic.name] = Publisher(self, topic)
        elif pub.topic.type is not topic.type:
            raise TypeError(f"{topic.name}: already published as {pub.topic.type.__name__}")
        return pub

    def subscribe(self, topic: Topic, handler: Callable[[Any], Any], qos: QoS = QoS.LATEST,
                  depth: int | None = None, sim_cost: float = 0.0) -> Subscription:
        """Subscribe ``handler`` to ``topic`` with ``qos``; ``depth`` overrides the queue bound. ``sim_cost``
        s: the simulated time one call takes on a live simulated clock (its compute on the lab's PC and the
        hops before it; the node is busy meanwhile and its output leaves at the end); ignored on the wall
        clock."""
        topic = self.topic(topic)
        sub = Subscription(self, topic, handler, qos, depth, sim_cost)
        self._subs.setdefault(topic.name, []).append(sub)
        self._subs_b.setdefault(sub.name_b, []).append(sub)
        if self._bus is not None:
            self._bus.changed()
        if self._loop is not None:
            self._start_sub(sub)
        return sub

    def sample(self, topic: Topic) -> Subscription:
        """Keep the newest message of ``topic`` without handling each: ``.read()`` on the returned
        subscription decodes and validates it when the node reads it (None before the first). For a state read
        at the node's own pace: a 140 Hz joint state read once per frame costs one decode per frame, not 140 a
        second."""
        return self.subscribe(topic, None, QoS.LATEST)

    def timer(self, period: float, callback: Callable[[], Any], sim_cost: float = 0.0,
              sim_delay: float = 0.0):
        """Call ``callback`` every ``period`` s of this node's clock (drift-free schedule). Sync callbacks run
        on the loop. Returns the timer's task (or a :class:`SimTimer` on a simulated clock): ``.cancel()``
        stops it. ``sim_cost`` s: as for :meth:`subscribe`; ``sim_delay`` s (a live simulated clock,
        ``clock: sim``; 0 in a lockstep replay): what the callback publishes is delivered that much later
        again, without keeping the node busy (a link's latency, pipelined)."""
        if not period > 0:
            raise ValueError(f"timer period must be > 0 s, got {period!r}")
        if self._clock.simulated:
            tm = self._clock.add_timer(period, callback, self, sim_cost, sim_delay)
            self._timers.append(tm)
            return tm
        return self._wall_timer(period, callback)

    def _wall_timer(self, period: float, callback: Callable[[], Any]) -> asyncio.Task:
        is_async = inspect.iscoroutinefunction(callback)

        async def run() -> None:
            async for _ in ticks(period):
                await self._fire(callback, is_async)

        task = asyncio.get_running_loop().create_task(run())
        self._timers.append(task)
        return task

    async def _fire(self, callback: Callable[[], Any], is_async: bool | None = None) -> None:
        """Run one timer callback; a ``ValueError`` is a rejection, anything else a logged handler error."""
        t0, cpu = _thread_time(), None
        try:
            if is_async if is_async is not None else inspect.iscoroutinefunction(callback):
                cpu = CpuCounter()      # its own steps only (flexsheet.runtime.cpu_time)
                await timed(callback(), cpu)
            else:
                callback()
        except ValueError as exc:
            self._reject(f"timer: {exc}")
        except Exception:  # noqa: BLE001
            self._handler_error("timer")
        finally:
            self.timer_cpu_s += cpu.s if cpu is not None else _thread_time() - t0

    def shutdown(self) -> None:
        """Ask the node to stop (thread-safe)."""
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)

    @property
    def stopping(self) -> bool:
        """Whether a stop was asked (:meth:`shutdown`, SIGINT/SIGTERM): long work in ``setup`` or an awaited
        handler checks it to end early."""
        return self._stop is not None and self._stop.is_set()

    def cpu_seconds(self) -> float:
        """CPU time spent in this node's handlers and timer callbacks so far, s (``time.thread_time``; an
        async one's own steps, :mod:`flexsheet.runtime.cpu_time`); decoding, the loop and threads the node
        starts itself are not included."""
        return self.timer_cpu_s + sum(s.cpu_s for lst in self._subs.values() for s in lst)

    # ------------------------------------------------------------------ runtime
    def _start_sub(self, sub: Subscription) -> None:
        sub.start(self._loop)
        self.transport.subscribe(sub.topic.name)

    def _send(self, pub: Publisher, frames: list) -> None:
        tr = self.transport
        if pub.latched:
            tr.set_latched_remote(pub.name, frames)
        if not tr.send_remote(frames):
            pub.stats.dropped += 1

    def _on_frames(self, frames: list) -> None:
        """Wire frames for this node (from the transport, on the loop): queue them on the topic's
        subscriptions."""
        t = frames[0]
        subs = self._subs_b.get(t if type(t) is bytes else bytes(t))
        if subs:
            for sub in subs:
                sub.push(frames)

    def _on_local(self, topic: bytes, msg: Message) -> None:
        """A message object from a node of the same container (any thread)."""
        subs = self._subs_b.get(topic)
        if subs:
            for sub in subs:
                sub.push(msg)

    def _reject(self, reason: str) -> None:
        self.rejected_total += 1
        self.last_rejection = reason.splitlines()[0][:300]
        self.log_limited(logging.WARNING, f"rejected: {self.last_rejection}")

    def _handler_error(self, where: str) -> None:
        self.errors_total += 1
        self.state_message = f"handler error in {where}"
        self.log.exception("handler error in %s (node keeps running)", where)

    def log_limited(self, level: int, line: str) -> None:
        """Log ``line`` at ``level`` at most once a second; the lines dropped meanwhile are counted in the
        next."""
        now = time.monotonic()
        if now - self._last_log >= 1.0:
            extra = f" (+{self._suppressed} more suppressed)" if self._suppressed else ""
            self.log.log(level, line + extra)
            self._last_log, self._suppressed = now, 0
        else:
            self._suppressed += 1

    def heartbeat(self) -> Heartbeat:
        """Current diagnostics as a :class:`Heartbeat` (rates over the last heartbeat period; stamped with the
        wall clock even in a lockstep replay, since heartbeats tell liveness)."""
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
        message = self.state_message
        report = getattr(self.transport, "link_report", None)  # peers without a link for a while (LinkWatch)
        links = report() if report is not None else ""
        if links:
            state = "warn" if state == "ok" else state
            message = f"{message}; {links}" if message else links
        return Heartbeat(header=self._hb_pub.header("display", time.time()), node=self.name,
                         node_type=self.config.node_type, host=self.config.host, pid=os.getpid(),
                         endpoint=self.transport.endpoint, uptime=time.monotonic() - self._started,
                         state=state,
                         message=message, publishers=pubs, subscriptions=subs,
                         rejected_total=self.rejected_total, last_rejection=self.last_rejection,
                         period=period,
                         service_endpoint=self.services.endpoint if self.services is not None else "")

    async def run(self, install_signals: bool = True) -> None:
        """Start the transport, call :meth:`setup`, serve until SIGINT/SIGTERM or :meth:`shutdown`, tear
        down."""
        self._loop = asyncio.get_running_loop()
        self._loop_thread = threading.current_thread()
        self._loop_tid = threading.get_ident()
        self._stop = asyncio.Event()
        if install_signals:
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._loop.add_signal_handler(sig, self._stop.set)
        await self._dispatch.start(self.transport)
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
            self._start_services()
            self._wall_timer(self.config.heartbeat_period, lambda: self._hb_pub.publish(self.heartbeat()))
            self.ready = True
            self._announced = announce(self.name, self.transport.endpoint or "",
                                       self.config.curve is not None)
            self.log.info("%s up: endpoint %s, %d peers, publishes %s", self.name,
                          self.transport.endpoint or "-",
                          len(getattr(self.transport, "peers", [])),
                          ", ".join(n for n in self._publishers if n != T.DIAGNOSTICS.name) or "-")
            await self._stop.wait()
        finally:
            await self._close()

    def _start_services(self) -> None:
        """Bind the service socket on the publisher's address (none without a TCP endpoint) with the built-in
        services (:mod:`flexsheet.runtime.services`)."""
        ep = self.transport.endpoint or ""
        if not ep.startswith("tcp://"):
            return
        ctx = getattr(self.transport, "ctx", None) or getattr(getattr(self._bus, "sub", None), "ctx", None)
        self.services = srv = ServiceServer(ep.rsplit(":", 1)[0], self.config.curve, ctx)
        params = ParamServices(self)
        srv.add("param/list", params.list, "every param: name, type, default, value, description, settable")
        srv.add("param/get", params.get, "{name}: a param's value")
        srv.add("param/set", params.set, "{name, value}: set a run-time param "
                                         "(DYNAMIC_PARAMS)", commanding=True)
        srv.add("clock/now", lambda args: self.now(), "the node's clock now, s (simulated on a simulated "
                                                      "graph)")
        srv.add("topic/pub", lambda args: topic_pub(self, args), "{topic, frames}: deliver one encoded "
                "message of a topic this node subscribes to, as if it came from the wire (topic "
                "pub)", commanding=True)
        for name, (handler, doc, commanding) in self._pending_services.items():
            srv.add(name, handler, doc, commanding)
        srv.start()

    async def _close(self) -> None:
        withdraw(self._announced)
        self._announced = None
        if self.services is not None:
            self.services.close()
        for task in self._timers:
            task.cancel()
        for lst in self._subs.values():
            for sub in lst:
                sub.close()
        await self._join_workers()
        try:
            await asyncio.wait_for(self.teardown(), timeout=2.0)
        except Exception:  # noqa: BLE001 - shutdown must finish whatever teardown does
            self.log.exception("teardown failed")
        self.transport.close()
        self.log.info("%s stopped", self.name)

    async def _join_workers(self) -> None:
        """Wait (at most ``WORKER_JOIN_S``) for the sync handlers' worker threads to finish the item in hand.

        Why: the workers are daemon threads. If the interpreter exits while one is inside a C++ extension that
        released the GIL (OpenCV, most often), Python 3.11 ends that thread with ``pthread_exit`` when it asks
        for the GIL back, and the forced unwind through the extension's ``noexcept`` GIL guard calls
        ``std::terminate``: the process aborts with "terminate called without an active exception" after a
        clean stop (it failed CI in the triangulator; reproduced 20 of 20 with a ``cv2.GaussianBlur`` loop).
        """
        workers = [s.task for lst in self._subs.values() for s in lst
                   if isinstance(s.task, SubscriptionWorker)]
        deadline = time.monotonic() + WORKER_JOIN_S
        while any(w.is_alive() for w in workers) and time.monotonic() < deadline:
            await asyncio.sleep(0.005)
        late = [w.name for w in workers if w.is_alive()]
        if late:
            self.log.warning("%s: sync handler(s) still running %.0f s after the stop: %s (the process may "
                             "abort at exit)", self.name, WORKER_JOIN_S, ", ".join(late))

