"""In-process harness for node tests: scripted inputs in, recorded outputs out, real codec in between.

Example::

    async def scenario():
        async with NodeHarness(PlannerNode, params={"object_stiffness": 20.0}) as h:
            h.inject(topics.FINGERTIP, msg) out = await h.wait_for(topics.SHEET_TARGET, n=1, timeout=2.0)
            assert h.rejected(topics.FINGERTIP) == 0 asyncio.run(scenario())

Source: dora-rs ``testing.py`` MockNode, proxystore's in-process stream (house rule 3).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import defaultdict
from collections.abc import Iterator

from flexsheet.runtime.codec import decode, encode
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.console import CONSOLE
from flexsheet.runtime.node import Node
from flexsheet.runtime.transport import InProcTransport
from messages import Message, Topic

__all__ = ["NodeHarness", "console_lines"]


class NodeHarness:
    """Runs one node in this process on an :class:`InProcTransport`.

    ``published[name]`` holds the decoded messages the node published on topic ``name`` (in order).
    Raises ``pydantic.ValidationError`` at construction for bad ``params``.
    """

    def __init__(self, node_cls: type[Node], params: dict | None = None, name: str = "harness",
                 remaps: dict[str, str] | None = None) -> None:
        self.transport = InProcTransport()
        self.node = node_cls(NodeConfig(name=name, node_type=node_cls.node_type, params=params or {},
                                        remaps=remaps or {}), transport=self.transport)
        self.published: dict[str, list[Message]] = defaultdict(list)
        self._raw: dict[str, list[list]] = defaultdict(list)
        self.transport.listeners.append(self._record)
        self._task: asyncio.Task | None = None

    def _record(self, frames: list) -> None:
        self._raw[frames[0].decode()].append(frames)

    async def __aenter__(self) -> NodeHarness:
        self._task = asyncio.get_running_loop().create_task(self.node.run(install_signals=False))
        for _ in range(2000):  # wait for setup() to finish (heartbeat publisher exists after start)
            if self.node._stop is not None and hasattr(self.node, "_hb_pub") and all(
                    s.task is not None for lst in self.node._subs.values()
                    for s in lst) and self._setup_done():
                break
            if self._task.done():
                self._task.result()  # re-raise a setup error
            await asyncio.sleep(0.005)
        return self

    def _setup_done(self) -> bool:
        return any(t for t in self.node._timers)  # heartbeat timer is started after setup()

    async def __aexit__(self, *exc) -> None:
        self.node.shutdown()
        if self._task is not None:
            await asyncio.wait_for(self._task, timeout=5.0)

    def inject(self, topic: Topic, msg: Message) -> None:
        """Deliver ``msg`` to the node on ``topic`` (encoded and decoded exactly as on the wire)."""
        self.transport.deliver(encode(topic.name, msg))

    def inject_raw(self, topic: Topic, frames: list[bytes]) -> None:
        """Deliver raw frames after the topic frame (e.g. ``[b"garbage"]``) to test rejection."""
        self.transport.deliver([topic.name.encode(), *frames])

    def messages(self, topic: Topic) -> list[Message]:
        """All messages the node published on ``topic`` so far, decoded and validated."""
        return [decode(f, topic) for f in self._raw.get(topic.name, [])]

    async def wait_for(self, topic: Topic, n: int = 1, timeout: float = 2.0) -> list[Message]:
        """Wait until the node published at least ``n`` messages on ``topic``; returns them all.

        Raises ``TimeoutError`` naming the topic and how many arrived.
        """
        deadline = time.monotonic() + timeout
        while len(self._raw.get(topic.name, [])) < n:
            if time.monotonic() > deadline:
                raise TimeoutError(f"{topic.name}: {len(self._raw.get(topic.name, []))} of {n} messages in "
                                   f"{timeout} s")
            if self._task is not None and self._task.done():
                self._task.result()
            await asyncio.sleep(0.002)
        return self.messages(topic)

    async def settle(self, seconds: float = 0.05) -> None:
        """Let queued messages be handled (handlers in worker threads included)."""
        await asyncio.sleep(seconds)

    def rejected(self, topic: Topic | None = None) -> int:
        """Rejections counted so far for ``topic`` (all topics if None)."""
        if topic is None:
            return self.node.rejected_total
        return sum(s.stats.rejected for s in self.node._subs.get(topic.name, []))


class _Lines(logging.Handler):
    def __init__(self, lines: list[str]) -> None:
        super().__init__()
        self.lines = lines

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


@contextlib.contextmanager
def console_lines() -> Iterator[list[str]]:
    """The lines a launcher or a container shows the user (:mod:`flexsheet.runtime.console`) while the block
    runs, collected in the list it yields."""
    lines: list[str] = []
    log, handler = logging.getLogger(CONSOLE), _Lines(lines)
    level = log.level
    log.setLevel(logging.INFO)
    log.addHandler(handler)
    try:
        yield lines
    finally:
        log.removeHandler(handler)
        log.setLevel(level)
