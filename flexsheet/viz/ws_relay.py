"""The live view's front door: a WebSocket relay that accepts both names of the Foxglove WebSocket protocol.

The ``foxglove-sdk`` server speaks the Foxglove WebSocket protocol v1 but accepts only the subprotocol name
``foxglove.sdk.v1``; the official ``@foxglove/ws-protocol`` client and Lichtblick offer only
``foxglove.websocket.v1`` and get HTTP 400. The two names carry the same protocol (foxglove/ws-protocol#916,
lichtblick-suite/lichtblick#819). :class:`SubprotocolRelay` listens on the public address with the
``websockets`` library, takes a viewer that offers either name (answering with the name it offered), opens one
upstream connection per viewer to the SDK server under ``foxglove.sdk.v1`` and copies every frame both ways,
text as text and binary as binary, unchanged. It runs on its own thread and event loop, so a viewer never
costs the node's loop (in the simulated graph, the lockstep clock's).
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading

from websockets.asyncio.client import connect
from websockets.asyncio.server import ServerConnection, serve
from websockets.exceptions import ConnectionClosed

__all__ = ["SUBPROTOCOLS", "UPSTREAM_SUBPROTOCOL", "SubprotocolRelay"]

log = logging.getLogger(__name__)

#: the names a viewer may offer, in the server's order of preference
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
#: the only name the foxglove-sdk server accepts
UPSTREAM_SUBPROTOCOL = "foxglove.sdk.v1"
#: frames and bytes the relay holds for a viewer that stops reading: little, so that the server's per-viewer
#: backlog (``message_backlog_size``) is what fills and drops the oldest frames, as without the relay
RELAY_QUEUE = 2
RELAY_RCVBUF = 64 << 10


class SubprotocolRelay:
    """Relay viewers on ``host``:``port`` (0: a free port, see :attr:`port`) to the SDK server at
    ``upstream_port`` on 127.0.0.1. :meth:`start` returns once listening; raises ``OSError`` naming the
    address when it cannot bind. :meth:`stop` closes every connection and ends the thread. ``viewers``:
    connected now; ``dropped``: message-data frames a slow viewer did not get."""

    def __init__(self, host: str, port: int, upstream_port: int) -> None:
        self.host, self.port, self.upstream = host, int(port), f"ws://127.0.0.1:{int(upstream_port)}"
        self.viewers = 0
        self.dropped = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._stop: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    def start(self, timeout: float = 10.0) -> None:
        self._thread = threading.Thread(target=self._run, name="viz-ws-relay", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise OSError(f"the live view's relay did not start on {self.host}:{self.port} in {timeout} s")
        if self._error is not None:
            raise OSError(f"cannot serve the live view on {self.host}:{self.port}: {self._error}") from None

    def stop(self) -> None:
        if self._loop is not None and self._stop is not None and self._loop.is_running():
            self._loop.call_soon_threadsafe(self._stop.set)
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def _run(self) -> None:
        try:
            asyncio.run(self._serve())
        except BaseException as exc:  # noqa: BLE001 - a bind error is reported to start(); later ones logged
            if not self._ready.is_set():
                self._error = exc
                self._ready.set()
            else:
                log.error("live view relay stopped: %s", exc)

    async def _serve(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        async with serve(self._viewer, self.host, self.port, subprotocols=SUBPROTOCOLS, max_size=None,
                         compression=None, write_limit=RELAY_RCVBUF) as server:
            self.port = server.sockets[0].getsockname()[1]
            self._ready.set()
            await self._stop.wait()

    async def _viewer(self, ws: ServerConnection) -> None:
        """One viewer: an upstream connection of its own, frames copied both ways until either side closes."""
        self.viewers += 1
        down = ws.transport.get_extra_info("socket")
        if down is not None:
            down.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, RELAY_RCVBUF)
        try:
            async with connect(self.upstream, subprotocols=[UPSTREAM_SUBPROTOCOL], max_size=None,
                               compression=None, max_queue=RELAY_QUEUE) as up:
                sock = up.transport.get_extra_info("socket")
                if sock is not None:     # a viewer that stops reading backs up into the server's own backlog
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RELAY_RCVBUF)
                pumps = [asyncio.create_task(self._pump(ws, up)),
                         asyncio.create_task(self._to_viewer(up, ws))]
                await asyncio.wait(pumps, return_when=asyncio.FIRST_COMPLETED)
                for t in pumps:
                    t.cancel()
        except (OSError, ConnectionClosed) as exc:
            log.warning("live view: viewer %s dropped: %s", ws.remote_address, exc)
        finally:
            self.viewers -= 1

    async def _to_viewer(self, up, ws: ServerConnection) -> None:
        """Server → viewer. A message-data frame (binary, opcode 1) that finds the viewer's send buffer above
        :data:`RELAY_RCVBUF` is dropped (counted in ``dropped``), as the server drops for a slow viewer; every
        other frame (control, advertisements, replies) is sent whatever it waits."""
        try:
            async for frame in up:
                if (type(frame) is bytes and frame[:1] == b"\x01"
                        and ws.transport.get_write_buffer_size() > RELAY_RCVBUF):
                    self.dropped += 1
                    continue
                await ws.send(frame)
        except ConnectionClosed:
            pass
        finally:
            await ws.close()

    @staticmethod
    async def _pump(src, dst) -> None:
        try:
            async for frame in src:
                await dst.send(frame)
        except ConnectionClosed:
            pass
        finally:
            await dst.close()
