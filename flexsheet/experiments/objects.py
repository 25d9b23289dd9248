"""``flexsheet experiment objects --draws N``: the full display on objects drawn at random, each in any pose
and stroked in any direction (:mod:`flexsheet.model.scene_draw`), as a lab would bring them.

For each draw the scene is written to ``OUT/draw<k>/`` and the whole graph of ``launch/sim.yaml`` runs on it
on the simulated clock, on TCP ports of its own (the world's default script: a 10 s stroke, a 30 s stroke, a
10 s stroke and push), then the run's report is read. Per object (the run's ``summary.json`` and bag):

* ``felt_dtheta_deg`` 10 / 30 s: Table I felt (true finger against true sheet, paper Fig. 9), and
  ``felt_30_by_status``: the 30 s row split by the planner's status at each sample (the report's
  ``table1.by_status``: which share of the mean came while the arms could not reach the pose, ...);
* ``residual_lag_ms``: the sheet's lag beyond the prediction's lead (``delay``);
* ``landings``: touches, arrivals, the share the sheet met first (``placement``);
* ``force_within_15pct`` of presses ≥ 2 mm in, ``saturated`` share, ``follow_ms`` (``compliance``);
* ``span_p99_mm``, ``strain_over_plan``, ``placement_p99_mm`` (``sheet``, ``placement``);
* ``bridge_holds``: joint-state cycles each bridge refused its target, by reason (``hold:limit:J3``, …; not
  ``hold:no_target``, before the first target), and ``keepout_violations``;
* ``fem_model``: which model the FEM node served the presses (``/object/deformation`` ≥ 2 mm deep) with, from
  each message's ``method``: ``nonlinear`` (a table: every press), ``linear`` (none), or ``mixed`` (a scene's
  table built on first use arrived during the run); ``fem_presses``: per press (from ≥ 2 mm until < 1 mm) its
  start (s since the first deformation) and model; ``fem_nonlinear_from_s``: the first press message a table
  served.

With ``--reference`` the paper's cylinder runs too on the same truth seed: the targets "felt Δθ at 30 s ≤ 2 ×
the cylinder's" are judged against it. Writes ``objects.json`` and ``objects.png`` (one chart, the same
numbers) into ``OUT`` (the JSON after every draw too). Exit status 1 when no draw produced a report.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections import Counter
from pathlib import Path

from flexsheet.dirs import launch_dir
from flexsheet.experiments.stroke import DURATION_10S, SCRIPT_10S, run_seed
from flexsheet.model.scene_draw import write_scene
from flexsheet.runtime.bag_read import read_bag
from flexsheet.runtime.codec import DecodeError, decode_any
from flexsheet.runtime.ports import free_port

log = logging.getLogger(__name__)

__all__ = ["measure_object", "bridge_holds", "fem_models", "verdicts", "main", "TARGETS"]

#: the issue's targets per object (units in the keys)
TARGETS = {"felt_30_vs_cylinder": 2.0, "residual_lag_ms": 30.0, "force_within_15pct": 0.95, "saturated": 0.05,
           "follow_ms": 60.0, "span_p99_mm": 1.0, "strain_over_plan": 0.02, "bridge_holds": 0,
           "keepout_violations": 0}
#: simulated seconds per run: the world's default script ends at 63 s
DURATION = 70.0
#: ``ObjectDeformation.method`` values of the FEM's nonlinear tables (the rest: its linear model)
NONLINEAR_METHODS = ("snapshots", "path_snapshots", "corotational")
#: a deformation at least this deep (m) is a press (the compliance figure's presses)
PRESS_DEPTH = 0.002


def bridge_holds(bag: Path) -> dict[str, int]:
    """Joint-state cycles per bridge status that refused or held a target (``hold:…`` but
    ``hold:no_target``, ``hold:disabled``), summed over both arms, from the bag's ``/arm/*/joint_state``."""
    c: Counter = Counter()
    for m in read_bag(bag, ["/arm/left/joint_state", "/arm/right/joint_state"]):
        try:
            s = decode_any(m.frames).bridge_status
        except (DecodeError, AttributeError):
            continue
        if s.startswith("hold") and s not in ("hold:no_target", "hold:disabled"):
            c[s] += 1
    return dict(sorted(c.items()))


