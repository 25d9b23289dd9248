"""``flexsheet experiment speed --out DIR``: what each CPU cut saves, charted against what it costs in
accuracy.

Runs ``flexsheet launch launch/sim.yaml --duration S --out DIR/NAME`` (default 30 simulated seconds, truth
seed 0, on the simulated clock) once as the reference, once more with the next truth seed (the spread of
each figure between two truths: the noise a cut is judged against), and once per cut:

* ``--cut NAME=NODE.KEY=VALUE[,NODE.KEY=VALUE...]``: a cut made by parameters (a launch ``--set``);
* ``--before DIR``: the same run from another checkout (``DIR``, e.g. a ``git worktree`` of the commit before
  a code change), named ``--before-name``; its point is the change from there to this tree, with a
  byte-for-byte comparison of every recorded topic (``/diagnostics`` left out: it carries wall time).

Per run: CPU-seconds per simulated second of the whole process (``sim_clock.json``), the real-time factor,
and the accuracy figures a cut could move (``FIGURES``: the tracked eye's error, Table I's felt Δθ at the
longest row the run reaches, the sheet's placement p99, the force felt within 15 % when the run presses).
Per cut a point: CPU saved (reference minus cut; for ``--before``, before minus this tree) against each
figure's change, with the verdict *kept* when no figure moves beyond the two truths' spread (a change that
publishes identical bytes moves none), else *costs accuracy*. Writes ``DIR/speed.json`` and
``DIR/speed.png`` (one panel per figure). Timings only mean something on a quiet machine: the runs go one
after another and the load average before each is kept.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from flexsheet.experiments.determinism import topic_hashes

__all__ = ["FIGURES", "figures", "cut_point", "main"]

#: figure -> (label, unit): lower is better for each
FIGURES = {"eye_error_median_mm": ("tracked eye error, median", "mm"),
           "felt_dtheta_mean_deg": ("Table I felt Δθ, mean", "deg"),
           "placement_p99_mm": ("sheet placement, p99", "mm"),
           "force_outside_15pct": ("force felt outside ±15 %", "share")}


def figures(summary: dict) -> dict:
    """The accuracy figures (``FIGURES``) of one run's ``summary.json`` dict; a figure the run did not reach
    (no press: no force figure) is None. Table I's felt row is the longest the run has (30 s, else 10 s)."""
    felt = (summary.get("table1") or {}).get("felt") or {}
    row = next((felt[r] for r in ("30", "10") if r in felt), None)
    forced = ((summary.get("compliance") or {}).get("felt") or {}).get("within_15pct")
    return {"eye_error_median_mm": ((summary.get("eye") or {}).get("error_mm") or {}).get("median"),
            "felt_dtheta_mean_deg": None if row is None else row.get("dtheta_mean_deg"),
            "placement_p99_mm": ((summary.get("placement") or {}).get("distance_mm") or {}).get("p99"),
            "force_outside_15pct": None if forced is None else 1.0 - float(forced)}


def _run(name: str, tree: Path, sets: list[str], args: argparse.Namespace, seed: int) -> dict:
    out = Path(args.out).resolve() / name
    cmd = [sys.executable, "-m", "flexsheet", "launch", "launch/sim.yaml", "--duration", str(args.duration),
           "--out", str(out), "--set", f"twin.truth_seed={seed}", "--set", "viz.port=0"]
    for s in sets:
        cmd += ["--set", s]
    load = os.getloadavg()[0]
    print(f"[speed] {name}: {' '.join(cmd[3:])} (in {tree}, load {load:.2f}) ...", flush=True)
    t0 = time.monotonic()
    res = subprocess.run(cmd, cwd=tree, capture_output=True, text=True)
    # the launch exits 1 when the report's verdicts miss: still a run; without its summary it is none
    s = json.loads((out / "summary.json").read_text()) if (out / "summary.json").is_file() else {}
    clock = s.get("sim_clock") or {}
    if res.returncode not in (0, 1) or not clock.get("sim_s"):
        sys.stderr.write(res.stdout[-3000:] + res.stderr[-2000:])
        raise RuntimeError(f"run {name} failed (exit {res.returncode}, no simulated time in its summary); "
                           "its log is above")
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=tree, capture_output=True, text=True)
    r = {"name": name, "tree": str(tree), "commit": commit.stdout.strip() or None, "set": sets, "seed": seed,
         "load_before": round(load, 2),
         "launch_rc": res.returncode,
         "launch_wall_s": round(time.monotonic() - t0, 1),
         "cpu_per_sim_s": round(clock["process_cpu_run_s"] / clock["sim_s"], 4),
         "realtime_factor": round(clock["realtime_factor"], 3), "figures": figures(s),
         "hashes": topic_hashes(out / "sim.mcap")}
    r["hashes"].pop("/diagnostics", None)
    print(f"[speed] {name}: {r['cpu_per_sim_s']:.3f} CPU-s per simulated s, real-time factor "
          f"{r['realtime_factor']:.2f}, {r['figures']}", flush=True)
    return r


def cut_point(name: str, base: dict, cut: dict, noise: dict) -> dict:
    """The cut's point: CPU saved and each figure's change against ``base``, judged against ``noise``."""
    delta, moved = {}, []
    for f in FIGURES:
        a, b = base["figures"][f], cut["figures"][f]
        delta[f] = None if a is None or b is None else b - a
        if delta[f] is not None and noise.get(f) is not None and abs(delta[f]) > noise[f]:
            moved.append(f)
    identical = base["hashes"] == cut["hashes"]
    return {"name": name, "cpu_saved_per_sim_s": round(base["cpu_per_sim_s"] - cut["cpu_per_sim_s"], 4),
            "cpu_saved_share": round(1.0 - cut["cpu_per_sim_s"] / base["cpu_per_sim_s"], 4),
            "delta": delta, "moved_beyond_noise": moved, "identical_bytes": identical,
            "verdict": "kept" if not moved else "costs accuracy"}


