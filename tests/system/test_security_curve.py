"""CURVE on the graph, per node: a publisher that does not hold the key of the node at its endpoint (no CURVE,
an unlisted key, the host's tool key) is refused by the subscriber's handshake, and a node of the graph that
is not allowed the arm-target topic (``security.publishers``) has its targets dropped and counted, so nothing
but the planner reaches an arm bridge. Keys come from ``flexsheet keys generate --launch FILE`` into
``$FLEXSHEET_KEYS`` and reach the launch file by ``public_keys_file``."""

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

from flexsheet.runtime.bus import Bus, ContainerTransport
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.launch import LaunchError, load_launch
from flexsheet.runtime.launch_config import curve_config, node_config
from flexsheet.runtime.node import Node
from flexsheet.runtime.qos import QoS
from flexsheet.runtime.zmq.curve import CurveConfig
from messages import ArmTarget
from messages import topics as T


def _keys(launch, *names, check=True):
    """``flexsheet keys generate --launch LAUNCH NAMES`` into ``$FLEXSHEET_KEYS`` (the ``keys_env``
    fixture)."""
    out = subprocess.run([sys.executable, "-m", "flexsheet", "keys", "generate", "--launch", str(launch),
                          *names],
                         capture_output=True, text=True, check=check)
    return out.stdout if check else out


