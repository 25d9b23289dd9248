"""The display's registration run in the twin: every procedure of :mod:`flexsheet.calibration.procedures` on
frames rendered from a hidden truth (:class:`TwinSource`), each estimate scored against that truth only after
it is fixed, cached per seed (:func:`sim_display_calib`: the ``display.yaml`` the twin's estimator nodes
load).
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from dataclasses import asdict

import numpy as np

from flexsheet.calibration.display_calib_file import write_display_calib
from flexsheet.calibration.head_camera import SITTINGS
from flexsheet.calibration.procedures import FULL, QUICK, Options, run_all
from flexsheet.calibration.sheet import PRESS_DEPTHS, Press, model_error, plan_presses, relative_errors
from flexsheet.dirs import cache_root as flexsheet_cache_root
from flexsheet.model.tension import SheetMaterial
from flexsheet.twin.head_rig import HeadRigTwin
from flexsheet.twin.load_cell import LoadCellTwin
from flexsheet.twin.registration_camera import CalibrationTwin
from flexsheet.twin.truth import TwinTruth

log = logging.getLogger(__name__)

__all__ = ["TwinSource", "run_display_sim", "sim_display_calib", "score_registration", "verdicts", "TARGETS",
           "SUMMARY_VERSION", "sim_display_calib_cached", "score_sheet", "working_model_error",
           "WORKING_STRAINS",
           "contacts_model_error",
           "WORKING_TARGET_PCT"]

SUMMARY_VERSION = 14   # 14: the sheet model knows where the finger presses (position_u, position_v)

Pair = tuple[np.ndarray, np.ndarray]


class TwinSource:
    """Frames rendered by :class:`flexsheet.twin.registration_camera.CalibrationTwin` from a hidden truth.

    ``board_frames``/``pattern_frames``/``marker_frames``: frames averaged per capture for each scene.
    ``sheet_white_dn``: projector white on the sheet (lower it to play a dark sheet)."""

    kind = "twin"

    def __init__(self, twin: CalibrationTwin, board_frames: int = 8, pattern_frames: int = 1,
                 marker_frames: int = 4, sheet_white_dn: float = 190.0, board_bow_mm: float = 0.0):
        self.twin = twin
        self.n_board_frames = board_frames
        self.n_pattern_frames = pattern_frames
        self.n_marker_frames = marker_frames
        self.sheet_white_dn = sheet_white_dn
        self.board_bow_mm = board_bow_mm

    @property
    def label(self) -> str:
        t = self.twin.truth
        return f"twin seed {t.seed} ({t.realism})"

    def board_views(self, board, sheet_poses: list[np.ndarray], offset: float = 0.0) -> list[Pair]:
        """One averaged stereo pair per commanded sheet pose (home first)."""
        f = self.twin.frames
        self.twin.frames = self.n_board_frames
        try:
            return self.twin.board_views(board, sheet_poses, offset, self.board_bow_mm)
        finally:
            self.twin.frames = f

    def pattern_frames(self, patterns: list[np.ndarray], sheet_pose: np.ndarray, index: int) -> list[Pair]:
        """Stereo pairs of every pattern with the sheet at ``sheet_pose`` (pose number ``index``)."""
        return self.twin.pattern_frames(patterns, sheet_pose, white_dn=self.sheet_white_dn,
                                        frames=self.n_pattern_frames)

    has_head_camera = True
    has_load_cell = True

    def sheet_presses(self, plan) -> list:
        """The probe's readings (:class:`flexsheet.calibration.sheet.Press`) for each (stretch, u, v, depths)
        of ``plan`` on the true sheet (:class:`flexsheet.twin.load_cell.LoadCellTwin`)."""
        cell = self._load_cell()
        return [r for s, u, v, ds in plan for r in cell.press(s, u, v, ds)]

    def _load_cell(self):
        if getattr(self, "_cell", None) is None:
            self._cell = LoadCellTwin(self.twin.truth, seed=self.twin.truth.seed)
        return self._cell

    def head_fixture_images(self, poses: list[np.ndarray]) -> list[np.ndarray]:
        """Head-camera images of the glasses board on the chin-rest fixture's steps
        (:class:`flexsheet.twin.head_rig.HeadRigTwin`)."""
        return self._head_rig().fixture_images(poses)

    def head_chin_rest_images(self) -> list[np.ndarray]:
        """The viewer on the chin rest, glasses on, seen by the head camera: one image per sitting."""
        rig = self._head_rig()
        return [rig.chin_rest_image() for _ in range(SITTINGS)]

    def pupillometer_ipd(self) -> float:
        """The viewer's IPD as the lab's pupillometer reads it, m."""
        return self._head_rig().pupillometer_ipd()

    def _head_rig(self):
        if getattr(self, "_rig", None) is None:
            t = self.twin.truth
            self._rig = HeadRigTwin(t.seed, t.realism)
        return self._rig

    def marker_frames(self, side: str, joints: list[np.ndarray]) -> tuple[list[Pair], list[np.ndarray]]:
        """Stereo pairs while arm ``side`` visits ``joints``; returns (frames, the joints actually
        commanded)."""
        f = self.twin.frames
        self.twin.frames = self.n_marker_frames
        try:
            return self.twin.marker_frames(side, joints), [np.asarray(q, float) for q in joints]
        finally:
            self.twin.frames = f



def _err(t, r):
    return {"translation_error_mm": t * 1e3, "rotation_error_deg": math.degrees(r)}


#: the registration targets: camera, projector, arm bases
TARGETS = {"camera_mm": 0.5, "camera_deg": 0.1, "projector_mm": 2.0, "projector_deg": 0.2,
           "projector_px": 0.5,
           "arms_mm": 1.0}


def score_registration(truth: TwinTruth, cam, rc, proj, rp, arms: dict, sheet=None) -> dict:
    """The estimates of :mod:`flexsheet.calibration.procedures` (camera entry + result, projector entry +
    result, ``{side: (ArmEntry, ArmResult)}``, the sheet entry or None) scored against ``truth``: ``camera``,
    ``projector``, ``arms.<side>`` (translation_error_mm, rotation_error_deg, residuals), ``sheet`` (the
    identified model's and the nominal string band's median error against the true force over the presses, %)
    and ``targets``. Call it only once every estimate is fixed."""
    out = {}
    out["camera"] = {**_err(*truth.camera_pose_error(cam.T_display_camera)), "rms_px": rc.rms_px,
                     "residual_mm": rc.residual_mm, "views": rc.n_views}
    out["projector"] = {**_err(*truth.projector_pose_error(proj.T_display_projector)),
                        "reprojection_px": rp.reprojection_px, "poses": rp.n_poses, "points": rp.n_inliers,
                        "focal_error_px": float(proj.K[0, 0] - truth.projector_K[0, 0]),
                        "principal_point_error_px": (proj.K[:2, 2] - truth.projector_K[:2, 2]).tolist()}
    out["arms"] = {s: {**_err(*truth.base_error(s, e.T_display_base)), "residual_mm": r.residual_mm,
                       "configs": r.n_configs,
                       "marker_offset_error_mm": float(np.linalg.norm(e.marker_offset - truth.clamp_marker[s])
                                                       * 1e3)}
                   for s, (e, r) in arms.items()}
    if sheet is not None:
        out["sheet"] = score_sheet(truth, sheet)
    out["targets"] = dict(TARGETS)
    return out


def score_sheet(truth: TwinTruth, sheet) -> dict:
    """The sheet entry against the true force (noise-free) at every reading of the press plan:
    ``model_error_pct`` / ``model_rms_pct`` (the identified model), ``nominal_error_pct`` (the string band it
    replaces), ``fitted_median_pct`` (what the fit saw, with the load cell's noise) and ``target_pct``; and
    ``working`` (:func:`working_model_error`): over the display's working strains, at contacts the plan does
    not press."""
    cell = LoadCellTwin(truth)
    true = [Press(s, u, v, d, cell.true_force(s, u, v, d)) for s, u, v, ds in plan_presses() for d in ds]
    med, rms = model_error(sheet.material(), true)
    return {"model_error_pct": med, "model_rms_pct": rms,
            "nominal_error_pct": model_error(SheetMaterial(), true)[0],
            "fitted_median_pct": sheet.provenance.residuals.get("median_pct"), "target_pct": SHEET_TARGET_PCT,
            "working": working_model_error(truth, sheet)}


#: the display's working clamp strains, where the identified model is judged (every 0.005 from 0.005 to 0.05)
WORKING_STRAINS = tuple(round(0.005 * k, 3) for k in range(1, 11))
#: contacts judged there (u, v) m: the press plan's and three between them it never presses
WORKING_POINTS = ((0.0, 0.0), (0.036, 0.0), (0.072, 0.0), (0.0, 0.036), (0.036, 0.036), (0.054, 0.0),
                  (0.018, 0.018), (0.0, 0.054))
#: the identified model's median error over the working strains, %
WORKING_TARGET_PCT = 5.0


def working_model_error(truth: TwinTruth, sheet) -> dict:
    """The sheet entry's relative error against the true force (noise-free, forces ≥ 20 mN) over
    :data:`WORKING_STRAINS` × :data:`WORKING_POINTS` × the plan's depths: ``median_pct``, ``p90_pct``,
    ``max_pct``, ``n``, ``strains`` [lo, hi] and ``target_pct`` (:data:`WORKING_TARGET_PCT`, on the median). A
    judge's figure: it reads the truth."""
    cell = LoadCellTwin(truth)
    r = relative_errors(sheet.material(),
                        [Press(s, u, v, d, cell.true_force(s, u, v, d)) for s in WORKING_STRAINS
                         for u, v in WORKING_POINTS for d in PRESS_DEPTHS])
    return {"median_pct": float(np.median(r)), "p90_pct": float(np.percentile(r, 90)),
            "max_pct": float(r.max()),
            "n": int(len(r)), "strains": [WORKING_STRAINS[0], WORKING_STRAINS[-1]],
            "target_pct": WORKING_TARGET_PCT}


def contacts_model_error(truth: TwinTruth, sheet, uv, weights=None) -> dict:
    """The sheet entry's relative error against the true force (noise-free, forces ≥ 20 mN) where a run
    touched the sheet: at the contacts ``uv`` (k, 2) m (u along the clamp line, v across) over
    :data:`WORKING_STRAINS` × the plan's depths, each contact weighted by ``weights`` (k,) (its judged
    samples; None: 1). ``median_pct``, ``p90_pct``, ``max_pct``, ``contacts``, ``strains`` and ``target_pct``
    (:data:`WORKING_TARGET_PCT`, on the p90). A judge's figure: it reads the truth. Raises ``ValueError`` for
    no contact, weights of another length, or no press of 20 mN at any contact."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    w = np.ones(len(uv)) if weights is None else np.asarray(weights, float)
    if not len(uv) or w.shape != (len(uv),):
        raise ValueError(f"need contacts (k, 2) and k weights, got {uv.shape} and {w.shape}")
    cell, mat = LoadCellTwin(truth), sheet.material()
    err, wt = [], []
    for (u, v), wi in zip(uv, w, strict=True):
        try:
            r = relative_errors(mat, [Press(s, u, v, d, cell.true_force(s, u, v, d)) for s in WORKING_STRAINS
                                      for d in PRESS_DEPTHS])
        except ValueError:          # no press there of 20 mN: nothing to judge the model by
            continue
        err.append(r)
        wt.append(np.full(len(r), wi))
    if not err:
        raise ValueError(f"no press of 20 mN at any of the {len(uv)} contacts to judge the model by")
    e, wt = np.concatenate(err), np.concatenate(wt)
    order = np.argsort(e)
    cum = np.cumsum(wt[order]) / wt.sum()
    q = lambda p: float(e[order][min(np.searchsorted(cum, p), len(e) - 1)])   # noqa: E731 - weighted quantile
    return {"median_pct": q(0.5), "p90_pct": q(0.9), "max_pct": float(e.max()), "contacts": int(len(uv)),
            "strains": [WORKING_STRAINS[0], WORKING_STRAINS[-1]], "target_pct": WORKING_TARGET_PCT}


#: the identified sheet model's median error against the true force, %
SHEET_TARGET_PCT = 10.0


def verdicts(summary: dict) -> dict:
    """``{name: bool}``: each target of ``summary["targets"]`` met (scored summaries only)."""
    c, p, t = summary["camera"], summary["projector"], summary["targets"]
    out = {"camera_mm": c["translation_error_mm"] <= t["camera_mm"],
           "camera_deg": c["rotation_error_deg"] <= t["camera_deg"],
           "projector_mm": p["translation_error_mm"] <= t["projector_mm"],
           "projector_deg": p["rotation_error_deg"] <= t["projector_deg"],
           "projector_px": p["reprojection_px"] <= t["projector_px"]}
    for side, a in summary["arms"].items():
        out[f"arms_{side}_mm"] = a["translation_error_mm"] <= t["arms_mm"]
    if "sheet" in summary:
        out["sheet_pct"] = summary["sheet"]["model_error_pct"] <= summary["sheet"]["target_pct"]
        if "working" in summary["sheet"]:
            w = summary["sheet"]["working"]
            out["sheet_working_pct"] = w["median_pct"] <= w["target_pct"]
    return out


def run_display_sim(seed: int, out_dir: str, opts: Options = FULL, realism: str = "realistic",
                    force: bool = False) -> dict:
    """Run every procedure in the twin of truth ``seed``; write ``out_dir/display.yaml`` and
    ``out_dir/summary.json`` (errors against the truth under ``camera``, ``projector``, ``arms.left``,
    ``arms.right``; residuals; options; timings). Cached: an existing summary with the same seed, realism,
    options and version is returned unless ``force``. Returns the summary dict."""
    os.makedirs(out_dir, exist_ok=True)
    spath = os.path.join(out_dir, "summary.json")
    ypath = os.path.join(out_dir, "display.yaml")
    key = _cache_key(seed, realism, opts)
    old = None if force else _cached(out_dir, key)
    if old is not None:
        log.info(f"display: seed {seed}: cached ({spath})")
        return old
    t_all = time.perf_counter()
    truth = TwinTruth.draw(int(seed), realism)
    src = TwinSource(CalibrationTwin(truth, seed=int(seed)), opts.board_frames, opts.pattern_frames,
                     opts.marker_frames)
    reg = run_all(src, opts)
    write_display_calib(ypath, reg.calib)
    # scoring against the truth: only now, after every estimate is fixed
    summary = {**key, **score_registration(truth, reg.camera_entry, reg.camera, reg.projector_entry,
                                            reg.projector, reg.arms, reg.calib.sheet)}
    summary["timings"] = {**reg.timings, "total_s": time.perf_counter() - t_all}
    with open(spath, "w") as fh:
        json.dump(summary, fh, indent=1)
    c, p = summary["camera"], summary["projector"]
    log.info(f"display: seed {seed}: camera {c['translation_error_mm']:.3f} mm {c['rotation_error_deg']:.4f}"
              f"°, projector {p['translation_error_mm']:.2f} mm {p['rotation_error_deg']:.3f}° "
              f"{p['reprojection_px']:.3f} px, arms " + ", ".join(
                  f"{s} {summary['arms'][s]['translation_error_mm']:.3f} mm" for s in summary["arms"]))
    return summary


def _cache_key(seed: int, realism: str, opts: Options) -> dict:
    return {"seed": int(seed), "realism": realism, "options": asdict(opts), "version": SUMMARY_VERSION}


def _cached(out_dir: str, key: dict) -> dict | None:
    spath, ypath = os.path.join(out_dir, "summary.json"), os.path.join(out_dir, "display.yaml")
    if not (os.path.isfile(spath) and os.path.isfile(ypath)):
        return None
    try:
        with open(spath) as fh:
            old = json.load(fh)
    except (OSError, json.JSONDecodeError):
        return None
    return old if all(old.get(k) == v for k, v in key.items()) else None


def _cache_dir(seed: int, realism: str, cache_root: str | None, quick: bool) -> str:
    root = cache_root or flexsheet_cache_root()
    return os.path.join(root, "display", f"{realism}-{int(seed)}{'-quick' if quick else ''}")


def sim_display_calib_cached(seed: int, realism: str = "realistic", cache_root: str | None = None,
                             quick: bool = False) -> str | None:
    """The path :func:`sim_display_calib` would return if its cache is current (same seed, realism, options
    and procedure version), else ``None``: nothing runs."""
    out = _cache_dir(seed, realism, cache_root, quick)
    return os.path.join(out, "display.yaml") if _cached(out,
                                                        _cache_key(seed, realism, QUICK if quick else FULL)) \
        else None


def sim_display_calib(seed: int, realism: str = "realistic", cache_root: str | None = None,
                      quick: bool = False) -> str:
    """Path of the twin's ``display.yaml`` for truth ``seed``, running the procedures once per seed and
    caching them under ``cache_root`` (default ``$FLEXSHEET_CACHE`` or
    ``~/.cache/flexsheet``)/display/<realism>-<seed>. This is what the twin's estimator nodes should load at
    start-up."""
    out = _cache_dir(seed, realism, cache_root, quick)
    run_display_sim(seed, out, QUICK if quick else FULL, realism)
    return os.path.join(out, "display.yaml")