def _chart(out: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(FIGURES), figsize=(3.3 * len(FIGURES), 3.6))
    for ax, (f, (label, unit)) in zip(axes, FIGURES.items(), strict=True):
        n = out["noise"].get(f)
        if n is not None:
            ax.axhspan(-n, n, color="0.9", label="two truths' spread")
        for p in out["points"]:
            d = p["delta"][f]
            if d is not None:
                color = "tab:green" if p["verdict"] == "kept" else "tab:red"
                ax.scatter(p["cpu_saved_per_sim_s"], d, color=color)
                ax.annotate(p["name"], (p["cpu_saved_per_sim_s"], d), fontsize=7, xytext=(3, 3),
                            textcoords="offset points")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel("CPU saved (CPU-s per simulated s)")
        ax.set_ylabel(f"change ({unit}; + is worse)")
        ax.set_title(label, fontsize=9)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"CPU cuts against accuracy: launch/sim.yaml, {out['duration_s']:g} simulated s, seed "
                 f"{out['seed']} (reference {out['reference']['cpu_per_sim_s']:.2f} CPU-s per simulated s, "
                 f"real-time factor {out['reference']['realtime_factor']:.2f}; target ≥ 2.0)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flexsheet experiment speed", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: flexsheet experiment speed --out /tmp/speed --duration 10 "
                                        "--cut head30=head_camera.rate_hz=30\n         flexsheet experiment "
                                        "speed --out docs/figures/speed --before /tmp/before")
    ap.add_argument("--out", required=True, help="output folder (each run in a subfolder)")
    ap.add_argument("--duration", type=float, default=30.0, help="simulated seconds per run (default 30)")
    ap.add_argument("--seed", type=int, default=0, help="twin truth seed of the reference (default 0)")
    ap.add_argument("--cut", action="append", default=[], metavar="NAME=NODE.KEY=VALUE[,...]",
                    help="a cut made by parameters (repeatable)")
    ap.add_argument("--before", metavar="DIR", help="another checkout: its run against this tree's")
    ap.add_argument("--before-name", default="code", help="the --before point's name (default 'code')")
    args = ap.parse_args(argv)
    if not args.duration > 0:
        ap.error(f"--duration must be > 0 simulated seconds, got {args.duration!r}")
    cuts = []
    for c in args.cut:
        name, _, sets = c.partition("=")
        if not name or "=" not in sets:
            ap.error(f"--cut {c!r}: expected NAME=NODE.KEY=VALUE[,NODE.KEY=VALUE...]")
        cuts.append((name, sets.split(",")))
    if args.before and not (Path(args.before) / "flexsheet").is_dir():
        ap.error(f"--before {args.before!r}: not a checkout (no flexsheet/ in it)")
    here = Path(__file__).resolve().parents[2]
    try:
        ref = _run("reference", here, [], args, args.seed)
        other = _run("reference_next_seed", here, [], args, args.seed + 1)
        runs = [_run(name, here, sets, args, args.seed) for name, sets in cuts]
        before = _run(f"before_{args.before_name}", Path(args.before).resolve(), [], args, args.seed) \
            if args.before else None
    except RuntimeError as exc:
        print(f"[speed] {exc}", file=sys.stderr)
        return 1
    noise = {f: (None if ref["figures"][f] is None or other["figures"][f] is None
                 else abs(ref["figures"][f] - other["figures"][f])) for f in FIGURES}
    points = [cut_point(r["name"], ref, r, noise) for r in runs]
    if before is not None:
        points.append(cut_point(args.before_name, before, ref, noise))
    out = {"title": "CPU cuts against accuracy (simulated clock)",
           "units": {f: u for f, (_, u) in FIGURES.items()},
           "duration_s": args.duration, "seed": args.seed, "target": {"realtime_factor": 2.0},
           "reference": {k: v for k, v in ref.items() if k != "hashes"},
           "reference_next_seed": {k: v for k, v in other.items() if k != "hashes"},
           "noise": noise, "points": points,
           "runs": [{k: v for k, v in r.items() if k != "hashes"}
                    for r in runs + ([before] if before else [])],
           "verdict": "met" if ref["realtime_factor"] >= 2.0 else "MISSED",
           "note": "noise: each figure's spread between the reference's truth seed and the next; CPU is the "
                   "whole process's per simulated second on this host (timing: a quiet machine only)"}
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "speed.json").write_text(json.dumps(out, indent=1) + "\n")
    _chart(out, Path(args.out) / "speed.png")
    for p in points:
        print(f"[speed] {p['name']}: saves {p['cpu_saved_per_sim_s']:+.3f} CPU-s per simulated s "
              f"({100 * p['cpu_saved_share']:+.1f} %), identical bytes {p['identical_bytes']}, {p['verdict']}"
              f"{'' if not p['moved_beyond_noise'] else ' (' + ', '.join(p['moved_beyond_noise']) + ')'}")
    print(f"[speed] reference real-time factor {ref['realtime_factor']:.2f} (target ≥ 2.0): "
          f"{out['verdict']}; wrote {args.out}/speed.json, speed.png")
    return 0 if points else 1


if __name__ == "__main__":
    sys.exit(main())
