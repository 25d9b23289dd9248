"""The figures' sweeps: one point of Fig. 11's inclined sheet (:func:`measure_inclined`) and of Fig. 13's
pushed sheet (:func:`measure_pushed`), the estimator's image photographed on the true sheet, and the sweeps
over θ and S (:func:`sweep_inclined`, :func:`sweep_pushed`)."""

from __future__ import annotations

import logging

import numpy as np

from flexsheet.experiments.correction.estimator import DisplayEstimator
from flexsheet.experiments.correction.measurer import Measurer
from flexsheet.experiments.correction.poses import HOME_POSE, inclined_pose
from flexsheet.experiments.correction.settings import MODEL_LABELS
from flexsheet.experiments.correction.twin_world import TwinWorld
from flexsheet.model.sheet import SheetSurface

log = logging.getLogger(__name__)


def _pose_dev(world_info: dict, est: SheetSurface) -> dict:
    dn = float(np.degrees(np.arccos(np.clip(world_info["normal"] @ est.normal, -1.0, 1.0))))
    return {"sheet_origin_error_mm": float(np.linalg.norm(world_info["origin"] - est.origin) * 1e3),
            "sheet_normal_error_deg": dn}


def measure_inclined(est: DisplayEstimator, world: TwinWorld, meas: Measurer, theta: float,
                     photos: dict | None = None, direction: str = "down") -> dict:
    """Fig. 11 at inclination ``theta`` deg: the uncorrected image and the picked model's, on the true
    sheet."""
    q = est.joints(*inclined_pose(theta, direction))
    sheet = est.sheet(q)
    true, info = world.sheet(q)
    picked = est.pick(sheet)
    row: dict = {"model": picked, **_pose_dev(info, sheet)}
    for name, model in (("uncorrected", "none"), ("corrected", picked)):
        ph = meas.shoot(est.draw(model, sheet), world, true)
        e = meas.errors(ph, "hud")
        row[f"{name}_mm"], row[f"{name}_sizes_mm"], row[f"{name}_position_mm"] = (e["mean_mm"], e["sizes_mm"],
                                                                                  e["position_mm"])
        if photos is not None:
            photos[f"inclined_{theta:g}_{name}"] = ph
    return row


def measure_pushed(est: DisplayEstimator, world: TwinWorld, meas: Measurer, depth_mm: float,
                   models=("none", "four_triangle", "fine"), photos: dict | None = None) -> dict:
    """Fig. 13 at push depth ``depth_mm``: each of ``models`` and the picked one, on the true (FEM) sheet."""
    origin, normal, axis_u = HOME_POSE
    q = est.joints(origin, normal, axis_u)
    finger = origin - depth_mm * 1e-3 * normal            # commanded, known to both sides
    sheet = est.sheet(q, finger)                          # the renderer's sheet (its shape model)
    sheets = {"fine": est.sheet(q, finger, series=True), "fem_nominal": sheet}
    true, info = world.sheet(q, finger)
    picked = est.pick(sheet)
    if picked == "fine":
        picked = "fem_nominal"
    row: dict = {"model": picked, "true_depth_mm": info["depth"] * 1e3,
                 "true_contact_mm": [info["push_u"] * 1e3, info["push_v"] * 1e3], **_pose_dev(info, sheet)}
    for model in dict.fromkeys((*models, picked)):
        gl = "fine" if model == "fem_nominal" else model
        ph = meas.shoot(est.draw(gl, sheets.get(model, sheet)), world, true)
        e = meas.errors(ph, "hw")
        lab = MODEL_LABELS[model]
        row[f"{lab}_mm"], row[f"{lab}_sizes_mm"], row[f"{lab}_position_mm"] = (e["mean_mm"], e["sizes_mm"],
                                                                               e["position_mm"])
        if photos is not None:
            photos[f"pushed_{depth_mm:g}_{lab}"] = ph
    row["corrected_mm"] = row[f"{MODEL_LABELS[picked]}_mm"]
    row["corrected_sizes_mm"] = row[f"{MODEL_LABELS[picked]}_sizes_mm"]
    row["corrected_position_mm"] = row[f"{MODEL_LABELS[picked]}_position_mm"]
    return row


def sweep_inclined(est: DisplayEstimator, world: TwinWorld, meas: Measurer, thetas, photos: dict,
                   tag: str) -> dict:
    """Fig. 11: :func:`measure_inclined` at each of ``thetas`` deg, keyed by θ; each row is logged after
    ``tag``."""
    rows = {}
    for th in thetas:
        rows[f"{th:g}"] = r = measure_inclined(est, world, meas, th, photos)
        log.info(f"{tag}: inclined {th:g}°: uncorrected {r['uncorrected_mm']:.2f} mm, "
                 f"{r['model']} {r['corrected_mm']:.2f} mm")
    return rows


def sweep_pushed(est: DisplayEstimator, world: TwinWorld, meas: Measurer, depths, photos: dict,
                 tag: str) -> dict:
    """Fig. 13: :func:`measure_pushed` of every model at each of ``depths`` mm, keyed by S; each row is logged
    after ``tag``."""
    rows = {}
    models = ("none", "four_triangle", "fine", "fem_nominal")
    for S in depths:
        rows[f"{S:g}"] = r = measure_pushed(est, world, meas, S, models, photos)
        log.info(f"{tag}: pushed {S:g} mm: " + ", ".join(
            f"{MODEL_LABELS[m]} {r[MODEL_LABELS[m] + '_mm']:.2f}" for m in models)
                 + f" mm; picked {r['model']}")
    return rows
