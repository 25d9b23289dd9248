"""The registration procedures in lab order, on any frame source (twin or lab images), producing
``display.yaml`` entries; and the whole display in the twin against a hidden truth.

Lab order (docs/calibration.md): stereo calibration (``flexsheet calibrate stereo``, not here) →
:func:`run_camera_pose` → :func:`run_projector` → :func:`run_arms` → :func:`run_eye`. Each step starts from the
nominal values (:func:`flexsheet.calibration.display_calib.nominal_display_calib`) and from the entries measured
before it — never from the truth. :func:`run_display_sim` runs all of them in the twin, scores each estimate
against the truth (only here, after estimation) and caches the result per seed.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass

import numpy as np

from flexsheet.calibration import arms as arms_mod
from flexsheet.calibration import camera_pose as cp_mod
from flexsheet.calibration import projector as pj_mod
from flexsheet.calibration.display_calib import (
    ArmEntry,
    CameraEntry,
    DisplayCalib,
    ProjectorEntry,
    Provenance,
    nominal_display_calib,
    write_display_calib,
)
from flexsheet.calibration.eye import fixed_eye
from flexsheet.vision.stereo_calibration import BoardSpec, parse_board

__all__ = ["Options", "QUICK", "FULL", "run_camera_pose", "run_projector", "run_arms", "run_eye",
           "run_display_sim", "sim_display_calib", "SUMMARY_VERSION"]

SUMMARY_VERSION = 2


@dataclass(frozen=True)
class Options:
    """Procedure settings. ``board``: board spec (:func:`flexsheet.vision.stereo_calibration.parse_board`),
    ``square`` m, ``board_offset`` m; ``views``: board views (home + tilts); ``board_frames``: frames averaged
    per view; ``projector_poses``; ``pattern_spacing`` projector px; ``pattern_frames``; ``arm_configs`` per arm;
    ``marker_frames``; ``prior``: stereo bootstrap JSON for the camera-pose prior ("" = shipped XIMEA one,
    "none" = no prior); ``fit_k1``: projector radial term."""

    board: str = "chessboard:9x8"
    square: float = 0.022
    board_offset: float = 0.0
    views: int = 21
    board_frames: int = 8
    projector_poses: int = 6
    pattern_spacing: int = 8
    pattern_frames: int = 1
    arm_configs: int = 16
    marker_frames: int = 4
    prior: str = ""
    fit_k1: bool = True

    def board_spec(self) -> BoardSpec:
        return parse_board(self.board, self.square)


FULL = Options()
#: the test/CI preset: fewer views, poses and configurations, still within the targets (docs/calibration.md)
QUICK = Options(projector_poses=4, arm_configs=12)


def _progress(msg: str, progress) -> None:
    if progress:
        progress(msg)


def run_camera_pose(source, opts: Options, start: DisplayCalib | None = None, progress=None):
    """Camera-pose procedure: board views from ``source`` → :class:`CameraEntry` and the estimator's result.
    ``start``: where the nominal camera comes from (default :func:`nominal_display_calib`)."""
    start = start or nominal_display_calib()
    board = opts.board_spec()
    poses = cp_mod.plan_board_views(opts.views)
    _progress(f"camera-pose: capturing {len(poses)} board views", progress)
    views = source.board_views(board, poses, opts.board_offset)
    prior = None if opts.prior == "none" else (cp_mod.load_prior(opts.prior) if opts.prior else cp_mod.load_prior())
    _progress("camera-pose: detecting corners and fitting", progress)
    r = cp_mod.estimate_camera_pose(views, board, start.camera.stereo, start.camera.T_display_camera,
                                    offset=opts.board_offset, prior_cov=prior)
    prov = Provenance(f"camera-pose: {opts.board} {opts.square * 1e3:g} mm on the sheet at home + {r.n_views - 1} "
                      f"tilts; stereo bundle adjustment with a prior ({'none' if prior is None else 'bootstrap'})",
                      source=source.label, n_poses=r.n_views,
                      residuals={"rms_px": r.rms_px, "residual_mm": r.residual_mm, "flatness_mm": r.flatness_mm})
    return CameraEntry(r.T_display_camera, prov, r.stereo, 0.5 * (r.cov + r.cov.T)), r


def run_projector(source, opts: Options, calib: DisplayCalib, progress=None):
    """Projector procedure: Gray-code frames at each pose → :class:`ProjectorEntry` and the result. Needs
    ``calib.camera``. The number of poses is ``opts.projector_poses`` (twin) or the captured count (lab)."""
    calib.require("camera")
    nom = nominal_display_calib().projector
    W, H = nom.width, nom.height
    if getattr(source, "manifest", None):
        W = int(source.manifest.get("projector", {}).get("width", W))
        H = int(source.manifest.get("projector", {}).get("height", H))
    pats = pj_mod.gray_code_patterns(W, H)
    n = source.n_projector_poses() if hasattr(source, "n_projector_poses") else opts.projector_poses
    plans = pj_mod.plan_projector_poses(min(max(n, 1), len(pj_mod.POSE_PLAN)))
    cam = calib.camera
    poses = []
    for k in range(n):
        _progress(f"projector: pose {k + 1}/{n}: {len(pats)} patterns", progress)
        frames = source.pattern_frames(pats, plans[min(k, len(plans) - 1)], k)
        poses.append(pj_mod.triangulate_pose(frames, W, H, cam.stereo, cam.T_display_camera,
                                             spacing=opts.pattern_spacing))
    _progress("projector: calibrating", progress)
    r = pj_mod.estimate_projector(poses, nom.K, (W, H), fit_k1=opts.fit_k1)
    j = pj_mod.refine_joint(poses, cam.stereo, cam.T_display_camera, None, r.K, r.D, r.T_display_projector,
                            fit_k1=opts.fit_k1)
    r.K, r.D, r.T_display_projector = j.K, j.D, j.T_display_projector
    r.reprojection_px, r.n_inliers = j.reprojection_px, j.n_points
    prov = Provenance(f"projector: Gray code {W}x{H} on the sheet at {n} poses, stereo-triangulated, "
                      f"cv2.calibrateCamera (intrinsic guess, k1{'' if opts.fit_k1 else ' fixed'}), then maximum "
                      f"likelihood with the projector as a third camera (camera fixed)",
                      source=source.label, n_poses=n,
                      residuals={"reprojection_px": j.reprojection_px, "camera_px": j.sigma_px,
                                 "points": float(j.n_points)})
    return ProjectorEntry(j.K, j.D, j.T_display_projector, W, H, prov), r


def run_arms(source, opts: Options, calib: DisplayCalib, sides=("left", "right"), progress=None):
    """Arm procedure for each side: marker frames → {side: (ArmEntry, ArmResult)}. Needs ``calib.camera``."""
    calib.require("camera")
    cam = calib.camera
    nom = nominal_display_calib()
    out = {}
    for side in sides:
        a = nom.arms[side]
        qs = arms_mod.plan_arm_configs(side, opts.arm_configs, a.T_display_base, a.marker_offset, cam.stereo,
                                       cam.T_display_camera)
        _progress(f"arms: {side}: {len(qs)} configurations", progress)
        frames, q_used = source.marker_frames(side, qs)
        _, ul, ur = arms_mod.predict_marker(side, q_used, a.T_display_base, a.marker_offset, cam.stereo,
                                            cam.T_display_camera)
        idx, X, skipped, cov = arms_mod.triangulate_markers(frames, (ul, ur), cam.stereo, cam.T_display_camera)
        r = arms_mod.estimate_arm_base(side, [q_used[i] for i in idx], X, a.T_display_base, a.marker_offset,
                                       cov=cov, skipped=skipped)
        prov = Provenance(f"arms: clamp marker at {len(q_used)} joint configurations, triangulated; least squares "
                          f"over the URDF FK for base pose + marker offset", source=source.label,
                          n_poses=r.n_configs, residuals={"residual_mm": r.residual_mm})
        out[side] = (ArmEntry(r.T_display_base, r.marker_offset, prov), r)
    return out


def run_eye(V=None, ipd: float | None = None, source: str = "lab"):
    """The fixed-eye entry (paper's V unless given)."""
    nom = nominal_display_calib().eye
    return fixed_eye(nom.V if V is None else V, nom.ipd if ipd is None else ipd, source=source)


def _err(t, r):
    return {"translation_error_mm": t * 1e3, "rotation_error_deg": math.degrees(r)}


def run_display_sim(seed: int, out_dir: str, opts: Options = FULL, realism: str = "realistic",
                    force: bool = False, progress=print) -> dict:
    """Run every procedure in the twin of truth ``seed``; write ``out_dir/display.yaml`` and
    ``out_dir/summary.json`` (errors against the truth under ``camera``, ``projector``, ``arms.left``,
    ``arms.right``; residuals; options; timings). Cached: an existing summary with the same seed, realism,
    options and version is returned unless ``force``. Returns the summary dict."""
    from flexsheet.calibration.sources import TwinSource
    from flexsheet.calibration.twin import CalibrationTwin
    from flexsheet.twin.truth import TwinTruth

    os.makedirs(out_dir, exist_ok=True)
    spath = os.path.join(out_dir, "summary.json")
    ypath = os.path.join(out_dir, "display.yaml")
    key = {"seed": int(seed), "realism": realism, "options": asdict(opts), "version": SUMMARY_VERSION}
    if not force and os.path.isfile(spath) and os.path.isfile(ypath):
        with open(spath) as fh:
            old = json.load(fh)
        if all(old.get(k) == v for k, v in key.items()):
            _progress(f"display: seed {seed}: cached ({spath})", progress)
            return old
    t_all = time.perf_counter()
    truth = TwinTruth.draw(int(seed), realism)
    src = TwinSource(CalibrationTwin(truth, seed=int(seed)), opts.board_frames, opts.pattern_frames,
                     opts.marker_frames)
    timings = {}
    t0 = time.perf_counter()
    cam, rc = run_camera_pose(src, opts, progress=progress)
    timings["camera_s"] = time.perf_counter() - t0
    calib = DisplayCalib(camera=cam)
    t0 = time.perf_counter()
    proj, rp = run_projector(src, opts, calib, progress=progress)
    timings["projector_s"] = time.perf_counter() - t0
    calib.projector = proj
    t0 = time.perf_counter()
    arms = run_arms(src, opts, calib, progress=progress)
    timings["arms_s"] = time.perf_counter() - t0
    calib.arms = {s: e for s, (e, _) in arms.items()}
    calib.eye = run_eye(source=src.label)
    write_display_calib(ypath, calib)
    # scoring against the truth: only now, after every estimate is fixed
    summary = dict(key)
    summary["camera"] = {**_err(*truth.camera_pose_error(cam.T_display_camera)), "rms_px": rc.rms_px,
                         "residual_mm": rc.residual_mm, "views": rc.n_views}
    summary["projector"] = {**_err(*truth.projector_pose_error(proj.T_display_projector)),
                            "reprojection_px": rp.reprojection_px, "poses": rp.n_poses, "points": rp.n_inliers,
                            "focal_error_px": float(proj.K[0, 0] - truth.projector_K[0, 0]),
                            "principal_point_error_px": (proj.K[:2, 2] - truth.projector_K[:2, 2]).tolist()}
    summary["arms"] = {s: {**_err(*truth.base_error(s, e.T_display_base)), "residual_mm": r.residual_mm,
                           "configs": r.n_configs,
                           "marker_offset_error_mm": float(np.linalg.norm(e.marker_offset - truth.clamp_marker[s]) * 1e3)}
                       for s, (e, r) in arms.items()}
    summary["targets"] = {"camera_mm": 0.5, "camera_deg": 0.1, "projector_mm": 2.0, "projector_deg": 0.2,
                          "projector_px": 0.5, "arms_mm": 1.0}
    summary["timings"] = {**timings, "total_s": time.perf_counter() - t_all}
    with open(spath, "w") as fh:
        json.dump(summary, fh, indent=1)
    c, p = summary["camera"], summary["projector"]
    _progress(f"display: seed {seed}: camera {c['translation_error_mm']:.3f} mm {c['rotation_error_deg']:.4f}°, "
              f"projector {p['translation_error_mm']:.2f} mm {p['rotation_error_deg']:.3f}° "
              f"{p['reprojection_px']:.3f} px, arms " + ", ".join(
                  f"{s} {summary['arms'][s]['translation_error_mm']:.3f} mm" for s in summary["arms"]), progress)
    return summary


def sim_display_calib(seed: int, realism: str = "realistic", cache_root: str | None = None,
                      quick: bool = False, progress=None) -> str:
    """Path of the twin's ``display.yaml`` for truth ``seed``, running the procedures once per seed and caching
    them under ``cache_root`` (default ``$FLEXSHEET_CACHE`` or ``~/.cache/flexsheet``)/display/<realism>-<seed>.
    This is what the twin's estimator nodes should load at start-up (issue 15)."""
    root = cache_root or os.environ.get("FLEXSHEET_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "flexsheet")
    out = os.path.join(root, "display", f"{realism}-{int(seed)}{'-quick' if quick else ''}")
    run_display_sim(seed, out, QUICK if quick else FULL, realism, progress=progress)
    return os.path.join(out, "display.yaml")
