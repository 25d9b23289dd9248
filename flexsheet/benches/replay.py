"""``flexsheet bench replay``: how fast a lockstep replay runs, and whether two replays of one bag agree.

A developer replays a recorded bag into a subset of nodes (``launch/replay.yaml``: the planner and the FEM
solver, docs/replay.md) with ``player.mode=lockstep``: every message handled in order, on the bag's clock
(:mod:`flexsheet.runtime.lockstep`). This bench

1. takes the bag given with ``--bag``, or records one first: ``flexsheet launch launch/sim.yaml --duration S``
   (the default scene; ~1 min of wall time for 20 simulated seconds on a 2-core machine);
2. runs ``flexsheet launch LAUNCH --set player.file=BAG --set player.mode=lockstep`` ``--runs`` times
   (default 2), each as its own process, and reads each run's ``cpu_<container>.json``: the lockstep loop's
   ``speed`` (bag seconds per wall second, the player's start delay and the nodes' set-up left out) and each
   node's handler CPU;
3. compares the replays' recorded outputs message by message (the wire frames of every topic of the
   replay's bag): ``byte_identical`` is true when every run recorded the same messages.

Target: speed ≥ :data:`SPEED_TARGET` (replay on a 2-core machine, nothing beside it) and byte-identical.
Writes ``replay.json`` to ``--out``; exit status 0 when both are met, 1 when not, 2 when a launch failed or
measured nothing.
"""

from __future__ import annotations

import argparse
import collections
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from flexsheet.runtime.bag_read import read_bag

__all__ = ["SPEED_TARGET", "bag_digest", "main"]

#: bag seconds per wall second a lockstep replay must reach
SPEED_TARGET = 5.0

EXAMPLES = """example: flexsheet bench replay --out docs/figures/bench
         flexsheet bench replay --bag out/sim/sim.mcap --runs 3 --json"""


def bag_digest(path: str | Path) -> dict[str, tuple[int, str]]:
    """{topic: (messages, SHA-256 of their wire frames in file order)} of the bag at ``path``. Raises
    ``ValueError`` naming the file when it is not an MCAP file."""
    h: dict[str, Any] = collections.defaultdict(hashlib.sha256)
    n: collections.Counter = collections.Counter()
    for m in read_bag(path):
        for f in m.frames:
            h[m.topic].update(bytes(f))
        n[m.topic] += 1
    return {t: (n[t], h[t].hexdigest()) for t in sorted(h)}


def _launch(cmd: list[str], what: str) -> bool:
    """Run one ``flexsheet launch`` (its output kept back, shown on failure); True when it exited 0."""
    print(f"[bench replay] {what}: flexsheet {' '.join(cmd)} ...", file=sys.stderr, flush=True)
    proc = subprocess.run([sys.executable, "-m", "flexsheet"] + cmd, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True)
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout[-3000:])
        print(f"[bench replay] {what}: the launch exited {proc.returncode}", file=sys.stderr)
    return proc.returncode == 0


