"""CURVE on the graph: a publisher that is not the listed host (no CURVE, or an unlisted key) on the
arm-target topic is refused by the subscriber's handshake, so nothing it sends reaches an arm bridge."""

from __future__ import annotations

import asyncio
import subprocess
import sys

import numpy as np
import pytest
import zmq.auth
from conftest import free_port

from flexsheet.runtime.launch import LaunchError, load_launch, node_config
from flexsheet.runtime.node import Node, NodeConfig, QoS
from flexsheet.runtime.transport import CurveConfig
from messages import ArmTarget
from messages import topics as T


def _keys(tmp_path, *hosts):
    out = subprocess.run([sys.executable, "-m", "flexsheet", "keys", "generate", *hosts, "-o", str(tmp_path / "keys")],
                         capture_output=True, text=True, check=True)
    return out.stdout  # the launch-file block


def _launch(tmp_path, block: str):
    p1, p2 = free_port(), free_port()
    text = f"""
name: secure
hosts:
  main: {{address: 127.0.0.1}}
  arm1: {{address: 127.0.0.1}}
nodes:
  planner: {{type: planner, host: main, port: {p1}}}
  arm_left: {{type: arm_bridge, host: arm1, port: {p2}}}
{block.split(chr(10), 1)[1]}"""
    path = tmp_path / "secure.yaml"
    path.write_text(text)
    return load_launch(path)


class Sink(Node):
    async def setup(self) -> None:
        self.got: list[ArmTarget] = []
        self.subscribe(T.ARM_LEFT_TARGET, lambda m: self.got.append(m), qos=QoS.KEEP_ALL)


class Source(Node):
    async def setup(self) -> None:
        self.pub = self.publisher(T.ARM_LEFT_TARGET)
        self.timer(0.01, lambda: self.pub.publish(ArmTarget(header=self.pub.header("display"), arm="left",
                                                            pose=np.eye(4))))


async def _exchange(source_cfg: NodeConfig, sink_cfg: NodeConfig, seconds: float = 1.0) -> int:
    sink, source = Sink(sink_cfg), Source(source_cfg)
    tasks = [asyncio.get_running_loop().create_task(n.run(install_signals=False)) for n in (sink, source)]
    await asyncio.sleep(seconds)
    for n in (sink, source):
        n.shutdown()
    await asyncio.gather(*tasks)
    return len(sink.got)


def test_listed_publisher_gets_through_and_strangers_do_not(tmp_path):
    block = _keys(tmp_path, "main", "arm1")
    lf = _launch(tmp_path, block)
    assert lf.security.curve
    legit, bridge = node_config(lf, "planner"), node_config(lf, "arm_left")
    assert bridge.curve is not None and legit.curve is not None
    stranger_pub, stranger_secret = zmq.auth.load_certificate(
        zmq.auth.create_certificates(tmp_path, "stranger")[1])
    plain = NodeConfig(name="rogue_plain", endpoint=legit.endpoint)                       # no CURVE at all
    unlisted = NodeConfig(name="rogue_key", endpoint=legit.endpoint,                     # CURVE, wrong key
                          curve=CurveConfig(stranger_pub, stranger_secret, allowed_clients=legit.curve.allowed_clients))
    counts = {name: asyncio.run(_exchange(cfg, bridge))
              for name, cfg in (("legit", legit), ("plain", plain), ("unlisted", unlisted))}
    assert counts["legit"] > 20, counts
    assert counts["plain"] == 0 and counts["unlisted"] == 0, counts


def test_unlisted_subscriber_is_refused_by_the_publisher(tmp_path):
    block = _keys(tmp_path, "main", "arm1")
    lf = _launch(tmp_path, block)
    legit, bridge = node_config(lf, "planner"), node_config(lf, "arm_left")
    spy_pub, spy_secret = zmq.auth.load_certificate(zmq.auth.create_certificates(tmp_path, "spy")[1])
    spy = NodeConfig(name="spy", endpoint="", peers=bridge.peers,
                     curve=CurveConfig(spy_pub, spy_secret, server_keys=bridge.curve.server_keys))
    assert asyncio.run(_exchange(legit, spy)) == 0


def test_curve_config_errors_name_the_key(tmp_path):
    block = _keys(tmp_path, "main")   # no key for arm1
    with pytest.raises(LaunchError, match="security.public_keys.*arm1"):
        _launch(tmp_path, block)
