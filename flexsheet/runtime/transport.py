"""Transports: the only module that talks to ZeroMQ, plus an in-process twin for tests.

A transport moves encoded multipart frames (see :mod:`flexsheet.runtime.codec`) between nodes:

* :class:`ZmqTransport` — brokerless. Each node binds **one** XPUB socket at its endpoint (from the launch
  file) and connects **one** SUB socket to every peer endpoint of the graph; SUB subscribes by topic name,
  so filtering happens at the publisher. XPUB sees each new subscription, which is how latched topics
  resend their last value to late joiners without any ``sleep()``.
  Readiness comes from the sockets' file descriptors through ``loop.add_reader`` and every ready message
  is drained with non-blocking ``recv`` — no ``zmq.asyncio`` futures on the hot path (pyzmq's own
  ``zmq/asyncio.py`` allocates a future per receive, which is what doubles its latency).
* :class:`InProcTransport` — the same interface in one process, for node tests (:mod:`flexsheet.runtime.testing`).

Errors: :class:`TransportError` when an endpoint cannot be bound (address in use, bad address).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import zmq

__all__ = ["Transport", "ZmqTransport", "InProcTransport", "TransportError", "CurveConfig"]

log = logging.getLogger(__name__)
# plain ints: pyzmq's enum flags cost a Python enum operation each (measurable per message)
_EVENTS, _POLLIN, _NOBLOCK, _RCVMORE = int(zmq.EVENTS), int(zmq.POLLIN), int(zmq.NOBLOCK), int(zmq.RCVMORE)
_SNDMORE = int(zmq.SNDMORE)
FramesHandler = Callable[[list], None]


class TransportError(RuntimeError):
    """An endpoint could not be bound or connected (message names the endpoint and the reason)."""


@dataclass
class CurveConfig:
    """ZeroMQ CURVE security for one node (RFC 26 CurveZMQ, via pyzmq's ``zmq.auth``).

    ``public_key``/``secret_key``: this host's Z85 keypair (from ``flexsheet keys generate``).
    ``server_keys``: peer endpoint → the Z85 public key its publisher must prove it owns; a peer whose
    publisher lacks that secret key fails the handshake and none of its messages arrive.
    ``allowed_clients``: Z85 public keys allowed to subscribe to this node's publisher (ZAP check);
    any other subscriber is refused. Source: pyzmq ``zmq.auth`` and ``examples/security``.
    """

    public_key: bytes
    secret_key: bytes
    server_keys: dict[str, bytes] = field(default_factory=dict)
    allowed_clients: list[bytes] = field(default_factory=list)


class _AllowList:
    def __init__(self, keys: list[bytes]) -> None:
        self.keys = set(keys)
        self.refused = 0

    def callback(self, domain: str, key: bytes) -> bool:
        ok = key in self.keys
        if not ok:
            self.refused += 1
            log.warning("CURVE: refused a subscriber with an unlisted public key %s", key.decode(errors="replace"))
        return ok


class Transport:
    """Interface: ``start``, ``send``, ``subscribe``, ``set_latched``, ``close``. All called on the loop thread."""

    endpoint: str = ""

    async def start(self, on_frames: FramesHandler) -> None:
        raise NotImplementedError

    def send(self, frames: list) -> bool:
        """Send one message; returns False if it was dropped (peer queue full)."""
        raise NotImplementedError

    def subscribe(self, topic: str) -> None:
        raise NotImplementedError

    def set_latched(self, topic: str, frames: list) -> None:
        """Remember ``frames`` as the last value of latched ``topic`` (resent to new subscribers)."""
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError


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
    """

    def __init__(self, endpoint: str, peers: Iterable[str], *, sndhwm: int = 2000, rcvhwm: int = 20000,
                 curve: CurveConfig | None = None) -> None:
        self.endpoint = endpoint
        self.curve = curve
        self._auth = None
        self.allow: _AllowList | None = None
        self.peers = [p for p in dict.fromkeys(peers) if p]
        self.sndhwm, self.rcvhwm = sndhwm, rcvhwm
        self._latched: dict[bytes, list] = {}
        self.ctx: zmq.Context | None = None
        self.pub: zmq.Socket | None = None
        self.sub: zmq.Socket | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._on_frames: FramesHandler | None = None
        self._poll_task: asyncio.Task | None = None

    async def start(self, on_frames: FramesHandler) -> None:
        self._loop = asyncio.get_running_loop()
        self._on_frames = on_frames
        self.ctx = zmq.Context()  # one context per process, created inside the running loop
        curve = self.curve
        if curve is not None and self.endpoint:
            from zmq.auth.thread import ThreadAuthenticator

            self._auth = ThreadAuthenticator(self.ctx, log=log)
            self._auth.start()
            self.allow = _AllowList(curve.allowed_clients)
            self._auth.configure_curve_callback("*", credentials_provider=self.allow)
        if self.endpoint:
            self.pub = self.ctx.socket(zmq.XPUB)
            self.pub.setsockopt(zmq.LINGER, 0)
            if curve is not None:
                self.pub.curve_secretkey = curve.secret_key
                self.pub.curve_publickey = curve.public_key
                self.pub.curve_server = True
            self.pub.setsockopt(zmq.SNDHWM, self.sndhwm)
            self.pub.setsockopt(zmq.XPUB_VERBOSE, 1)
            try:
                self.pub.bind(self.endpoint)
            except zmq.ZMQError as exc:
                self.close()
                raise TransportError(f"cannot bind publisher endpoint {self.endpoint!r}: {exc}") from None
            if self.endpoint.endswith(":0") or self.endpoint.endswith(":*"):
                self.endpoint = self.pub.getsockopt(zmq.LAST_ENDPOINT).decode()
            self._loop.add_reader(self.pub.getsockopt(zmq.FD), self._drain_pub)
        self.sub = self.ctx.socket(zmq.SUB)
        self.sub.setsockopt(zmq.LINGER, 0)
        self.sub.setsockopt(zmq.RCVHWM, self.rcvhwm)
        self.sub.setsockopt(zmq.RECONNECT_IVL, 100)
        self.sub.setsockopt(zmq.RECONNECT_IVL_MAX, 1000)
        if curve is not None:
            self.sub.curve_secretkey = curve.secret_key
            self.sub.curve_publickey = curve.public_key
        for peer in self.peers:
            try:
                if curve is not None:
                    if peer not in curve.server_keys:
                        raise TransportError(f"CURVE is on but no public key is listed for peer {peer!r}")
                    self.sub.curve_serverkey = curve.server_keys[peer]  # applies to this connect only
                self.sub.connect(peer)
            except zmq.ZMQError as exc:
                self.close()
                raise TransportError(f"cannot connect to peer endpoint {peer!r}: {exc}") from None
        self._loop.add_reader(self.sub.getsockopt(zmq.FD), self._drain_sub)
        # ZeroMQ's FD is edge-triggered: a slow safety poll catches any edge lost between drains.
        self._poll_task = self._loop.create_task(self._safety_poll())

    def subscribe(self, topic: str) -> None:
        assert self.sub is not None, "start() first"
        self.sub.setsockopt(zmq.SUBSCRIBE, topic.encode())
        self._drain_sub()

    def send(self, frames: list) -> bool:
        if self.pub is None or self.pub.closed:
            return False  # shutting down: a late publish from a worker thread is dropped, not an error
        try:
            self.pub.send_multipart(frames, flags=_NOBLOCK, copy=False)
        except zmq.Again:
            return False
        finally:
            # any operation can change the socket's events without the FD firing again
            if self._loop is not None:
                self._loop.call_soon(self._drain_pub)
        return True

    def set_latched(self, topic: str, frames: list) -> None:
        self._latched[topic.encode()] = frames

    def add_peer(self, endpoint: str) -> None:
        """Connect the SUB socket to one more publisher endpoint (used by tools that discover late)."""
        if endpoint and endpoint not in self.peers and self.sub is not None:
            self.peers.append(endpoint)
            self.sub.connect(endpoint)

    def _drain_sub(self) -> None:
        sub = self.sub
        if sub is None or sub.closed:
            return
        handler = self._on_frames
        recv, getsockopt = sub.recv, sub.getsockopt
        while getsockopt(_EVENTS) & _POLLIN:
            try:
                frames = [recv(_NOBLOCK, copy=False)]
            except zmq.Again:
                break
            while getsockopt(_RCVMORE):
                frames.append(recv(_NOBLOCK, copy=False))
            handler(frames)

    def _drain_pub(self) -> None:
        pub = self.pub
        if pub is None or pub.closed:
            return
        while pub.getsockopt(_EVENTS) & _POLLIN:
            try:
                msg = pub.recv(_NOBLOCK)
            except zmq.Again:
                break
            if msg[:1] == b"\x01":  # a subscription: resend latched values it matches
                prefix = msg[1:]
                for topic, frames in self._latched.items():
                    if topic.startswith(prefix):
                        try:
                            pub.send_multipart(frames, flags=zmq.NOBLOCK, copy=False)
                        except zmq.Again:
                            pass

    async def _safety_poll(self) -> None:
        while True:
            await asyncio.sleep(0.05)
            self._drain_sub()
            self._drain_pub()

    def close(self) -> None:
        if self._poll_task is not None:
            self._poll_task.cancel()
        for sock in (self.sub, self.pub):
            if sock is not None and not sock.closed:
                if self._loop is not None:
                    try:
                        self._loop.remove_reader(sock.getsockopt(zmq.FD))
                    except Exception:  # noqa: BLE001 - loop may be closed already
                        pass
                sock.close(linger=0)
        if self._auth is not None:
            self._auth.stop()
            self._auth = None
        if self.ctx is not None:
            self.ctx.term()
            self.ctx = None


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
