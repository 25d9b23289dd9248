"""Simulated time for a container: a bag replayed in lockstep, or a live simulated graph (``clock: sim``).

Live simulated graph. A launch file with ``clock: sim`` runs every node in one container on a
:class:`~flexsheet.runtime.clock.SimClock` driven by :func:`run_live` (Gazebo's lockstep, ROS 2's
``use_sim_time``, a discrete-event simulation): time starts once every node is set up and then jumps from
event to event — a timer, a delivery — only when everything due has been handled. Each subscription and timer
declares the simulated time one call takes (``sim_cost``: the lab PC's compute, a device's latency); the node
is busy meanwhile and its output leaves, stamped, at the end. Nothing depends on the host's speed: two runs
with one seed publish byte-identical messages, stamps included; the host only sets the real-time factor.

Lockstep replay.
``flexsheet launch launch/replay.yaml --set player.mode=lockstep`` plays the bag into the nodes of the
player's container as fast as they can handle it: each message is delivered, handled by every subscription
it reaches, and the messages those handlers publish are delivered and handled in turn (breadth first, in a
fixed order: subscription order in the container) before the next bag message goes out. QoS ``latest``
therefore never drops, and no two handlers ever run at once: the result does not depend on thread timing.

The container's nodes run on the bag's clock (:class:`flexsheet.runtime.clock.SimClock`, like ROS's
``use_sim_time``): before a bag message is delivered the clock is set to its log time (when the recorder got
it in the live run, i.e. about when the live nodes got it), so :meth:`Node.now`, the header stamps of every
published message and :meth:`Node.timer` read replayed time. A timer fires, in due order, when the replayed
time passes its due time, and what it publishes is handled before the next bag message. Two lockstep
replays of one bag thus publish byte-identical messages, stamps included — provided the nodes read time
only through the runtime (``self.now()``, ``pub.header()``, ``self.timer()``), never ``time.time()`` /
``time.monotonic()`` directly, and do no work in threads or tasks of their own that publishes later.

Messages that reach the container from outside during a lockstep replay are queued like the bag's and
handled in arrival order (that part is then as deterministic as its source). Heartbeats stay on the wall
clock (they tell liveness).

Source: ROS 2 ``use_sim_time`` and ``rosbag2 play --clock``; the deterministic event-queue idea of
discrete-event simulation.
"""

from __future__ import annotations

import asyncio
import collections
import heapq
import itertools
import math
import threading
import time
from typing import TYPE_CHECKING, Any

from flexsheet.runtime.config import ConfigError
from flexsheet.runtime.qos import QoS

if TYPE_CHECKING:
    from flexsheet.runtime.node import Node
    from flexsheet.runtime.subscription import Subscription
from flexsheet.runtime.bag_read import read_bag
from messages import topics as T

__all__ = ["Lockstep", "check", "play", "run_live", "LockstepStats", "SIM_EPOCH", "WALL_TOPICS"]

#: simulated time at which a live simulated graph starts, s (a fixed, clearly simulated instant: runs of one
#: seed carry identical stamps, and no stamp is 0, which some fields use for "none")
SIM_EPOCH = 1000.0


class LockstepStats:
    """What a lockstep replay did: ``messages`` from the bag, ``handled`` handler calls, ``timers`` fired,
    ``bag_s`` replayed time span, ``wall_s`` wall time, ``speed`` = bag_s / wall_s."""

    def __init__(self) -> None:
        self.messages = self.handled = self.timers = 0
        self.bag_s = self.wall_s = 0.0

    @property
    def speed(self) -> float:
        return self.bag_s / self.wall_s if self.wall_s > 0 else 0.0

    def as_dict(self) -> dict[str, Any]:
        return {"messages": self.messages, "handled": self.handled, "timers": self.timers,
                "bag_s": self.bag_s,
                "wall_s": self.wall_s, "speed": self.speed}


