"""The hour's soak (``tests/run.sh --soak``; not in CI): does the graph stay up for hours without a leak?

Runs ``launch/lab_sim.yaml`` (the lab's three hosts, CURVE on, moved onto loopback as docs/deploy.md does) on
one machine with the world's script looping (``world.loop=true``), its recorder on, and a viz node added (the
launch file written into ``OUT`` with one more node) to which a Foxglove client stays connected, subscribed to
the scene, the fingertip and the arms, reading everything. Every minute it records each node's resident memory
(psutil, by the pids the launcher reports when it starts each) and whether each node process still lives; at
the end it stops the graph as Ctrl-C does and reads the bag back with the official MCAP reader (``mcap``), and
from the arms' ``/arm/*/joint_state`` stamps computes each minute's arm-cycle jitter (p99 of |interval − the
median interval|).

Targets: no node's resident memory grows more than 10 % after its first 5 minutes; 0 node deaths; the bag
reads back complete (a summary, every recorded topic present, no read error); every minute's jitter p99 within
1.5× that of the first 5 minutes. Writes ``OUT/soak.json`` and ``OUT/soak.png`` (title, units, targets,
verdicts).

    tests/run.sh --soak                                  # 60 min into out/soak
    python3 tests/soak.py --minutes 10 --out /tmp/soak   # a shorter one
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import psutil
import yaml

ROOT = Path(__file__).resolve().parents[1]
HOSTS = ["--set", "hosts.main.address=127.0.0.1", "--set", "hosts.arm1.address=127.0.0.2",
         "--set", "hosts.arm2.address=127.0.0.3"]
ARM_TOPICS = ("/arm/left/joint_state", "/arm/right/joint_state")
WARMUP_MIN = 5                  #: the first minutes: the baseline of memory and jitter
MEMORY_GROWTH = 0.10            #: target: resident memory after the warm-up grows at most this fraction
JITTER_RATIO = 1.5              #: target: each minute's jitter p99 at most this × the warm-up's


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _launch_file(out: Path, port: int) -> Path:
    """launch/lab_sim.yaml plus a viz node on ``port`` (host main), written into ``out``."""
    doc = yaml.safe_load((ROOT / "launch" / "lab_sim.yaml").read_text())
    doc["nodes"]["viz"] = {"type": "viz", "host": "main", "nice": 10, "params": {"port": port}}
    path = out / "lab_sim_soak.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _flexsheet(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flexsheet", *args], cwd=ROOT, capture_output=True,
                          text=True, **kw)


def _node_pids(log: Path, want: set[str], timeout: float) -> dict[str, int]:
    """Node name → pid, from the launcher's ``[name] started pid N`` lines, once every node in ``want``
    started. Raises ``RuntimeError`` naming the missing ones after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    seen: dict[str, int] = {}
    while time.monotonic() < deadline:
        seen = _started(log)
        if want <= set(seen):
            return seen
        time.sleep(2.0)
    raise RuntimeError(f"nodes not started in {timeout:.0f} s: missing {sorted(want - set(seen))}")


def _started(log: Path) -> dict[str, int]:
    """The newest ``[name] started pid N`` of each node in the launcher's log (a restart gives a new pid)."""
    out: dict[str, int] = {}
    for m in re.finditer(r"^\[(\S+)\s*\] started pid (\d+)$", log.read_text(errors="replace"), re.M):
        out[m.group(1)] = int(m.group(2))
    return out


class Viewer(threading.Thread):
    """A Foxglove client that stays connected and reads everything (flexsheet.viz.wsclient), counting
    frames."""

    def __init__(self, port: int) -> None:
        super().__init__(daemon=True)
        self.port, self.frames, self.error, self.stop = port, 0, None, threading.Event()

    def run(self) -> None:
        from flexsheet.viz.wsclient import FoxgloveClient

        async def main() -> None:
            deadline = time.monotonic() + 120.0
            while True:
                try:
                    c = await FoxgloveClient.open(self.port)
                    break
                except OSError:
                    if time.monotonic() > deadline:
                        raise
                    await asyncio.sleep(1.0)
            await c.wait_channels({"/viz/scene", "/fingertip"}, timeout=60.0)
            await c.subscribe([t for t in ("/viz/scene", "/viz/tf", "/fingertip", *ARM_TOPICS)
                               if t in c.channels])
            while not self.stop.is_set():
                try:
                    m = await c._recv(time.monotonic() + 5.0)
                except TimeoutError:
                    continue
                self.frames += m is not None
            await c.ws.close()

        try:
            asyncio.run(main())
        except Exception as exc:  # noqa: BLE001 - reported in the result, never raised from the thread
            self.error = f"{type(exc).__name__}: {exc}"


