"""Stability where the sheet model fails: the pushed error against an error in the true sheet the estimator
cannot see (tension ratio, pre-strain; :func:`sweep_sheet`), and the breaking point where an error passes one
projector pixel (:func:`flexsheet.experiments.stability.breaking_point`)."""

from __future__ import annotations

import dataclasses
import logging

from flexsheet.experiments.correction.estimator import DisplayEstimator
from flexsheet.experiments.correction.measurer import Measurer
from flexsheet.experiments.correction.settings import MODEL_LABELS, PIXEL
from flexsheet.experiments.correction.sweeps import measure_pushed
from flexsheet.experiments.correction.twin_world import TwinWorld
from flexsheet.experiments.stability import breaking_point
from flexsheet.twin.truth import TwinTruth

log = logging.getLogger(__name__)

#: true tension ratios (the estimator assumes β = 1; the truth's spread is log-normal 20 %)
TENSION_FACTORS = (0.3, 0.5, 0.7, 0.85, 1.0, 1.2, 1.4, 2.0, 3.0)
#: true pre-strains (the estimator assumes 0; the truth's spread is |N(0, 0.5 %)|)
PRESTRAINS = (0.0, 0.005, 0.01, 0.02, 0.04)


def sweep_sheet(est: DisplayEstimator, truth: TwinTruth, meas: Measurer, kind: str, values=None,
                depth_mm: float = 50.0, quick: bool = False) -> dict:
    """Pushed error (``depth_mm``) of every model against an error in the true sheet the estimator cannot see:
    ``kind`` ``tension_ratio`` — the true β = value × the estimator's assumed β (1.0); ``prestrain`` — the
    true pre-strain = value (the estimator assumes 0; the same as an error in the clamp strain it measures).
    The truth's other values are kept (one FEM table per value). The breaking point is where the renderer's
    picked model passes one projector pixel, going away from the assumption on each side."""
    if kind == "tension_ratio":
        values = values or ((0.5, 1.0, 2.0) if quick else TENSION_FACTORS)
        assumed = 1.0
    elif kind == "prestrain":
        values = values or ((0.0, 0.02) if quick else PRESTRAINS)
        assumed = 0.0
    else:
        raise ValueError(f"kind must be 'tension_ratio' or 'prestrain', got {kind!r}")
    models = ("none", "four_triangle", "fine", "fem_nominal")
    rows = []
    for x in values:
        t = dataclasses.replace(truth, **({"tension_ratio": float(x)} if kind == "tension_ratio"
                                          else {"sheet_prestrain": float(x)}))
        r = measure_pushed(est, TwinWorld(t), meas, depth_mm, models)
        rows.append({"value": float(x),
                     **{MODEL_LABELS[m] + "_mm": r[MODEL_LABELS[m] + "_mm"] for m in models},
                     "picked": r["model"], "corrected_mm": r["corrected_mm"]})
        log.info(f"[correction] stability: true {kind} {x:g}: picked {r['model']} {r['corrected_mm']:.2f} mm")
    lim = PIXEL * 1e3
    out: dict = {"kind": kind, "depth_mm": depth_mm, "assumed": assumed, "rows": rows, "criterion_mm": lim}
    for m in ("corrected", *[MODEL_LABELS[m] for m in models]):
        if kind == "tension_ratio":          # distance from the assumption as a factor, both ways
            up = sorted((r["value"], r[f"{m}_mm"]) for r in rows if r["value"] >= assumed)
            down = sorted((1.0 / r["value"], r[f"{m}_mm"]) for r in rows if r["value"] <= assumed)
            hi = breaking_point(*zip(*up, strict=True), lim) if up else None
            lo = breaking_point(*zip(*down, strict=True), lim) if down else None
            out[f"{m}_breaks_at"] = {"above": hi, "below": None if lo is None else 1.0 / lo}
        else:
            up = sorted((r["value"], r[f"{m}_mm"]) for r in rows)
            out[f"{m}_breaks_at"] = {"above": breaking_point(*zip(*up, strict=True), lim)}
    return out