class Lockstep:
    """The discrete-event scheduler of a container's :class:`~flexsheet.runtime.bus.Bus` (``bus``) on a
    :class:`~flexsheet.runtime.clock.SimClock`: subscriptions queue their input here (:meth:`enqueue`) instead
    of on their consumers; :meth:`drain` handles what is due, one item at a time on the loop, and
    :meth:`advance` moves the clock to a later instant, firing timers and deliveries in due order.

    Live simulated clock (``clock.live``): a handler (or timer) with ``sim_cost`` c started at t makes its
    node busy until t + c; what it publishes is delivered at t + c and stamped t + c (``Clock.stamp``); an
    item due while its node is busy waits until the node is free (QoS ``latest``: only the newest waiting item
    is handled, the older are dropped and counted). In a lockstep replay every cost is 0: breadth first, in
    publication order, as before. Wall-clock topics (``/diagnostics``) are handled when they arrive, without
    charge or wait (their content is wall time: they tell liveness, not simulated state).
    """

    def __init__(self, bus: Any) -> None:
        self.bus = bus
        self.clock = bus.clock
        self.live = bool(getattr(bus.clock, "live", False))
        self.heap: list = []            # (due s, order, sub, item)
        self._order = itertools.count()
        self._lock = threading.Lock()
        self.busy: dict = {}            # node -> simulated time it is free again, s
        self.stats = LockstepStats()
        self.charged: dict[str, float] = collections.defaultdict(float)   # node name -> charged compute, s
        self.dropped = 0                # latest-QoS items superseded while their node was busy
        self._delay = 0.0               # the running call's link delay (its output leaves that much later)

    @property
    def agenda(self) -> list:
        """The queued items (tests: empty after a drain)."""
        return [(sub, item) for _, _, sub, item in self.heap]

    def enqueue(self, sub: Subscription, item: Any) -> None:
        """Queue ``item`` for ``sub`` (any thread): due when the running handler's output leaves."""
        if sub.topic.name in WALL_TOPICS:
            due = self.clock.now()
        else:
            due = self.clock.stamp()
        with self._lock:
            key = (due, next(self._order))
            sub.newest = key
            heapq.heappush(self.heap, (key[0], key[1], sub, item))

    def next_due(self) -> float | None:
        """Due time of the earliest queued item or timer, s (None: nothing scheduled)."""
        t = self.heap[0][0] if self.heap else None
        tm = self.clock.next_due(math.inf)
        if tm is not None and (t is None or tm.due < t):
            t = tm.due
        return t

    async def _charged(self, node: Node, cost: float, call, delay: float = 0.0) -> None:
        """Run ``call`` (an awaitable) as ``node``'s work of ``cost`` s: busy, output stamped at the end (and
        ``delay`` s later again: a link's latency, during which the node is free)."""
        clock = self.clock
        if not self.live:
            await call
            return
        end = clock.now() + cost
        if cost > 0.0:
            self.busy[node] = end
            self.charged[node.name] += cost
        clock.emit = end + delay
        self._delay = delay
        try:
            await call
        finally:
            clock.emit = None
            self._delay = 0.0

    def charge(self, node: Node, seconds: float) -> None:
        """The running call of ``node`` takes ``seconds`` more of simulated time (live clock only; outside a
        scheduled call nothing happens)."""
        clock = self.clock
        if not self.live or clock.emit is None or not seconds > 0.0:
            return
        clock.emit += seconds
        self.busy[node] = clock.emit - self._delay
        self.charged[node.name] += seconds

    async def drain(self) -> None:
        """Handle every queued item due now (and what their handlers publish that is due now)."""
        heap, clock = self.heap, self.clock
        while heap and heap[0][0] <= clock.now():
            with self._lock:
                due, order, sub, item = heapq.heappop(heap)
            if sub._closed:
                continue
            node = sub.node
            if sub.topic.name not in WALL_TOPICS:
                free = self.busy.get(node, -math.inf)
                if free > clock.now():          # the node is still working: the item waits for it
                    with self._lock:
                        heapq.heappush(heap, (free, order, sub, item))
                    continue
                if self.live and sub.qos is not QoS.KEEP_ALL and sub.newest is not None and sub.newest[
                    1] != order \
                        and sub.newest[0] <= clock.now():
                    self.dropped += 1           # a newer item for this latest-QoS subscription is due
                    sub.stats.dropped += 1
                    continue
                await self._charged(node, sub.sim_cost, sub.handle_now(item))
            else:
                await sub.handle_now(item)
            self.stats.handled += 1

    async def advance(self, t: float) -> None:
        """Move the clock to ``t`` s, in due order: fire every timer due at or before ``t`` (the clock reads
        its due time while it runs; a timer whose node is busy fires when it is free) and deliver every queued
        item due by then, handling what they publish; then set the clock to ``t``."""
        clock = self.clock
        if not clock.started:
            clock.set(t)
        while True:
            await self.drain()
            tm = clock.next_due(t)
            item_due = self.heap[0][0] if self.heap else math.inf
            if tm is None and item_due > t:
                break
            if tm is None or item_due < tm.due:
                clock.set(item_due)
                continue
            free = self.busy.get(tm.node, -math.inf)
            if free > tm.due:                    # its node is busy: the tick waits for it
                tm.due = free
                continue
            clock.set(tm.due)
            tm.due += tm.period
            if tm.due <= clock.now():           # overran: restart the schedule rather than burst
                tm.due = clock.now() + tm.period
            await self._charged(tm.node, tm.sim_cost, tm.node._fire(tm.callback), tm.sim_delay)
            self.stats.timers += 1
        clock.set(t)


#: topics whose content is wall time (liveness), handled on arrival without charge on a simulated clock
WALL_TOPICS = frozenset({"/diagnostics"})


