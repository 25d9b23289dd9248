"""Transports: the only module that talks to ZeroMQ, plus an in-process twin for tests.

A transport moves encoded multipart frames (see :mod:`flexsheet.runtime.codec`) between nodes:

* :class:`ZmqTransport` — brokerless. Each node binds **one** XPUB socket at its endpoint (from the launch
  file) and connects **one** SUB socket to every peer endpoint of the graph (plus one per set of publishers
  a guarded topic is restricted to, :class:`SubLinks`); SUB subscribes by topic name, so filtering happens
  at the publisher. XPUB sees each new subscription, which is how latched topics
  resend their last value to late joiners without any ``sleep()``.
  Readiness comes from the sockets' file descriptors through ``loop.add_reader`` and every ready message
  is drained with non-blocking ``recv`` — no ``zmq.asyncio`` futures on the hot path (pyzmq's own
  ``zmq/asyncio.py`` allocates a future per receive, which is what doubles its latency).
* :class:`InProcTransport` — the same interface in one process, for node tests (:mod:`flexsheet.runtime.testing`).
* :class:`XPub` — one bound XPUB socket, shared by :class:`ZmqTransport` and the composable container
  (:mod:`flexsheet.runtime.container`): a send is thread-safe (one lock per socket, so a node's worker thread
  sends without waking the event loop), and the socket's subscriptions are tracked (``XPUB_VERBOSE``: every
  subscribe, and an unsubscribe when the last subscriber of a prefix leaves or disconnects), so a publisher
  knows whether anyone outside its process wants a topic (:meth:`XPub.wants`) and encodes only then.

Links heal (:class:`LinkWatch`): libzmq gives up on a connection for good after a protocol or handshake error
(``session_base_t::engine_error``: a ``protocol_error`` terminates the session, no reconnect), so one listener
that speaks the wrong protocol on a dead node's port (not ZMTP, or plain ZMTP against CURVE) cut that node off
until its subscribers restarted. Every SUB socket's monitor is watched; an endpoint whose session ended without
a reconnect is connected again, with back-off, and refusals are logged at most once per
:data:`LinkWatch.LOG_EVERY_S` per endpoint, with a count.

Memory (:class:`XPub`): a publisher's queue per subscriber is bounded by bytes as well as by count: the send
high-water mark is lowered to ``budget_bytes`` / (largest message sent), so a subscriber that stops reading
costs at most about :data:`PUB_QUEUE_BYTES` of the publisher's memory; a message that a full subscriber queue
could not take is counted (``send`` returns False; the node counts it in its publisher's ``dropped``).

Errors: :class:`TransportError` when an endpoint cannot be bound (address in use, bad address).
"""

from __future__ import annotations

import asyncio
import logging
import struct
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import zmq

__all__ = ["Transport", "ZmqTransport", "InProcTransport", "TransportError", "CurveConfig", "XPub", "BusSocket", "SubLinks",
           "LinkWatch", "PUB_QUEUE_BYTES", "create_curve_keypair", "load_curve_keys", "ServiceSocket", "request",
           "ToolPublisher"]

log = logging.getLogger(__name__)
# plain ints: pyzmq's enum flags cost a Python enum operation each (measurable per message)
_EVENTS, _POLLIN, _NOBLOCK, _RCVMORE = int(zmq.EVENTS), int(zmq.POLLIN), int(zmq.NOBLOCK), int(zmq.RCVMORE)
_SNDMORE = int(zmq.SNDMORE)
_NOBLOCK_MORE = _NOBLOCK | _SNDMORE
FramesHandler = Callable[[list], None]
_monotonic = time.monotonic

#: bytes a publisher socket may queue for one subscriber that does not read (see :class:`XPub`): 32 MiB is
#: ~50 stereo frames (655 kB, ~1 s at 48 Hz) or ~7 rendered frames (4.7 MB); small messages keep SNDHWM
PUB_QUEUE_BYTES = 32 << 20
#: the send high-water mark never goes below this many messages, however big the messages
MIN_SNDHWM = 4


class TransportError(RuntimeError):
    """An endpoint could not be bound or connected (message names the endpoint and the reason)."""


@dataclass
class CurveConfig:
    """ZeroMQ CURVE security for one node (RFC 26 CurveZMQ, via pyzmq's ``zmq.auth``).

    ``public_key``/``secret_key``: this host's Z85 keypair (from ``flexsheet keys generate``).
    ``server_keys``: peer endpoint → the Z85 public key its publisher must prove it owns; a peer whose
    publisher lacks that secret key fails the handshake and none of its messages arrive.
    ``allowed_clients``: Z85 public keys allowed to subscribe to this node's publisher (ZAP check);
    any other subscriber is refused.
    ``tool_keys``: the hosts' keys, the callers allowed a node's commanding services (:mod:`flexsheet.runtime.services`).
    ``topic_publishers``: guarded topic → the endpoints allowed to publish it (the launch file's
    ``security.publishers``, per node as SROS2 grants per participant): a guarded topic is received only on a
    SUB socket connected to those endpoints alone, each pinned to its node's key (:class:`SubLinks`).
    Source: pyzmq ``zmq.auth`` and ``examples/security``; SROS2 access control (``sros2/policy``).
    """

    public_key: bytes
    secret_key: bytes
    server_keys: dict[str, bytes] = field(default_factory=dict)
    allowed_clients: list[bytes] = field(default_factory=list)
    topic_publishers: dict[str, list[str]] = field(default_factory=dict)
    #: Z85 public keys of the hosts (the tools run there): the only callers a node's commanding services take
    tool_keys: list[bytes] = field(default_factory=list)


