"""The whole display registration on many drawn truths, in the twin: how often each target is met.

One seed says little about a target that a bad draw of the as-built display can miss. This runs the full
preset (``flexsheet.calibration.procedures.FULL``) on each truth seed, scores it against that seed's hidden
truth (:func:`flexsheet.twin.registration.run_display_sim`) and writes ``OUT/draws.json``: per seed the
errors, and per target the median, the worst and the seeds that miss it; ``OUT/draws.png`` charts each error
against its target (matplotlib Agg), with the same numbers. Run by
``flexsheet calibrate display --draws 40 --out docs/figures/calibration/draws``.

Units: mm, degrees, projector px.
"""

from __future__ import annotations

import json
import logging
import os
import random

import numpy as np

from flexsheet.calibration.procedures import FULL, QUICK
from flexsheet.twin.registration import TARGETS, run_display_sim, verdicts

log = logging.getLogger(__name__)

__all__ = ["draw_seeds", "run_draws"]

#: (summary path, target key, label) of each figure judged
FIGURES = (("camera.translation_error_mm", "camera_mm", "camera position, mm"),
           ("camera.rotation_error_deg", "camera_deg", "camera rotation, deg"),
           ("projector.translation_error_mm", "projector_mm", "projector position, mm"),
           ("projector.rotation_error_deg", "projector_deg", "projector rotation, deg"),
           ("projector.reprojection_px", "projector_px", "projector reprojection, px"),
           ("arms.left.translation_error_mm", "arms_mm", "left arm base, mm"),
           ("arms.right.translation_error_mm", "arms_mm", "right arm base, mm"))


def draw_seeds(n: int, draw: int) -> list[int]:
    """``n`` distinct truth seeds in 10…99 999, drawn by ``random.Random(draw)`` (recorded, so a chart can be
    redrawn). Raises ``ValueError`` for n < 1."""
    if n < 1:
        raise ValueError(f"draws must be >= 1, got {n!r}")
    return random.Random(int(draw)).sample(range(10, 100_000), int(n))


def _get(s: dict, path: str) -> float:
    for k in path.split("."):
        s = s[k]
    return float(s)


def run_draws(seeds: list[int], out_dir: str, quick: bool = False, realism: str = "realistic",
              draw: int | None = None) -> dict:
    """Register the display in the twin of each of ``seeds`` (per-seed folders ``out_dir/seed<N>``, cached as
    ``--sim`` caches) and write ``out_dir/draws.json`` and ``out_dir/draws.png``. Returns the JSON dict:
    ``seeds``, ``draw`` (the seed of :func:`draw_seeds`, or None), ``preset``, ``targets``, ``per_seed``
    {seed: {figure: value}}, ``figures`` {figure: {median, p90, worst, worst_seed, target, misses: [seeds],
    met_share}}. Raises ``ValueError`` on an empty seed list."""
    if not seeds:
        raise ValueError("need at least one seed")
    os.makedirs(out_dir, exist_ok=True)
    opts = QUICK if quick else FULL
    per: dict[str, dict] = {}
    for i, seed in enumerate(seeds, 1):
        s = run_display_sim(int(seed), os.path.join(out_dir, f"seed{int(seed)}"), opts, realism)
        per[str(seed)] = {path: _get(s, path) for path, _, _ in FIGURES}
        bad = [k for k, ok in verdicts(s).items() if not ok]
        log.info(f"draws: {i}/{len(seeds)} seed {seed}: "
                 + ("all met" if not bad else "MISSED " + ", ".join(bad)))
    figs = {}
    for path, key, label in FIGURES:
        v = np.array([per[str(s)][path] for s in seeds])
        miss = [int(s) for s, x in zip(seeds, v, strict=True) if x > TARGETS[key]]
        k = int(np.argmax(v))
        figs[path] = {"label": label, "median": float(np.median(v)), "p90": float(np.percentile(v, 90)),
                      "worst": float(v[k]), "worst_seed": int(seeds[k]), "target": TARGETS[key],
                      "misses": miss,
                      "met_share": 1.0 - len(miss) / len(seeds),
                      "verdict": "met" if not miss else f"MISSED on {len(miss)} of {len(seeds)}"}
    doc = {"seeds": [int(s) for s in seeds], "draw": draw, "realism": realism,
           "preset": "quick" if quick else "full",
           "targets": dict(TARGETS), "per_seed": per, "figures": figs}
    with open(os.path.join(out_dir, "draws.json"), "w") as fh:
        json.dump(doc, fh, indent=1)
    _plot(doc, os.path.join(out_dir, "draws.png"))
    log.info(f"wrote {out_dir}/draws.json, {out_dir}/draws.png")
    return doc


def _plot(doc: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figs = doc["figures"]
    fig, axes = plt.subplots(1, len(figs), figsize=(2.1 * len(figs), 4.2))
    for ax, (fpath, f) in zip(axes, figs.items(), strict=True):
        v = [doc["per_seed"][str(s)][fpath] for s in doc["seeds"]]
        x = np.random.default_rng(0).uniform(-0.15, 0.15, len(v))
        ax.scatter(x, v, s=10, c=["C3" if y > f["target"] else "C0" for y in v])
        ax.axhline(f["target"], color="k", ls=":", lw=1)
        ax.set_xlim(-0.5, 0.5)
        ax.set_xticks([])
        ax.set_title(f"{f['label']}\n{f['verdict']}", fontsize=8)
        ax.set_ylim(0, max(max(v), f["target"]) * 1.15)
        ax.grid(True, axis="y", alpha=0.3)
    fig.suptitle(f"Display registration over {len(doc['seeds'])} drawn truths ({doc['preset']} preset, "
                 f"{doc['realism']}): each error against its target (dotted)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