async def run_live(bus: Any, until: float | None, stopped, rtf: float | None = None) -> LockstepStats:
    """Drive the live simulated graph of ``bus`` (a container's :class:`~flexsheet.runtime.bus.Bus` on a live
    :class:`~flexsheet.runtime.clock.SimClock`; launch files' ``clock: sim``) for ``until`` s of simulated
    time from where its clock stands (:data:`SIM_EPOCH` if unset; None: until ``stopped()`` is true, e.g. a
    required node ended). The caller starts it once every node of the container is active (as ROS 2 lifecycle
    nodes); time then advances only when everything due has been handled: from one event (a timer, a delivery)
    to the next. The loop yields to asyncio between events, so signals, heartbeats and subscribers outside the
    process are served. ``rtf``: pace simulated time at most ``rtf`` x wall time (Gazebo's
    ``real_time_factor``; None: as fast as the handlers allow): before an event at simulated ``t`` it waits
    until ``(t - epoch) / rtf`` wall seconds have passed. Pacing only waits, so the events and what they
    publish are the same. Returns the statistics, kept up to date while it runs (``bag_s``: simulated seconds,
    ``wall_s``, ``speed`` = the real-time factor)."""
    ls = bus.lockstep
    if not ls.clock.started:
        ls.clock.set(SIM_EPOCH)
    epoch = ls.clock.now()
    t0 = time.monotonic()
    end = math.inf if until is None else epoch + until
    st = ls.stats
    n = 0
    while not stopped():
        nxt = ls.next_due()
        if nxt is None:
            await asyncio.sleep(0.001)
            continue
        if rtf is not None:
            lag = (min(nxt, end) - epoch) / rtf - (time.monotonic() - t0)
            if lag > 0:   # ahead of the wall clock: wait (in slices, so a stop is heard)
                await asyncio.sleep(min(lag, 0.05))
                continue
        if nxt > end:
            await ls.advance(end)
            break
        await ls.advance(nxt)
        n += 1
        if n % 8 == 0:
            await asyncio.sleep(0)   # serve the loop: signals, heartbeats, sockets
        st.bag_s = ls.clock.now() - epoch
        st.wall_s = time.monotonic() - t0
    st.bag_s = ls.clock.now() - epoch
    st.wall_s = time.monotonic() - t0
    return st


def check(player: Node) -> Lockstep:
    """The lockstep scheduler of ``player``'s container; raises :class:`ConfigError` (exit status 78) when the
    player is not in a lockstep container, or asks for ``loop`` (replayed time cannot go back)."""
    ls = getattr(player, "_lockstep", None)
    if ls is None:
        raise ConfigError(f"{player.name}: mode=lockstep needs the player in a container with the nodes it "
                          "drives (container: NAME on the player and on each of them, docs/realtime.md)")
    if getattr(player.params, "loop", False):
        raise ConfigError(f"{player.name}: mode=lockstep cannot loop (the replayed clock would go back)")
    return ls


async def play(player: Node, messages=None) -> LockstepStats:
    """Play the bag of ``player`` (its params ``file``, ``topics``, ``start_delay``, ``exit_when_done``) into
    its container in lockstep (see the module docstring). ``messages``: an iterable of
    :class:`flexsheet.runtime.bag_read.BagMessage` to play instead of reading ``file`` (tests). Sets
    ``player.sent`` and ``player.done`` (if it has them); logs the replay speed; returns the statistics.
    """
    ls = check(player)
    p = player.params
    await asyncio.sleep(getattr(p, "start_delay", 0.0))  # wall time: subscribers outside the process connect
    while not player._bus.ready():  # every node of the container finished its setup (FEM precompute)
        await asyncio.sleep(0.01)
    if messages is None:
        messages = read_bag(p.file, list(p.topics) or None)

    latched = {t.name for t in T.ALL if t.latched}
    st = ls.stats
    tr = player.transport
    t0 = time.monotonic()
    first = last = None
    for m in messages:
        if first is None:
            first = m.log_time
        last = m.log_time
        await ls.advance(m.log_time)
        if m.topic in latched:
            tr.set_latched(m.topic, m.frames)
        tr.send(m.frames)
        await ls.drain()
        st.messages += 1
        if hasattr(player, "sent"):
            player.sent = st.messages
    st.wall_s = time.monotonic() - t0
    st.bag_s = (last - first) if first is not None else 0.0
    player.log.info("lockstep: %d messages, %.1f s of bag in %.2f s (%.1fx real time), %d handler calls, "
                    "%d timer ticks", st.messages, st.bag_s, st.wall_s, st.speed, st.handled, st.timers)
    done = getattr(player, "done", None)
    if done is not None:
        done.set()
    if getattr(p, "exit_when_done", False):
        await asyncio.sleep(0.2)  # let the last frames leave the sockets
        player.shutdown()
    return st