def fem_models(bag: Path) -> dict:
    """``fem_model``, ``fem_presses``, ``fem_nonlinear_from_s`` (module doc) from the bag's
    ``/object/deformation``."""
    t0, first_nl, presses, cur = None, None, [], None
    for m in read_bag(bag, ["/object/deformation"]):
        try:
            d = decode_any(m.frames)
            t, nl = float(d.header.stamp), d.method in NONLINEAR_METHODS
            deep = d.valid and d.depth >= PRESS_DEPTH
        except (DecodeError, AttributeError):
            continue
        t0 = t if t0 is None else t0
        if deep and nl and first_nl is None:
            first_nl = round(t - t0, 3)
        if deep and cur is None:
            cur = {"start_s": round(t - t0, 3), "models": set()}
            presses.append(cur)
        if deep:
            cur["models"].add("nonlinear" if nl else "linear")
        elif not d.valid or d.depth < PRESS_DEPTH / 2:       # released (hysteresis: noise about 2 mm)
            cur = None
    for p in presses:
        p["model"] = "mixed" if len(p["models"]) > 1 else p["models"].pop()
        del p["models"]
    models = {p["model"] for p in presses}
    return {"fem_model": None if not models else (models.pop() if len(models) == 1 else "mixed"),
            "fem_presses": presses, "fem_nonlinear_from_s": first_nl}


def _fem_model_from_log(log_text: str) -> dict:
    """Without a bag: the FEM's model as its start-up line names it (no presses)."""
    return {"fem_model": "linear" if "serving the LINEAR model" in log_text else "nonlinear",
            "fem_presses": [], "fem_nonlinear_from_s": None}


def _get(d: dict, *path, default=None):
    for k in path:
        if not isinstance(d, dict) or k not in d:
            return default
        d = d[k]
    return d


def measure_object(summary: dict, bag: Path | None, log_text: str = "") -> dict:
    """The per-object figures (module doc) from a run's ``summary`` and bag (``None``: no hold counts, the
    FEM's model guessed from the launch log's text ``log_text``)."""
    felt = _get(summary, "table1", "felt", default={}) or {}
    has_bag = bag is not None and bag.exists()
    holds = bridge_holds(bag) if has_bag else {}
    return {
        "felt_dtheta_deg": {row: _get(felt, row, "dtheta_mean_deg") for row in ("10", "30")},
        "felt_30_by_status": _get(summary, "table1", "by_status", "30"),
        "residual_lag_ms": _get(summary, "delay", "residual_lag_ms"),
        "landings": {**{k: _get(summary, "placement", k)
                        for k in ("touches", "arrivals", "sheet_first", "late", "never")},
                     "in_place_and_pose": _get(summary, "placement", "onsets", "in_place_and_pose")},
        "force_within_15pct": _get(summary, "compliance", "felt", "within_15pct"),
        "saturated": _get(summary, "compliance", "saturated"),
        "follow_ms": _get(summary, "compliance", "follow_ms"),
        "span_p99_mm": _get(summary, "sheet", "span_error_mm", "p99"),
        "strain_over_plan": _get(summary, "sheet", "strain_over_plan_max"),
        "placement_p99_mm": _get(summary, "placement", "distance_mm", "p99"),
        "bridge_holds": sum(holds.values()),
        "bridge_holds_by_status": holds,
        "keepout_violations": _get(summary, "safety", "keepout_violations"),
        **(fem_models(bag) if has_bag else _fem_model_from_log(log_text)),
    }