@pytest.fixture
def keys_env(tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXSHEET_KEYS", str(tmp_path / "keys"))
    return tmp_path / "keys"


POLICY = "publishers: {/arm/left/target: [planner]}"


def _launch(tmp_path, security: str = "security: {curve: true, public_keys_file: $(keys)/public_keys.yaml, "
                                      + POLICY + "}"):
    p1 = free_port(span=3)
    text = f"""
name: secure
hosts:
  main: {{address: 127.0.0.1}}
  arm1: {{address: 127.0.0.1}}
nodes:
  planner: {{type: planner, host: main, port: {p1}}}
  arm_left: {{type: arm_bridge, host: arm1, port: {p1 + 1}}}
  triangulator: {{type: triangulator, host: main, port: {p1 + 2}}}
{security}
"""
    path = tmp_path / "secure.yaml"
    path.write_text(text)
    return load_launch(path)


class Sink(Node):
    async def setup(self) -> None:
        self.got: list[ArmTarget] = []
        self.subscribe(T.ARM_LEFT_TARGET, lambda m: self.got.append(m), qos=QoS.KEEP_ALL)


class WideSink(Sink):
    """A sink that also subscribes the wider prefix ``/arm/`` on the wire (as a record-everything tool
    would)."""

    async def setup(self) -> None:
        await super().setup()
        self.transport.subscribe("/arm/")


class Source(Node):
    async def setup(self) -> None:
        self.pub = self.publisher(T.ARM_LEFT_TARGET)
        self.timer(0.01, lambda: self.pub.publish(ArmTarget(header=self.pub.header("display"), arm="left",
                                                            pose=np.eye(4))))


async def _exchange(source_cfg: NodeConfig, sink_cfg: NodeConfig, seconds: float = 1.0,
                    container: bool = False,
                    report: list | None = None) -> int:
    transport = None
    if container:   # the sink as a node of a composable container (the bus's one SUB side, the host's key)
        host_curve = curve_config(_exchange.lf, sink_cfg.host)
        transport = ContainerTransport(Bus("c", sink_cfg.peers, host_curve), sink_cfg.endpoint)
    sink, source = Sink(sink_cfg, transport=transport), Source(source_cfg)
    tasks = [asyncio.get_running_loop().create_task(n.run(install_signals=False)) for n in (sink, source)]
    await asyncio.sleep(seconds)
    if report is not None:
        report.append(sink.heartbeat())
    for n in (sink, source):
        n.shutdown()
    await asyncio.gather(*tasks)
    return len(sink.got)


def test_listed_publisher_gets_through_and_strangers_do_not(tmp_path, keys_env):
    lf = _launch(tmp_path)
    _keys(lf.path)
    assert lf.security.curve
    legit, bridge = node_config(lf, "planner"), node_config(lf, "arm_left")
    assert bridge.curve is not None and legit.curve is not None
    assert legit.curve.public_key != curve_config(lf, "main").public_key   # the node's key, not its host's
    stranger_pub, stranger_secret = zmq.auth.load_certificate(
        zmq.auth.create_certificates(tmp_path, "stranger")[1])
    plain = NodeConfig(name="rogue_plain", endpoint=legit.endpoint)                       # no CURVE at all
    unlisted = NodeConfig(name="rogue_key", endpoint=legit.endpoint,                     # CURVE, wrong key
                          curve=CurveConfig(stranger_pub, stranger_secret,
                                            allowed_clients=legit.curve.allowed_clients))
    host_key = NodeConfig(name="stolen_host_key", endpoint=legit.endpoint,  # main's key at the planner's port
                          curve=curve_config(lf, "main"))
    counts = {name: asyncio.run(_exchange(cfg, bridge))
              for name,
              cfg in (("legit", legit), ("plain", plain), ("unlisted", unlisted), ("host", host_key))}
    assert counts["legit"] > 20, counts
    assert counts["plain"] == 0 and counts["unlisted"] == 0 and counts["host"] == 0, counts


@pytest.mark.parametrize("container", [False, True], ids=["node", "container"])
def test_a_node_not_allowed_the_topic_never_reaches_the_bridge(tmp_path, keys_env, container):
    """The triangulator's own (valid) key, publishing arm targets from its own endpoint: none reaches the
    bridge; the planner's still arrive, on a node alone and in a container."""
    lf = _launch(tmp_path)
    _keys(lf.path)
    _exchange.lf = lf
    bridge, planner, tri = (node_config(lf, n) for n in ("arm_left", "planner", "triangulator"))
    assert bridge.curve.topic_publishers == {"/arm/left/target": [planner.endpoint]}
    hb: list = []
    assert asyncio.run(_exchange(tri, bridge, container=container, report=hb)) == 0
    assert hb[0].state == "ok", hb[0].message   # every link of the bridge is up: the guard, not a broken link
    assert asyncio.run(_exchange(planner, bridge, container=container)) > 20
    # a wider prefix on the wire: the other node's targets still dropped, the planner's once
    if not container:
        for source, lo, hi in ((tri, 0, 0), (planner, 80, 101)):
            sink, src = WideSink(bridge), Source(source)

            async def run(sink=sink, src=src):
                tasks = [asyncio.get_running_loop().create_task(n.run(install_signals=False))
                         for n in (sink, src)]
                await asyncio.sleep(1.0)
                for n in (sink, src):
                    n.shutdown()
                await asyncio.gather(*tasks)

            asyncio.run(run())
            assert lo <= len(sink.got) <= min(hi, src.pub.stats.count), (len(sink.got), src.pub.stats.count)
    # without the policy the triangulator's targets get through: the guard is what stops them
    open_lf = _launch(tmp_path, "security: {curve: true, public_keys_file: $(keys)/public_keys.yaml}")
    _keys(open_lf.path)
    _exchange.lf = open_lf
    assert asyncio.run(_exchange(node_config(open_lf, "triangulator"), node_config(open_lf, "arm_left"),
                                 container=container)) > 20


def test_unlisted_subscriber_is_refused_by_the_publisher(tmp_path, keys_env):
    lf = _launch(tmp_path)
    _keys(lf.path)
    legit, bridge = node_config(lf, "planner"), node_config(lf, "arm_left")
    spy_pub, spy_secret = zmq.auth.load_certificate(zmq.auth.create_certificates(tmp_path, "spy")[1])
    spy = NodeConfig(name="spy", endpoint="", peers=bridge.peers,
                     curve=CurveConfig(spy_pub, spy_secret, server_keys=bridge.curve.server_keys))
    assert asyncio.run(_exchange(legit, spy)) == 0


def test_curve_config_errors_name_the_key_and_the_command(tmp_path, keys_env):
    lf = _launch(tmp_path)
    _keys(lf.path, "main", "planner", "triangulator")   # no key for arm1 nor arm_left
    with pytest.raises(LaunchError, match=r"security.public_keys.*arm1, arm_left.*flexsheet keys generate "
                                          r"--launch .*secure.yaml"):
        node_config(lf, "planner")
    # inline keys (no file) are checked when the file is loaded
    inline = yaml.safe_load((keys_env / "public_keys.yaml").read_text())
    with pytest.raises(LaunchError, match="security.public_keys.*arm1"):
        _launch(tmp_path, "security: {curve: true, public_keys: " + json.dumps(inline) + "}")
    # a policy naming a node the file lacks, or without CURVE, is refused at load
    with pytest.raises(LaunchError, match=r"security.publishers./arm/left/target.*no node named 'plannr'"):
        _launch(tmp_path, "security: {curve: true, public_keys_file: x, publishers: {/arm/left/target: "
                          "[plannr]}}")
    with pytest.raises(LaunchError, match=r"security.publishers.*needs curve: true"):
        _launch(tmp_path, "security: {" + POLICY + "}")


def test_keys_generate_writes_what_the_launch_file_needs_and_keeps_existing_keys(tmp_path, keys_env):
    """One ``keys generate --launch`` (to $FLEXSHEET_KEYS) gives every host and node a CURVE config; a second
    run keeps the keys (a deployed arm PC stays valid); --force replaces one and public_keys.yaml follows; a
    name the launch file lacks (a typo) is refused and writes nothing."""
    lf = _launch(tmp_path)
    bad = _keys(lf.path, "main", "amr1", check=False)
    assert bad.returncode == 2 and "'amr1' is no host or node" in bad.stderr and not keys_env.exists()
    out = _keys(lf.path)
    assert "new keypair" in out and str(keys_env) in out
    assert stat.S_IMODE(keys_env.stat().st_mode) == 0o700
    assert stat.S_IMODE((keys_env / "arm_left.key_secret").stat().st_mode) == 0o600
    first = yaml.safe_load((keys_env / "public_keys.yaml").read_text())
    assert set(first) == {"main", "arm1", "planner", "arm_left", "triangulator"}
    assert all(len(k) == 40 for k in first.values()) and len(set(first.values())) == 5
    cfgs = ({h: curve_config(lf, h) for h in ("main", "arm1")}
            | {n: node_config(lf, n).curve for n in lf.nodes})
    assert {h: c.public_key.decode() for h, c in cfgs.items()} == first
    assert "kept" in _keys(lf.path)
    assert yaml.safe_load((keys_env / "public_keys.yaml").read_text()) == first
    j = json.loads(_keys(lf.path, "--json"))               # --json: each key's status, each host's secrets
    assert {n: k["status"] for n, k in j["keys"].items()} == {n: "kept" for n in first}
    assert j["hosts"]["arm1"] == [str(keys_env / "arm1.key_secret"), str(keys_env / "arm_left.key_secret")]
    _keys(lf.path, "arm_left", "--force")
    second = yaml.safe_load((keys_env / "public_keys.yaml").read_text())
    assert second["planner"] == first["planner"] and second["arm_left"] != first["arm_left"]
    assert node_config(lf, "arm_left").curve.public_key.decode() == second["arm_left"]
