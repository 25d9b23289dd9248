"""``flexsheet experiment stroke --stability``: where the display breaks, on its own graph.

One error at a time, all else at the realistic twin's values, truth seed 0, the 10 s stroke of the paper on
the simulated-clock graph of ``launch/sim.yaml`` (:func:`flexsheet.experiments.graph_stroke.run_seed`); each
run's report gives the felt Δθ (the true finger against the true sheet). The errors:

* **camera noise** — the twin's image noise × ``noise_scale`` (camera param; 1 = the realistic camera);
* **delay** — the camera link's extra delay, exposure → frame in the graph (camera ``link_delay_s``): the
  estimator's prediction horizon stays at its default, so this is a delay the display does not know of;
* **marker loss** — the share of camera frames lost (camera ``drop_rate``);
* **arm-base error** — the estimators' ``display.yaml`` with both arm bases moved by ``scale`` × a fixed
  random 1 mm and 0.1° per axis (:func:`flexsheet.experiments.stability.perturb_bases`), written beside the
  runs and handed to the graph (``display_calib``); the truth's arms stay where they are.

The breaking point of an error is the smallest value at which the felt Δθ passes the paper's 0.359° (linear
interpolation, :func:`flexsheet.experiments.stability.breaking_point`), and where it passes the felt target; a
value the launch refuses (its row says why: the planner takes bases tilted ≤ 1° only) counts as broken.
Writes ``DIR/stability.json`` and ``DIR/stability.png`` (one panel per error: Δθ against the error, the
target and the paper's line, the breaking point marked) and each run under ``DIR/<error>_<value>/``.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from flexsheet.experiments.table1 import FELT_TARGET_FACTOR, PAPER_TABLE1, target

__all__ = ["SWEEPS", "run_stability", "chart"]

#: error → (label with units, values); the first value of each is the baseline (the realistic twin)
SWEEPS = {
    "noise_scale": ("camera image noise, x the realistic camera's", [1.0, 4.0, 8.0, 16.0]),
    "link_delay_ms": ("extra camera-link delay, ms", [0.0, 25.0, 50.0, 100.0, 200.0]),
    "drop_rate": ("camera frames lost, share", [0.0, 0.3, 0.6, 0.8]),
    "base_error": ("arm-base error, x (1 mm, 0.1 deg) per axis", [0.0, 4.0, 8.0, 16.0]),
}
#: the 10 s stroke alone, simulated seconds enough for it (start delay, approach, holds)
SCRIPT = "world.script=[{mode: stroke, moving_time: 10.0}]"
DURATION_S = 24.0


def _perturbed_calib(out: Path, scale: float, seed: int) -> Path:
    """The twin registration's display.yaml with both arm bases moved by ``scale`` (written under ``out``)."""
    from flexsheet.calibration.display_calib import load_display_calib, write_display_calib
    from flexsheet.experiments.stability import perturb_bases
    from flexsheet.twin.registration import sim_display_calib

    src = sim_display_calib(seed, "realistic")      # the launch's own twin registration (cached per seed)
    calib = load_display_calib(src)
    moved = perturb_bases({s: calib.arms[s].T_display_base for s in ("left", "right")}, scale, seed)
    for side in ("left", "right"):
        calib.arms[side] = replace(calib.arms[side], T_display_base=moved[side])
    path = out / f"display_base_error_{scale:g}.yaml"
    out.mkdir(parents=True, exist_ok=True)
    write_display_calib(str(path), calib)
    return path


def _sets(error: str, value: float, out: Path, seed: int) -> list[str]:
    if error == "noise_scale":
        return [f"camera.noise_scale={value:g}"]
    if error == "link_delay_ms":
        return [f"camera.link_delay_s={value / 1e3:g}"]
    if error == "drop_rate":
        return [f"camera.drop_rate={value:g}"]
    if error == "base_error":
        return [f"display_calib={_perturbed_calib(out, value, seed)}"] if value > 0 else []
    raise ValueError(f"unknown error {error!r}; errors: {', '.join(SWEEPS)}")


