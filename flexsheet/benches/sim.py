"""``flexsheet bench sim``: where the simulated display's CPU time goes, per simulated second.

It runs ``flexsheet launch FILE --duration S --out DIR`` (default ``launch/sim.yaml``, 20 simulated seconds,
the scene and the truth seed of the file unless ``--set`` changes them) and reads what the launch writes at
its stop: ``DIR/sim_clock.json``: the simulated and wall span, and from the start of simulated time to the
stop (start-up left out, as the realtime factor leaves it out) each node's handler CPU on this host and the
whole process's CPU. Reported, in CPU-seconds per simulated second:

* each node: the thread CPU its handlers and timers took (``host_handler_cpu_run_s``), against :data:`BUDGET`;
* ``runtime``: the rest of the process (the in-process bus, the lockstep scheduler, the codec, the event loop,
  worker threads), against its budget;
* ``total`` against ``1 / rtf_target`` (one process on one core: ``rtf_target`` simulated seconds per wall
  second at most) and the run's ``realtime_factor`` (simulated over wall seconds, start-up excluded);
  ``rtf_target`` is 2.0 on the default scene and 1.5 on another (``--set scene=...``).

The budgets split the target's one core among the nodes (an assumption: roughly each node's share of the work
a lab PC does, with a sixth left to the runtime); the verdict is each against its budget. Writes ``sim.json``
and ``sim.png`` (bars per node, the budget ticked) to ``--out`` when given. Timings mean something only on a
quiet machine: the load average before the run is reported with them.

``--profile`` runs the container under :mod:`cProfile` as well and adds ``profile`` (the hottest functions
and files, :func:`flexsheet.benches.sim_profile.hottest`) to the JSON, written as ``profile.json`` with
``--out``; a profiled run is slower, so its speed figures are not the bench's (the verdict is still given).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from flexsheet.benches.sim_profile import hottest
from flexsheet.runtime.container import PROFILE_ENV

__all__ = ["BUDGET", "RTF_TARGET", "RTF_TARGET_SCENE", "cost_per_sim_s", "main"]

#: the targets: simulated seconds per wall second, on the default scene and on any other (``--set scene=``)
RTF_TARGET = 2.0
RTF_TARGET_SCENE = 1.5
#: CPU-s per simulated s each node may take at :data:`RTF_TARGET` (their sum is 1 / RTF_TARGET, one core;
#: another scene's run scales them to its target); "runtime": the process's rest
BUDGET: dict[str, float] = {
    "camera": 0.05, "head_camera": 0.045, "renderer": 0.05, "world": 0.05, "planner": 0.055, "arm_left": 0.03,
    "arm_right": 0.03, "triangulator": 0.03, "fem": 0.03, "ctrl_left": 0.0075, "ctrl_right": 0.0075,
    "viz": 0.0075, "recorder": 0.0125, "runtime": 0.095,
}


def cost_per_sim_s(sim_clock: dict) -> dict:
    """CPU-s per simulated s from a launch's ``sim_clock.json`` dict, over the run itself (start-up and the
    stop left out: ``host_handler_cpu_run_s``, ``process_cpu_run_s``):
    ``{"nodes": {name: x}, "runtime": x, "total": x, "sim_s", "wall_s",
    "realtime_factor"}``. Raises ``ValueError`` naming the key when the file lacks one or the span is not >
    0."""
    for key in ("sim_s", "wall_s", "host_handler_cpu_run_s", "process_cpu_run_s"):
        if key not in sim_clock:
            raise ValueError(f"sim_clock.json has no {key!r}: not a 'clock: sim' launch's output, or it "
                             "never reached simulated time")
    sim_s = float(sim_clock["sim_s"])
    if not sim_s > 0.0:
        raise ValueError(f"sim_s must be > 0, got {sim_s!r}: the run never advanced simulated time")
    nodes = {n: float(v) / sim_s for n, v in sim_clock["host_handler_cpu_run_s"].items()}
    total = float(sim_clock["process_cpu_run_s"]) / sim_s
    return {"nodes": nodes, "runtime": max(total - sum(nodes.values()), 0.0), "total": total, "sim_s": sim_s,
            "wall_s": float(sim_clock["wall_s"]), "realtime_factor": float(sim_clock["realtime_factor"])}


def _chart(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(result["per_sim_s"].items(), key=lambda kv: kv[1]["cpu"])
    names = [k for k, _ in rows]
    fig, ax = plt.subplots(figsize=(7.5, 0.32 * len(rows) + 1.6))
    colors = ["tab:green" if r["ok"] else "tab:red" for _, r in rows]
    ax.barh(names, [r["cpu"] for _, r in rows], color=colors)
    ax.scatter([r["budget"] for _, r in rows], names, marker="|", s=300, color="k", label="budget")
    ax.set_xlabel("CPU-seconds per simulated second")
    t = result["total"]
    ax.set_title(f"bench sim: {t['cpu']:.2f} CPU-s per simulated s (target ≤ {t['budget']:.2f}: "
                 f"{'met' if t['ok'] else 'MISSED'}); realtime factor {result['realtime_factor']:.2f} "
                 f"(target ≥ {result['rtf_target']})", fontsize=9)
    ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


EXAMPLES = """example: flexsheet bench sim --duration 20 --out docs/figures/bench
         flexsheet bench sim --set scene=launch/scenes/organ.yaml --json
         flexsheet bench sim --duration 20 --profile --out docs/figures/bench"""


def _print(result: dict) -> None:
    """The table (and with a profile its hottest functions) for a person."""
    print(f"{'node':14s} {'CPU-s/sim-s':>11s} {'budget':>7s}")
    for n, r in sorted(result["per_sim_s"].items(), key=lambda kv: -kv[1]["cpu"]):
        print(f"{n:14s} {r['cpu']:11.3f} {r['budget']:7.3f} {'' if r['ok'] else 'OVER'}")
    t = result["total"]
    print(f"{'total':14s} {t['cpu']:11.3f} {t['budget']:7.3f} {'' if t['ok'] else 'OVER'}")
    print(f"realtime factor {result['realtime_factor']:.2f} (target ≥ {result['rtf_target']}): "
          f"{result['verdict']}")
    if "profile" in result:
        print("hottest functions (own CPU-s per simulated s, under cProfile):")
        for r in result["profile"]["functions"][:15]:
            print(f"  {r['own']:7.4f}  {r['function']}  {r['where']}")


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; print a table (one JSON object with ``--json``); 0 when the total and the realtime
    factor meet their targets, 1 when not, 2 when the launch failed."""
    ap = argparse.ArgumentParser(prog="flexsheet bench sim", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog=EXAMPLES)
    ap.add_argument("--file", default="launch/sim.yaml", help="the launch file (default launch/sim.yaml)")
    ap.add_argument("--duration", type=float, default=20.0, help="simulated seconds (default 20)")
    ap.add_argument("--set", action="append", default=[], metavar="NODE.KEY=VALUE",
                    help="passed to the launch")
    ap.add_argument("--domain", type=int, default=None, help="the launch's domain (default: as the launch)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--out", default="", help="also write DIR/sim.json and DIR/sim.png")
    ap.add_argument("--profile", action="store_true",
                    help="also profile the run (cProfile): the hottest functions and files, per simulated s; "
                         "with --out written to DIR/profile.json, not sim.json (a profiled run is slower)")
    args = ap.parse_args(argv)
    if not args.duration > 0.0:
        ap.error(f"--duration must be > 0 simulated seconds, got {args.duration!r}")
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="flexsheet-bench-sim-") as tmp:
        cmd = [sys.executable, "-m", "flexsheet", "launch", args.file, "--duration", str(args.duration),
               "--out", tmp] + [x for s in args.set for x in ("--set", s)]
        if args.domain is not None:
            cmd += ["--domain", str(args.domain)]
        print(f"[bench sim] {' '.join(cmd[2:])} (load average {load0[0]:.2f}) ...", file=sys.stderr,
              flush=True)
        env = dict(os.environ)
        stats_file = Path(tmp) / "container.pstats"
        if args.profile:
            env[PROFILE_ENV] = str(stats_file)
        t0 = time.monotonic()
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
        wall = time.monotonic() - t0
        clock_file = Path(tmp) / "sim_clock.json"
        if proc.returncode != 0 or not clock_file.is_file():
            sys.stderr.write(proc.stdout[-4000:])
            print(f"[bench sim] the launch exited {proc.returncode} without its clock file", file=sys.stderr)
            return 2
        cost = cost_per_sim_s(json.loads(clock_file.read_text()))
        if args.profile:
            if not stats_file.is_file():
                print(f"[bench sim] --profile: the launch wrote no profile ({stats_file})", file=sys.stderr)
                return 2
            profile = hottest(stats_file, cost["sim_s"])
    target = RTF_TARGET_SCENE if any(x.startswith("scene=") for x in args.set) else RTF_TARGET
    budget = {n: round(b * RTF_TARGET / target, 4) for n, b in BUDGET.items()}
    per = {n: {"cpu": round(v, 4), "budget": budget.get(n, 0.01), "ok": v <= budget.get(n, 0.01)}
           for n, v in cost["nodes"].items()}
    per["runtime"] = {"cpu": round(cost["runtime"], 4), "budget": budget["runtime"],
                      "ok": cost["runtime"] <= budget["runtime"]}
    budget_total = round(1.0 / target, 4)
    result = {"title": "bench sim: CPU-seconds per simulated second, per node",
              "units": "CPU-s per simulated s",
              "file": args.file, "set": args.set, "duration_sim_s": round(cost["sim_s"], 3),
              "wall_s": round(cost["wall_s"], 2), "launch_wall_s": round(wall, 2),
              "realtime_factor": round(cost["realtime_factor"], 3), "rtf_target": target,
              "load_average_before": [round(x, 2) for x in load0], "per_sim_s": per,
              "total": {"cpu": round(cost["total"], 4), "budget": budget_total,
                        "ok": cost["total"] <= budget_total}}
    result["verdict"] = ("met" if result["total"]["ok"] and cost["realtime_factor"] >= target
                         else "MISSED")
    if args.profile:
        result["profile"] = profile
        result["title"] = "bench sim --profile: CPU-s per simulated s under cProfile (slower than unprofiled)"
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        if args.profile:
            (out / "profile.json").write_text(json.dumps(result, indent=1) + "\n")
        else:
            (out / "sim.json").write_text(json.dumps(result, indent=1) + "\n")
            _chart(result, out / "sim.png")
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        _print(result)
    return 0 if result["verdict"] == "met" else 1
