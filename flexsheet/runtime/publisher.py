"""A node's typed publisher of one topic (:class:`Publisher`, made by
:meth:`flexsheet.runtime.node.Node.publisher`) and the counters of a publisher or subscription."""

from __future__ import annotations

import itertools
import threading
from typing import Any

from flexsheet.runtime.codec import encode
from messages import Header, Message, Topic

__all__ = ["Publisher", "TopicCounters"]


class TopicCounters:
    """What a publisher or a subscription counts: messages, drops, rejections, and the rate over the last
    heartbeat period, Hz (read into the node's heartbeat)."""

    __slots__ = ("count", "dropped", "rejected", "last_count", "rate")

    def __init__(self) -> None:
        self.count = self.dropped = self.rejected = self.last_count = 0
        self.rate = 0.0


class Publisher:
    """Typed publisher for one topic of ``node`` (its :class:`~flexsheet.runtime.node.Node`). ``publish``
    checks the type and is safe to call from any thread."""

    def __init__(self, node: Any, topic: Topic) -> None:
        self.node, self.topic = node, topic
        self.name = topic.name
        self.name_b = topic.name.encode()
        self.latched = bool(topic.latched)
        self._seq = itertools.count()  # next() is atomic under the GIL: no lock per message
        self.stats = TopicCounters()

    def header(self, frame_id: str = "display", stamp: float | None = None) -> Header:
        """Next :class:`Header` for this publisher: ``seq`` incremented, ``stamp`` = the clock's
        :meth:`flexsheet.runtime.clock.Clock.stamp` if None (the wall clock's now; on a live simulated clock,
        when the output leaves)."""
        return Header(stamp=self.node._clock.stamp() if stamp is None else float(stamp), frame_id=frame_id,
                      seq=next(self._seq))

    def publish(self, msg: Message) -> None:
        """Deliver ``msg`` to the subscribers in this process (the object itself) and, encoded once, to those
        outside it (only when there are any, or the topic is latched). Raises ``TypeError`` naming expected vs
        given type."""
        if type(msg) is not self.topic.type:
            raise TypeError(f"{self.name}: expected {self.topic.type.__name__}, got {type(msg).__name__}")
        node = self.node
        self.stats.count += 1
        bus = node._bus
        frames = bus.publish(self, msg) if bus is not None else None
        tr = node.transport
        if self.latched or tr.wants(self.name_b):
            if frames is None:
                frames = encode(self.name, msg)
            if tr.threadsafe_send or threading.get_ident() == node._loop_tid:
                node._send(self, frames)
            else:
                node._loop.call_soon_threadsafe(node._send, self, frames)

