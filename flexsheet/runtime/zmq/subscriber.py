"""The SUB side of a process: :func:`connect_sub`, :class:`SubLinks` (a SUB socket to every peer, plus one per
set of publishers a guarded topic is restricted to) and a composable container's :class:`BusSocket`."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable

import zmq

from flexsheet.runtime.transport import FramesHandler, TransportError
from flexsheet.runtime.zmq.curve import CurveConfig, allow_list
from flexsheet.runtime.zmq.frames import drain_sub
from flexsheet.runtime.zmq.linkwatch import LinkWatch

__all__ = ["connect_sub", "SubLinks", "BusSocket"]

_monotonic = time.monotonic


def connect_sub(ctx: zmq.Context, peers: list[str], curve: CurveConfig | None, rcvhwm: int,
                on_error: Callable[[], None] | None = None) -> tuple[zmq.Socket, LinkWatch]:
    """A SUB socket on ``ctx`` connected to every endpoint of ``peers`` (CURVE client when ``curve``), and its
    :class:`LinkWatch`, whose monitor is attached before the first connect (so no handshake goes unseen).

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
    watch = LinkWatch(sub, peers, curve)   # the monitor first: a handshake done before it would never be seen
    for peer in peers:
        try:
            if curve is not None:
                if peer not in curve.server_keys:
                    raise TransportError(f"CURVE is on but no public key is listed for peer {peer!r}")
                sub.curve_serverkey = curve.server_keys[peer]  # applies to this connect only
            sub.connect(peer)
        except (zmq.ZMQError, TransportError) as exc:
            watch.close()
            sub.close(linger=0)
            if on_error is not None:
                on_error()
            if isinstance(exc, TransportError):
                raise
            raise TransportError(f"cannot connect to peer endpoint {peer!r}: {exc}") from None
    return sub, watch


class SubLinks:
    """The SUB side of one process: a SUB socket connected to every peer (with its :class:`LinkWatch`), plus,
    under CURVE with guarded topics (``curve.topic_publishers``), one SUB socket per set of allowed
    publishers, connected to those endpoints alone.

    A guarded topic is subscribed on its publishers' socket only, so another node's publisher (ZMTP filters at
    the publisher) never sends it and the SUB's own filter drops it should it come; a message of a guarded
    topic that arrives on the socket of every peer under a wider prefix subscription ("") is dropped too (it
    may be the allowed publisher's copy, which arrives on its own socket, or another node's: the socket cannot
    tell, so nothing is counted). Every socket's links heal (:class:`LinkWatch`). ``on_error`` is called
    before a :class:`TransportError` (bad peer) is raised. Runs on the loop thread.
    """

    def __init__(self, ctx: zmq.Context, peers: Iterable[str], curve: CurveConfig | None, rcvhwm: int,
                 on_error: Callable[[], None] | None = None) -> None:
        self.peers = [p for p in dict.fromkeys(peers) if p]
        self.curve = curve
        self.sock, self.watch = connect_sub(ctx, self.peers, curve, rcvhwm, on_error)
        self.guards: dict[bytes, tuple[str, ...]] = {}
        self.guarded: dict[tuple[str, ...], tuple[zmq.Socket, LinkWatch]] = {}
        self._general = self._filtered = None
        for topic, eps in (curve.topic_publishers if curve is not None else {}).items():
            allowed = tuple(sorted(ep for ep in dict.fromkeys(eps) if ep in self.peers))
            self.guards[topic.encode()] = allowed
            if allowed and allowed not in self.guarded:
                try:
                    self.guarded[allowed] = connect_sub(ctx, list(allowed), curve, rcvhwm, on_error)
                except TransportError:
                    self.close()
                    raise

    def fds(self) -> list[int]:
        """The (edge-triggered) file descriptors of every SUB socket, for ``loop.add_reader``."""
        return [s.getsockopt(zmq.FD) for s in self._socks() if not s.closed]

    def _socks(self) -> list[zmq.Socket]:
        return [self.sock] + [s for s, _ in self.guarded.values()]

    def subscribe(self, prefix: bytes) -> None:
        """Subscribe ``prefix``: a guarded topic on its publishers' socket alone; any other prefix on the
        socket of every peer, plus each guarded topic it covers on that topic's publishers' socket."""
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
                    raise ValueError(f"CURVE is on: {endpoint} needs the public key of one of the launch "
                                     "file's identities")
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


class BusSocket:
    """A composable container's SUB side (:class:`SubLinks`), with the ZeroMQ context (and CURVE
    authenticator) its nodes' :class:`XPub` sockets share (:class:`flexsheet.runtime.bus.Bus`).

    ``peers``: endpoints to connect to; ``curve``: CURVE keys or None; ``rcvhwm``: receive high-water mark."""

    def __init__(self, peers: list[str], curve: CurveConfig | None, rcvhwm: int) -> None:
        self.ctx = zmq.Context()
        self._auth = allow_list(self.ctx, curve)[0] if curve is not None else None
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

