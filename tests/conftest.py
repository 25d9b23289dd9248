"""Shared fixtures: free TCP ports, demo launch files, process helpers."""

from __future__ import annotations

import os
import socket
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def demo_launch(tmp_path: Path):
    """Write a talker/listener(/recorder) launch file on free ports; returns a factory(extra_nodes_yaml)."""

    def make(extra: str = "", listener_qos: str = "keep_all", rate: float = 20.0) -> Path:
        base = free_port() // 10 * 10
        base = min(max(base, 20000), 60000)
        text = f"""
name: demo
hosts:
  main: {{address: 127.0.0.1}}
base_port: {base}
shutdown_timeout: 2.0
nodes:
  talker: {{type: talker, host: main, params: {{rate: {rate}}}, respawn: {{policy: on-failure, delay: 0.2}}}}
  listener: {{type: listener, host: main, params: {{qos: {listener_qos}}}}}
{extra}"""
        path = tmp_path / "demo.yaml"
        path.write_text(text)
        return path

    return make


def pid_alive(pid: int) -> bool:
    """True if /proc/<pid> exists and is not a zombie."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat.split(")")[-1].split()[0] != "Z"


os.environ.setdefault("FLEXSHEET_LOG", "INFO")


@pytest.fixture
def netns():
    """Namespaces <prefix>-{main,arm1,arm2} on a bridge inside a 4th 'switch' namespace
    (:func:`netns_util.three_hosts`); fails with the reason if they cannot be made (needs root, iproute2)."""
    from netns_util import three_hosts

    try:
        with three_hosts() as names:
            yield names
    except RuntimeError as exc:
        pytest.fail(str(exc))
