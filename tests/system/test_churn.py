"""A graph stays up while short-lived clients connect and leave (slow tier, loopback only, bounded).

One node process (the graph: a publisher at 500 Hz with its service socket, ``PYTHONFAULTHANDLER=1``) runs for
:data:`SECONDS` s while :data:`CLIENTS` client processes at a time, all pinned to core 0 with the graph
(``taskset -c 0``: a busy core, as the crash reports had), each connect a SUB socket, subscribe (the topic and
a prefix of their own, so each departure reaches the publisher as an unsubscription), read for ~20 ms, call
the node's ``list`` service once and leave: ``close(linger=0)``, or SIGKILL at random. Half the runs are
CURVE. The graph must end by itself with exit 0: a death by a signal (libzmq's I/O-thread crash,
zeromq/libzmq#4524) or no clean exit by the deadline fails.

The positive control (:func:`test_the_churn_crashes_a_graph_that_changes_its_hwm_on_the_live_socket`) turns
on a switch in the graph script only: after each departure it changes ``SNDHWM`` on the live XPUB socket,
the very call the runtime never makes; the stock libzmq 4.3.5 then dies under the same churn.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zmq

from flexsheet.runtime.ports import free_port

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
SECONDS = 90.0        #: how long the graph runs under churn
CLIENTS = 16          #: client processes alive at a time

GRAPH = r'''
import asyncio, json, os, sys, time
import numpy as np
import zmq
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.node import Node
from flexsheet.runtime.zmq.curve import CurveConfig
from flexsheet.runtime.zmq.xpub import XPub
from messages import Fingertip
from messages import topics as T

ep, seconds = sys.argv[1], float(sys.argv[2])
keys = json.loads(os.environ["CHURN_KEYS"]) if os.environ.get("CHURN_KEYS") else None
if os.environ.get("CHURN_LIVE_HWM") == "1":   # the positive control: the call the runtime never makes
    _drain = XPub._drain_locked
    def _drain_and_change_hwm(self):
        n = len(self.prefixes)
        _drain(self)
        if len(self.prefixes) < n and not self.sock.closed:    # a client left: its pipe is being torn down
            self.sndhwm = 1000 + (self.sndhwm + 1) % 1000
            self.sock.setsockopt(zmq.SNDHWM, self.sndhwm)
    XPub._drain_locked = _drain_and_change_hwm

class Graph(Node):
    async def setup(self):
        self.pub = self.publisher(T.FINGERTIP)
        self.timer(0.002, self.tick)
    def tick(self):
        p = np.zeros(3)
        self.pub.publish(Fingertip(header=self.pub.header("display"), position=p, covariance=np.eye(3) * 1e-8,
                                   valid=True, predicted_position=p, exposure_stamp=time.time()))

async def main():
    curve = None
    if keys:
        curve = CurveConfig(public_key=keys["server_public"].encode(), secret_key=keys["server_secret"].encode(),
                            allowed_clients=[keys["client_public"].encode()],
                            tool_keys=[keys["client_public"].encode()])
    node = Graph(NodeConfig(name="graph", endpoint=ep, peers=[], curve=curve))
    task = asyncio.get_running_loop().create_task(node.run(install_signals=False))
    while not node.ready:
        await asyncio.sleep(0.01)
    print(json.dumps({"service": node.services.endpoint}), flush=True)
    await asyncio.sleep(seconds)
    node.shutdown()
    await task
    print(json.dumps({"clean_exit": True}), flush=True)

asyncio.run(main())
'''  # noqa: E501 - a table, template or command line kept whole

CLIENT = r'''
import json, os, random, signal, sys, time
import msgpack, zmq
ep, service = sys.argv[1], sys.argv[2]
keys = json.loads(os.environ["CHURN_KEYS"]) if os.environ.get("CHURN_KEYS") else None
ctx = zmq.Context()
def secure(s):
    if keys:
        s.curve_publickey = keys["client_public"].encode()
        s.curve_secretkey = keys["client_secret"].encode()
        s.curve_serverkey = keys["server_public"].encode()
sub = ctx.socket(zmq.SUB); secure(sub)
sub.connect(ep)
sub.setsockopt(zmq.SUBSCRIBE, b"/fingertip")
sub.setsockopt(zmq.SUBSCRIBE, f"/churn/{os.getpid()}".encode())   # this client's own prefix
end = time.monotonic() + 0.02
while time.monotonic() < end:
    if sub.poll(5):
        sub.recv_multipart()
req = ctx.socket(zmq.DEALER); secure(req)
req.connect(service)
req.send_multipart([b"", msgpack.packb({"service": "list", "args": {}})])
req.poll(200)
if random.random() < 0.3:
    os.kill(os.getpid(), signal.SIGKILL)                # leave without a goodbye
sub.close(linger=0); req.close(linger=0); ctx.term()
'''


def _keys() -> dict:
    sp, ss = zmq.curve_keypair()
    cp, cs = zmq.curve_keypair()
    return {"server_public": sp.decode(), "server_secret": ss.decode(), "client_public": cp.decode(),
            "client_secret": cs.decode()}


def churn(tmp_path: Path, curve: bool, live_hwm: bool, seconds: float = SECONDS,
          clients: int = CLIENTS) -> dict:
    """Run the graph under churn; returns its exit code (negative: the signal that killed it), the cycles of
    clients run, whether it printed its clean exit, and its stderr's last lines."""
    (tmp_path / "graph.py").write_text(GRAPH)
    (tmp_path / "client.py").write_text(CLIENT)
    pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONFAULTHANDLER": "1"}
    env.pop("CHURN_KEYS", None)
    if curve:
        env["CHURN_KEYS"] = json.dumps(_keys())
    genv = {**env, "CHURN_LIVE_HWM": "1" if live_hwm else "0"}
    ep = f"tcp://127.0.0.1:{free_port()}"
    graph = subprocess.Popen(pin + [sys.executable, str(tmp_path / "graph.py"), ep, str(seconds)], env=genv,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = graph.stdout.readline()
    if not line:
        graph.wait(30)
        raise AssertionError(f"the graph did not start: {graph.stderr.read()[-2000:]}")
    service = json.loads(line)["service"]
    alive: list[subprocess.Popen] = []
    cycles, deadline = 0, time.monotonic() + seconds + 60.0
    rng = random.Random(0)
    try:
        while graph.poll() is None and time.monotonic() < deadline:
            alive = [c for c in alive if c.poll() is None]
            while len(alive) < clients and graph.poll() is None:
                alive.append(subprocess.Popen(pin
                                              + [sys.executable, str(tmp_path / "client.py"), ep, service],
                                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
                cycles += 1
            time.sleep(0.005 + 0.01 * rng.random())
    finally:
        for c in alive:
            c.kill()
            c.wait()
        if graph.poll() is None:
            graph.send_signal(signal.SIGKILL)
        out, err = graph.communicate(timeout=30)
    return {"code": graph.returncode, "cycles": cycles, "clean_exit": '"clean_exit": true' in out,
            "stderr": err[-3000:]}


@pytest.mark.parametrize("curve", [False, True], ids=["plain", "curve"])
def test_the_graph_outlives_clients_that_connect_and_leave(tmp_path, curve):
    res = churn(tmp_path, curve=curve, live_hwm=False)
    print(f"churn ({'curve' if curve else 'plain'}): {res['cycles']} clients in {SECONDS:.0f} s, "
          f"graph exit {res['code']}")
    assert res["cycles"] >= 300, res                     # the churn really ran (~9 clients/s on a busy core)
    assert res["code"] == 0 and res["clean_exit"], res   # no death by a signal, a clean exit in time


def test_the_churn_crashes_a_graph_that_changes_its_hwm_on_the_live_socket(tmp_path):
    """The positive control: the same churn kills a graph that changes SNDHWM on its live socket after each
    departure (the pattern of zeromq/libzmq#4524), so the test above can fail."""
    res = churn(tmp_path, curve=False, live_hwm=True)
    print(f"churn control: {res['cycles']} clients, graph exit {res['code']}")
    assert res["code"] in (-signal.SIGSEGV, -signal.SIGABRT, -signal.SIGBUS), res
