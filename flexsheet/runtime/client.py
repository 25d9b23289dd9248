"""A tool's handle on the live graph, for synchronous code that drives it (``flexsheet calibrate display
--live``): the nodes' services, the newest message of a topic, and the next messages of a topic stamped after
an instant.

:class:`GraphClient` runs its own event loop in a background thread, subscribed to every endpoint of the
launch file (with its CURVE keys); methods block the caller, never the loop. Nothing here knows the display.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable
from typing import Any

from flexsheet.runtime.codec import DecodeError, decode
from flexsheet.runtime.launch import load_launch
from flexsheet.runtime.launch_config import curve_config
from flexsheet.runtime.services import ServiceError, call_async
from flexsheet.runtime.zmq.transport import ZmqTransport
from messages import Heartbeat, Message
from messages import topics as T

__all__ = ["GraphClient"]


class GraphClient:
    """Connect to the graph of launch file ``launch`` as a tool of ``host`` (its CURVE keys; None: the first
    host whose key is here); use as a context manager (or :meth:`close`).

    Raises :class:`flexsheet.runtime.launch.LaunchError` for an unusable launch file or missing keys."""

    def __init__(self, launch: str, host: str | None = None):
        self.lf = load_launch(launch)
        self.launch = launch
        self.curve = curve_config(self.lf, host)
        self._beats: dict[str, Heartbeat] = {}
        self._latest: dict[str, Message] = {}
        self._topics: dict[str, T.Topic] = {}
        self._collect: dict[str, list] = {}
        self._keep_latest: set[str] = set()
        self._lock = threading.Lock()
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="graph-client", daemon=True)
        self._thread.start()
        self._ready.wait(10.0)
        if self._error is not None:
            raise self._error
        self.watch(T.DIAGNOSTICS)

    # ------------------------------------------------------------------ loop thread
    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        self._tr = ZmqTransport("", list(self.lf.endpoints().values()), curve=self.curve)
        try:
            self._loop.run_until_complete(self._tr.start(self._on_frames))
        except BaseException as exc:  # noqa: BLE001 - handed to the constructor's caller
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        self._loop.run_forever()

    def _on_frames(self, frames: list) -> None:
        name = bytes(frames[0]).decode(errors="replace")
        topic = self._topics.get(name)
        if topic is None:
            return
        with self._lock:
            sink = self._collect.get(name)
        if (name != T.DIAGNOSTICS.name and sink is None and not topic.latched
            and name not in self._keep_latest):
            return
        try:
            msg = decode(frames, topic)
        except DecodeError:
            return
        with self._lock:
            if isinstance(msg, Heartbeat):
                self._beats[msg.node] = msg
            self._latest[name] = msg
            if sink is not None:
                sink.append(msg)

    def _do(self, fn: Callable[[], Any]) -> Any:
        done = threading.Event()
        box: list = []

        def run():
            try:
                box.append((True, fn()))
            except BaseException as exc:  # noqa: BLE001 - re-raised in the caller's thread
                box.append((False, exc))
            done.set()

        self._loop.call_soon_threadsafe(run)
        done.wait()
        ok, value = box[0]
        if not ok:
            raise value
        return value

    # ------------------------------------------------------------------ API
    def watch(self, topic: T.Topic, keep_latest: bool = True) -> None:
        """Subscribe to ``topic``; with ``keep_latest`` its newest message is kept (:meth:`latest`)."""
        if keep_latest:
            self._keep_latest = self._keep_latest | {topic.name}
        if topic.name not in self._topics:        # subscribed once; a second watch only changes keep_latest
            self._topics[topic.name] = topic
            self._do(lambda: self._tr.subscribe(topic.name))

    def latest(self, topic: T.Topic) -> Message | None:
        """The newest message of a watched ``topic`` (None before the first)."""
        with self._lock:
            return self._latest.get(topic.name)

    def wait(self, what: str, predicate: Callable[[], Any], timeout: float, poll: float = 0.02) -> Any:
        """Poll ``predicate`` until it returns something true; that value. Raises ``TimeoutError`` naming
        ``what`` after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while True:
            v = predicate()
            if v:
                return v
            if time.monotonic() > deadline:
                raise TimeoutError(f"{what}: not within {timeout:g} s")
            time.sleep(poll)

    def collect(self, topic: T.Topic, n: int, after: float, timeout: float,
                stamp: Callable[[Message], float] = lambda m: m.header.stamp) -> list[Message]:
        """The next ``n`` messages of ``topic`` whose ``stamp(msg)`` (s, the graph's clock) is at least
        ``after``. Raises ``TimeoutError`` saying how many came within ``timeout`` s."""
        self.watch(topic, keep_latest=topic.name in self._keep_latest)
        sink: list = []
        with self._lock:
            self._collect[topic.name] = sink
        try:
            deadline = time.monotonic() + timeout
            while True:
                with self._lock:
                    good = [m for m in sink if stamp(m) >= after]
                if len(good) >= n:
                    return good[:n]
                if time.monotonic() > deadline:
                    raise TimeoutError(f"{topic.name}: {len(good)} of {n} messages stamped after {after:.3f} "
                                       f"s within {timeout:g} s")
                time.sleep(0.01)
        finally:
            with self._lock:
                self._collect.pop(topic.name, None)

    def node(self, name: str, timeout: float = 5.0) -> Heartbeat:
        """The newest heartbeat of node ``name``; raises ``TimeoutError`` naming the nodes heard."""
        try:
            return self.wait(f"node {name!r} heard", lambda: self._beats.get(name), timeout)
        except TimeoutError:
            raise TimeoutError(f"node {name!r} not heard in {timeout:g} s (heard: "
                               f"{', '.join(sorted(self._beats)) or 'none'}; graph of "
                               f"{self.launch})") from None

    def call(self, node: str, service: str, args: dict | None = None, timeout: float = 5.0) -> Any:
        """Call ``service`` of ``node``; its result. Raises :class:`flexsheet.runtime.services.ServiceError`
        with the node's error line, ``TimeoutError`` when the node is not heard."""
        hb = self.node(node, timeout)
        if not hb.service_endpoint:
            raise ServiceError(f"node {node!r} offers no services")
        key = self.curve.server_keys.get(hb.endpoint) if self.curve is not None else None
        fut = asyncio.run_coroutine_threadsafe(
            call_async(hb.service_endpoint, service, args or {}, timeout, self.curve, key), self._loop)
        return fut.result(timeout + 5.0)

    def now(self, node: str) -> float:
        """The graph's clock, s, as ``node`` reads it (its ``clock/now`` service)."""
        return float(self.call(node, "clock/now"))

    def close(self) -> None:
        """Stop the loop and close the sockets."""
        if self._thread.is_alive():
            async def shut() -> None:
                self._tr.close()
                for _ in range(3):          # let the transport's cancelled tasks finish before the loop stops
                    await asyncio.sleep(0)
            try:
                asyncio.run_coroutine_threadsafe(shut(), self._loop).result(5.0)
            except Exception:  # noqa: BLE001 - closing must not fail: the loop is stopped below regardless
                pass
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(5.0)

    def __enter__(self) -> GraphClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
