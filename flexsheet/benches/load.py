"""``flexsheet bench load``: every topic of the display at 2× its nominal rate, real payloads, for S seconds.

What it runs, each as its own OS process talking ZeroMQ like the live graph:

* one publisher process per producing node of ``launch/sim.yaml`` (camera, triangulator, planner, arm_left,
  arm_right, fem, renderer, world), each a :class:`flexsheet.runtime.node.Node` publishing its topics of
  :data:`messages.topics.ALL` at ``factor`` × ``nominal_hz`` with realistic payloads: the stereo frame
  2×512×640 uint8 (655 kB), the rendered frame 2×768×1024×3 uint8 (4.7 MB), the FEM surface 600 vertices
  and 1 100 triangles, the 16×16 membrane grid; the calibration is latched once; every process sends its
  heartbeat on ``/diagnostics`` as usual;
* one subscriber process subscribed to every topic with ``QoS.KEEP_ALL`` (so that every message is timed):
  latency = receive time in the handler − ``header.stamp`` (the publisher's ``time.time()`` just before
  encoding; one machine, one clock);
* one recorder (:class:`flexsheet.runtime.bag.RecorderNode`, the topics of ``launch/sim.yaml``: all but
  ``/camera/stereo``) writing an MCAP bag to a temporary folder.

The parent samples ``VmRSS`` of every process (``/proc/<pid>/status``) every ``--sample`` s and fits a line
(least squares, :func:`numpy.polyfit`) to each process's RSS after the warm-up: the slope in MB/min says
whether a queue grows without bound (a bounded process has a slope near 0 whatever its level). Reported:
per process peak RSS and slope, the largest slope, and latency p50/p99 per topic and over all messages,
plus messages sent/received/dropped per topic (publisher counts from the heartbeats, subscriber counts from
its own statistics).

Numbers taken on a shared 2-core machine are pessimistic (CPU contention shows up as latency).
Source: DDS/ROS 2 QoS history depth (bounded queues), ``procfs(5)`` VmRSS.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from flexsheet.runtime.bag import RecorderNode
from flexsheet.runtime.bag_read import bag_info
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.node import Node
from flexsheet.runtime.ports import free_port
from flexsheet.runtime.qos import QoS
from messages import topics as T
from messages.samples import sample_fields

log = logging.getLogger(__name__)

#: producing node → its topics (as in launch/sim.yaml)
GROUPS: dict[str, list[str]] = {
    "camera": [T.STEREO.name, T.CALIBRATION.name],
    "triangulator": [T.FINGERTIP.name],
    "planner": [T.SHEET_TARGET.name, T.ARM_LEFT_TARGET.name, T.ARM_RIGHT_TARGET.name],
    "arm_left": [T.ARM_LEFT_STATE.name],
    "arm_right": [T.ARM_RIGHT_STATE.name],
    "fem": [T.DEFORMATION.name],
    "renderer": [T.RENDERED.name],
    "world": [T.FINGER_TRUTH.name, T.SHEET_STATE.name],
}
#: realistic sizes of the free array dimensions (message field → shape)
SHAPES: dict[tuple[str, str], tuple[int, ...]] = {
    ("StereoFrame", "left"): (512, 640), ("StereoFrame", "right"): (512, 640),
    ("RenderedFrame", "left"): (768, 1024, 3), ("RenderedFrame", "right"): (768, 1024, 3),
    ("ObjectDeformation", "vertices"): (600, 3), ("ObjectDeformation", "faces"): (1100, 3),
    ("SheetState", "membrane"): (16, 16),
    ("StereoCalibration", "D1"): (5,), ("StereoCalibration", "D2"): (5,),
}
RECORDED = [t.name for t in T.ALL if t.name != T.STEREO.name]
def _image(shape: tuple[int, ...], rng: np.random.Generator, random: bool) -> np.ndarray:
    if random:
        return rng.integers(0, 256, shape).astype(np.uint8)
    h, w = shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    img = (96 + 64 * np.sin(xx / 37.0) * np.cos(yy / 23.0)).astype(np.float32)
    img += rng.normal(0.0, 2.0, (h, w))          # sensor-like noise of a few grey levels
    img = np.clip(img, 0, 255).astype(np.uint8)
    return np.repeat(img[..., None], shape[2], axis=2) if len(shape) == 3 else img


def payload_fields(topic_name: str, seed: int = 0, random_images: bool = False) -> dict:
    """Field values (all but ``header``) of a valid, realistically sized message of ``topic_name``.

    Arrays get the sizes of :data:`SHAPES` (free dimensions elsewhere: 2). Images (uint8 arrays of ≥ 2
    dims) are a smooth pattern with ±2 grey levels of noise, about as compressible as a camera or rendered
    frame; ``random_images`` makes them uniform noise (incompressible: the recorder's worst case). Other
    arrays get random values; strings matching a ``left|right`` pattern get ``"left"``. Raises ``KeyError``
    for an unknown topic and ``TypeError`` for a field kind it cannot fill.
    """
    cls = T.BY_NAME[topic_name].type
    shapes = {field: shape for (owner, field), shape in SHAPES.items() if owner == cls.__name__}
    kw = sample_fields(cls, seed, shapes=shapes, image=lambda shape, rng: _image(shape, rng, random_images))
    if cls.__name__ == "ArmTarget" or cls.__name__ == "ArmJointState":
        kw["arm"] = "right" if "right" in topic_name else "left"
    return kw


# ------------------------------------------------------------------------------------------------ children
def _make_publisher(group: str, factor: float, random_images: bool = False):
    class LoadPublisher(Node):
        """Publishes the topics of one producing node at ``factor`` × nominal rate (bench only)."""

        async def setup(self) -> None:
            for name in GROUPS[group]:
                topic = T.BY_NAME[name]
                pub = self.publisher(topic)
                fields = payload_fields(name, random_images=random_images)
                if topic.latched or topic.nominal_hz <= 0:
                    pub.publish(topic.type(header=pub.header("display"), **fields))
                    continue
                self.timer(1.0 / (factor * topic.nominal_hz), self._sender(pub, topic.type, fields))

        def _sender(self, pub, cls, fields):
            def send() -> None:
                # header stamp = now: the payload arrays are reused (the codec never copies them)
                pub.publish(cls.model_construct(header=pub.header("display"), **fields))
            return send

    return LoadPublisher


def _make_subscriber(out: Path):
    class LoadSubscriber(Node):
        """Subscribes every topic (KEEP_ALL) and keeps receive − stamp per topic (bench only)."""

        async def setup(self) -> None:
            self.lat: dict[str, list[float]] = {t.name: [] for t in T.ALL}
            self.subs = {}
            for t in T.ALL:
                self.subs[t.name] = self.subscribe(t, self._handler(t.name), qos=QoS.KEEP_ALL)
            self.max_queue = 0
            self.timer(0.05, self._watch_queues)

        def _watch_queues(self) -> None:
            self.max_queue = max(self.max_queue, max(len(s.queue) for s in self.subs.values()))

        def _handler(self, name: str):
            lat = self.lat[name]

            def on(msg) -> None:
                lat.append(time.time() - msg.header.stamp)
            return on

        async def teardown(self) -> None:
            res = {"latency": {k: v for k, v in self.lat.items()},
                   "received": {k: s.stats.count for k, s in self.subs.items()},
                   "dropped": {k: s.stats.dropped for k, s in self.subs.items()},
                   "max_queue": self.max_queue}
            out.write_text(json.dumps(res))

    return LoadSubscriber


def _child(argv: list[str]) -> int:
    """Entry of a child process: ``--role pub|sub|rec``."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--role", required=True)
    ap.add_argument("--group", default="")
    ap.add_argument("--endpoint", default="")
    ap.add_argument("--peers", nargs="*", default=[])
    ap.add_argument("--factor", type=float, default=2.0)
    ap.add_argument("--out", default="")
    ap.add_argument("--random-images", action="store_true")
    a = ap.parse_args(argv)

    if a.role == "pub":
        cls = _make_publisher(a.group, a.factor, a.random_images)
        node = cls(NodeConfig(name=a.group, node_type="load_pub", endpoint=a.endpoint, peers=[]))
    elif a.role == "sub":
        cls = _make_subscriber(Path(a.out))
        node = cls(NodeConfig(name="load_sub", node_type="load_sub", endpoint=a.endpoint, peers=a.peers))
    else:
        node = RecorderNode(NodeConfig(name="recorder", node_type="recorder", endpoint=a.endpoint,
                                       peers=a.peers,
                                       params={"output": a.out, "topics": RECORDED}))
    asyncio.run(node.run())
    return 0


