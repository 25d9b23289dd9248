"""Links heal, memory is bounded.

* A listener that holds a dead node's port and speaks the wrong protocol used to cut that node off for good:
  libzmq ends a connection's session after a protocol or handshake error and never connects to that endpoint
  again. Squatted by (a) a raw TCP listener that sends garbage (a ZMTP-like signature with a bad greeting) and
  (b) a plain ZMTP socket while the graph uses CURVE, then released and the real publisher restarted: the
  subscriber receives again (:class:`flexsheet.runtime.zmq.linkwatch.LinkWatch`). A control run without the
  watch receives nothing, so the squat really did kill the connection.
* A subscriber that never reads big messages costs the publisher at most its byte budget
  (:data:`flexsheet.runtime.zmq.xpub.PUB_QUEUE_BYTES` per subscriber), and the messages its full queue could
  not take are counted in the publisher's ``dropped``.
* ``flexsheet launch FILE --check`` refuses an output under /proc.

Numbers: ``python tests/system/test_links_heal.py`` prints the recovery times and the memory run.
"""

from __future__ import annotations

import asyncio
import json
import logging
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from flexsheet.experiments.faults.links import (
    DEADLINE_S,
    GarbageSquatter,
    Sink,
    memory_run,
    squat_then_restart,
)
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.launch_check import check_launch
from flexsheet.runtime.ports import free_port
from flexsheet.runtime.zmq import linkwatch
from flexsheet.runtime.zmq.linkwatch import LinkWatch

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("variant", ["garbage", "plain_zmtp_vs_curve"])
def test_subscriber_receives_again_after_a_squatter_leaves(variant):
    res = asyncio.run(squat_then_restart(variant))
    print(json.dumps(res))
    assert res["received"] >= 20, res
    assert res["recovery_s"] is not None and res["recovery_s"] < DEADLINE_S, res
    assert res["reconnects"] >= 1, res          # the watch connected again (libzmq had given up)
    assert res["up"], res
    if variant == "plain_zmtp_vs_curve":
        assert "mechanism mismatch" in res["reason"], res


def test_without_the_watch_the_squat_cuts_the_link_for_good():
    """Control: the same squat with the watch switched off leaves the subscriber deaf (libzmq's own
    behaviour), so the test above measures the watch, not luck."""
    res = asyncio.run(squat_then_restart("garbage", heal=False, deadline=3.0))
    print(json.dumps(res))
    assert res["received"] == 0, res


def test_silent_endpoint_is_named_in_the_heartbeat(monkeypatch):
    """A peer that nobody can reach (here a squatted port) makes the subscriber's heartbeat say ``warn`` and
    name the endpoint; refusals are logged at most once per LOG_EVERY_S per endpoint."""
    monkeypatch.setattr(LinkWatch, "SILENT_S", 0.5)
    port = free_port()
    ep = f"tcp://127.0.0.1:{port}"

    async def run() -> tuple:
        squat = GarbageSquatter(port)
        sink = Sink(NodeConfig(name="sink", endpoint="", peers=[ep]))
        task = asyncio.get_running_loop().create_task(sink.run(install_signals=False))
        try:
            await asyncio.sleep(3.0)
            return sink.heartbeat(), sink.transport.watch.links[ep], squat.accepted
        finally:
            sink.shutdown()
            await task
            squat.release()

    records: list = []
    handler = _ListHandler(records)
    linkwatch.log.addHandler(handler)
    try:
        hb, link, accepted = asyncio.run(run())
    finally:
        linkwatch.log.removeHandler(handler)
    assert hb.state == "warn" and f"no link to {ep}" in hb.message, hb
    # back-off: 0.1, 0.2, 0.4, 0.8 s
    assert accepted >= 3 and link.reconnects >= 2, (accepted, link.reconnects)
    lines = [r for r in records if ep in r]
    assert 1 <= len(lines) <= 2, lines  # 3 s: one line (+1 if a 5 s window ends), not one per refusal


def test_a_link_up_before_the_first_poll_is_seen_up():
    """The monitor is attached before the first connect (checked on the socket's call order: on a quick
    machine the handshake rarely beats a monitor attached just after, so the order is what is tested), and a
    handshake that completes before the watch's first poll still marks the link up: the heartbeat never warns
    of a live link."""
    import time

    import zmq

    from flexsheet.runtime.zmq.subscriber import connect_sub

    calls: list[str] = []

    class Recording(zmq.Socket):
        def get_monitor_socket(self, *a, **k):
            calls.append("monitor")
            return super().get_monitor_socket(*a, **k)

        def connect(self, addr):
            if addr.startswith("tcp://"):        # not the monitor's own inproc pair
                calls.append("connect")
            return super().connect(addr)

    class Ctx(zmq.Context):
        _socket_class = Recording

    ctx = Ctx()
    pub = ctx.socket(zmq.XPUB)
    pub.setsockopt(zmq.LINGER, 0)
    port = pub.bind_to_random_port("tcp://127.0.0.1")
    ep = f"tcp://127.0.0.1:{port}"
    calls.clear()
    sub, watch = connect_sub(ctx, [ep], None, 1000)
    try:
        assert calls == ["monitor", "connect"], calls
        time.sleep(0.5)                          # the handshake is long done before anyone polls
        watch.poll()
        assert watch.links[ep].up, ep
        assert watch.report(now=time.monotonic() + 2 * LinkWatch.SILENT_S) == ""
    finally:
        watch.close()
        sub.close(linger=0)
        pub.close(linger=0)
        ctx.term()


class _ListHandler(logging.Handler):
    def __init__(self, out: list) -> None:
        super().__init__()
        self.out = out

    def emit(self, record) -> None:
        self.out.append(record.getMessage())


# ---------------------------------------------------------------------------------------------- memory
def test_a_subscriber_that_never_reads_costs_the_publisher_its_byte_budget_and_drops_are_counted():
    res = memory_run()
    print(json.dumps(res))
    assert res["published"] >= 150, res                  # ~250 MB offered to a subscriber that reads nothing
    assert res["growth_mb"] <= 100.0, res                # the budget is 32 MiB per subscriber
    assert res["sndhwm"] * res["largest"] <= res["budget"], res
    assert res["dropped"] > 0, res


def test_check_refuses_an_output_under_proc(tmp_path):
    doc = {"name": "chk", "hosts": {"main": {"address": "127.0.0.1"}}, "base_port": 21000,
           "nodes": {"rec": {"type": "recorder", "host": "main", "params": {"output": "/proc/x.mcap"}}}}
    path = tmp_path / "chk.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    res = check_launch(path)
    assert len(res.errors) == 1, res.errors
    assert res.errors[0].startswith(f"{path}: node rec: params.output = '/proc/x.mcap': cannot write "
                                    "here: "), res.errors
    assert "under /proc" in res.errors[0]
    out = subprocess.run([sys.executable, "-m", "flexsheet", "launch", str(path), "--check"],
                         capture_output=True,
                         text=True, cwd=ROOT, timeout=120)
    assert out.returncode != 0 and "node rec: params.output = '/proc/x.mcap'" in out.stdout + out.stderr, out


if __name__ == "__main__":
    for v in ("garbage", "plain_zmtp_vs_curve"):
        print(json.dumps(asyncio.run(squat_then_restart(v))))
    print(json.dumps(asyncio.run(squat_then_restart("garbage", heal=False, deadline=3.0))))
    print(json.dumps(memory_run()))
    print(
        json.dumps({"control: budget of 2000 frames (SNDHWM 2000 alone)": memory_run(budget=2000 * 655585)}))
