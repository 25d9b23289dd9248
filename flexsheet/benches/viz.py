"""``flexsheet bench viz``: CPU of the viz bridge in the running simulation, per viewer subscription set.

Starts ``launch/sim_composed.yaml`` (the simulated display as processes on the wall clock; or ``--launch``, a
wall-clock launch file: on ``clock: sim`` every node shares one process) with a viz node added in a process of
its own on a free port, waits for the stroke to run, then measures the viz process's CPU (utime + stime from
``/proc/<pid>/stat``, all its threads: Python, ZeroMQ I/O, the SDK's tokio workers) over windows of
``--window`` s: no viewer; a viewer with the shipped layout's channels (3-D scene, frames, metrics, images); a
viewer on every channel; and no viewer again (inputs stay subscribed: the transport has no unsubscribe). The
viewer is
:class:`flexsheet.viz.wsclient.FoxgloveClient`. ``--runs N`` launches the sim N times; ``OUT/viz_cpu.json``
holds every run and, per window, the median and min/max of the CPU (% of one core); ``OUT/viz_cpu.png`` draws
them, beside an earlier run's (``--baseline FILE``) when given. ``--param KEY=VALUE`` sets a viz parameter.
The machine's load shows in the numbers (the load average is recorded per run): compare runs taken under
similar load, or interleave them.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from flexsheet.dirs import launch_dir
from flexsheet.runtime.ports import free_port
from flexsheet.viz.foxglove import (
    CAMERA_LEFT,
    CAMERA_LEFT_INFO,
    CAMERA_RIGHT,
    CAMERA_RIGHT_INFO,
    METRICS,
    RENDER_IMAGE,
    SCENE,
    TF,
)
from flexsheet.viz.wsclient import FoxgloveClient

__all__ = ["main", "WINDOWS"]

LAYOUT_CHANNELS = [SCENE, TF, METRICS, CAMERA_LEFT, CAMERA_RIGHT, RENDER_IMAGE, CAMERA_LEFT_INFO,
                   CAMERA_RIGHT_INFO]
#: window name -> channels the viewer subscribes (None: every advertised channel; []: no viewer)
WINDOWS = {"no viewer": [], "layout viewer": LAYOUT_CHANNELS, "all channels": None, "no viewer, after": []}
_TICK = os.sysconf("SC_CLK_TCK")


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


def _one_run(lf: dict, params: dict, args, out: Path, label: str) -> dict:
    """Launch the sim once with the viz node on a free port and measure every window; returns window ->
    numbers."""
    port = free_port()
    host = next(iter(lf["hosts"]))
    lf = dict(lf, nodes={**{k: v for k, v in lf["nodes"].items() if v.get("type") != "viz"},
                         "viz": {"type": "viz", "host": host, "nice": 10,
                                 "params": {**params, "port": port}}})
    with tempfile.TemporaryDirectory() as tmp:
        launch = Path(tmp) / "bench_viz.yaml"
        launch.write_text(yaml.safe_dump(lf, sort_keys=False))
        duration = args.warmup + len(WINDOWS) * (args.window + 3.0) + 5.0
        with open(out / f"sim{label}.log", "w") as log:
            # run where launch/ is (the launch file's relative paths); the run's output beside the figures
            sim = subprocess.Popen([sys.executable, "-m", "flexsheet", "launch", str(launch), "--duration",
                                    str(duration), "--out", str(out.resolve() / f"sim{label}")],
                                   cwd=launch_dir().parent, stdout=log, stderr=subprocess.STDOUT)
        try:
            pid = _find_viz(launch)
            print(f"[bench viz] run{label}: viz pid {pid}, port {port}; warming up {args.warmup:.0f} "
                  "s", flush=True)
            time.sleep(args.warmup)
            res = {}
            for name, channels in WINDOWS.items():
                res[name] = asyncio.run(_window(pid, port, channels, args.window))
                print(f"[bench viz] {name:<18} {100 * res[name]['cpu_fraction_of_one_core']:5.1f} % of one "
                      f"core, {res[name]['messages_per_s']:6.1f} msg/s to the viewer", flush=True)
        finally:
            sim.terminate()
            sim.wait(timeout=60)
    res["loadavg_1"] = os.getloadavg()[0]
    return res


def stats(runs: list[dict]) -> dict:
    """Per window: median, min and max over ``runs`` of the CPU (% of one core) and of the viewer's msg/s."""
    out = {}
    for name in WINDOWS:
        cpu = [100 * r[name]["cpu_fraction_of_one_core"] for r in runs if name in r]
        msg = [r[name]["messages_per_s"] for r in runs if name in r]
        if cpu:
            out[name] = {"cpu_pct_median": statistics.median(cpu), "cpu_pct_min": min(cpu),
                         "cpu_pct_max": max(cpu),
                         "viewer_msg_per_s_median": statistics.median(msg), "n": len(cpu)}
    return out


