"""Stability against the projector calibration: a projector moved by a unit error in a random direction
(:func:`perturbed_projector`), the registration's own error scaled (:func:`scaled_error`), the screen → pixel
mapping error they induce (:func:`mapping_error_px`) and both figures' corrected errors against it
(:func:`sweep_projector`)."""

from __future__ import annotations

import dataclasses
import logging
import math

import cv2
import numpy as np

from flexsheet.experiments.correction.calibrated_display import CalibratedDisplay
from flexsheet.experiments.correction.estimator import DisplayEstimator
from flexsheet.experiments.correction.measurer import Measurer
from flexsheet.experiments.correction.settings import PIXEL
from flexsheet.experiments.correction.sweeps import measure_inclined, measure_pushed
from flexsheet.experiments.correction.twin_world import TwinWorld
from flexsheet.experiments.measurement import projector_pixels
from flexsheet.experiments.stability import breaking_point
from flexsheet.model.projector import Projector
from flexsheet.twin.truth import TwinTruth

log = logging.getLogger(__name__)

#: projector calibration error scales: × the registration's own error (direction "calibrated"), and × one
#: :data:`PROJECTOR_UNIT_ERROR` in random directions
PROJECTOR_SCALES = (0.0, 1.0, 3.0, 10.0, 30.0, 100.0)
RANDOM_SCALES = (0.1, 0.25, 0.5, 1.0, 2.0, 4.0)
#: one unit of random projector error: the registration target (2 mm, 0.2°) in a random direction,
#: with 0.5 px of principal point and 0.1 % of focal length (unlike a
#: calibration's error, it is not constrained by the reprojection of the
#: calibration points, so it moves the image: 0.2° is ~5 px on the screen)
PROJECTOR_UNIT_ERROR = {"translation_mm": 2.0, "rotation_deg": 0.2, "principal_point_px": 0.5,
                        "focal_rel": 0.001}
#: points where the induced mapping error is taken: the imaginary screen ±100 × ±80 mm and 50 mm behind it
_MAP_POINTS = np.array([[x, y, z] for x in (0.0, -0.05) for y in np.linspace(-0.1, 0.1, 9)
                        for z in np.linspace(-0.08, 0.08, 7)])



def perturbed_projector(projector: Projector, scale: float, seed: int, direction: int = 0) -> Projector:
    """``projector`` moved by ``scale`` × :data:`PROJECTOR_UNIT_ERROR` in the random direction number
    ``direction`` of ``seed`` (translation, rotation axis, principal-point direction, sign of the focal
    error)."""
    rng = np.random.default_rng([int(seed), 4242, int(direction)])
    u = PROJECTOR_UNIT_ERROR
    dt = rng.normal(size=3)
    dt *= scale * u["translation_mm"] * 1e-3 / np.linalg.norm(dt)
    ax = rng.normal(size=3)
    ax *= scale * math.radians(u["rotation_deg"]) / np.linalg.norm(ax)
    dc = rng.normal(size=2)
    dc *= scale * u["principal_point_px"] / np.linalg.norm(dc)
    sf = 1.0 if rng.random() < 0.5 else -1.0
    K = np.asarray(projector.K, float).copy()
    K[0, 0] *= 1.0 + sf * scale * u["focal_rel"]
    K[1, 1] *= 1.0 + sf * scale * u["focal_rel"]
    K[:2, 2] += dc
    R = cv2.Rodrigues(ax)[0] @ np.asarray(projector.R, float)
    return Projector(K, R, np.asarray(projector.position, float) + dt, projector.width, projector.height)


def scaled_error(true: Projector, true_D, est: Projector, est_D, scale: float) -> tuple[Projector,
                                                                                        np.ndarray]:
    """The projector whose error against ``true`` is ``scale`` × the error of ``est`` (K, D and centre
    linearly; the rotation along the geodesic, exp(s·log.info(R_est R_trueᵀ)) R_true)."""
    K = true.K + scale * (est.K - true.K)
    D = np.asarray(true_D, float) + scale * (np.asarray(est_D, float) - np.asarray(true_D, float))
    w = cv2.Rodrigues(np.asarray(est.R, float) @ np.asarray(true.R, float).T)[0]
    R = cv2.Rodrigues(scale * w)[0] @ np.asarray(true.R, float)
    P = (np.asarray(true.position, float)
         + scale * (np.asarray(est.position, float) - np.asarray(true.position, float)))
    return Projector(K, R, P, true.width, true.height), D


