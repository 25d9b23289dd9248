"""Talker and listener: the smallest nodes, used by runtime tests, the transport benchmark and docs.

The talker publishes a :class:`messages.Fingertip` on ``/fingertip`` at ``rate`` Hz with an increasing
x position (m); the listener subscribes with ``qos`` and logs/prints what it gets.
"""

from __future__ import annotations

import time

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from flexsheet.runtime.node import Node
from flexsheet.runtime.qos import QoS
from messages import Fingertip
from messages import topics as T

__all__ = ["TalkerNode", "ListenerNode"]


class TalkerParams(BaseModel):
    """``rate`` Hz (> 0); ``count``: stop after this many messages (0 = forever); ``start_delay`` s before
    the first message (lets subscribers connect first); ``worker_s``: > 0 starts a child process at setup that
    sleeps this long holding the node's output, not tied to its parent (as a node's table builder is while it
    still imports; the launcher must not wait for it when the node dies: tests/system/test_runtime_launch.py);
    ``exit_lines``: lines printed at teardown (a node with much to say as it stops: the launcher must still
    record that exit, tests/system/test_runtime_launch.py)."""

    model_config = ConfigDict(extra="forbid")
    rate: float = Field(default=10.0, gt=0.0, le=100000.0)
    count: int = Field(default=0, ge=0)
    start_delay: float = Field(default=0.0, ge=0.0)
    worker_s: float = Field(default=0.0, ge=0.0, le=3600.0)
    exit_lines: int = Field(default=0, ge=0, le=1_000_000)


class TalkerNode(Node):
    """Publishes a synthetic fingertip at ``rate`` Hz (for tests and demos)."""

    Params = TalkerParams
    node_type = "talker"

    async def setup(self) -> None:
        self.pub = self.publisher(T.FINGERTIP)
        self.n = 0
        self.t_start = time.monotonic() + self.params.start_delay
        self.timer(1.0 / self.params.rate, self.tick)
        if self.params.worker_s > 0:
            import subprocess
            import sys

            w = subprocess.Popen([sys.executable, "-c", f"import time; time.sleep({self.params.worker_s!r})"])
            print(f"talker: worker pid {w.pid}", flush=True)

    async def teardown(self) -> None:
        if self.params.exit_lines:
            import sys

            sys.stdout.write("".join(f"talker: last words {i}\n" for i in range(self.params.exit_lines)))
            sys.stdout.flush()

    def tick(self) -> None:
        if (self.params.count and self.n >= self.params.count) or time.monotonic() < self.t_start:
            return
        now = time.time()
        pos = np.array([0.001 * self.n, 0.0, 0.0])
        self.pub.publish(Fingertip(header=self.pub.header("display", now), position=pos,
                                   covariance=np.eye(3) * 1e-8,
                                   valid=True, predicted_position=pos, exposure_stamp=now))
        self.n += 1


class ListenerParams(BaseModel):
    """``qos``: latest | keep_all | latched; ``delay``: s of simulated work per message (tests QoS)."""

    model_config = ConfigDict(extra="forbid")
    qos: str = Field(default="keep_all", pattern="^(latest|keep_all|latched)$")
    delay: float = Field(default=0.0, ge=0.0)


class ListenerNode(Node):
    """Prints ``heard seq=N x=...`` for every fingertip it handles (sync handler, worker thread)."""

    Params = ListenerParams
    node_type = "listener"
    DYNAMIC_PARAMS = frozenset({"delay"})

    async def setup(self) -> None:
        self.subscribe(T.FINGERTIP, self.on_fingertip, qos=QoS(self.params.qos))

    def on_fingertip(self, msg: Fingertip) -> None:
        if self.params.delay:
            time.sleep(self.params.delay)
        print(f"heard seq={msg.header.seq} x={msg.position[0]:.3f}", flush=True)
