"""Composable containers: objects between nodes of one process (read-only arrays, no encode unless someone
outside asks), QoS in a container, crash containment and restart by policy, and the launch-file path
(``container:`` → one process; ``flexsheet node list`` shows it; the supervisor restarts a killed
container)."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import zmq
from conftest import free_port, pid_alive

import flexsheet.runtime.bus as bus_mod
import flexsheet.runtime.publisher as publisher_mod
from flexsheet.runtime.bus import Bus, ContainerTransport
from flexsheet.runtime.codec import decode
from flexsheet.runtime.config import EXIT_CONFIG, NodeConfig
from flexsheet.runtime.container import Container, Member
from flexsheet.runtime.node import Node
from flexsheet.runtime.qos import QoS
from flexsheet.runtime.testing import console_lines
from messages import Fingertip, Header, StereoCalibration
from messages import topics as T
from messages.samples import sample_fields


def tip(seq: int, x: float = 0.0) -> Fingertip:
    p = np.array([x, 0.0, 0.0])
    return Fingertip(header=Header(stamp=100.0 + seq, seq=seq), position=p, covariance=np.eye(3), valid=True,
                     predicted_position=p, exposure_stamp=100.0 + seq)


class Pub(Node):
    async def setup(self) -> None:
        self.tip = self.publisher(T.FINGERTIP)
        self.calib = self.publisher(T.CALIBRATION)


class Sub(Node):
    """Collects fingertips (QoS and handler kind from attributes set before run)."""

    qos = QoS.KEEP_ALL
    slow = 0.0
    sync = True

    async def setup(self) -> None:
        self.got: list = []
        self.threads: set[str] = set()
        self.subscribe(T.FINGERTIP, self.on_sync if self.sync else self.on_async, qos=self.qos)

    def on_sync(self, msg: Fingertip) -> None:
        self.threads.add(threading.current_thread().name)
        if self.slow:
            time.sleep(self.slow)
        self.got.append(msg)

    async def on_async(self, msg: Fingertip) -> None:
        self.got.append(msg)


def _make(cls, bus: Bus, name: str, endpoint: str = "", **attrs) -> Node:
    node = cls(NodeConfig(name=name, endpoint=endpoint, heartbeat_period=0.2),
               transport=ContainerTransport(bus, endpoint))
    for k, v in attrs.items():
        setattr(node, k, v)
    return node


async def _start(*nodes: Node) -> list[asyncio.Task]:
    tasks = [asyncio.get_running_loop().create_task(n.run(install_signals=False)) for n in nodes]
    deadline = time.monotonic() + 10
    while not all(n.ready for n in nodes):
        assert time.monotonic() < deadline, "nodes did not come up"
        for t in tasks:
            if t.done():
                t.result()
        await asyncio.sleep(0.01)
    return tasks


async def _stop(nodes, tasks, bus: Bus) -> None:
    for n in nodes:
        n.shutdown()
    await asyncio.gather(*tasks)
    bus.close()


async def _until(cond, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "condition not met in time"
        await asyncio.sleep(0.005)


def test_in_process_message_is_the_object_itself_with_read_only_arrays_and_never_encoded(monkeypatch):
    calls = []
    real = publisher_mod.encode

    def counting(topic, msg):
        calls.append(topic)
        return real(topic, msg)

    monkeypatch.setattr(publisher_mod, "encode", counting)
    monkeypatch.setattr(bus_mod, "encode", counting)

    async def scenario():
        bus = Bus("t")
        pub, a, b = _make(Pub, bus, "pub"), _make(Sub, bus, "a"), _make(Sub, bus, "b", sync=False)
        tasks = await _start(pub, a, b)
        sent = [tip(i, 0.01 * i) for i in range(5)]
        own = sent[0].position                     # the publisher's own array stays writeable for it
        for m in sent:
            pub.tip.publish(m)
        await _until(lambda: len(a.got) == 5 and len(b.got) == 5)
        await _stop([pub, a, b], tasks, bus)
        return sent, own, a, b

    sent, own, a, b = asyncio.run(scenario())
    assert [m is s for m, s in zip(a.got, sent, strict=True)] == [True] * 5          # no copy, no decode
    assert [m is s for m, s in zip(b.got, sent, strict=True)] == [True] * 5
    assert not a.got[0].position.flags.writeable and not a.got[0].covariance.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        a.got[0].position[0] = 1.0
    assert own.flags.writeable and np.shares_memory(own, a.got[0].position)
    assert all(t.startswith("sub/fingertip@a") for t in a.threads)                  # sync handler: its worker
    assert [t for t in calls if t != T.DIAGNOSTICS.name] == []  # nobody outside: no encode


def test_encoded_once_only_while_someone_outside_subscribes(monkeypatch):
    calls = []
    real = publisher_mod.encode

    def counting(topic, msg):
        calls.append(topic)
        return real(topic, msg)

    monkeypatch.setattr(publisher_mod, "encode", counting)
    ep = f"tcp://127.0.0.1:{free_port()}"

    async def scenario():
        bus = Bus("t")
        pub, a = _make(Pub, bus, "pub", endpoint=ep), _make(Sub, bus, "a")
        tasks = await _start(pub, a)
        pub.tip.publish(tip(0))                       # only in-process subscribers yet
        ctx = zmq.Context()
        sub = ctx.socket(zmq.SUB)
        sub.connect(ep)
        sub.setsockopt(zmq.SUBSCRIBE, T.FINGERTIP.name.encode())
        await _until(lambda: pub.transport.wants(T.FINGERTIP.name.encode()))
        for i in range(1, 4):
            pub.tip.publish(tip(i))
        got = []
        while len(got) < 3:
            assert await asyncio.get_running_loop().run_in_executor(None, sub.poll, 3000), ("nothing on the "
                                                                                            "wire")
            got.append(sub.recv_multipart())
        sub.close(0)
        ctx.term()
        await _until(lambda: not pub.transport.wants(T.FINGERTIP.name.encode()))    # unsubscribed on close
        pub.tip.publish(tip(4))
        await _until(lambda: len(a.got) == 5)
        await _stop([pub, a], tasks, bus)
        return got

    got = asyncio.run(scenario())
    assert [decode(f, T.FINGERTIP).header.seq for f in got] == [1, 2, 3]
    assert [t for t in calls if t == T.FINGERTIP.name] == [T.FINGERTIP.name] * 3    # once each, only 1..3


def test_qos_in_a_container_latest_drops_keep_all_keeps_latched_reaches_late_joiner_once():
    async def scenario():
        bus = Bus("t")
        pub = _make(Pub, bus, "pub")
        latest = _make(Sub, bus, "latest", qos=QoS.LATEST, slow=0.05)
        keep = _make(Sub, bus, "keep", qos=QoS.KEEP_ALL, slow=0.002)
        tasks = await _start(pub, latest, keep)
        for i in range(20):
            pub.tip.publish(tip(i))
        await _until(lambda: len(keep.got) == 20 and latest.got and latest.got[-1].header.seq == 19)
        calib = StereoCalibration(header=Header(stamp=1.0), **sample_fields(StereoCalibration))
        pub.calib.publish(calib)

        class Late(Node):
            async def setup(self) -> None:
                self.calibs = []
                self.subscribe(T.CALIBRATION, self.calibs.append, qos=QoS.LATCHED)

        late = _make(Late, bus, "late")
        tasks += await _start(late)
        await _until(lambda: late.calibs)
        pub.calib.publish(calib)                      # the same object again: a latched resend, not new data
        await asyncio.sleep(0.1)
        dropped = latest._subs[T.FINGERTIP.name][0].stats.dropped
        await _stop([pub, latest, keep, late], tasks, bus)
        return latest.got, dropped, keep.got, late.calibs, calib

    lat, dropped, keep, calibs, calib = asyncio.run(scenario())
    assert [m.header.seq for m in keep] == list(range(20))
    assert lat[-1].header.seq == 19 and len(lat) <= 3 and dropped >= 17 and len(lat) + dropped == 20
    assert len(calibs) == 1 and calibs[0] is calib


class Counter(Node):
    """State that must survive a neighbour's crash: counts its own timer ticks."""

    async def setup(self) -> None:
        self.ticks = 0
        self.timer(0.01, self.tick)

    def tick(self) -> None:
        self.ticks += 1


