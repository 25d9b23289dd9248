"""Two graphs of one launch file side by side on one machine, in domains 3 and 4 (as ROS_DOMAIN_ID): both run,
each binds its own ports, and a tool sees only the graph of its own domain. The full display in two domains
at once is the same mechanism (``flexsheet launch launch/sim.yaml --domain 3`` beside ``--domain 4``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

from flexsheet.runtime.domain import DOMAIN_ENV, DOMAIN_STRIDE


def _flexsheet(*args: str, env: dict | None = None, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flexsheet", *args], capture_output=True, text=True,
                          timeout=timeout, env=env)


def test_two_graphs_of_one_file_run_side_by_side_and_tools_see_their_own_domain(demo_launch, tmp_path):
    path = demo_launch(rate=10.0)
    env = {k: v for k, v in os.environ.items() if k != DOMAIN_ENV}
    env["FLEXSHEET_GRAPH_DIR"] = str(tmp_path / "graph")         # this test's discovery only
    procs = {d: subprocess.Popen([sys.executable, "-m", "flexsheet", "launch", str(path), "--domain", str(d),
                                  "--duration", "20"], env=env, stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT,
                                 text=True) for d in (3, 4)}
    try:
        seen: dict[int, list] = {}
        end = time.monotonic() + 60
        while time.monotonic() < end and len(seen) < 2 and all(p.poll() is None for p in procs.values()):
            for d in (3, 4):
                r = _flexsheet("node", "list", "--json", env={**env, DOMAIN_ENV: str(d)})
                rows = json.loads(r.stdout) if r.returncode == 0 and r.stdout.strip() else []
                if {row["node"] for row in rows} >= {"talker", "listener"}:
                    seen[d] = rows
            time.sleep(0.5)
        assert set(seen) == {3, 4}, seen
        ports = {d: sorted(int(row["endpoint"].rsplit(":", 1)[1]) for row in seen[d]) for d in (3, 4)}
        assert [p4 - p3 for p3, p4 in zip(ports[3], ports[4], strict=True)] == [DOMAIN_STRIDE] * len(ports[3])
        r = _flexsheet("node", "list", "--json", "--domain", "5", env=env)
        assert r.returncode != 0 and "domain 5" in r.stderr, (r.stdout, r.stderr)       # nobody in domain 5
        outs = {d: p.communicate(timeout=90)[0] for d, p in procs.items()}
        for d, p in procs.items():
            assert p.returncode == 0, outs[d][-3000:]
            assert "heard seq=" in outs[d]
            assert "Address already in use" not in outs[d]
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait()
