"""A node's ZeroMQ transport (:class:`ZmqTransport`): one bound XPUB, one SUB connected to every peer."""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterable

import zmq

from flexsheet.runtime.transport import FramesHandler, Transport, TransportError
from flexsheet.runtime.zmq.curve import AllowList, CurveConfig, allow_list
from flexsheet.runtime.zmq.linkwatch import LinkWatch
from flexsheet.runtime.zmq.subscriber import SubLinks
from flexsheet.runtime.zmq.xpub import SMALL_MESSAGE_BYTES, XPub

__all__ = ["ZmqTransport"]


class ZmqTransport(Transport):
    """Brokerless pub/sub over ZeroMQ: bind one XPUB at ``endpoint``, connect one SUB to every ``peers``.

    Parameters
    ----------
    endpoint : str
        ZeroMQ endpoint to bind (``tcp://127.0.0.1:7101``, ``tcp://10.0.0.1:7101``, ``ipc:///tmp/x``);
        empty string: this node publishes nothing on the wire (a pure subscriber tool).
    peers : iterable of str
        Endpoints to connect the SUB socket to (every publisher of the graph; may include ``endpoint``).
    sndhwm, rcvhwm : int
        ZeroMQ high-water marks in messages (drops beyond them are counted by the node via seq gaps).
    largest_bytes : int
        the largest message the node publishes, bytes: with ``sndhwm`` it sets the publisher's high-water mark
        once, before bind (:class:`XPub`).
    drain_period : float
        0 (default): received messages are handled as soon as the SUB socket is readable (one loop wake-up per
        ready edge). > 0 s: the SUB socket is drained only every ``drain_period`` s, in one batch — for a node
        that wants the newest of many inputs rather than each one on time (the Foxglove bridge: ~650 input
        messages/s in the sim, about a third of its CPU was the wake-ups). Messages queue in ZeroMQ meanwhile
        (up to ``rcvhwm``).

    ``send`` is thread-safe (see :class:`XPub`); everything else runs on the loop thread.
    """

    threadsafe_send = True

    def __init__(self, endpoint: str, peers: Iterable[str], *, sndhwm: int = 2000, rcvhwm: int = 20000,
                 curve: CurveConfig | None = None, drain_period: float = 0.0,
                 largest_bytes: int = SMALL_MESSAGE_BYTES) -> None:
        if not (drain_period >= 0.0 and drain_period < 10.0):
            raise ValueError(f"drain_period must be in [0, 10) s, got {drain_period!r}")
        self.endpoint = endpoint
        self.drain_period = float(drain_period)
        self.curve = curve
        self._auth = None
        self.allow: AllowList | None = None
        self.peers = [p for p in dict.fromkeys(peers) if p]
        self.sndhwm, self.rcvhwm = sndhwm, rcvhwm
        self.largest_bytes = largest_bytes
        self.ctx: zmq.Context | None = None
        self.xpub: XPub | None = None
        self.links: SubLinks | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._on_frames: FramesHandler | None = None
        #: called on the loop after each drain of the SUB sockets (the node dispatches what it queued)
        self.on_drained: Callable[[], None] | None = None
        self._poll_task: asyncio.Task | None = None

    @property
    def pub(self) -> zmq.Socket | None:
        """The bound XPUB socket (None without an endpoint)."""
        return self.xpub.sock if self.xpub is not None else None

    async def start(self, on_frames: FramesHandler) -> None:
        self._loop = asyncio.get_running_loop()
        self._on_frames = on_frames
        self.ctx = zmq.Context()  # one context per process, created inside the running loop
        curve = self.curve
        if curve is not None and self.endpoint:
            self._auth, self.allow = allow_list(self.ctx, curve)
        if self.endpoint:
            try:
                self.xpub = XPub(self.ctx, self.endpoint, curve, self.sndhwm, self._loop, self.largest_bytes)
            except TransportError:
                self.close()
                raise
            self.endpoint = self.xpub.endpoint
        self.links = SubLinks(self.ctx, self.peers, curve, self.rcvhwm, self.close)
        if self.drain_period <= 0.0:
            for fd in self.links.fds():
                self._loop.add_reader(fd, self._drain_sub)
        # ZeroMQ's FD is edge-triggered: a slow safety poll catches any edge lost between drains (with a
        # ``drain_period`` it is the only drain).
        self._poll_task = self._loop.create_task(self._safety_poll())

    @property
    def sub(self) -> zmq.Socket | None:
        """The SUB socket connected to every peer (None before :meth:`start`)."""
        return self.links.sock if self.links is not None else None

    @property
    def watch(self) -> LinkWatch | None:
        """The :class:`LinkWatch` of :attr:`sub` (None before :meth:`start`)."""
        return self.links.watch if self.links is not None else None

    def subscribe(self, topic: str) -> None:
        assert self.links is not None, "start() first"
        self.links.subscribe(topic.encode())
        self._drain_sub()

    def wants(self, topic: bytes) -> bool:
        return self.xpub is not None and self.xpub.wants(topic)

    def send(self, frames: list) -> bool:
        xpub = self.xpub
        return xpub is not None and xpub.send(frames)

    def set_latched(self, topic: str, frames: list) -> None:
        if self.xpub is not None:
            self.xpub.set_latched(topic, frames)

    def add_peer(self, endpoint: str) -> None:
        """Connect the SUB socket to one more publisher endpoint (used by tools that discover late)."""
        if endpoint and endpoint not in self.peers and self.links is not None:
            self.peers.append(endpoint)
            self.links.add_peer(endpoint)

    def remove_peer(self, endpoint: str) -> bool:
        """Disconnect from an endpoint :meth:`add_peer` added; False when it was not a peer."""
        if endpoint in self.peers and self.links is not None:
            self.peers.remove(endpoint)
            return self.links.remove_peer(endpoint)
        return False

    def link_report(self) -> str:
        return self.links.report() if self.links is not None else ""

    def _drain_sub(self) -> None:
        links = self.links
        if links is not None:
            try:
                links.drain(self._on_frames)
            finally:
                if self.on_drained is not None:
                    self.on_drained()

    async def _safety_poll(self) -> None:
        while True:
            await asyncio.sleep(self.drain_period or 0.05)
            self._drain_sub()
            if self.xpub is not None:
                self.xpub.drain()
            if self.links is not None:
                self.links.poll()

    def close(self) -> None:
        if self._poll_task is not None:
            self._poll_task.cancel()
        if self.xpub is not None:
            self.xpub.close()
        links, self.links = self.links, None
        if links is not None:
            if self._loop is not None:
                for fd in links.fds():
                    try:
                        self._loop.remove_reader(fd)
                    except Exception:  # noqa: BLE001 - loop may be closed already
                        pass
            links.close()
        if self._auth is not None:
            self._auth.stop()
            self._auth = None
        if self.ctx is not None:
            self.ctx.term()
            self.ctx = None

