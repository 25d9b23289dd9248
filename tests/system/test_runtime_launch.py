"""Launch across real processes: pub/sub, clean stop with no orphans (checked in /proc), respawn after kill
-9, latched topics for late joiners, and clear errors for bad launch files."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import free_port, pid_alive

from flexsheet.runtime.domain import domain_id, shift_port
from flexsheet.runtime.launch import LaunchError, load_launch


class Launch:
    """``flexsheet launch FILE`` in a subprocess, its output collected line by line."""

    def __init__(self, path: Path, *extra: str) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "flexsheet", "launch", str(path), *extra],
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     start_new_session=True)
        self.lines: list[str] = []
        self._t = threading.Thread(target=self._read, daemon=True)
        self._t.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line.rstrip())

    def wait_for(self, pattern: str, timeout: float = 20.0, count: int = 1) -> list[re.Match]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = [m for line in list(self.lines) if (m := re.search(pattern, line))]
            if len(found) >= count:
                return found
            time.sleep(0.05)
        raise AssertionError(f"{pattern!r} x{count} not seen in {timeout} s; output:\n"
                             + "\n".join(self.lines[-40:]))

    def pids(self) -> dict[str, int]:
        out = {}
        for line in self.lines:
            if m := re.match(r"\[(\w+)\s*\] started pid (\d+)", line):
                out[m.group(1)] = int(m.group(2))
        return out

    def stop(self, sig=signal.SIGINT, timeout: float = 20.0) -> int:
        self.proc.send_signal(sig)
        code = self.proc.wait(timeout=timeout)
        self._t.join(timeout=5)
        return code


def test_pubsub_across_processes_and_clean_stop_without_orphans(demo_launch):
    lf = Launch(demo_launch())
    try:
        lf.wait_for(r"\[listener\s*\] heard seq=\d+ x=", count=5)
        pids = lf.pids()
        assert set(pids) == {"talker", "listener"}
        assert all(pid_alive(p) for p in pids.values())
    finally:
        code = lf.stop()
    assert code == 0
    assert any("all nodes stopped" in line for line in lf.lines)
    time.sleep(0.2)
    assert not [p for p in pids.values() if pid_alive(p)], "orphan node processes left behind"
    # output is prefixed with the node name, line by line
    assert all(line.startswith("[") for line in lf.lines if line)


def test_respawn_after_kill_9(demo_launch):
    lf = Launch(demo_launch())
    try:
        lf.wait_for(r"\[talker\s*\] started pid")
        lf.wait_for(r"heard seq=", count=3)
        old = lf.pids()["talker"]
        os.kill(old, signal.SIGKILL)
        lf.wait_for(r"\[talker\s*\] respawning")
        lf.wait_for(r"\[talker\s*\] started pid", count=2)
        new = lf.pids()["talker"]
        assert new != old and pid_alive(new)
        start = next(i for i, line in enumerate(lf.lines) if "respawning" in line)
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:  # the new talker's messages (seq restarts at 0) reach the listener
            if any((m := re.search(r"heard seq=(\d+) ", line)) and int(m.group(1)) < 100
                   for line in lf.lines[start:]):
                break
            time.sleep(0.05)
        else:
            raise AssertionError("no message from the respawned talker:\n"
                                 + "\n".join(lf.lines[start:start + 30]))
        assert any("exited with code -9" in line for line in lf.lines)
    finally:
        assert lf.stop() == 1   # the kill is a failure of the run, named
    assert any(line.endswith("failed during the run: talker (exit -9)") for line in lf.lines)
    time.sleep(0.2)
    assert not pid_alive(new)


def _talker_file(tmp_path, name: str, talker: str, shutdown_timeout: float = 2.0):
    """A launch file of one talker node (``talker``: the node's YAML flow mapping after ``type, host``) on
    free ports, in ``tmp_path``."""
    path = tmp_path / f"{name}.yaml"
    path.write_text(f"""
name: {name}
hosts:
  main: {{address: 127.0.0.1}}
base_port: {free_port(span=10)}
shutdown_timeout: {shutdown_timeout}
nodes:
  talker: {{type: talker, host: main, {talker}}}
""")
    return path


def test_a_killed_node_is_respawned_at_once_though_its_worker_holds_its_output(tmp_path):
    """A node killed -9 while a child it started (not tied to it, as a table builder still importing) holds
    its output pipe: the launcher reports the exit and respawns within seconds, and the child, in the node's
    process group, goes with it (the renderer's sheet-table worker stalled the faults scenario's respawn past
    30 s). Before the fix the exit was seen only when the child's 60 s sleep ended."""
    path = _talker_file(tmp_path, "worker",
                        "params: {rate: 20, worker_s: 60}, respawn: {policy: on-failure, delay: 0.2}")
    lf = Launch(path)
    try:
        (m,) = lf.wait_for(r"\[talker\s*\] talker: worker pid (\d+)")
        worker = int(m.group(1))
        old = lf.pids()["talker"]
        assert pid_alive(worker)
        t0 = time.monotonic()
        os.kill(old, signal.SIGKILL)
        lf.wait_for(r"\[talker\s*\] exited with code -9", timeout=10.0)
        lf.wait_for(r"\[talker\s*\] started pid", count=2, timeout=10.0)
        assert time.monotonic() - t0 < 10.0
        time.sleep(0.2)
        assert not pid_alive(worker), "the dead node's worker outlived it"
    finally:
        assert lf.stop() == 1   # the kill -9


def test_a_respawned_node_that_stops_cleanly_is_not_a_failure_though_it_says_much_as_it_stops(tmp_path):
    """A node killed -9 and respawned, then stopped with the launch (SIGINT), exits 0; the launch exits 1 for
    the kill alone (a launch in which a node failed exits non-zero); the launcher records
    that last exit even when the node's final output is still being read as the stop completes (its watcher
    is cancelled then). Before the fix the kill's -9 stayed the node's last exit code and ``flexsheet launch``
    exited 1 after a clean run (the faults scenario's renderer, 2 of 3 runs on a loaded machine:
    its watcher polled for the reaped exit code in 5 ms sleeps while the stop, woken by the exit callback,
    cancelled it). The race itself did not reproduce with this node on an idle machine; the test holds the
    clean stop of a respawned node that has much to say."""
    path = _talker_file(tmp_path, "loud",
                        "params: {rate: 20, exit_lines: 200000}, respawn: {policy: on-failure, delay: 0.2}",
                        shutdown_timeout=5.0)
    lf = Launch(path)
    try:
        lf.wait_for(r"\[talker\s*\] .*talker up: endpoint")
        os.kill(lf.pids()["talker"], signal.SIGKILL)
        lf.wait_for(r"\[talker\s*\] exited with code -9", timeout=10.0)
        lf.wait_for(r"\[talker\s*\] .*talker up: endpoint", count=2, timeout=20.0)
    finally:
        code = lf.stop(timeout=60.0)
    assert sum("talker: last words" in line for line in lf.lines) == 200000      # every line was read
    # the kill is the run's one failure (exit 1, named); the clean stop of its respawn is not another
    failed = [ln for ln in lf.lines if "failed during the run" in ln]
    assert len(failed) == 1 and failed[0].endswith("talker (exit -9)"), [ln for ln in lf.lines
                                                                         if "[launch]" in ln]
    assert code == 1


def test_a_bind_failure_is_a_configuration_error_not_respawned_and_a_duration_stop_still_fails(tmp_path):
    """A node whose endpoint's port another process holds cannot bind: the launcher does not respawn it (it
    restarted such nodes 10 times), and the launch exits 78 though ``--duration`` stopped it (it exited 0);
    a second node that ran cleanly to the end does not change that."""
    import socket

    port = free_port()
    path = tmp_path / "bind.yaml"
    path.write_text(f"""
name: bind
hosts:
  main: {{address: 127.0.0.1}}
nodes:
  talker: {{type: talker, host: main, port: {port}, respawn: {{policy: always, delay: 0.1}}}}
  listener: {{type: listener, host: main, port: {free_port()}}}
""")
    holder = socket.socket()
    holder.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    port = shift_port(port, domain_id())           # where the launch binds it in this process's domain
    holder.bind(("127.0.0.1", port))
    holder.listen()
    try:
        out = subprocess.run([sys.executable, "-m", "flexsheet", "launch", str(path), "--duration", "4"],
                             capture_output=True, text=True, timeout=60)
    finally:
        holder.close()
    text = out.stdout + out.stderr
    assert out.returncode == 78, text[-3000:]
    assert text.count("started pid") == 2 and "respawning" not in text, text[-3000:]
    assert re.search(r"\[talker\s*\].*configuration error: .*" + str(port), text), text[-3000:]


def test_a_real_time_nodes_children_start_in_the_normal_class(tmp_path):
    """A node with ``rt_priority`` runs SCHED_FIFO; a process it starts (here the talker's ``worker_s`` child,
    as the world node's sheet-table builder) begins in the normal class (SCHED_RESET_ON_FORK), not at the
    node's real-time priority, where a CPU-bound build would starve every normal node. Needs root (CI is
    root)."""
    if os.geteuid() != 0:
        pytest.skip("SCHED_FIFO needs root (CAP_SYS_NICE)")
    path = _talker_file(tmp_path, "rt", "rt_priority: 5, params: {rate: 20, worker_s: 30}")
    lf = Launch(path)
    try:
        (m,) = lf.wait_for(r"\[talker\s*\] talker: worker pid (\d+)")
        node, worker = lf.pids()["talker"], int(m.group(1))
        assert os.sched_getscheduler(worker) == os.SCHED_OTHER          # without the reset: SCHED_FIFO, 5
        assert os.sched_getscheduler(node) == os.SCHED_FIFO | os.SCHED_RESET_ON_FORK
        assert os.sched_getparam(node).sched_priority == 5
    finally:
        assert lf.stop() == 0


def test_host_filter_starts_only_that_hosts_share(demo_launch, tmp_path):
    path = demo_launch()
    text = path.read_text().replace("hosts:\n  main: {address: 127.0.0.1}",
                                    "hosts:\n  main: {address: 127.0.0.1}\n  arm1: {address: 127.0.0.1}")
    text = text.replace("listener: {type: listener, host: main", "listener: {type: listener, host: arm1")
    path.write_text(text)
    a = Launch(path, "--host", "arm1")
    b = Launch(path, "--host", "main")
    try:
        a.wait_for(r"heard seq=", count=3)   # a listener on 'arm1' hears the talker on 'main'
        assert set(a.pids()) == {"listener"} and set(b.pids()) == {"talker"}
    finally:
        a.stop()
        b.stop()


@pytest.mark.parametrize("yaml_text, needle", [
    ("nodes:\n  t: {type: nosuch}\n", "key 'nodes.t.type': Value error, unknown node type 'nosuch'"),
    ("nodes:\n  t: {type: talker, host: mars}\n", "key 'nodes.t.host': unknown host 'mars'"),
    ("nodes:\n  t: {type: talker, colour: red}\n", "key 'nodes.t.colour'"),
    ("base_port: 80\nnodes: {}\n", "key 'base_port'"),
    ("nodes: [1, 2\n", "not valid YAML"),
])
def test_bad_launch_file_names_file_key_and_value(tmp_path, yaml_text, needle):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml_text)
    with pytest.raises(LaunchError) as err:
        load_launch(path)
    assert str(path) in str(err.value)
    assert needle in str(err.value)


def test_bad_param_fails_before_sockets_with_field_name(demo_launch):
    path = demo_launch()
    out = subprocess.run([sys.executable, "-m", "flexsheet", "run", "talker", "--launch", str(path), "--name",
                          "talker", "--param", "rate=-3"], capture_output=True, text=True, timeout=30)
    assert out.returncode == 78  # EX_CONFIG: the launcher does not respawn it
    assert "configuration error: param 'rate'" in out.stderr and "-3" in out.stderr