class Crasher(Node):
    """Raises out of setup on its first two starts (a crash, not a config error), then runs."""

    starts = 0

    async def setup(self) -> None:
        type(self).starts += 1
        if type(self).starts <= 2:
            raise RuntimeError(f"crash number {type(self).starts}")


class BadConfig(Node):
    async def setup(self) -> None:
        raise ValueError("param 'gain' = -1: must be > 0")


def test_a_crashing_node_is_restarted_alone_and_its_neighbours_keep_their_state():
    async def scenario():
        bus = Bus("t")

        def member(cls, name, **kw):
            return Member(name, lambda b: cls(NodeConfig(name=name, endpoint="", heartbeat_period=0.2),
                                              transport=ContainerTransport(b, "")), **kw)

        c = Container("t", [member(Counter, "counter"), member(Crasher, "crasher", delay=0.05),
                            member(BadConfig, "bad", delay=0.05)], bus)
        task = asyncio.get_running_loop().create_task(c.run(install_signals=False))
        await _until(lambda: c.node("counter") is not None and c.node("counter").ready)
        counter = c.node("counter")
        await _until(lambda: c.node("crasher") is not None and c.node("crasher").ready)
        ticks_after_restarts = counter.ticks
        same = c.node("counter") is counter
        await asyncio.sleep(0.1)
        c.stop()
        code = await task
        return c, same, ticks_after_restarts, counter.ticks, code

    with console_lines() as lines:
        c, same, mid, end, code = asyncio.run(scenario())
    crasher = next(m for m in c.members if m.name == "crasher")
    bad = next(m for m in c.members if m.name == "bad")
    assert same and end > mid > 0                     # the counter was never restarted and kept counting
    assert crasher.restarts == 2 and crasher.codes[:2] == [1, 1]
    assert bad.codes == [EXIT_CONFIG] and bad.restarts == 0
    assert any("bad: configuration error" in line and "gain" in line for line in lines)
    assert any("crasher: restarting" in line for line in lines)
    # the launch knows
    assert code == 1 and any("failed during the run: crasher, bad" in line for line in lines)


