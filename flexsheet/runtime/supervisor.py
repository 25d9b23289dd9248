"""The launch supervisor: starts a launch file's nodes (or one host's share) as OS processes — one per node,
or one per composable container — prefixes their output, respawns them by policy, forwards signals, escalates
shutdown (SIGINT, SIGTERM, SIGKILL) and reports CPU per process (:class:`Supervisor`). The file model is
:mod:`flexsheet.runtime.launch`."""

from __future__ import annotations

import asyncio
import ctypes
import json
import os
import signal
import sys
import time
from pathlib import Path

from flexsheet.runtime.codec import DecodeError, decode
from flexsheet.runtime.config import EXIT_CONFIG
from flexsheet.runtime.console import console_logger
from flexsheet.runtime.launch import LaunchError, LaunchFile, NodeSpec, RespawnSpec
from flexsheet.runtime.launch_config import curve_config
from flexsheet.runtime.zmq.transport import ZmqTransport
from messages import topics as T

#: exit codes of a node or container stopped by the launcher that are not failures (0, SIGINT's 130 and the
#: signals themselves)
STOP_EXITS = frozenset({0, 130, -2, -15})

__all__ = ["Supervisor", "container_spec", "children_of"]


def _child_setup(nice: int, rt_priority: int = 0):
    def setup() -> None:  # runs in the child between fork and exec
        try:
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
        except OSError:
            pass
        if nice:
            try:
                os.nice(nice)
            except OSError:  # negative niceness without root: run at the default priority
                pass
        if rt_priority:
            try:
                # reset on fork: a process the node starts (a table builder, a
                # subprocess) begins in the normal class, not at the node's
                # real-time priority, where its imports alone would starve the graph
                os.sched_setscheduler(0, os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0),
                                      os.sched_param(rt_priority))
            except (OSError, AttributeError):  # no privilege: normal scheduling
                pass
    return setup


class _Child:
    def __init__(self, name: str, spec: NodeSpec, members: list[str] | None = None) -> None:
        self.name, self.spec = name, spec
        self.members = members or []  # the nodes of a container child (empty: one node)
        self.proc: asyncio.subprocess.Process | None = None
        self.restarts = 0
        self.stopping = False
        self.lines_read = 0       # output lines logged: a stopping node still talking is not hung
        self.exit_codes: list[int] = []
        self.failures: list[int] = []  # exit codes of incarnations that failed (not by the launcher's stop)
        self.cpu_s = 0.0          # CPU time of the ended incarnations, s
        self.cpu_live = 0.0       # CPU time of the running incarnation at the last sample, s
        self.cpu_warm: tuple[float, float] | None = None  # (monotonic time, CPU s) once warmed up
        self.pids: list[int] = []
        self.started_at = 0.0


def container_spec(lf: LaunchFile, members: list[str]) -> NodeSpec:
    """The process-level spec of a container whose nodes are ``members``: required if any member is; respawn
    ``always`` if any member's policy is, else ``on-failure`` if any is, else ``never``, with the smallest
    delay and the largest ``max_restarts``; the smallest ``nice`` and the largest ``rt_priority``. The
    container of a ``clock: sim`` file is required and runs at normal priority (simulated time needs no
    real-time class)."""
    specs = [lf.nodes[n] for n in members]
    if getattr(lf, "clock", "wall") == "sim":
        return NodeSpec(type=specs[0].type, host=specs[0].host, respawn=RespawnSpec(policy="never"),
                        required=True,
                        container=specs[0].container)
    policies = {s.respawn.policy for s in specs}
    policy = "always" if "always" in policies else ("on-failure" if "on-failure" in policies else "never")
    respawn = RespawnSpec(policy=policy, delay=min(s.respawn.delay for s in specs),
                          max_restarts=max(s.respawn.max_restarts for s in specs))
    return NodeSpec(type=specs[0].type, host=specs[0].host, respawn=respawn,
                    required=any(s.required for s in specs),
                    nice=min(s.nice for s in specs), rt_priority=max(s.rt_priority for s in specs),
                    container=specs[0].container)


def children_of(lf: LaunchFile, host: str | None) -> list[_Child]:
    """One child process per node, or per container on one host (at its first member's place in the file)."""
    out: list[_Child] = []
    seen: set[tuple[str, str]] = set()
    for n, s in lf.nodes.items():
        if host is not None and s.host != host:
            continue
        if s.container is None:
            out.append(_Child(n, s))
            continue
        key = (s.container, s.host)
        if key in seen:
            continue
        seen.add(key)
        members = [m for m, t in lf.nodes.items() if t.container == s.container and t.host == s.host]
        hosts_of_name = {t.host for t in lf.nodes.values() if t.container == s.container}
        label = s.container if len(hosts_of_name) == 1 else f"{s.container}@{s.host}"
        out.append(_Child(label, container_spec(lf, members), members))
    return out


