"""The transport interface a node sends and receives through, and an in-process twin of it for tests.

A transport moves encoded multipart frames (see :mod:`flexsheet.runtime.codec`) between nodes: the ZeroMQ one
(:class:`flexsheet.runtime.zmq.transport.ZmqTransport`, the package :mod:`flexsheet.runtime.zmq` is the only
code that talks to ZeroMQ), a composable container's (:class:`flexsheet.runtime.bus.ContainerTransport`), or
:class:`InProcTransport` in one process, for node tests (:mod:`flexsheet.runtime.testing`).

Errors: :class:`TransportError` when an endpoint cannot be bound (address in use, bad address).
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["Transport", "TransportError", "InProcTransport", "FramesHandler"]

FramesHandler = Callable[[list], None]


class TransportError(RuntimeError):
    """An endpoint could not be bound or connected (message names the endpoint and the reason)."""


class Transport:
    """Interface: ``start``, ``send``, ``subscribe``, ``set_latched``, ``close`` (called on the loop thread),
    plus ``wants`` and ``send_remote`` for the node's publish path.

    ``threadsafe_send``: True when ``send``/``send_remote``/``set_latched``/``wants`` may be called from any
    thread (else the node marshals them onto its loop). ``bus``: the in-process bus of a composable container
    (:class:`flexsheet.runtime.bus.Bus`), None for a node alone in its process.
    """

    endpoint: str = ""
    threadsafe_send: bool = False
    bus = None

    async def start(self, on_frames: FramesHandler) -> None:
        raise NotImplementedError

    def send(self, frames: list) -> bool:
        """Send one message to every subscriber; returns False if it was dropped (peer queue full)."""
        raise NotImplementedError

    def send_remote(self, frames: list) -> bool:
        """Send one message to the subscribers outside this process (the node delivered it in-process)."""
        return self.send(frames)

    def wants(self, topic: bytes) -> bool:
        """True if a subscriber that needs encoded frames may want ``topic`` (default: always)."""
        return True

    def subscribe(self, topic: str) -> None:
        raise NotImplementedError

    def set_latched(self, topic: str, frames: list) -> None:
        """Remember ``frames`` as the last value of latched ``topic`` (resent to new subscribers)."""
        raise NotImplementedError

    def set_latched_remote(self, topic: str, frames: list) -> None:
        """:meth:`set_latched` for the subscribers outside this process only (the node's publish path)."""
        self.set_latched(topic, frames)

    def link_report(self) -> str:
        """One line naming the peer endpoints this node has heard nothing from for a while (no link; see
        :meth:`flexsheet.runtime.zmq.linkwatch.LinkWatch.report`), or "" (also for a transport without links,
        or a container's node: its container's SUB socket is asked)."""
        sock = getattr(self.bus, "sub", None)
        return sock.report() if sock is not None else ""

    def close(self) -> None:
        raise NotImplementedError


class InProcTransport(Transport):
    """In-process transport: ``send`` records frames and loops them back; ``deliver`` injects frames.

    Used by :class:`flexsheet.runtime.testing.NodeHarness`; frames still go through the real codec.
    """

    def __init__(self) -> None:
        self.endpoint = "inproc://harness"
        self.sent: list[list] = []
        self.topics: set[str] = set()
        self._on_frames: FramesHandler | None = None
        self.listeners: list[FramesHandler] = []

    async def start(self, on_frames: FramesHandler) -> None:
        self._on_frames = on_frames

    def subscribe(self, topic: str) -> None:
        self.topics.add(topic)

    def send(self, frames: list) -> bool:
        frames = [bytes(f) if not isinstance(f, bytes) else f for f in frames]
        self.sent.append(frames)
        for listener in self.listeners:
            listener(frames)
        self.deliver(frames)
        return True

    def deliver(self, frames: list) -> None:
        """Hand ``frames`` to the node as if received from the wire (only subscribed topics)."""
        topic = bytes(frames[0]).decode(errors="replace") if frames else ""
        if topic in self.topics and self._on_frames is not None:
            self._on_frames(list(frames))

    def set_latched(self, topic: str, frames: list) -> None:
        pass

    def close(self) -> None:
        self._on_frames = None

