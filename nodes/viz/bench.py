"""``flexsheet bench viz``: CPU of the viz bridge in the running simulation, per viewer subscription set.

Starts ``launch/sim.yaml`` (or ``--launch``) with a viz node added on a free port, waits for the stroke to run,
then measures the viz process's CPU (utime + stime from ``/proc/<pid>/stat``, all its threads: Python, ZeroMQ
I/O, the SDK's tokio workers) over windows of ``--window`` s: no viewer; a viewer with the shipped layout's
channels (3-D scene, frames, metrics, images); a viewer on every channel; and no viewer again (inputs stay
subscribed: the transport has no unsubscribe). The viewer is :class:`nodes.viz.wsclient.FoxgloveClient`.
Writes ``OUT/viz_cpu.json`` and ``OUT/viz_cpu.png`` (fraction of one core per window). The machine's load
shows in the numbers: run it on an otherwise idle machine for the figure that matters.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from flexsheet.runtime.foxglove_scene import (
    CAMERA_LEFT,
    CAMERA_LEFT_INFO,
    CAMERA_RIGHT,
    CAMERA_RIGHT_INFO,
    METRICS,
    RENDER_IMAGE,
    SCENE,
    TF,
)

__all__ = ["main", "WINDOWS"]

ROOT = Path(__file__).resolve().parents[2]
LAYOUT_CHANNELS = [SCENE, TF, METRICS, CAMERA_LEFT, CAMERA_RIGHT, RENDER_IMAGE, CAMERA_LEFT_INFO, CAMERA_RIGHT_INFO]
#: window name -> channels the viewer subscribes (None: every advertised channel; []: no viewer)
WINDOWS = {"no viewer": [], "layout viewer": LAYOUT_CHANNELS, "all channels": None, "no viewer, after": []}
_TICK = os.sysconf("SC_CLK_TCK")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cpu_s(pid: int) -> float:
    f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / _TICK


def _find_viz(launch: Path, timeout: float = 60.0) -> int:
    deadline = time.monotonic() + timeout
    key = str(launch).encode()
    while time.monotonic() < deadline:
        for p in Path("/proc").iterdir():
            if not p.name.isdigit():
                continue
            try:
                cmd = (p / "cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if b"run" in cmd and b"viz" in cmd and key in cmd:
                return int(p.name)
        time.sleep(0.2)
    raise RuntimeError(f"the viz node of {launch} did not start within {timeout} s")


async def _window(pid: int, port: int, channels, seconds: float) -> dict:
    from nodes.viz.wsclient import FoxgloveClient

    c = None
    if channels != []:
        c = await FoxgloveClient.open(port)
        await c.wait_channels({SCENE})
        await c.subscribe(sorted(c.channels) if channels is None else channels)
        await asyncio.sleep(1.0)
    n = nbytes = 0
    c0, t0 = _cpu_s(pid), time.monotonic()
    end = t0 + seconds
    while time.monotonic() < end:
        if c is None:
            await asyncio.sleep(0.2)
            continue
        try:
            m = await c.recv(end)
        except TimeoutError:
            break
        if m is not None:
            n, nbytes = n + 1, nbytes + len(m[2])
    dt = time.monotonic() - t0
    out = {"cpu_fraction_of_one_core": (_cpu_s(pid) - c0) / dt, "messages_per_s": n / dt,
           "MB_per_s": nbytes / dt / 1e6, "seconds": dt}
    if c is not None:
        await c.ws.close()
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flexsheet bench viz", description=__doc__.splitlines()[0],
                                 epilog="example:\n  flexsheet bench viz --out out/bench_viz --window 10",
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--launch", default=str(ROOT / "launch" / "sim.yaml"), help="launch file to run")
    ap.add_argument("--window", type=float, default=10.0, help="seconds per measurement window")
    ap.add_argument("--warmup", type=float, default=14.0, help="seconds before the first window")
    ap.add_argument("--out", default="out/bench_viz", help="output folder")
    ap.add_argument("--base-port", type=int, default=0, help="override the launch file's base_port (0: keep)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lf = yaml.safe_load(Path(args.launch).read_text())
    port = _free_port()
    lf["nodes"] = {k: v for k, v in lf["nodes"].items() if v.get("type") != "viz"}
    host = next(iter(lf["hosts"]))
    lf["nodes"]["viz"] = {"type": "viz", "host": host, "nice": 10, "params": {"port": port}}
    if args.base_port:
        lf["base_port"] = args.base_port
    with tempfile.TemporaryDirectory() as tmp:
        launch = Path(tmp) / "bench_viz.yaml"
        launch.write_text(yaml.safe_dump(lf, sort_keys=False))
        duration = args.warmup + len(WINDOWS) * (args.window + 3.0) + 5.0
        sim = subprocess.Popen([sys.executable, "-m", "flexsheet", "launch", str(launch), "--duration", str(duration),
                                "--out", str(out / "sim")], cwd=ROOT, stdout=open(out / "sim.log", "w"),
                               stderr=subprocess.STDOUT)
        try:
            pid = _find_viz(launch)
            print(f"[bench viz] viz pid {pid}, port {port}; warming up {args.warmup:.0f} s", flush=True)
            time.sleep(args.warmup)
            res = {}
            for name, channels in WINDOWS.items():
                res[name] = asyncio.run(_window(pid, port, channels, args.window))
                print(f"[bench viz] {name:<18} {100 * res[name]['cpu_fraction_of_one_core']:5.1f} % of one core, "
                      f"{res[name]['messages_per_s']:6.1f} msg/s to the viewer", flush=True)
        finally:
            sim.terminate()
            sim.wait(timeout=60)
    load = os.getloadavg()
    summary = {"windows": res, "loadavg_1_5_15": load, "cpus": os.cpu_count(), "launch": args.launch}
    (out / "viz_cpu.json").write_text(json.dumps(summary, indent=1))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.2))
    names = list(res)
    ax.barh(names, [100 * res[k]["cpu_fraction_of_one_core"] for k in names], color="tab:blue")
    ax.axvline(5.0, color="tab:red", ls="--", lw=1, label="budget 5 %")
    ax.set_xlabel("viz node CPU (% of one core)")
    ax.set_title(f"viz bridge in the sim (load average {load[0]:.1f} on {os.cpu_count()} CPUs)", fontsize=9)
    ax.invert_yaxis()
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "viz_cpu.png", dpi=120)
    print(f"[bench viz] wrote {out / 'viz_cpu.json'} and {out / 'viz_cpu.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
