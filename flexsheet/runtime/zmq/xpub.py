"""A node's bound XPUB (:class:`XPub`: thread-safe sends, latched values for late joiners, subscriptions
tracked, queues bounded by bytes, every option set before bind)."""

from __future__ import annotations

import asyncio
import logging
import threading

import zmq

from flexsheet.runtime.domain import port_holder
from flexsheet.runtime.transport import TransportError
from flexsheet.runtime.zmq.curve import CurveConfig
from flexsheet.runtime.zmq.frames import EVENTS, NOBLOCK, NOBLOCK_MORE, POLLIN, frame_nbytes, send_frames

__all__ = ["XPub", "PUB_QUEUE_BYTES", "MIN_SNDHWM", "SMALL_MESSAGE_BYTES", "CLOSE_LINGER_MS",
           "send_hwm"]

log = logging.getLogger(__name__)

#: bytes a publisher socket may queue for one subscriber that does not read (see :class:`XPub`): 32 MiB is
#: ~50 stereo frames (655 kB, ~1 s at 48 Hz) or ~7 rendered frames (4.7 MB); small messages keep SNDHWM
PUB_QUEUE_BYTES = 32 << 20
#: the send high-water mark never goes below this many messages, however big the messages
MIN_SNDHWM = 4
#: the largest message a node declares by default, bytes (a node of images declares its own)
SMALL_MESSAGE_BYTES = 16 << 10


def send_hwm(sndhwm: int, largest_bytes: int, budget_bytes: int = PUB_QUEUE_BYTES) -> int:
    """The send high-water mark (messages) that keeps one subscriber's queue of ``largest_bytes`` messages
    within ``budget_bytes``: ``budget_bytes // largest_bytes``, at most ``sndhwm``, at least
    :data:`MIN_SNDHWM`. Raises ``ValueError`` naming a value that is not a positive int."""
    for name, v in (("sndhwm", sndhwm), ("largest_bytes", largest_bytes), ("budget_bytes", budget_bytes)):
        if not (isinstance(v, int) and v >= 1):
            raise ValueError(f"{name} must be an int >= 1, got {v!r}")
    return max(MIN_SNDHWM, min(sndhwm, budget_bytes // largest_bytes))

#: linger of a publisher socket at close, ms (see :meth:`XPub.close`)
CLOSE_LINGER_MS = 100


class XPub:
    """One bound XPUB socket: thread-safe :meth:`send`, latched values resent to late joiners, and the set of
    topic prefixes its subscribers asked for (:meth:`wants`).

    Created on the loop thread; :meth:`drain` is the loop's reader for the socket's FD. Every socket operation
    takes ``lock`` (ZeroMQ sockets may change threads only across a full memory barrier, which the lock
    gives). Raises :class:`TransportError` naming the endpoint when it cannot be bound.

    Bounded by bytes, set once: the high-water mark is :func:`send_hwm` of ``sndhwm`` and ``largest_bytes``
    (the largest message the node declares), set before ``bind`` and never changed on the live socket
    (changing it while a subscriber's pipe is torn down crashes libzmq 4.3.5's I/O thread:
    zeromq/libzmq#4524). A subscriber that stops reading then holds about ``budget_bytes``. A message bigger
    than declared is still sent (counted in ``oversize``; its node should declare more). Counted drops: the
    socket runs with ``XPUB_NODROP``, so a send that a full queue cannot take fails instead of vanishing; it
    is then sent again lossy (the subscribers with room still get it) and :meth:`send` returns False.
    ``dropped`` counts them.
    """

    def __init__(self, ctx: zmq.Context, endpoint: str, curve: CurveConfig | None, sndhwm: int,
                 loop: asyncio.AbstractEventLoop, largest_bytes: int = SMALL_MESSAGE_BYTES,
                 budget_bytes: int = PUB_QUEUE_BYTES) -> None:
        self.lock = threading.Lock()
        self.latched: dict[bytes, list] = {}
        self.prefixes: set[bytes] = set()
        self._wants: dict[bytes, bool] = {}
        self._loop = loop
        self.budget_bytes = int(budget_bytes)
        self.largest = int(largest_bytes)
        self.sndhwm = send_hwm(max(1, int(sndhwm)), self.largest, self.budget_bytes)
        self.dropped = 0
        self.oversize = 0   # messages bigger than ``largest`` (sent all the same; the HWM stays)
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
            holder = port_holder(int(endpoint.rsplit(":", 1)[1])) if exc.errno == zmq.EADDRINUSE else ""
            raise TransportError(f"cannot bind publisher endpoint {endpoint!r}: {exc}"
                                 + (f" (held by {holder}; another graph? give it another --domain)" if holder
                                    else "")) from None
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
        """Send one multipart message without blocking (any thread); False if a subscriber's full queue
        dropped it (the others got it; counted in ``dropped``) or the socket is shut down."""
        if len(frames) == 2:  # [topic, meta]: no array buffers (the topic's few bytes are left out)
            m = frames[1]
            size = len(m) if type(m) is bytes else frame_nbytes(m)
        else:
            size = 0
            for f in frames:
                size += len(f) if type(f) is bytes else frame_nbytes(f)
        with self.lock:
            sock = self.sock
            if sock.closed:
                return False  # shutting down: a late publish from a worker thread is dropped, not an error
            if size > self.largest:
                if not self.oversize:
                    log.warning("%s: a %d-byte message is larger than the %d bytes its node declares "
                                "(LARGEST_MESSAGE_BYTES): the queue bound is exceeded", self.endpoint, size,
                                self.largest)
                self.oversize += 1
            try:
                send = sock.send
                last = len(frames) - 1
                for i, f in enumerate(frames):  # send_multipart, minus its per-frame enum arithmetic
                    send(f, NOBLOCK_MORE if i < last else NOBLOCK, copy=False)
            except zmq.Again:  # XPUB_NODROP: a matching subscriber's queue is full
                self.dropped += 1
                self._send_lossy(frames)
                return False
            except zmq.ZMQError:
                return False
        # a send can swallow the FD's edge for a subscription that arrived meanwhile: the safety poll (50 ms)
        # and wants() (which drains when its answer would be no) catch it
        return True

    def _send_lossy(self, frames: list) -> None:
        """Send to the subscribers whose queue has room, the full ones skipped (lock held)."""
        sock = self.sock
        sock.setsockopt(zmq.XPUB_NODROP, 0)
        try:
            send_frames(sock, frames)
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
        while sock.getsockopt(EVENTS) & POLLIN:
            try:
                msg = sock.recv(NOBLOCK)
            except zmq.Again:
                break
            kind, prefix = msg[:1], msg[1:]
            if kind == b"\x01":  # a subscription: resend latched values it matches
                changed = changed or prefix not in self.prefixes
                self.prefixes.add(prefix)
                for topic, frames in self.latched.items():
                    if topic.startswith(prefix):
                        try:
                            send_frames(sock, frames)
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
            # (src/session_base.cpp:233)", zeromq/libzmq#3442; it killed the camera
            # node at a launch's shutdown). Reproduced with 4 subscribers closing as
            # the XPUB closes after 0.6 MB frames: 6 aborts in 60 runs at linger 0,
            # none in 210 at 100 ms. ctx.term() then waits at most CLOSE_LINGER_MS.
            self.sock.close(linger=CLOSE_LINGER_MS)
