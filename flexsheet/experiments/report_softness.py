"""What the finger feels against what the object asks, from a run's bag (pure; no transport).

The world publishes the finger's true contact with the true sheet (``/world/contact``, ``ContactTruth``: depth
and force, N, from the truth's sheet FEM table at the true depth, never a model of the planner's); the virtual object's force at the display's
measured fingertip is the FEM node's ``ObjectDeformation.contact_force``. Their ratio, sample by sample while the
finger presses, is the presented softness error a person could notice: a stiffness (or force-at-depth)
difference under the Weber fraction of about 15 % goes unnoticed (Bergmann Tiest & Kappers, IEEE Trans.
Haptics 2:189, 2009, with the surface-deformation cue present).

Units: N, m, N/m; stamps s.
"""

from __future__ import annotations

import numpy as np

from flexsheet.experiments.report_timing import planner_scales, scales_at

__all__ = ["WEBER_FRACTION", "MIN_DEPTH", "felt_force"]

#: a force or stiffness ratio within 1 ± this goes unnoticed (Bergmann Tiest & Kappers 2009)
WEBER_FRACTION = 0.15
#: pushes shallower than this (m) are not judged: the fingertip grazes the sheet, and a force of a few mN
#: divides into a meaningless ratio
MIN_DEPTH = 0.002
#: an object force sample is paired with a sheet sample at most this long (s) after its fingertip's exposure
MAX_GAP = 0.1


def felt_force(d: dict[str, list], scales: list[tuple[float, float]] | None = None) -> dict:
    """Pair each ``/world/contact`` sample pressed at least :data:`MIN_DEPTH` deep with the newest
    ``/object/deformation`` whose fingertip was exposed at most :data:`MAX_GAP` s before it (object force > 0),
    and compare the sheet's true force with the object's times the planner's ``stiffness_scale`` in force when
    the sheet sample arrived: ``scales`` [(arrival s, scale)] (None: from the planner's heartbeats in ``d``,
    :func:`~flexsheet.experiments.report_timing.planner_scales`; 1 without any).

    ``d``: topic → [(log time, message)]. Returns ``{}`` without pressed samples, else ``{"n", "ratio"`` (felt /
    requested: median, p5, p95), ``"within_weber"`` (share of samples with |ratio − 1| ≤ 15 %),
    ``"felt_n"`` and ``"requested_n"`` (force medians, N), ``"felt_stiffness_n_per_m"`` (median secant force /
    depth of the true sheet), ``"target"``, ``"verdict"`` ("met" when the median ratio is within 1 ± 15 %)}``.
    Raises ``ValueError`` for a non-positive scale."""
    scales = planner_scales(d) if scales is None else list(scales)
    bad = [s for _, s in scales if not s > 0.0]
    if bad:
        raise ValueError(f"stiffness scale must be > 0, got {bad[0]!r}")
    pressed = [(t, m) for t, m in d.get("/world/contact", []) if m.depth >= MIN_DEPTH and m.force > 0.0]
    scale = np.nan_to_num(scales_at(scales, np.array([t for t, _ in pressed])), nan=1.0)
    sheets = [m for _, m in pressed]
    defs = sorted((m for _, m in d.get("/object/deformation", []) if m.contact_force > 0.0),
                  key=lambda m: m.source_stamp)
    if not sheets or not defs:
        return {}
    ds = np.array([m.source_stamp for m in defs])
    felt, req, depth = [], [], []
    for s, sc in zip(sheets, scale, strict=True):
        k = int(np.searchsorted(ds, s.header.stamp, side="right")) - 1
        if k < 0 or s.header.stamp - ds[k] > MAX_GAP:
            continue
        felt.append(s.force)
        req.append(defs[k].contact_force * float(sc))
        depth.append(s.depth)
    if not felt:
        return {}
    felt_a, req_a = np.array(felt), np.array(req)
    ratio = felt_a / req_a
    med = float(np.median(ratio))
    return {"n": len(felt), "ratio": {"median": med, "p5": float(np.percentile(ratio, 5)),
                                      "p95": float(np.percentile(ratio, 95))},
            "within_weber": float(np.mean(np.abs(ratio - 1.0) <= WEBER_FRACTION)),
            "felt_n": float(np.median(felt_a)), "requested_n": float(np.median(req_a)),
            "felt_stiffness_n_per_m": float(np.median(felt_a / np.array(depth))),
            "target": f"median felt/requested force within 1 ± {WEBER_FRACTION:.2f} (Weber fraction, Bergmann "
                      "Tiest & Kappers 2009)",
            "verdict": "met" if abs(med - 1.0) <= WEBER_FRACTION else "MISSED"}
