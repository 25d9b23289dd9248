"""``flexsheet bench transport``: the runtime against raw pyzmq + msgpack, between two processes, same run.

Measures, for both stacks:

* one-way latency (median, p99) of a small message — a :class:`messages.Fingertip` (≈ 230 B on the wire) for
  the runtime, the same fields packed as a msgpack map for raw — sent at 1 kHz so that queueing does not mix
  in, both publishers sleeping between messages (a busy-waiting publisher keeps its core awake and would
  measure CPU wake-up, not the stack); latency is ``time.monotonic()`` at the subscriber's handler minus the
  stamp taken just before publishing (CLOCK_MONOTONIC is shared by all processes of one machine);
* throughput of 2×640×480 uint8 stereo frames (:class:`messages.StereoFrame` vs a raw multipart of the two
  buffers), sent as fast as the publisher can, counted at the subscriber;
* intra-container latency (``composed_*``): the same small message between two nodes of one composable
  container (:mod:`flexsheet.runtime.container`: one process, one loop, the message object handed on), from
  the call to ``publish`` to an ``async def`` handler (``composed_latency_*``) and to a plain ``def`` handler
  in its worker thread (``composed_sync_latency_*``); ``composed_build_latency_median_us`` also counts
  building the message (pydantic validation of a Fingertip), as the cross-process figures do.

The cross-process subscriber runs in a child process (``python -m flexsheet.benches.transport --sink …``)
and reports JSON. Figures taken on a shared machine are pessimistic: run it at least twice and compare ranges
(``chrt -f 10 flexsheet bench transport`` as root keeps other load from mixing in).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import time

import msgpack
import numpy as np
import zmq

from flexsheet.runtime.bus import Bus, ContainerTransport
from flexsheet.runtime.codec import decode, encode
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.node import Node
from flexsheet.runtime.ports import free_port
from flexsheet.runtime.qos import QoS
from messages import Fingertip, Header, StereoFrame
from messages import topics as T

N_LAT = 3000
N_FRAMES = 1500
W, H = 640, 480


# ------------------------------------------------------------------------------------------ sinks (child)
def _raw_sink(endpoint: str, kind: str, n: int) -> dict:
    ctx = zmq.Context()
    sub = ctx.socket(zmq.SUB)
    sub.setsockopt(zmq.RCVHWM, 100000)
    sub.connect(endpoint)
    sub.setsockopt(zmq.SUBSCRIBE, b"")
    print("ready", flush=True)
    lat, got, t_first, t_last = [], 0, 0.0, 0.0
    while got < n:
        if not sub.poll(5000):
            break
        if kind == "lat":
            frames = sub.recv_multipart()
            d = msgpack.unpackb(frames[1])
            lat.append(time.monotonic() - d["sent"])
        else:
            frames = sub.recv_multipart(copy=False)
            left = np.frombuffer(frames[2].buffer, np.uint8).reshape(H, W)
            right = np.frombuffer(frames[3].buffer, np.uint8).reshape(H, W)
            assert left.shape == right.shape
            t_last = time.monotonic()
            if got == 0:
                t_first = t_last
        got += 1
    sub.close(0)
    ctx.term()
    return {"lat": lat, "got": got, "t_first": t_first, "t_last": t_last}


class _Sink(Node):
    async def setup(self) -> None:
        self.lat: list[float] = []
        self.got, self.t_first, self.t_last = 0, 0.0, 0.0
        if self.params_kind == "lat":
            self.subscribe(T.FINGERTIP, self.on_tip, qos=QoS.KEEP_ALL)
        else:
            self.subscribe(T.STEREO, self.on_frame, qos=QoS.KEEP_ALL)
        print("ready", flush=True)

    async def on_tip(self, msg: Fingertip) -> None:
        self.lat.append(time.monotonic() - msg.exposure_stamp)
        self.got += 1
        if self.got >= self.n:
            self.shutdown()

    async def on_frame(self, msg: StereoFrame) -> None:
        self.t_last = time.monotonic()
        if self.got == 0:
            self.t_first = self.t_last
        self.got += 1
        if self.got >= self.n:
            self.shutdown()


def _node_sink(endpoint: str, kind: str, n: int) -> dict:
    node = _Sink(NodeConfig(name="bench_sink", endpoint="", peers=[endpoint], heartbeat_period=10.0))
    node.params_kind, node.n = kind, n

    async def main() -> None:
        asyncio.get_running_loop().call_later(60.0, node.shutdown)
        await node.run(install_signals=False)

    asyncio.run(main())
    return {"lat": node.lat, "got": node.got, "t_first": node.t_first, "t_last": node.t_last}


# ------------------------------------------------------------------------------------------ sources
def _start_sink(stack: str, kind: str, endpoint: str, n: int) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, "-m", "flexsheet.benches.transport", "--sink", stack, kind,
                          endpoint, str(n)],
                         stdout=subprocess.PIPE, text=True)
    assert p.stdout is not None
    line = p.stdout.readline()
    if line.strip() != "ready":
        raise RuntimeError(f"bench sink did not start: {line!r}")
    time.sleep(0.3)  # let the SUB connect and subscribe (a benchmark, not a node: no latched handshake)
    return p


def _finish(p: subprocess.Popen) -> dict:
    out, _ = p.communicate(timeout=120)
    return json.loads(out.strip().splitlines()[-1])


def _raw_source(kind: str, n: int) -> dict:
    port = free_port()
    endpoint = f"tcp://127.0.0.1:{port}"
    ctx = zmq.Context()
    pub = ctx.socket(zmq.PUB)
    pub.setsockopt(zmq.SNDHWM, 2000)
    pub.bind(endpoint)
    p = _start_sink("raw", kind, endpoint, n)
    pos, cov = np.zeros(3), np.eye(3)
    left = np.random.default_rng(0).integers(0, 255, (H, W), dtype=np.uint8)
    right = left.copy()
    t0 = time.monotonic()
    for i in range(n + 200):
        if kind == "lat":
            d = {"stamp": time.time(), "frame_id": "display", "seq": i, "position": pos.tobytes(),
                 "covariance": cov.tobytes(), "valid": True, "sent": time.monotonic()}
            pub.send_multipart([b"/fingertip", msgpack.packb(d)])
            delay = t0 + (i + 1) / 1000.0 - time.monotonic()
            if delay > 0:
                time.sleep(delay)   # paced like the runtime's publisher (which sleeps in its event loop)
        else:
            meta = msgpack.packb({"stamp": time.time(), "seq": i, "shape": [H, W]})
            pub.send_multipart([b"/camera/stereo", meta, left, right], copy=False)
        if p.poll() is not None:
            break
    res = _finish(p)
    pub.close(0)
    ctx.term()
    return res


class _Source(Node):
    async def setup(self) -> None:
        self.tip = self.publisher(T.FINGERTIP)
        self.stereo = self.publisher(T.STEREO)


def _node_source(kind: str, n: int) -> dict:
    port = free_port()
    endpoint = f"tcp://127.0.0.1:{port}"
    node = _Source(NodeConfig(name="bench_source", endpoint=endpoint, peers=[], heartbeat_period=10.0))
    left = np.random.default_rng(0).integers(0, 255, (H, W), dtype=np.uint8)
    right = left.copy()
    result: dict = {}

    async def drive() -> None:
        await asyncio.sleep(0.05)
        loop = asyncio.get_running_loop()
        p = await loop.run_in_executor(None, _start_sink, "node", kind, endpoint, n)
        pos, cov = np.zeros(3), np.eye(3)
        t0 = time.monotonic()
        for i in range(n + 200):
            if kind == "lat":
                now = time.monotonic()
                node.tip.publish(Fingertip(header=node.tip.header("display"), position=pos, covariance=cov,
                                           valid=True, predicted_position=pos, exposure_stamp=now))
                delay = t0 + (i + 1) / 1000.0 - time.monotonic()
                await asyncio.sleep(max(delay, 0.0))
            else:
                now = time.time()
                node.stereo.publish(StereoFrame(header=node.stereo.header("camera_left", now), left=left,
                                                right=right, exposure_stamp=now, exposure_time=0.005))
                if i % 8 == 0:
                    await asyncio.sleep(0)
            if p.poll() is not None:
                break
        result.update(await loop.run_in_executor(None, _finish, p))
        node.shutdown()

    async def main() -> None:
        asyncio.get_running_loop().create_task(drive())
        await node.run(install_signals=False)

    asyncio.run(main())
    return result


class _LocalSink(Node):
    async def setup(self) -> None:
        self.lat: list[tuple[float, float]] = []
        self.t_pub: dict[int, float] = {}
        self.subscribe(T.FINGERTIP, self.on_sync if self.sync else self.on_tip, qos=QoS.KEEP_ALL)

    async def on_tip(self, msg: Fingertip) -> None:
        now = time.monotonic()
        self.lat.append((now - self.t_pub[msg.header.seq], now - msg.exposure_stamp))

    def on_sync(self, msg: Fingertip) -> None:
        now = time.monotonic()
        self.lat.append((now - self.t_pub[msg.header.seq], now - msg.exposure_stamp))


def _composed(n: int, sync: bool) -> list[tuple[float, float]]:
    """(publish → handler, build → handler) latencies (s) of ``n`` fingertips at 1 kHz between two nodes of
    one container (in this process)."""
    async def main() -> list[float]:
        bus = Bus("bench")
        src = _Source(NodeConfig(name="bench_source", endpoint="", heartbeat_period=10.0),
                      transport=ContainerTransport(bus, ""))
        sink = _LocalSink(NodeConfig(name="bench_sink", endpoint="", heartbeat_period=10.0),
                          transport=ContainerTransport(bus, ""))
        sink.sync = sync
        loop = asyncio.get_running_loop()
        tasks = [loop.create_task(x.run(install_signals=False)) for x in (sink, src)]
        while not (src.ready and sink.ready):
            await asyncio.sleep(0.01)
        pos, cov = np.zeros(3), np.eye(3)
        t0 = time.monotonic()
        for i in range(n + 100):
            now = time.monotonic()
            msg = Fingertip(header=src.tip.header("display"), position=pos, covariance=cov, valid=True,
                            predicted_position=pos, exposure_stamp=now)
            sink.t_pub[msg.header.seq] = time.monotonic()
            src.tip.publish(msg)
            delay = t0 + (i + 1) / 1000.0 - time.monotonic()
            await asyncio.sleep(max(delay, 0.0))
        await asyncio.sleep(0.05)
        for x in (src, sink):
            x.shutdown()
        await asyncio.gather(*tasks)
        bus.close()
        return sink.lat

    return asyncio.run(main())


def _summarise(lat_res: dict, thr_res: dict) -> dict:
    lat = np.array(lat_res["lat"][100:]) * 1e6  # drop warm-up
    span = thr_res["t_last"] - thr_res["t_first"]
    fps = (thr_res["got"] - 1) / span if span > 0 else 0.0
    return {"latency_median_us": float(np.median(lat)), "latency_p99_us": float(np.percentile(lat, 99)),
            "latency_samples": int(lat.size), "stereo_fps": fps, "stereo_frames": int(thr_res["got"])}


def _codec_costs(n: int = 20000) -> dict:
    """What validating a small message costs in this process, µs a message (median of 5 batches of
    ``n // 5``): building a :class:`messages.Fingertip` (pydantic validation), encoding it and decoding it
    with validation (the wire boundary). The runtime pays all three on every hop that crosses processes; raw
    pyzmq none."""
    pos, cov = np.zeros(3), np.eye(3)

    def build() -> Fingertip:
        return Fingertip(header=Header(stamp=1.0, frame_id="display", seq=1), position=pos, covariance=cov,
                         valid=True, predicted_position=pos, exposure_stamp=1.0)

    msg = build()
    frames = encode(T.FINGERTIP.name, msg)
    out = {}
    for name, fn in (("build", build), ("encode", lambda: encode(T.FINGERTIP.name, msg)),
                     ("decode", lambda: decode(frames, T.FINGERTIP))):
        batches = []
        for _ in range(5):
            t0 = time.perf_counter()
            for _ in range(n // 5):
                fn()
            batches.append((time.perf_counter() - t0) / (n // 5) * 1e6)
        out[f"codec_{name}_us"] = float(np.median(batches))
    return out


def run_bench(n_lat: int = N_LAT, n_frames: int = N_FRAMES) -> dict:
    """Run both stacks and the intra-container case; returns a flat dict of figures with ``ratio`` keys
    (runtime / raw), ``composed_latency_median_us`` (and ``_p99_us``, ``composed_sync_*``), the validation's
    own cost (``codec_*_us``) and the ratio it alone sets as a floor (``floor_ratio_latency_median``: raw's
    median plus build, encode and decode, over raw's median), and the machine's load (``loadavg_1_before``,
    ``loadavg_1_after``, ``cores``): figures taken beside other work are not comparable."""
    load0 = os.getloadavg()[0]
    raw = _summarise(_raw_source("lat", n_lat), _raw_source("thr", n_frames))
    ours = _summarise(_node_source("lat", n_lat), _node_source("thr", n_frames))
    out = {f"runtime_{k}": v for k, v in ours.items()} | {f"raw_{k}": v for k, v in raw.items()}
    out["ratio_latency_median"] = ours["latency_median_us"] / raw["latency_median_us"]
    out["ratio_latency_p99"] = ours["latency_p99_us"] / raw["latency_p99_us"]
    out["ratio_stereo_fps"] = ours["stereo_fps"] / raw["stereo_fps"] if raw["stereo_fps"] else 0.0
    for key, sync in (("composed", False), ("composed_sync", True)):
        lat = np.array(_composed(n_lat, sync)[100:]) * 1e6
        out[f"{key}_latency_median_us"] = float(np.median(lat[:, 0]))
        out[f"{key}_latency_p99_us"] = float(np.percentile(lat[:, 0], 99))
        out[f"{key}_build_latency_median_us"] = float(np.median(lat[:, 1]))
        out[f"{key}_latency_samples"] = int(len(lat))
    out |= _codec_costs()
    out["floor_ratio_latency_median"] = (raw["latency_median_us"] + out["codec_build_us"]
                                         + out["codec_encode_us"]
                                         + out["codec_decode_us"]) / raw["latency_median_us"]
    out |= {"loadavg_1_before": load0, "loadavg_1_after": os.getloadavg()[0], "cores": os.cpu_count()}
    return out


def main(argv: list[str] | None = None) -> int:
    """``flexsheet bench transport [--json] [--messages N] [--frames N]``."""
    ap = argparse.ArgumentParser(prog="flexsheet bench transport", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example:\n  flexsheet bench transport --json")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--messages", type=int, default=N_LAT, help="small messages for latency (at 1 kHz)")
    ap.add_argument("--frames", type=int, default=N_FRAMES, help="stereo frames for throughput")
    ap.add_argument("--sink", nargs=4, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.sink:
        stack, kind, endpoint, n = args.sink
        res = (_raw_sink if stack == "raw" else _node_sink)(endpoint, kind, int(n))
        print(json.dumps(res))
        return 0
    r = run_bench(args.messages, args.frames)
    if args.json:
        print(json.dumps(r))
        return 0
    print(f"{'':28}{'runtime':>12}{'raw pyzmq':>12}{'ratio':>8}")
    print(f"{'small msg latency median':28}{r['runtime_latency_median_us']:10.1f}us"
          f"{r['raw_latency_median_us']:10.1f}us{r['ratio_latency_median']:8.2f}")
    print(f"{'small msg latency p99':28}{r['runtime_latency_p99_us']:10.1f}us{r['raw_latency_p99_us']:10.1f}"
          f"us{r['ratio_latency_p99']:8.2f}")
    print(f"{'stereo 2x640x480 u8':28}{r['runtime_stereo_fps']:9.0f}f/s{r['raw_stereo_fps']:9.0f}f/s"
          f"{r['ratio_stereo_fps']:8.2f}")
    print(f"{'validation alone (floor)':28}build {r['codec_build_us']:.1f} + encode "
          f"{r['codec_encode_us']:.1f} + decode {r['codec_decode_us']:.1f} us: ratio >= "
          f"{r['floor_ratio_latency_median']:.2f} (load {r['loadavg_1_before']:.2f})")
    for key, label in (("composed", "in one container, async"), ("composed_sync", "in one container, def")):
        print(f"{label:28}{r[key + '_latency_median_us']:10.1f}us median {r[key + '_latency_p99_us']:8.1f}us "
              f"p99 (with building the message: {r[key + '_build_latency_median_us']:.1f}us median)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
