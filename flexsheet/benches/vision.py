"""``flexsheet bench vision [--json]``: speed and accuracy figures of the vision pipeline (flat JSON).

Keys:

* ``detect_triangulate_median_ms`` — median wall time of :meth:`FingertipTracker.process` (detection in the
  ROI + matching + optimal triangulation + covariance + gate) per 640×480 stereo pair of the BumbleBee2
  twin, the marker moving along the default stroke; ``..._p95_ms`` and ``full_frame_median_ms`` (ROI off:
  full-frame search every frame, the cost paid on loss) beside it.
* ``rms_error_mm_at_0p5m_sigma0p1`` — RMS 3-D error (mm) of optimal triangulation at 0.5 m with
  σ = 0.1 px of Gaussian noise on each image coordinate, for the issue's reference BumbleBee2 at
  1024×768 (f ≈ 817 px, B = 0.12 m); the same for the 640×480 BumbleBee2 and the XIMEA twin, and the
  theoretical floors.
* ``stereo_rms_px`` — stereo RMS reprojection error of ``calibrate stereo`` on the 17 real XIMEA pairs
  (``tests/data/stereo_xi``, square 0.024 m), with ``baseline_mm``.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import time

import cv2
import numpy as np

from flexsheet.twin.camera import StereoCameraTwin, default_trajectory
from flexsheet.twin.camera_config import SimConfig
from flexsheet.vision.camera_model import (
    DEFAULT_CAMERA_POSITION,
    bumblebee2_calibration,
    camera_model,
    look_at,
)
from flexsheet.vision.stereo import StereoModel
from flexsheet.vision.stereo_calibration import calibrate_stereo, parse_board
from flexsheet.vision.tracker import FingertipTracker, TrackerConfig

__all__ = ["main", "timing", "mc_rms_mm", "real_stereo_rms"]

DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tests", "data", "stereo_xi")


def timing(n: int = 300, seed: int = 0, method: str = "optimal") -> dict:
    """Per-pair timing (ms) of the tracker on ``n`` twin frames (BumbleBee2 640×480, default mount, stroke
    trajectory at 3× speed): ROI mode and full-frame mode. Returns a dict of medians/p95 and valid rate."""
    calib = bumblebee2_calibration()
    T = look_at(DEFAULT_CAMERA_POSITION)
    rnd = StereoCameraTwin(calib, T, SimConfig(seed=seed))
    frames = []
    for k in range(n):
        pos, vel = default_trajectory(3.0 * k / 48.0)
        frames.append(rnd.render(pos, 3.0 * vel))
    out = {}
    for mode in ("roi", "full"):
        tr = FingertipTracker(calib, TrackerConfig(method=method), T)
        ts, valid = [], 0
        for k, (L, R) in enumerate(frames):
            if mode == "full":
                tr.forget_roi()
            t0 = time.perf_counter()
            res = tr.process(L, R, k / 48.0)
            ts.append(time.perf_counter() - t0)
            valid += res.valid
        ts = np.array(ts[10:]) * 1e3
        out[mode] = {"median_ms": float(np.median(ts)), "p95_ms": float(np.percentile(ts, 95)),
                     "valid_rate": valid / n}
    return out


def mc_rms_mm(model: StereoModel, depth: float, sigma: float, method: str = "optimal", n: int = 4000,
              seed: int = 0, lateral: float = 0.6) -> float:
    """Monte Carlo RMS 3-D error (mm) at ``depth`` m (left camera z) with per-coordinate pixel noise
    ``sigma`` px, points uniform over the central ``lateral`` fraction of the left image."""
    rng = np.random.default_rng(seed)
    w, h = model.image_size
    u = rng.uniform(w * (1 - lateral) / 2, w * (1 + lateral) / 2, n)
    v = rng.uniform(h * (1 - lateral) / 2, h * (1 + lateral) / 2, n)
    rays = np.column_stack([u, v, np.ones(n)]) @ model.K1inv.T
    X = rays * (depth / rays[:, 2:3])
    il, ir = model.project(X, distort=False)
    Y = model.triangulate(il + rng.normal(0, sigma, il.shape), ir + rng.normal(0, sigma, ir.shape), method)
    return float(np.sqrt(np.mean(np.sum((Y - X) ** 2, axis=1))) * 1e3)


def real_stereo_rms(data: str = DATA) -> dict:
    """Calibrate the real XIMEA pairs in ``data`` (chessboard 9×6, square 0.024 m); stereo RMS and
    baseline."""
    lefts, rights = (sorted(glob.glob(os.path.join(data, "left*.jpg"))),
                     sorted(glob.glob(os.path.join(data, "right*.jpg"))))
    res = calibrate_stereo([cv2.imread(f, 0) for f in lefts], [cv2.imread(f, 0) for f in rights],
                           parse_board("chessboard:9x6", 0.024))
    return {"stereo_rms_px": res.rms_px, "baseline_mm": float(np.linalg.norm(res.T) * 1e3),
            "pairs": len(res.used)}


def main(argv: list[str] | None = None) -> int:
    """CLI ``flexsheet bench vision`` (argparse). Prints figures (``--json``: one flat JSON object)."""
    p = argparse.ArgumentParser(prog="flexsheet bench vision", description=__doc__.splitlines()[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="example:\n  flexsheet bench vision --json")
    p.add_argument("--json", action="store_true", help="print one flat JSON object")
    p.add_argument("--frames", type=int, default=300, help="twin frames timed (default 300)")
    a = p.parse_args(argv)
    tm = timing(a.frames)
    ref = StereoModel.from_calib(bumblebee2_calibration(1024, 768, pixel_um=4.65))
    bb = StereoModel.from_calib(bumblebee2_calibration())
    xi = StereoModel.from_calib(camera_model("ximea"))
    real = real_stereo_rms()
    out = {
        "detect_triangulate_median_ms": round(tm["roi"]["median_ms"], 4),
        "detect_triangulate_p95_ms": round(tm["roi"]["p95_ms"], 4),
        "full_frame_median_ms": round(tm["full"]["median_ms"], 4),
        "valid_rate": round(tm["roi"]["valid_rate"], 4),
        "rms_error_mm_at_0p5m_sigma0p1": round(mc_rms_mm(ref, 0.5, 0.1), 4),
        "floor_depth_mm_at_0p5m_sigma0p1": round(ref.depth_floor(0.5, 0.1) * 1e3, 4),
        "rms_error_mm_at_0p5m_sigma0p1_bb2_640": round(mc_rms_mm(bb, 0.5, 0.1), 4),
        "rms_error_mm_at_0p5m_sigma0p1_ximea": round(mc_rms_mm(xi, 0.5, 0.1), 4),
        "rms_error_mm_at_0p5m_disparity0p1": round(mc_rms_mm(ref, 0.5, 0.1 / np.sqrt(2)), 4),
        "stereo_rms_px": round(real["stereo_rms_px"], 4),
        "stereo_baseline_mm": round(real["baseline_mm"], 3),
        "cpu_count": os.cpu_count(),
    }
    if a.json:
        print(json.dumps(out))
    else:
        for k, v in out.items():
            print(f"{k:45s} {v}")
    return 0
