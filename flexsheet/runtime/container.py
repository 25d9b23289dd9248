"""Composable nodes: several nodes of one host in one process and one asyncio loop (ROS 2 component
containers).

A launch file puts a node in a container with ``container: NAME``; the nodes of one container and one host run
in one process, started by the supervisor as ``flexsheet run --container NAME --launch FILE --host HOST``::

    nodes:
      camera:       {type: camera, host: main, container: vision}
      triangulator: {type: triangulator, host: main, container: vision}
      planner:      {type: planner, host: main, container: vision}

Between the nodes of a container a message travels as the frozen message object itself, through the
container's :class:`~flexsheet.runtime.bus.Bus`: no encode, no decode, no copy, no socket; its numpy arrays
are handed on as read-only views (a receiver cannot write into the publisher's arrays; the publisher must not
write into an array after publishing it, as with any zero-copy transport). Each node keeps its own publisher
socket at its launch-file endpoint (:class:`flexsheet.runtime.zmq.xpub.XPub`), so the rest of the graph, the
recorder and the tools see the same endpoints, topics and heartbeats as before; a message is encoded — once —
only when a subscriber outside the process has asked for its topic (XPUB subscription tracking) or the topic
is latched. The container has one SUB socket, connected to every endpoint of the graph outside the container,
and hands what arrives to its nodes' subscriptions as usual (decoded and validated there: the wire boundary).

QoS (latest, keep-all, latched: a latched object is kept and handed to a late in-process joiner), heartbeats,
diagnostics, parameters and remaps work as for a node alone. A node that raises out of its ``run`` (its setup,
its transport) is restarted inside the container by its own ``respawn`` policy, as a fresh instance, while the
other nodes keep running with their state; a configuration error (exit status 78 alone) is not restarted. What
a container cannot contain: a crash of the interpreter itself (a segfault or abort in a C extension — OpenCV,
numpy, pyzmq, a GL driver — ``os._exit``, the kernel's OOM killer) ends every node of the process (the
supervisor then restarts the whole container by the members' policy); a handler that blocks the loop (a sync
call in an ``async def``) stalls every node of the container; nodes share the GIL, so a pure-Python CPU hog in
one slows the others; niceness and RT priority are per process (the container takes the smallest ``nice`` and
the largest ``rt_priority`` of its members); a node's module-level globals are shared.

Errors: :class:`flexsheet.runtime.launch.LaunchError` for a container that names no node on the host.
Source: ROS 2 ``rclcpp_components`` (component container, intra-process communication), ZeroMQ XPUB
(``ZMQ_XPUB_VERBOSE``).
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flexsheet.runtime.bus import Bus, ContainerTransport
from flexsheet.runtime.clock import SimClock
from flexsheet.runtime.config import EXIT_CONFIG, ConfigError, NodeConfig
from flexsheet.runtime.console import console_logger
from flexsheet.runtime.launch import LaunchError, load_launch
from flexsheet.runtime.launch_config import curve_config, node_config
from flexsheet.runtime.lockstep import SIM_EPOCH, run_live
from flexsheet.runtime.node import Node
from flexsheet.runtime.plugins import node_class
from flexsheet.runtime.transport import TransportError

__all__ = ["Container", "Member", "container_members", "container_from_launch", "run_container"]

log = logging.getLogger("container")


@dataclass
class Member:
    """One node of a container: ``make(bus)`` builds a fresh instance (each start and restart); ``policy``
    (never | on-failure | always), ``delay`` s, ``max_restarts``: its launch-file respawn policy;
    ``required``: when it ends, the container ends."""

    name: str
    make: Callable[[Bus], Node]
    policy: str = "on-failure"
    delay: float = 0.5
    max_restarts: int = 10
    required: bool = False
    node: Node | None = None
    restarts: int = 0
    codes: list[int] = field(default_factory=list)
    finished: bool = False
    cpu_s: float = 0.0  # handler + timer CPU of the instances that ended


class Container:
    """Runs the :class:`Member` nodes of one container on one loop (see the module docstring).

    :meth:`run` returns the process exit status: 0 after a stop (signal, :meth:`stop`, every node ended by
    itself), a required member's own status when it ends, :data:`~flexsheet.runtime.config.EXIT_CONFIG` when a
    required member or every member has a configuration error.
    """

    def __init__(self, name: str, members: list[Member], bus: Bus, shutdown_timeout: float = 3.0,
                 cpu_file: str | None = None,
                 sim_until: float | None = None, sim_file: str | None = None,
                 rtf: float | None = None) -> None:
        self.name, self.members, self.bus = name, members, bus
        self.sim_until = sim_until   # live simulated clock: stop after this many simulated seconds
        self.sim_file = sim_file     # live simulated clock: where the run's clock figures go (JSON)
        self.rtf = rtf  # live simulated clock: cap on simulated s per wall s (None: as fast as it can)
        # live simulated clock: wall s from start until each node was active
        self.active_s: dict[str, float] = {}
        # (process CPU, members' CPU) when sim time starts
        self._cpu_at_start: tuple[float, dict[str, float]] | None = None
        self.shutdown_timeout = shutdown_timeout
        self.log = console_logger("container")   # what it says to the user (flexsheet.runtime.console)
        self.cpu_file = cpu_file
        self._stop = asyncio.Event()
        self._stopping = False
        self.reason = ""
        self.code = 0
        bus.ready_check = lambda: all(m.finished or (m.node is not None and m.node.ready) for m in members)

    def stop(self) -> None:
        """Ask every node to stop (thread-safe from the loop's own thread or a signal handler)."""
        self._stop.set()

    def node(self, name: str) -> Node | None:
        """The running instance of member ``name`` (None while it is down)."""
        return next((m.node for m in self.members if m.name == name), None)

    async def _member(self, m: Member) -> int:
        from pydantic import ValidationError

        while True:
            try:
                node = m.make(self.bus)
            except ValidationError as exc:
                for err in exc.errors():
                    self.log.info(f"{m.name}: configuration error: param '{'.'.join(map(str, err['loc']))}': "
                               f"{err['msg']} (value {err.get('input')!r:.200})")
                code = EXIT_CONFIG
            else:
                m.node = node
                try:
                    await node.run(install_signals=False)
                    code = 0
                except ConfigError as exc:
                    self.log.info(f"{m.name}: configuration error: {exc}")
                    code = EXIT_CONFIG
                except TransportError as exc:   # cannot bind or connect: a restart fails the same way
                    self.log.info(f"{m.name}: configuration error: {exc}")
                    code = EXIT_CONFIG
                except asyncio.CancelledError:
                    raise
                except Exception:  # noqa: BLE001 - a node's crash stays in the node
                    log.exception("%s crashed (the other nodes of container %s keep running)", m.name,
                                  self.name)
                    code = 1
                finally:
                    m.cpu_s += node.cpu_seconds()
                    m.node = None
            m.codes.append(code)
            if self._stopping:
                return code
            self.log.info(f"{m.name}: ended with status {code}")
            if code == EXIT_CONFIG:
                self.log.info(f"{m.name}: configuration error: not restarted")
                return self._end(m, code)
            if m.required:
                return self._end(m, code)
            if m.policy == "never" or (m.policy == "on-failure" and code == 0):
                return self._end(m, code)
            if m.restarts >= m.max_restarts:
                self.log.info(f"{m.name}: not restarted: {m.max_restarts} restarts used")
                return self._end(m, code)
            m.restarts += 1
            self.log.info(f"{m.name}: restarting in {m.delay:.1f} s (restart {m.restarts}/{m.max_restarts}; "
                       f"the other nodes of container {self.name} keep running)")
            await asyncio.sleep(m.delay)
            if self._stopping:
                return code

    def _end(self, m: Member, code: int) -> int:
        m.finished = True
        if m.required:
            self.reason = f"required node {m.name} ended ({code})"
            self.code = code
            self._stop.set()
        elif all(x.finished for x in self.members):
            self.reason = "every node ended"
            if all(x.codes and x.codes[-1] == EXIT_CONFIG for x in self.members):
                self.code = EXIT_CONFIG
            self._stop.set()
        return code

    async def run(self, install_signals: bool = True) -> int:
        loop = asyncio.get_running_loop()
        if install_signals:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, self.stop)
        t0, c0 = time.monotonic(), time.process_time()
        try:
            await self.bus.start()
        except TransportError as exc:
            self.log.info(f"container {self.name}: configuration error: {exc}")
            return EXIT_CONFIG
        self.log.info(f"container {self.name}: {len(self.members)} nodes in pid {os.getpid()}: "
                   + ", ".join(m.name for m in self.members)
                   + ((" (simulated clock)" if self.bus.clock.live else " (lockstep: replayed clock)")
                      if self.bus.lockstep is not None else ""))
        tasks = {loop.create_task(self._member(m)): m for m in self.members}
        driver = loop.create_task(self._drive()) if getattr(self.bus.clock, "live", False) else None
        await self._stop.wait()
        self._stopping = True
        if driver is not None:
            driver.cancel()
            await asyncio.gather(driver, return_exceptions=True)
        for m in reversed(self.members):
            if m.node is not None:
                m.node.shutdown()
        done, pending = await asyncio.wait(tasks, timeout=self.shutdown_timeout * 2)
        for t in pending:
            self.log.info(f"{tasks[t].name}: did not stop in {self.shutdown_timeout * 2:.1f} s; cancelled")
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        self.bus.close()
        if install_signals:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)
        self._write_cpu(time.monotonic() - t0, time.process_time() - c0)
        failed = [m.name for m in self.members if any(c != 0 for c in m.codes)]
        if self.code == 0 and failed:   # a node that failed and was restarted here: the launch must know
            self.log.info(f"container {self.name}: node(s) failed during the run: {', '.join(failed)}")
            return 1
        return self.code

    async def _drive(self) -> None:
        """Drive the live simulated clock (:func:`flexsheet.runtime.lockstep.run_live`) until ``sim_until``
        simulated seconds (then stop the container) or the stop; write the clock figures."""
        t0 = time.monotonic()
        ready_s = None

        def stopped() -> bool:
            return self._stopping

        async def wait_ready() -> None:
            nonlocal ready_s
            while not self.bus.ready() and not self._stopping:
                for m in self.members:
                    if m.name not in self.active_s and m.node is not None and m.node.ready:
                        self.active_s[m.name] = time.monotonic() - t0
                await asyncio.sleep(0.01)
            for m in self.members:
                self.active_s.setdefault(m.name, time.monotonic() - t0)
            ready_s = time.monotonic() - t0
            self.log.info(f"container {self.name}: every node active after {ready_s:.1f} s; simulated time "
                       f"starts at {SIM_EPOCH:g} "
                       "s" + (f" and runs {self.sim_until:g} s" if self.sim_until else "")
                       + (f", paced at {self.rtf:g}x wall time" if self.rtf else ""))

        stats = self.bus.lockstep.stats   # kept up to date while it runs: valid however the run ends
        try:
            await wait_ready()
            self._cpu_at_start = (time.process_time(), self._host_cpu())    # the run's own CPU: from here on
            await run_live(self.bus, self.sim_until, stopped, self.rtf)
            if self.sim_until is not None and not self._stopping:
                self.reason = f"simulated duration {self.sim_until:g} s reached"
                self.log.info(f"container {self.name}: {self.reason} in {stats.wall_s:.1f} s of wall time "
                           f"(real-time factor {stats.speed:.2f})")
                self._stop.set()
        finally:
            self._write_sim(ready_s)

    def _write_sim(self, ready_s: float | None) -> None:
        if not self.sim_file:
            return
        ls = self.bus.lockstep
        stats = ls.stats
        host_cpu = self._host_cpu()
        run = {}
        if self._cpu_at_start is not None:         # start-up (tables, imports, set-up) and the stop left out
            c0, h0 = self._cpu_at_start
            run = {"process_cpu_run_s": time.process_time() - c0,
                   "host_handler_cpu_run_s": {k: v - h0.get(k, 0.0) for k, v in host_cpu.items()}}
        data = {"clock": "sim", "rtf_target": self.rtf, "ready_wall_s": ready_s,
                "active_wall_s": dict(self.active_s),
                "sim_s": stats.bag_s, "wall_s": stats.wall_s, "realtime_factor": stats.speed,
                "handled": stats.handled, "timer_ticks": stats.timers,
                "superseded_latest": ls.dropped,
                "charged_compute_s": dict(sorted(ls.charged.items())),
                "host_handler_cpu_s": host_cpu, **run,
                "note": "charged_compute_s: simulated time charged to each node (declared sim_cost: the "
                        "lab's timings); host_handler_cpu_s: what its handlers took on this host (thread CPU "
                        "time); *_run_s: the same, and the whole process's CPU, from the start of simulated "
                        "time on"}
        try:
            Path(self.sim_file).parent.mkdir(parents=True, exist_ok=True)
            Path(self.sim_file).write_text(json.dumps(data, indent=1))
        except OSError as exc:
            self.log.info(f"container {self.name}: cannot write {self.sim_file}: {exc}")

    def _host_cpu(self) -> dict[str, float]:
        """Each member's CPU on this host so far, s: its set-up's and its handlers' (thread CPU time)."""
        return {m.name: m.cpu_s + (m.node.cpu_seconds() if m.node is not None else 0.0) for m in self.members}

    def _write_cpu(self, wall: float, cpu: float) -> None:
        if not self.cpu_file:
            return
        data = {"container": self.name, "pid": os.getpid(), "wall_s": wall, "process_cpu_s": cpu,
                "nodes": {m.name: {"handler_cpu_s": m.cpu_s, "restarts": m.restarts} for m in self.members},
                # a lockstep replay's figures (flexsheet.runtime.lockstep.LockstepStats; None on other clocks)
                "lockstep": (self.bus.lockstep.stats.as_dict()
                             if self.bus.lockstep is not None and not self.bus.clock.live else None),
                "note": "handler_cpu_s: CPU of each node's handlers and timer callbacks (thread time; an "
                        "async one's own steps); the rest of process_cpu_s is shared: the loop, decoding, "
                        "threads"}
        try:
            Path(self.cpu_file).parent.mkdir(parents=True, exist_ok=True)
            Path(self.cpu_file).write_text(json.dumps(data, indent=1))
        except OSError as exc:
            self.log.info(f"container {self.name}: cannot write {self.cpu_file}: {exc}")


