"""``flexsheet bench graph [--seconds S] [--json]``: the display's own path on the wall clock, without the
twin.

The pairs come from the camera twin's renderer, with the registration the camera node would publish for the
ideal twin (:mod:`flexsheet.calibration.published_registration`); the nodes are loaded by their node types
(the ``flexsheet.nodes`` entry points, :mod:`flexsheet.runtime.plugins`), as the launcher does.

The nodes of the display (triangulator, planner, both arm bridges, FEM, renderer offscreen on this machine's
GL) run in one container on the wall clock, fed by a player that publishes pre-rendered stereo pairs of the
ideal camera twin at 48 Hz along the paper's stroke: no world node, no camera rendering, no recorder beside
them. The arms' Modbus controller twins stand in for the lab's controllers, hardware of their own: each runs
in a process of its own (:func:`controllers`). From the stamps the nodes set:

* ``camera_frame_to_arm_command`` — the frame's ``header.stamp`` (when it was handed to the graph) to the
  first arm command carrying its fingertip (``ArmJointState.write_stamp``, the earlier arm);
* ``fingertip_to_rendered_frame`` — the fingertip's ``sent_stamp`` to the rendered pair that drew it
  (``RenderedFrame.header.stamp``; the renderer redraws and publishes every new input here, at most 120 Hz).

Each with ``median_ms``, ``p99_ms``, ``n``, the target and the verdict; exit status 1 when a path measured
nothing (``n`` 0), naming it, and 78 when the builder refuses a path's graph
(:class:`~flexsheet.runtime.graph_builder.GraphBuilder`; nothing starts). The bridges reach their controller
twins over TCP (``source: tcp``), as on the lab's arm PCs. These are the lab's real-time figures
(docs/realtime.md); the simulated clock charges the declared ones (flexsheet/model/timing.py).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import yaml

from flexsheet.calibration.published_registration import published_registration
from flexsheet.dirs import launch_dir
from flexsheet.runtime.bus import Bus
from flexsheet.runtime.config import EXIT_CONFIG
from flexsheet.runtime.container import Container
from flexsheet.runtime.graph_builder import Graph, GraphBuilder, GraphRefused, NodeTopics
from flexsheet.runtime.node import Node
from flexsheet.runtime.plugins import node_class
from flexsheet.runtime.qos import QoS
from flexsheet.twin.camera import twin_renderer
from flexsheet.twin.camera_source import sim_config
from flexsheet.twin.finger import FingerScript
from flexsheet.twin.truth import TwinTruth
from flexsheet.vision.camera_model import camera_model
from flexsheet.vision.stereo_calibration import to_message
from messages import StereoFrame
from messages import topics as T

RATE_HZ = 48.0
TARGETS = {"camera_frame_to_arm_command": {"median_ms": 2.5, "p99_ms": 5.0},
           "fingertip_to_rendered_frame": {"median_ms": 15.0}}
#: the measured paths; the bench exits 1 when any of them measured nothing
PATHS = tuple(TARGETS)


def _frames(n: int) -> tuple[list[tuple[np.ndarray, np.ndarray]], object, np.ndarray]:
    """``n`` stereo pairs of the ideal twin along the paper's 10 s stroke, its calibration and camera pose."""
    p = node_class("camera").Params(source="sim", model="ximea", twin={"realism": "ideal", "truth_seed": 0})
    calib = camera_model("ximea")
    published, T_dc, _ = published_registration(p.display_calib, calib, exact_nominal=True, model=p.model)
    renderer = twin_renderer(TwinTruth.draw(0, "ideal"), sim_config(p))
    script = FingerScript(mode="stroke", moving_time=10.0)   # the paper's 10 s stroke (the world's default)
    frames = []
    for t in np.linspace(0.0, script.duration, n, endpoint=False):
        pos, vel = script.state(float(t))
        frames.append(renderer.render(pos, vel, True))
    return frames, published, T_dc


class _Player(Node):
    """Publishes the latched calibration and the pre-rendered pairs at 48 Hz (stamped now)."""

    frames: list = []
    calib: object = None
    T_dc: np.ndarray | None = None

    async def setup(self) -> None:
        cal = self.publisher(T.CALIBRATION)
        cal.publish(to_message(self.calib, cal.header("camera_left"), self.T_dc))
        self.pub = self.publisher(T.STEREO)
        self.i = 0
        self.timer(1.0 / RATE_HZ, self.tick)

    def tick(self) -> None:
        left, right = self.frames[self.i % len(self.frames)]
        self.i += 1
        hdr = self.pub.header("camera_left")
        self.pub.publish(StereoFrame(header=hdr, left=left, right=right, exposure_stamp=hdr.stamp,
                                     exposure_time=0.004, stereo_skew=0.0))