class _AllowList:
    """The ZAP check of a CURVE publisher: admits the listed client keys; refusals are counted (``refused``) and
    logged at most once per :data:`LOG_EVERY_S` s with the count since the last line (a handshake flood wrote
    one warning per refusal: 1 106 lines, and the logging slowed the node)."""

    LOG_EVERY_S = 5.0

    def __init__(self, keys: list[bytes]) -> None:
        self.keys = set(keys)
        self.refused = 0
        self._logged_at = -1e9
        self._unlogged = 0

    def callback(self, domain: str, key: bytes) -> bool:
        ok = key in self.keys
        if not ok:
            self.refused += 1
            self._unlogged += 1
            now = _monotonic()
            if now - self._logged_at >= self.LOG_EVERY_S:
                log.warning("CURVE: refused %d subscriber handshake(s) with an unlisted public key since the last "
                            "line (last key %s; %d in all)", self._unlogged, key.decode(errors="replace"),
                            self.refused)
                self._logged_at, self._unlogged = now, 0
        return ok


class Transport:
    """Interface: ``start``, ``send``, ``subscribe``, ``set_latched``, ``close`` (called on the loop thread), plus
    ``wants`` and ``send_remote`` for the node's publish path.

    ``threadsafe_send``: True when ``send``/``send_remote``/``set_latched``/``wants`` may be called from any
    thread (else the node marshals them onto its loop). ``bus``: the in-process bus of a composable container
    (:class:`flexsheet.runtime.container.Bus`), None for a node alone in its process.
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
        :meth:`LinkWatch.report`), or "" (also for a transport without links, or a container's node: its
        container's SUB socket is asked)."""
        sock = getattr(self.bus, "sub", None)
        return sock.report() if sock is not None else ""

    def close(self) -> None:
        raise NotImplementedError


def _allow_list(ctx: zmq.Context, curve: CurveConfig):
    """Start a ZAP authenticator on ``ctx`` that admits ``curve.allowed_clients`` (returns it and its list)."""
    from zmq.auth.thread import ThreadAuthenticator

    auth = ThreadAuthenticator(ctx, log=log)
    auth.start()
    allow = _AllowList(curve.allowed_clients)
    auth.configure_curve_callback("*", credentials_provider=allow)
    return auth, allow


#: linger of a publisher socket at close, ms (see :meth:`XPub.close`)
CLOSE_LINGER_MS = 100


