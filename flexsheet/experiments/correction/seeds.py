"""The seeds table (``seeds.json`` + ``seeds.png``: the headline numbers of each (realism, seed) run side by
side) and, with the speed timing, each model's accuracy against its speed
(``accuracy_vs_speed.{json,png}``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from flexsheet.experiments.correction.settings import PIXEL


def aggregate(out: Path, runs: dict, speed: dict | None = None) -> dict:
    """``out/seeds.json`` + ``out/seeds.png``: the headline numbers of each (realism, seed) run side by
    side."""
    doc: dict = {"target_mm": PIXEL * 1e3, "runs": {}}
    for key, s in runs.items():
        doc["runs"][key] = {
            "realism": s["twin"]["realism"], "truth_seed": s["twin"]["truth_seed"],
            "truth_sheet": s["twin"]["truth_sheet"],
            "registration_errors": s["estimator"].get("registration_errors"),
            "inclined":
                {k: {f: r[f] for f in ("uncorrected_mm", "corrected_mm", "corrected_position_mm", "model")}
                 for k, r in s["inclined"].items()},
            "pushed":
                {k: {f: r[f] for f in r if f.endswith("_mm") and not f.endswith(("sizes_mm", "contact_mm"))}
                 | {"model": r["model"]} for k, r in s["pushed"].items()},
            "headline": s["headline"]}
    if speed:
        doc["stereo_pair_ms"] = speed
    (out / "seeds.json").write_text(json.dumps(doc, indent=1))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
    for key, s in runs.items():
        ls = "-" if s["twin"]["realism"] == "realistic" else ":"
        th = [float(k) for k in s["inclined"]]
        ax[0].plot(th, [max(r["corrected_mm"], 0.01) for r in s["inclined"].values()], ls + "o",
                   label=f"{key} corrected")
        ds = [float(k) for k in s["pushed"]]
        ax[1].plot(ds, [max(r["corrected_mm"], 0.01) for r in s["pushed"].values()], ls + "o",
                   label=f"{key} picked model")
        if "fine_mm" in next(iter(s["pushed"].values())):
            ax[1].plot(ds, [r["fine_mm"] for r in s["pushed"].values()], ls + "x", alpha=0.5,
                       label=f"{key} series fine (old)")
    for a, t in ((ax[0], "Fig. 11: inclined sheet, flat correction"), (ax[1], "Fig. 13: pushed sheet")):
        a.axhline(0.7, color="grey", lw=0.8, ls="--", label="target: 1 projector pixel")
        a.set_yscale("log")
        a.set_ylim(0.01, 10)
        a.set_title(t + " (solid: realistic twin, dotted: ideal)", fontsize=9)
        a.set_ylabel("mean absolute size error [mm]")
        a.legend(fontsize=6, ncol=2)
    ax[0].set_xlabel("θ [deg]")
    ax[1].set_xlabel("S [mm]")
    fig.tight_layout()
    fig.savefig(out / "seeds.png", dpi=110)
    plt.close(fig)
    if speed:
        _accuracy_vs_speed(out, runs, speed)
    return doc


def _accuracy_vs_speed(out: Path, runs: dict, speed: dict) -> None:
    """``accuracy_vs_speed.{json,png}``: each model's stereo-pair time against its error at the largest θ and
    S (mean over the realistic runs)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    real = [s for s in runs.values() if s["twin"]["realism"] == "realistic"] or list(runs.values())
    tmax = max(real[0]["inclined"], key=float)
    dmax = max(real[0]["pushed"], key=float)

    def mean(f):
        return float(np.mean([f(s) for s in real]))

    pts = {"none": (mean(lambda s: s["inclined"][tmax]["uncorrected_mm"]),
                    mean(lambda s: s["pushed"][dmax]["uncorrected_mm"])),
           "flat": (mean(lambda s: s["inclined"][tmax]["corrected_mm"]),
                    mean(lambda s: s["pushed"][dmax]["uncorrected_mm"])),
           "four_triangle": (None, mean(lambda s: s["pushed"][dmax]["four_triangle_mm"])),
           "fine": (None, mean(lambda s: s["pushed"][dmax]["fine_mm"]))}
    if "fem_nominal" in speed and "fem_nominal_mm" in real[0]["pushed"][dmax]:
        pts["fem_nominal"] = (None, mean(lambda s: s["pushed"][dmax]["fem_nominal_mm"]))
    doc = {m: {"stereo_pair_ms": speed[m], f"inclined_{tmax}_error_mm": ei, f"pushed_{dmax}_error_mm": ep}
           for m, (ei, ep) in pts.items()}
    doc["gl_renderer"] = speed.get("gl_renderer", "?")
    doc["runs"] = sorted(k for k, s in runs.items() if s in real)
    (out / "accuracy_vs_speed.json").write_text(json.dumps(doc, indent=1))
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for m, (ei, ep) in pts.items():
        ax.plot(speed[m], max(ep, 0.01), "o", ms=9, label=f"{m}: pushed S={dmax} mm")
        if ei is not None:
            ax.plot(speed[m], max(ei, 0.01), "s", ms=6, mfc="none", label=f"{m}: inclined θ={tmax}°")
    ax.axhline(0.7, color="grey", lw=0.8, ls=":", label="target: 1 pixel (0.7 mm)")
    ax.axvline(1000 / 120, color="red", lw=0.8, ls=":", label="120 Hz budget (8.3 ms)")
    ax.set_xlabel(f"time per stereo pair, 2×1024×768 [ms] ({doc['gl_renderer'].split('(')[0].strip()})")
    ax.set_ylabel("mean absolute size error [mm], realistic twin")
    ax.set_yscale("log")
    ax.set_ylim(0.01, 50)
    ax.set_title("Correction models: accuracy against speed", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "accuracy_vs_speed.png", dpi=110)
    plt.close(fig)
