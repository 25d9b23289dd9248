"""The chart of ``flexsheet experiment stroke_model`` (:mod:`flexsheet.experiments.stroke_model`): Table I's
rows of the in-process model against the paper's and the target (matplotlib Agg PNG; mm and deg labelled)."""

from __future__ import annotations

from pathlib import Path

from flexsheet.analysis.table1 import PAPER_TABLE1, TARGET_FACTOR, target

__all__ = ["plot"]


def plot(chart: dict, summary: dict, path: Path) -> None:
    """Table I's rows of ``chart`` and ``summary`` (:func:`flexsheet.experiments.stroke_model.run`) to
    ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    for key, style in (("prediction", "o-"), ("no_prediction", "s--")):
        lbl = key.replace("_", " ")
        rows = chart["by_time"][key]
        ax[0, 0].plot(chart["moving_time_s"], [r["dtheta_mean_deg"] for r in rows], style, label=lbl)
        ax[1, 0].plot(chart["moving_time_s"], [r["dd_2r_mean_mm"] for r in rows], style,
                      label=f"{lbl}, Δd 2R")
        ax[1, 0].plot(chart["moving_time_s"], [r["dd_mean_mm"] for r in rows], style, alpha=0.4,
                      label=f"{lbl}, Δd R")
        rows = chart["by_latency"][key]
        ax[0, 1].plot(chart["latency_ms"], [r["dtheta_mean_deg"] for r in rows], style, label=lbl)
        ax[1, 1].plot(chart["latency_ms"], [r["dd_2r_mean_mm"] for r in rows], style, label=f"{lbl}, Δd 2R")
    for T, mk in (("10", "*"), ("30", "P")):
        ax[0, 0].plot(float(T), PAPER_TABLE1[T]["dtheta_mean_deg"], mk, color="k", ms=12,
                      label=f"paper {T} s")
        ax[1, 0].plot(float(T), PAPER_TABLE1[T]["dd_mean_mm"], mk, color="k", ms=12,
                      label=f"paper {T} s (2R)")
        ax[0, 0].plot(float(T), summary["ideal"][T]["dtheta_mean_deg"], "x", color="g", ms=10,
                      label=f"ideal twin {T} s (3 seeds)")
        ax[0, 0].plot(float(T), summary[T]["dtheta_mean_deg"], "d", color="m", ms=9,
                      label=f"realistic twin {T} s (3 seeds)")
    for T in ("10", "30"):
        ax[0, 0].axhline(target(T)["dtheta_mean_deg"], color="r", lw=0.8, ls=":",
                         label=f"target {T} s (paper / {TARGET_FACTOR:g})")
    ax[0, 0].axhline(summary["noise_floor"]["dtheta_floor_deg"], color="gray", lw=0.8, ls="-.",
                     label="floor: measured D's noise alone")
    for a in (ax[0, 1], ax[1, 1]):
        a.axvline(summary["latency_budget_ms"], color="gray", lw=0.8, ls=":", label="budget")
    ax[0, 0].set(xlabel="moving time 0→60° [s]", ylabel="mean Δθ [deg]", yscale="log",
                 title="Δθ vs moving time")
    ax[1, 0].set(xlabel="moving time 0→60° [s]", ylabel="mean Δd [mm]", yscale="log",
                 title="Δd vs moving time (2R: paper's convention; R: chord)")
    ax[0, 1].set(xlabel="loop latency exposure→sheet [ms]", ylabel="mean Δθ [deg]",
                 title="Δθ vs latency (10 s)")
    ax[1, 1].set(xlabel="loop latency exposure→sheet [ms]", ylabel="mean Δd 2R [mm]",
                 title="Δd vs latency (10 s)")
    for a in ax.flat:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=6)
    fig.suptitle("Stroking the paper's cylinder, in-process on the realistic twin (truth seed 0; markers: 3 "
                 "seeds)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