def mapping_error_px(true: Projector, true_D, est: Projector, est_D) -> float:
    """RMS distance (projector px) between the pixels the two projectors give the points of the imaginary
    screen (±100 × ±80 mm) and of a plane 50 mm behind it: how far the renderer's screen → pixel map is
    off."""
    a, _ = projector_pixels(_MAP_POINTS, true, true_D)
    b, _ = projector_pixels(_MAP_POINTS, est, est_D)
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def sweep_projector(cal: CalibratedDisplay, truth: TwinTruth, meas: Measurer, scales=PROJECTOR_SCALES,
                    random_scales=RANDOM_SCALES, theta: float = 50.0, depth_mm: float = 50.0,
                    directions: int = 2,
                    sheet_model=None, quick: bool = False) -> dict:
    """Both figures' corrected errors against a scaled projector calibration error (a sensitivity study: these
    estimator inputs are built from the truth on purpose). Two families, eye and arm bases kept calibrated:

    * ``calibrated``: the registration's own error (``cal`` − truth: K, D, pose) × each of ``scales`` (1 = the
      ``display.yaml`` as registered, 0 = perfect);
    * ``random``: the true projector moved by each of ``random_scales`` × :data:`PROJECTOR_UNIT_ERROR` in
      ``directions`` random directions (the worst direction is kept).

    Each row also gives the induced screen → pixel mapping error (:func:`mapping_error_px`), the common x-axis
    of both families; the breaking point is where the corrected error passes one projector pixel."""
    world = TwinWorld(truth)
    if quick:
        scales, random_scales, directions = (0.0, 1.0, 30.0), (1.0,), 1

    def measure(p, D, label):
        c = dataclasses.replace(cal, projector=p, distortion=np.asarray(D, float).copy(), source=label)
        est = DisplayEstimator(c, sheet_model=sheet_model)
        ri = measure_inclined(est, world, meas, theta)
        rp = measure_pushed(est, world, meas, depth_mm, ())
        est.release()
        return {"mapping_px": mapping_error_px(world.projector, world.distortion, p, D),
                "inclined_corrected_mm": ri["corrected_mm"],
                "inclined_position_mm": ri["corrected_position_mm"],
                "pushed_corrected_mm": rp["corrected_mm"], "pushed_model": rp["model"]}

    fam: dict = {"calibrated": [], "random": []}
    for k in scales:
        p, D = scaled_error(world.projector, world.distortion, cal.projector, cal.distortion, k)
        fam["calibrated"].append({"scale": float(k), **measure(p, D, f"truth + {k:g} × registration error")})
        r = fam["calibrated"][-1]
        log.info(f"[correction] stability: registration error × {k:g} ({r['mapping_px']:.2f} px): inclined "
                 f"{r['inclined_corrected_mm']:.2f} mm, pushed {r['pushed_corrected_mm']:.2f} mm")
    for k in random_scales:
        acc = [measure(*(perturbed_projector(world.projector, k, truth.seed, d), world.distortion),
                       f"truth + {k:g} × unit (direction {d})") for d in range(directions)]
        worst = max(acc, key=lambda r: r["inclined_corrected_mm"])
        fam["random"].append({"scale": float(k), **worst, "directions": len(acc),
                              "mapping_px_all": [r["mapping_px"] for r in acc],
                              "inclined_corrected_all_mm": [r["inclined_corrected_mm"] for r in acc],
                              "pushed_corrected_all_mm": [r["pushed_corrected_mm"] for r in acc]})
        log.info(f"[correction] stability: random projector error × {k:g}: worst inclined "
                 f"{worst['inclined_corrected_mm']:.2f} mm at {worst['mapping_px']:.2f} px")
    lim = PIXEL * 1e3
    out: dict = {"unit": PROJECTOR_UNIT_ERROR, "theta_deg": theta, "depth_mm": depth_mm, "criterion_mm": lim,
                 "directions": directions, **fam}
    for name, rows in fam.items():
        rows_px = sorted(rows, key=lambda r: r["mapping_px"])
        for fig in ("inclined", "pushed"):
            ys = [r[f"{fig}_corrected_mm"] for r in rows]
            out[f"{name}_{fig}_breaks_at_scale"] = breaking_point([r["scale"] for r in rows], ys, lim)
            out[f"{name}_{fig}_breaks_at_px"] = breaking_point([r["mapping_px"] for r in rows_px],
                                                               [r[f"{fig}_corrected_mm"] for r in rows_px],
                                                               lim)
    return out
