"""``flexsheet experiment determinism --out DIR``: the display on the simulated clock, run twice with one
seed.

Runs ``flexsheet launch launch/sim.yaml --duration S --out DIR/runK`` twice (default 30 simulated seconds,
truth seed 0) and writes ``DIR/determinism.json``: the SHA-256 of every recorded topic's messages (frames,
stamps included) in each run and whether they agree, each run's ``realtime_factor`` and wall time, the
modelled lab latency chain (``latency_ms.chain``) and the nodes' readiness, with the issue's targets and
verdicts; and ``DIR/determinism.png`` (realtime factor and the two chain ends against their targets).
``/diagnostics`` is left out of the comparison: heartbeats carry wall time (liveness) by design.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import time
from pathlib import Path

from flexsheet.runtime.bag_read import read_bag

__all__ = ["topic_hashes", "main"]

#: simulated seconds of a ``--quick`` run: the nodes up, the finger's approach and the first stroke
QUICK_S = 10.0
TARGETS = {"exposure_to_arm_command_median_ms": 15.0, "exposure_to_projected_median_ms": 25.0,
           "realtime_factor_min": 1.0, "fem_active_s": 10.0}


def topic_hashes(bag: Path) -> dict[str, dict]:
    """Topic → {"sha256", "messages"} over the recorded frames of every message, in bag order."""
    h: dict[str, tuple] = {}
    for m in read_bag(bag):
        d, n = h.get(m.topic, (hashlib.sha256(), 0))
        for f in m.frames:
            d.update(bytes(f))
        h[m.topic] = (d, n + 1)
    return {t: {"sha256": d.hexdigest(), "messages": n} for t, (d, n) in sorted(h.items())}


def _chart(out: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))
    rf = [r["realtime_factor"] for r in out["runs"]]
    ax[0].bar([f"run {i + 1}" for i in range(len(rf))], rf)
    ax[0].axhline(TARGETS["realtime_factor_min"], color="r", ls="--", label="target ≥ 1.0")
    ax[0].set_ylabel("real-time factor (simulated s / wall s)")
    ax[0].legend(fontsize=8)
    ch = out["runs"][0]["chain_ms"]
    names = ["exposure_to_arm_command", "exposure_to_projected"]
    ax[1].bar(names, [ch[n]["median"] for n in names], label="median (simulated clock)")
    ax[1].scatter(names, [TARGETS[f"{n}_median_ms"] for n in names], color="r", marker="_", s=600,
                  label="target")
    ax[1].set_ylabel("latency (ms)")
    ax[1].legend(fontsize=8)
    fig.suptitle(f"launch/sim.yaml twice, {out['duration_s']:g} s, seed {out['seed']}: "
                 f"{'byte-identical' if out['identical'] else 'DIFFERENT'}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flexsheet experiment determinism", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: flexsheet experiment determinism --out "
                                        "docs/figures/simclock\n         flexsheet experiment determinism "
                                        "--quick --out /tmp/det")
    ap.add_argument("--out", required=True, help="output folder (the two runs go into run1/, run2/)")
    ap.add_argument("--duration", type=float, default=30.0, help="simulated seconds per run (default 30)")
    ap.add_argument("--seed", type=int, default=0, help="twin truth seed (default 0)")
    ap.add_argument("--launch", default="launch/sim.yaml", help="a clock: sim launch file (default "
                                                                "launch/sim.yaml)")
    ap.add_argument("--quick", action="store_true", help=f"{QUICK_S:g} simulated s per run (the comparison "
                                                         "only)")
    args = ap.parse_args(argv)
    if args.quick:
        args.duration = QUICK_S
    if not args.duration > 0:
        ap.error(f"--duration must be > 0, got {args.duration}")
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    runs = []
    for k in (1, 2):
        run = out_dir / f"run{k}"
        print(f"[determinism] run {k}/2: flexsheet launch {args.launch} --duration {args.duration:g} "
              f"--set twin.truth_seed={args.seed} ...", flush=True)
        t0 = time.monotonic()
        res = subprocess.run([sys.executable, "-m", "flexsheet", "launch", args.launch, "--duration",
                              str(args.duration), "--out", str(run), "--set", f"twin.truth_seed={args.seed}",
                              "--set", "viz.port=0"], capture_output=True, text=True)
        wall = time.monotonic() - t0
        if res.returncode != 0 or not (run / "summary.json").exists():
            print(res.stdout[-3000:], res.stderr[-2000:], sep="\n", file=sys.stderr)
            print(f"[determinism] run {k} failed (exit {res.returncode})", file=sys.stderr)
            return 1
        s = json.loads((run / "summary.json").read_text())
        runs.append({"hashes": topic_hashes(run / "sim.mcap"), "realtime_factor": s.get("realtime_factor"),
                     "launch_wall_s": wall, "clock": (s.get("clock") or {}).get("kind"),
                     "chain_ms": s["latency_ms"]["chain"],
                     "sheet_at_pose_reached": s["latency_ms"].get("sheet_at_pose_reached"),
                     "readiness": s.get("readiness", {}),
                     "table1": {k2: s[k2] for k2 in s if k2[:1].isdigit()}})
        print(f"[determinism] run {k}: real-time factor {s.get('realtime_factor', 0):.2f}, {wall:.0f} s wall",
              flush=True)
    a, b = runs[0]["hashes"], runs[1]["hashes"]
    compared = sorted(t for t in set(a) | set(b) if t != "/diagnostics")
    same = {t: a.get(t) == b.get(t) for t in compared}
    ch = runs[0]["chain_ms"]
    fem_s = max(r["readiness"].get("fem_active_s", float("nan")) for r in runs)
    out = {"launch": args.launch, "duration_s": args.duration, "seed": args.seed,
           "identical": all(same.values()),
           "topics": same, "runs": runs, "targets": TARGETS,
           "verdicts": {
               "byte_identical": "met" if all(same.values()) else "MISSED",
               "realtime_factor": "met" if min(r["realtime_factor"] for r in runs) >= 1.0 else "MISSED",
               "exposure_to_arm_command": "met" if ch["exposure_to_arm_command"]["median"] <= 15.0
               else "MISSED",
               "exposure_to_projected": "met" if ch["exposure_to_projected"]["median"] <= 25.0 else "MISSED",
               "fem_active": "met" if fem_s <= 10.0 else "MISSED"},
           "note": "/diagnostics is not compared: heartbeats carry wall time by design"}
    (out_dir / "determinism.json").write_text(json.dumps(out, indent=1))
    _chart(out, out_dir / "determinism.png")
    print(f"[determinism] {'byte-identical' if out['identical'] else 'DIFFERENT'} on {len(compared)} topics; "
          f"verdicts {out['verdicts']}; wrote {out_dir}/determinism.json, determinism.png", flush=True)
    return 0 if out["identical"] else 1


if __name__ == "__main__":
    sys.exit(main())
