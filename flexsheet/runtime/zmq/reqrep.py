"""Request/reply sockets of the services (:mod:`flexsheet.runtime.services`): a node's :class:`ServiceSocket`
(ROUTER) and the client's :func:`request` (DEALER)."""

from __future__ import annotations

import asyncio

import zmq

from flexsheet.runtime.zmq.curve import CurveConfig

__all__ = ["ServiceSocket", "request"]


class ServiceSocket:
    """A node's service socket (:mod:`flexsheet.runtime.services`): a ROUTER bound on ``address``
    ("tcp://HOST") at a port the OS picks (:attr:`endpoint`), a CURVE server with the node's keys when
    ``curve``, on the node's context ``ctx`` (its ZAP authenticator then covers it) or its own. Requests above
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
        """(caller identity, request payload, the caller's CURVE public key in Z85 or "" without CURVE), or
        None once the socket is closed."""
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
    arrives within ``timeout`` s. ``curve`` (the caller's keys) with ``server_key`` (the node's public
    key)."""
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