# ---------------------------------------------------------------------------------------------- launch file
class Launch:
    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "flexsheet", "launch", *args],
                                     stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, start_new_session=True)
        self.lines: list[str] = []
        self._t = threading.Thread(target=self._read, daemon=True)
        self._t.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line.rstrip())

    def wait_for(self, pattern: str, timeout: float = 30.0, count: int = 1) -> list[re.Match]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = [m for line in list(self.lines) if (m := re.search(pattern, line))]
            if len(found) >= count:
                return found
            time.sleep(0.05)
        raise AssertionError(f"{pattern!r} x{count} not seen; output:\n" + "\n".join(self.lines[-40:]))

    def stop(self) -> int:
        self.proc.send_signal(signal.SIGINT)
        code = self.proc.wait(timeout=30)
        self._t.join(timeout=5)
        return code


def test_launch_file_container_is_one_process_listed_by_node_list_and_restarted_when_killed(tmp_path):
    base = free_port(span=20)
    path = tmp_path / "demo.yaml"
    path.write_text(f"""
name: demo
hosts:
  main: {{address: 127.0.0.1}}
base_port: {base}
shutdown_timeout: 2.0
nodes:
  talker: {{type: talker, host: main, container: pair, params: {{rate: 20.0}}, respawn: {{delay: 0.2}}}}
  listener: {{type: listener, host: main, container: pair, params: {{qos: keep_all}}}}
  outside: {{type: listener, host: main, params: {{qos: keep_all}}}}
""")
    out = tmp_path / "out"
    lf = Launch(str(path), "--out", str(out))
    try:
        pid = int(lf.wait_for(r"\[pair\s*\] started pid (\d+) \(container: talker, listener\)")[0].group(1))
        lf.wait_for(r"\[pair\s*\] heard seq=\d+", count=3)          # in-process listener
        lf.wait_for(r"\[outside\s*\] heard seq=\d+", count=3)       # out-of-process listener: encoded frames
        res = subprocess.run([sys.executable, "-m", "flexsheet", "node", "list", "--launch", str(path),
                              "--timeout", "2.0"], capture_output=True, text=True, timeout=60)
        rows = {ln.split()[0]: ln for ln in res.stdout.splitlines() if ln.strip()}
        assert "container=pair" in rows["talker"] and f"pid={pid}" in rows["talker"], res.stdout
        assert "container=pair" in rows["listener"] and f"pid={pid}" in rows["listener"], res.stdout
        assert "container=-" in rows["outside"] and f"pid={pid}" not in rows["outside"], res.stdout
        last = max(int(m.group(1)) for m in lf.wait_for(r"\[outside\s*\] heard seq=(\d+)", count=30))
        os.kill(pid, signal.SIGKILL)  # what a segfault does to the whole process
        lf.wait_for(r"\[pair\s*\] respawning")
        new = int(lf.wait_for(r"\[pair\s*\] started pid (\d+)", count=2)[1].group(1))
        assert new != pid
        n = len(lf.lines)
        deadline = time.monotonic() + 30
        while not any((m := re.search(r"\[outside\s*\] heard seq=(\d+) ", ln)) and int(m.group(1)) < last
                      for ln in lf.lines[n:]):                      # the new talker counts from 0 again
            assert time.monotonic() < deadline, "the restarted container's talker is not heard outside"
            time.sleep(0.05)
    finally:
        code = lf.stop()
    # the kill
    assert code == 1 and any(ln.endswith("failed during the run: pair (exit -9)") for ln in lf.lines)
    time.sleep(0.2)
    assert not pid_alive(new)
    cpu = __import__("json").loads((out / "cpu.json").read_text())
    assert set(cpu["nodes"]) == {"talker", "listener", "outside"}
    assert (cpu["processes"]["pair"]["nodes"] == ["talker", "listener"]
            and cpu["processes"]["pair"]["cpu_s"] > 0)
    assert cpu["nodes"]["talker"]["process"] == "pair" and cpu["nodes"]["outside"]["cpu_s"] > 0