def run_stability(out: Path, launch: Path, seed: int = 0, sweeps: dict | None = None, log=print) -> dict:
    """Run every sweep (default :data:`SWEEPS`) into ``out``; returns and writes ``stability.json``."""
    from flexsheet.experiments.graph_stroke import run_seed
    from flexsheet.experiments.stability import breaking_point

    sweeps = sweeps or SWEEPS
    paper = PAPER_TABLE1["10"]["dtheta_mean_deg"]
    goal = target("10", FELT_TARGET_FACTOR)["dtheta_mean_deg"]
    res: dict = {"title": "Felt Δθ (10 s stroke) against one error at a time, on the simulated-clock graph",
                 "units": {"dtheta": "deg"}, "truth_seed": seed, "paper_dtheta_deg": paper,
                 "target_dtheta_deg": goal, "errors": {}}
    baseline = None
    for error, (label, values) in sweeps.items():
        rows = []
        for v in values:
            if v == values[0] and baseline is not None and error != "base_error":
                rows.append(dict(baseline, value=v))
                continue
            d = out / f"{error}_{v:g}"
            sets = [a for x in [SCRIPT, *_sets(error, v, out, seed)] for a in ("--set", x)]
            try:
                s = run_seed(seed, d, DURATION_S, launch, sets, log=log)
            except RuntimeError:            # refused at launch (a param check), else a failure to report
                lines = (d / "launch.log").read_text(errors="replace").splitlines()
                if not any("nothing started" in ln for ln in lines):
                    raise
                why = next((ln for ln in lines if "error" in ln.lower()), lines[-1] if lines else "")
                rows.append({"value": v, "dtheta_mean_deg": None, "n": 0, "refused": str(why)[:300]})
                log(f"[stability] {error} {v:g}: the launch refused it: {str(why)[:200]}")
                continue
            felt = s.get("table1", {}).get("felt", {}).get("10", {})
            row = {"value": v, "dtheta_mean_deg": felt.get("dtheta_mean_deg"), "n": felt.get("n", 0),
                   "angle3d_mean_deg": felt.get("angle3d_mean_deg"), "gap_mean_mm": felt.get("gap_mean_mm")}
            rows.append(row)
            if baseline is None and v == values[0]:
                baseline = row
            log(f"[stability] {error} {v:g}: felt dtheta {row['dtheta_mean_deg']}")
        x = [r["value"] for r in rows]
        y = [r["dtheta_mean_deg"] if r["dtheta_mean_deg"] is not None else float("inf") for r in rows]
        res["errors"][error] = {"label": label, "rows": rows,
                                "breaks_paper_at": breaking_point(x, y, paper),
                                "breaks_target_at": breaking_point(x, y, goal)}
    out.mkdir(parents=True, exist_ok=True)
    (out / "stability.json").write_text(json.dumps(res, indent=1))
    chart(res, out / "stability.png")
    return res


def chart(res: dict, path: Path) -> None:
    """One panel per error: felt Δθ against it, the target and the paper's lines, the breaking points."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    errs = res["errors"]
    fig, axes = plt.subplots(1, len(errs), figsize=(4.2 * len(errs), 4.2), squeeze=False)
    for ax, (name, e) in zip(axes[0], errs.items(), strict=True):
        x = [r["value"] for r in e["rows"]]
        y = [r["dtheta_mean_deg"] if r["dtheta_mean_deg"] is not None else np.nan for r in e["rows"]]
        ax.plot(x, y, "o-", label="felt Δθ, deg")
        ax.axhline(res["target_dtheta_deg"], color="g", ls="--", lw=0.9,
                   label=f"target {res['target_dtheta_deg']:.3f}°")
        ax.axhline(res["paper_dtheta_deg"], color="r", ls=":", lw=0.9, label=f"paper {res['paper_dtheta_deg']:.3f}°")
        for key, colour in (("breaks_target_at", "g"), ("breaks_paper_at", "r")):
            if e[key] is not None:
                ax.axvline(e[key], color=colour, lw=0.6)
        bp = e["breaks_paper_at"]
        verdict = f"breaks the paper at {bp:.3g}" if bp is not None else "never worse than the paper here"
        ax.set_title(f"{name}: {verdict}", fontsize=9)
        ax.set_xlabel(e["label"], fontsize=8)
        ax.set_ylabel("felt Δθ, deg (10 s stroke)")
        ax.legend(fontsize=7)
    fig.suptitle(res["title"], fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
