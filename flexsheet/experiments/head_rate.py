"""``flexsheet experiment head_rate --out DIR``: the head camera's frame rate, speed against what the eye
sees.

The head camera's twin renders the glasses and the tracker finds them in every frame, on the simulated
display's one loop: about a fifth of its CPU at 60 Hz. This runs ``flexsheet launch launch/sim.yaml`` once
per rate (``--set head_camera.rate_hz=R``, the scene and truth seed of the file, the whole run unless
``--duration``) and reads each run's ``summary.json``:

* the real-time factor (simulated s per wall s on this host; the speed);
* the view error (where the true eyes see the object's points against where they belong, projector px,
  tracked eyes; target ≤ 1 px median, ≤ 2 px p95) and the eye error (``/eye/pose`` against the true eyes,
  mm; target ≤ 2 mm median): what the viewer perceives;
* the keep-out's staleness: the fastest true head (``/world/head``) times a frame interval plus the
  eye's age at delivery, against the 0.01 m guard band the planner keeps beyond its margin for the eye's
  error; and the head guard's figures (keep-out violations, speed near the head) and the paper's Table I
  felt angle, to show what else the rate moves.

Writes ``DIR/head_rate.json`` and ``DIR/head_rate.png`` (view error, staleness and real-time factor against
the rate, the targets drawn). The verdict per rate is the view and eye errors and the staleness against their
targets; the chosen rate is the lowest that meets all of them. Timings mean something only on a quiet machine
(the load average is kept).
Each run's bag is deleted once read (``--keep`` keeps them under ``DIR/runs``).

Example: ``flexsheet experiment head_rate --out docs/figures/head_rate --rates 60 30 20``
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from flexsheet.planning.head_guard import GUARD_BAND
from flexsheet.runtime.bag_read import read_bag
from flexsheet.runtime.codec import decode
from messages import topics as T

__all__ = ["head_timing", "main", "row"]

TARGETS = {"view_error_px_median": 1.0, "view_error_px_p95": 2.0, "eye_error_mm_median": 2.0,
           "staleness_mm": GUARD_BAND * 1e3}


def head_timing(bag: Path) -> dict:
    """From a run's bag: the true head's fastest speed (``/world/head``, m/s: the judge's truth, never an
    estimator's input) and the median age of ``/eye/pose`` when it was delivered (log time − its mid-exposure
    stamp, s)."""
    speeds, ages = [], []
    for m in read_bag(bag, [T.HEAD_TRUTH.name, T.EYE_POSE.name]):
        if m.topic == T.HEAD_TRUTH.name:
            speeds.append(float(np.linalg.norm(decode(m.frames, T.HEAD_TRUTH).velocity)))
        else:
            ages.append(m.log_time - float(decode(m.frames, T.EYE_POSE).header.stamp))
    if not speeds or not ages:
        raise ValueError(f"{bag}: no /world/head or /eye/pose recorded")
    return {"head_speed_max_mps": max(speeds), "eye_age_s": float(np.median(ages))}


def row(rate_hz: float, summary: dict, timing: dict) -> dict:
    """One rate's figures from a run's ``summary.json`` (dict) and :func:`head_timing`, with its verdict
    against :data:`TARGETS`. ``staleness_mm``: how far the fastest true head moves while the planner's
    keep-out holds one tracked eye (a frame interval plus the eye's age), against the keep-out's guard band
    (:data:`flexsheet.planning.head_guard.GUARD_BAND`), which the planner keeps for the eye's error."""
    view = summary["view"]["tracked"]
    eye = summary["eye"]["error_mm"]
    safety = summary["safety"]
    felt30 = summary["headline"]["rows"].get("30", {})
    out = {"rate_hz": float(rate_hz), "realtime_factor": float(summary["realtime_factor"]),
           "view_error_px_median": float(view["error_px_median"]),
           "view_error_px_p95": float(view["error_px_p95"]),
           "eye_error_mm_median": float(eye["median"]), "eye_frames": int(eye["n"]),
           "keepout_violations": int(safety["keepout_violations"]),
           "max_speed_near_head_mps": float(safety["max_speed_near_head_mps"]),
           "table1_felt_30s_deg": felt30.get("dtheta_mean_deg"),
           "head_speed_max_mps": timing["head_speed_max_mps"], "eye_age_ms": timing["eye_age_s"] * 1e3,
           "staleness_mm": timing["head_speed_max_mps"] * (1.0 / rate_hz + timing["eye_age_s"]) * 1e3}
    out["verdict"] = "met" if all(out[k] <= v for k, v in TARGETS.items()) else "MISSED"
    return out


def _chart(out: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = out["rows"]
    r = [x["rate_hz"] for x in rows]
    fig, ax = plt.subplots(1, 3, figsize=(12, 3.5))
    ax[0].plot(r, [x["view_error_px_median"] for x in rows], "o-", label="median")
    ax[0].plot(r, [x["view_error_px_p95"] for x in rows], "s-", label="p95")
    ax[0].axhline(TARGETS["view_error_px_median"], color="r", ls="--", lw=1, label="target: median ≤ 1 px")
    ax[0].axhline(TARGETS["view_error_px_p95"], color="r", ls=":", lw=1, label="target: p95 ≤ 2 px")
    ax[0].set_xlabel("head camera rate (Hz)")
    ax[0].set_ylabel("view error, tracked eyes (projector px)")
    ax[0].legend(fontsize=7)
    ax[1].plot(r, [x["staleness_mm"] for x in rows], "o-")
    ax[1].axhline(TARGETS["staleness_mm"], color="r", ls="--", lw=1, label="guard band 10 mm")
    ax[1].set_xlabel("head camera rate (Hz)")
    ax[1].set_ylabel("keep-out staleness, fastest head (mm)")
    ax[1].legend(fontsize=7)
    ax[2].plot(r, [x["realtime_factor"] for x in rows], "o-")
    ax[2].set_xlabel("head camera rate (Hz)")
    ax[2].set_ylabel("real-time factor (simulated s / wall s)")
    fig.suptitle(f"{out['title']}: chosen {out['chosen_rate_hz']} Hz", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flexsheet experiment head_rate", description=__doc__.splitlines()[0],
                                 epilog="example: flexsheet experiment head_rate --out "
                                        "docs/figures/head_rate --rates 60 30 20",
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, type=Path, help="folder for head_rate.json and head_rate.png")
    ap.add_argument("--rates", nargs="+", type=float, default=[60.0, 30.0, 20.0],
                    help="head camera rates, Hz")
    ap.add_argument("--file", default="launch/sim.yaml", help="the launch file (default launch/sim.yaml)")
    ap.add_argument("--duration", type=float, default=None, help="simulated seconds (default: the whole run)")
    ap.add_argument("--set", action="append", default=[], metavar="NODE.KEY=VALUE",
                    help="passed to each launch")
    ap.add_argument("--keep", action="store_true", help="keep each run's output under OUT/runs")
    a = ap.parse_args(argv)
    if not a.rates or any(not 0.0 < r <= 240.0 for r in a.rates):
        ap.error(f"--rates: each in (0, 240] Hz, got {a.rates}")
    a.out.mkdir(parents=True, exist_ok=True)
    load = os.getloadavg()
    rows = []
    for rate in a.rates:
        run = a.out / "runs" / f"{rate:g}hz"
        shutil.rmtree(run, ignore_errors=True)
        cmd = [sys.executable, "-m", "flexsheet", "launch", a.file, "--out", str(run),
               "--set", f"head_camera.rate_hz={rate:g}", *sum((["--set", s] for s in a.set), [])]
        if a.duration is not None:
            cmd += ["--duration", f"{a.duration:g}"]
        print(f"[head_rate] {rate:g} Hz: {' '.join(cmd[2:])}", file=sys.stderr, flush=True)
        proc = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        summary = run / "summary.json"
        if proc.returncode != 0 or not summary.exists():
            print(proc.stderr[-2000:], file=sys.stderr)
            print(f"[head_rate] {rate:g} Hz: the launch exited {proc.returncode} without a "
                  "summary", file=sys.stderr)
            return 1
        rows.append(row(rate, json.loads(summary.read_text()), head_timing(run / "sim.mcap")))
        print(f"[head_rate] {rate:g} Hz: " + json.dumps(rows[-1]), file=sys.stderr, flush=True)
        if not a.keep:
            shutil.rmtree(run, ignore_errors=True)
    if not a.keep:
        shutil.rmtree(a.out / "runs", ignore_errors=True)
    met = [x["rate_hz"] for x in rows if x["verdict"] == "met"]
    out = {"title": "Head camera rate: real-time factor against the view error", "file": a.file, "set": a.set,
           "duration_s": a.duration,
           "units": {"rate_hz": "Hz", "view_error": "projector px", "eye_error": "mm", "staleness": "mm",
                     "realtime_factor": "sim s / wall s", "speed": "m/s", "age": "ms", "table1": "deg"},
           "targets": TARGETS, "load_average_before": [round(x, 2) for x in load], "rows": rows,
           "chosen_rate_hz": min(met) if met else None,
           "verdict": "met" if met else "MISSED"}
    (a.out / "head_rate.json").write_text(json.dumps(out, indent=1) + "\n")
    _chart(out, a.out / "head_rate.png")
    print(f"[head_rate] wrote {a.out / 'head_rate.json'} and head_rate.png; chosen {out['chosen_rate_hz']} "
          "Hz")
    return 0


if __name__ == "__main__":
    sys.exit(main())
