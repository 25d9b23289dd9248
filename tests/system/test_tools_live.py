"""The run-time tools against a live graph (a talker on /fingertip): ``topic echo --count N`` prints exactly N
messages, and echoing a topic nobody publishes says so within its ``--timeout`` and exits 1."""

from __future__ import annotations

import subprocess
import sys
import time

from test_runtime_launch import Launch


def _flexsheet(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flexsheet", *args], capture_output=True, text=True,
                          timeout=60)


def test_echo_prints_exactly_count_and_an_absent_topic_says_so(demo_launch):
    path = demo_launch(rate=2000.0)   # several messages per drain: the count must still hold
    lf = Launch(path)
    try:
        lf.wait_for(r"heard seq=", count=3)
        for n in (1, 2, 5):
            r = _flexsheet("topic", "echo", "/fingertip", "--count", str(n), "--launch", str(path))
            assert r.returncode == 0, r.stderr
            assert r.stdout.count("--- /fingertip ") == n, r.stdout[-2000:]
        t0 = time.monotonic()
        r = _flexsheet("topic", "echo", "/nobody", "--timeout", "1.0", "--launch", str(path))
        took = time.monotonic() - t0
        assert r.returncode == 1 and "no message on /nobody in 1 s" in r.stderr, r.stderr
        assert r.stdout == "" and took < 30.0, (r.stdout, took)
    finally:
        lf.stop()


def test_topic_and_node_info_from_the_live_graph_as_json(demo_launch):
    """``topic info`` and ``node info`` (and ``--json`` on them and on the lists) report the talker's
    /fingertip with its rate and the listener's QoS from the heartbeats; an unknown topic or node is said,
    exit 1."""
    import json

    path = demo_launch(rate=50.0)
    lf = Launch(path)
    try:
        lf.wait_for(r"heard seq=", count=3)
        time.sleep(1.5)                                            # a full heartbeat period of rates
        r = _flexsheet("topic", "info", "/fingertip", "--json", "--launch", str(path))
        assert r.returncode == 0, r.stderr
        t = json.loads(r.stdout)
        assert t["type"] == "flexsheet/Fingertip" and [p["node"] for p in t["publishers"]] == ["talker"]
        assert 40.0 <= t["publishers"][0]["rate_hz"] <= 60.0 and t["publishers"][0]["count"] > 20, t
        assert [(s["node"], s["qos"]) for s in t["subscribers"]] == [("listener", "keep_all")], t
        n = json.loads(_flexsheet("node", "info", "talker", "--json", "--launch", str(path)).stdout)
        assert n["node"] == "talker" and n["state"] == "ok" and n["pid"] > 0
        assert any(p["topic"] == "/fingertip" and p["count"] > 20 for p in n["publishers"]), n
        t0 = time.monotonic()      # every node of the file heard: the call ends then, not at its --timeout
        names = [e["node"]
                 for e in json.loads(_flexsheet("node", "list", "--json", "--timeout", "20", "--launch",
                                                str(path)).stdout)]
        assert names == ["listener", "talker"] and time.monotonic() - t0 < 10.0
        assert "/fingertip" in json.loads(_flexsheet("topic", "list", "--json", "--launch", str(path)).stdout)
        r = _flexsheet("node", "info", "nobody", "--launch", str(path))
        assert r.returncode == 1 and "node 'nobody' not heard" in r.stderr and "talker" in r.stderr
        r = _flexsheet("topic", "info", "/nobody", "--launch", str(path))
        assert r.returncode == 1 and "/nobody: no live node" in r.stderr
        # hz and bw over 2 s of the 50 Hz talker, echo as JSON lines
        hz = json.loads(_flexsheet("topic", "hz", "/fingertip", "--window", "2", "--json", "--launch",
                                   str(path)).stdout)
        assert 40.0 <= hz["rate_hz"] <= 60.0 and 70 <= hz["messages"] <= 110, hz
        bw = json.loads(_flexsheet("topic", "bw", "/fingertip", "--window", "2", "--json", "--launch",
                                   str(path)).stdout)
        assert 70 <= bw["messages"] <= 110 and 100 < bw["mean_bytes"] < 2000, bw
        assert bw["min_bytes"] <= bw["mean_bytes"] <= bw["max_bytes"], bw
        assert abs(bw["bytes_per_s"] - bw["mean_bytes"] * bw["messages"] / 2.0) < 1e-6 * bw["bytes_per_s"], bw
        r = _flexsheet("topic", "echo", "/fingertip", "--count", "2", "--json", "--launch", str(path))
        rows = [json.loads(x) for x in r.stdout.splitlines()]
        assert len(rows) == 2 and all(m["topic"] == "/fingertip" and m["type"] == "flexsheet/Fingertip"
                                      for m in rows)
        assert rows[1]["header"]["seq"] > rows[0]["header"]["seq"], rows
        r = _flexsheet("topic", "bw", "/nobody", "--window", "0.5", "--launch", str(path))
        assert r.returncode == 1 and "no messages" in r.stdout
    finally:
        lf.stop()