class XPub:
    """One bound XPUB socket: thread-safe :meth:`send`, latched values resent to late joiners, and the set of
    topic prefixes its subscribers asked for (:meth:`wants`).

    Created on the loop thread; :meth:`drain` is the loop's reader for the socket's FD. Every socket operation
    takes ``lock`` (ZeroMQ sockets may change threads only across a full memory barrier, which the lock gives).
    Raises :class:`TransportError` naming the endpoint when it cannot be bound.

    Bounded by bytes: ``sndhwm`` (messages) is the most each subscriber's queue holds; once a message bigger than
    ``budget_bytes / sndhwm`` is sent, the high-water mark (of every subscriber's queue, libzmq applies it to the
    existing ones) drops to ``budget_bytes // largest message`` (at least :data:`MIN_SNDHWM`), so the queue of a
    subscriber that stops reading holds about ``budget_bytes``. Counted drops: the socket runs with
    ``XPUB_NODROP``, so a send that a full queue cannot take fails instead of vanishing; it is then sent again
    lossy (the subscribers with room still get it) and :meth:`send` returns False. ``dropped`` counts them.
    """

    def __init__(self, ctx: zmq.Context, endpoint: str, curve: CurveConfig | None, sndhwm: int,
                 loop: asyncio.AbstractEventLoop, budget_bytes: int = PUB_QUEUE_BYTES) -> None:
        self.lock = threading.Lock()
        self.latched: dict[bytes, list] = {}
        self.prefixes: set[bytes] = set()
        self._wants: dict[bytes, bool] = {}
        self._loop = loop
        self.budget_bytes = int(budget_bytes)
        self.sndhwm = self.max_sndhwm = max(1, int(sndhwm))
        self.largest = self.budget_bytes // self.sndhwm  # a bigger message lowers the high-water mark
        self.dropped = 0
        self.sock = ctx.socket(zmq.XPUB)
        self.sock.setsockopt(zmq.LINGER, 0)
        if curve is not None:
            self.sock.curve_secretkey = curve.secret_key
            self.sock.curve_publickey = curve.public_key
            self.sock.curve_server = True
        self.sock.setsockopt(zmq.SNDHWM, self.sndhwm)
        self.sock.setsockopt(zmq.XPUB_VERBOSE, 1)
        self.sock.setsockopt(zmq.XPUB_NODROP, 1)
        try:
            self.sock.bind(endpoint)
        except zmq.ZMQError as exc:
            self.sock.close(linger=0)
            raise TransportError(f"cannot bind publisher endpoint {endpoint!r}: {exc}") from None
        self.endpoint = endpoint
        if endpoint.endswith(":0") or endpoint.endswith(":*"):
            self.endpoint = self.sock.getsockopt(zmq.LAST_ENDPOINT).decode()
        self.fd = self.sock.getsockopt(zmq.FD)
        loop.add_reader(self.fd, self.drain)

    @property
    def closed(self) -> bool:
        return self.sock.closed

    def wants(self, topic: bytes) -> bool:
        """True if a subscriber of this socket asked for a prefix of ``topic`` (checks new subscriptions first
        when the cached answer is no, so a subscriber that just joined is not missed)."""
        if self._wants.get(topic):
            return True
        with self.lock:
            self._drain_locked()
            w = self._wants.get(topic)
            if w is None:
                w = self._wants[topic] = any(topic.startswith(p) for p in self.prefixes)
        return w

    def send(self, frames: list) -> bool:
        """Send one multipart message without blocking (any thread); False if a subscriber's full queue dropped
        it (the others got it; counted in ``dropped``) or the socket is shut down."""
        if len(frames) == 2:  # [topic, meta]: no array buffers (the topic's few bytes are left out)
            m = frames[1]
            size = len(m) if type(m) is bytes else _nbytes(m)
        else:
            size = 0
            for f in frames:
                size += len(f) if type(f) is bytes else _nbytes(f)
        with self.lock:
            sock = self.sock
            if sock.closed:
                return False  # shutting down: a late publish from a worker thread is dropped, not an error
            if size > self.largest:
                self._fit_hwm(size)
            try:
                send = sock.send
                last = len(frames) - 1
                for i, f in enumerate(frames):  # send_multipart, minus its per-frame enum arithmetic
                    send(f, _NOBLOCK_MORE if i < last else _NOBLOCK, copy=False)
            except zmq.Again:  # XPUB_NODROP: a matching subscriber's queue is full
                self.dropped += 1
                self._send_lossy(frames)
                return False
            except zmq.ZMQError:
                return False
        # a send can swallow the FD's edge for a subscription that arrived meanwhile: the safety poll (50 ms)
        # and wants() (which drains when its answer would be no) catch it
        return True

    def _fit_hwm(self, size: int) -> None:
        """Lower the send high-water mark so that ``size``-byte messages fit ``budget_bytes`` (lock held)."""
        self.largest = size
        hwm = max(MIN_SNDHWM, min(self.max_sndhwm, self.budget_bytes // size))
        if hwm < self.sndhwm:
            self.sock.setsockopt(zmq.SNDHWM, hwm)
            self.sndhwm = hwm

    def _send_lossy(self, frames: list) -> None:
        """Send to the subscribers whose queue has room, the full ones skipped (lock held)."""
        sock = self.sock
        sock.setsockopt(zmq.XPUB_NODROP, 0)
        try:
            _send_frames(sock, frames)
        except zmq.ZMQError:
            pass
        finally:
            sock.setsockopt(zmq.XPUB_NODROP, 1)

    def set_latched(self, topic: str, frames: list) -> None:
        self.latched[topic.encode()] = frames

    def drain(self) -> None:
        """Handle pending subscription messages (the loop's reader callback; thread-safe)."""
        with self.lock:
            self._drain_locked()

    def _drain_locked(self) -> None:
        sock = self.sock
        if sock.closed:
            return
        changed = False
        while sock.getsockopt(_EVENTS) & _POLLIN:
            try:
                msg = sock.recv(_NOBLOCK)
            except zmq.Again:
                break
            kind, prefix = msg[:1], msg[1:]
            if kind == b"\x01":  # a subscription: resend latched values it matches
                changed = changed or prefix not in self.prefixes
                self.prefixes.add(prefix)
                for topic, frames in self.latched.items():
                    if topic.startswith(prefix):
                        try:
                            _send_frames(sock, frames)
                        except zmq.Again:  # an old subscriber's queue is full: the new one still gets it
                            self._send_lossy(frames)
                        except zmq.ZMQError:
                            pass
            elif kind == b"\x00":  # the last subscriber of this prefix left
                changed = True
                self.prefixes.discard(prefix)
        if changed:
            self._wants.clear()

    def close(self) -> None:
        with self.lock:
            if self.sock.closed:
                return
            try:
                self._loop.remove_reader(self.fd)
            except Exception:  # noqa: BLE001 - loop may be closed already
                pass
            # a short linger, not 0: closing with linger 0 while a subscriber disconnects mid-way through a
            # multipart message aborts the whole process in libzmq 4.3.5 ("Resource temporarily unavailable
            # (src/session_base.cpp:233)", zeromq/libzmq#3442; it killed the camera node at a launch's shutdown).
            # Reproduced with 4 subscribers closing as the XPUB closes after 0.6 MB frames: 6 aborts in 60
            # runs at linger 0, none in 210 at 100 ms. ctx.term() then waits at most CLOSE_LINGER_MS.
            self.sock.close(linger=CLOSE_LINGER_MS)


def _send_frames(sock: zmq.Socket, frames: list) -> None:
    """Send one multipart message without blocking (``send_multipart`` minus its per-frame enum arithmetic)."""
    send = sock.send
    last = len(frames) - 1
    for i, f in enumerate(frames):
        send(f, _NOBLOCK_MORE if i < last else _NOBLOCK, copy=False)


def _nbytes(frame) -> int:
    """Size of one frame that is not ``bytes`` (an array, a memoryview, a ``zmq.Frame``), bytes."""
    n = getattr(frame, "nbytes", None)
    return n if n is not None else len(frame)


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
                 curve: CurveConfig | None = None, drain_period: float = 0.0) -> None:
        if not (drain_period >= 0.0 and drain_period < 10.0):
            raise ValueError(f"drain_period must be in [0, 10) s, got {drain_period!r}")
        self.endpoint = endpoint
        self.drain_period = float(drain_period)
        self.curve = curve
        self._auth = None
        self.allow: _AllowList | None = None
        self.peers = [p for p in dict.fromkeys(peers) if p]
        self.sndhwm, self.rcvhwm = sndhwm, rcvhwm
        self.ctx: zmq.Context | None = None
        self.xpub: XPub | None = None
        self.links: SubLinks | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._on_frames: FramesHandler | None = None
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
            self._auth, self.allow = _allow_list(self.ctx, curve)
        if self.endpoint:
            try:
                self.xpub = XPub(self.ctx, self.endpoint, curve, self.sndhwm, self._loop)
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
        if self.links is not None:
            self.links.drain(self._on_frames)

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


def connect_sub(ctx: zmq.Context, peers: list[str], curve: CurveConfig | None, rcvhwm: int,
                on_error: Callable[[], None] | None = None) -> zmq.Socket:
    """A SUB socket on ``ctx`` connected to every endpoint of ``peers`` (CURVE client when ``curve``).

    Raises :class:`TransportError` naming the peer that cannot be connected (``on_error`` is called first).
    """
    sub = ctx.socket(zmq.SUB)
    sub.setsockopt(zmq.LINGER, 0)
    sub.setsockopt(zmq.RCVHWM, rcvhwm)
    sub.setsockopt(zmq.RECONNECT_IVL, 100)
    sub.setsockopt(zmq.RECONNECT_IVL_MAX, 1000)
    if curve is not None:
        sub.curve_secretkey = curve.secret_key
        sub.curve_publickey = curve.public_key
    for peer in peers:
        try:
            if curve is not None:
                if peer not in curve.server_keys:
                    raise TransportError(f"CURVE is on but no public key is listed for peer {peer!r}")
                sub.curve_serverkey = curve.server_keys[peer]  # applies to this connect only
            sub.connect(peer)
        except (zmq.ZMQError, TransportError) as exc:
            sub.close(linger=0)
            if on_error is not None:
                on_error()
            if isinstance(exc, TransportError):
                raise
            raise TransportError(f"cannot connect to peer endpoint {peer!r}: {exc}") from None
    return sub


# monitor events as plain ints (pyzmq's enums cost an enum operation each)
_EV_CONNECTED, _EV_DELAYED = int(zmq.EVENT_CONNECTED), int(zmq.EVENT_CONNECT_DELAYED)
_EV_RETRIED, _EV_DISCONNECTED = int(zmq.EVENT_CONNECT_RETRIED), int(zmq.EVENT_DISCONNECTED)
_EV_OK, _EV_FAIL_NO_DETAIL = int(zmq.EVENT_HANDSHAKE_SUCCEEDED), int(zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL)
_EV_FAIL_PROTOCOL, _EV_FAIL_AUTH = int(zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL), int(zmq.EVENT_HANDSHAKE_FAILED_AUTH)
_LINK_EVENTS = (_EV_CONNECTED | _EV_DELAYED | _EV_RETRIED | _EV_DISCONNECTED | _EV_OK | _EV_FAIL_PROTOCOL
                | _EV_FAIL_AUTH | _EV_FAIL_NO_DETAIL)
_PROTOCOL_ERRORS = {int(getattr(zmq, n)): n[len("PROTOCOL_ERROR_"):].lower().replace("_", " ")
                    for n in dir(zmq) if n.startswith("PROTOCOL_ERROR_")}


class _Link:
    """What :class:`LinkWatch` knows of one peer endpoint."""

    __slots__ = ("endpoint", "up", "since", "check_at", "retry_at", "backoff", "failures", "failed_down",
                 "unlogged", "logged_at", "reason", "reconnects")

    def __init__(self, endpoint: str, now: float) -> None:
        self.endpoint = endpoint
        self.up = False
        self.since = now                      # when it last went up or down (down from the start)
        self.check_at: float | None = None    # the session must show a sign of life by then, or it is gone
        self.retry_at: float | None = None    # gone: connect again then
        self.backoff = LinkWatch.BACKOFF_MIN_S
        self.failures = 0                     # failed handshakes, in all
        self.failed_down = 0                  # ... since the link was last up
        self.unlogged = 0                     # ... since the last log line
        self.logged_at = -1e9
        self.reason = ""                      # the last failure
        self.reconnects = 0                   # connections made again by the watch


class LinkWatch:
    """Keeps every peer endpoint of one SUB socket connected, whatever a listener on that port did.

    libzmq reconnects a connection lost to a network error, but a protocol error (the peer is not ZMTP, speaks
    another security mechanism, sends a malformed greeting or command) ends the connection's session for good:
    libzmq never connects to that endpoint again. Read from the socket's monitor: a session that disconnects
    and shows no reconnect (``EVENT_CONNECT_RETRIED``, which libzmq emits right after the disconnect when it
    retries) within :data:`GRACE_S`, or that failed its handshake (``HANDSHAKE_FAILED_PROTOCOL``/``_AUTH``), is
    gone: the endpoint is disconnected and connected again after a back-off (:data:`BACKOFF_MIN_S` doubling to
    :data:`BACKOFF_MAX_S`; reset by a handshake that succeeds). So within about ``BACKOFF_MAX_S`` + libzmq's
    ``RECONNECT_IVL_MAX`` (1 s) after a squatter leaves and the real publisher is back, messages flow again.

    :meth:`poll` runs on the socket's thread (the transports' safety poll, every 50 ms). A connection given up
    is logged at most once per :data:`LOG_EVERY_S` per endpoint, with the count of failed handshakes;
    :meth:`report` names the endpoints without a link for more than :data:`SILENT_S` (the node's heartbeat
    says it).
    """

    GRACE_S = 0.5
    BACKOFF_MIN_S = 0.1
    BACKOFF_MAX_S = 1.0
    LOG_EVERY_S = 5.0
    SILENT_S = 5.0
    POLL_S = 0.05

    def __init__(self, sock: zmq.Socket, peers: Iterable[str], curve: CurveConfig | None = None) -> None:
        self.sock = sock
        self.curve = curve
        self.mon: zmq.Socket | None = sock.get_monitor_socket(_LINK_EVENTS)
        now = _monotonic()
        self.links: dict[str, _Link] = {ep: _Link(ep, now) for ep in peers}
        self._busy: set[_Link] = set()  # links with a pending check or retry
        self.next_poll = now

    def add(self, endpoint: str) -> None:
        """Watch one more endpoint (connected by the caller)."""
        if endpoint not in self.links:
            self.links[endpoint] = _Link(endpoint, _monotonic())

    def remove(self, endpoint: str) -> None:
        """Stop watching an endpoint (disconnected by the caller)."""
        link = self.links.pop(endpoint, None)
        if link is not None:
            self._busy.discard(link)

    def poll(self, now: float | None = None) -> None:
        """Read the monitor's events and connect again to every endpoint whose session is gone."""
        mon = self.mon
        if mon is None or mon.closed or self.sock.closed:
            return
        now = _monotonic() if now is None else now
        self.next_poll = now + self.POLL_S
        while mon.getsockopt(_EVENTS) & _POLLIN:
            try:
                head = mon.recv(_NOBLOCK)
                endpoint = mon.recv(_NOBLOCK).decode(errors="replace") if mon.getsockopt(_RCVMORE) else ""
            except zmq.Again:
                break
            link = self.links.get(endpoint)
            if link is not None and len(head) >= 6:
                self._event(link, *struct.unpack_from("<HI", head), now)
        for link in list(self._busy):
            self._step(link, now)

    def _event(self, link: _Link, event: int, value: int, now: float) -> None:
        if event == _EV_RETRIED or event == _EV_DELAYED or event == _EV_CONNECTED:
            link.check_at = None                       # libzmq is (re)connecting: alive
        elif event == _EV_OK:
            if link.failed_down:
                log.info("link to %s up again (%d failed handshake(s) while it was down)", link.endpoint,
                         link.failed_down)
            link.up, link.since = True, now
            link.check_at = link.retry_at = None
            link.backoff = self.BACKOFF_MIN_S
            link.failed_down = 0
        elif event == _EV_DISCONNECTED:
            if link.up:
                link.up, link.since = False, now
            if link.check_at is None and link.retry_at is None:
                link.check_at = now + self.GRACE_S     # gone unless libzmq retries
                self._busy.add(link)
        elif event == _EV_FAIL_PROTOCOL or event == _EV_FAIL_AUTH or event == _EV_FAIL_NO_DETAIL:
            if event == _EV_FAIL_PROTOCOL:
                link.reason = "handshake refused: " + _PROTOCOL_ERRORS.get(value, f"protocol error {value:#x}")
            elif event == _EV_FAIL_AUTH:
                link.reason = f"handshake refused by the publisher (ZAP status {value})"
            elif not (link.failed_down and link.reason.startswith("handshake refused")):  # a refusal says more
                link.reason = f"handshake failed: {_strerror(value)}"
            link.failures += 1
            link.failed_down += 1
            link.unlogged += 1
            if event != _EV_FAIL_NO_DETAIL and link.retry_at is None:
                link.check_at = now                    # libzmq ends the connection: no retry will come
                self._busy.add(link)

    def _step(self, link: _Link, now: float) -> None:
        if link.check_at is not None and now >= link.check_at:
            link.check_at = None
            link.retry_at = now + link.backoff
            self._log(link, now)
        if link.retry_at is not None and now >= link.retry_at:
            link.retry_at = None
            link.backoff = min(self.BACKOFF_MAX_S, link.backoff * 2.0)
            self._reconnect(link)
        if link.check_at is None and link.retry_at is None:
            self._busy.discard(link)

    def _reconnect(self, link: _Link) -> None:
        sock, ep = self.sock, link.endpoint
        try:
            sock.disconnect(ep)
        except zmq.ZMQError:
            pass  # libzmq may have dropped the endpoint already
        try:
            if self.curve is not None:
                sock.curve_serverkey = self.curve.server_keys[ep]
            sock.connect(ep)
        except (zmq.ZMQError, KeyError) as exc:
            link.retry_at = _monotonic() + link.backoff
            log.warning("link to %s: cannot connect again: %s", ep, exc)
            return
        link.reconnects += 1

    def _log(self, link: _Link, now: float) -> None:
        """One line per :data:`LOG_EVERY_S` per endpoint: the connection was given up, why, how often."""
        if now - link.logged_at < self.LOG_EVERY_S:
            return
        n, link.unlogged, link.logged_at = link.unlogged, 0, now
        log.warning("link to %s: %s; libzmq gave up on it, connecting again in %.1f s (back-off up to %.0f s; "
                    "%d failed handshake(s) since the last line, %d in all)", link.endpoint,
                    link.reason or "ended without a reconnect", link.retry_at - now, self.BACKOFF_MAX_S, n,
                    link.failures)

    def report(self, now: float | None = None) -> str:
        """``"no link to EP for N s (reason)"`` for each endpoint (at most 3 named) down for more than
        :data:`SILENT_S`, joined by "; ", or ""."""
        now = _monotonic() if now is None else now
        silent = [x for x in self.links.values() if not x.up and now - x.since > self.SILENT_S]
        if not silent:
            return ""
        parts = [f"no link to {x.endpoint} for {now - x.since:.0f} s"
                 + (f" ({x.failed_down} failed handshake(s), last: {x.reason})" if x.failed_down else "")
                 for x in silent[:3]]
        if len(silent) > 3:
            parts.append(f"and {len(silent) - 3} more endpoint(s)")
        return "; ".join(parts)

    def close(self) -> None:
        """Stop the monitor and close its socket (before the SUB socket and the context)."""
        mon, self.mon = self.mon, None
        if mon is None:
            return
        try:
            if not self.sock.closed:
                self.sock.disable_monitor()
        except zmq.ZMQError:
            pass
        mon.close(linger=0)


def _strerror(code: int) -> str:
    import os

    try:
        return os.strerror(code)
    except ValueError:
        return f"errno {code}"


def drain_sub(sub: zmq.Socket | None, handler: FramesHandler) -> None:
    """Receive every message ready on ``sub`` without blocking and hand each to ``handler`` as a list of frames:
    the topic and meta frames as ``bytes`` (small: a copy is cheaper than a ``zmq.Frame``), the array buffers
    as zero-copy ``zmq.Frame`` objects."""
    if sub is None or sub.closed:
        return
    recv, getsockopt = sub.recv, sub.getsockopt
    while getsockopt(_EVENTS) & _POLLIN:
        try:
            frames = [recv(_NOBLOCK)]
        except zmq.Again:
            break
        if getsockopt(_RCVMORE):
            frames.append(recv(_NOBLOCK))
            while getsockopt(_RCVMORE):
                frames.append(recv(_NOBLOCK, copy=False))
        handler(frames)


class SubLinks:
    """The SUB side of one process: a SUB socket connected to every peer (with its :class:`LinkWatch`), plus,
    under CURVE with guarded topics (``curve.topic_publishers``), one SUB socket per set of allowed publishers,
    connected to those endpoints alone.

    A guarded topic is subscribed on its publishers' socket only, so another node's publisher (ZMTP filters at
    the publisher) never sends it and the SUB's own filter drops it should it come; a message of a guarded topic
    that arrives on the socket of every peer under a wider prefix subscription ("") is dropped too (it may be
    the allowed publisher's copy, which arrives on its own socket, or another node's: the socket cannot tell,
    so nothing is counted). Every socket's
    links heal (:class:`LinkWatch`). ``on_error`` is called before a :class:`TransportError` (bad peer) is
    raised. Runs on the loop thread.
    """

    def __init__(self, ctx: zmq.Context, peers: Iterable[str], curve: CurveConfig | None, rcvhwm: int,
                 on_error: Callable[[], None] | None = None) -> None:
        self.peers = [p for p in dict.fromkeys(peers) if p]
        self.curve = curve
        self.sock = connect_sub(ctx, self.peers, curve, rcvhwm, on_error)
        self.watch = LinkWatch(self.sock, self.peers, curve)
        self.guards: dict[bytes, tuple[str, ...]] = {}
        self.guarded: dict[tuple[str, ...], tuple[zmq.Socket, LinkWatch]] = {}
        self._general = self._filtered = None
        for topic, eps in (curve.topic_publishers if curve is not None else {}).items():
            allowed = tuple(sorted(ep for ep in dict.fromkeys(eps) if ep in self.peers))
            self.guards[topic.encode()] = allowed
            if allowed and allowed not in self.guarded:
                try:
                    sock = connect_sub(ctx, list(allowed), curve, rcvhwm, on_error)
                except TransportError:
                    self.close()
                    raise
                self.guarded[allowed] = (sock, LinkWatch(sock, allowed, curve))

    def fds(self) -> list[int]:
        """The (edge-triggered) file descriptors of every SUB socket, for ``loop.add_reader``."""
        return [s.getsockopt(zmq.FD) for s in self._socks() if not s.closed]

    def _socks(self) -> list[zmq.Socket]:
        return [self.sock] + [s for s, _ in self.guarded.values()]

    def subscribe(self, prefix: bytes) -> None:
        """Subscribe ``prefix``: a guarded topic on its publishers' socket alone; any other prefix on the socket
        of every peer, plus each guarded topic it covers on that topic's publishers' socket."""
        self._subscription(prefix, zmq.SUBSCRIBE)

    def unsubscribe(self, prefix: bytes) -> None:
        """Undo one :meth:`subscribe` of ``prefix``."""
        self._subscription(prefix, zmq.UNSUBSCRIBE)

    def _subscription(self, prefix: bytes, option: int) -> None:
        covered = [t for t in self.guards if t.startswith(prefix)]
        if prefix not in self.guards:
            self.sock.setsockopt(option, prefix)
        for topic in covered:
            allowed = self.guards[topic]
            if allowed:
                self.guarded[allowed][0].setsockopt(option, topic)

    def add_peer(self, endpoint: str, server_key: bytes | None = None) -> None:
        """Connect the socket of every peer to one more endpoint (a tool that discovers late). With CURVE the
        endpoint's publisher must prove ``server_key`` (default: the key the launch file lists for it), which
        must be one of the graph's identities; raises ``ValueError`` otherwise."""
        if endpoint not in self.peers:
            if self.curve is not None:
                key = server_key or self.curve.server_keys.get(endpoint)
                if key is None or (server_key is not None and key not in self.curve.allowed_clients):
                    raise ValueError(f"CURVE is on: {endpoint} needs the public key of one of the launch file's "
                                     "identities")
                self.sock.curve_serverkey = key
            try:                                # a malformed endpoint raises before anything is recorded
                self.sock.connect(endpoint)
            except zmq.ZMQError as exc:
                raise ValueError(f"cannot connect to {endpoint!r}: {exc}") from None
            self.peers.append(endpoint)
            self.watch.add(endpoint)

    def remove_peer(self, endpoint: str) -> bool:
        """Disconnect from an endpoint :meth:`add_peer` added; False when it was not a peer."""
        if endpoint not in self.peers:
            return False
        self.peers.remove(endpoint)
        self.watch.remove(endpoint)
        try:
            self.sock.disconnect(endpoint)
        except zmq.ZMQError:            # never connected (a malformed or refused endpoint)
            pass
        return True

    def drain(self, handler: FramesHandler) -> None:
        """Hand every waiting message of every socket to ``handler`` (:func:`drain_sub`), less the guarded
        topics that came from a publisher not allowed them."""
        if not self.guards:
            drain_sub(self.sock, handler)
            return
        if self._general != handler:   # a bound method is a new object at each access, equal to the last
            guards = self.guards

            def filtered(frames: list) -> None:
                t = frames[0]
                if (t if type(t) is bytes else bytes(t)) not in guards:
                    handler(frames)

            self._general, self._filtered = handler, filtered
        drain_sub(self.sock, self._filtered)
        for sock, _ in self.guarded.values():
            drain_sub(sock, handler)

    def poll(self, now: float | None = None) -> None:
        """Keep every socket's links (:meth:`LinkWatch.poll`)."""
        self.watch.poll(now)
        for _, watch in self.guarded.values():
            watch.poll(now)

    @property
    def next_poll(self) -> float:
        return self.watch.next_poll

    def report(self) -> str:
        """The reports of every socket's links (:meth:`LinkWatch.report`), joined by "; "."""
        parts = [self.watch.report()] + [w.report() for _, w in self.guarded.values()]
        return "; ".join(dict.fromkeys(p for p in parts if p))

    def close(self) -> None:
        """Stop the monitors and close every socket (before the context ends; idempotent)."""
        for sock, watch in [(self.sock, self.watch)] + list(self.guarded.values()):
            watch.close()
            if not sock.closed:
                sock.close(linger=0)


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


class BusSocket:
    """A composable container's SUB side (:class:`SubLinks`), with the ZeroMQ context (and CURVE authenticator)
    its nodes' :class:`XPub` sockets share (:class:`flexsheet.runtime.container.Bus`).

    ``peers``: endpoints to connect to; ``curve``: CURVE keys or None; ``rcvhwm``: receive high-water mark."""

    def __init__(self, peers: list[str], curve: CurveConfig | None, rcvhwm: int) -> None:
        self.ctx = zmq.Context()
        self._auth = _allow_list(self.ctx, curve)[0] if curve is not None else None
        self.links = SubLinks(self.ctx, peers, curve, rcvhwm)
        self.sock, self.watch = self.links.sock, self.links.watch

    @property
    def closed(self) -> bool:
        return self.sock.closed

    def fds(self) -> list[int]:
        """The sockets' (edge-triggered) file descriptors, for ``loop.add_reader``."""
        return self.links.fds()

    def subscribe(self, prefix: bytes) -> None:
        self.links.subscribe(prefix)

    def unsubscribe(self, prefix: bytes) -> None:
        self.links.unsubscribe(prefix)

    def report(self) -> str:
        return self.links.report()

    def drain(self, handler: FramesHandler) -> None:
        """Hand every waiting multipart message to ``handler`` (:meth:`SubLinks.drain`); every
        :data:`LinkWatch.POLL_S` also keep the links (:meth:`SubLinks.poll`; the container's safety poll calls
        this every 50 ms)."""
        links = self.links
        links.drain(handler)
        if _monotonic() >= links.next_poll:
            links.poll()

    def close(self) -> None:
        """Close the sockets, stop the authenticator and end the context (idempotent)."""
        self.links.close()
        if self._auth is not None:
            self._auth.stop()
            self._auth = None
        if not self.ctx.closed:
            self.ctx.term()


def create_curve_keypair(folder: str | Path, name: str) -> tuple[Path, Path]:
    """Write ``folder/name.key`` (public) and ``folder/name.key_secret`` (both); returns their paths."""
    import zmq.auth

    public, secret = zmq.auth.create_certificates(str(folder), name)
    return Path(public), Path(secret)


def load_curve_keys(path: str | Path) -> tuple[bytes, bytes | None]:
    """``(public, secret)`` Z85 keys of a certificate file (``secret`` is None for a public-only file).
    Raises ``OSError``/``ValueError`` for a missing or malformed file."""
    import zmq.auth

    return zmq.auth.load_certificate(str(path))


class ServiceSocket:
    """A node's service socket (:mod:`flexsheet.runtime.services`): a ROUTER bound on ``address``
    ("tcp://HOST") at a port the OS picks (:attr:`endpoint`), a CURVE server with the node's keys when ``curve``,
    on the node's context ``ctx`` (its ZAP authenticator then covers it) or its own. Requests above
    ``max_bytes`` are dropped by libzmq (MAXMSGSIZE). Used on the loop thread only."""

    def __init__(self, address: str, curve: CurveConfig | None = None, ctx: zmq.Context | None = None,
                 max_bytes: int = 1 << 20) -> None:
        import zmq.asyncio

        self._ctx = zmq.asyncio.Context.shadow(ctx) if ctx is not None else zmq.asyncio.Context()
        self._own = ctx is None
        self.sock = self._ctx.socket(zmq.ROUTER)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.setsockopt(zmq.MAXMSGSIZE, max_bytes + 256)
        if curve is not None:
            self.sock.curve_secretkey = curve.secret_key
            self.sock.curve_publickey = curve.public_key
            self.sock.curve_server = True
        self.endpoint = f"{address}:{self.sock.bind_to_random_port(address)}"

    async def recv(self) -> tuple[bytes, bytes, str] | None:
        """(caller identity, request payload, the caller's CURVE public key in Z85 or "" without CURVE), or None
        once the socket is closed."""
        try:
            frames = await self.sock.recv_multipart(copy=False)
        except (zmq.ContextTerminated, zmq.ZMQError):
            return None
        try:
            user = frames[-1].get("User-Id") or ""
        except zmq.ZMQError:
            user = ""
        return frames[0].bytes, frames[-1].bytes, user

    async def reply(self, ident: bytes, payload: bytes) -> None:
        """Answer the caller ``ident`` (a caller that went away is ignored)."""
        try:
            await self.sock.send_multipart([ident, b"", payload])
        except zmq.ZMQError:
            pass

    def close(self) -> None:
        self.sock.close(0)
        if self._own:
            self._ctx.term()


async def request(endpoint: str, payload: bytes, timeout: float, curve: CurveConfig | None = None,
                  server_key: bytes | None = None) -> bytes | None:
    """Send one request to the :class:`ServiceSocket` at ``endpoint`` and return its reply, or None when none
    arrives within ``timeout`` s. ``curve`` (the caller's keys) with ``server_key`` (the node's public key)."""
    import zmq.asyncio

    ctx = zmq.asyncio.Context()
    sock = ctx.socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    if curve is not None:
        sock.curve_secretkey = curve.secret_key
        sock.curve_publickey = curve.public_key
        sock.curve_serverkey = server_key
    try:
        sock.connect(endpoint)
        await sock.send_multipart([b"", payload])
        try:
            frames = await asyncio.wait_for(sock.recv_multipart(), timeout)
        except TimeoutError:
            return None
        return frames[-1]
    finally:
        sock.close(0)
        ctx.term()


class ToolPublisher:
    """A tool's own publisher (``flexsheet topic pub``): an XPUB bound on ``address`` ("tcp://HOST") at a port
    the OS picks (:attr:`endpoint`), a CURVE server with the host's keys when ``curve``; nodes connect to it on
    request (``graph/connect``) and :meth:`wait_subscribers` waits until their subscriptions arrived."""

    def __init__(self, address: str, curve: CurveConfig | None = None) -> None:
        import zmq.asyncio

        self._ctx = zmq.asyncio.Context()
        self.sock = self._ctx.socket(zmq.XPUB)
        self.sock.setsockopt(zmq.XPUB_VERBOSE, 1)
        self.sock.setsockopt(zmq.LINGER, 500)
        if curve is not None:
            self.sock.curve_secretkey = curve.secret_key
            self.sock.curve_publickey = curve.public_key
            self.sock.curve_server = True
        self.endpoint = f"{address}:{self.sock.bind_to_random_port(address)}"

    async def wait_subscribers(self, topic: str, n: int, timeout: float) -> int:
        """Wait (at most ``timeout`` s) until ``n`` subscriptions covering ``topic`` arrived; returns how many did."""
        got, t = 0, topic.encode()
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        while got < n and loop.time() < end:
            try:
                msg = await asyncio.wait_for(self.sock.recv(), max(0.0, end - loop.time()))
            except TimeoutError:
                break
            if msg[:1] == b"\x01" and t.startswith(msg[1:]):
                got += 1
        return got

    async def send(self, frames: list) -> None:
        await self.sock.send_multipart(frames)

    def close(self) -> None:
        self.sock.close()
        self._ctx.term()