class _Sink(Node):
    """Keeps what the measured outputs carry."""

    async def setup(self) -> None:
        self.tips: dict[float, tuple[float, float]] = {}
        self.writes: dict[float, float] = {}
        self.renders: dict[float, float] = {}
        self.targets: dict[float, float] = {}
        self.subscribe(T.FINGERTIP, self.on_tip, qos=QoS.KEEP_ALL)
        self.subscribe(T.SHEET_TARGET, lambda m: self.targets.setdefault(m.source_stamp, m.header.stamp),
                       qos=QoS.KEEP_ALL)
        self.subscribe(T.ARM_LEFT_STATE, self.on_arm, qos=QoS.KEEP_ALL)
        self.subscribe(T.ARM_RIGHT_STATE, self.on_arm, qos=QoS.KEEP_ALL)
        self.subscribe(T.RENDERED, self.on_render, qos=QoS.KEEP_ALL)

    def on_tip(self, m) -> None:
        if m.valid:
            self.tips[m.exposure_stamp] = (m.frame_stamp, m.sent_stamp)

    def on_arm(self, m) -> None:
        e = m.target_stamp
        if e and m.write_stamp and (e not in self.writes or m.write_stamp < self.writes[e]):
            self.writes[e] = m.write_stamp

    def on_render(self, m) -> None:
        self.renders.setdefault(m.source_stamp, m.header.stamp)


def _stats(x: list[float], target: dict) -> dict:
    a = np.asarray(x, float) * 1e3
    out = {"median_ms": float(np.median(a)) if a.size else None,
           "p99_ms": float(np.percentile(a, 99)) if a.size
           else None, "n": int(a.size), "target": target}
    out["verdict"] = "met" if a.size and all(out[k] is not None and out[k] <= v for k,
                                             v in target.items()) else \
        "MISSED"
    return out


def bench_graph(names: tuple[str, ...]) -> Graph:
    """The graph of one measured path: the player, the ``names`` nodes of ``launch/sim.yaml`` (their params
    from it, the bridges on ``source: tcp``) and the sink, built on the wall clock by
    :class:`~flexsheet.runtime.graph_builder.GraphBuilder`. Raises
    :class:`~flexsheet.runtime.graph_builder.GraphRefused` for a graph that cannot run."""
    lf = yaml.safe_load((launch_dir() / "sim.yaml").read_text())["nodes"]
    params = {n: dict(lf[n].get("params", {})) for n in lf}
    params["renderer"].update(publish_rate=120.0, max_render_rate=120.0)
    params["arm_left"]["port"] = CONTROLLERS["ctrl_left"]
    params["arm_right"]["port"] = CONTROLLERS["ctrl_right"]
    # on the wall clock the bridges reach their controller twins over TCP, as on the lab's arm PCs
    # (source sim is the in-process twin of a simulated clock, which the builder refuses on the wall clock)
    params["arm_left"]["source"] = params["arm_right"]["source"] = "tcp"
    b = GraphBuilder(clock="wall", name="bench graph")
    b.add("player", cls=_Player, topics=NodeTopics(frozenset({T.STEREO.name, T.CALIBRATION.name})))
    for name in names:
        b.add(name, lf[name]["type"], params[name])
    b.add("sink", cls=_Sink, topics=NodeTopics())
    return b.build()


async def _run(seconds: float, warmup: float, graph: Graph) -> dict:
    bus = Bus("bench", clock=None)
    made: dict[str, Node] = {}
    c = Container("bench", graph.members(made), bus)
    task = asyncio.get_running_loop().create_task(c.run(install_signals=False))
    t0 = time.monotonic()
    while not bus.ready():
        if task.done() or time.monotonic() - t0 > 300:
            raise RuntimeError("the display's nodes did not come up (see the log)")
        await asyncio.sleep(0.05)
    await asyncio.sleep(warmup)
    sink = made["sink"]
    sink.tips.clear()
    sink.writes.clear()
    sink.renders.clear()
    sink.targets.clear()
    await asyncio.sleep(seconds)
    tips, writes, renders, targets = (dict(sink.tips), dict(sink.writes), dict(sink.renders),
                                      dict(sink.targets))
    c.stop()
    await task
    hops = {"frame_to_fingertip": [s - f for f, s in tips.values()],
            "fingertip_to_sheet_target": [targets[e] - s for e, (_, s) in tips.items() if e in targets],
            "sheet_target_to_arm_command": [writes[e] - targets[e] for e in targets if e in writes]}
    return {"hops": {k: float(np.median(v)) * 1e3 if v else None for k, v in hops.items()},
            "arm": [writes[e] - f for e, (f, _) in tips.items() if e in writes],
            "render": [renders[e] - s for e, (_, s) in tips.items() if e in renders], "fingertips": len(tips)}


#: the two paths, each measured in its own run (in the lab the FEM and the renderer have their own processes
#: and cores beside the main PC's camera -> planner container; here one process would share one GIL)
ARM_PATH = ("triangulator", "planner", "arm_left", "arm_right")
RENDER_PATH = ("triangulator", "fem", "renderer")
#: the arm controllers' Modbus twins: the lab's robot controllers are hardware of their own, so the twins run
#: in processes of their own (in the container their servo ticks took the GIL from the measured path)
CONTROLLERS = {"ctrl_left": 15121, "ctrl_right": 15122}


