"""The honest vision twin: fingertip error against the hidden truth, measured from rendered images.

The estimator sees what a lab has: the camera's registration (``display.yaml``'s camera entry, produced by
the registration procedure on the twin's images) and the images. The truth
(:class:`flexsheet.twin.truth.TwinTruth`) only forms the images and scores the result.

* :func:`registered_camera` — the camera entry of a truth: the realistic twin's registration
  (:mod:`flexsheet.calibration.procedures`: the board on the sheet rendered through the true cameras, true
  arms and the measured sensor noise, then the camera-pose fit), cached per truth; the ideal twin's nominal
  registration is exact.
* :func:`static_error` / :func:`moving_error` — per-frame fingertip error (display frame) of the real
  pipeline (:class:`flexsheet.vision.tracker.FingertipTracker`) on images of the camera twin
  (:func:`flexsheet.twin.camera.twin_renderer`): a still finger at ~0.5 m, and the paper's stroke
  (:class:`flexsheet.twin.finger.FingerScript`, 60° of the cylinder in 10 s or 30 s) with dropped frames.
* :func:`measure_sensor_noise` — the read/shot noise of the real XIMEA images by a second, independent method
  (flat-patch second differences), and the corner jitter that noise causes on the real images.

No error is injected anywhere: every number comes out of rendered images through the detector.
"""

from __future__ import annotations

import glob
import hashlib
import json
import logging
import math
import os
from dataclasses import asdict, replace

import cv2
import numpy as np

from flexsheet.calibration import procedures as P
from flexsheet.calibration.display_calib import CameraEntry, DisplayCalib, nominal_display_calib
from flexsheet.calibration.display_calib_file import load_display_calib, write_display_calib
from flexsheet.dirs import cache_root
from flexsheet.twin.camera import twin_renderer
from flexsheet.twin.camera_config import XIMEA_SENSOR, SimConfig
from flexsheet.twin.finger import FingerScript
from flexsheet.twin.registration import TwinSource, sim_display_calib
from flexsheet.twin.registration_camera import CalibrationTwin
from flexsheet.twin.truth import Spreads, TwinTruth
from flexsheet.vision.tracker import FingertipTracker, TrackerConfig

log = logging.getLogger(__name__)

__all__ = ["cache_dir", "registered_camera", "sim_config", "static_points",
           "static_error", "moving_error", "registration_error", "scaled_truth", "measure_sensor_noise",
           "sensing_summary", "XIMEA_DIR"]

XIMEA_DIR = "/work/shared/data/stereo_calib_xi"
_HERE = os.path.dirname(os.path.abspath(__file__))
_SOURCES = ("../calibration/camera_pose.py", "../twin/registration_camera.py", "../calibration/procedures.py",
            "../calibration/sources.py", "../twin/truth.py", "../vision/ximea_calib_bootstrap.json")


def cache_dir() -> str:
    """Folder of cached twin registrations: ``$FLEXSHEET_CACHE/vision`` or ``~/.cache/flexsheet/vision``."""
    return os.path.join(cache_root(), "vision")


def sim_config(realism: str, **kw) -> SimConfig:
    """The camera twin's sensing for ``realism`` (``realistic``: :class:`SimConfig`; ``ideal``:
    :meth:`SimConfig.ideal`) with overrides ``kw``."""
    if realism not in ("realistic", "ideal"):
        raise ValueError(f"realism must be 'realistic' or 'ideal', got {realism!r}")
    return SimConfig(**kw) if realism == "realistic" else SimConfig.ideal(**kw)


def _key(truth: TwinTruth, n_views: int) -> str:
    h = hashlib.sha1()
    s = truth.summary()
    h.update(json.dumps({"camera": s["camera"], "T": s["T_display_camera"], "bases": s["bases"],
                         "links": s["link_deltas"], "zeros": s["joint_offsets"], "views": n_views},
                        sort_keys=True).encode())
    for rel in _SOURCES:
        with open(os.path.join(_HERE, rel), "rb") as fh:
            h.update(fh.read())
    return h.hexdigest()[:16]


