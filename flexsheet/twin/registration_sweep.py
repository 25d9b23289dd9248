"""Each registration estimate's error against the number of poses, over several truth seeds, in the twin —
plus the failure modes (a dark sheet, a bowed board, too few poses). Writes ``OUT/sweep.json`` and
``OUT/calibration_sweep.png`` (matplotlib Agg) with the same numbers. Run by
``flexsheet calibrate display --sweep --seeds 1,2,3 --out docs/figures/calibration``.

Per seed the frames are rendered once for the largest count and the estimators run on prefixes of them
(the plans are ordered so every prefix is well spread); the projector and arm sweeps use the camera entry
from the full camera-pose run, as the lab would.
"""

from __future__ import annotations

import json
import logging
import math
import os

import numpy as np

from flexsheet.calibration import arms as arms_mod
from flexsheet.calibration import camera_pose as cp_mod
from flexsheet.calibration import projector as pj_mod
from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.calibration.procedures import FULL, QUICK
from flexsheet.calibration.projector_joint import refine_joint
from flexsheet.twin.registration_camera import CalibrationTwin
from flexsheet.twin.truth import TwinTruth

log = logging.getLogger(__name__)

__all__ = ["CAMERA_N", "PROJECTOR_N", "ARMS_N", "run_sweep"]

CAMERA_N = (1, 3, 5, 8, 12, 16, 21)
PROJECTOR_N = (2, 3, 4, 5, 6, 8)
ARMS_N = (6, 8, 10, 12, 16, 20)
DARK_WHITE_DN = (190.0, 60.0, 30.0, 15.0, 8.0)
#: the twin's board bow: sag at the sheet's corners (±120 mm), mm; the estimator reports it at the board's
#: farthest inner corner (0.47× of that for the default board)
BOW_MM = (0.0, 0.25, 0.5, 1.0, 2.0)


def _deg(r):
    return math.degrees(r)


def _projector(pcs, cam, K, size, fit_k1):
    """The projector step as :func:`flexsheet.calibration.procedures.run_projector` does it."""
    r = pj_mod.estimate_projector(pcs, K, size, fit_k1=fit_k1)
    return refine_joint(pcs, cam.stereo, cam.T_display_camera, None, r.K, r.D, r.T_display_projector,
                               fit_k1=fit_k1)


def _seed_sweep(seed: int, realism: str, quick: bool) -> dict:
    opts = QUICK if quick else FULL
    cam_n = [n for n in CAMERA_N if n <= (12 if quick else 21)]
    pj_n = [n for n in PROJECTOR_N if n <= (5 if quick else 8)]
    arm_n = [n for n in ARMS_N if n <= (12 if quick else 20)]
    truth = TwinTruth.draw(seed, realism)
    twin = CalibrationTwin(truth, seed=seed)
    nom = nominal_display_calib()
    board = opts.board_spec()
    prior = cp_mod.load_prior()
    out: dict = {"camera": {}, "projector": {}, "arms": {"left": {}, "right": {}}}
    log.info(f"sweep seed {seed}: {max(cam_n)} board views")
    twin.frames = opts.board_frames
    views = twin.board_views(board, cp_mod.plan_board_views(max(cam_n)), opts.board_offset)
    best = None
    for n in cam_n:
        r = cp_mod.estimate_camera_pose(views[:n], board, nom.camera.stereo, nom.camera.T_display_camera,
                                        prior_cov=prior, min_views=1)
        t, a = truth.camera_pose_error(r.T_display_camera)
        out["camera"][n] = {"translation_error_mm": t * 1e3, "rotation_error_deg": _deg(a),
                            "rms_px": r.rms_px}
        best = r
    log.info(f"sweep seed {seed}: {max(pj_n)} projector poses")
    W, H = nom.projector.width, nom.projector.height
    pats = pj_mod.gray_code_patterns(W, H)
    pcs = [pj_mod.triangulate_pose(twin.pattern_frames(pats, T, frames=opts.pattern_frames), W, H,
                                   best.stereo,
                                   best.T_display_camera, spacing=opts.pattern_spacing)
           for T in pj_mod.plan_projector_poses(max(pj_n))]
    for n in pj_n:
        try:
            r = _projector(pcs[:n], best, nom.projector.K, (W, H), opts.fit_k1)
        except ValueError as e:
            out["projector"][n] = {"error": str(e)}
            continue
        t, a = truth.projector_pose_error(r.T_display_projector)
        out["projector"][n] = {"translation_error_mm": t * 1e3, "rotation_error_deg": _deg(a),
                               "reprojection_px": r.reprojection_px}
    log.info(f"sweep seed {seed}: {max(arm_n)} configurations per arm")
    twin.frames = opts.marker_frames
    for side in ("left", "right"):
        a0 = nom.arms[side]
        qs = arms_mod.plan_arm_configs(side, max(arm_n), a0.T_display_base, a0.marker_offset, best.stereo,
                                       best.T_display_camera)
        frames = twin.marker_frames(side, qs)
        _, ul, ur = arms_mod.predict_marker(side, qs, a0.T_display_base, a0.marker_offset, best.stereo,
                                            best.T_display_camera)
        for n in arm_n:
            idx, X, sk, cov = arms_mod.triangulate_markers(frames[:n], (ul[:n], ur[:n]), best.stereo,
                                                           best.T_display_camera)
            r = arms_mod.estimate_arm_base(side, [qs[i] for i in idx], X, a0.T_display_base, a0.marker_offset,
                                           min_configs=6, cov=cov)
            t, _ = truth.base_error(side, r.T_display_base)
            out["arms"][side][n] = {"translation_error_mm": t * 1e3, "residual_mm": r.residual_mm}
    return out


