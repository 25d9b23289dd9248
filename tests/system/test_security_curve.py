"""CURVE on the graph: a publisher that is not the listed host (no CURVE, or an unlisted key) on the
arm-target topic is refused by the subscriber's handshake, so nothing it sends reaches an arm bridge. Keys come
from ``flexsheet keys generate`` into ``$FLEXSHEET_KEYS`` and reach the launch file by ``public_keys_file``."""

from __future__ import annotations

import asyncio
import json
import stat
import subprocess
import sys

import numpy as np
import pytest
import yaml
import zmq.auth
from conftest import free_port

from flexsheet.runtime.launch import LaunchError, curve_config, load_launch, node_config
from flexsheet.runtime.node import Node, NodeConfig, QoS
from flexsheet.runtime.transport import CurveConfig
from messages import ArmTarget
from messages import topics as T


def _keys(tmp_path, *hosts):
    """``flexsheet keys generate HOSTS`` into ``$FLEXSHEET_KEYS`` (set by the ``keys_env`` fixture)."""
    out = subprocess.run([sys.executable, "-m", "flexsheet", "keys", "generate", *hosts],
                         capture_output=True, text=True, check=True)
    return out.stdout


@pytest.fixture
def keys_env(tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXSHEET_KEYS", str(tmp_path / "keys"))
    return tmp_path / "keys"


def _launch(tmp_path, security: str = "security: {curve: true, public_keys_file: $(keys)/public_keys.yaml}"):
    p1 = free_port(span=2)
    p2 = p1 + 1
    text = f"""
name: secure
hosts:
  main: {{address: 127.0.0.1}}
  arm1: {{address: 127.0.0.1}}
nodes:
  planner: {{type: planner, host: main, port: {p1}}}
  arm_left: {{type: arm_bridge, host: arm1, port: {p2}}}
{security}
"""
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


def test_listed_publisher_gets_through_and_strangers_do_not(tmp_path, keys_env):
    _keys(tmp_path, "main", "arm1")
    lf = _launch(tmp_path)
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


def test_unlisted_subscriber_is_refused_by_the_publisher(tmp_path, keys_env):
    _keys(tmp_path, "main", "arm1")
    lf = _launch(tmp_path)
    legit, bridge = node_config(lf, "planner"), node_config(lf, "arm_left")
    spy_pub, spy_secret = zmq.auth.load_certificate(zmq.auth.create_certificates(tmp_path, "spy")[1])
    spy = NodeConfig(name="spy", endpoint="", peers=bridge.peers,
                     curve=CurveConfig(spy_pub, spy_secret, server_keys=bridge.curve.server_keys))
    assert asyncio.run(_exchange(legit, spy)) == 0


def test_curve_config_errors_name_the_key_and_the_command(tmp_path, keys_env):
    _keys(tmp_path, "main")   # no key for arm1
    lf = _launch(tmp_path)
    with pytest.raises(LaunchError, match=r"security.public_keys.*arm1.*flexsheet keys generate main arm1"):
        node_config(lf, "planner")
    # inline keys (no file) are checked when the file is loaded
    inline = yaml.safe_load((keys_env / "public_keys.yaml").read_text())
    with pytest.raises(LaunchError, match="security.public_keys.*arm1"):
        _launch(tmp_path, "security: {curve: true, public_keys: " + json.dumps(inline) + "}")


def test_keys_generate_writes_what_the_launch_file_needs_and_keeps_existing_keys(tmp_path, keys_env):
    """One ``keys generate`` (to $FLEXSHEET_KEYS) gives every host a CURVE config; a second run keeps the
    keys (a deployed arm PC stays valid); --force replaces them and public_keys.yaml follows."""
    out = _keys(tmp_path, "main", "arm1")
    assert "new keypair" in out and str(keys_env) in out
    assert stat.S_IMODE(keys_env.stat().st_mode) == 0o700
    assert stat.S_IMODE((keys_env / "arm1.key_secret").stat().st_mode) == 0o600
    first = yaml.safe_load((keys_env / "public_keys.yaml").read_text())
    assert set(first) == {"main", "arm1"} and all(len(k) == 40 for k in first.values())
    lf = _launch(tmp_path)
    cfgs = {h: curve_config(lf, h) for h in ("main", "arm1")}
    assert {h: c.public_key.decode() for h, c in cfgs.items()} == first
    assert "kept" in _keys(tmp_path, "main", "arm1")
    assert yaml.safe_load((keys_env / "public_keys.yaml").read_text()) == first
    subprocess.run([sys.executable, "-m", "flexsheet", "keys", "generate", "arm1", "--force"], check=True,
                   capture_output=True)
    second = yaml.safe_load((keys_env / "public_keys.yaml").read_text())
    assert second["main"] == first["main"] and second["arm1"] != first["arm1"]
    assert curve_config(lf, "arm1").public_key.decode() == second["arm1"]