# ----------------------------------------------------------------------------------------- from a launch file
def container_members(lf, name: str, host: str | None) -> list[str]:
    """Names of the nodes of ``lf`` in container ``name`` on ``host`` (all hosts if None), in file order."""
    return [n for n, s in lf.nodes.items() if s.container == name and (host is None or s.host == host)]


def container_from_launch(lf, name: str, host: str | None = None, out: str | None = None,
                          overrides: dict[str, dict[str, Any]] | None = None,
                          sim_until: float | None = None) -> Container:
    """The :class:`Container` of nodes ``container: name`` on ``host`` of launch file ``lf``.

    ``overrides``: node → {param: value}. A container whose ``player`` node has ``mode: lockstep`` runs on a
    :class:`~flexsheet.runtime.clock.SimClock` (lockstep replay). Raises ``LaunchError`` when no node of the
    file is in that container on that host, or when its nodes span hosts and ``host`` is None.
    """
    names = container_members(lf, name, host)
    if not names:
        where = f" on host {host!r}" if host else ""
        known = sorted({s.container for s in lf.nodes.values() if s.container})
        raise LaunchError(f"{lf.path}: no node has 'container: {name}'{where}; containers: "
                          f"{', '.join(known) or '-'}")
    hosts = {lf.nodes[n].host for n in names}
    if len(hosts) > 1:
        raise LaunchError(f"{lf.path}: container {name!r} has nodes on hosts {', '.join(sorted(hosts))}: "
                          "give --host (one process per host)")
    host = hosts.pop()
    overrides = overrides or {}
    configs: dict[str,
                  NodeConfig] = {n: node_config(lf, n, out=out, overrides=overrides.get(n)) for n in names}
    lockstep = any(lf.nodes[n].type == "player" and configs[n].params.get("mode") == "lockstep"
                   for n in names)
    members_eps = {configs[n].endpoint for n in names}
    peers = [ep for ep in lf.endpoints().values() if ep not in members_eps]
    live = getattr(lf, "clock", "wall") == "sim"
    clock = SimClock(live=live) if (lockstep or live) else None
    if live:   # simulated time stands at its epoch while the nodes set up, then runs (run_live)

        clock.set(SIM_EPOCH)
    bus = Bus(name, peers, curve_config(lf, host), clock)
    members = []
    for n in names:
        spec = lf.nodes[n]
        cls = node_class(spec.type)

        def make(b: Bus, cls=cls, cfg=configs[n]) -> Node:
            return cls(cfg, transport=ContainerTransport(b, cfg.endpoint))

        members.append(Member(n, make, spec.respawn.policy, spec.respawn.delay, spec.respawn.max_restarts,
                              spec.required))
    cpu_file = os.path.join(out, f"cpu_{name}.json") if out else None
    sim_file = os.path.join(out, "sim_clock.json") if (out and live) else None
    return Container(name, members, bus, shutdown_timeout=lf.shutdown_timeout, cpu_file=cpu_file,
                     sim_until=sim_until if live else None, sim_file=sim_file, rtf=lf.rtf if live else None)


#: a file name: the container runs under :mod:`cProfile` and writes its stats there (``flexsheet bench sim
#: --profile``); the loop's thread only, which on ``clock: sim`` runs every handler
PROFILE_ENV = "FLEXSHEET_PROFILE"


def run_container(launch: str, name: str, host: str | None = None, out: str | None = None,
                  overrides: dict[str, dict[str, Any]] | None = None, sim_until: float | None = None) -> int:
    """``flexsheet run --container NAME --launch FILE``: run that container in this process; returns the exit
    status (78 for a launch-file or configuration error)."""
    import sys

    try:
        lf = load_launch(launch)
        c = container_from_launch(lf, name, host, out, overrides, sim_until=sim_until)
    except LaunchError as exc:
        print(f"flexsheet run --container {name}: configuration error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    profile = os.environ.get(PROFILE_ENV)
    if not profile:
        return asyncio.run(c.run())
    import cProfile

    prof = cProfile.Profile(time.thread_time)  # CPU, not wall: a wait costs nothing
    try:
        return prof.runcall(asyncio.run, c.run())
    finally:
        prof.dump_stats(profile)
