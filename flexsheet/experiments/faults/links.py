"""Attacks on the links (:mod:`flexsheet.runtime.zmq`): a node's port squatted while it is down by a
listener that speaks the wrong protocol (garbage after a ZMTP signature; plain ZMTP against CURVE), then
released; a subscriber that never reads 655 kB stereo frames; arm targets sent with a stolen host key and with
another node's own key (authorization per node). Used by ``flexsheet experiment faults`` and
tests/system/test_links_heal.py."""

from __future__ import annotations

import asyncio
import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import zmq

from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.keys import generate
from flexsheet.runtime.launch import identities, load_launch
from flexsheet.runtime.launch_config import curve_config, node_config
from flexsheet.runtime.node import Node
from flexsheet.runtime.ports import free_port
from flexsheet.runtime.qos import QoS
from flexsheet.runtime.zmq.curve import CurveConfig
from messages import ArmTarget
from messages import topics as T

__all__ = ["GARBAGE", "DEADLINE_S", "Sink", "Source", "GarbageSquatter", "PlainZmtpSquatter",
           "squat_then_restart",
           "memory_run", "stolen_keys"]

ROOT = Path(__file__).resolve().parents[3]
#: a ZMTP signature byte, then a greeting no ZMTP peer sends: libzmq ends the session (no retry)
GARBAGE = b"\xff" + bytes(range(1, 64))
DEADLINE_S = 10.0   # generous: the watch's back-off is at most 1 s, libzmq's reconnect interval at most 1 s


class Sink(Node):
    async def setup(self) -> None:
        self.got: list[float] = []
        self.subscribe(T.ARM_LEFT_TARGET, lambda m: self.got.append(time.monotonic()), qos=QoS.KEEP_ALL)


class Source(Node):
    async def setup(self) -> None:
        self.pub = self.publisher(T.ARM_LEFT_TARGET)
        self.timer(0.01, lambda: self.pub.publish(ArmTarget(header=self.pub.header("display"), arm="left",
                                                            pose=np.eye(4))))


class GarbageSquatter:
    """A raw TCP listener on ``port``: answers every connection with :data:`GARBAGE` and holds it."""

    def __init__(self, port: int) -> None:
        self.ls = socket.socket()
        self.ls.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.ls.bind(("127.0.0.1", port))
        self.ls.listen()
        self.conns: list[socket.socket] = []
        self.accepted = 0
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while True:
            try:
                c, _ = self.ls.accept()
            except OSError:
                return
            self.accepted += 1
            self.conns.append(c)
            try:
                c.sendall(GARBAGE)
            except OSError:
                pass

    def release(self) -> None:
        self.ls.shutdown(socket.SHUT_RDWR)   # wakes accept(): a close alone would keep the port bound
        self.ls.close()
        self.thread.join(2.0)
        for c in self.conns:
            c.close()


class PlainZmtpSquatter:
    """A plain (no CURVE) ZeroMQ XPUB bound on the endpoint: a CURVE subscriber's handshake fails with a
    mechanism mismatch."""

    def __init__(self, endpoint: str) -> None:
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.XPUB)
        self.sock.bind(endpoint)
        self.accepted = 0

    def release(self) -> None:
        self.sock.close(linger=0)
        self.ctx.term()


def curve_pair(endpoint: str) -> tuple[CurveConfig, CurveConfig]:
    """(source, sink) CURVE configs: the sink trusts the source's key, the source admits the sink's."""
    src_pub, src_sec = zmq.curve_keypair()
    sink_pub, sink_sec = zmq.curve_keypair()
    return (CurveConfig(src_pub, src_sec, allowed_clients=[sink_pub]),
            CurveConfig(sink_pub, sink_sec, server_keys={endpoint: src_pub}))