def registered_camera(truth: TwinTruth, quick: bool = False, cache: str | None = None) -> tuple[CameraEntry,
                                                                                                str]:
    """The camera entry a lab would have for this truth, and the ``display.yaml`` path holding it.

    A realistic truth of the default spreads: the twin's whole registration for its seed
    (:func:`flexsheet.twin.registration.sim_display_calib`, cached per seed — the file the twin's estimator
    nodes load; ``quick``: its test preset). A truth drawn with other spreads (stability sweeps): the
    camera-pose procedure alone (:func:`flexsheet.calibration.procedures.run_camera_pose`, test preset, twin
    board views), cached under :func:`cache_dir` by a hash of the truth's camera and arms and of the
    procedure's sources. Ideal truth: the nominal registration (exact for it). Raises ``ValueError`` when a
    procedure fails."""
    cache = cache or cache_dir()
    if truth.realism == "ideal":
        path = os.path.join(cache, "display_nominal.yaml")
        if not os.path.isfile(path):
            write_display_calib(path, DisplayCalib(camera=nominal_display_calib().camera))
        return load_display_calib(path, require=("camera",)).camera, path
    if truth.spreads == Spreads():
        path = sim_display_calib(truth.seed, truth.realism, quick=quick)
        return load_display_calib(path, require=("camera",)).camera, path
    path = os.path.join(cache, f"camera_seed{truth.seed}_{_key(truth, P.QUICK.views)}.yaml")
    if os.path.isfile(path):
        return load_display_calib(path, require=("camera",)).camera, path

    log.info(f"registering the camera of a scaled truth (seed {truth.seed}, {P.QUICK.views} board views)...")
    o = P.QUICK
    src = TwinSource(CalibrationTwin(truth, seed=truth.seed), o.board_frames, o.pattern_frames,
                     o.marker_frames)
    entry, _ = P.run_camera_pose(src, o)
    write_display_calib(path, DisplayCalib(camera=entry))
    return load_display_calib(path, require=("camera",)).camera, path


def static_points(n: int, seed: int = 0) -> np.ndarray:
    """(n, 3) marker positions, display frame, m: in front of the sheet over the stroke's region (x 5–40 mm,
    y and z within ±50 mm of the sheet centre), 0.45–0.52 m from the default camera."""
    rng = np.random.default_rng([seed, 101])
    return np.column_stack([rng.uniform(0.005, 0.04, n), rng.uniform(-0.05, 0.05, n),
                            rng.uniform(-0.05, 0.05, n)])


#: a valid fix farther than this from the truth is *wrong* (a false match), m
WRONG_M = 0.005


def _summ(errs: list[np.ndarray], valid: int, total: int) -> dict:
    """Error summary: RMS, p95, max (mm), bias and noise about it (mm), valid rate (of ``total`` frames) and
    wrong rate (valid fixes > :data:`WRONG_M` off, of ``total``)."""
    E = np.asarray(errs, float).reshape(-1, 3)
    if len(E) == 0:
        return {"rms_mm": float("nan"), "p95_mm": float("nan"), "bias_mm": [float("nan")] * 3,
                "valid_rate": valid / max(total, 1), "n": 0, "wrong_rate": 0.0}
    d = np.linalg.norm(E, axis=1)
    return {"rms_mm": float(np.sqrt(np.mean(d ** 2)) * 1e3), "p95_mm": float(np.percentile(d, 95) * 1e3),
            "max_mm": float(d.max() * 1e3), "bias_mm": (E.mean(axis=0) * 1e3).round(4).tolist(),
            "noise_mm": float(np.sqrt(np.mean(np.sum((E - E.mean(axis=0)) ** 2, axis=1))) * 1e3),
            "valid_rate": valid / max(total, 1), "n": int(len(E)),
            "wrong_rate": float(np.mean(d > WRONG_M)) * valid / max(total, 1)}


def static_error(truth: TwinTruth, calib: dict, T_display_camera: np.ndarray, cfg: SimConfig,
                 points: np.ndarray, frames: int = 3, sim_seed: int = 0) -> dict:
    """Per-frame error of a still finger: ``frames`` frames at each of ``points`` (N, 3) m (a fresh track per
    point), rendered by the camera twin of ``truth`` with ``cfg``, triangulated with the estimator's
    ``calib`` (stereo dict) and ``T_display_camera``. Returns RMS/p95/max error (mm), bias (mean error vector,
    mm), noise (RMS about the bias, mm), valid rate and reasons."""
    rnd = twin_renderer(truth, replace(cfg, seed=sim_seed))
    errs, valid, reasons = [], 0, {}
    for p in np.asarray(points, float):
        tr = FingertipTracker(calib, TrackerConfig(), T_display_camera)
        for k in range(frames):
            L, R = rnd.render(p)
            res = tr.process(L, R, k / 48.0)
            reasons[res.reason] = reasons.get(res.reason, 0) + 1
            if res.valid:
                valid += 1
                errs.append(res.position - p)
    out = _summ(errs, valid, len(points) * frames)
    cam = truth.T_display_camera[:3, 3]
    out["reasons"] = reasons
    out["range_m"] = [float(np.min(np.linalg.norm(points - cam, axis=1))),
                      float(np.max(np.linalg.norm(points - cam, axis=1)))]
    return out


