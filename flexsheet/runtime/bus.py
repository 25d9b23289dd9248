"""The in-process message bus of a composable container (:mod:`flexsheet.runtime.container`).

Between the nodes of a container a message travels as the frozen message object itself, through the
container's :class:`Bus`: no encode, no decode, no copy, no socket; its numpy arrays are handed on as
read-only views (:func:`freeze_arrays`: a receiver cannot write into the publisher's arrays; the publisher
must not write into an array after publishing it, as with any zero-copy transport). Each node keeps its own
publisher socket at its launch-file endpoint (:class:`ContainerTransport`, a
:class:`flexsheet.runtime.zmq.xpub.XPub`); a message is encoded — once — only when a subscriber outside the
process has asked for its topic or the topic is latched. The bus has the container's one SUB socket
(:class:`flexsheet.runtime.zmq.subscriber.BusSocket`), connected to every endpoint of the graph outside the
container, and hands what arrives to its nodes' subscriptions (decoded and validated there: the wire
boundary).
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable

import numpy as np

from flexsheet.runtime.clock import WALL_CLOCK, Clock
from flexsheet.runtime.codec import encode
from flexsheet.runtime.lockstep import Lockstep
from flexsheet.runtime.node import Node
from flexsheet.runtime.transport import Transport, TransportError
from flexsheet.runtime.zmq.curve import CurveConfig
from flexsheet.runtime.zmq.subscriber import BusSocket
from flexsheet.runtime.zmq.xpub import XPub
from messages import Message
from messages.common import array_spec

__all__ = ["Bus", "ContainerTransport", "freeze_arrays"]

_ARRAY_FIELDS: dict[type, tuple[str, ...]] = {}


def _array_fields(cls: type) -> tuple[str, ...]:
    names = _ARRAY_FIELDS.get(cls)
    if names is None:
        names = _ARRAY_FIELDS[cls] = tuple(n for n,
                                           f in cls.model_fields.items() if array_spec(f) is not None)
    return names


def freeze_arrays(msg: Message) -> Message:
    """Make every numpy array field of ``msg`` a read-only view (in place; the publisher's arrays keep their
    own flags). Returns ``msg``. Cost: one view per writeable array field."""
    d = msg.__dict__
    for name in _array_fields(type(msg)):
        a = d[name]
        if type(a) is np.ndarray and a.flags.writeable:
            ro = a.view()
            ro.flags.writeable = False
            d[name] = ro  # the model is frozen for its users; the runtime swaps in an equal read-only view
    return msg


class Bus:
    """The in-process message bus of one container: routes message objects between its nodes, wire frames
    from the rest of the graph to them, and owns the container's ZeroMQ context and SUB socket.

    ``peers``: publisher endpoints outside the container; ``curve``: this host's CURVE settings (or None);
    ``clock``: the nodes' clock (:data:`~flexsheet.runtime.clock.WALL_CLOCK`, or a
    :class:`~flexsheet.runtime.clock.SimClock` for a lockstep replay, which also creates :attr:`lockstep`).
    """

    def __init__(self, name: str = "container", peers: list[str] | None = None,
                 curve: CurveConfig | None = None,
                 clock: Clock | None = None, rcvhwm: int = 20000) -> None:
        self.name = name
        self.peers = [p for p in dict.fromkeys(peers or []) if p]
        self.curve = curve
        self.clock = clock or WALL_CLOCK
        self.lockstep = None
        if self.clock.simulated:
            self.lockstep = Lockstep(self)
        self.rcvhwm = rcvhwm
        self.nodes: list[Node] = []
        self._prefixes: dict[Node, list[bytes]] = {}
        self._targets: dict[bytes, tuple] = {}
        self._latched_obj: dict[bytes, Message] = {}
        self._latched_frames: dict[bytes, list] = {}
        self.sub: BusSocket | None = None
        self.loop: asyncio.AbstractEventLoop | None = None
        self._loop_tid: int | None = None
        self._poll_task: asyncio.Task | None = None
        self.local_messages = 0  # messages handed on in-process (objects)
        self.ready_check: Callable[[], bool] = lambda: all(n.ready for n in self.nodes)

    # ------------------------------------------------------------------ lifecycle
    async def start(self) -> None:
        """Create the context (with the CURVE authenticator when ``curve``) and the SUB socket."""
        if self.sub is not None:
            return
        self.loop = asyncio.get_running_loop()
        self._loop_tid = threading.get_ident()
        self.sub = BusSocket(self.peers, self.curve, self.rcvhwm)
        for fd in self.sub.fds():
            self.loop.add_reader(fd, self._drain_sub)
        self._poll_task = self.loop.create_task(self._safety_poll())

    def close(self) -> None:
        if self._poll_task is not None:
            self._poll_task.cancel()
        if self.sub is not None:
            if not self.sub.closed:
                for fd in self.sub.fds():
                    try:
                        self.loop.remove_reader(fd)
                    except Exception:  # noqa: BLE001 - loop may be closed already
                        pass
            self.sub.close()
            self.sub = None

    async def _safety_poll(self) -> None:
        while True:  # ZeroMQ FDs are edge-triggered: catch an edge lost between drains
            await asyncio.sleep(0.05)
            self._drain_sub()
            for node in list(self.nodes):
                xpub = getattr(node.transport, "xpub", None)
                if xpub is not None:
                    xpub.drain()

    def ready(self) -> bool:
        """True when every node of the container finished its setup (the lockstep player waits for it)."""
        return self.ready_check()

    # ------------------------------------------------------------------ membership
    def attach(self, node: Node) -> None:
        if node not in self.nodes:
            self.nodes.append(node)
            self._prefixes.setdefault(node, [])
            self.changed()

    def detach(self, node: Node) -> None:
        if node in self.nodes:
            self.nodes.remove(node)
        prefixes = self._prefixes.pop(node, [])
        if self.sub is not None and not self.sub.closed:
            for p in prefixes:
                self.sub.unsubscribe(p)
        self.changed()

    def changed(self) -> None:
        """Forget the routing cache (a node or a subscription came or went)."""
        self._targets = {}

    def subscribe(self, node: Node, topic: str) -> None:
        """``node`` wants ``topic`` (a prefix, as ZeroMQ's): from the wire and from the other nodes; latched
        values already published in the container are handed to it now."""
        prefix = topic.encode()
        self._prefixes.setdefault(node, []).append(prefix)
        self.changed()
        if self.sub is not None:
            self.sub.subscribe(prefix)
            self._drain_sub()
        raw = _is_raw(node)
        for name_b, msg in list(self._latched_obj.items()):
            if name_b.startswith(prefix):
                if raw:
                    node._on_frames(encode(name_b.decode(), msg))
                else:
                    node._on_local(name_b, msg)
        for name_b, frames in list(self._latched_frames.items()):
            if name_b.startswith(prefix):
                node._on_frames(frames)

    def targets(self, topic: bytes) -> tuple:
        """``(node, raw)`` of every node of the container subscribed to ``topic`` (cached)."""
        t = self._targets.get(topic)
        if t is None:
            out = []
            for node in self.nodes:
                if any(topic.startswith(p) for p in self._prefixes.get(node, ())):
                    raw = _is_raw(node)
                    if raw or topic in node._subs_b:
                        out.append((node, raw))
            t = self._targets[topic] = tuple(out)
        return t

    # ------------------------------------------------------------------ routing
    def publish(self, pub, msg: Message) -> list | None:
        """Hand ``msg`` (published by ``pub``, any thread) to the container's subscribers as the object
        itself; a node that takes raw frames (the recorder) gets it encoded. Returns those frames if it had to
        encode (the publisher reuses them for the wire), else None."""
        name_b = pub.name_b
        if pub.latched:
            self._latched_obj[name_b] = freeze_arrays(msg)
        targets = self._targets.get(name_b)
        if targets is None:
            targets = self.targets(name_b)
        if not targets:
            return None
        freeze_arrays(msg)
        frames = None
        for node, raw in targets:
            if raw:
                if frames is None:
                    frames = encode(pub.name, msg)
                self._raw(node, frames)
            else:
                node._on_local(name_b, msg)
        self.local_messages += 1
        return frames

    def publish_frames(self, frames: list) -> None:
        """Hand raw frames a node sent itself (the bag player) to the container's subscribers (decoded and
        validated by each subscription, as frames from the wire are)."""
        t = frames[0]
        for node, raw in self.targets(t if type(t) is bytes else bytes(t)):
            if raw:
                self._raw(node, frames)
            else:
                node._on_frames(frames)

    def latch_frames(self, topic: str, frames: list) -> None:
        self._latched_frames[topic.encode()] = frames

    def _raw(self, node: Node, frames: list) -> None:
        if threading.get_ident() == self._loop_tid:
            node._on_frames(frames)
        else:  # a raw listener (the recorder) runs on the loop
            self.loop.call_soon_threadsafe(node._on_frames, frames)

    def _on_wire(self, frames: list) -> None:
        t = frames[0]
        for node, _ in self.targets(t if type(t) is bytes else bytes(t)):
            node._dispatch.frames(frames)

    def _drain_sub(self) -> None:
        """Hand what the SUB sockets hold to the nodes; then each node calls the async handlers of what it
        queued (:meth:`flexsheet.runtime.subscription.Dispatcher.drained`)."""
        if self.sub is not None:
            try:
                self.sub.drain(self._on_wire)
            finally:
                for node in tuple(self.nodes):
                    node._dispatch.drained()


def _is_raw(node: Node) -> bool:
    """True for a node that takes raw frames itself (overrides ``Node._on_frames``, as the recorder does)."""
    return type(node)._on_frames is not Node._on_frames


class ContainerTransport(Transport):
    """The transport of one node in a container: its own XPUB at its endpoint, the container's :class:`Bus`
    for everything in-process and for the SUB side. ``send`` (raw frames, e.g. the bag player) reaches the
    container's nodes and the wire; the node's publish path uses the bus and :meth:`send_remote`."""

    threadsafe_send = True

    def __init__(self, bus: Bus, endpoint: str, sndhwm: int = 2000) -> None:
        self.bus = bus
        self.endpoint = endpoint
        self.sndhwm = sndhwm
        self.xpub: XPub | None = None
        self.node: Node | None = None

    @property
    def peers(self) -> list[str]:
        return self.bus.peers

    def attach(self, node: Node) -> None:
        self.node = node

    async def start(self, on_frames) -> None:
        await self.bus.start()
        self.bus.attach(self.node)
        if self.endpoint:
            try:
                curve = self.node.config.curve or self.bus.curve  # the node's own key (the bus: the host's)
                self.xpub = XPub(self.bus.sub.ctx, self.endpoint, curve, self.sndhwm,
                                 asyncio.get_running_loop(),
                                 self.node.LARGEST_MESSAGE_BYTES)
            except TransportError:
                self.bus.detach(self.node)
                raise
            self.endpoint = self.xpub.endpoint

    def subscribe(self, topic: str) -> None:
        self.bus.subscribe(self.node, topic)

    def wants(self, topic: bytes) -> bool:
        return self.xpub is not None and self.xpub.wants(topic)

    def send(self, frames: list) -> bool:
        self.bus.publish_frames(frames)
        return self.send_remote(frames)

    def send_remote(self, frames: list) -> bool:
        xpub = self.xpub
        return xpub is None or xpub.send(frames)

    def set_latched(self, topic: str, frames: list) -> None:
        self.bus.latch_frames(topic, frames)
        self.set_latched_remote(topic, frames)

    def set_latched_remote(self, topic: str, frames: list) -> None:
        if self.xpub is not None:
            self.xpub.set_latched(topic, frames)

    def close(self) -> None:
        if self.node is not None:
            self.bus.detach(self.node)
        if self.xpub is not None:
            self.xpub.close()