async def squat_then_restart(variant: str, heal: bool = True, deadline: float = DEADLINE_S) -> dict:
    """Sink up; the port squatted for 1.5 s (the sink's reconnects hit the squatter); released; the real
    publisher started. Returns counts and the time from the publisher's bind to the sink's first message."""
    port = free_port()
    ep = f"tcp://127.0.0.1:{port}"
    src_curve, sink_curve = curve_pair(ep) if variant == "plain_zmtp_vs_curve" else (None, None)
    sink = Sink(NodeConfig(name="sink", endpoint="", peers=[ep], curve=sink_curve))
    loop = asyncio.get_running_loop()
    tasks = [loop.create_task(sink.run(install_signals=False))]
    source = None
    try:
        while not sink.ready:
            await asyncio.sleep(0.01)
        if not heal:
            sink.transport.watch.poll = lambda now=None: None
        squat = GarbageSquatter(port) if variant == "garbage" else PlainZmtpSquatter(ep)
        await asyncio.sleep(1.5)
        link = sink.transport.watch.links[ep]
        during = {"failures": link.failures, "reconnects": link.reconnects,
                  "report": sink.transport.link_report()}
        squat.release()
        source = Source(NodeConfig(name="source", endpoint=ep, peers=[], curve=src_curve))
        tasks.append(loop.create_task(source.run(install_signals=False)))
        while not source.ready:
            await asyncio.sleep(0.005)
        back = time.monotonic()
        while len(sink.got) < 20 and time.monotonic() - back < deadline:
            await asyncio.sleep(0.02)
        first = sink.got[0] - back if sink.got else None
        return {"variant": variant, "heal": heal, "received": len(sink.got), "recovery_s": first,
                "squat_accepted": getattr(squat, "accepted", None), "reconnects": link.reconnects,
                "failures": link.failures, "reason": link.reason, "during": during, "up": link.up}
    finally:
        for n in (sink, source):
            if n is not None:
                n.shutdown()
        await asyncio.gather(*tasks)


STOLEN_KEYS_LAUNCH = """
name: per_node_keys
hosts:
  main: {{address: 127.0.0.1}}
  arm1: {{address: 127.0.0.1}}
nodes:
  planner: {{type: planner, host: main, port: {p}}}
  arm_left: {{type: arm_bridge, host: arm1, port: {p1}}}
  triangulator: {{type: triangulator, host: main, port: {p2}}}
security: {{curve: true, public_keys_file: $(keys)/public_keys.yaml, publishers: {{/arm/left/target: [planner]}}}}
"""  # noqa: E501 - a table, template or command line kept whole


def stolen_keys(folder: Path, seconds: float = 1.0) -> dict:
    """Arm targets to a bridge's subscription under CURVE with per-node keys and ``security.publishers``
    (``/arm/left/target: [planner]``), from: the planner (the control), a process holding the main host's key
    at the planner's endpoint, and the triangulator with its own key from its own endpoint. Keys are generated
    into ``folder``. Returns the targets received from each (the thief's handshake fails; the triangulator's
    publisher is never asked for the topic) and the bridge's link report."""
    p = free_port(span=3)
    path = folder / "per_node_keys.yaml"
    path.write_text(STOLEN_KEYS_LAUNCH.format(p=p, p1=p + 1, p2=p + 2))
    old = os.environ.get("FLEXSHEET_KEYS")
    os.environ["FLEXSHEET_KEYS"] = str(folder / "keys")
    try:
        lf = load_launch(path)
        generate(identities(lf), folder / "keys")
        bridge = node_config(lf, "arm_left")
        bridge.name = "sink"
        planner, tri = node_config(lf, "planner"), node_config(lf, "triangulator")
        stolen = NodeConfig(name="thief", endpoint=planner.endpoint, peers=[], curve=curve_config(lf, "main"))
    finally:
        if old is None:
            os.environ.pop("FLEXSHEET_KEYS", None)
        else:
            os.environ["FLEXSHEET_KEYS"] = old

    async def exchange(source_cfg: NodeConfig) -> dict:
        sink, source = Sink(bridge), Source(source_cfg)
        tasks = [asyncio.get_running_loop().create_task(n.run(install_signals=False)) for n in (sink, source)]
        await asyncio.sleep(seconds)
        out = {"sent": source.pub.stats.count, "received": len(sink.got)}
        for n in (sink, source):
            n.shutdown()
        await asyncio.gather(*tasks)
        return out

    return {name: asyncio.run(exchange(cfg))
            for name,
            cfg in (("planner", planner), ("host_key_at_planner_port", stolen), ("other_node_key", tri))}