def moving_error(truth: TwinTruth, calib: dict, T_display_camera: np.ndarray, cfg: SimConfig,
                 moving_time: float = 10.0, drop_rate: float = 0.0, window_s: float | None = None,
                 sim_seed: int = 0, rate_hz: float = 48.0) -> dict:
    """Per-frame error along the paper's stroke (:class:`flexsheet.twin.finger.FingerScript`: 0→60° of the
    cylinder in ``moving_time`` s, with its lag, wander and tremor), one tracker over the whole run, frames at
    ``rate_hz`` each dropped with probability ``drop_rate``; the camera twin renders each frame's motion blur
    from the script's velocity. ``window_s``: only that long a stretch from the middle of the stroke
    (quick runs). Returns the error summary plus ``speed_mps`` (mean, max) and ``dropped``."""
    fs = FingerScript(moving_time=moving_time, seed=sim_seed)
    t0, t1 = fs.t_move, fs.t_move + moving_time
    if window_s is not None:
        mid = 0.5 * (t0 + t1)
        t0, t1 = mid - 0.5 * window_s, mid + 0.5 * window_s
    ts = np.arange(t0, t1, 1.0 / rate_hz)
    P = fs.positions(ts)
    V = (fs.positions(ts + 1e-4) - fs.positions(ts - 1e-4)) / 2e-4
    rnd = twin_renderer(truth, replace(cfg, seed=sim_seed))
    tr = FingertipTracker(calib, TrackerConfig(), T_display_camera)
    rng = np.random.default_rng([sim_seed, 7])
    errs, valid, dropped, reasons = [], 0, 0, {}
    for t, p, v in zip(ts, P, V, strict=True):
        if drop_rate > 0 and rng.random() < drop_rate:
            dropped += 1
            continue
        L, R = rnd.render(p, v)
        res = tr.process(L, R, float(t))
        reasons[res.reason] = reasons.get(res.reason, 0) + 1
        if res.valid:
            valid += 1
            errs.append(res.position - p)
    out = _summ(errs, valid, len(ts) - dropped)
    sp = np.linalg.norm(V, axis=1)
    out.update(reasons=reasons, dropped=dropped, frames=len(ts),
               speed_mps=[float(sp.mean()), float(sp.max())],
               moving_time_s=moving_time)
    return out


def registration_error(truth: TwinTruth, entry: CameraEntry) -> dict:
    """The camera entry's pose error against the truth (mm, deg) — scoring only."""
    dt, dr = truth.camera_pose_error(entry.T_display_camera)
    return {"translation_error_mm": dt * 1e3, "rotation_error_deg": math.degrees(dr),
            "residual_mm": entry.provenance.residuals.get("residual_mm", float("nan")),
            "rms_px": entry.provenance.residuals.get("rms_px", float("nan"))}


def scaled_truth(seed: int, scale: float) -> TwinTruth:
    """A realistic truth with the camera's spreads (stereo bootstrap spread, mount mm and deg) times
    ``scale``."""
    sp = Spreads()
    sp = replace(sp, camera_scale=sp.camera_scale * scale, camera_mount_mm=sp.camera_mount_mm * scale,
                 camera_mount_deg=sp.camera_mount_deg * scale)
    return TwinTruth.draw(seed, "realistic", sp)