# ------------------------------------------------------------------------------------------------ parent
def rss_mb(pid: int) -> float | None:
    """Resident set size of process ``pid`` in MB (``VmRSS`` of ``/proc/<pid>/status``); None if gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except (FileNotFoundError, ProcessLookupError):
        return None
    return None


def slope_mb_per_min(t: np.ndarray, rss: np.ndarray) -> float:
    """Least-squares slope of RSS (MB) over time (s), in MB/min. Needs ≥ 3 samples (else ``ValueError``)."""
    t, rss = np.asarray(t, float), np.asarray(rss, float)
    if t.size < 3:
        raise ValueError(f"need >= 3 RSS samples for a slope, got {t.size}")
    return float(np.polyfit(t, rss, 1)[0] * 60.0)


def run_load(seconds: float = 60.0, factor: float = 2.0, warmup: float = 10.0, sample: float = 0.5,
             random_images: bool = False) -> dict:
    """Run the load (see module doc) for ``seconds`` s; returns the results dict. ``warmup`` s are left out
    of the RSS slope fit (imports, first allocations, socket buffers filling)."""
    if not seconds > warmup:
        raise ValueError(f"seconds ({seconds}) must exceed warmup ({warmup})")
    tmp = Path(tempfile.mkdtemp(prefix="flexsheet_load_"))
    base = free_port(span=len(GROUPS) + 2)     # below the ephemeral range: subscribers connect before binds
    ports = list(range(base, base + len(GROUPS) + 2))
    eps = {g: f"tcp://127.0.0.1:{p}" for g, p in zip(GROUPS, ports, strict=False)}
    py = [sys.executable, "-m", "flexsheet.benches.load", "--child"]
    procs: dict[str, subprocess.Popen] = {}
    sub_out = tmp / "sub.json"
    peers = list(eps.values())
    env = dict(os.environ, FLEXSHEET_LOG="WARNING")
    try:
        procs["subscriber"] = subprocess.Popen([*py, "--role", "sub", "--endpoint", f"tcp://127.0.0.1:{ports[-2]}",
                                                "--peers", *peers, "--out", str(sub_out)], env=env)
        procs["recorder"] = subprocess.Popen([*py, "--role", "rec", "--endpoint", f"tcp://127.0.0.1:{ports[-1]}",
                                              "--peers", *peers, "--out", str(tmp / "load.mcap")], env=env)
        time.sleep(1.0)   # subscribers first: they connect and reconnect until the publishers bind
        for g, ep in eps.items():
            procs[g] = subprocess.Popen([*py, "--role", "pub", "--group", g, "--endpoint", ep,
                                         "--factor", str(factor)]
                                        + (["--random-images"] if random_images else []),
                                        env=env)
        t0 = time.monotonic()
        samples: dict[str, list[tuple[float, float]]] = {k: [] for k in procs}
        while (now := time.monotonic() - t0) < seconds:
            for k, p in procs.items():
                if p.poll() is not None:
                    raise RuntimeError(f"load process {k} exited with code {p.returncode}")
                r = rss_mb(p.pid)
                if r is not None:
                    samples[k].append((now, r))
            time.sleep(sample)
        # stop the publishers first, then the subscriber and the recorder (they write their results)
        for k in [*GROUPS, "subscriber", "recorder"]:
            procs[k].send_signal(2)
            procs[k].wait(timeout=30)
            if k == "world":
                time.sleep(0.5)
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait()
    sub = json.loads(sub_out.read_text())

    bag = bag_info(tmp / "load.mcap")
    procs_res = {}
    for k, s in samples.items():
        a = np.array(s)
        keep = a[:, 0] >= warmup
        procs_res[k] = {"peak_rss_mb": float(a[:, 1].max()), "rss_after_warmup_mb": float(a[keep, 1][0]),
                        "rss_end_mb": float(a[-1, 1]),
                        "slope_mb_per_min": slope_mb_per_min(a[keep, 0], a[keep, 1]),
                        "t": a[:, 0].tolist(), "rss": a[:, 1].tolist()}
    all_lat = np.concatenate([np.asarray(v, float) for v in sub["latency"].values() if v]) * 1e3
    topics = {}
    for t in T.ALL:
        lat = np.asarray(sub["latency"][t.name], float) * 1e3
        topics[t.name] = {"rate_hz": factor * t.nominal_hz, "received": sub["received"][t.name],
                          "dropped": sub["dropped"][t.name], "recorded": bag.counts.get(t.name, 0),
                          "p50_ms": float(np.percentile(lat, 50)) if lat.size else None,
                          "p99_ms": float(np.percentile(lat, 99)) if lat.size else None}
    import shutil

    shutil.rmtree(tmp, ignore_errors=True)
    return {"seconds": seconds, "factor": factor, "warmup": warmup, "cpus": os.cpu_count(),
            "random_images": random_images,
            "p50_ms": float(np.percentile(all_lat, 50)), "p99_ms": float(np.percentile(all_lat, 99)),
            "messages": int(all_lat.size),
            "max_slope_mb_per_min": max(p["slope_mb_per_min"] for p in procs_res.values()),
            "subscriber_max_queue": sub["max_queue"], "recorder_dropped": dict(bag.dropped),
            "processes": procs_res, "topics": topics}


def _chart(res: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5))
    for k, p in res["processes"].items():
        a.plot(p["t"], p["rss"], label=f"{k} ({p['slope_mb_per_min']:+.2f} MB/min)")
    a.axvline(res["warmup"], color="k", ls=":", lw=0.8)
    a.set(xlabel="time, s", ylabel="RSS, MB", title=f"memory at {res['factor']:g}× nominal rates (fit after "
                                                    "the dotted line)")
    a.legend(fontsize=7)
    names = [n for n, t in res["topics"].items() if t["p99_ms"] is not None]
    x = np.arange(len(names))
    b.bar(x - 0.2, [res["topics"][n]["p50_ms"] for n in names], 0.4, label="p50")
    b.bar(x + 0.2, [res["topics"][n]["p99_ms"] for n in names], 0.4, label="p99")
    b.set_xticks(x, names, rotation=60, ha="right", fontsize=7)
    b.set(ylabel="publish → subscriber handler, ms", yscale="log",
          title=f"latency: all messages p99 {res['p99_ms']:.1f} ms")
    b.legend()
    fig.tight_layout()
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "load.png", dpi=110)
    plt.close(fig)
    (out / "load.json").write_text(json.dumps(res, indent=1))


def main(argv: list[str]) -> int:
    """``flexsheet bench load [--seconds S] [--factor F] [--json] [--out DIR]`` (see module doc)."""
    ap = argparse.ArgumentParser(prog="flexsheet bench load", description=__doc__.splitlines()[0],
                                 epilog="example:\n  flexsheet bench load --seconds 60 --out "
                                        "docs/figures/reliability",
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0, help="load duration, s (default 60)")
    ap.add_argument("--factor", type=float, default=2.0, help="rate factor over nominal_hz (default 2)")
    ap.add_argument("--warmup", type=float, default=None, help="s left out of the RSS fit (default min(10, "
                                                               "S/4))")
    ap.add_argument("--random-images", action="store_true",
                    help="incompressible noise images (the recorder's worst case) instead of image-like ones")
    ap.add_argument("--json", action="store_true", help="print the results as JSON")
    ap.add_argument("--out", help="write load.png and load.json here")
    a = ap.parse_args(argv)
    if not (a.seconds > 0 and a.factor > 0):
        ap.error(f"--seconds and --factor must be > 0, got {a.seconds}, {a.factor}")
    warmup = a.warmup if a.warmup is not None else min(10.0, a.seconds / 4)
    res = run_load(a.seconds, a.factor, warmup, random_images=a.random_images)
    if a.out:
        _chart(res, Path(a.out))
    if a.json:
        print(json.dumps({k: v for k, v in res.items() if k != "processes"} |
                         {"processes": {k: {kk: vv for kk, vv in p.items() if kk not in ("t", "rss")}
                                        for k, p in res["processes"].items()}}, indent=1))
        return 0
    print(f"load: {a.factor:g}x nominal rates for {a.seconds:g} s on {res['cpus']} CPUs "
          f"({res['messages']} messages timed)")
    print(f"{'topic':<24}{'Hz':>7}{'recv':>8}{'drop':>6}{'bag':>7}{'p50 ms':>9}{'p99 ms':>9}")
    for n, t in res["topics"].items():
        p50 = f"{t['p50_ms']:.2f}" if t["p50_ms"] is not None else "-"
        p99 = f"{t['p99_ms']:.2f}" if t["p99_ms"] is not None else "-"
        print(f"{n:<24}{t['rate_hz']:7.0f}{t['received']:8d}{t['dropped']:6d}{t['recorded']:7d}{p50:>9}{p99:>9}")
    print(f"{'process':<14}{'peak RSS MB':>12}{'slope MB/min':>14}")
    for k, p in res["processes"].items():
        print(f"{k:<14}{p['peak_rss_mb']:12.1f}{p['slope_mb_per_min']:14.2f}")
    print(f"all messages: p50 {res['p50_ms']:.2f} ms, p99 {res['p99_ms']:.2f} ms; largest RSS slope "
          f"{res['max_slope_mb_per_min']:+.2f} MB/min; subscriber queue max {res['subscriber_max_queue']}")
    return 0


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        sys.exit(_child(sys.argv[2:]))
    sys.exit(main(sys.argv[1:]))