@contextlib.contextmanager
def controllers(timeout: float = 60.0):
    """The arm controllers' twins (:data:`CONTROLLERS`, their other params from ``launch/sim.yaml``), each
    ``flexsheet run arm_controller_sim`` in a child process, up (their Modbus ports accept) for the ``with``
    block, stopped after it. Raises ``RuntimeError`` naming the twin that did not come up within ``timeout``
    s."""
    lf = yaml.safe_load((launch_dir() / "sim.yaml").read_text())["nodes"]
    procs = {}
    for n, port in CONTROLLERS.items():
        params = {**lf[n].get("params", {}), "port": port}
        cmd = [sys.executable, "-m", "flexsheet", "run", "arm_controller_sim", "--name", n]
        for k, v in params.items():
            cmd += ["--param", f"{k}={json.dumps(v)}"]
        procs[n] = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        t0 = time.monotonic()
        for n, port in CONTROLLERS.items():
            while True:
                try:
                    socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
                    break
                except OSError:
                    if procs[n].poll() is not None or time.monotonic() - t0 > timeout:
                        raise RuntimeError(f"bench graph: the controller twin {n} did not come up on port "
                                           f"{port} (exit {procs[n].poll()})") from None
                    time.sleep(0.1)
        yield
    finally:
        for p in procs.values():
            p.send_signal(signal.SIGINT)
        for p in procs.values():
            try:
                p.wait(10.0)
            except subprocess.TimeoutExpired:
                p.kill()


def measure(seconds: float, warmup: float) -> dict:
    """Both paths (module doc), each in its own run of ``warmup`` + ``seconds`` wall seconds. Raises
    :class:`~flexsheet.runtime.graph_builder.GraphRefused` before either starts when a path's graph cannot
    run."""
    arm_graph, render_graph = bench_graph(ARM_PATH), bench_graph(RENDER_PATH)
    with controllers():
        arm = asyncio.run(_run(seconds, warmup, arm_graph))
    ren = asyncio.run(_run(seconds, warmup, render_graph))
    return {"camera_frame_to_arm_command": _stats(arm["arm"], TARGETS["camera_frame_to_arm_command"]),
            "fingertip_to_rendered_frame": _stats(ren["render"], TARGETS["fingertip_to_rendered_frame"]),
            "arm_path_hops_median_ms": arm["hops"],
            "fingertips": {"arm_run": arm["fingertips"], "render_run": ren["fingertips"]}, "seconds": seconds,
            "clock": "wall",
            "note": "the display's nodes in one container on this host's wall clock, fed pre-rendered pairs "
                    "at 48 Hz (no world, camera twin or recorder load); the arm path (triangulator, planner, "
                    "both bridges; their Modbus controller twins in processes of their own) and the render "
                    "path (triangulator, FEM, renderer on this machine's GL) in separate runs"}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flexsheet bench graph", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: flexsheet bench graph --seconds 10 --json > "
                                        "graph_bench.json")
    ap.add_argument("--seconds", type=float, default=10.0, help="measured wall seconds (default 10)")
    ap.add_argument("--warmup", type=float, default=3.0, help="seconds after every node is up, not measured")
    ap.add_argument("--frames", type=int, default=144, help="pre-rendered pairs played in a loop (default "
                                                            "144)")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = ap.parse_args(argv)
    try:     # both paths' graphs, checked before anything is rendered or started
        bench_graph(ARM_PATH), bench_graph(RENDER_PATH)
    except GraphRefused as refused:
        for line in refused.lines:
            print(f"[bench graph] {line}", file=sys.stderr)
        print("[bench graph] FAILED: the graph was refused; nothing started", file=sys.stderr, flush=True)
        return EXIT_CONFIG
    print(f"[bench graph] rendering {args.frames} stereo pairs of the ideal twin ...", file=sys.stderr,
          flush=True)
    _Player.frames, _Player.calib, _Player.T_dc = _frames(args.frames)
    print(f"[bench graph] running the arm path, then the render path, {args.warmup:g} + {args.seconds:g} s "
          "each ...",
          file=sys.stderr, flush=True)
    logging.getLogger().setLevel(logging.WARNING)
    # the controller twins stop before their bridges here (one container): pymodbus logs the bridges' last
    # sends with a frame dump; not a fault of the path measured
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    out = measure(args.seconds, args.warmup)
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        for k in PATHS:
            v = out[k]
            print(f"{k:32s} median {v['median_ms']} ms  p99 {v['p99_ms']} ms  n {v['n']}  target "
                  f"{v['target']}: {v['verdict']}")
    empty = [k for k in PATHS if not out[k]["n"]]
    if empty:
        print(f"[bench graph] FAILED: measured nothing on {', '.join(empty)} (n 0; the log above says why)",
              file=sys.stderr, flush=True)
        return 1
    return 0