def verdicts(m: dict, cyl30: float | None) -> dict:
    """Each target (:data:`TARGETS`) met / MISSED / not measured for object figures ``m``."""
    def le(v, t):
        return "not measured" if v is None else ("met" if v <= t else "MISSED")
    f30 = m["felt_dtheta_deg"]["30"]
    out = {"felt_30_vs_cylinder": ("not measured" if f30 is None or cyl30 is None
                                   else le(f30, TARGETS["felt_30_vs_cylinder"] * cyl30))}
    for k in ("residual_lag_ms", "saturated", "follow_ms", "span_p99_mm", "strain_over_plan", "bridge_holds",
              "keepout_violations"):
        out[k] = le(m[k], TARGETS[k])
    w = m["force_within_15pct"]
    out["force_within_15pct"] = "not measured" if w is None else ("met" if w >= TARGETS["force_within_15pct"]
                                                                 else "MISSED")
    return out


def chart(result: dict, path: Path) -> None:
    """Six panels, one bar per object (and the cylinder when run) against the targets: felt Δθ at 30 s,
    force within 15 %, saturated, span p99, residual lag, bridge holds (``path``, PNG; the numbers are
    ``objects.json``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = list(result["objects"].items())
    names = [n for n, _ in rows]
    cyl = result.get("cylinder")
    panels = [("felt Δθ 30 s (deg)", lambda m: m["felt_dtheta_deg"]["30"],
               2.0 * cyl["felt_dtheta_deg"]["30"] if cyl and cyl["felt_dtheta_deg"]["30"] else None),
              ("force within 15 % (share)", lambda m: m["force_within_15pct"], TARGETS["force_within_15pct"]),
              ("saturated (share)", lambda m: m["saturated"], TARGETS["saturated"]),
              ("span p99 (mm)", lambda m: m["span_p99_mm"], TARGETS["span_p99_mm"]),
              ("residual lag (ms)", lambda m: m["residual_lag_ms"], TARGETS["residual_lag_ms"]),
              ("bridge holds (cycles)", lambda m: m["bridge_holds"], 0)]
    fig, axes = plt.subplots(2, 3, figsize=(13, 6.5))
    for ax, (title, get, target) in zip(axes.flat, panels, strict=True):
        vals = [get(m) if get(m) is not None else float("nan") for _, m in rows]
        ax.bar(range(len(vals)), vals, color="tab:blue")
        if target is not None:
            ax.axhline(target, color="k", ls="--", lw=1.0, label="target")
            ax.legend(fontsize=7)
        ax.set_xticks(range(len(vals)), names, rotation=60, fontsize=6)
        ax.set_title(title, fontsize=9)
    n_met = sum(all(v != "MISSED" for v in o["verdicts"].values()) for o in result["objects"].values())
    fig.suptitle(f"The display on {len(rows)} drawn objects (full graph, simulated clock, truth seed "
                 f"{result['truth_seed']}): {n_met}/{len(rows)} meet every target", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _ports_apart() -> list[str]:
    """``--set`` items that move the graph's TCP ports (its base port, the viewer's WebSocket, the controller
    twins') to free ones, so a run does not collide with another graph on this machine."""
    ctrl = {"left": free_port(), "right": free_port()}
    items = [f"base_port={free_port(span=32)}", f"viz.port={free_port()}"]
    for side, port in ctrl.items():
        items += [f"ctrl_{side}.port={port}", f"arm_{side}.port={port}"]
    return [a for kv in items for a in ("--set", kv)]