# ------------------------------------------------------------------------------------------------ real noise
def measure_sensor_noise(directory: str = XIMEA_DIR, block: int = 8, max_grad: float = 1.5,
                         jitter_repeats: int = 4, seed: int = 0) -> dict:
    """Read and shot noise of the real XIMEA images, and the corner jitter they cause (independent of the
    registration's board-fit method, ``flexsheet.twin.sensor_noise.measure_ximea_noise``).

    Noise: every ``block``×``block`` patch of every image whose smoothed gradient stays below ``max_grad``
    DN/px (a flat board square or background) gives its mean level I and a robust σ from second differences
    along rows and columns (σ = 1.4826·MAD/√6: a second difference of white noise has variance 6σ², and it
    cancels linear shading). Patches are binned by level; σ² = read² + gain·I is fitted (least squares, bins
    weighted by their patch count) over the unsaturated bins (level < 230). Corner jitter: the 9×6 corners
    of each image (``findChessboardCorners`` + ``cornerSubPix`` 11×11) are found again after adding
    ``jitter_repeats`` fresh draws of the fitted noise; the RMS displacement is the jitter a repeated frame
    would show (the images hold no repeated frames, so temporal jitter cannot be measured directly; this
    re-injection estimates it from the measured noise: adding noise of the same level moves a corner by the
    same spread, to first order).

    Returns a dict with ``bins`` (level, σ, count), ``read_dn``, ``shot_gain``, ``corner_jitter_px`` (RMS per
    coordinate) and the registration's numbers for comparison. Raises ``ValueError`` when no image is found.
    """
    files = sorted(glob.glob(os.path.join(directory, "*.jpg")))
    if not files:
        raise ValueError(f"no *.jpg images in {directory!r}")
    mus, sds = [], []
    imgs = []
    for f in files:
        im = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
        if im is None:
            continue
        imgs.append(im)
        img = im.astype(np.float64)
        S = cv2.GaussianBlur(img, (0, 0), 2.0)
        g = np.hypot(cv2.Sobel(S, cv2.CV_64F, 1, 0, ksize=3), cv2.Sobel(S, cv2.CV_64F, 0, 1, ksize=3)) / 8.0
        gmax = cv2.dilate(g, np.ones((5, 5), np.uint8))
        h, w = img.shape
        for y in range(2, h - block - 2, block):
            for x in range(2, w - block - 2, block):
                if gmax[y:y + block, x:x + block].max() > max_grad:
                    continue
                b = img[y:y + block, x:x + block]
                dd = np.concatenate([(b[:, 2:] - 2 * b[:, 1:-1] + b[:, :-2]).ravel(),
                                     (b[2:] - 2 * b[1:-1] + b[:-2]).ravel()])
                mus.append(b.mean())
                sds.append(1.4826 * np.median(np.abs(dd - np.median(dd))) / math.sqrt(6.0))
    mus, sds = np.asarray(mus), np.asarray(sds)
    bins = []
    for lo in range(0, 256, 16):
        m = (mus >= lo) & (mus < lo + 16)
        if m.sum() >= 20:
            bins.append([float(np.mean(mus[m])), float(np.sqrt(np.mean(sds[m] ** 2))), int(m.sum())])
    B = np.array([b for b in bins if b[0] < 230])
    A = np.column_stack([np.ones(len(B)), B[:, 0]])
    wts = np.sqrt(B[:, 2])
    coef, *_ = np.linalg.lstsq(A * wts[:, None], B[:, 1] ** 2 * wts, rcond=None)
    read = math.sqrt(max(coef[0], 0.0))
    gain = max(float(coef[1]), 0.0)
    # corner jitter by re-injecting the fitted noise
    rng = np.random.default_rng(seed)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)
    disp = []
    for im in imgs:
        ok, c = cv2.findChessboardCorners(im, (9, 6),
                                          flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not ok:
            continue
        c0 = cv2.cornerSubPix(im, c.copy(), (11, 11), (-1, -1), crit).reshape(-1, 2)
        sig = np.sqrt(read ** 2 + gain * im.astype(np.float64))
        for _ in range(jitter_repeats):
            noisy = np.clip(np.rint(im + sig * rng.standard_normal(im.shape)), 0, 255).astype(np.uint8)
            c1 = cv2.cornerSubPix(noisy, c.copy(), (11, 11), (-1, -1), crit).reshape(-1, 2)
            disp.append(c1 - c0)
    D = np.concatenate(disp) if disp else np.zeros((0, 2))
    jitter = float(np.sqrt(np.mean(D ** 2))) if len(D) else float("nan")
    return {"source": directory, "images": len(imgs), "patches": int(len(mus)), "bins": bins,
            "read_dn": read, "shot_gain": gain, "corner_jitter_px": jitter,
            "registration_fit": dict(XIMEA_SENSOR),
            "method": "flat 8x8 patches (smoothed gradient < 1.5 DN/px), sigma from second differences "
                      "(1.4826 MAD / sqrt 6); sigma^2 = read^2 + gain*I fitted over level bins < 230 DN; "
                      "corner jitter by re-injecting the fitted noise (no repeated frames in the data)"}


def sensing_summary(cfg: SimConfig) -> dict:
    """The sensing settings of ``cfg`` as a JSON-able dict (recorded beside every result)."""
    return {k: v for k, v in asdict(cfg).items() if k != "seed"}