def _failure_modes(seed: int, realism: str) -> dict:
    """A dark sheet (projector white on the sheet → decoded pixels, projector error or the refusal) and a
    bowed board (sag at the sheet corners → camera error with the bow fitted and with a flat board assumed),
    on one seed."""
    truth = TwinTruth.draw(seed, realism)
    twin = CalibrationTwin(truth, seed=seed + 1000)
    nom = nominal_display_calib()
    opts = QUICK
    board = opts.board_spec()
    prior = cp_mod.load_prior()
    out: dict = {"board_bow": {}, "dark_sheet": {}}
    log.info(f"failure modes (seed {seed}): bowed board")
    twin.frames = opts.board_frames
    cam = None
    for bow in BOW_MM:
        views = twin.board_views(board, cp_mod.plan_board_views(opts.views), bow_mm=bow)
        out["board_bow"][bow] = {}
        for fit in (True, False):
            key = "bow_fitted" if fit else "flat_assumed"
            try:
                r = cp_mod.estimate_camera_pose(views, board, nom.camera.stereo, nom.camera.T_display_camera,
                                                prior_cov=prior, fit_bow=fit)
                t, a = truth.camera_pose_error(r.T_display_camera)
                out["board_bow"][bow][key] = {"translation_error_mm": t * 1e3, "rotation_error_deg": _deg(a),
                                              "rms_px": r.rms_px, "fitted_bow_mm": r.bow_mm}
                cam = r if (bow == 0.0 and fit) else cam
            except ValueError as e:
                out["board_bow"][bow][key] = {"error": str(e)}
    log.info(f"failure modes (seed {seed}): dark sheet")
    W, H = nom.projector.width, nom.projector.height
    pats = pj_mod.gray_code_patterns(W, H)
    plans = pj_mod.plan_projector_poses(3)
    for white in DARK_WHITE_DN:
        try:
            pcs = [pj_mod.triangulate_pose(twin.pattern_frames(pats, T, white_dn=white, frames=1), W, H,
                                           cam.stereo, cam.T_display_camera) for T in plans]
            r = _projector(pcs, cam, nom.projector.K, (W, H), True)
            t, a = truth.projector_pose_error(r.T_display_projector)
            out["dark_sheet"][white] = {"translation_error_mm": t * 1e3, "rotation_error_deg": _deg(a),
                                        "reprojection_px": r.reprojection_px,
                                        "decoded_pixels_left": int(np.mean([p.valid_left for p in pcs]))}
        except ValueError as e:
            out["dark_sheet"][white] = {"error": str(e)}
    return out


def run_sweep(seeds: list[int], out_dir: str, quick: bool = False, realism: str = "realistic") -> dict:
    """Run the sweep over ``seeds`` and write ``out_dir/sweep.json`` and ``out_dir/calibration_sweep.png``.
    Returns the JSON dict. Raises ``ValueError`` on an empty seed list."""
    if not seeds:
        raise ValueError("need at least one seed")
    os.makedirs(out_dir, exist_ok=True)
    per = {s: _seed_sweep(s, realism, quick) for s in seeds}
    doc = {"seeds": seeds, "realism": realism, "quick": quick,
           "targets": {"camera_mm": 0.5, "camera_deg": 0.1, "projector_mm": 2.0, "projector_deg": 0.2,
                       "projector_px": 0.5, "arms_mm": 1.0},
           "per_seed": per, "failure_modes": _failure_modes(seeds[0], realism)}
    with open(os.path.join(out_dir, "sweep.json"), "w") as fh:
        json.dump(doc, fh, indent=1, default=str)
    _plot(doc, os.path.join(out_dir, "calibration_sweep.png"))
    log.info(f"wrote {out_dir}/sweep.json, {out_dir}/calibration_sweep.png")
    return doc


def _plot(doc: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = doc["targets"]
    panels = [("camera", "translation_error_mm", "camera pose error, mm", t["camera_mm"], "board views"),
              ("camera", "rotation_error_deg", "camera rotation error, deg", t["camera_deg"], "board views"),
              ("projector", "translation_error_mm", "projector position error, mm", t["projector_mm"],
               "sheet poses"),
              ("projector", "rotation_error_deg", "projector rotation error, deg", t["projector_deg"],
               "sheet poses"),
              ("projector", "reprojection_px", "projector reprojection RMS, px", t["projector_px"],
               "sheet poses"),
              ("arms", "translation_error_mm", "arm base error, mm", t["arms_mm"], "configurations per arm")]
    fig, axes = plt.subplots(2, 3, figsize=(13, 7.5))
    for ax, (part, key, title, target, xlabel) in zip(axes.ravel(), panels, strict=True):
        for s, res in doc["per_seed"].items():
            series = ([(part, res[part])] if part != "arms"
                      else [(f"{side}", res["arms"][side]) for side in ("left", "right")])
            for label, d in series:
                xs = [int(n) for n in d if key in d[n]]
                ys = [d[n][key] for n in d if key in d[n]]
                lab = f"seed {s}" + (f" {label}" if part == "arms" else "")
                ax.plot(xs, ys, "o-" if label != "right" else "s--", ms=4, label=lab)
        ax.axhline(target, color="k", ls=":", lw=1, label="target")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel(xlabel)
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    axes[1, 2].legend(fontsize=6, ncol=2)
    fig.suptitle(f"Display registration in the twin ({doc['realism']} truth): error vs number of "
                 "poses", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