def _run(name: str, scene: Path | None, out: Path, truth_seed: int, launch: Path, extra: list[str],
         duration: float = DURATION) -> dict:
    """Run the graph on ``scene`` (None: the launch file's own) into ``out``: the figures, or
    ``{"error": …}``."""
    args = list(extra) + _ports_apart() + (["--set", f"scene={scene}"] if scene is not None else [])
    try:
        summary = run_seed(truth_seed, out, duration, launch, args)
    except RuntimeError as exc:
        log.warning(f"[objects] {name}: {exc}")
        return {"error": str(exc)}
    text = (out / "launch.log").read_text(errors="replace") if (out / "launch.log").exists() else ""
    bags = sorted(out.glob("*.mcap"))
    return measure_object(summary, bags[0] if bags else None, text)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flexsheet experiment objects", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: flexsheet experiment objects --draws 8 --reference "
                                        "--out docs/figures/objects\n"
                                        "         flexsheet experiment objects --first 3 --draws 1 --out "
                                        "/tmp/objects\n"
                                        "         flexsheet experiment objects --quick --out "
                                        "/tmp/objects_quick")
    ap.add_argument("--out", required=True, help="output folder (draw<k>/, objects.json, objects.png)")
    ap.add_argument("--draws", type=int, default=8, help="how many objects (default 8)")
    ap.add_argument("--first", type=int, default=0, help="seed of the first draw (default 0)")
    ap.add_argument("--truth-seed", type=int, default=0,
                    help="the twin's truth seed for every run (default 0)")
    ap.add_argument("--reference", action="store_true",
                    help="also run the paper's cylinder on the truth seed")
    ap.add_argument("--launch", default=str(launch_dir() / "sim.yaml"), help="launch file (clock: sim)")
    ap.add_argument("--set", action="append", default=[], metavar="NODE.KEY=VALUE",
                    help="a param override passed to each run (flexsheet launch --set)")
    ap.add_argument("--quick", action="store_true",
                    help=f"one draw, the 10 s stroke alone ({DURATION_10S:g} simulated s): felt 10 s, "
                         "landings, span and holds (no 30 s row, no press)")
    args = ap.parse_args(argv)
    duration = DURATION
    if args.quick:
        args.draws, duration, args.set = 1, DURATION_10S, [SCRIPT_10S, *args.set]
    if args.draws < 1:
        ap.error(f"--draws must be >= 1, got {args.draws}")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    out, launch = Path(args.out).resolve(), Path(args.launch).resolve()
    extra = [a for kv in args.set for a in ("--set", kv)]
    result: dict = {"truth_seed": args.truth_seed, "targets": TARGETS, "overrides": args.set,
                    "duration_s": duration, "objects": {}}
    if args.reference:
        print("[objects] the paper's cylinder (reference) ...", flush=True)
        result["cylinder"] = _run("cylinder", None, out / "cylinder", args.truth_seed, launch, extra,
                                  duration)
    cyl30 = _get(result, "cylinder", "felt_dtheta_deg", "30")
    for k in range(args.first, args.first + args.draws):
        path = write_scene(k, out / f"draw{k}")
        desc = path.read_text().splitlines()[0].lstrip("# ")
        print(f"[objects] draw {k} ({k - args.first + 1}/{args.draws}): {desc}", flush=True)
        m = _run(f"draw{k}", path, out / f"draw{k}", args.truth_seed, launch, extra, duration)
        if "error" not in m:
            m["verdicts"] = verdicts(m, cyl30)
            m["description"] = desc
            missed = [t for t, v in m["verdicts"].items() if v == "MISSED"]
            print(f"[objects] draw {k}: felt 30 s {m['felt_dtheta_deg']['30']}, within 15 % "
                  f"{m['force_within_15pct']}, span p99 {m['span_p99_mm']} mm, holds {m['bridge_holds']}; "
                  f"MISSED: {', '.join(missed) or 'none'}", flush=True)
        result["objects"][f"draw{k}"] = m
        (out / "objects.json").write_text(json.dumps(result, indent=1))     # after each draw: hours of runs
    good = {n: m for n, m in result["objects"].items() if "error" not in m}
    out.mkdir(parents=True, exist_ok=True)
    (out / "objects.json").write_text(json.dumps(result, indent=1))
    if not good:
        print("[objects] FAILED: no draw produced a report (see each draw's launch.log)", file=sys.stderr)
        return 1
    chart({**result, "objects": good}, out / "objects.png")
    print(f"[objects] wrote {out / 'objects.json'} and objects.png", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