def _bag(path: Path) -> tuple[dict, dict[str, list[float]]]:
    """Read the bag with the official MCAP reader: (its summary as counts, the arms' joint-state stamps)."""
    from mcap.reader import make_reader

    counts: dict[str, int] = {}
    stamps: dict[str, list[float]] = {t: [] for t in ARM_TOPICS}
    err = None
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        try:
            for _, ch, msg in reader.iter_messages():
                counts[ch.topic] = counts.get(ch.topic, 0) + 1
                if ch.topic in stamps:
                    stamps[ch.topic].append(float(json.loads(msg.data)["header"]["stamp"]))
        except Exception as exc:  # noqa: BLE001 - a read error is the finding
            err = f"{type(exc).__name__}: {exc}"
    stats = summary.statistics if summary else None
    info = {"summary": summary is not None, "read_error": err, "messages": int(sum(counts.values())),
            "summary_message_count": int(stats.message_count) if stats else None, "topics": counts}
    return info, stamps


def _jitter_by_minute(stamps: dict[str, list[float]], t0: float, minutes: int) -> list[float | None]:
    """Each minute's p99 of |interval − median interval| over both arms, ms (None: no samples)."""
    out: list[float | None] = []
    for k in range(minutes):
        devs = []
        for s in stamps.values():
            a = np.sort(np.asarray(s))
            a = a[(a >= t0 + 60 * k) & (a < t0 + 60 * (k + 1))]
            if len(a) > 10:
                iv = np.diff(a)
                devs.append(np.abs(iv - np.median(iv)))
        out.append(float(np.percentile(np.concatenate(devs), 99) * 1e3) if devs else None)
    return out