def _figure(path: Path, after: dict, before: dict | None, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(WINDOWS)
    fig, ax = plt.subplots(figsize=(7.5, 3.4))
    sets = [("after", after, "tab:blue")] if before is None else [("before", before, "tab:gray"),
                                                                  ("after", after, "tab:blue")]
    h = 0.8 / len(sets)
    for i, (label, st, color) in enumerate(sets):
        y = [k + (i - (len(sets) - 1) / 2) * h for k in range(len(names))]
        med = [st[n]["cpu_pct_median"] if n in st else 0.0 for n in names]
        err = [[m - st[n]["cpu_pct_min"] for m, n in zip(med, names, strict=True)],
               [st[n]["cpu_pct_max"] - m for m, n in zip(med, names, strict=True)]]
        ax.barh(y, med, height=h, xerr=err, color=color, capsize=3,
                label=f"{label}: median, min-max of {st[names[1]]['n']} runs")
        for yy, m, hi in zip(y, med, err[1], strict=True):
            ax.text(m + hi + 0.15, yy, f"{m:.1f}", va="center", fontsize=7)
    ax.set_yticks(range(len(names)), names)
    ax.axvline(5.0, color="tab:red", ls="--", lw=1, label="budget 5 %")
    ax.set_xlabel("viz node CPU, % of one core (all its threads, /proc)")
    ax.set_title(title, fontsize=8)
    ax.invert_yaxis()
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flexsheet bench viz", description=__doc__.splitlines()[0],
                                 epilog="example:\n  flexsheet bench viz --out out/bench_viz --runs 3\n"
                                        "  flexsheet bench viz --out out/bench_viz_10hz --param "
                                        "scene_rate=10 --param input_rate=10 --baseline "
                                        "out/bench_viz/viz_cpu.json",
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--launch", default=str(launch_dir() / "sim_composed.yaml"),
                    help="wall-clock launch file to run (default launch/sim_composed.yaml)")
    ap.add_argument("--window", type=float, default=10.0, help="seconds per measurement window")
    ap.add_argument("--warmup", type=float, default=14.0, help="seconds before the first window")
    ap.add_argument("--runs", type=int, default=1, help="launches of the sim (median and spread over them)")
    ap.add_argument("--out", default="out/bench_viz", help="output folder")
    ap.add_argument("--base-port", type=int, default=0, help="override the launch file's base_port (0: keep)")
    ap.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                    help="viz node parameter (YAML value), repeatable: --param scene_rate=10 --param "
                         "camera_scale=1")
    ap.add_argument("--baseline", help="viz_cpu.json of an earlier run of this bench, drawn beside as "
                                       "'before'")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lf = yaml.safe_load(Path(args.launch).read_text())
    if lf.get("clock") == "sim":
        ap.error(f"{args.launch} runs on clock: sim, every node in one process, so the viz node's CPU cannot "
                 "be told apart: give a wall-clock launch file (default launch/sim_composed.yaml)")
    if args.base_port:
        lf["base_port"] = args.base_port
    params = {}
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep:
            ap.error(f"--param expects KEY=VALUE, got {item!r}")
        params[key] = yaml.safe_load(value)
    runs = [_one_run(lf, params, args, out, f"{i + 1}" if args.runs > 1 else "") for i in range(args.runs)]
    summary = {"stats": stats(runs), "runs": runs, "cpus": os.cpu_count(), "launch": args.launch,
               "viz_params": params,
               "command": " ".join(["flexsheet", "bench", "viz", *(argv or sys.argv[1:])])}
    before = None
    if args.baseline:
        base = json.loads(Path(args.baseline).read_text())
        before = base.get("stats") or stats(base.get("runs", [base.get("windows", {})]))
        summary["baseline"] = {"file": args.baseline, "stats": before, "command": base.get("command"),
                               "runs": base.get("runs", [base.get("windows", {})])}
    (out / "viz_cpu.json").write_text(json.dumps(summary, indent=1))
    loads = ", ".join(f"{r['loadavg_1']:.1f}" for r in runs)
    _figure(out / "viz_cpu.png", summary["stats"], before,
            f"viz bridge in the sim ({os.cpu_count()} CPUs; load average {loads} during the runs)")
    for name, st in summary["stats"].items():
        print(f"[bench viz] {name:<18} median {st['cpu_pct_median']:4.1f} % (min {st['cpu_pct_min']:.1f}, "
              f"max {st['cpu_pct_max']:.1f}) over {st['n']} runs")
    print(f"[bench viz] wrote {out / 'viz_cpu.json'} and {out / 'viz_cpu.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
