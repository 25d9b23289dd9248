"""``flexsheet experiment stroke --out DIR [--seeds 0 1 2]``: Table I felt and paper, from the display's own
graph.

For each truth seed the whole graph of ``launch/sim.yaml`` runs on the simulated clock in one process
(``flexsheet launch launch/sim.yaml --duration D --set twin.truth_seed=N``: the same node classes, params and
messages as the lab; the twin's cameras, finger, arms and sheet; the geometry from the twin's registration,
not the truth), and its run report (:mod:`flexsheet.analysis.report`) measures from the bag:

* ``felt``: the true fingertip against the true sheet (what the user feels; the headline);
* ``paper``: the measured fingertip against the sheet the display believes (the paper's Table I);
* ``delay``: exposure → sheet at its pose, the value the prediction horizon should have.

On the simulated clock one run per seed is exact (two runs write the same bytes: ``flexsheet experiment
determinism``). Writes ``DIR/seed<N>/`` (each run's bag, summary and charts), ``DIR/summary.json`` (per seed
and the worst seed per row, the targets and the verdicts: a target is met only when every seed meets it) and
``DIR/stroke.png`` with the same numbers in ``DIR/stroke.json``.
"""

from __future__ import annotations

import argparse
import json
import logging
import subprocess
import sys
import time
from pathlib import Path

from flexsheet.analysis.table1 import FELT_TARGET_FACTOR, PAPER_TABLE1, TARGET_FACTOR, target
from flexsheet.dirs import launch_dir

log = logging.getLogger(__name__)

__all__ = ["run_seed", "aggregate", "chart", "main", "ROWS"]

#: the rows judged: the paper's two moving times
ROWS = tuple(PAPER_TABLE1)
#: the 10 s stroke alone (``--quick``, and each run of ``experiment stability --graph``), and the simulated
#: seconds it needs (start, approach, holds)
SCRIPT_10S = "world.script=[{mode: stroke, moving_time: 10.0}]"
DURATION_10S = 24.0


def run_seed(seed: int, out: Path, duration: float, launch: Path, extra: list[str] | None = None) -> dict:
    """Run the graph of ``launch`` for ``duration`` simulated s on truth seed ``seed`` into ``out``; returns
    its ``summary.json``. Raises ``RuntimeError`` naming the seed and the log when the run writes none."""
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("*.mcap"):          # an earlier run's bags: the report reads every bag in the folder
        old.unlink()
    cmd = [sys.executable, "-m", "flexsheet", "launch", str(launch), "--duration", f"{duration:g}", "--out",
           str(out), "--set", f"twin.truth_seed={seed}", *(extra or [])]
    t0 = time.monotonic()
    with open(out / "launch.log", "w") as fh:
        subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, cwd=launch_dir().parent, check=False)
    path = out / "summary.json"
    if not path.exists():
        raise RuntimeError(f"seed {seed}: the run wrote no summary.json (see {out / 'launch.log'})")
    log.info(f"[stroke] seed {seed}: {duration:g} simulated s in {time.monotonic() - t0:.0f} s")
    return json.loads(path.read_text())


def aggregate(summaries: dict[int, dict], rows: tuple[str, ...] = ROWS) -> dict:
    """Per seed and worst seed of each Table I row (felt: Δθ mean, 3-D angle, gap, Δd; paper: Δθ mean, Δd),
    the delays, the targets and the verdicts of ``rows`` (met only when the worst seed meets). ``summaries``:
    seed → a run report's summary."""
    out: dict = {"seeds": sorted(summaries), "table1": {"felt": {}, "paper": {}}, "delay": {},
                 "targets": {"felt": {k: target(k, FELT_TARGET_FACTOR)["dtheta_mean_deg"] for k in ROWS},
                             "paper": {k: target(k, TARGET_FACTOR)["dtheta_mean_deg"] for k in ROWS}},
                 "paper_table1": PAPER_TABLE1}
    fields = {"felt": ("dtheta_mean_deg", "angle3d_mean_deg", "gap_mean_mm", "dd_mean_mm", "dd_2r_mean_mm",
                       "n"),
              "paper": ("dtheta_mean_deg", "dd_mean_mm", "dd_2r_mean_mm", "n")}
    for kind, keys in fields.items():
        for row in sorted({r for s in summaries.values() for r in s.get("table1", {}).get(kind, {})}):
            per = {seed: {k: s["table1"][kind][row].get(k) for k in keys}
                   for seed, s in summaries.items() if row in s.get("table1", {}).get(kind, {})}
            worst = max(v["dtheta_mean_deg"] for v in per.values())
            out["table1"][kind][row] = {"per_seed": per, "dtheta_mean_deg": worst,
                                        "dtheta_mean_deg_all": [per[s]["dtheta_mean_deg"]
                                                                for s in sorted(per)]}
    for seed, s in summaries.items():
        if s.get("delay"):
            out["delay"][seed] = s["delay"]
    out["head"] = head_worst(summaries)
    out["verdicts"] = {}
    for kind in ("felt", "paper"):
        for row in rows:
            r = out["table1"][kind].get(row)
            if r is not None and len(r["per_seed"]) == len(summaries):
                ok = r["dtheta_mean_deg"] <= out["targets"][kind][row]
                out["verdicts"][f"{kind}.{row}"] = "met" if ok else "MISSED"
            else:
                out["verdicts"][f"{kind}.{row}"] = "MISSED (not measured on every seed)"
    return out