def _chart(res: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.5))
    for name, rss in res["rss_mb"].items():
        ax[0].plot(range(1, len(rss) + 1), rss, label=name)
    ax[0].axvline(WARMUP_MIN, color="grey", ls=":")
    ax[0].set(xlabel="minute", ylabel="resident memory (MB)",
              title=f"memory: growth after min {WARMUP_MIN} ≤ {MEMORY_GROWTH:.0%}: "
                    f"{res['verdicts']['memory']}")
    ax[0].legend(fontsize=7, ncol=2)
    j = [np.nan if v is None else v for v in res["jitter_p99_ms"]]
    ax[1].plot(range(1, len(j) + 1), j, "o-")
    if res["jitter_baseline_ms"]:
        ax[1].axhline(res["jitter_baseline_ms"] * JITTER_RATIO, color="r", ls="--",
                      label=f"target {JITTER_RATIO}× warm-up")
        ax[1].legend()
    ax[1].set(xlabel="minute", ylabel="arm cycle jitter p99 (ms)",
              title=f"arm cycle jitter: {res['verdicts']['jitter']}")
    fig.suptitle(f"soak: launch/lab_sim.yaml, {res['minutes']} min, viewer + recorder "
                 f"(deaths {res['deaths']}: {res['verdicts']['deaths']}; bag: {res['verdicts']['bag']})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="tests/soak.py", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example:\n  python3 tests/soak.py --minutes 10 --out /tmp/soak")
    ap.add_argument("--minutes", type=int, default=60, help="how long the graph runs (default 60)")
    ap.add_argument("--out", default="out/soak", help="folder of the bag, soak.json and soak.png (default "
                                                      "out/soak)")
    args = ap.parse_args(argv)
    if args.minutes <= WARMUP_MIN:
        ap.error(f"--minutes must exceed the {WARMUP_MIN}-minute warm-up, got {args.minutes}")
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    port = _free_port()
    launch = _launch_file(out, port)
    keys = out / "keys"                 # CURVE keys of the launch file with its viz node, as in the lab
    r = _flexsheet("keys", "generate", "--launch", str(launch), "-o", str(keys))
    if r.returncode:
        sys.exit(f"[soak] flexsheet keys generate failed:\n{r.stderr}")
    os.environ["FLEXSHEET_KEYS"] = str(keys)
    nodes = set(yaml.safe_load(launch.read_text())["nodes"])
    log = open(out / "launch.log", "w")
    proc = subprocess.Popen([sys.executable, "-m", "flexsheet", "launch", str(launch), *HOSTS, "--set",
                             "world.loop=true", "--out", str(out / "run")], cwd=ROOT, stdout=log,
                            stderr=subprocess.STDOUT, start_new_session=True)
    print(f"[soak] graph started (pid {proc.pid}); log {out / 'launch.log'}", flush=True)
    res: dict = {"minutes": args.minutes, "launch": "launch/lab_sim.yaml + viz", "cores": os.cpu_count()}
    try:
        pids = _node_pids(out / "launch.log", nodes, timeout=180.0)
        procs = {n: psutil.Process(p) for n, p in pids.items()}
        viewer = Viewer(port)
        viewer.start()
        rss: dict[str, list[float]] = {n: [] for n in procs}
        dead: dict[str, int] = {}
        t_start = time.time()
        for minute in range(1, args.minutes + 1):
            time.sleep(max(0.0, t_start + 60 * minute - time.time()))
            for n, p in procs.items():
                try:
                    alive = p.is_running() and p.status() != psutil.STATUS_ZOMBIE
                    rss[n].append(p.memory_info().rss / 1e6 if alive else float("nan"))
                except psutil.NoSuchProcess:
                    alive = False
                    rss[n].append(float("nan"))
                if not alive and n not in dead:
                    dead[n] = minute
            for n, pid in _started(out / "launch.log").items():     # a node restarted by the launcher died
                if n in pids and pid != pids[n] and n not in dead:
                    dead[n] = minute
            if proc.poll() is not None:
                raise RuntimeError(f"the launch ended at minute {minute} (exit {proc.returncode})")
            top = max(rss, key=lambda k: rss[k][-1] if rss[k][-1] == rss[k][-1] else 0)
            print(f"[soak] minute {minute}/{args.minutes}: {len(procs) - len(dead)}/{len(procs)} nodes "
                  f"alive, largest {top} {rss[top][-1]:.0f} MB, viewer frames {viewer.frames}", flush=True)
        viewer.stop.set()
        viewer.join(timeout=15)
        res.update(t0=t_start, nodes=sorted(procs), rss_mb=rss, deaths=len(dead), died=dead,
                   viewer={"frames": viewer.frames, "error": viewer.error})
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
        log.close()
    bags = sorted((out / "run").glob("*.mcap"))
    if not bags:
        sys.exit(f"[soak] no bag in {out / 'run'}")
    res["bag"], stamps = _bag(bags[0])
    res["bag"]["file"] = bags[0].name
    growth = {}
    for n, series in res["rss_mb"].items():
        a = np.asarray(series, dtype=float)
        base = np.nanmax(a[:WARMUP_MIN]) if np.isfinite(a[:WARMUP_MIN]).any() else np.nan
        growth[n] = float(np.nanmax(a[WARMUP_MIN:]) / base - 1.0) if np.isfinite(base) else None
    res["rss_growth_after_warmup"] = growth
    jit = _jitter_by_minute(stamps, min((s[0] for s in stamps.values() if s), default=res["t0"]),
                            args.minutes)
    base = [v for v in jit[:WARMUP_MIN] if v is not None]
    res["jitter_p99_ms"], res["jitter_baseline_ms"] = jit, (float(np.median(base)) if base else None)
    worst = max((g for g in growth.values() if g is not None), default=None)
    b = res["bag"]
    res["verdicts"] = {
        "memory": "met" if worst is not None and worst <= MEMORY_GROWTH else "MISSED",
        "deaths": "met" if res["deaths"] == 0 else "MISSED",
        "bag": "met" if b["summary"] and b["read_error"] is None and all(t in b["topics"] for t in ARM_TOPICS)
               and b["summary_message_count"] == b["messages"] else "MISSED",
        "jitter": "met" if res["jitter_baseline_ms"] and all(
            v is not None and v <= JITTER_RATIO * res["jitter_baseline_ms"] for v in jit[WARMUP_MIN:])
        else "MISSED",
    }
    res["targets"] = {"memory_growth": MEMORY_GROWTH, "deaths": 0, "jitter_ratio": JITTER_RATIO,
                      "warmup_min": WARMUP_MIN}
    (out / "soak.json").write_text(json.dumps(res, indent=1))
    _chart(res, out / "soak.png")
    print(f"[soak] {json.dumps(res['verdicts'])}; worst memory growth "
          f"{'n/a' if worst is None else f'{worst:+.1%}'}; wrote {out / 'soak.json'}, soak.png", flush=True)
    return 0 if all(v == "met" for v in res["verdicts"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
