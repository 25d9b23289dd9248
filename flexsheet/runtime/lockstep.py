"""Deterministic, fast replay: a bag played into a container in lockstep, on the bag's clock.

``flexsheet launch launch/replay.yaml --set player.mode=lockstep`` plays the bag into the nodes of the
player's container as fast as they can handle it: each message is delivered, handled by every subscription
it reaches, and the messages those handlers publish are delivered and handled in turn (breadth first, in a
fixed order: subscription order in the container) before the next bag message goes out. QoS ``latest``
therefore never drops, and no two handlers ever run at once: the result does not depend on thread timing.

The container's nodes run on the bag's clock (:class:`flexsheet.runtime.node.SimClock`, like ROS's
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
import time
from typing import TYPE_CHECKING, Any

from flexsheet.runtime.node import ConfigError

if TYPE_CHECKING:
    from flexsheet.runtime.container import Bus
    from flexsheet.runtime.node import Node, Subscription

__all__ = ["Lockstep", "check", "play", "LockstepStats"]


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
        return {"messages": self.messages, "handled": self.handled, "timers": self.timers, "bag_s": self.bag_s,
                "wall_s": self.wall_s, "speed": self.speed}


class Lockstep:
    """The lockstep scheduler of a container's :class:`~flexsheet.runtime.container.Bus`: subscriptions queue
    their input here (:meth:`enqueue`, any thread) instead of on their consumers, and :meth:`drain` handles it
    one item at a time on the loop."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self.clock = bus.clock
        self.agenda: collections.deque = collections.deque()
        self.stats = LockstepStats()

    def enqueue(self, sub: Subscription, item: Any) -> None:
        self.agenda.append((sub, item))  # deque.append is atomic: safe from any thread

    async def drain(self) -> None:
        """Handle every queued item, and what their handlers publish, until nothing is left."""
        agenda = self.agenda
        while agenda:
            sub, item = agenda.popleft()
            if sub._closed:
                continue
            await sub.handle_now(item)
            self.stats.handled += 1

    async def advance(self, t: float) -> None:
        """Fire, in due order, every timer due at or before ``t`` s (the clock reads each one's due time while
        it runs, and what it publishes is handled), then set the clock to ``t``."""
        clock = self.clock
        if not clock.started:
            clock.set(t)
        while True:
            tm = clock.next_due(t)
            if tm is None:
                break
            clock.set(tm.due)
            tm.due += tm.period
            await tm.node._fire(tm.callback)
            self.stats.timers += 1
            await self.drain()
        clock.set(t)


def check(player: Node) -> Lockstep:
    """The lockstep scheduler of ``player``'s container; raises :class:`ConfigError` (exit status 78) when the
    player is not in a lockstep container, or asks for ``loop`` (replayed time cannot go back)."""
    ls = getattr(player, "_lockstep", None)
    if ls is None:
        raise ConfigError(f"{player.name}: mode=lockstep needs the player in a container with the nodes it drives "
                          "(container: NAME on the player and on each of them, docs/realtime.md)")
    if getattr(player.params, "loop", False):
        raise ConfigError(f"{player.name}: mode=lockstep cannot loop (the replayed clock would go back)")
    return ls


async def play(player: Node, messages=None) -> LockstepStats:
    """Play the bag of ``player`` (its params ``file``, ``topics``, ``start_delay``, ``exit_when_done``) into its
    container in lockstep (see the module docstring). ``messages``: an iterable of
    :class:`flexsheet.runtime.bag.BagMessage` to play instead of reading ``file`` (tests). Sets
    ``player.sent`` and ``player.done`` (if it has them); logs the replay speed; returns the statistics.
    """
    ls = check(player)
    p = player.params
    await asyncio.sleep(getattr(p, "start_delay", 0.0))  # wall time: subscribers outside the process connect
    while not player._bus.ready():  # every node of the container finished its setup (FEM precompute)
        await asyncio.sleep(0.01)
    if messages is None:
        from flexsheet.runtime.bag import read_bag

        messages = read_bag(p.file, list(p.topics) or None)
    from messages import topics as T

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