def _run(args, bag: str, out: Path, k: int) -> dict | None:
    """One replay of ``bag`` into ``out``: its lockstep figures, the nodes' handler CPU and the output bag's
    digest; None when it failed or measured nothing."""
    cmd = ["launch", args.launch, "--out", str(out), "--set", f"player.file={bag}", "--set",
           "player.mode=lockstep"] + (["--domain", str(args.domain)] if args.domain is not None else [])
    if not _launch(cmd, f"replay {k + 1}/{args.runs}"):
        return None
    files = sorted(out.glob("cpu_*.json"))
    stats = [json.loads(f.read_text()) for f in files]
    stats = [s for s in stats if s.get("lockstep")]
    bags = list(out.glob("*.mcap"))
    if len(stats) != 1 or not stats[0]["lockstep"]["messages"] or len(bags) != 1:
        print(f"[bench replay] replay {k + 1}: no lockstep container figures or no recorded bag in {out} "
              f"({[f.name for f in files]}, {[b.name for b in bags]})", file=sys.stderr)
        return None
    s = stats[0]
    return {"lockstep": s["lockstep"],
            "handler_cpu_s": {n: round(v["handler_cpu_s"], 3) for n, v in s["nodes"].items()},
            "digest": bag_digest(bags[0])}


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; print a summary (one JSON object with ``--json``); exit status as the module doc."""
    ap = argparse.ArgumentParser(prog="flexsheet bench replay", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=EXAMPLES)
    ap.add_argument("--bag", default="", help="the bag to replay (default: record one of --duration s)")
    ap.add_argument("--duration", type=float, default=20.0,
                    help="simulated seconds of the bag recorded when no --bag is given (default 20)")
    ap.add_argument("--launch", default="launch/replay.yaml",
                    help="the replay's launch file (default launch/replay.yaml)")
    ap.add_argument("--runs", type=int, default=2,
                    help="replays of the bag, compared (default 2, at least 2)")
    ap.add_argument("--domain", type=int, default=None, help="the launches' domain (default: as the launch)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--out", default="", help="also write DIR/replay.json")
    args = ap.parse_args(argv)
    if args.runs < 2:
        ap.error(f"--runs must be at least 2 (the replays are compared), got {args.runs}")
    if not args.duration > 0.0:
        ap.error(f"--duration must be > 0 simulated seconds, got {args.duration!r}")
    if args.bag and not Path(args.bag).is_file():
        ap.error(f"--bag: no file {args.bag!r}")
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="flexsheet-bench-replay-") as tmp:
        bag = args.bag
        if not bag:
            rec = Path(tmp) / "recorded"
            cmd = ["launch", "launch/sim.yaml", "--duration", str(args.duration), "--out", str(rec)]
            if args.domain is not None:
                cmd += ["--domain", str(args.domain)]
            t0 = time.monotonic()
            if not _launch(cmd, "recording the bag"):
                return 2
            bag = str(rec / "sim.mcap")
            print(f"[bench replay] recorded {bag} in {time.monotonic() - t0:.0f} s", file=sys.stderr)
        runs = []
        for k in range(args.runs):
            r = _run(args, str(Path(bag).resolve()), Path(tmp) / f"replay{k}", k)
            if r is None:
                return 2
            runs.append(r)
    speeds = [r["lockstep"]["speed"] for r in runs]
    identical = all(r["digest"] == runs[0]["digest"] for r in runs[1:])
    result = {"title": "bench replay: lockstep replay speed and run-to-run identity",
              "units": "bag s per wall s", "launch": args.launch,
              "bag": args.bag or f"recorded: launch/sim.yaml, {args.duration:g} simulated s",
              "bag_s": round(runs[0]["lockstep"]["bag_s"], 3), "messages": runs[0]["lockstep"]["messages"],
              "handled": runs[0]["lockstep"]["handled"],
              "speed": [round(s, 3) for s in speeds],
              "speed_median": round(sorted(speeds)[len(speeds) // 2], 3),
              "target": {"speed": SPEED_TARGET, "byte_identical": True},
              "byte_identical": identical,
              "topics": {t: n for t, (n, _) in runs[0]["digest"].items()},
              "handler_cpu_s": [r["handler_cpu_s"] for r in runs],
              "load_average_before": [round(x, 2) for x in load0], "cores": os.cpu_count()}
    result["verdict"] = "met" if min(speeds) >= SPEED_TARGET and identical else "MISSED"
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "replay.json").write_text(json.dumps(result, indent=1) + "\n")
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(f"lockstep replay of {result['bag_s']:g} s of bag ({result['messages']} messages, "
              f"{result['handled']} handler calls): {', '.join(f'{s:.2f}x' for s in speeds)} real time "
              f"(target >= {SPEED_TARGET:g}x); runs byte-identical: {identical}; "
              f"handler CPU s {runs[0]['handler_cpu_s']}; {result['verdict']}")
    return 0 if result["verdict"] == "met" else 1
