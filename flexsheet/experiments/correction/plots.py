"""One run's figures: Fig. 11 (``fig11_inclined.png``), Fig. 13 (``fig13_pushed.png``) and the measurement
camera's photographs at θ = 50° and S = 50 mm (``photos.png``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def run_charts(out: Path, s: dict, thetas, depths, photos) -> None:
    """Draw one run's figures into ``out`` (module doc) from its summary ``s``, the inclined angles ``thetas``
    (deg), the push ``depths`` (mm) and the measurement camera's ``photos``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tw = f"{s['twin']['realism']} twin, truth seed {s['twin']['truth_seed']}"
    _fig11(plt, out, s, thetas, tw)
    _fig13(plt, out, s, depths, tw)
    _photos(plt, out, photos)


def _fig11(plt, out: Path, s: dict, thetas, tw: str) -> None:
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for size, mk in (("h", "o"), ("u", "s"), ("d", "^")):
        ax.plot(thetas, [max(s["inclined"][f"{t:g}"]["uncorrected_sizes_mm"][size], 0.01) for t in thetas],
                "--" + mk, label=f"Δ{size} uncorrected")
        ax.plot(thetas, [max(s["inclined"][f"{t:g}"]["corrected_sizes_mm"][size], 0.01) for t in thetas],
                "-" + mk, label=f"Δ{size} corrected (picked model)")
    ax.axhline(0.7, color="grey", lw=0.8, ls=":", label="1 projector pixel (0.7 mm)")
    ax.plot([50], [27.5], "k*", ms=12, label="paper θ=50° uncorrected mean")
    ax.plot([50], [2.1], "r*", ms=12, label="paper θ=50° corrected mean")
    ax.set_xlabel("sheet inclination θ [deg]")
    ax.set_ylabel("absolute size error [mm]")
    ax.set_title(f"Fig. 11 on the {tw}", fontsize=9)
    ax.set_yscale("log")
    ax.set_ylim(0.01, 50)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "fig11_inclined.png", dpi=110)
    plt.close(fig)


def _fig13(plt, out: Path, s: dict, depths, tw: str) -> None:
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    names = [n for n in ("uncorrected", "four_triangle", "fine", "fem_nominal")
             if f"{n}_mm" in s["pushed"][f"{depths[0]:g}"]]
    for name in names:
        ax.plot(depths, [max(s["pushed"][f"{d:g}"][f"{name}_mm"], 0.01) for d in depths],
                "--o" if name == "uncorrected" else "-o", label=f"{name} (mean of Δh, Δw)")
    ax.plot(depths, [max(s["pushed"][f"{d:g}"]["corrected_mm"], 0.01) for d in depths], "k-", lw=4,
            alpha=0.25,
            label="picked by the renderer")
    ax.axhline(0.7, color="grey", lw=0.8, ls=":", label="1 projector pixel (0.7 mm)")
    ax.plot([50], [15.8], "k*", ms=12, label="paper S=50 uncorrected mean")
    ax.plot([50], [2.1], "r*", ms=12, label="paper S=50 4-triangle mean")
    ax.set_xlabel("push depth S [mm]")
    ax.set_ylabel("mean absolute size error [mm]")
    ax.set_title(f"Fig. 13 on the {tw} (true sheet: FEM)", fontsize=9)
    ax.set_yscale("log")
    ax.set_ylim(0.01, 50)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "fig13_pushed.png", dpi=110)
    plt.close(fig)


def _photos(plt, out: Path, photos: dict) -> None:
    keys = [k for k in photos if k.startswith(("inclined_50", "pushed_50"))][:6]
    if keys:
        fig, axes = plt.subplots(1, len(keys), figsize=(3 * len(keys), 2.8))
        for a, k in zip(np.atleast_1d(axes), keys, strict=False):
            a.imshow(photos[k], cmap="gray", vmin=0, vmax=1)
            a.set_title(k, fontsize=8)
            a.axis("off")
        fig.tight_layout()
        fig.savefig(out / "photos.png", dpi=90)
        plt.close(fig)