PUBLISHER = r"""
import asyncio, json, sys, time
import numpy as np
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.node import Node
from messages import StereoFrame
from messages import topics as T

ep, seconds, hz, budget = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
if budget:   # the control run: another byte budget
    from flexsheet.runtime.zmq import xpub
    xpub.XPub.__init__.__defaults__ = (xpub.SMALL_MESSAGE_BYTES, budget)

def rss_mb():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0

class Cam(Node):
    LARGEST_MESSAGE_BYTES = 2 * 640 * 512 + (16 << 10)

    async def setup(self):
        self.pub = self.publisher(T.STEREO)
        self.img = np.random.default_rng(0).integers(0, 255, (512, 640), dtype=np.uint8)   # 2 x 328 kB
        self.timer(1.0 / hz, self.tick)

    def tick(self):   # new buffers for every frame, as a camera's (the wire sends them zero-copy)
        self.pub.publish(StereoFrame(header=self.pub.header("camera_left"), left=self.img.copy(),
                                     right=self.img.copy(), exposure_stamp=time.time(), exposure_time=0.005))

async def main():
    node = Cam(NodeConfig(name="cam", endpoint=ep, peers=[]))
    task = asyncio.get_running_loop().create_task(node.run(install_signals=False))
    while not node.ready:
        await asyncio.sleep(0.01)
    await asyncio.sleep(1.0)      # publishing, nobody subscribed: the baseline
    rss0 = rss_mb()
    print(json.dumps({"ready": True}), flush=True)
    sys.stdin.readline()          # the test's subscriber is connected
    t0, samples = time.monotonic(), []
    while time.monotonic() - t0 < seconds:
        await asyncio.sleep(0.25)
        samples.append(rss_mb())
    s = node.pub.stats
    xpub = node.transport.xpub
    print(json.dumps({"rss0": rss0, "rss_max": max(samples), "published": s.count, "dropped": s.dropped,
                      "sndhwm": xpub.sndhwm, "largest": xpub.largest, "budget": xpub.budget_bytes}), flush=True)
    node.shutdown()
    await task

asyncio.run(main())
"""  # noqa: E501 - a table, template or command line kept whole


def memory_run(seconds: float = 8.0, hz: float = 48.0, budget: int = 0) -> dict:
    """A publisher process of 655 kB stereo frames at ``hz`` and a subscriber that connects, subscribes and
    never reads (its receive queue holds one message). Returns the publisher's RSS growth over its RSS while
    nobody subscribed, and its counts. ``budget``: another byte budget per subscriber (0: the default)."""
    port = free_port()
    ep = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-c", PUBLISHER, ep, str(seconds), str(hz), str(budget)],
                            stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, env=env, cwd=ROOT)
    ctx = zmq.Context()
    sub = ctx.socket(zmq.SUB)
    try:
        if not json.loads(proc.stdout.readline())["ready"]:
            raise RuntimeError("the publisher did not come up")
        sub.setsockopt(zmq.RCVHWM, 1)
        sub.setsockopt(zmq.RCVBUF, 64 << 10)
        sub.setsockopt(zmq.SUBSCRIBE, T.STEREO.name.encode())
        sub.connect(ep)
        time.sleep(0.3)
        proc.stdin.write("go\n")
        proc.stdin.flush()
        out = json.loads(proc.stdout.readline())
        proc.wait(timeout=20)
    finally:
        sub.close(linger=0)
        ctx.term()
        if proc.poll() is None:
            proc.kill()
    out["growth_mb"] = out["rss_max"] - out["rss0"]
    out["offered_mb"] = out["published"] * 655360 / 2**20
    return out