def chart(summary: dict, path: Path) -> None:
    """Felt and paper Δθ mean per row and seed against the targets (``path``, PNG; the numbers are
    ``summary``, written beside it as JSON by :func:`main`)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    seeds = summary["seeds"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, kind in zip(axes, ("felt", "paper"), strict=True):
        rows = [r for r in ROWS if r in summary["table1"][kind]]
        x = np.arange(len(rows))
        w = 0.8 / max(1, len(seeds))
        for i, seed in enumerate(seeds):
            vals = [summary["table1"][kind][r]["per_seed"].get(seed, {}).get("dtheta_mean_deg", np.nan)
                    for r in rows]
            ax.bar(x - 0.4 + w * (i + 0.5), vals, w, label=f"truth seed {seed}")
        for i, r in enumerate(rows):
            ax.hlines(summary["targets"][kind][r], i - 0.45, i + 0.45, color="k", ls="--", lw=1.0)
            ax.hlines(PAPER_TABLE1[r]["dtheta_mean_deg"], i - 0.45, i + 0.45, color="tab:red", ls=":", lw=1.0)
        ax.set_xticks(x, [f"{r} s stroke" for r in rows])
        ax.set_ylabel("Δθ mean (deg)")
        verdict = ", ".join(f"{r} s {summary['verdicts'][f'{kind}.{r}']}" for r in rows)
        ax.set_title(f"{kind}: dashed target, dotted the paper\n{verdict}", fontsize=8)
        ax.legend(fontsize=7)
    fig.suptitle("Table I from the full graph on the simulated clock: felt (true finger vs true sheet) and "
                 "paper (measured finger vs believed sheet)", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def head_worst(summaries: dict[int, dict]) -> dict:
    """The viewer's head over the seeds (each run's ``eye``, ``view``, ``safety``): per seed and the worst of
    each figure; ``{}`` when no run had a head."""
    per = {seed: {k: s[k] for k in ("eye", "view", "safety") if s.get(k)} for seed, s in summaries.items()}
    per = {seed: v for seed, v in per.items() if v}
    if not per:
        return {}

    def worst(get, fn=max):
        vals = [get(v) for v in per.values()]
        vals = [x for x in vals if x is not None]
        return fn(vals) if vals else None

    return {"per_seed": per,
            "eye_error_mm_median": worst(lambda v: v.get("eye", {}).get("error_mm", {}).get("median")),
            "view_tracked_px_median":
                worst(lambda v: v.get("view", {}).get("tracked", {}).get("error_px_median")),
            "view_tracked_px_p95": worst(lambda v: v.get("view", {}).get("tracked", {}).get("error_px_p95")),
            "view_fixed_px_median": worst(lambda v: v.get("view", {}).get("fixed", {}).get("error_px_median"),
                                          min),
            "min_head_distance_m": worst(lambda v: v.get("safety", {}).get("min_head_distance_m"), min),
            "keepout_violations": worst(lambda v: v.get("safety", {}).get("keepout_violations")),
            "max_speed_near_head_mps": worst(lambda v: v.get("safety", {}).get("max_speed_near_head_mps")),
            "verdicts":
                {k: ("met" if all(v.get(k, {}).get("verdict") == "met" for v in per.values()) else "MISSED")
                 for k in ("eye", "view", "safety")}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flexsheet experiment stroke", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: flexsheet experiment stroke --out docs/figures/stroke\n"
                                        "         flexsheet experiment stroke --out /tmp/s --seeds 0 --set "
                                        "triangulator.tracking_index=0.3\n"
                                        "         flexsheet experiment stroke --quick --out "
                                        "/tmp/stroke_quick")
    ap.add_argument("--out", required=True, help="output folder (seed<N>/, summary.json, stroke.png, "
                                                 "stroke.json)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="truth seeds (default 0 1 2)")
    ap.add_argument("--duration", type=float, default=70.0,
                    help="simulated s per run, a cap (default 70; the world's script, a 10 s stroke, a 30 s "
                         "stroke and a 10 s stroke and push, ends the run at 63 s)")
    ap.add_argument("--launch", default=str(launch_dir() / "sim.yaml"), help="launch file (clock: sim)")
    ap.add_argument("--quick", action="store_true",
                    help=f"truth seed 0 only, the 10 s stroke alone ({DURATION_10S:g} simulated s); judges "
                         "that row")
    ap.add_argument("--set", action="append", default=[], metavar="NODE.KEY=VALUE",
                    help="a param override passed to each run (flexsheet launch --set)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    rows = ROWS
    if args.quick:
        args.seeds, args.duration, rows = [0], DURATION_10S, ("10",)
        args.set = [SCRIPT_10S, *args.set]
    extra = [a for kv in args.set for a in ("--set", kv)]
    summaries = {}
    for seed in args.seeds:
        print(f"[stroke] seed {seed}: running the graph ({args.duration:g} simulated s) ...", flush=True)
        summaries[seed] = run_seed(seed, out / f"seed{seed}", args.duration, Path(args.launch), extra)
    summary = aggregate(summaries, rows)
    summary["overrides"] = args.set
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    (out / "stroke.json").write_text(json.dumps(summary, indent=1))
    chart(summary, out / "stroke.png")
    for kind in ("felt", "paper"):
        for row in rows:
            r = summary["table1"][kind].get(row)
            if r:
                print(f"[stroke] {kind} {row} s: Δθ mean per seed "
                      f"{[round(v, 3) for v in r['dtheta_mean_deg_all']]} deg, worst "
                      f"{r['dtheta_mean_deg']:.3f}, target {summary['targets'][kind][row]:.3f}: "
                      f"{summary['verdicts'][f'{kind}.{row}']}", flush=True)
    print(f"[stroke] wrote {out}/summary.json, stroke.png, stroke.json", flush=True)
    return 0 if all(v == "met" for v in summary["verdicts"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
