"""The registration procedures in lab order, on any frame source (twin or lab images), producing
``display.yaml`` entries; and the whole display in the twin against a hidden truth.

Lab order (docs/calibration.md): stereo calibration (``flexsheet calibrate stereo``, not here) →
:func:`run_camera_pose` → :func:`run_projector` → :func:`run_arms` → :func:`run_eye`. Each step starts from
the nominal values (:func:`flexsheet.calibration.display_calib.nominal_display_calib`) and from the entries
measured before it — never from the truth. :func:`flexsheet.twin.registration.run_display_sim` runs all of
them in the twin and scores each estimate against the truth.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from flexsheet.calibration import arms as arms_mod
from flexsheet.calibration import camera_pose as cp_mod
from flexsheet.calibration import projector as pj_mod
from flexsheet.calibration.display_calib import (
    ArmEntry,
    CameraEntry,
    DisplayCalib,
    ProjectorEntry,
    Provenance,
    SheetEntry,
    nominal_display_calib,
)
from flexsheet.calibration.eye import fixed_eye
from flexsheet.calibration.head_camera import (
    design_head_camera,
    eye_entry,
    fixture_poses,
    register_head_camera,
)
from flexsheet.calibration.projector_joint import refine_joint
from flexsheet.calibration.sheet import TERMS, fit_sheet, plan_presses
from flexsheet.vision.glasses import GlassesBoard, GlassesTracker
from flexsheet.vision.stereo_calibration import BoardSpec, parse_board

log = logging.getLogger(__name__)

__all__ = ["Options", "QUICK", "FULL", "run_camera_pose", "run_projector", "run_arms", "run_eye",
           "run_head_camera",
           "run_sheet", "sheet_entry", "run_all"]


@dataclass(frozen=True)
class Options:
    """Procedure settings. ``board``: board spec (:func:`flexsheet.vision.stereo_calibration.parse_board`),
    ``square`` m, ``board_offset`` m; ``views``: board views (home + tilts); ``board_frames``: frames averaged
    per view; ``projector_poses``; ``pattern_spacing`` projector px; ``pattern_frames``; ``arm_configs`` per
    arm; ``marker_frames``; ``prior``: stereo bootstrap JSON for the camera-pose prior ("" = shipped XIMEA
    one, "none" = no prior); ``fit_k1``: projector radial term; ``sheet_presses``: identify the sheet from
    probe presses where the source has a load cell (:func:`run_sheet`)."""

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
    sheet_presses: bool = True

    def board_spec(self) -> BoardSpec:
        return parse_board(self.board, self.square)


FULL = Options()
#: the test/CI preset: fewer views, poses and configurations, still within the targets (docs/calibration.md)
QUICK = Options(projector_poses=4, arm_configs=12, sheet_presses=False)


def run_camera_pose(source, opts: Options, start: DisplayCalib | None = None):
    """Camera-pose procedure: board views from ``source`` → :class:`CameraEntry` and the estimator's result.
    ``start``: where the nominal camera comes from (default :func:`nominal_display_calib`)."""
    start = start or nominal_display_calib()
    board = opts.board_spec()
    poses = cp_mod.plan_board_views(opts.views)
    log.info(f"camera-pose: capturing {len(poses)} board views")
    views = source.board_views(board, poses, opts.board_offset)
    prior = (None if opts.prior == "none"
             else (cp_mod.load_prior(opts.prior) if opts.prior else cp_mod.load_prior()))
    log.info("camera-pose: detecting corners and fitting")
    r = cp_mod.estimate_camera_pose(views, board, start.camera.stereo, start.camera.T_display_camera,
                                    offset=opts.board_offset, prior_cov=prior)
    prov = Provenance(f"camera-pose: {opts.board} {opts.square * 1e3:g} mm on the sheet at home + "
                      f"{r.n_views - 1} tilts; stereo bundle adjustment with a prior "
                      f"({'none' if prior is None else 'bootstrap'})",
                      source=source.label, n_poses=r.n_views,
                      residuals={"rms_px": r.rms_px, "residual_mm": r.residual_mm,
                                 "flatness_mm": r.flatness_mm})
    return CameraEntry(r.T_display_camera, prov, r.stereo, 0.5 * (r.cov + r.cov.T)), r


def run_projector(source, opts: Options, calib: DisplayCalib):
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
        log.info(f"projector: pose {k + 1}/{n}: {len(pats)} patterns")
        frames = source.pattern_frames(pats, plans[min(k, len(plans) - 1)], k)
        poses.append(pj_mod.triangulate_pose(frames, W, H, cam.stereo, cam.T_display_camera,
                                             spacing=opts.pattern_spacing))
    log.info("projector: calibrating")
    r = pj_mod.estimate_projector(poses, nom.K, (W, H), fit_k1=opts.fit_k1)
    j = refine_joint(poses, cam.stereo, cam.T_display_camera, None, r.K, r.D, r.T_display_projector,
                            fit_k1=opts.fit_k1)
    r.K, r.D, r.T_display_projector = j.K, j.D, j.T_display_projector
    r.reprojection_px, r.n_inliers = j.reprojection_px, j.n_points
    prov = Provenance(f"projector: Gray code {W}x{H} on the sheet at {n} poses, stereo-triangulated, "
                      f"cv2.calibrateCamera (intrinsic guess, k1{'' if opts.fit_k1 else ' fixed'}), then "
                      f"maximum likelihood with the projector as a third camera (camera fixed)",
                      source=source.label, n_poses=n,
                      residuals={"reprojection_px": j.reprojection_px, "camera_px": j.sigma_px,
                                 "points": float(j.n_points)})
    return ProjectorEntry(j.K, j.D, j.T_display_projector, W, H, prov), r


def run_arms(source, opts: Options, calib: DisplayCalib, sides=("left", "right")):
    """Arm procedure for each side: marker frames → {side: (ArmEntry, ArmResult)}. Needs ``calib.camera``."""
    calib.require("camera")
    cam = calib.camera
    nom = nominal_display_calib()
    out = {}
    for side in sides:
        a = nom.arms[side]
        qs = arms_mod.plan_arm_configs(side, opts.arm_configs, a.T_display_base, a.marker_offset, cam.stereo,
                                       cam.T_display_camera)
        log.info(f"arms: {side}: {len(qs)} configurations")
        frames, q_used = source.marker_frames(side, qs)
        _, ul, ur = arms_mod.predict_marker(side, q_used, a.T_display_base, a.marker_offset, cam.stereo,
                                            cam.T_display_camera)
        idx, X, skipped, cov = arms_mod.triangulate_markers(frames, (ul, ur), cam.stereo,
                                                            cam.T_display_camera)
        r = arms_mod.estimate_arm_base(side, [q_used[i] for i in idx], X, a.T_display_base, a.marker_offset,
                                       cov=cov, skipped=skipped)
        prov = Provenance(f"arms: clamp marker at {len(q_used)} joint configurations, triangulated; least "
                          f"squares over the URDF FK for base pose + marker offset", source=source.label,
                          n_poses=r.n_configs, residuals={"residual_mm": r.residual_mm})
        out[side] = (ArmEntry(r.T_display_base, r.marker_offset, prov), r)
    return out


def run_eye(V=None, ipd: float | None = None, source: str = "lab"):
    """The fixed-eye entry (paper's V unless given)."""
    nom = nominal_display_calib().eye
    return fixed_eye(nom.V if V is None else V, nom.ipd if ipd is None else ipd, source=source)


@dataclass
class Registration:
    """:func:`run_all`'s result: ``calib`` (every entry), each step's estimator result (``camera``,
    ``projector``: result objects; ``arms``: side → (ArmEntry, ArmResult)) and ``timings`` (s per step)."""

    calib: DisplayCalib
    camera_entry: CameraEntry
    camera: object
    projector_entry: ProjectorEntry
    projector: object
    arms: dict
    timings: dict


def run_all(source, opts: Options) -> Registration:
    """Camera pose, projector, arms and eye in lab order on ``source`` (each step from the ones before); then
    the head camera and the tracked eye when the source has the head camera's scenes."""
    import time

    timings = {}
    t0 = time.perf_counter()
    cam, rc = run_camera_pose(source, opts)
    timings["camera_s"] = time.perf_counter() - t0
    calib = DisplayCalib(camera=cam)
    t0 = time.perf_counter()
    proj, rp = run_projector(source, opts, calib)
    timings["projector_s"] = time.perf_counter() - t0
    calib.projector = proj
    t0 = time.perf_counter()
    arms = run_arms(source, opts, calib)
    timings["arms_s"] = time.perf_counter() - t0
    calib.arms = {s: e for s, (e, _) in arms.items()}
    calib.eye = run_eye(source=source.label)
    if getattr(source, "has_head_camera", False):
        t0 = time.perf_counter()
        calib.head_camera, calib.eye = run_head_camera(source)
        timings["head_camera_s"] = time.perf_counter() - t0
    else:
        log.info("head camera: not registered by this source (the image is drawn for the fixed V)")
    if opts.sheet_presses and getattr(source, "has_load_cell", False):
        t0 = time.perf_counter()
        calib.sheet = run_sheet(source)
        timings["sheet_s"] = time.perf_counter() - t0
    return Registration(calib, cam, rc, proj, rp, arms, timings)


def run_sheet(source, plan=None):
    """The sheet's entry (:mod:`flexsheet.calibration.sheet`): the probe pressed at each (stretch, u, v,
    depths) of ``plan`` (default :func:`~flexsheet.calibration.sheet.plan_presses`), the planner's model
    fitted."""
    plan = plan or plan_presses()
    return sheet_entry(source.sheet_presses(plan), plan, source.label)


def sheet_entry(presses: list, plan: list, label: str):
    """The sheet's entry fitted to ``presses`` (:class:`~flexsheet.calibration.sheet.Press` readings) taken on
    ``plan`` by the source ``label``. Raises ``ValueError`` as
    :func:`~flexsheet.calibration.sheet.fit_sheet`."""
    fit = fit_sheet(presses)
    log.info(f"sheet: {len(presses)} readings at {len(plan)} presses: w {fit.contact_width * 1e3:.1f} mm, "
             f"growth {fit.contact_growth:.2f}, own {fit.own_stiffness:.3g} N + {fit.own_growth:.3g} N/m, "
             f"stretching {fit.stretching:.3g} N/m³, strain offset {fit.strain_offset:+.4f}, position "
             f"{fit.position_u:+.3f} along / {fit.position_v:+.3f} across; model within "
             f"{fit.median_pct:.1f} % (median) of the readings")
    prov = Provenance(f"sheet: probe on a load cell, {len(plan)} presses at clamp strains "
                      f"{sorted({s for s, _, _, _ in plan})}, F = h (g [T (w d + w2 d^2) + b d + a d^2] + c "
                      "d^3) fitted",
                      source=label, n_poses=len(plan),
                      residuals={"median_pct": fit.median_pct, "rms_pct": fit.rms_pct})
    return SheetEntry(**{k: getattr(fit, k) for k in TERMS}, provenance=prov)


def run_head_camera(source):
    """The head camera's entry and the tracked eye entry (:mod:`flexsheet.calibration.head_camera`): the board
    on the chin-rest fixture's steps, then the viewer's sittings on the chin rest and the pupillometer's
    IPD."""
    import numpy as np

    board = GlassesBoard()
    K0, _, w, h = design_head_camera()
    poses = fixture_poses()
    finder = GlassesTracker(K0, None, np.eye(4), board, np.zeros(3), 0.064)
    entry = register_head_camera([finder.detect(im) for im in source.head_fixture_images(poses)], poses,
                                 board, K0,
                                 (w, h), source.label)
    tracker = GlassesTracker(entry.K, entry.D, entry.T_display_camera, board, np.zeros(3), 0.064)
    poses = [tracker.track(im) for im in source.head_chin_rest_images()]
    if not poses or any(p is None for p in poses):
        raise ValueError("head camera: the glasses on the chin rest were not found in every sitting "
                         f"({sum(p is not None for p in poses)} of {len(poses)}; is the viewer seated?)")
    eye = eye_entry([p.T_display_glasses for p in poses], source.pupillometer_ipd(), source=source.label)
    log.info(f"head camera: {entry.provenance.n_poses} fixture steps, "
             f"{entry.provenance.residuals['rms_px']:.3f} px rms; eye offset "
             f"{np.round(eye.glasses_eye_offset * 1e3, 1).tolist()} mm from {len(poses)} sittings, ipd "
             f"{eye.ipd * 1e3:.1f} mm")
    return entry, eye