def _proc_cpu_s(pid: int) -> float | None:
    """utime + stime of process ``pid`` (all its threads), s, from ``/proc/<pid>/stat``; None if gone."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            data = f.read()
    except OSError:
        return None
    fields = data[data.rfind(b")") + 2:].split()
    return (int(fields[11]) + int(fields[12])) / _CLK_TCK


_CLK_TCK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


class Supervisor:
    """Runs the nodes of one host of a launch file as child processes (see the module docstring).

    ``host`` None runs every node (all hosts on this machine). ``out`` is exported as ``FLEXSHEET_OUT`` and
    substituted for ``$(out)``. ``duration`` s stops the run after that long (None: until Ctrl-C or a
    required node exits). Each prefixed output line and progress line is logged at INFO on
    ``flexsheet.console.launch`` (:mod:`flexsheet.runtime.console`).
    """

    def __init__(self, lf: LaunchFile, host: str | None = None, out: str | None = None,
                 duration: float | None = None, python: str = sys.executable,
                 overrides: dict[str, list[str]] | None = None) -> None:
        if host is not None and host not in lf.hosts:
            raise LaunchError(f"{lf.path}: --host {host!r} is not a host of the file; hosts: "
                              f"{', '.join(lf.hosts)}")
        self.lf, self.host, self.out, self.duration = lf, host, out, duration
        self.sim = getattr(lf, "clock", "wall") == "sim"   # the container counts simulated seconds itself
        self.log = console_logger("launch")
        self.python = python
        self.overrides = overrides or {}
        self.children = children_of(lf, host)
        self._stop = asyncio.Event()
        self._lines_read = 0          # node output lines logged: a stopping node still talking is not hung
        self.reason = ""
        self.lost_events: list[tuple[str, str]] = []
        self.config_errors: list[str] = []  # nodes that exited with EXIT_CONFIG (not respawned)
        width = max((len(c.name) for c in self.children), default=4)
        self._fmt = f"[{{:<{width}}}] {{}}"

    def _cmd(self, child: _Child) -> list[str]:
        if child.members:
            cmd = [self.python, "-u", "-m", "flexsheet", "run", "--container", child.spec.container,
                   "--launch",
                   str(self.lf.path), "--host", child.spec.host]
            if self.out:
                cmd += ["--out", self.out]
            if self.sim and self.duration is not None:
                cmd += ["--sim-duration", repr(float(self.duration))]
            for node in child.members:
                for kv in self.overrides.get(node, []):
                    cmd += ["--set", f"{node}.{kv}"]
            return cmd
        cmd = [self.python, "-u", "-m", "flexsheet", "run", child.spec.type, "--launch", str(self.lf.path),
               "--name", child.name]
        if self.out:
            cmd += ["--out", self.out]
        for kv in self.overrides.get(child.name, []):
            cmd += ["--param", kv]
        return cmd

    async def _spawn(self, child: _Child) -> None:
        env = dict(os.environ, PYTHONUNBUFFERED="1", FLEXSHEET_LAUNCH=str(Path(self.lf.path).resolve()))
        if self.out:
            env["FLEXSHEET_OUT"] = self.out
        child.proc = await asyncio.create_subprocess_exec(
            *self._cmd(child), stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
            stdin=asyncio.subprocess.DEVNULL, env=env, start_new_session=True,
            preexec_fn=_child_setup(child.spec.nice, child.spec.rt_priority))

    async def _pump(self, child: _Child) -> None:
        assert child.proc is not None and child.proc.stdout is not None
        while True:
            line = await child.proc.stdout.readline()
            if not line:
                break
            self._lines_read += 1
            child.lines_read += 1
            self.log.info(self._fmt.format(child.name, line.decode(errors="replace").rstrip()))

    @staticmethod
    def _kill_group(pgid: int) -> None:
        """SIGKILL to what is left of an exited node's process group (its session: ``start_new_session``)."""
        try:
            os.killpg(pgid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass                             # the group is empty: nothing outlived the node

    async def _exit_code(self, child: _Child, pump: asyncio.Task) -> int:
        """The node's exit code as soon as its process exits, its output read to the end. Whatever is left in
        its process group then (a worker it started that had not yet tied itself to its parent,
        :mod:`flexsheet.runtime.background`) is killed: it would hold the node's output pipe open, and
        asyncio's ``wait()`` waits for that pipe too, so the launcher would report neither the exit nor
        respawn the node until the worker ended (the renderer's sheet table, ~30 s or more: a kill -9 during
        its worker's imports stalled the respawn). Output still held open 2 s after that is no longer read."""
        proc = child.proc
        loop = asyncio.get_running_loop()
        exited = loop.create_future()
        try:
            pidfd = os.pidfd_open(proc.pid)              # readable once the process has exited (Linux >= 5.3)
        except (AttributeError, OSError):
            pidfd = None                                 # already reaped, or no pidfd: the pipe's end decides
        if pidfd is not None:
            loop.add_reader(pidfd, lambda: exited.done() or exited.set_result(None))
        try:
            await asyncio.wait({exited, pump}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            if pidfd is not None:
                loop.remove_reader(pidfd)
                os.close(pidfd)
            exited.cancel()
        if pump.done():                      # the output closed first, as a node ends: the process is exiting
            code = await proc.wait()
            self._kill_group(proc.pid)
            return code
        for _ in range(200):                 # asyncio's child watcher reaps it a moment later
            if proc.returncode is not None:
                break
            await asyncio.sleep(0.005)
        if proc.returncode is None:          # not reaped within 1 s: wait for it (and its pipe) as before
            return await proc.wait()
        self._kill_group(proc.pid)
        try:
            await asyncio.wait_for(asyncio.shield(pump), timeout=2.0)
        except TimeoutError:
            pump.cancel()
            self.log.info(self._fmt.format(child.name, "output still held open by another process 2 s after "
                                                    "exit: no longer read"))
        return proc.returncode

    @staticmethod
    def _record_exit(child: _Child, code: int) -> None:
        """One incarnation's end: its exit code, and its CPU time added to the node's ended incarnations."""
        child.exit_codes.append(code)
        child.cpu_s += child.cpu_live
        child.cpu_live = 0.0

    async def _watch(self, child: _Child) -> None:
        while True:
            await self._spawn(child)
            child.pids.append(child.proc.pid)
            child.started_at = child.started_at or time.monotonic()
            self.log.info(self._fmt.format(child.name, f"started pid {child.proc.pid}"
                                        + (f" (container: {', '.join(child.members)})" if child.members
                                           else "")))
            code = await self._exit_code(child, asyncio.create_task(self._pump(child)))
            self._record_exit(child, code)
            if child.stopping or self._stop.is_set():
                if code not in STOP_EXITS:   # e.g. a container whose node failed and was restarted, or -9
                    child.failures.append(code)
                return
            self.log.info(self._fmt.format(child.name, f"exited with code {code}"))
            if code != 0:
                child.failures.append(code)
            if code == EXIT_CONFIG:  # bad params or a missing file: a restart would fail the same way
                self.log.info(self._fmt.format(child.name, "configuration error (see the line above): not "
                                                        "respawned; check with: flexsheet launch "
                                                        f"{self.lf.path} --check"
                                                        + (f" --host {self.host}" if self.host else "")))
                self.config_errors.append(child.name)
                if child.spec.required:
                    self.reason = f"required node {child.name} has a configuration error"
                    self._stop.set()
                return
            if child.spec.required:
                self.reason = f"required node {child.name} exited ({code})"
                self._stop.set()
                return
            policy = child.spec.respawn
            if policy.policy == "never" or (policy.policy == "on-failure" and code == 0):
                return
            if child.restarts >= policy.max_restarts:
                self.log.info(self._fmt.format(child.name, f"not respawned: {policy.max_restarts} restarts "
                                                           "used"))
                return
            child.restarts += 1
            self.log.info(self._fmt.format(child.name, f"respawning in {policy.delay:.1f} s "
                                                    f"(restart {child.restarts}/{policy.max_restarts})"))
            await asyncio.sleep(policy.delay)
            if self._stop.is_set():
                return

    async def _stop_child(self, child: _Child) -> None:
        child.stopping = True
        proc = child.proc
        if proc is None or proc.returncode is not None:
            return
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            try:
                os.killpg(proc.pid, sig)
            except ProcessLookupError:
                return
            for _ in range(6):       # a node still printing its last output gets up to 6 timeouts, not one
                before = child.lines_read
                try:
                    await asyncio.wait_for(asyncio.shield(proc.wait()), timeout=self.lf.shutdown_timeout)
                    return
                except TimeoutError:
                    if child.lines_read == before:
                        break
            self.log.info(self._fmt.format(child.name, f"did not stop on {sig.name}; escalating"))

    async def _drain(self, watchers: list[asyncio.Task], quiet_s: float = 3.0,
                     limit_s: float = 120.0) -> None:
        """Wait for the watchers to record their nodes' exits (≤ 1 s reap + 2 s of output), and for longer
        while the stopped nodes' last output is still arriving (a node with much to say as it stops, on a
        loaded machine: no line is dropped while lines keep coming); at most ``limit_s``."""
        t_end = time.monotonic() + limit_s
        while True:
            before = self._lines_read
            _, pending = await asyncio.wait(watchers, timeout=quiet_s)
            if not pending or self._lines_read == before or time.monotonic() > t_end:
                return

    async def run(self) -> int:
        """Run until Ctrl-C, SIGTERM, ``duration`` or a required node's exit. Returns 0; :data:`EXIT_CONFIG`
        if a node had a configuration error (a bind failure included); else 1 if any node exited non-zero by
        itself during the run (respawned or not). Exits caused by the launcher's own stop are never
        failures."""
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, self._on_signal, sig)
        if not self.children:
            self.log.info(f"[launch] no nodes for host {self.host!r} in {self.lf.path}")
            return 0
        n_nodes = sum(len(c.members) or 1 for c in self.children)
        self.log.info(f"[launch] {self.lf.name}: starting {n_nodes} nodes"
                   + (f" in {len(self.children)} processes" if n_nodes != len(self.children) else "")
                   + (f" on host {self.host}" if self.host else ""))
        watchers = [loop.create_task(self._watch(c)) for c in self.children]
        monitor = loop.create_task(self._monitor())
        sampler = loop.create_task(self._sample_cpu())
        t0 = time.monotonic()
        try:
            if self.duration is not None and not self.sim:
                await asyncio.wait_for(self._stop.wait(), timeout=self.duration)
            else:
                await self._stop.wait()
        except TimeoutError:
            self.reason = f"duration {self.duration:g} s reached"
        self.log.info(f"[launch] stopping after {time.monotonic() - t0:.1f} s: "
                      f"{self.reason or 'stop requested'}")
        monitor.cancel()
        sampler.cancel()
        self._sample_now()
        await asyncio.gather(*(self._stop_child(c) for c in reversed(self.children)))
        await self._drain(watchers)
        for w in watchers:
            w.cancel()
        await asyncio.gather(*watchers, return_exceptions=True)
        for c in self.children:     # a watcher cancelled while it still read the stopped node's last output
            rc = c.proc.returncode if c.proc is not None else None  # never recorded that incarnation's exit:
            if rc is not None and len(c.exit_codes) < len(c.pids):    # a respawned node kept its kill's -9
                self._record_exit(c, rc)                              # and the run "failed"
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
        self.log.info("[launch] all nodes stopped")
        if self.out:
            self.write_cpu(Path(self.out) / "cpu.json", time.monotonic() - t0)
        failed = [c for c in self.children if c.failures]
        if failed:   # name them: a run's exit 1 must say whose exit it is (exits the launcher caused are not)
            self.log.info("[launch] node(s) failed during the run: " + ", ".join(
                f"{c.name} (exit {', '.join(map(str, c.failures))})" for c in failed))
        if self.config_errors:
            return EXIT_CONFIG
        return 1 if failed else 0

    def _on_signal(self, sig: signal.Signals) -> None:
        if self._stop.is_set():  # second Ctrl-C: stop faster
            self.lf.shutdown_timeout = min(self.lf.shutdown_timeout, 0.5)
        self.reason = f"{signal.Signals(sig).name} received"
        self._stop.set()

    async def _monitor(self) -> None:
        """Watch every node's heartbeat on ``/diagnostics`` (all hosts of the file) and report, once per
        transition, a node that goes silent for ``3 × heartbeat_period`` (its host is gone, partitioned or
        the node hangs) and when it comes back. Counts go into ``self.lost_events``."""
        last: dict[str, float] = {}
        host_of = {n: s.host for n, s in self.lf.nodes.items()}
        lost: set[str] = set()

        def on_frames(frames: list) -> None:
            try:
                hb = decode(frames, T.DIAGNOSTICS)
            except DecodeError:
                return
            last[hb.node] = time.monotonic()
            if hb.node in lost:
                lost.discard(hb.node)
                self.log.info(f"[launch] node {hb.node} on host {host_of.get(hb.node, '?')} is back "
                              "(heartbeat)")

        tr = ZmqTransport("", self.lf.endpoints().values(), curve=curve_config(self.lf, self.host or None))
        await tr.start(on_frames)
        tr.subscribe(T.DIAGNOSTICS.name)
        limit = 3.0 * self.lf.heartbeat_period
        try:
            while True:
                await asyncio.sleep(self.lf.heartbeat_period / 2)
                now = time.monotonic()
                for name, t in last.items():
                    if name in self.lf.nodes and name not in lost and now - t > limit:
                        lost.add(name)
                        self.lost_events.append((name, host_of.get(name, "?")))
                        self.log.info(f"[launch] node {name} on host {host_of.get(name, '?')} lost: no "
                                   f"heartbeat for {now - t:.1f} s")
        finally:
            tr.close()

    #: s after the start before the steady-state CPU share
    #: is measured (imports, precompute and caches excluded)
    cpu_warmup_s = 10.0

    def _sample_now(self) -> None:
        now = time.monotonic()
        for c in self.children:
            if c.proc is not None and c.proc.returncode is None:
                v = _proc_cpu_s(c.proc.pid)
                if v is not None:
                    c.cpu_live = v
            if c.cpu_warm is None and c.started_at and now - c.started_at >= self.cpu_warmup_s:
                c.cpu_warm = (now, c.cpu_s + c.cpu_live)

    async def _sample_cpu(self, period: float = 1.0) -> None:
        """Sample every child's CPU time each ``period`` s (a child that dies loses at most one period)."""
        while True:
            self._sample_now()
            await asyncio.sleep(period)

    def cpu_report(self, wall_s: float) -> dict:
        """Per node CPU use over the run: ``{"wall_s", "cores", "processes": {child: {"cpu_s", "cpu_percent",
        "steady_cpu_percent", "pids", "nodes", "restarts"}}, "nodes": {node: {"cpu_s", "cpu_percent",
        "process", "shared"}}}``. A node alone in its process: its process's CPU time
        (all its threads). A node in a container: its handlers' and timers' thread CPU time as the container
        measured it (``cpu_<container>.json``), ``shared`` naming the process whose total also holds the
        container's loop, decoding and worker threads. ``cpu_percent``: of one core, over ``wall_s``."""
        procs, nodes = {}, {}
        now = time.monotonic()
        for c in self.children:
            cpu = c.cpu_s + c.cpu_live
            procs[c.name] = {"cpu_s": round(cpu, 3),
                             "cpu_percent": round(100.0 * cpu / wall_s, 2) if wall_s else 0.0,
                             "pids": c.pids, "nodes": c.members or [c.name], "restarts": c.restarts}
            if c.cpu_warm is not None and now - c.cpu_warm[0] > 1.0:
                procs[c.name]["steady_cpu_percent"] = round(100.0 * (cpu - c.cpu_warm[1])
                                                            / (now - c.cpu_warm[0]), 2)
            if not c.members:
                nodes[c.name] = {"cpu_s": round(cpu, 3), "cpu_percent": procs[c.name]["cpu_percent"],
                                 "process": c.name}
                if "steady_cpu_percent" in procs[c.name]:
                    nodes[c.name]["steady_cpu_percent"] = procs[c.name]["steady_cpu_percent"]
                continue
            inner: dict = {}
            if self.out:
                try:
                    inner = json.loads((Path(self.out)
                                        / f"cpu_{c.spec.container}.json").read_text()).get("nodes", {})
                except (OSError, ValueError):
                    inner = {}
            for n in c.members:
                v = float(inner.get(n, {}).get("handler_cpu_s", 0.0))
                nodes[n] = {"cpu_s": round(v, 3),
                            "cpu_percent": round(100.0 * v / wall_s, 2) if wall_s else 0.0,
                            "process": c.name, "shared": True}
        return {"wall_s": round(wall_s, 3), "cores": os.cpu_count(), "processes": procs, "nodes": nodes,
                "note": "cpu_percent: of one core over the whole run, start-up included; steady_cpu_percent: "
                        f"from {self.cpu_warmup_s:g} s after the start to the stop; container nodes: "
                        "handler+timer thread CPU only, the rest of their process's cpu_s is shared (loop, "
                        "decoding, worker threads)"}

    def write_cpu(self, path: Path, wall_s: float) -> None:
        """Write :meth:`cpu_report` as JSON to ``path`` (a failure is printed, never raised)."""
        try:
            path.write_text(json.dumps(self.cpu_report(wall_s), indent=1))
            self.log.info(f"[launch] per-node CPU: {path}")
        except OSError as exc:
            self.log.info(f"[launch] cannot write {path}: {exc}")

    def pids(self) -> list[int]:
        """PIDs of the running children."""
        return [c.proc.pid for c in self.children if c.proc is not None and c.proc.returncode is None]