def test_params_services_and_topic_pub_on_the_live_graph(demo_launch):
    """param list/get/set and service list/call reach a running node through its service socket (found in its
    heartbeat); a read-only or out-of-range param and an unknown service are refused with one line, and the
    node keeps running; topic pub delivers exactly the messages it publishes to the subscribing node."""
    import json

    path = demo_launch(rate=5.0)
    lf = Launch(path)
    try:
        lf.wait_for(r"heard seq=", count=2)
        services = json.loads(_flexsheet("service", "list", "listener", "--json", "--launch",
                                         str(path)).stdout)
        assert {"param/list", "param/get", "param/set", "topic/pub", "list"} <= set(services), services
        rows = {r["name"]: r for r in json.loads(_flexsheet("param", "list", "listener", "--json", "--launch",
                                                            str(path)).stdout)}
        assert rows["delay"]["value"] == 0.0 and rows["delay"]["dynamic"] and rows["delay"]["type"] == "float"
        assert rows["qos"]["value"] == "keep_all" and not rows["qos"]["dynamic"]
        r = _flexsheet("param", "set", "listener", "delay", "0.002", "--launch", str(path))
        assert r.returncode == 0 and "set listener.delay = 0.002" in r.stdout, r.stderr
        got = json.loads(_flexsheet("param", "get", "listener", "delay", "--json", "--launch",
                                    str(path)).stdout)
        assert got["value"] == 0.002
        r = _flexsheet("param", "set", "listener", "qos", "latest", "--launch", str(path))
        assert r.returncode == 1 and "param 'qos' is read-only at run time" in r.stderr, r.stderr
        r = _flexsheet("param", "set", "listener", "delay", "-1", "--launch", str(path))
        assert r.returncode == 1 and "param 'delay'" in r.stderr and "greater than or equal to 0" in r.stderr
        r = _flexsheet("service", "call", "listener", "nope", "--launch", str(path))
        assert r.returncode == 1 and "no service 'nope'" in r.stderr
        r = _flexsheet("param", "get", "nobody", "x", "--timeout", "1", "--launch", str(path))
        assert r.returncode == 1 and "node 'nobody' not heard" in r.stderr
        # topic pub: three fingertips at x = 0.777 m reach the listener, and only three
        msg = ("{position: [0.777, 0.0, 0.0], covariance: [[1.0e-8, 0, 0], [0, 1.0e-8, 0], [0, 0, 1.0e-8]], "
               "valid: true, predicted_position: [0.777, 0.0, 0.0], exposure_stamp: 0.0}")
        r = _flexsheet("topic", "pub", "/fingertip", msg, "--times", "3", "--rate", "20", "--json",
                       "--launch", str(path))
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout) == {"topic": "/fingertip", "type": "flexsheet/Fingertip", "published": 3,
                                        "subscribers": ["listener"]}
        lf.wait_for(r"x=0\.777", count=3)
        time.sleep(0.5)
        assert sum("x=0.777" in line for line in lf.lines) == 3
        # topic/pub refuses, naming the field, a topic the node
        # does not subscribe to and frames of another topic
        r = _flexsheet("service", "call", "listener", "topic/pub", "{topic: /sheet/target, frames: [a, b]}",
                       "--launch", str(path))
        assert r.returncode == 1 and "frames must be a list" in r.stderr, r.stderr  # YAML strings, not bytes
        r = _flexsheet("topic", "pub", "/fingertip", "{position: [1, 2]}", "--launch", str(path))
        assert r.returncode == 2 and "field 'position'" in r.stderr, r.stderr
        assert lf.proc.poll() is None                       # the node took every bad request and runs on
    finally:
        lf.stop()
