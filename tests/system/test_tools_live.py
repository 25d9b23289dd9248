"""The run-time tools against a live graph (a talker on /fingertip): ``topic echo --count N`` prints exactly N
messages, and echoing a topic nobody publishes says so within its ``--timeout`` and exits 1."""

from __future__ import annotations

import subprocess
import sys
import time

from test_runtime_launch import Launch


def _flexsheet(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flexsheet", *args], capture_output=True, text=True, timeout=60)


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
